"""ISO 286 hole-basis clearance fits (H hole, shafts c..h) and their cost by a cost-tolerance law.

Tables (micrometres, nominal sizes in mm over a, up to and including b), as tabulated, not from
the formula i = 0.45 D^(1/3) + 0.001 D, whose ISO rounding they carry:
- standard tolerance grades IT5-IT11: ISO 286-1:2010, Table 1;
- shaft fundamental deviations es of c, d, e, f, g, h: ISO 286-1:2010, its table of the shafts'
  fundamental deviations (a to j); hole H has EI = 0.
Both are reproduced in ANSI B4.2-1978 (R2020), Appendix B ("Tables of international tolerance
grades, fundamental deviations and their derivations"); its Table 2 ("Preferred hole basis clearance
fits") lists the resulting clearance limits that tests/test_fits.py checks, and the `pressfit`
package's independent tabulation is checked at 22 sizes.  (The ISO table numbers other than ISO
286-1 Table 1 were not checked against the standard's text, which is not public.)
A fit H<p>/<l><q> at diameter D: hole D + [0, IT_p], shaft D + [es - IT_q, es], so the diametral
clearance runs from -es (min) to IT_p + IT_q - es (max).  rss6's revolute radial clearance
([clearance] revolute_radial_m, docs/model.md section 4) is the largest eccentricity of the journal in
its bearing, the radial play: HALF the diametral clearance.

Cost (relative units per joint): the reciprocal-power cost-tolerance law C(T) = a + b (T_ref / T)^k
of each toleranced part (hole and shaft, T its IT width), Chase, Greenwood, Loosli and Hauglund (1990),
'Least cost tolerance allocation for mechanical assemblies with automated process selection',
Manufacturing Review 3(1): 49-59 (after Sutherland and Roth 1975): a fixed cost plus one that grows
without bound as the tolerance closes, with k = 1 the exponent they fit to turning data.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from ..vocabulary import UserError

__all__ = ["DEFAULT_FITS", "SIZE_BANDS_MM", "IT_UM", "SHAFT_ES_UM", "Fit", "FitError", "CostLaw", "COST_LAW",
           "parse_fit",
           "fit_limits", "FitLimits"]

SIZE_BANDS_MM = (3, 6, 10, 18, 30, 50, 80, 120)       # upper ends; a size sits in (previous, upper]
IT_UM = {   # ISO 286-1:2010 Table 1, um, per band of SIZE_BANDS_MM
    5: (4, 5, 6, 8, 9, 11, 13, 15),
    6: (6, 8, 9, 11, 13, 16, 19, 22),
    7: (10, 12, 15, 18, 21, 25, 30, 35),
    8: (14, 18, 22, 27, 33, 39, 46, 54),
    9: (25, 30, 36, 43, 52, 62, 74, 87),
    10: (40, 48, 58, 70, 84, 100, 120, 140),
    11: (60, 75, 90, 110, 130, 160, 190, 220),
}
# ISO 286-1:2010 Table 2, shaft upper deviation es (um): (upper end of its size band in mm, es); c
# changes on the intermediate bands 30-40-50, 50-65-80, 80-100-120
SHAFT_ES_UM = {
    "c": ((3, -60), (6, -70), (10, -80), (18, -95), (30, -110), (40, -120), (50, -130), (65, -140),
          (80, -150), (100, -170), (120, -180)),
    "d": tuple(zip(SIZE_BANDS_MM, (-20, -30, -40, -50, -65, -80, -100, -120))),
    "e": tuple(zip(SIZE_BANDS_MM, (-14, -20, -25, -32, -40, -50, -60, -72))),
    "f": tuple(zip(SIZE_BANDS_MM, (-6, -10, -13, -16, -20, -25, -30, -36))),
    "g": tuple(zip(SIZE_BANDS_MM, (-2, -4, -5, -6, -7, -9, -10, -12))),
    "h": tuple(zip(SIZE_BANDS_MM, (0,) * 8)),
}
# the clearance fits rss6 allocate offers by default, tightest to loosest at 18-30 mm; the ISO 286-1 Annex
# preferred running fits among them (H7/g6, H8/f7, H9/d9, H11/c11) and the grades between
DEFAULT_FITS = ("H7/g6", "H7/f7", "H8/f7", "H8/e8", "H9/e9", "H9/d9", "H10/d10", "H11/d11", "H11/c11")
_FIT = re.compile(r"^H(\d+)/([a-z])(\d+)$")


class FitError(UserError):
    """A fit name or diameter outside the tables."""


@dataclass(frozen=True)
class Fit:
    """A hole-basis fit H<hole_grade>/<shaft_letter><shaft_grade>, e.g. H7/g6."""
    hole_grade: int
    shaft_letter: str
    shaft_grade: int

    @property
    def name(self) -> str:
        return f"H{self.hole_grade}/{self.shaft_letter}{self.shaft_grade}"


@dataclass(frozen=True)
class FitLimits:
    """A fit at one nominal diameter (m): the parts' tolerance widths and the clearance limits."""
    fit: Fit
    diameter: float          # m
    hole_tolerance: float    # m, IT of the hole grade
    shaft_tolerance: float   # m, IT of the shaft grade
    min_diametral: float     # m, smallest hole minus largest shaft
    max_diametral: float     # m

    @property
    def radial_low(self) -> float:
        """Smallest radial clearance (m): half the diametral one (module doc)."""
        return self.min_diametral / 2

    @property
    def radial_high(self) -> float:
        """Largest radial clearance (m)."""
        return self.max_diametral / 2


