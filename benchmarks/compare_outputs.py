"""Every rss6 command's output before and after a change (e.g. a refactoring): record a fixed list of
small commands, then compare two recordings item by item.

    python benchmarks/compare_outputs.py record OUTDIR         # with the rss6 beside sys.executable
    python benchmarks/compare_outputs.py compare DIR_A DIR_B   # exit 0: all equal, 1: some differ

``record`` runs COMMANDS (smoke scene, fixed seeds, one local worker) with the ``rss6`` executable
beside ``sys.executable``, so the venv that runs this script decides which code is recorded, in
OUTDIR as working directory (every output path is relative). Per command it keeps NAME.stdout,
NAME.stderr and NAME.rc; the netCDF, CSV and TOML files the commands write stay in OUTDIR; record.json
holds the command lines, the rss6 used and the wall times (provenance, not compared). OUTDIR's
absolute path, the tmp folder, the venv and the code's folder are replaced by <OUTDIR>, <TMP>,
<VENV>, <CODE> in stdout and stderr when recorded. Run ``rss6 warm`` first: a cold numba cache
costs the contact commands minutes (and only the compile notes on stderr, masked below, differ).
A recording took 371-437 s on 2 cores shared with a CI job (load 9-11), tradeoff 100-145 s of it.

``compare`` checks, one line per item: exit codes equal; stdout and stderr equal after the masks
below; every netCDF file (read raw, ``decode_cf=False``, so encodings count too) has the same
dimensions, data variables and coordinates, the same dtypes, shapes and variable attributes, values
at a relative difference of exactly 0 (``relative_differences`` of compare_ensembles.py; any
non-zero is reported), and the same global attributes except VOLATILE_ATTRS; CSV files equal cell by
cell except VOLATILE_COLUMNS; every other file (the budget's TOML) equal as text; files in one
recording only are differences. PNG files and record.json are listed as skipped.

Masks of stdout and stderr (pattern -> replacement), each because the text depends on the machine's
speed or state, not on the code's results:
- ``"wall_time_s": 0.27`` -> ``"wall_time_s": <T>``: simulate --json's wall time.
- ``in 1.23 s`` -> ``in <T> s``: simulate's and sensitivity's wall time ("... in 5.6 s").
- ``0.0791 s per realisation`` -> ``<T> s per realisation``: tradeoff's measured cost per setting.
- the rest of tradeoff's ``cheapest within 5 %: ...`` line -> ``<timing-dependent>``: the setting
  recommended is the cheapest measured, so which one it is (and its speed-up) depends on timings.
- ``rss6 0.3.0`` / ``"rss6_version": "0.3.0"`` -> ``<VERSION>``: a change may bump the version.
- stderr only: progress lines ``rss6 run: 8/16 realisations (50 %), 7.4 s...`` are dropped (how
  many appear depends on speed: one every 2 s); compile notes (``compiling ... first: numba's cache
  ...``) are dropped (they depend on the numba cache); ``tcp://127.0.0.1:38715`` -> ``tcp://<ADDR>``
  (--until's cluster port is the OS's pick); dask/distributed log lines are dropped (heartbeat
  warnings of a loaded machine).
Recording twice at one commit, the wall times, the tradeoff costs and speed-up, the progress lines
and the port differed; the version, compile notes and dask logs are masked as a precaution (a
change may bump the version; the others depend on the machine's state).

Attributes and values allowed to differ (all but the version found volatile by recording twice at
one commit; a change may bump the version):
- global attribute ``wall_time_s`` (simulate -o, sensitivity): wall time of the computation;
- global attribute ``reference_check_seconds_per_realization`` (tradeoff): a measured cost;
- global attributes ``source``, ``rss6_version``, ``source_rss6_version``: the rss6 version;
- variable ``seconds_per_realization`` (tradeoff.nc) and its entry in the checksum attribute
  ``rss6_sha256`` (the other entries are compared; the JSON is compared per variable, but for its
  ``/attributes`` entry: the attributes themselves are compared above), and CSV column
  ``seconds_per_realization`` (tradeoff.csv): measured costs.
``history`` is compared (rss6 writes into it only the options that fix the results, no machine's
options), and no rss6 file carries a date.

Across the pipeline's restructure into parts (issue 37: dd21ceb against the restructured commit),
`compare` finds every data variable, printed table and exit code equal, and two intended changes:
the `--until` run's progress line on stderr names "1 workers" instead of the address of the local
cluster it had started for its batches (one client of one cluster now serves them all), and the
multi-fidelity file's `interval_high_only` attribute (and a statistics file's one-sided `bounds`
note) names the module that now holds the method, pipeline.analysis.estimators, instead of
pipeline.stats.
"""
from __future__ import annotations

