"""The test suite's default selection at two commits, side by side in one run: each commit installed
in its own venv with its own warmed numba cache, both suites started at once (so a shared, noisy
machine loads both alike), and per-test times compared from pytest's JUnit XML.

    python benchmarks/suite_speed.py BEFORE AFTER [--work DIR] [-- PYTEST_ARGS]

prints each suite's wall time and pytest's own total, the ratio AFTER/BEFORE over the tests the two
commits share (the same tests, so the code's speed), and the seconds the tests new in AFTER add.
"""
from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _setup(work: Path, name: str, rev: str) -> dict:
    """A clone at ``rev`` installed (not editable) in its own venv, its contact kernel compiled into its
    own numba cache; returns the environment its suite runs in."""
    tree, venv, cache = work / name, work / f"venv-{name}", work / f"numba-{name}"
    subprocess.run(["git", "clone", "-q", str(REPO), str(tree)], check=True)
    subprocess.run(["git", "-C", str(tree), "checkout", "-q", rev], check=True)
    subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "pip"), "install", "--quiet", f"{tree}[test]"], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), RSS6_TEST_INSTALLED="1",
               PATH=f"{venv / 'bin'}{os.pathsep}{os.environ['PATH']}", VIRTUAL_ENV=str(venv))
    subprocess.run(["rss6", "warm"], check=True, env=env, cwd=work, stdout=subprocess.DEVNULL)
    return env


def _times(junit: Path) -> dict:
    """Seconds per test (module, name) of a JUnit XML file."""
    return {(tc.get("classname").split(".")[-1], tc.get("name")): float(tc.get("time"))
            for tc in ET.parse(junit).getroot().iter("testcase")}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--work", type=Path, default=Path("suite-speed"), help="a folder that does not exist yet")
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    args = p.parse_args(argv[:cut])
    args.pytest_args = argv[cut + 1:]   # after --: passed to both suites (e.g. -k kinematics)
    args.work.mkdir(parents=True)
    work = args.work.resolve()
    envs = {name: _setup(work, name, rev) for name, rev in (("before", args.before), ("after", args.after))}
    start, procs = time.monotonic(), {}
    for name, env in envs.items():
        log = open(work / f"suite-{name}.log", "w")
        procs[name] = subprocess.Popen([str(work / name / ".ci" / "test"), f"--junitxml={work / name}.xml",
                                        *args.pytest_args],
                                       env=env, stdout=log, stderr=subprocess.STDOUT)
    walls = {}
    while len(walls) < len(procs):
        for name, proc in procs.items():
            if name not in walls and proc.poll() is not None:
                walls[name] = time.monotonic() - start
        time.sleep(1)
    t = {name: _times(work / f"{name}.xml") for name in envs}
    common = t["before"].keys() & t["after"].keys()
    shared = {name: sum(t[name][k] for k in common) for name in envs}
    print(f"python benchmarks/suite_speed.py {args.before} {args.after}  ({time.strftime('%Y-%m-%d %H:%M')}, "
          f"load average {os.getloadavg()[0]:.1f})")
    for name in envs:
        print(f"{name:6s} {getattr(args, name):>12s}: wall {walls[name]:7.0f} s, exit {procs[name].returncode}, "
              f"{len(t[name])} tests, pytest total {sum(t[name].values()):7.0f} s")
    added = sum(t["after"][k] for k in t["after"].keys() - common)
    print(f"the {len(common)} shared tests: after/before = {shared['after'] / shared['before']:.3f}; "
          f"the {len(t['after'].keys() - common)} new tests add {added:.0f} s")
    by_module = collections.Counter()
    for (module, _), sec in t["after"].items():
        by_module[module] += sec
    print("slowest modules after:", ", ".join(f"{m} {s:.0f} s" for m, s in by_module.most_common(5)))
    return max(p.returncode for p in procs.values())


if __name__ == "__main__":
    raise SystemExit(main())
