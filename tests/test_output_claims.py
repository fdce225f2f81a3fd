"""A command writing a folder of answers (allocate, budget, map, tradeoff, stability) records the request
they answer and refuses, before any work, to overwrite them with another request's."""
import json

import pytest

from pipeline.cli import main
from pipeline.files.outputs import claimed_output_folder
from pipeline.files.schema import EnsembleFileError

SPEC = "displacement:x,y,z<=0.1mm@q95"


def claim_output_folder(folder, command: str, request: dict, answers: tuple = ()) -> None:
    """Claim ``folder`` for ``request`` and write an output in it."""
    with claimed_output_folder(folder, command, request, answers):
        (folder / f"{command}.out").write_text("answer")


def test_a_folder_answers_one_request_and_names_what_another_changes(tmp_path):
    request = {"scene": "a1", "--spec": ["displacement:z<=1mm@q95"], "-n": 59, "--costs": None}
    claim_output_folder(tmp_path / "f", "allocate", request)
    claim_output_folder(tmp_path / "f", "allocate", dict(request))   # the same request: resumes
    claim_output_folder(tmp_path / "f", "budget", request | {"-n": 60})   # another command's record
    with pytest.raises(EnsembleFileError, match=r"-n 59 there, 60 now") as exc:
        claim_output_folder(tmp_path / "f", "allocate", request | {"-n": 60})
    assert str(exc.value).startswith(f"{tmp_path / 'f'}: holds rss6 allocate's outputs")
    with pytest.raises(EnsembleFileError, match=r"another scene text; --costs unset there, c2 now"):
        claim_output_folder(tmp_path / "f", "allocate", request | {"scene": "b2", "--costs": "c2"})
    with pytest.raises(EnsembleFileError, match=r"--spec 'displacement:z<=1mm@q95' there, none now"):
        claim_output_folder(tmp_path / "f", "allocate", request | {"--spec": []})
    (tmp_path / "f" / "rss6_allocate_request.json").write_text("{")
    with pytest.raises(EnsembleFileError, match=r"rss6_allocate_request.json: unreadable"):
        claim_output_folder(tmp_path / "f", "allocate", request)


def test_a_folder_holding_answers_without_their_record_is_refused(tmp_path):
    """A deleted record let another request overwrite the folder's answer (map, tradeoff, budget exit 0;
    allocate rewrote its scene, then failed): answers without a record are refused; other files are not."""
    (tmp_path / "notes.txt").write_text("the user's")
    claim_output_folder(tmp_path, "budget", {"-n": 4}, ("*_budget.toml",))   # unrelated files: claimed
    (tmp_path / "paper_budget.toml").write_text("the answer")
    (tmp_path / "rss6_budget_request.json").unlink()
    with pytest.raises(EnsembleFileError, match=r"holds rss6 budget's outputs \(paper_budget.toml\) but no "
                                                r"rss6_budget_request.json"):
        claim_output_folder(tmp_path, "budget", {"-n": 8}, ("*_budget.toml",))
    assert (tmp_path / "paper_budget.toml").read_text() == "the answer"


def test_a_request_that_fails_before_writing_anything_claims_nothing(tmp_path):
    (tmp_path / "notes.txt").write_text("the user's")
    for folder, held in ((tmp_path / "new", None), (tmp_path, {"notes.txt"})):
        with pytest.raises(ValueError), claimed_output_folder(folder, "map", {"-n": 4}):
            raise ValueError("no pose reachable")
        assert not folder.exists() if held is None else {p.name for p in folder.iterdir()} == held
    with pytest.raises(KeyboardInterrupt), claimed_output_folder(tmp_path / "part", "budget", {"-n": 4}):
        (tmp_path / "part" / "chunk.nc").write_text("finished work")
        raise KeyboardInterrupt
    assert (tmp_path / "part" / "rss6_budget_request.json").exists()   # claims the work it keeps


def _one_line_refusal(argv, capsys, *words) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1, captured.err
    for word in words:
        assert word in captured.err, captured.err


def test_allocate_with_another_spec_keeps_the_folders_answer(tmp_path, capsys):
    """The reported case: a second allocate into the folder of a first, with another spec, rewrote the
    answer's scene and then failed on the verification ensemble; now it stops before the search."""
    folder = tmp_path / "al"
    argv = ["allocate", "smoke", "--spec", SPEC, "-n", "59", "--workers", "1", "-o", str(folder)]
    assert main(argv) == 0
    capsys.readouterr()
    answer = {p.name: p.read_bytes() for p in folder.iterdir()}
    _one_line_refusal(argv[:3] + ["displacement:x,y,z<=0.2mm@q95"] + argv[4:], capsys,
                      str(folder), "--spec", "0.1mm", "0.2mm", "choose another -o")
    _one_line_refusal(argv + ["--seed", "3"], capsys, "--seed 0 there, 3 now")
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == answer
    assert main(argv) == 0   # the same request again


