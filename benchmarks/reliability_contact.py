"""Benchmark: a rare event of the manufactured robot at the contact level by subset simulation (issue 40).

Run on demand: ``python benchmarks/reliability_contact.py [--limit-mm L] [-n N] [--workers 2] [--keep DIR]
[--plot PNG]`` (``--plot``: the run's figure of the levels' thresholds and of what fails).
Runs ``rss6 reliability configs/paper_manufacturing.toml --model contact --event
"displacement:z>Lmm/steady" --method subset -n N --json`` in a fresh process and prints its wall
time, the estimate with its interval and coefficient of variation, the evaluations per level and
the thresholds, and what plain Monte Carlo would need for the same coefficient of variation,
n = (1 - P) / (P CoV^2) realisations, with the time that takes at this run's seconds per
evaluation.  The default limit, 1.65 mm, lies near the steady z maxima's 1e-4 quantile (docs/results.md,
"The manufactured robot's rare event", says how it was chosen and gives this run's numbers).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper_manufacturing.toml"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit-mm", type=float, default=LIMIT_MM, help=f"z limit, mm (default {LIMIT_MM})")
    parser.add_argument("-n", type=int, default=N, help=f"evaluations per subset level (default {N})")
    parser.add_argument("--workers", type=int, default=2, help="local dask workers (default 2)")
    parser.add_argument("--keep", type=Path, help="folder to keep the reliability file in (default: a temporary one)")
    parser.add_argument("--plot", type=Path, help="also write the run's figure (rss6 reliability --plot)")
    args = parser.parse_args(argv)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="rss6-reliability-"))
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "manufacturing_contact_reliability.nc"
    command = [sys.executable, "-m", "pipeline.cli", "reliability", str(CONFIG), "--model", "contact",
               "--event", f"displacement:z>{args.limit_mm:g}mm/steady", "--method", "subset", "-n", str(args.n),
               "--workers", str(args.workers), "-o", str(out), "--json"]
    if args.plot:
        command += ["--plot", str(args.plot.resolve())]
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"reliability_contact: the run failed ({proc.returncode}): {proc.stderr.strip()}")
    res = json.loads(proc.stdout)
    pf, cov, evaluations = res["pf"], res["cov"], res["evaluations"]
    mc = (1.0 - pf) / (pf * cov ** 2) if pf > 0 and cov > 0 else float("inf")
    per_eval = wall / evaluations
    print(f"rss6 reliability {CONFIG.name} --model contact --event 'displacement:z>{args.limit_mm:g}mm/steady' "
          f"--method subset -n {args.n} --workers {args.workers} (load {load:.1f} at start)")
    lo, up = ("none" if res[k] is None else f"{res[k]:.3g}" for k in ("lower", "upper"))   # none below N = 300
    print(f"P = {pf:.3g}, {100 * res['confidence']:g} % interval [{lo}, {up}], "
          f"CoV {cov:.2f}; {evaluations} evaluations in {wall:.0f} s wall ({per_eval:.2f} s each, "
          f"{args.workers} workers)")
    print(f"evaluations per level {res['evaluations_per_level']}, thresholds (m) "
          + ", ".join(f"{t:.4g}" for t in res["thresholds"]))
    print(f"plain Monte Carlo for the same CoV: {mc:.3g} realisations, about {mc * per_eval / 3600:.1f} h "
          f"at this run's {per_eval:.2f} s per evaluation")
    print(f"within 15 minutes: {'yes' if wall <= 900 else 'no'}")
    return 0


LIMIT_MM = 1.65
N = 300

if __name__ == "__main__":
    sys.exit(main())
