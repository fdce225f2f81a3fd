"""Time integrators for M(t) a + C(t) v + K(t) d = F(t) as coefficient sets behind one step.

All four are members of the generalized-alpha family (Chung & Hulbert 1993),
written in acceleration form:
    d+ = d~ + beta h^2 a+,   v+ = v~ + gamma h a+,
    d~ = d + h v + (1/2 - beta) h^2 a,   v~ = v + (1 - gamma) h a,
    (1-am) [M a]+ + am [M a] + (1-af) [C v + K d]+ + af [C v + K d] = (1-af) F+ + af F,
each bracket taken with the matrices of its own instant.
- Newmark (beta, gamma); average acceleration 1/4, 1/2 is the paper's and the default;
- HHT-alpha (Hilber, Hughes & Taylor 1977): am = 0, af = alpha in [0, 1/3];
- generalized-alpha with high-frequency spectral radius rho_inf in [0, 1];
- central difference: beta = 0, gamma = 1/2 (explicit: K leaves the step matrix;
  stable for h < 2 / omega_max).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Integrator", "INTEGRATORS", "make_integrator", "StepWeights", "predict", "correct"]

INTEGRATORS = ("newmark", "hht", "generalized-alpha", "central-difference")   # the names make_integrator knows


@dataclass(frozen=True)
class Integrator:
    name: str
    beta: float
    gamma: float
    alpha_m: float = 0.0
    alpha_f: float = 0.0

    @property
    def explicit(self) -> bool:
        return self.beta == 0.0

    @classmethod
    def newmark(cls, beta: float = 0.25, gamma: float = 0.5) -> "Integrator":
        if not (0.0 <= beta <= 0.5 and 0.0 <= gamma <= 1.0):
            raise ValueError(f"newmark: beta in [0, 0.5] and gamma in [0, 1], got {beta}, {gamma}")
        return cls("newmark", beta, gamma)

    @classmethod
    def hht(cls, alpha: float = 0.05) -> "Integrator":
        if not 0.0 <= alpha <= 1.0 / 3.0:
            raise ValueError(f"hht: alpha must lie in [0, 1/3], got {alpha}")
        return cls("hht", (1.0 + alpha) ** 2 / 4.0, 0.5 + alpha, 0.0, alpha)

    @classmethod
    def generalized_alpha(cls, rho_inf: float = 0.8) -> "Integrator":
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"generalized-alpha: spectral radius must lie in [0, 1], got {rho_inf}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        return cls("generalized-alpha", 0.25 * (1.0 - am + af) ** 2, 0.5 - am + af, am, af)

    @classmethod
    def central_difference(cls) -> "Integrator":
        return cls("central-difference", 0.0, 0.5)

    def step_coefficients(self, h: float) -> tuple[float, float, float]:
        """Weights (c_M, c_C, c_K) of the step matrix c_M M + c_C C + c_K K solved for a+."""
        w = 1.0 - self.alpha_f
        return 1.0 - self.alpha_m, w * self.gamma * h, w * self.beta * h * h

    def weights(self, h: float) -> "StepWeights":
        """The predictor's and corrector's weights for a step of h (s)."""
        return StepWeights(h, (0.5 - self.beta) * h * h, (1.0 - self.gamma) * h, self.beta * h * h,
                           self.gamma * h)


@dataclass(frozen=True)
class StepWeights:
    """Weights of one step of length h (s): predictor d~ = d + h v + d_pred a, v~ = v + v_pred a;
    corrector d+ = d~ + d_corr a+, v+ = v~ + v_corr a+."""
    h: float
    d_pred: float   # (1/2 - beta) h^2, s^2
    v_pred: float   # (1 - gamma) h, s
    d_corr: float   # beta h^2, s^2
    v_corr: float   # gamma h, s


def predict(d, v, a, h: float, d_pred: float, v_pred: float):
    """The generalized-alpha predictor (d~, v~) from the state at a step's start (any shape), with
    the weights of :class:`StepWeights`.  :func:`.contact_kernel.predict_one` is its compiled twin
    (tests/test_integrators.py)."""
    return d + h * v + d_pred * a, v + v_pred * a


def correct(dp, vp, a, d_corr: float, v_corr: float):
    """The corrector (d+, v+) from the prediction and the step's new acceleration a+.
    :func:`.contact_kernel.correct_one` is its compiled twin."""
    return dp + d_corr * a, vp + v_corr * a


def make_integrator(name: str, newmark_beta: float = 0.25, newmark_gamma: float = 0.5,
                    hht_alpha: float = 0.05, spectral_radius: float = 0.8) -> Integrator:
    """The integrator called ``name`` with its parameters (others are ignored).

    Names: newmark, hht, generalized-alpha, central-difference.
    """
    if name == "newmark":
        return Integrator.newmark(newmark_beta, newmark_gamma)
    if name == "hht":
        return Integrator.hht(hht_alpha)
    if name == "generalized-alpha":
        return Integrator.generalized_alpha(spectral_radius)
    if name == "central-difference":
        return Integrator.central_difference()
    raise ValueError(f"unknown integrator {name!r}; choose one of {', '.join(INTEGRATORS)}")
