"""Interrupting `rss6 run`: exit code 130, a line saying what is kept, no traceback."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.ensemble.run import TEST_HOLD_ENV


def _interrupt_a_run(tmp_path, kill):
    """Start a quasi-static run of two chunks whose second waits (pipeline.ensemble.run.TEST_HOLD_ENV) for a
    release file that never comes, and SIGINT it (by ``kill``) once the first chunk is stored: the
    second is then in flight whatever the machine's speed."""
    out = tmp_path / "cut.nc"
    parts = Path(str(out) + ".parts")
    env = dict(os.environ, **{TEST_HOLD_ENV: f"2:{tmp_path / 'never'}"})
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", "run", "smoke", "-n", "4",
                             "--chunk", "2", "--workers", "1", "--model", "quasi-static",
                             "-o", str(out)], cwd=tmp_path, start_new_session=True, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while not list(parts.glob("chunk-*.nc")) and proc.poll() is None:
            time.sleep(0.05)                   # until the first chunk is stored
        assert proc.poll() is None, f"the run ended before it could be interrupted: {proc.communicate()}"
        kill(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)   # one Ctrl-C is enough
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


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_or_sighup_to_a_run_ends_it_as_ctrl_c_does(tmp_path, stop):
    """A batch scheduler's SIGTERM (or a closed terminal's SIGHUP) ended the run with no line, a stale
    lock and nothing said (a new user's review): it is now Ctrl-C's clean stop."""
    out = tmp_path / "cut.nc"
    _assert_clean_interrupt(*_interrupt_a_run(tmp_path, lambda pid, _: os.kill(pid, stop)))
    assert not Path(str(out) + ".lock").exists()


def test_sigint_to_a_run_exits_130_and_keeps_the_finished_chunks(tmp_path):
    """`kill -INT PID` of the rss6 process while a chunk computes: one SIGINT ends the run (the
    terminal's Ctrl-C, to the whole process group, is tests/test_cli_guard.py's)."""
    _assert_clean_interrupt(*_interrupt_a_run(tmp_path, os.kill))


def test_ctrl_c_while_waiting_for_dask_is_raised_by_rss6_not_inside_dask(monkeypatch):
    """A Ctrl-C that arrives while the main thread waits in dask's client is held and raised by
    results_as_finished before its next wait: never inside dask's locks (where it could hang the shutdown)."""
    import pipeline.ensemble.cluster as cluster
    from pipeline.files.writing import sigint_deferred
    waits = []

    def wait_in_dask(client, pending):   # stands for dask.distributed.wait: Ctrl-C meanwhile
        waits.append(1)
        assert len(waits) < 3, "the held Ctrl-C was not acted on"
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)   # the handler runs here, in dask's code: it must only take note
        return iter(())
    monkeypatch.setattr(cluster, "_gathered", wait_in_dask)
    with pytest.raises(KeyboardInterrupt) as caught:
        with sigint_deferred() as interrupted:
            list(cluster.results_as_finished(None, ["future"], None, 60.0, interrupted))
    assert len(waits) == 1 and caught.traceback[-1].name == "results_as_finished"


def test_a_run_stopped_before_any_chunk_finished_says_nothing_is_kept(tmp_path, monkeypatch, capsys):
    """Ctrl-C before the first chunk is stored: no parts folder exists, and the line says so instead of
    naming one (a new user's review)."""
    import pipeline.commands.run as run_command
    from pipeline.cli import main

    def stop(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(run_command, "_compute", stop)
    out = tmp_path / "k.nc"
    assert main(["run", "smoke", "-n", "4", "--model", "quasi-static", "-o", str(out)]) == 130
    err = capsys.readouterr().err.strip()
    assert err == "rss6: interrupted; nothing had finished, so nothing is kept", err
    assert not (tmp_path / "k.nc.parts").exists()


def test_ctrl_c_while_the_local_cluster_starts_is_held_then_raised_with_the_cluster_closed(monkeypatch):
    """The cluster's start took Ctrl-C ignored, and a Ctrl-C in those 1-3 s was lost (a new user's
    review: a run went on to the end). It is now held: the cluster, once up, is closed and the Ctrl-C
    raised. A fake cluster sends the SIGINT from its constructor, so no timing is involved."""
    import dask.distributed

    import pipeline.ensemble.cluster as cluster
    closed = []

    class Starting:
        def __init__(self, **kwargs):
            signal.raise_signal(signal.SIGINT)   # as a Ctrl-C landing while the workers start
            assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN

        def close(self):
            closed.append(True)
    monkeypatch.setattr(cluster, "start_worker_server", lambda: None)
    monkeypatch.setattr(dask.distributed, "LocalCluster", Starting)
    with pytest.raises(KeyboardInterrupt):
        cluster.local_cluster(2)
    assert closed == [True]
