"""The paper level's and the pipeline's shortcuts (docs/performance.md section 15b) against the
straightforward computations they replace: the same bits, or the same values where eq. 17 acts."""
import dataclasses

import numpy as np
import pytest

from pipeline.files.reading import load_netcdf
from pipeline.files.records import chunk_dataset, window_masks, window_reductions
from pipeline.files.writing import write_netcdf
from rss6core import SimulationResult
from rss6core.clearance import _uniform, draw_clearances, realization_rng, sphere_directions
from rss6core.contact_laws import hertz_stiffness, lankarani_nikravesh, poisson_ratio
from rss6core.paper_method import PaperClosure, _inside, paper_contact_forces, paper_draw
from rss6core.quasi_static import CENTRAL_PAD, time_derivatives


def test_draws_equal_the_broadcast_formulas():
    """The sphere directions (compiled, rss6core/draw_kernel.py) equal the broadcast expressions
    they replace: the polar cosine bit for bit, the azimuth's cosine and sine to round-off (the
    kernel's are not glibc's; e_A: tests/test_draw_kernel.py)."""
    rng = realization_rng(0, 7)
    direct = sphere_directions(rng, 500)
    rng = realization_rng(0, 7)
    u1, u2 = rng.uniform(size=500), rng.uniform(size=500)
    z, eta2 = 1.0 - 2.0 * u1, 2.0 * np.pi * u2
    sin1 = np.sqrt((1.0 - z) * (1.0 + z))
    broadcast = np.stack([sin1 * np.cos(eta2), sin1 * np.sin(eta2), z], -1)
    assert direct[:, 2].tobytes() == broadcast[:, 2].tobytes()
    assert np.abs(direct - broadcast).max() <= 1e-15


@pytest.mark.parametrize("low, high", [(0.0, 1.0), (0.0, 2.0 * np.pi), (0.3e-3, 0.7e-3), (-1e-4, 1e-4)])
def test_a_generators_uniforms_are_those_of_generator_uniform_bit_for_bit(low, high):
    """_uniform takes a Generator's doubles from random() and scales them itself: the values and
    the stream after them are those of Generator.uniform(low, high) (docs/performance.md section 29)."""
    ours, theirs = realization_rng(3, 9), realization_rng(3, 9)
    got = _uniform(ours, "A_radial_angle", low, high, size=(2001, 6))
    assert got.tobytes() == theirs.uniform(low, high, size=(2001, 6)).tobytes()
    assert ours.uniform(size=5).tobytes() == theirs.uniform(size=5).tobytes()


def test_spherical_eccentricities_equal_the_broadcast_product_bit_for_bit(paper):
    """e_C and e_B of a per-step draw, scaled one component at a time, are (k_s delta_s)[..., None]
    times the sphere directions of the same uniforms, bit for bit (docs/performance.md section 29)."""
    steps = 37
    draw = draw_clearances(paper, 0, 5, steps=steps)
    rng = realization_rng(0, 5)
    rng.uniform(size=24 + 3 * 6 * steps)             # the sizes, then radial, angle and axial of A
    for joint, got, size in (("C", draw.e_C, draw.size_C), ("B", draw.e_B, draw.size_B)):
        magnitude = rng.uniform(size=(steps, 6)) * size
        direction = sphere_directions(rng, 6 * steps, paper.sampling.direction, joint).reshape(steps, 6, 3)
        assert got.tobytes() == (magnitude[..., None] * direction).tobytes(), joint