def test_map_into_the_folder_of_another_map_is_refused(tmp_path, capsys):
    folder = tmp_path / "m"
    assert main(["map", "smoke", "-n", "4", "-o", str(folder)]) == 0
    capsys.readouterr()
    before = (folder / "workspace_map.nc").read_bytes()
    _one_line_refusal(["map", "smoke", "-n", "8", "-o", str(folder)], capsys, "-n 4 there, 8 now")
    assert (folder / "workspace_map.nc").read_bytes() == before
    assert json.loads((folder / "rss6_map_request.json").read_text())["-n"] == 4
    (folder / "rss6_map_request.json").unlink()
    _one_line_refusal(["map", "smoke", "-n", "8", "-o", str(folder)], capsys, "workspace_map.nc", "but no")
    assert (folder / "workspace_map.nc").read_bytes() == before


def test_a_stability_horizon_past_the_trajectory_is_refused_before_work(tmp_path, capsys):
    _one_line_refusal(["stability", "paper", "--horizon", "5", "-o", str(tmp_path / "s")], capsys,
                      "--horizon 5", "2 s")
    assert not (tmp_path / "s").exists()


def test_a_default_output_is_named_after_the_scene_file_not_its_name_key(configs, tmp_path, monkeypatch, capsys):
    """A copy of smoke.toml saved as my.toml (its name key still "smoke") once defaulted to smoke_*.nc and
    was refused there as another scene; the default name now comes from the file, a shipped name as given."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my.toml").write_text((configs / "smoke.toml").read_text() + "\n# my copy, to edit\n")
    for config in ("smoke", "my.toml"):
        assert main(["run", config, "-n", "2", "--model", "quasi-static", "--workers", "1"]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.glob("*.nc")) == ["my_quasi-static.nc", "smoke_quasi-static.nc"]


def test_a_figure_folder_holds_one_files_figures(tmp_path, capsys):
    """rss6 plot wrote a --store full file's envelopes, then a summary file's histograms over the first's into
    the same folder: a mixed set. Replotting the same (grown) file rewrites its figures; another file is refused
    in one line, exit 2, the folder as it was; so is a folder of figures without their record."""
    files = {}
    for name, store in (("full", "full"), ("summary", "summary")):
        files[name] = tmp_path / f"{name}.nc"
        assert main(["run", "smoke", "-n", "2", "--model", "quasi-static", "--store", store,
                     "-o", str(files[name])]) == 0
    figures = tmp_path / "figures"
    assert main(["plot", str(files["full"]), "-o", str(figures)]) == 0
    held = {p.name: p.read_bytes() for p in figures.iterdir()}
    assert "envelope_displacement.png" in held and "rss6_plot_request.json" in held
    assert main(["run", "smoke", "-n", "3", "--model", "quasi-static", "--store", "full",
                 "-o", str(files["full"])]) == 0                     # grown: the same file, replotted
    assert main(["plot", str(files["full"]), "-o", str(figures)]) == 0
    held = {p.name: p.read_bytes() for p in figures.iterdir()}
    capsys.readouterr()
    assert main(["plot", str(files["summary"]), "-o", str(figures)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"rss6 plot: error: {figures}: holds rss6 plot's outputs")
    assert f"file {files['full']} there, {files['summary']} now" in err
    assert {p.name: p.read_bytes() for p in figures.iterdir()} == held
    (figures / "rss6_plot_request.json").unlink()
    assert main(["plot", str(files["full"]), "-o", str(figures)]) == 2
    assert "but no rss6_plot_request.json" in capsys.readouterr().err


def test_a_refusal_names_the_option_that_named_the_folder(tmp_path):
    claim_output_folder(tmp_path / "charts", "sensitivity", {"file": "/a.nc"}, ("sobol_*.png",))
    with pytest.raises(EnsembleFileError, match=r"choose another --plots, or remove"):
        with claimed_output_folder(tmp_path / "charts", "sensitivity", {"file": "/b.nc"}, ("sobol_*.png",),
                                   "--plots"):
            pass
