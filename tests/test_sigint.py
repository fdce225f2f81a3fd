"""Interrupting `rss6 run`: exit code 130, a line saying what is kept, no traceback."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def _interrupt_a_run(tmp_path, kill):
    """Start a quasi-static run of two 2000-realisation chunks (a few seconds each) and SIGINT it
    (by ``kill``) 0.5 s after it reports the first chunk stored: while the second computes."""
    out = tmp_path / "cut.nc"
    parts = Path(str(out) + ".parts")
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", "run", "smoke", "-n", "4000",
                             "--chunk", "2000", "--workers", "1", "--model", "quasi-static",
                             "-o", str(out)], cwd=tmp_path, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = []                              # until the progress line after the first chunk
        while not (seen and seen[-1].startswith("rss6 run: 2000/")) and (line := proc.stderr.readline()):
            seen.append(line)                  # (the start line, and dask may warn, e.g. of a busy port)
        assert seen and seen[-1].startswith("rss6 run: 2000/4000"), seen
        time.sleep(0.5)
        assert proc.poll() is None, "the run ended before it could be interrupted"
        kill(proc.pid, signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:  # a first Ctrl-C is sometimes lost (open in issue 23): again
            kill(proc.pid, signal.SIGINT)
            _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, err, out, parts


def _assert_clean_interrupt(returncode, err, out, parts):
    assert returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.rstrip().splitlines()[-1].startswith("rss6: interrupted; finished chunks are kept in")
    assert not out.exists() and len(list(parts.glob("*.nc"))) == 1


def test_sigint_to_a_run_exits_130_and_keeps_the_finished_chunks(tmp_path):
    """`kill -INT PID` of the rss6 process, between chunk writes.

    Known and not covered here (pipeline/run.py): a SIGINT that lands while the main process
    writes a chunk file can deadlock in xarray's file lock, and Ctrl-C in a terminal, which
    signals the whole process group (``_interrupt_a_run(tmp_path, os.killpg)``), makes the dask
    worker processes print tracebacks in some runs."""
    _assert_clean_interrupt(*_interrupt_a_run(tmp_path, os.kill))