def _eq17(scene, draw, dt):
    """Eq. 17's force history (T, 18) N written out on the padded draw, without any shortcut."""
    w = scene.geometry.w
    e_r = draw.e_A - np.einsum("tli,li->tl", draw.e_A, w)[..., None] * w
    rho = np.concatenate([np.linalg.norm(e, axis=-1) for e in (e_r, draw.e_C, draw.e_B)], -1)
    size = np.concatenate([draw.radial_size, draw.size_C, draw.size_B])
    ct, mat = scene.contact, scene.material
    nu = poisson_ratio(mat.youngs_modulus, mat.shear_modulus)
    radius = np.repeat([ct.journal_radius, ct.sphere_radius, ct.sphere_radius], 6)
    K = ct.stiffness_scale * hertz_stiffness(radius, radius + size, mat.youngs_modulus, nu, mat.youngs_modulus, nu)
    rate = np.gradient(rho, dt, axis=0)[CENTRAL_PAD:-CENTRAL_PAD]
    rho = rho[CENTRAL_PAD:-CENTRAL_PAD]
    impact = np.maximum(rate.max(axis=0), ct.impact_speed_floor)
    return lankarani_nikravesh(rho - size, rate, impact, K, ct.exponent, ct.restitution)[0]


@pytest.mark.parametrize("scale", [None, 1.0 - 1e-12, 1.0, 1.02])
def test_paper_contact_forces_skip_eq17_only_where_nothing_penetrates(paper, scale):
    """Drawn eccentricities (inside), ones pushed to within rounding of the wall or onto it (where
    rounding decides whether |e| - size is positive), and ones pushed 2 % beyond it: the forces are
    eq. 17's in every case (zero only inside)."""
    draw = paper_draw(paper, 0, 2, 600)
    if scale is not None:   # every spherical C eccentricity to `scale` times its clearance
        unit = draw.e_C / np.linalg.norm(draw.e_C, axis=-1, keepdims=True)
        draw = dataclasses.replace(draw, e_C=unit * (scale * draw.size_C)[:, None])
    got, want = paper_contact_forces(paper, draw, 1e-3), _eq17(paper, draw, 1e-3)
    assert got.shape == want.shape == (600, 18)
    np.testing.assert_array_equal(got, want)
    assert (want[:, 6:12] > 0).all() == (scale is not None and scale > 1.0)
    assert (want[:, 6:12] > 0).any() == (scale is not None and scale >= 1.0)   # on the wall: some


def test_paper_contact_forces_take_the_scenes_stiffness_scale(paper):
    """[contact] stiffness_scale = 2 doubles eq. 17's forces of spherical joints pushed 2 % beyond their
    clearance, to the last bit (K enters linearly; a power of two scales exactly): the paper level's
    contact stiffness is the contact level's (contact_laws.joint_stiffness), scale and all."""
    stiff = dataclasses.replace(paper, contact=dataclasses.replace(paper.contact, stiffness_scale=2.0))
    draw = paper_draw(paper, 0, 2, 200)
    unit = draw.e_C / np.linalg.norm(draw.e_C, axis=-1, keepdims=True)
    draw = dataclasses.replace(draw, e_C=unit * (1.02 * draw.size_C)[:, None])
    plain = paper_contact_forces(paper, draw, 1e-3)
    assert (plain[:, 6:12] > 0).all()
    np.testing.assert_array_equal(paper_contact_forces(stiff, draw, 1e-3), 2.0 * plain)


def test_window_reductions_of_scattered_samples_are_those_of_the_samples():
    """A window whose samples are not consecutive is reduced over exactly those samples."""
    err = np.random.default_rng(1).normal(size=(3, 9, 6))
    masks = np.array([[True, False, True, True, False, False, True, False, False],
                      [False, True, True, True, True, False, False, False, False]])
    peak, mean = window_reductions(err, masks)
    for k, mask in enumerate(masks):
        np.testing.assert_array_equal(peak[k], np.abs(err[:, mask]).max(axis=1))
        np.testing.assert_allclose(mean[k], np.abs(err[:, mask]).mean(axis=1), rtol=1e-15)


