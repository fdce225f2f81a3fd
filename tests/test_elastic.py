"""The KED solver on the robot: assembly, integrators, limits and conservation laws."""
import dataclasses

import numpy as np
import pytest
import scipy.linalg

from rss6core.assembly import (StepSolver, build_elastic_model, dense_matrices, end_maps, frame_coupling_forces,
                               rigid_loads)
from rss6core.elastic import elastic_energy, quasi_static_state, simulate_elastic
from rss6core.integrators import Integrator
from rss6core.kinematics import rigid_motion
from rss6core.models import natural_frequencies
from rss6core.scene import Damping


def _still(scene, duration, dt, gravity=True):
    """The robot held at its home pose, undamped (and weightless unless gravity)."""
    return dataclasses.replace(
        scene, trajectory=dataclasses.replace(scene.trajectory, frequency=0.0, duration=duration),
        simulation=dataclasses.replace(scene.simulation, time_step=dt),
        damping=Damping(0.0, 0.0), gravity=scene.gravity if gravity else 0.0)


@pytest.fixture(scope="module")
def home(paper):
    model = build_elastic_model(paper, 4)
    maps = end_maps(model, rigid_motion(paper, np.array([0.0])), paper.geometry)
    M, K = dense_matrices(model, maps[0])
    return model, maps, M, K


def test_matrices_symmetric_positive_definite(home):
    _, _, M, K = home
    assert np.abs(M - M.T).max() < 1e-12 * np.abs(M).max()
    assert np.abs(K - K.T).max() < 1e-12 * np.abs(K).max()
    assert np.linalg.eigvalsh(M).min() > 0
    # no zero mode left: the rods' spin is removed, the platform is held by six legs
    assert np.linalg.eigvalsh(K).min() > 0


def test_condensed_solver_matches_dense_solve(home):
    model, maps, M, K = home
    rhs = np.random.default_rng(0).normal(size=model.dofs)
    x = StepSolver(model, maps, 4.0e6, 0.3).solve(0, rhs)
    dense = np.linalg.solve(4.0e6 * M + 0.3 * K, rhs)
    assert np.abs(x - dense).max() < 1e-9 * np.abs(dense).max()


def test_lowest_mode_is_the_readmes_91_5_hz(paper):
    """Golden value (README): 91.5 Hz, far above the trajectory's 1 Hz (a quasi-static response)."""
    f = natural_frequencies(paper) / (2 * np.pi)
    assert f[0] == pytest.approx(91.5, rel=1e-2)


def test_static_sag_is_symmetric(paper):
    """Held still under gravity, the 3-fold and mirror-symmetric robot only sinks (and barely turns)."""
    still = _still(paper, 0.002, 0.001)
    r = simulate_elastic(still, 4)
    d = r.displacement[0]
    assert d[2] < -1e-6
    assert np.abs(d[[0, 1, 3, 4, 5]]).max() < 1e-9 * abs(d[2]) / 1e-3


def _free_vibration(paper, integrator, steps=2000, dt=2e-4, lowest_mode=False):
    """Undamped, weightless robot released from a random (or its lowest mode) displacement."""
    still = _still(paper, steps * dt, dt, gravity=False)
    model = build_elastic_model(still, 4)
    _, _, M, K = _home_matrices(still, model)
    if lowest_mode:
        d0 = scipy.linalg.eigh(K, M)[1][:, 0] * 1e-6
    else:
        d0 = np.random.default_rng(1).normal(size=model.dofs) * 1e-6
    z = np.zeros_like(d0)
    a0 = np.linalg.solve(M, -K @ d0)
    r = simulate_elastic(still, 4, integrator, model=model, initial=(d0, z, a0), keep_states=True)
    kin, pot = elastic_energy(still, model, r.t, r.states[0], r.states[1])
    return r, kin + pot


def _home_matrices(scene, model):
    maps = end_maps(model, rigid_motion(scene, np.array([0.0])), scene.geometry)
    return (model, maps) + dense_matrices(model, maps[0])


def test_newmark_average_acceleration_conserves_energy(paper):
    """Undamped free vibration: trapezoidal Newmark keeps 1/2 v'Mv + 1/2 d'Kd to round-off."""
    r, energy = _free_vibration(paper, Integrator.newmark())
    assert r.status == "finished"
    assert np.abs(energy / energy[0] - 1).max() < 1e-9


def test_generalized_alpha_keeps_resolved_and_damps_unresolved_modes(paper):
    """rho_inf = 0.8: the lowest mode (omega h = 0.1) never gains energy (beyond the 1e-5
    ripple of 1/2 v'Mv + 1/2 d'Kd within a period) and loses < 1 % in 2000 steps; a random
    start, dominated by modes with omega h >> 1, loses almost all of it."""
    r, energy = _free_vibration(paper, Integrator.generalized_alpha(0.8), lowest_mode=True)
    assert r.status == "finished"
    assert energy.max() < energy[0] * (1 + 1e-5) and 0.99 < energy[-1] / energy[0] < 1
    r, energy = _free_vibration(paper, Integrator.generalized_alpha(0.8))
    assert r.status == "finished" and energy[-1] < 1e-2 * energy[0]