import argparse
import csv
import json
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_ensembles import relative_differences  # noqa: E402


@dataclass(frozen=True)
class Command:
    """One recorded rss6 invocation: its NAME (the stem of its log files) and its arguments."""
    name: str
    args: tuple[str, ...]


QS = ("smoke", "--model", "quasi-static", "--workers", "1")
COMMANDS = (
    Command("01_simulate", ("simulate", "smoke", "--json")),
    Command("02_simulate_contact", ("simulate", "smoke", "--model", "contact", "--json",
                                    "-o", "simulate_contact.nc")),
    Command("03_run_paper", ("run", "smoke", "--model", "paper", "-n", "8", "--store", "full",
                             "--workers", "1", "-o", "run_paper.nc")),
    Command("04_run_quasi_static", ("run", *QS, "-n", "16", "-o", "run_quasi_static.nc")),
    Command("05_run_contact", ("run", "smoke", "--model", "contact", "-n", "8", "--workers", "1",
                               "-o", "run_contact.nc")),
    Command("06_run_qmc", ("run", *QS, "-n", "16", "--sampler", "qmc", "--replicates", "4",
                           "-o", "run_qmc.nc")),
    Command("07_run_until", ("run", *QS, "-n", "64", "--until", "displacement:z@mean<=20%",
                             "-o", "run_until.nc")),
    Command("08_run_require", ("run", *QS, "-n", "16", "--require", "displacement:z<=1mm@mean",
                               "--require", "displacement:x,y<=0.001mm@mean", "-o", "run_require.nc")),
    Command("09_stats_json", ("stats", "run_quasi_static.nc", "--json")),
    Command("10_stats_output", ("stats", "run_contact.nc", "-o", "stats_contact.nc")),
    Command("11_sensitivity", ("sensitivity", *QS, "-n", "64", "--no-plots", "-o", "sensitivity.nc")),
    Command("12_budget", ("budget", *QS, "--spec", "displacement:x,y,z<=0.1mm@q95", "-n", "64",
                          "-o", "budget")),
    Command("13_multifidelity", ("multifidelity", "smoke", "--high", "paper", "--low", "quasi-static",
                                 "-n", "8", "--low-n", "32", "--cost-ratio", "10", "--width", "0.05",
                                 "--workers", "1", "-o", "multifidelity.nc")),
    Command("14_tradeoff", ("tradeoff", "smoke", "-n", "1", "-o", "tradeoff")),
)

MANIFEST = "record.json"
VERSION = r"\d+\.\d+(?:\.\d+)?(?:[.+-]\w+)*"
TIME = r"\d+(?:\.\d*)?(?:e[+-]?\d+)?"
MASKS = (   # (pattern, replacement) applied to stdout and stderr; why: the module docstring
    (re.compile(rf'"wall_time_s": {TIME}'), '"wall_time_s": <T>'),
    (re.compile(rf"\bin {TIME} s\b"), "in <T> s"),
    (re.compile(rf"\b{TIME} s per realisation"), "<T> s per realisation"),
    (re.compile(r"(cheapest within \S+ %: ).*"), r"\1<timing-dependent>"),
    (re.compile(rf"\brss6 {VERSION}"), "rss6 <VERSION>"),
    (re.compile(rf'("(?:source_)?rss6_version": )"{VERSION}"'), r'\1"<VERSION>"'),
    (re.compile(r"tcp://[\w.:\[\]-]+:\d+"), "tcp://<ADDR>"),
)
DROPPED_STDERR = (   # whole stderr lines left out; why: the module docstring
    re.compile(r"^rss6 run: \d+/\d+ realisations \("),
    re.compile(r"compiling .* first: numba's cache"),
    re.compile(r"distributed\.[\w.]+ - (?:DEBUG|INFO|WARNING|ERROR|CRITICAL) - "),
)
VOLATILE_ATTRS = frozenset({"wall_time_s", "reference_check_seconds_per_realization",
                            "source", "rss6_version", "source_rss6_version"})