@pytest.mark.parametrize("scale", [1.0 - 1e-12, 1.0, 1.02])
def test_paper_contact_forces_see_a_revolute_pushed_radially_onto_its_wall(paper, scale):
    """The revolute's radial part (off its axis w) pushed to within rounding of the radial clearance,
    onto it and 2 % beyond, its axial part kept, one leg at a time: the forces are eq. 17's (the inside test forms the
    radial part from strided components, docs/performance.md section 29)."""
    draw = paper_draw(paper, 0, 3, 400)
    w = paper.geometry.w
    axial = np.einsum("tli,li->tl", draw.e_A, w)[..., None] * w
    radial = draw.e_A - axial
    unit = radial / np.linalg.norm(radial, axis=-1, keepdims=True)
    for leg in range(6):   # one leg at a time: the inside test must see that leg alone
        e_A = draw.e_A.copy()
        e_A[:, leg] = unit[:, leg] * scale * draw.radial_size[leg] + axial[:, leg]
        pushed = dataclasses.replace(draw, e_A=e_A)
        got, want = paper_contact_forces(paper, pushed, 1e-3), _eq17(paper, pushed, 1e-3)
        np.testing.assert_array_equal(got, want)
        assert (want[:, leg] > 0).all() == (scale > 1.0) and not want[:, 6:].any()
        size = np.concatenate([draw.radial_size, draw.size_C, draw.size_B])
        assert not _inside(pushed, w, size)            # within the margin, on the wall or beyond it
        e_A[:, leg] = unit[:, leg] * 0.999 * draw.radial_size[leg] + axial[:, leg]
        assert _inside(dataclasses.replace(draw, e_A=e_A), w, size)   # clearly inside: the shortcut


def test_the_inside_test_sees_one_spherical_joint_at_one_output_step_and_not_the_pads(paper):
    """Each spherical joint (C and B, every leg) pushed onto its clearance at a single step: the first
    and last output steps and one between make the draw not inside; the same push at a pad step (beyond
    the output steps, read only by the differences) leaves it inside, and a NaN is never inside."""
    draw = paper_draw(paper, 0, 5, 50)
    w, pad = paper.geometry.w, CENTRAL_PAD
    size = np.concatenate([draw.radial_size, draw.size_C, draw.size_B])
    assert _inside(draw, w, size)
    for name, offset in (("e_C", 6), ("e_B", 12)):
        for leg in range(6):
            for step, inside in ((pad, False), (pad + 20, False), (pad + 49, False), (pad - 1, True), (pad + 50, True)):
                e = getattr(draw, name).copy()
                e[step, leg] *= (1.0 - 1e-12) * size[offset + leg] / np.linalg.norm(e[step, leg])
                assert _inside(dataclasses.replace(draw, **{name: e}), w, size) == inside, (name, leg, step)
    e = draw.e_B.copy()
    e[pad + 7, 3, 1] = np.nan
    assert not _inside(dataclasses.replace(draw, e_B=e), w, size)


def _nan_aware_reductions(err, masks):
    """The window maxima and means of |err| written out with NaN masking, in the history's own
    layout (the reductions before section 34)."""
    e = [np.abs(err)[:, mask] for mask in masks]
    return (np.stack([np.max(np.where(np.isfinite(x), x, -np.inf), axis=1) for x in e]),
            np.stack([np.nanmean(x, axis=1) for x in e]))