@dataclass(frozen=True)
class CostLaw:
    """C(T) = a + b (T_ref / T)^k per toleranced part, relative cost units; T, T_ref in m."""
    a: float = 1.0
    b: float = 1.0
    k: float = 1.0
    reference: float = 20e-6   # m: a 20 um tolerance costs a + b

    def part(self, tolerance: float) -> float:
        return self.a + self.b * (self.reference / tolerance) ** self.k

    def fit(self, limits: FitLimits) -> float:
        """Cost of one joint at this fit: its hole and its shaft."""
        return self.part(limits.hole_tolerance) + self.part(limits.shaft_tolerance)


COST_LAW = CostLaw()


def parse_fit(name: str) -> Fit:
    """The Fit of a name like 'H7/g6'; FitError naming the tables' letters and grades otherwise."""
    m = _FIT.match(name.strip())
    ok = m and int(m[1]) in IT_UM and int(m[3]) in IT_UM and m[2] in SHAFT_ES_UM
    if not ok:
        raise FitError(f"fit {name!r}: give H<grade>/<shaft letter><grade> with grades "
                       f"{min(IT_UM)}-{max(IT_UM)} and shaft letters {', '.join(SHAFT_ES_UM)} (ISO 286 "
                       "clearance fits), e.g. H7/g6")
    return Fit(int(m[1]), m[2], int(m[3]))


def _band(diameter_mm: float, uppers) -> int:
    if not 0 < diameter_mm <= uppers[-1]:
        raise FitError(f"diameter {diameter_mm:g} mm: the ISO 286 tables here cover sizes over 0 up to "
                       f"{uppers[-1]} mm")
    return next(i for i, upper in enumerate(uppers) if diameter_mm <= upper + 1e-9)


def fit_limits(fit: Fit | str, diameter: float) -> FitLimits:
    """The fit's tolerances and diametral clearance limits (m) at nominal diameter ``diameter`` (m)."""
    fit = parse_fit(fit) if isinstance(fit, str) else fit
    d_mm = diameter * 1e3
    band = _band(d_mm, SIZE_BANDS_MM)
    it_hole, it_shaft = IT_UM[fit.hole_grade][band], IT_UM[fit.shaft_grade][band]
    es_table = SHAFT_ES_UM[fit.shaft_letter]
    es = es_table[_band(d_mm, [upper for upper, _ in es_table])][1]
    um = 1e6   # whole micrometres divided, not multiplied by 1e-6: 20 um is 2e-05 m, not 1.9999999999999998e-05
    return FitLimits(fit, diameter, it_hole / um, it_shaft / um, -es / um, (it_hole + it_shaft - es) / um)