VOLATILE_VARIABLES = frozenset({"seconds_per_realization"})
VOLATILE_COLUMNS = frozenset({"seconds_per_realization"})
CHECKSUM_ATTR = "rss6_sha256"   # pipeline.files.schema.CHECKSUM: {variable: sha256, "/attributes": {...}} as JSON
SKIPPED_SUFFIXES = (".png",)


# ---------------------------------------------------------------------------------------------
# record

def rss6_executable() -> Path:
    """The rss6 script of the venv whose Python runs this file."""
    return Path(sys.executable).parent / "rss6"


def placeholders(outdir: Path) -> list[tuple[str, str]]:
    """Absolute paths that differ between recordings, longest first, with their placeholders."""
    code = subprocess.run([sys.executable, "-c", "import pipeline, pathlib; "
                           "print(pathlib.Path(pipeline.__file__).resolve().parent.parent)"],
                          capture_output=True, text=True).stdout.strip()
    pairs = [(str(outdir.resolve()), "<OUTDIR>"), (str(Path(sys.prefix).resolve()), "<VENV>"),
             (str(Path(tempfile.gettempdir()).resolve()), "<TMP>")]
    pairs += [(code, "<CODE>")] if code else []
    return sorted(pairs, key=lambda p: -len(p[0]))


def code_commit(paths: list[tuple[str, str]]) -> str:
    """The git commit of the recorded code's folder (+ ' with changes' if tracked files differ), or ''."""
    code = next((path for path, mark in paths if mark == "<CODE>"), None)
    if code is None:
        return ""
    head = subprocess.run(["git", "-C", code, "rev-parse", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", code, "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return head.stdout.strip() + (" with changes" if dirty else "") if head.returncode == 0 else ""


def run_one(rss6: Path, command: Command, outdir: Path, paths: list[tuple[str, str]]) -> float:
    """Run ``command`` in ``outdir``; write its NAME.stdout, NAME.stderr, NAME.rc; the wall time, s."""
    start = time.perf_counter()
    done = subprocess.run([str(rss6), *command.args], cwd=outdir, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    for suffix, text in ((".stdout", done.stdout), (".stderr", done.stderr)):
        for path, mark in paths:
            text = text.replace(path, mark)
        (outdir / f"{command.name}{suffix}").write_text(text)
    (outdir / f"{command.name}.rc").write_text(f"{done.returncode}\n")
    return wall


def record(outdir: Path) -> int:
    """Run COMMANDS into the new (or empty) folder ``outdir``; print one line per command."""
    rss6 = rss6_executable()
    if not rss6.exists():
        print(f"compare_outputs: error: {rss6}: no rss6 beside {sys.executable}", file=sys.stderr)
        return 2
    if outdir.exists() and any(outdir.iterdir()):
        print(f"compare_outputs: error: {outdir}: not empty (rss6 would resume or refuse)", file=sys.stderr)
        return 2
    outdir.mkdir(parents=True, exist_ok=True)
    paths = placeholders(outdir)
    version = subprocess.run([str(rss6), "--version"], capture_output=True, text=True).stdout.strip()
    walls, start = {}, time.perf_counter()
    for command in COMMANDS:
        walls[command.name] = run_one(rss6, command, outdir, paths)
        rc = (outdir / f"{command.name}.rc").read_text().strip()
        print(f"{command.name:22s} exit {rc:>3s} {walls[command.name]:7.1f} s  rss6 {' '.join(command.args)}")
    total = time.perf_counter() - start
    manifest = {"rss6": str(rss6), "version": version, "python": sys.executable, "code": code_commit(paths),
                "total_wall_s": total,
                "commands": [{"name": c.name, "argv": ["rss6", *c.args], "wall_s": walls[c.name]}
                             for c in COMMANDS]}
    (outdir / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"recorded {len(COMMANDS)} commands in {total:.0f} s into {outdir}")
    return 0


# ---------------------------------------------------------------------------------------------
# compare

def masked(text: str, stderr: bool) -> list[str]:
    """The lines of ``text`` with MASKS applied (and, for stderr, DROPPED_STDERR lines left out)."""
    out = []
    for line in text.splitlines():
        if stderr and any(p.search(line) for p in DROPPED_STDERR):
            continue
        for pattern, replacement in MASKS:
            line = pattern.sub(replacement, line)
        out.append(line)
    return out


def compare_text(a: Path, b: Path, masks: bool) -> list[str]:
    """Differences of two text files (masked for .stdout/.stderr): the first differing line of each."""
    stderr = a.suffix == ".stderr"
    la = masked(a.read_text(), stderr) if masks else a.read_text().splitlines()
    lb = masked(b.read_text(), stderr) if masks else b.read_text().splitlines()
    if la == lb:
        return []
    i = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
    show = [f"line {i + 1}: A {la[i]!r}" if i < len(la) else f"line {i + 1}: A ends",
            f"B {lb[i]!r}" if i < len(lb) else "B ends"]
    return [f"{sum(x != y for x, y in zip(la, lb)) + abs(len(la) - len(lb))} lines differ, first "
            + "; ".join(show)]


def compare_csv(a: Path, b: Path) -> list[str]:
    """Differences of two CSV files, cell by cell, VOLATILE_COLUMNS left out."""
    with open(a, newline="") as fa, open(b, newline="") as fb:
        ra, rb = list(csv.reader(fa)), list(csv.reader(fb))
    if not ra or not rb or ra[0] != rb[0]:
        return ["headers differ"]
    keep = [i for i, name in enumerate(ra[0]) if name not in VOLATILE_COLUMNS]
    if len(ra) != len(rb):
        return [f"{len(ra) - 1} rows against {len(rb) - 1}"]
    cells = [(r, ra[0][i]) for r, (x, y) in enumerate(zip(ra, rb)) for i in keep
             if i >= len(x) or i >= len(y) or x[i] != y[i]]
    return [f"{len(cells)} cells differ, first: row {cells[0][0]}, column {cells[0][1]}"] if cells else []


def compare_attrs(a: dict, b: dict, where: str, volatile: frozenset = frozenset()) -> list[str]:
    """Differences of two attribute dicts, ``volatile`` keys left out (the checksum per variable)."""
    out = [f"{where}attribute {k!r} in one file only" for k in sorted((set(a) ^ set(b)) - volatile)]
    for k in sorted((set(a) & set(b)) - volatile):
        x, y = a[k], b[k]
        if k == CHECKSUM_ATTR:
            x, y = ({v: d for v, d in json.loads(s).items() if v not in VOLATILE_VARIABLES | {"/attributes"}}
                    for s in (x, y))   # the attributes themselves are compared one by one here
            changed = sorted(v for v in x.keys() | y.keys() if x.get(v) != y.get(v))
            out += [f"{where}checksums differ for {changed}"] if changed else []
            continue
        if not _equal(x, y):
            out.append(f"{where}attribute {k!r}: {str(x)[:60]!r} against {str(y)[:60]!r}")
    return out


def _equal(x, y) -> bool:
    """Attribute values equal (NaN equal to NaN where the values are numbers)."""
    try:
        return bool(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True))
    except TypeError:   # strings: no NaN
        return bool(np.array_equal(np.asarray(x), np.asarray(y)))


def compare_structure(a: xr.Dataset, b: xr.Dataset) -> list[str]:
    """Differences of dimensions, variable sets, and each common variable's dims, dtype and attributes."""
    out = [] if dict(a.sizes) == dict(b.sizes) else [f"dimensions {dict(a.sizes)} against {dict(b.sizes)}"]
    for kind, na, nb in (("data variable", a.data_vars, b.data_vars), ("coordinate", a.coords, b.coords)):
        out += [f"{kind} {n!r} in one file only" for n in sorted(set(na) ^ set(nb))]
    for name in sorted(set(a.variables) & set(b.variables)):
        va, vb = a[name].variable, b[name].variable
        if va.dims != vb.dims or va.shape != vb.shape or va.dtype != vb.dtype:
            out.append(f"variable {name!r}: {va.dims} {va.shape} {va.dtype} against {vb.dims} {vb.shape} {vb.dtype}")
        out += compare_attrs(va.attrs, vb.attrs, f"variable {name!r}: ")
    return out


def compare_netcdf(a: Path, b: Path) -> list[str]:
    """Differences of two netCDF files as stored: structure, values (relative difference 0), attributes."""
    with xr.open_dataset(a, decode_cf=False) as da, xr.open_dataset(b, decode_cf=False) as db:
        out = compare_structure(da, db)
        same = [n for n in set(da.variables) & set(db.variables) if n not in VOLATILE_VARIABLES
                and da[n].shape == db[n].shape and da[n].dims == db[n].dims]
        diffs = relative_differences(da[same].load(), db[same].load()) if same else {}
        out += [f"variable {n!r}: relative difference {d:.3e}" for n, d in sorted(diffs.items()) if d != 0]
        out += compare_attrs(da.attrs, db.attrs, "global ", VOLATILE_ATTRS)
    return out


def compare_item(rel: str, a: Path, b: Path) -> tuple[str, list[str]]:
    """('ok' | 'DIFF' | 'skip', details) for the file ``rel`` of the two recordings."""
    if rel == MANIFEST or rel.endswith(SKIPPED_SUFFIXES):
        return "skip", ["provenance and timings" if rel == MANIFEST else "figure, not compared"]
    if not (a / rel).exists() or not (b / rel).exists():
        return "DIFF", [f"only in {'A' if (a / rel).exists() else 'B'}"]
    suffix = Path(rel).suffix
    if suffix == ".nc":
        problems = compare_netcdf(a / rel, b / rel)
    elif suffix == ".csv":
        problems = compare_csv(a / rel, b / rel)
    elif suffix == ".rc":
        ca, cb = ((d / rel).read_text().strip() for d in (a, b))
        problems = [] if ca == cb else [f"exit code {ca} against {cb}"]
    else:
        problems = compare_text(a / rel, b / rel, masks=suffix in (".stdout", ".stderr"))
    return ("DIFF" if problems else "ok"), problems


def compare(a: Path, b: Path) -> int:
    """One line per file of either recording; 0 if all are equal, 1 otherwise."""
    for d in (a, b):
        if not (d / MANIFEST).is_file():
            print(f"compare_outputs: error: {d}: no {MANIFEST} (not a finished recording)", file=sys.stderr)
            return 2
    files = sorted({str(p.relative_to(d)) for d in (a, b) for p in d.rglob("*") if p.is_file()})
    differ = 0
    for rel in files:
        verdict, details = compare_item(rel, a, b)
        differ += verdict == "DIFF"
        print(f"{verdict:4s} {rel}" + (f": {'; '.join(details)}" if details else ""))
    print(f"{len(files)} files: {differ} differ" + ("" if differ else " (all equal after the documented masks)"))
    return 1 if differ else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="run the command list into a new folder")
    rec.add_argument("outdir", type=Path)
    cmp = sub.add_parser("compare", help="compare two recordings; exit 0 if equal, 1 if not")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    args = parser.parse_args(argv)
    return record(args.outdir) if args.command == "record" else compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