def _lowest_mode_release(paper, integrator, dt, duration=0.02):
    """Undamped, weightless robot at rest released from its lowest mode: at rest M and K are
    constant, so this is a one-DOF oscillator with the closed form d(t) = phi cos(omega_1 t)."""
    still = _still(paper, duration, dt, gravity=False)
    model = build_elastic_model(still, 4)
    _, _, M, K = _home_matrices(still, model)
    w2, modes = scipy.linalg.eigh(K, M, subset_by_index=[0, 0])
    phi = modes[:, 0] * 1e-6
    z = np.zeros_like(phi)
    r = simulate_elastic(still, 4, integrator, model=model, initial=(phi, z, -w2[0] * phi),
                         keep_states=True)
    exact = np.cos(np.sqrt(w2[0]) * r.t)[:, None] * phi[-6:]
    kin, pot = elastic_energy(still, model, r.t, r.states[0], r.states[1])
    return r, np.abs(r.displacement - exact).max() / np.abs(phi[-6:]).max(), kin + pot, np.sqrt(w2[0])


@pytest.mark.parametrize("method", [Integrator.newmark(), Integrator.hht(0.05), Integrator.hht(1 / 3),
                                    Integrator.generalized_alpha(0.8)],
                         ids=["newmark", "hht-0.05", "hht-1/3", "generalized-alpha-0.8"])
def test_second_order_against_the_closed_form_of_one_mode(paper, method):
    """Release in the lowest mode (91.5 Hz) for 0.02 s: halving h (omega h = 0.23, 0.115, 0.058)
    divides the error against phi cos(omega t) by 4, as a second-order method must."""
    errors = [_lowest_mode_release(paper, method, dt)[1] for dt in (4e-4, 2e-4, 1e-4)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 2) < 0.15), (errors, orders)


def _hht_spectral_radius(alpha: float, omega_h: float) -> float:
    """Largest |eigenvalue| of HHT's one-step map for x'' + omega^2 x = 0 (Hilber, Hughes &
    Taylor 1977): a+ + omega^2 [(1 - alpha) x+ + alpha x] = 0 with Newmark's updates,
    beta = (1 + alpha)^2 / 4, gamma = 1/2 + alpha; state (x, h v, h^2 a)."""
    beta, gamma, w2 = (1 + alpha) ** 2 / 4, 0.5 + alpha, omega_h ** 2
    new = np.array([[1.0, 0.0, -beta], [0.0, 1.0, -gamma], [(1 - alpha) * w2, 0.0, 1.0]])
    old = np.array([[1.0, 1.0, 0.5 - beta], [0.0, 1.0, 1 - gamma], [-alpha * w2, 0.0, 0.0]])
    return float(np.abs(np.linalg.eigvals(np.linalg.solve(new, old))).max())


@pytest.mark.parametrize("alpha", [0.05, 0.2])
def test_hht_dissipates_as_its_spectral_radius_says(paper, alpha):
    """Lowest mode, omega h = 0.115, 2000 steps: the energy follows E0 rho^(2 k), rho from HHT's
    own one-step map (not from rss6's coefficients), within its in-period ripple (< 1e-3, one-
    sided: it never exceeds the envelope), and loses 1 - rho^(2 n) in all to 2 %; a random
    start, dominated by modes with omega h >> 1 where rho -> (1 - alpha)/(1 + alpha), loses ~all."""
    dt = 2e-4
    r, _, energy, omega = _lowest_mode_release(paper, Integrator.hht(alpha), dt, duration=0.4)
    envelope = energy[0] * _hht_spectral_radius(alpha, omega * dt) ** (2 * np.arange(len(r.t)))
    assert r.status == "finished"
    assert np.all(energy <= envelope * (1 + 1e-5)) and np.all(energy >= envelope * (1 - 1e-3))
    loss, predicted = 1 - energy[-1] / energy[0], 1 - envelope[-1] / energy[0]
    assert loss == pytest.approx(predicted, rel=2e-2) and predicted > 1e-2 * alpha
    r, energy = _free_vibration(paper, Integrator.hht(alpha))
    assert r.status == "finished" and energy[-1] < 1e-2 * energy[0]


@pytest.mark.parametrize("factor, stable", [(0.97, True), (1.03, False)])
def test_central_difference_critical_step(paper, factor, stable):
    """Explicit method: stable just below 2/omega_max, diverges just above (within 5 %)."""
    h = factor * 2.0 / natural_frequencies(paper, 4)[-1]
    still = _still(paper, 3000 * h, h, gravity=False)
    model = build_elastic_model(still, 4)
    _, _, M, K = _home_matrices(still, model)
    d0 = np.random.default_rng(2).normal(size=model.dofs) * 1e-9
    a0 = np.linalg.solve(M, -K @ d0)
    r = simulate_elastic(still, 4, Integrator.central_difference(), model=model,
                         initial=(d0, np.zeros_like(d0), a0), divergence_limit=1e-3)
    assert (r.status == "finished") is stable
    if stable:
        assert np.nanmax(np.abs(r.displacement)) < 10 * np.abs(d0).max()