@pytest.mark.parametrize("steps", [9, 2001])
def test_window_reductions_of_finite_histories_equal_the_nan_aware_ones(steps):
    """A finished run's history (no NaN) takes the short path: its maxima are those of the NaN-aware
    reductions bit for bit, its means to a few units in the last place (pairwise sums along time
    against row by row), over the windows of window_masks (docs/performance.md sections 29 and 34);
    a history with a NaN keeps the general path's answer."""
    t = np.arange(steps) / (steps - 1)
    masks = window_masks(t, 0.1, 0.5)
    err = np.random.default_rng(steps).normal(size=(3, steps, 6)) * np.logspace(-9, 3, 6)
    peak, mean = window_reductions(err, masks)
    want_peak, want_mean = _nan_aware_reductions(err, masks)
    assert peak.tobytes() == want_peak.tobytes()
    np.testing.assert_allclose(mean, want_mean, rtol=1e-14, atol=0)
    with np.errstate(invalid="ignore"):
        assert np.array_equal(window_reductions(np.where(err > 3e3, np.nan, err), masks)[1][:, 0, :5],
                              mean[:, 0, :5])   # the general path sums as the short one where no NaN is
    err[1, steps // 2, 3] = np.nan
    peak, mean = window_reductions(err, masks)
    want_peak, want_mean = _nan_aware_reductions(err, masks)
    np.testing.assert_array_equal(peak, want_peak)
    np.testing.assert_allclose(mean, want_mean, rtol=1e-14, atol=0)   # NaN where the reference has one


def test_the_paper_closure_map_is_the_leg_closure_solved_step_by_step(paper):
    """PaperClosure.error's precomputed map G^-1 [(n . x_c) x_c, -x_r] applied to a draw equals the
    linearised closure G dp = (n . x_c) dl_ac - dl_cb solved at every step (eq. 33), to round-off."""
    t = paper.times[:300]
    closure = PaperClosure(paper, t)
    draw = paper_draw(paper, 1, 4, len(t))
    dl_ac, dl_cb = closure.virtual_lengths(draw)
    solved = np.linalg.solve(closure.G, (closure.n_dot_xc * dl_ac - dl_cb)[..., None])[..., 0]
    for got, want in zip(closure.error(draw), time_derivatives(solved, closure.t, CENTRAL_PAD)):
        assert np.abs(got - want).max() < 1e-14 * np.abs(want).max()
        assert np.abs(want).max() > 0


def _result(t, seed, peak=None):
    hist = np.random.default_rng(seed).normal(size=(3, len(t), 6))
    return SimulationResult(t, *hist, "finished", "", len(t) - 1, contact_force_peak=peak)


def test_a_chunk_is_its_realisations_one_by_one(paper):
    """chunk_dataset over three realisations equals it over each alone, stacked; a realisation
    without contact forces among others that have them gets NaN."""
    t = np.arange(11) * 0.1
    results = [_result(t, 0, np.arange(18.0)), _result(t, 1), _result(t, 2, -np.arange(18.0))]
    draws = [draw_clearances(paper, 0, r) for r in range(3)]
    chunk = chunk_dataset(results, draws, [4, 5, 6], "full", 0.2, 0.5)
    for k, r in enumerate((4, 5, 6)):
        alone = chunk_dataset([results[k]], [draws[k]], [r], "full", 0.2, 0.5)
        for name in ("max_abs_error", "mean_abs_error", "eccentricity", "clearance_size", "error"):
            assert chunk[name].sel(realization=[r]).equals(alone[name]), name
    force = chunk["max_contact_force"].values
    assert np.isnan(force[1]).all() and (force[[0, 2]] == [np.arange(18.0), -np.arange(18.0)]).all()
    np.testing.assert_array_equal(chunk["realization"], [4, 5, 6])
    assert window_masks(t, 0.2, 0.5).sum(axis=1).tolist() == [9, 3, 6]


def test_a_lazy_ensemble_keeps_only_its_histories_on_disk(paper, tmp_path):
    """load_netcdf(lazy=True): the histories as dask arrays in blocks of realisations, every other
    variable in memory, and the values those of an eager read."""
    from pipeline.ensemble.run import EnsembleSpec, run_chunk
    spec = EnsembleSpec(paper.source_text, "paper.toml", "quasi-static", "newmark", 0.01, 2, 0,
                        store="full")
    write_netcdf(run_chunk(spec, [0, 1, 2]), tmp_path / "q.nc")
    lazy, eager = load_netcdf(tmp_path / "q.nc", lazy=True), load_netcdf(tmp_path / "q.nc")
    assert lazy["error"].chunks is not None and lazy["error"].chunks[0] == (3,)
    assert all(lazy[name].chunks is None for name in lazy.variables if name != "error")
    assert lazy.load().identical(eager)
