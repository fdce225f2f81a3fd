"""``rss6 run``'s level prepared in the workers' fork server (pipeline/commands/prepare_ahead.py):
the level it prepares is the one the run's chunks read (the same cache key, so the workers it forks
prepare nothing), a command line the command refuses leaves nothing and says nothing, and the
server is handed the command line for ``run`` only."""
import json
import sys

import pytest

from pipeline.commands import prepare_ahead
from pipeline.commands import run as run_command
from pipeline.ensemble import run


def _spec_of_the_command(monkeypatch, tmp_path, argv):
    """The EnsembleSpec `rss6 run` computes for ``argv``, taken where it would start computing."""
    seen = {}

    def computed(args, spec, *rest):
        seen["spec"] = spec
        raise KeyboardInterrupt
    monkeypatch.setattr(run_command, "_compute", computed)
    from pipeline.cli import main
    assert main(["run", *argv, "-o", str(tmp_path / "out.nc")]) == 130
    return seen["spec"]


@pytest.mark.parametrize("options", [["--model", "paper"], ["--model", "elastic", "--dt", "0.002", "--elements", "2"],
                                     ["--model", "paper", "--seed", "7", "--integrator", "hht"]])
def test_the_level_prepared_ahead_is_the_one_the_runs_chunks_read(configs, monkeypatch, tmp_path, options):
    argv = [str(configs / "paper.toml"), "-n", "3", *options]
    spec = _spec_of_the_command(monkeypatch, tmp_path, argv)
    run._level.cache_clear()
    assert prepare_ahead.prepare(argv)
    assert run._level.cache_info().misses == 1
    run.run_chunk(spec, [0])
    info = run._level.cache_info()
    assert (info.misses, info.hits) == (1, 1)   # the chunk read the prepared level, it prepared none


@pytest.mark.parametrize("argv", [["no_such_scene.toml"], ["paper", "--model", "papr"], ["paper", "--dt", "-1"],
                                  ["paper", "-n"]])
def test_a_command_line_the_command_refuses_prepares_nothing_and_says_nothing(argv, capsys):
    run._level.cache_clear()
    assert not prepare_ahead.prepare(argv)
    assert run._level.cache_info().currsize == 0
    assert capsys.readouterr() == ("", "")


def test_the_server_reads_the_command_line_once_and_keeps_it_from_its_workers(configs, monkeypatch):
    argv = [str(configs / "smoke.toml"), "--model", "paper"]
    monkeypatch.setenv(prepare_ahead.PREPARE_ENV, json.dumps(argv))
    run._level.cache_clear()
    prepare_ahead.prepare_from_environment()
    assert run._level.cache_info().currsize == 1
    assert prepare_ahead.PREPARE_ENV not in __import__("os").environ


@pytest.mark.parametrize("argv, handed", [(["run", "paper", "-n", "5"], ["paper", "-n", "5"]),
                                          (["report", "paper"], None)])
def test_only_rss6_run_hands_its_command_line_to_the_server(monkeypatch, argv, handed):
    import pipeline.cli as cli
    calls = []
    monkeypatch.setattr(cli, "start_worker_server", lambda *args: calls.append(args))
    monkeypatch.setattr(cli.atexit, "register", lambda f: None)
    cli._start_workers_ahead(argv)
    if handed is None:
        assert calls == [()]
    else:
        (preload, environment), = calls
        assert preload == ("pipeline.commands.prepare_ahead",)
        assert json.loads(environment[prepare_ahead.PREPARE_ENV]) == handed
    assert prepare_ahead.__name__ in sys.modules


def test_the_workers_a_head_started_server_forks_hold_the_level_before_their_first_task(configs, tmp_path):
    """Through the real fork server and a local cluster: a worker's level cache holds the run's level
    before any chunk ran (a fresh process, as the rss6 command starts one)."""
    import subprocess
    script = f"""
import json
import pipeline.cli as cli
from dask.distributed import Client
from pipeline.ensemble.cluster import local_cluster
cli._start_workers_ahead(["run", {str(configs / "smoke.toml")!r}, "--model", "paper"])
def cached():
    from pipeline.ensemble.run import _level
    return _level.cache_info().currsize
with local_cluster(1) as cluster, Client(cluster) as client:
    print(json.dumps(list(client.run(cached).values())))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [1]