@pytest.mark.parametrize("method", [Integrator.newmark(), Integrator.generalized_alpha(0.8)])
def test_measured_convergence_order_is_two(smoke, method):
    """Error at the common instants against a 32x finer run; halving dt divides it by ~4."""
    ref = simulate_elastic(smoke, 4, method, dt=3.125e-5).displacement
    errors = []
    for dt in (1e-3, 5e-4, 2.5e-4):  # above 1 ms the 90-200 Hz modes are not yet resolved
        stride = int(round(dt / 3.125e-5))
        errors.append(np.abs(simulate_elastic(smoke, 4, method, dt=dt).displacement
                             - ref[::stride]).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 2) < 0.3), orders


def test_mesh_convergence_of_platform_error(paper):
    """1, 2, 4, 8 elements per link: the default (4) is within 0.01 % of 8 in every direction."""
    peak = {n: np.abs(simulate_elastic(paper, n).displacement).max(0) for n in (1, 2, 4, 8)}
    change = {n: np.abs(peak[n] / peak[8] - 1).max() for n in (1, 2, 4)}
    assert change[4] < 1e-4
    assert change[4] <= change[2] <= change[1] + 1e-12


def test_frame_coupling_terms_are_negligible(paper):
    """Eq. 26's 2 B'M B' U' and B'M B'' U, applied as loads, move the platform < 0.1 % of its error."""
    model = build_elastic_model(paper, 4)
    r = simulate_elastic(paper, 4, model=model, keep_states=True)
    motion = rigid_motion(paper)
    f = frame_coupling_forces(model, motion, paper, r.states[0])
    assert np.abs(f).max() < 1e-4 * np.abs(rigid_loads(model, motion, paper)).max()
    # far below resonance the response to a load is quasi-static: K^-1 f
    stiff = StepSolver(model, end_maps(model, motion, paper.geometry), 0.0, 1.0)
    u = np.stack([stiff.solve(k, f[k]) for k in range(len(motion.t))])[:, -6:]
    assert np.all(np.abs(u).max(0) < 1e-3 * np.abs(r.displacement).max(0))


def test_paper_elastic_peaks_are_the_readmes(paper):
    """Golden values (README table, `rss6 simulate paper --model elastic`): peak |error| per
    direction, 0.00045, 0.0056, 0.0293 mm and 4.4e-5, 6.0e-5, 9.1e-6 rad, to about 1 %."""
    r = simulate_elastic(paper, 4)
    peak = np.abs(r.displacement).max(0)
    assert r.status == "finished"
    assert peak[2] == pytest.approx(0.0293e-3, rel=1e-2)          # the vertical sag, m
    assert peak == pytest.approx([0.00045e-3, 0.0056e-3, 0.0293e-3, 4.4e-5, 6.0e-5, 9.1e-6],
                                 rel=1.5e-2)                      # two-digit values: rounding


def _outside_before(scene, t_start):
    """The scene's rigid motion, as if the trajectory left the workspace before t_start (NaN there)."""
    def motion(t):
        m = rigid_motion(scene, t)
        before = np.asarray(t) < t_start
        return dataclasses.replace(m, **{f.name: np.where(before.reshape((-1,) + (1,) * (getattr(m, f.name).ndim - 1)),
                                                         np.nan, getattr(m, f.name))
                                         for f in dataclasses.fields(m) if f.name != "platform"})
    return motion


def test_a_start_on_the_workspace_border_takes_one_sided_differences(paper):
    """Where the trajectory continued before t0 leaves the workspace, the initial state's v and a
    come from t0..t0 + 3h (second order) and match the central differences' to O(h^2)."""
    model, t0 = build_elastic_model(paper, 4), 0.3
    central = quasi_static_state(paper, model, t0)
    one_sided = quasi_static_state(paper, model, t0, motion=_outside_before(paper, t0))
    # v and a: the stencils divide the solves' round-off by h = 1e-4 s and h^2
    for name, c, o, rel in zip("dva", central, one_sided, (1e-7, 1e-5, 1e-4)):
        assert np.all(np.isfinite(o)), name
        assert np.max(np.abs(o - c)) <= rel * np.max(np.abs(c)), name
    lowered = dataclasses.replace(paper, trajectory=dataclasses.replace(
        paper.trajectory, offset=paper.trajectory.offset + np.array([0.0, 0.0, -0.3157, 0.0, 0.0, 0.0])))
    d, v, a = quasi_static_state(lowered, model, 0.0)   # its continuation before t = 0 is unreachable
    assert np.isfinite(rigid_motion(lowered, np.array([0.0])).alpha).all()
    assert not np.isfinite(rigid_motion(lowered, np.array([-1e-4])).alpha).all()
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))
