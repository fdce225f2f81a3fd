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
    assert (tmp_path / "smoke_qs.nc").is_file() and not (tmp_path / "smoke_qs.nc.parts").exists()
