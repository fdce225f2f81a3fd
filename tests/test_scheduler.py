"""`rss6 run --scheduler` against a real external dask scheduler on 127.0.0.1: an unreachable
address, and a scheduler whose every worker is gone, each end in one line and exit 2, with the
finished chunks kept for a resume."""
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.ensemble.run import TEST_HOLD_ENV
from pipeline.files.opening import open_ensemble

DASK = str(Path(sys.executable).with_name("dask"))
N = 20    # 10 chunks: the first is stored, the others wait (TEST_HOLD_ENV) until the worker is killed
RUN = [sys.executable, "-m", "pipeline.cli", "run", "smoke", "--model", "quasi-static", "-n", str(N),
       "--chunk", "2"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(args: list, log: Path, env: dict | None = None) -> subprocess.Popen:
    """A dask process in its own session (so that it and its children can be killed at once)."""
    with open(log, "w") as f:
        return subprocess.Popen([DASK, *args], stdout=f, stderr=subprocess.STDOUT,
                                start_new_session=True, env=env)


def _wait_for(condition, seconds: float, what: str) -> None:
    end = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < end, f"no {what} after {seconds} s"
        time.sleep(0.05)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(10)


def _error_line(err: str) -> str:
    """The last stderr line, checked to be the only non-progress line and no traceback."""
    lines = [ln for ln in err.strip().splitlines()
             if not ln.startswith("rss6 run:") or ln.startswith("rss6 run: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("value", ["0", "-1", "nan", "soon"])
def test_worker_timeout_is_checked_before_work(tmp_path, capsys, value):
    with pytest.raises(SystemExit) as exit_:
        main(RUN[3:] + ["--scheduler", "tcp://127.0.0.1:1", "--worker-timeout", value,
                        "-o", str(tmp_path / "out.nc")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--worker-timeout" in err, err
    assert list(tmp_path.iterdir()) == []


def test_worker_timeout_without_a_scheduler_is_refused(tmp_path, capsys):
    assert main(RUN[3:] + ["--worker-timeout", "5", "-o", str(tmp_path / "out.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--worker-timeout 5: applies with --scheduler only" in err, err
    assert list(tmp_path.iterdir()) == []


def test_workers_with_a_scheduler_is_refused(tmp_path, capsys):
    """--workers sizes rss6's own local cluster; with --scheduler it would be ignored."""
    assert main(RUN[3:] + ["--scheduler", "tcp://127.0.0.1:1", "--workers", "4", "-o", str(tmp_path / "o.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--workers 4: sets the local cluster" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("port, words", [
    (None, ["cannot reach the dask scheduler", "within 5 s"]),   # nothing listens there (5 s, not 20)
    ("", ["--scheduler", "missing port number", "no scheduler address"]),   # malformed: refused by argparse
])
def test_unreachable_scheduler_is_one_line_and_exit_2_within_seconds(tmp_path, port, words):
    address = f"tcp://127.0.0.1:{_free_port()}" if port is None else "tcp://127.0.0.1"
    proc = subprocess.run(RUN + ["--scheduler", address, "-o", str(tmp_path / "out.nc")],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    line = _error_line(proc.stderr)
    assert proc.returncode == 2, proc.stderr   # a 63-line traceback before, after a 20 s connect timeout
    assert address in line and all(w in line for w in words), line
    assert list(tmp_path.iterdir()) == []


def test_scheduler_that_loses_every_worker_stops_and_keeps_the_parts(tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    out = tmp_path / "out.nc"
    parts = tmp_path / "out.nc.parts"
    worker_log = tmp_path / "worker.log"
    procs = []
    try:
        procs.append(_start(["scheduler", "--host", "127.0.0.1", "--port", str(port),
                             "--no-dashboard"], tmp_path / "scheduler.log"))
        # its chunks after the first wait (TEST_HOLD_ENV): it is killed while chunks remain, however fast
        worker = _start(["worker", address, "--nworkers", "1", "--nthreads", "1", "--no-nanny",
                         "--no-dashboard", "--host", "127.0.0.1"], worker_log,
                        env=dict(os.environ, **{TEST_HOLD_ENV: f"2:{tmp_path / 'never'}"}))
        procs.append(worker)
        _wait_for(lambda: "Registered to" in worker_log.read_text(), 30, "worker registered")
        rss6 = subprocess.Popen(RUN + ["--scheduler", address, "--worker-timeout", "3",
                                       "-o", str(out)], cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        procs.append(rss6)
        _wait_for(lambda: any(parts.glob("chunk-*.nc")), 60, "part file")
        os.killpg(worker.pid, signal.SIGKILL)
        killed = time.monotonic()
        _, err = rss6.communicate(timeout=30)
        waited = time.monotonic() - killed
        kept, merged = sorted(parts.glob("chunk-*.nc")), out.exists()
        stored = {int(r) for path in kept for r in open_ensemble(path)["realization"].values}
        # a new worker: the same command resumes from the parts
        worker_log.write_text("")
        procs.append(_start(["worker", address, "--nworkers", "1", "--nthreads", "1", "--no-nanny",
                             "--no-dashboard", "--host", "127.0.0.1"], worker_log))
        _wait_for(lambda: "Registered to" in worker_log.read_text(), 30, "new worker registered")
        rerun = subprocess.run(RUN + ["--scheduler", address, "--worker-timeout", "3",
                                      "-o", str(out)], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    finally:
        for proc in procs:
            _stop(proc)
    line = _error_line(err)
    assert rss6.returncode == 2, err
    assert address in line and "no workers for 3 s" in line and str(parts) in line, line
    assert waited >= 3, waited   # it waited out --worker-timeout (no upper bound: that is the machine's speed)
    assert not merged
    assert stored == {0, 1}, stored
    assert rerun.returncode == 0, rerun.stderr
    assert f"wrote {out}: {N} realisations" in rerun.stdout, rerun.stdout
    assert f"{len(stored)} of them stored before" in rerun.stdout, rerun.stdout
    assert list(open_ensemble(out)["realization"].values) == list(range(N))


def test_scheduler_without_any_worker_stops_after_the_timeout(tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = _start(["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                       tmp_path / "scheduler.log")
    try:
        _wait_for(lambda: "Scheduler at" in (tmp_path / "scheduler.log").read_text(), 30,
                  "scheduler started")
        start = time.monotonic()
        proc = subprocess.run(RUN + ["--scheduler", address, "--worker-timeout", "3",
                                     "-o", str(tmp_path / "out.nc")], cwd=tmp_path,
                              capture_output=True, text=True, timeout=60)
        elapsed = time.monotonic() - start
    finally:
        _stop(scheduler)
    line = _error_line(proc.stderr)
    assert proc.returncode == 2, proc.stderr
    assert line == (f"rss6 run: error: the dask scheduler at {address} has had no workers for 3 s "
                    "(--worker-timeout 3)"), line
    assert elapsed > 3, elapsed   # it waited out --worker-timeout (no upper bound: that is the machine's speed)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scheduler.log"]   # no lock, no parts


@pytest.mark.slow
@pytest.mark.parametrize("workers", ["unreachable", "none"])
def test_report_on_an_unavailable_scheduler_is_one_line_and_exit_2(tmp_path, workers):
    """`rss6 report --scheduler` ends as `rss6 run --scheduler` does: one line, exit 2."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = []
    try:
        if workers == "none":
            procs.append(_start(["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                 "--no-dashboard"], tmp_path / "scheduler.log"))
            _wait_for(lambda: "Scheduler at" in (tmp_path / "scheduler.log").read_text(), 30,
                      "scheduler started")
        proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "report", "smoke", "-n", "4",
                               "--family-n", "2", "-o", str(tmp_path / "rep"), "--scheduler", address,
                               "--worker-timeout", "3"], cwd=tmp_path, capture_output=True,
                              text=True, timeout=120)
    finally:
        for p in procs:
            _stop(p)
    line = _error_line(proc.stderr)
    assert proc.returncode == 2, proc.stderr
    why = "cannot reach the dask scheduler" if workers == "unreachable" else "no workers for 3 s"
    assert line.startswith("rss6 report: error: ") and address in line and why in line, line
