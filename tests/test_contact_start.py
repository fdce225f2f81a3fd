"""The contact level's equilibrium start (rss6core/contact_start.py): force balance, agreement with the
quasi-static reaction level, reproducibility, and no start-up impact."""
import dataclasses

import numpy as np
import pytest

from rss6core import draw_clearances, parse_scene
from rss6core.contact_dynamics import CompiledStepper, _joints, build_joint_model, simulate_contact
from rss6core.contact_numpy import NumpyStepper
from rss6core.contact_start import (RESIDUAL_TOLERANCE, _penetrated, contact_initial_state, equilibrium_state,
                                    static_residual)
from rss6core.elastic import quasi_static_state
from rss6core.kinematics import rigid_motion
from rss6core.quasi_static import closure_matrix, quasi_static_error


def _batch(scene, n=3, seed=0):
    jm = build_joint_model(scene, scene.simulation.elements_per_link)
    return jm, _joints(scene, [draw_clearances(scene, seed, r) for r in range(n)])


def _frictionless(scene):
    return dataclasses.replace(scene, contact=dataclasses.replace(scene.contact, friction_coefficient=0.0))


def _with_start(scene, start):
    return dataclasses.replace(scene, simulation=dataclasses.replace(scene.simulation, contact_start=start))


@pytest.mark.parametrize("friction", [True, False])
def test_equilibrium_balances_the_t0_loads(smoke, friction):
    """M a(0) = F - C v - K d + g, assembled on the full (uncondensed) link vectors, vanishes to the
    solver's tolerance at the equilibrium; the drawn start is out of balance by newtons."""
    scene = smoke if friction else _frictionless(smoke)
    jm, joints = _batch(scene)
    st = equilibrium_state(scene, jm, joints)
    assert all(m == "" for m in st.message)
    load = np.abs(static_residual(scene, jm, joints, np.zeros_like(st.d), st.v)).max()   # |F - C v|
    imbalance = np.abs(static_residual(scene, jm, joints, st.d, st.v)).max(-1)
    assert np.all(imbalance <= 20 * RESIDUAL_TOLERANCE * load)    # round-off of the uncondensed sum
    drawn = contact_initial_state(scene, jm, joints)
    drawn_imbalance = np.abs(static_residual(scene, jm, joints, drawn.d, drawn.v)).max(-1)
    print(f"force imbalance at t = 0 (friction {friction}): drawn {drawn_imbalance.max():.3g} N, "
          f"equilibrium {imbalance.max():.2g} N after {st.iterations.max()} Newton iterations")   # pytest -s: docs
    assert np.all(drawn_imbalance > 1e6 * imbalance)


def test_frictionless_equilibrium_is_the_reaction_level_plus_penetration(smoke):
    """Without friction the t = 0 platform error, less the ideal-joint elastic sag, is the linearised
    closure of the reaction eccentricities pushed into their walls by the Hertz penetration of their
    rigid loads: within 2 % per direction (the links' contact-loaded deformation and the exact
    contact forces against the rigid ones); and within 3 % of the reaction level itself (the
    penetration moves rx and rz by ~2.3 % on the smoke scene)."""
    scene = _frictionless(smoke)
    jm, joints = _batch(scene)
    st = equilibrium_state(scene, jm, joints)
    sag = quasi_static_state(scene, jm.elastic, 0.0)[0][-6:]
    G, n = closure_matrix(rigid_motion(scene, np.array([0.0])))
    deep = _penetrated(scene, joints)
    motion = rigid_motion(scene, np.array([0.0, 1e-3, 2e-3]))
    for k in range(len(st.d)):
        eq = st.d[k, -6:] - sag
        closure = np.linalg.solve(G[0], np.einsum("li,li->l", n[0], deep.e_A[k] + deep.e_C[k] - deep.e_B[k]))
        assert np.all(np.abs(eq - closure) <= 0.02 * np.abs(closure))
        draw = draw_clearances(scene, 0, k)
        reaction = quasi_static_error(scene, motion, draw, "reaction")[0][0]
        assert np.all(np.abs(eq - reaction) <= 0.03 * np.abs(reaction))


def test_equilibrium_is_reproducible_and_batch_independent(smoke):
    jm, joints = _batch(smoke, n=3, seed=7)
    a = equilibrium_state(smoke, jm, joints)
    b = equilibrium_state(smoke, jm, joints)
    np.testing.assert_array_equal(a.d, b.d)
    _, one = _batch(smoke, n=1, seed=7)
    np.testing.assert_allclose(equilibrium_state(smoke, jm, one).d[0], a.d[0], rtol=0, atol=1e-15)


def test_a_bad_contact_start_is_a_one_line_scene_error(smoke):
    text = smoke.source_text.replace('quasi_static_eccentricity = "drawn"',
                                     'quasi_static_eccentricity = "drawn"\ncontact_start = "rest"')
    with pytest.raises(ValueError) as err:
        parse_scene(text, "bad.toml")
    assert "contact_start" in str(err.value) and "\n" not in str(err.value)
    assert parse_scene(text.replace('"rest"', '"equilibrium"'), "ok.toml").simulation.contact_start == \
        "equilibrium"


@pytest.mark.slow
def test_equilibrium_start_has_no_startup_impact(smoke):
    """Same realisations, both engines: the equilibrium start's acceleration error maximum over the
    first 50 ms is at most a tenth of the drawn start's, its a(0) is ~0, and the numpy and compiled
    engines start from the same state."""
    draws = [draw_clearances(smoke, 0, r) for r in range(2)]
    first = {}
    for start in ("drawn", "equilibrium"):
        batch = simulate_contact(_with_start(smoke, start), draws, stepper=CompiledStepper,
                                 initial=contact_initial_state)
        early = batch.t <= 0.05 + 1e-12
        first[start] = np.abs(batch.acceleration[:, early]).max((1, 2))
        if start == "equilibrium":
            assert np.abs(batch.acceleration[:, 0]).max() < 1e-6
            ref = simulate_contact(_with_start(smoke, start), draws, stepper=NumpyStepper,
                                   initial=contact_initial_state)
            np.testing.assert_allclose(ref.displacement[:, 0], batch.displacement[:, 0], rtol=0, atol=1e-15)
    assert np.all(first["equilibrium"] <= 0.1 * first["drawn"])


def test_cli_start_is_checked_before_work_and_shown_by_check(capsys):
    from pipeline.cli import main
    with pytest.raises(SystemExit) as stop:
        main(["simulate", "smoke", "--model", "contact", "--start", "rest"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--start" in err and "'rest'" in err
    assert main(["check", "smoke"]) == 0
    assert "start drawn" in capsys.readouterr().out


def test_an_unconverged_equilibrium_is_a_one_line_failure(smoke, monkeypatch):
    import rss6core.contact_start as cs
    monkeypatch.setattr(cs, "MAX_ITERATIONS", 3)     # ~28 are needed with friction
    jm, joints = _batch(smoke, n=1)
    message = cs.equilibrium_state(smoke, jm, joints).message[0]
    assert "static contact equilibrium did not converge in 3 Newton iterations" in message
    assert "at t = 0 s, step 0" in message and "\n" not in message
