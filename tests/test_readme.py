"""The README's Python API example runs as written (in a fresh folder) and does what it says."""
import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_api_example_runs(tmp_path):
    block = re.search(r"## Python API\n\n```python\n(.*?)```", README.read_text(), re.S)
    assert block, "README has no Python API example"
    script = tmp_path / "example.py"
    script.write_text(block.group(1))
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "q95" in proc.stdout and "Traceback" not in proc.stderr
    assert (tmp_path / "smoke_api.nc").is_file() and not (tmp_path / "smoke_api.nc.parts").exists()


def _block_after(text: str, marker: str) -> list[str]:
    """The lines of the first fenced block after ``marker`` in the README."""
    block = re.search(re.escape(marker) + r".*?```\n(.*?)```", text, re.S)
    assert block, f"README has no block after {marker!r}"
    return block.group(1).splitlines()


def _in_order(shown: list[str], printed: list[str]) -> None:
    """Every shown line (but '...') is a printed line, in the printed order."""
    at = 0
    for line in shown:
        if line == "...":
            continue
        assert line in printed[at:], f"README line not printed (in this order): {line!r}"
        at = printed.index(line, at) + 1


def test_readme_main_job_output_is_what_the_command_prints(tmp_path):
    text = README.read_text()
    command = re.search(r"&& (rss6 run paper [^\n]*)\n", text).group(1)
    assert command == "rss6 run paper -n 32 --model quasi-static -o paper_qs.nc"
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *command.split()[1:]], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    _in_order(_block_after(text, "The main job prints"), proc.stdout.splitlines())


def test_readme_error_example_is_what_check_prints(tmp_path, paper_text):
    shown = _block_after(README.read_text(), "exits 130 with the finished chunks kept")
    (tmp_path / "typo.toml").write_text(paper_text.replace("crank_length_m", "crank_lenght_m", 1))
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "check", "typo.toml"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == shown


def test_the_shipped_scenes_cite_sections_that_exist():
    """A scene's comment citing (FILE, "Heading") points at a heading of that file: the configs' citations
    of README sections had outlived the sections (they moved to docs/)."""
    root = README.parent
    text = "\n".join(path.read_text() for path in sorted((root / "configs").glob("*.toml")))
    comments = " ".join(line.split("#", 1)[1].strip() for line in text.splitlines() if "#" in line)
    cited = re.findall(r"\(?(README|docs/[\w.]+\.md), \"([^\"]+)\"", comments)
    assert len(cited) >= 8, cited
    for file, heading in cited:
        path = root / (file + ".md" if file == "README" else file)
        headings = [line.lstrip("#").strip() for line in path.read_text().splitlines() if line.startswith("#")]
        assert any(h.startswith(heading) for h in headings), f"{file} has no section {heading!r}"
