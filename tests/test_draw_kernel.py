"""The compiled clearance draw (rss6core/draw_kernel.py) against the numpy arithmetic it replaced,
kept here as an independent reference: the same uniforms in the same order give the same sizes, bit
for bit, and the same eccentricities to round-off (the kernel's sines and cosines of a turn are not
glibc's: docs/performance.md sections 30 and 34); the turn's sine and cosine against long double."""
import dataclasses

import numpy as np
import pytest
from scipy.special import ndtr, ndtri

from rss6core import load_scene
from rss6core.clearance import (SIZE_BLOCKS, UNIFORM_BLOCKS, ClearanceDraw, clearances_from_named_uniforms,
                                clearances_from_uniforms, draw_clearances, realization_rng, size_band,
                                truncated_normal, uniform_dimension)
from rss6core.paper_method import CENTRAL_PAD, END_TAG, paper_draw

SCENES = ("paper", "smoke", "paper_tolerance", "paper_manufacturing", "pick_place")


def _normal(u, mean, std, low, high):
    """The truncated normal by numpy and scipy (a point law: None for u)."""
    mean, std = np.asarray(mean, float), np.asarray(std, float)
    if np.any(std <= 0):
        return np.clip(np.broadcast_to(mean, np.shape(u) if u is not None else mean.shape), low, high).astype(float)
    lo, hi = ndtr((np.asarray(low) - mean) / std), ndtr((np.asarray(high) - mean) / std)
    return np.clip(mean + std * ndtri(lo + u * (hi - lo)), low, high)


def _reference(scene, u, steps):
    """The draw of docs/model.md section 4 from the uniform vector u (in stream order), by numpy's
    broadcasting: the arithmetic of the draw before the kernel (ee394b3)."""
    used = [0]

    def take(shape):
        n = int(np.prod(shape))
        used[0] += n
        return u[used[0] - n:used[0]].reshape(shape)

    sizes = []
    for family, nominal in zip(("revolute_radial", "revolute_axial", "spherical_C", "spherical_B"),
                               (scene.clearance.revolute_radial, scene.clearance.revolute_axial,
                                scene.clearance.spherical_C, scene.clearance.spherical_B)):
        band, v = size_band(scene, family), take(6)
        sizes.append(np.full(6, nominal) if band is None else
                     band.low + (band.high - band.low) * v if band.law == "uniform" else
                     _normal(v, nominal, band.std, band.low, band.high))
    dr, da, dC, dB = sizes
    law, shape = scene.sampling, (6,) if steps is None else (steps, 6)
    point_r, point_a = np.any(law.radial_std * dr <= 0), np.any(law.axial_std * da <= 0)
    radial = _normal(None if point_r else take(shape), law.radial_mean * dr, law.radial_std * dr, 0.0, dr)
    theta = 0.0 + (2.0 * np.pi - 0.0) * take(shape)
    axial = _normal(None if point_a else take(shape), law.axial_mean * da, law.axial_std * da, -da, da)
    radial, axial = np.broadcast_to(radial, shape), np.broadcast_to(axial, shape)
    b = scene.geometry.base_angles
    plane_x, plane_y = np.stack([np.cos(b), np.sin(b), 0 * b], -1), np.array([0.0, 0.0, 1.0])
    e_A = ((radial * np.cos(theta))[..., None] * plane_x + (radial * np.sin(theta))[..., None] * plane_y
           + axial[..., None] * scene.geometry.w)
    spheres = []
    for size in (dC, dB):
        magnitude, u1, u2 = take(shape) * size, take(shape), take(shape)
        if law.direction == "uniform":   # z = cos eta1 of eta1 = arccos(1 - 2 u1), its sine from z
            z = 1.0 - 2.0 * u1
            sin1 = np.sqrt((1.0 - z) * (1.0 + z))
        else:
            z, sin1 = np.cos(np.pi * u1), np.sin(np.pi * u1)
        eta2 = 2.0 * np.pi * u2
        direction = np.stack([sin1 * np.cos(eta2), sin1 * np.sin(eta2), z], -1)
        spheres.append(magnitude[..., None] * direction)
    return ClearanceDraw(dr, da, dC, dB, e_A, *spheres)


# |kernel - numpy| of an eccentricity, per metre of its largest: numpy's float64 sin(2 pi u) is within
# 7e-16 of the exact value (2 pi u is rounded first), the kernel's within 2e-16 (test_turn_...)
ROUND_OFF = 1e-15


def _same_draw(got, expected):
    """Sizes bit for bit, eccentricities to round-off of the sines and cosines."""
    for field in dataclasses.fields(ClearanceDraw):
        a, b = getattr(got, field.name), getattr(expected, field.name)
        assert a.shape == b.shape, field.name
        if field.name.startswith("e_"):
            assert np.abs(a - b).max(initial=0.0) <= ROUND_OFF * np.abs(b).max(initial=0.0), field.name
        else:
            assert a.tobytes() == b.tobytes(), field.name


