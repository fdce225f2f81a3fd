"""The acceleration study's pieces on synthetic histories (the study itself runs the contact level
for minutes: docs/study/acceleration_maxima.md), the beam-theory wiring into both FE levels and
rss6 tradeoff's settings."""
import dataclasses

import numpy as np
import pytest

from pipeline.studies.accelerations import (BURSTS, TIMOSHENKO, converged, default_variants, high_pass, main, markdown,
                                            window_maxima)
from pipeline.studies.setting import Setting, _scene_for
from pipeline.studies.tradeoff import default_settings
from rss6core import BeamTheory, natural_frequencies
from rss6core.contact_dynamics import build_joint_model

T = np.arange(2001) * 1e-3


def test_window_maxima_take_only_the_window():
    h = np.zeros((len(T), 6))
    h[100, 0], h[400, 1], h[2000, 2] = -9.0, 2.0, -3.0     # t = 0.1 (start-up), 0.4, 2.0 s
    assert window_maxima(T, h, 0.3).tolist() == [0.0, 2.0, 3.0, 0.0, 0.0, 0.0]
    assert window_maxima(T, h, 0.0, 0.2).tolist() == [9.0, 0.0, 0.0, 0.0, 0.0, 0.0]


def test_high_pass_keeps_a_100_hz_burst_and_drops_the_trajectory_rate():
    slow = 3.0 * np.sin(2 * np.pi * T)                              # 1 Hz, 3 rad/s^2
    burst = np.where(np.abs(T - 1.0) < 0.05, 0.5 * np.sin(2 * np.pi * 100 * T), 0.0)
    h = np.repeat((slow + burst)[:, None], 6, 1)
    fast = high_pass(T, h)
    assert np.abs(fast[(T > 0.1) & (T < 0.8)]).max() < 1e-3          # the 1 Hz part is gone
    # the burst's amplitude, within the 11-sample window's 10 % leak of a 100 Hz sine
    assert window_maxima(T, fast, *BURSTS[0])[4] == pytest.approx(0.5, rel=0.1)


def test_converged_is_the_five_percent_rule_on_medians():
    coarse = np.ones((5, 6))
    fine = coarse * np.array([1.0, 1.04, 0.96, 1.06, 0.94, 1.0])
    assert converged(coarse, fine).tolist() == [True, True, True, False, False, True]


def test_markdown_states_the_verdict_and_the_band():
    rng = np.random.default_rng(0)
    runs = {}
    for v in default_variants((8, 16)):
        scale = 1.03 if v.beam == TIMOSHENKO else 1.0
        runs[v] = {"steady": scale * (1 + 0.01 * rng.random((4, 6))), "bursts": np.ones((4, 2, 6)),
                   "seconds_per_realization": 1.0, "failed": 0, "steady_after": 0.75}
    text = markdown(runs, "paper", 4, 0, "python -m pipeline.studies.accelerations paper -n 4 -o d")
    assert text.startswith("`python -m pipeline.studies.accelerations paper -n 4 -o d`: Scene paper")  # its command
    assert "steady window t >= 0.75 s" in text
    assert "8 -> 16 elements" in text and "converged (within 5 %) in every direction" in text
    assert "model-form band" in text and "ry 3." in text
    assert text.count("| 16 el,") == 5            # three beam models, two of them at half the step


def test_bad_scene_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[beam]\ntheory = "bernoulli"\n')
    assert main([str(bad), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(bad) in err


def test_beam_theory_reaches_both_finite_element_levels(paper):
    timo = dataclasses.replace(paper, beam=TIMOSHENKO)
    eb, ts = natural_frequencies(paper, 4), natural_frequencies(timo, 4)
    # shear and rotary inertia soften the highest (element-scale) modes most: 168 kHz -> 66 kHz
    assert ts[-1] < 0.5 * eb[-1]
    assert ts[0] == pytest.approx(eb[0], rel=0.01) and ts[0] < eb[0]
    assert not np.allclose(build_joint_model(timo, 2).crank_M, build_joint_model(paper, 2).crank_M)


def test_tradeoff_compares_the_other_beam_theory(paper):
    settings, _ = default_settings(paper)
    other = [s for s in settings if s.beam is not None]
    assert {s.model for s in other} == {"elastic", "contact"}
    assert all(s.beam == BeamTheory("timoshenko", True) for s in other)
    assert _scene_for(paper, other[0]).beam == BeamTheory("timoshenko", True)
    assert _scene_for(paper, Setting("elastic", "newmark", 1e-3, 4)) is paper
