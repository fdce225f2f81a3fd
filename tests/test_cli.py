"""End-to-end: the rss6 command line as a user calls it."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.cli import main
from tests.conftest import CONFIGS


def test_check_json_paper(capsys):
    assert main(["check", str(CONFIGS / "paper.toml"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["home_crank_angles_deg"] == pytest.approx([-5.02] * 6, abs=0.01)
    assert len(out["crank_angle_range_deg"]) == 6
    assert all(lo < -5.02 < hi for lo, hi in out["crank_angle_range_deg"])
    assert len(out["max_actuator_torque_Nm"]) == 6 and min(out["max_actuator_torque_Nm"]) > 0
    assert set(out["link_masses_kg"]) == {"crank", "rod", "platform"}


def test_check_text_names_the_scene(capsys):
    assert main(["check", "smoke"]) == 0
    assert "scene 'smoke'" in capsys.readouterr().out


def test_bad_config_is_a_usage_error(tmp_path, capsys):
    bad = tmp_path / "typo.toml"
    bad.write_text((CONFIGS / "paper.toml").read_text().replace("mass_kg", "mas_kg"))
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "typo.toml" in err and "mas_kg" in err and "Traceback" not in err


def test_console_script_is_installed():
    script = Path(sys.executable).parent / "rss6"
    assert script.exists(), f"no rss6 console script beside {sys.executable}; pip install -e ."
    proc = subprocess.run([str(script), "check", "paper", "--json"],
                          capture_output=True, text=True, check=True)
    assert json.loads(proc.stdout)["scene"] == "paper"
