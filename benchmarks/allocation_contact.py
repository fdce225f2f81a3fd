"""Benchmark: ``rss6 allocate`` on the paper scene at the contact level for a steady-window spec.

Run on demand: ``python benchmarks/allocation_contact.py [-n 100] [--max-ensembles 12] [--workers 2]
[--spec SPEC] [-o DIR]`` (``rss6 warm`` first: a cold contact kernel adds its compile to the wall time).
Runs ``rss6 allocate paper --model contact --spec SPEC -n N --max-ensembles M --json`` in a fresh
process (``python -m pipeline.cli`` of this checkout) and prints the command, the date, the commit,
the machine's load average before and after beside the wall time, the number of ensembles the greedy
search ran, the class per family with its band and cost, the total cost against the cheapest uniform
class, and the verification's verdicts (the answer's own passing ensemble, judged by the gate).

The default spec, ``displacement:x,y,z<=0.35mm@q95/steady``, lies between what the dearest and the
cheapest uniform classes give: z's steady q95 upper bound at n = 100 is 0.1204 mm at H7/g6, 0.319 mm
at H9/d9, 0.4004 mm at H10/d10 and 0.6032 mm at H11/c11 (contact level, seed 0; docs/ensembles.md).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent
SPEC = "displacement:x,y,z<=0.35mm@q95/steady"


def _commit() -> str:
    proc = subprocess.run(["git", "-C", str(CHECKOUT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True)
    dirty = subprocess.run(["git", "-C", str(CHECKOUT), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return proc.stdout.strip() + ("+changes" if dirty else "")


def _report(out: dict, wall: float, loads: tuple[float, float]) -> str:
    """The answer as lines (module doc)."""
    lines = [f"wall time {wall:.1f} s (load average {loads[0]:.2f} before, {loads[1]:.2f} after)",
             f"ensembles run: {out['combinations_judged']} ({out['method']})",
             f"{'family':18}{'class':10}{'radial band (um)':>20}{'cost/joint':>12}"]
    for c in out["classes"]:
        band = f"{c['band_low_m'] * 1e6:.4g}-{c['band_high_m'] * 1e6:.4g}"
        lines.append(f"{c['family']:18}{c['class']:10}{band:>20}{c['cost_per_joint']:12.4g}")
    if out["uniform_cost"] is None:
        lines.append(f"total cost {out['total_cost']:.4g}; cheapest passing uniform class not found")
    else:
        saving = 100 * (1 - out["total_cost"] / out["uniform_cost"])
        lines.append(f"total cost {out['total_cost']:.4g} against {out['uniform_cost']:.4g} for uniform "
                     f"{out['uniform_class']} ({saving:.1f} % saved)")
    lines.append(f"verification ({out['verification_file']}): {out['verification']}")
    for v in out["verdicts"]:
        upper = "none" if v.get("upper") is None else f"{v['upper'] * 1e3:.4g} mm"
        lines.append(f"  {v['spec']} {v['direction']}: {v['outcome']} (upper bound {upper}, n = {v['n']})")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-n", type=int, default=100, help="realisations per ensemble (q95 needs at least 59)")
    p.add_argument("--max-ensembles", type=int, default=12)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--spec", default=SPEC)
    p.add_argument("-o", "--output", help="folder of the allocation (default: a fresh temporary one)")
    args = p.parse_args()
    folder = Path(args.output or tempfile.mkdtemp(prefix="allocation_contact_")) / "allocate"
    cmd = ["allocate", "paper", "--model", "contact", "--spec", args.spec, "-n", str(args.n), "--max-ensembles",
           str(args.max_ensembles), "--workers", str(args.workers), "--json", "--parents", "-o", str(folder)]
    print(f"rss6 {' '.join(cmd[:5])} '{args.spec}' {' '.join(cmd[6:-3])} -o DIR")
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, commit {_commit()}, "
          f"{os.cpu_count()} CPUs")
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *cmd], cwd=CHECKOUT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode not in (0, 1, 3):   # the gate: pass, fail, undecided
        raise SystemExit(f"allocation_contact: rss6 allocate failed ({proc.returncode}):\n{proc.stderr}")
    print(_report(json.loads(proc.stdout), wall, (load, os.getloadavg()[0])))


if __name__ == "__main__":
    main()
