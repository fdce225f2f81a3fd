"""The generalized-alpha predictor/corrector exists once in numpy (rss6core.integrators) and once as
its compiled twin on plain floats (rss6core.contact_kernel); they agree on random inputs."""
import numpy as np
import pytest
from numba import njit

from rss6core.contact_kernel import correct_one, predict_one
from rss6core.integrators import Integrator, correct, predict


def _twins(d, v, a, dp, vp, a_new, w, predict_twin, correct_twin):
    """The twins on the same inputs as the numpy functions, element by element."""
    pred = np.array([predict_twin(*x, w.h, w.d_pred, w.v_pred) for x in zip(d, v, a)]).T
    corr = np.array([correct_twin(*x, w.d_corr, w.v_corr) for x in zip(dp, vp, a_new)]).T
    return pred, corr


METHODS = [Integrator.newmark(), Integrator.hht(0.1), Integrator.generalized_alpha(0.6),
           Integrator.central_difference()]


@pytest.mark.parametrize("method", METHODS)
def test_compiled_twin_equals_the_numpy_predictor_and_corrector(method):
    """Random states over twelve decades: the twin's formula compiled plainly is the numpy function
    bit for bit; compiled as the kernel compiles it (fused multiply-add, reassociation) it is off by
    at most two units in the last place of the largest term summed (measured: 2; their round-off,
    not a change of method: with cancellation that can be thousands of ulps of a small result)."""
    rng = np.random.default_rng(4)
    w = method.weights(10.0 ** rng.uniform(-6, -3))
    d, v, a, a_new = (rng.normal(size=2000) * 10.0 ** rng.uniform(-9, 3, 2000) for _ in range(4))
    dp, vp = predict(d, v, a, w.h, w.d_pred, w.v_pred)
    dn, vn = correct(dp, vp, a_new, w.d_corr, w.v_corr)
    plain_p, plain_c = _twins(d, v, a, dp, vp, a_new, w, njit(predict_one.py_func), njit(correct_one.py_func))
    for ours, theirs in ((dp, plain_p[0]), (vp, plain_p[1]), (dn, plain_c[0]), (vn, plain_c[1])):
        assert np.array_equal(ours, theirs)
    fast_p, fast_c = _twins(d, v, a, dp, vp, a_new, w, predict_one, correct_one)
    terms = ((dp, fast_p[0], (d, w.h * v, w.d_pred * a)), (vp, fast_p[1], (v, w.v_pred * a)),
             (dn, fast_c[0], (dp, w.d_corr * a_new)), (vn, fast_c[1], (vp, w.v_corr * a_new)))
    for ours, theirs, summed in terms:
        largest = np.max(np.abs(np.stack(summed)), 0)
        assert np.all(np.abs(ours - theirs) <= 2.0 * np.spacing(largest))
    # the weights are the integrator's
    assert w.d_corr == method.beta * w.h * w.h and w.v_corr == method.gamma * w.h
    assert w.d_pred == (0.5 - method.beta) * w.h * w.h and w.v_pred == (1.0 - method.gamma) * w.h


def test_predictor_and_corrector_integrate_constant_acceleration_exactly():
    """d(t) = d0 + v0 t + a t^2 / 2 with a constant a: one step lands on it for any beta, gamma."""
    for method in (Integrator.newmark(), Integrator.hht(0.2), Integrator.generalized_alpha(0.3)):
        w = method.weights(0.01)
        dp, vp = predict(1.0, 2.0, 3.0, w.h, w.d_pred, w.v_pred)
        d, v = correct(dp, vp, 3.0, w.d_corr, w.v_corr)
        assert d == pytest.approx(1.0 + 2.0 * 0.01 + 1.5 * 1e-4, rel=1e-15)
        assert v == pytest.approx(2.0 + 3.0 * 0.01, rel=1e-15)