def _variants(configs, name):
    """The scene with both direction laws, and with point laws of the revolute (no uniforms taken)."""
    scene = load_scene(configs / f"{name}.toml")
    for direction in ("uniform", "paper"):
        yield dataclasses.replace(scene, sampling=dataclasses.replace(scene.sampling, direction=direction))
    yield dataclasses.replace(scene, sampling=dataclasses.replace(scene.sampling, radial_std=0.0, axial_std=0.0))


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("steps", [None, 7])
def test_the_compiled_draw_equals_numpys_arithmetic(configs, name, steps):
    """From a realisation's stream and from a vector of uniforms, one draw and per step: the kernel's
    sizes are the numpy reference's bit for bit, its eccentricities to round-off."""
    for scene in _variants(configs, name):
        for r in range(3):
            stream = realization_rng(5, r).random(uniform_dimension(steps))
            _same_draw(draw_clearances(scene, 5, r, steps), _reference(scene, stream, steps))
            u = np.random.default_rng(r).random(uniform_dimension(steps))
            _same_draw(clearances_from_uniforms(scene, u, steps), _reference(scene, u, steps))


@pytest.mark.parametrize("name", SCENES)
def test_the_compiled_draw_by_named_uniforms_equals_numpys_arithmetic(configs, name):
    """A Sobol' design's draw (uniforms by block name) is the reference's of the blocks in stream order."""
    for scene in _variants(configs, name):
        law, rng = scene.sampling, np.random.default_rng(11)
        blocks = {block: rng.random(6) for block in UNIFORM_BLOCKS}
        skipped = {"A_radial_magnitude"} if law.radial_std == 0 else set()
        skipped |= {"A_axial"} if law.axial_std == 0 else set()
        u = np.concatenate([blocks[b] for b in UNIFORM_BLOCKS if b not in skipped])
        _same_draw(clearances_from_named_uniforms(scene, blocks), _reference(scene, u, None))
    assert SIZE_BLOCKS == UNIFORM_BLOCKS[:4]


def test_the_paper_draw_is_the_reference_with_its_pads(paper):
    """The paper level's per-step draw: the output steps from the realisation's stream, the pads
    from their own (sizes from the first uniforms), each the reference's to round-off."""
    steps, seed, r = 2001, 3, 4
    got = paper_draw(paper, seed, r, steps)
    inner = _reference(paper, realization_rng(seed, r).random(uniform_dimension(steps)), steps)
    size_u = realization_rng(seed, r).random(24)
    fresh = np.random.default_rng(np.random.SeedSequence([seed, r, END_TAG])).random(
        uniform_dimension(2 * CENTRAL_PAD) - 24)
    ends = _reference(paper, np.concatenate([size_u, fresh]), 2 * CENTRAL_PAD)
    for e in ("e_A", "e_C", "e_B"):
        expected = np.concatenate([getattr(ends, e)[:CENTRAL_PAD], getattr(inner, e), getattr(ends, e)[CENTRAL_PAD:]])
        assert np.abs(getattr(got, e) - expected).max() <= ROUND_OFF * np.abs(expected).max(), e


def test_truncated_normal_equals_numpys_arithmetic_bit_for_bit():
    """The public truncated normal (per-leg parameters, any leading shape), against the reference."""
    mean, std, low, high = np.linspace(1e-4, 3e-4, 6), np.full(6, 1e-4), -2e-4, np.full(6, 4e-4)
    got = truncated_normal(realization_rng(1, 2), mean, std, low, high, (50, 6), "A_axial")
    expected = _normal(realization_rng(1, 2).random((50, 6)), mean, std, low, high)
    assert got.tobytes() == expected.tobytes()
    assert got.min() >= low and np.all(got <= high)


def test_turn_gives_the_cosine_and_sine_of_a_turn_to_a_quarter_of_a_unit_in_the_last_place():
    """turn(u) = (cos 2 pi u, sin 2 pi u) against long double (64-bit mantissa) trigonometry of the
    exact product, over a million uniforms and the quarter and eighth turns and their neighbours:
    within 2.5e-16 (fdlibm's polynomials; numpy's float64 sin(2 pi u) is 7e-16 off here)."""
    from rss6core.draw_kernel import sphere_directions_into, turn
    eighths = np.arange(9) / 8.0
    u = np.concatenate([np.random.default_rng(0).random(1_000_000), eighths, np.nextafter(eighths, 2.0)[:-1],
                        np.nextafter(eighths, -1.0)[1:]])
    got = np.empty((u.size, 3))   # the equator of the uniform sphere (u1 = 1/2): (cos, sin, 0) of the turn u
    sphere_directions_into(np.full(u.size, 0.5), u, True, got)
    exact = 2 * np.longdouble("3.141592653589793238462643383279502884") * u.astype(np.longdouble)
    assert np.abs(got[:, 0] - np.cos(exact)).max() <= 2.5e-16
    assert np.abs(got[:, 1] - np.sin(exact)).max() <= 2.5e-16
    assert all(turn(x) == tuple(got[k, :2]) for k, x in enumerate(u[-20:], u.size - 20))
    assert turn(0.0) == (1.0, 0.0) and turn(0.5)[0] == -1.0 and turn(0.25)[1] == 1.0


def test_every_draw_calls_the_one_overload_compiled_at_import(configs):
    """Draws of every shipped scene and path reuse the overloads draw_kernel compiles (or loads) at its
    import, so a fork server that preloads the module leaves its workers nothing to compile or load."""
    from rss6core import draw_kernel
    for name in SCENES:
        for scene in _variants(configs, name):
            draw_clearances(scene, 0, 1)
            paper_draw(scene, 0, 1, 5)
            clearances_from_named_uniforms(scene, {b: np.full(6, 0.5) for b in UNIFORM_BLOCKS})
    assert len(draw_kernel.eccentricities_into.signatures) == 1
    assert len(draw_kernel.truncated_normals.signatures) == 1
