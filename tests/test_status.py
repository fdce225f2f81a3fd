"""Every level reports failure with one status vocabulary and one message format (rss6core.status)."""
import dataclasses
import re

import numpy as np
import pytest

from rss6core.clearance import draw_clearances
from rss6core.contact_dynamics import CompiledStepper, simulate_contact
from rss6core.contact_numpy import NumpyStepper
from rss6core.models import simulate
from rss6core.status import FAILED, FINISHED, check_history, failure_message

# "<what> at t = <t> s, step <k>, with a <h> s step"
FORMAT = re.compile(r"^(?P<what>.+) at t = (?P<t>[-+.e0-9]+) s, step (?P<step>\d+), "
                    r"with a (?P<h>[-+.e0-9]+) s step$")


def _with(scene, **tables):
    return dataclasses.replace(scene, **{name: dataclasses.replace(getattr(scene, name), **fields)
                                         for name, fields in tables.items()})


def _parts(message):
    m = FORMAT.match(message)
    assert m, f"not in the common format: {message!r}"
    return m["what"], float(m["t"]), int(m["step"]), float(m["h"])


def test_failure_message_wording():
    assert failure_message("x diverged", 0.001, 5, 0.001) == "x diverged at t = 0.001 s, step 5, with a 0.001 s step"


@pytest.mark.parametrize("dt", [1e-3, 4e-4])
def test_rigid_level_reports_as_a_level_that_steps(smoke, dt):
    """The rigid level takes no step (its error is zero by definition) yet reports in the common
    vocabulary as the elastic level, which does step, reports the same run: the same output times,
    status, message and step count at the scene's step and at another; and its zero history is what
    the common check (check_history) finds finished in as many steps."""
    rigid, elastic = simulate(smoke, "rigid", dt=dt), simulate(smoke, "elastic", dt=dt)
    assert elastic.status == FINISHED
    assert np.array_equal(rigid.t, elastic.t) and rigid.t[1] == pytest.approx(dt)
    assert (rigid.status, rigid.message, rigid.steps) == (elastic.status, elastic.message, elastic.steps)
    outcome = check_history(rigid.displacement, rigid.t, "rigid")
    assert (rigid.status, rigid.message, rigid.steps) == (outcome.status, outcome.message, outcome.steps)
    assert not any(np.any(q) for q in (rigid.displacement, rigid.velocity, rigid.acceleration))


@pytest.mark.parametrize("model", ["quasi-static", "paper"])
def test_clearances_beyond_any_linearisation_fail_the_algebraic_levels(smoke, model):
    """2 m clearances put the linearised closure's error far beyond the 1 m divergence limit."""
    huge = _with(smoke, clearance=dict(revolute_radial=2.0, revolute_axial=2.0, spherical_C=2.0,
                                       spherical_B=2.0), trajectory=dict(duration=0.02))
    r = simulate(huge, model)
    assert r.status == FAILED
    what, t, step, h = _parts(r.message)
    assert "displacement error" in what and "exceeds the 1 m divergence limit" in what
    assert (t, step, h) == (0.0, 0, 1e-3)
    assert np.abs(r.displacement[0]).max() > 1.0


@pytest.mark.parametrize("model", ["elastic", "paper"])
def test_an_explicit_step_far_beyond_the_critical_one_fails_the_dynamic_levels(smoke, model):
    """Central differences at 1 ms, about 500 times the critical step: the elastic run blows up; the
    paper level inherits its failure, same words."""
    r = simulate(_with(smoke, trajectory=dict(duration=0.05)), model, integrator="central-difference")
    assert r.status == FAILED
    what, t, step, h = _parts(r.message)
    assert what.startswith("elastic displacement ") and "exceeds the 1 m divergence limit" in what
    assert h == 1e-3 and step >= 1 and t == pytest.approx(step * h)
    assert r.steps == step - 1
    assert np.all(np.isnan(r.displacement[step:]))


@pytest.mark.parametrize("stepper", [CompiledStepper, NumpyStepper], ids=["compiled", "numpy"])
def test_contact_level_divergence_and_newton_failure_in_the_common_format(smoke, stepper, monkeypatch):
    import rss6core.contact_dynamics as cd
    scene = _with(smoke, trajectory=dict(duration=0.01))
    draws = [draw_clearances(scene, 0, r) for r in range(2)]
    run = simulate_contact(scene, draws, divergence_limit=1e-9, stepper=stepper)
    assert run.status == [FAILED] * 2
    for m in run.message:
        what, t, step, h = _parts(m)
        assert what.startswith("displacement ") and "exceeds the 1e-09 m divergence limit" in what
        assert (t, step, h) == (1e-4, 1, 1e-4)
    monkeypatch.setattr(cd, "MAX_ITERATIONS", 0)       # no Newton update: no step converges
    run = simulate_contact(scene, draws, stepper=stepper)
    assert run.status == [FAILED] * 2
    for m in run.message:
        what, t, step, h = _parts(m)
        assert what == "Newton on the contact forces did not converge in 0 iterations"
        assert (t, step, h) == (1e-4, 1, 1e-4)


@pytest.mark.parametrize("value, step", [(1.0 - 1e-16, None), (1.0, 3), (np.inf, 3), (np.nan, 3), (-1.0, 3)])
def test_check_history_fails_at_the_first_sample_that_reaches_the_limit_or_is_not_finite(value, step):
    """One sample of a small history set to ``value`` against the 1 m limit: just below it the run
    is finished in every step; on the limit, beyond it, infinite or NaN it fails there (the
    contiguous shortcut for finished histories, docs/performance.md section 29, decides as the
    per-sample test)."""
    t = np.arange(8) * 1e-3
    d = np.full((8, 6), 1e-6)
    d[4, 2] = value
    outcome = check_history(d, t, "test", limit=1.0)
    status, steps = outcome.status, outcome.steps
    assert (status, steps) == ((FINISHED, 7) if step is None else (FAILED, step))
