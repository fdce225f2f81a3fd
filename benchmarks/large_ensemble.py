"""Benchmark: the memory of a large plain Monte Carlo ensemble (issue 40, "Scale").

``python benchmarks/large_ensemble.py [-n N] [--workers W] [--json] [--keep DIR]`` runs
``rss6 run paper -n N --model quasi-static --workers W -o FILE`` (N default 1,000,000, W 2) in a
subprocess and prints its wall time, the peak resident memory of its main process and of each
process below it (the dask nannies and workers), and the file's size. Peaks are each process's
VmHWM (the kernel's high-water mark of its resident set, Linux /proc), read every second until
the process ends, so no short peak is missed between samples. The file is written to a temporary
folder and removed, unless ``--keep DIR``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

TICK_S = 1.0


def _children() -> dict:
    """{parent pid: [pid]} of every process (Linux /proc)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        out.setdefault(ppid, []).append(int(stat.parent.name))
    return out


def _hwm_bytes(pid: int) -> int | None:
    """The resident high-water mark (VmHWM) of process ``pid`` in bytes, None once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _sample(root: int, peaks: dict, names: dict) -> None:
    """Record the high-water mark of ``root`` and of every process below it."""
    tree, todo = _children(), [root]
    while todo:
        pid = todo.pop()
        todo.extend(tree.get(pid, []))
        hwm = _hwm_bytes(pid)
        if hwm is not None:
            peaks[pid] = max(peaks.get(pid, 0), hwm)
            if pid not in names:
                try:
                    names[pid] = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:120]
                except OSError:
                    names[pid] = "?"


def measure(n: int, workers: int, folder: Path) -> dict:
    """Run the ensemble once; its wall time (s), peaks (MiB) and file size (MiB)."""
    out = folder / f"paper_quasi-static_{n}.nc"
    cmd = [sys.executable, "-m", "pipeline.cli", "run", "paper", "-n", str(n), "--model", "quasi-static",
           "--workers", str(workers), "-o", str(out)]
    peaks, names, stop = {}, {}, threading.Event()
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def sampler():
        while not stop.is_set():
            _sample(proc.pid, peaks, names)
            stop.wait(TICK_S)

    thread = threading.Thread(target=sampler, daemon=True)
    thread.start()
    stdout, stderr = proc.communicate()
    wall = time.perf_counter() - start
    stop.set()
    thread.join()
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stderr[-2000:]}")
    mib = 2.0 ** -20
    others = sorted(((peaks[p] * mib, names[p]) for p in peaks if p != proc.pid), reverse=True)
    return {"command": "rss6 " + " ".join(cmd[3:-2]), "n": n, "workers": workers, "wall_s": round(wall, 1),
            "main_peak_MiB": round(peaks.get(proc.pid, 0) * mib, 1),
            "other_peaks_MiB": [[round(m, 1), name] for m, name in others],
            "file_MiB": round(out.stat().st_size * mib, 1), "first_line": stdout.splitlines()[0]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=1_000_000, help="realisations (default 1,000,000)")
    parser.add_argument("--workers", type=int, default=2, help="local dask workers (default 2)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--keep", type=Path, help="write the file into this folder and keep it")
    args = parser.parse_args()
    if args.keep:
        result = measure(args.n, args.workers, args.keep)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            result = measure(args.n, args.workers, Path(tmp))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{result['command']}: {result['first_line']}")
    print(f"wall time {result['wall_s']:.1f} s; main process peak resident {result['main_peak_MiB']:.0f} MiB; "
          f"file {result['file_MiB']:.0f} MiB")
    for peak, name in result["other_peaks_MiB"]:
        print(f"  below it: peak {peak:.0f} MiB  {name}")


if __name__ == "__main__":
    main()
