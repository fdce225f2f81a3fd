"""The measurement behind the default analysis-window boundary ([simulation] steady_after_s, docs/model.md
section 6): from when on does each realisation's contact-level error repeat one trajectory period later,
i.e. no longer depend on its drawn initial state?

    rss6 run paper --model contact -n 24 --store full -o paper_contact_full.nc
    python docs/window_boundary.py paper_contact_full.nc

For each quantity and direction, D(t) = rms over realisations of e(t + P) - e(t) (does a realisation
repeat itself?) and S(t) = std over realisations of e(t) (do the realisations agree?), both divided
by the rms of e over t >= P; printed: the time after which each stays below 0.5, 0.2, 0.1 and 0.05
in every direction. Then, per window (startup t < t_s, steady t >= t_s, t_s the scene's steady_after_s)
and direction, max |e| per realisation over the file's histories: the coefficient of variation of the
displacement maxima over realisations and the medians of the displacement and acceleration maxima
(mm, rad; m/s^2, rad/s^2)."""
import sys

import numpy as np

from pipeline.files.reading import load_netcdf
from pipeline.vocabulary import QUANTITIES
from rss6core import parse_scene


def residual(e: np.ndarray, lag: int) -> np.ndarray:
    """D (T - lag, direction) of histories e (realisation, time, direction)."""
    diff = e[:, lag:] - e[:, :-lag]
    scale = np.sqrt((e[:, lag:] ** 2).mean(axis=(0, 1)))
    return np.sqrt((diff ** 2).mean(axis=0)) / scale


def spread(e: np.ndarray, late: np.ndarray) -> np.ndarray:
    """S (T, direction) of histories e (realisation, time, direction); ``late``: the samples t >= P."""
    scale = np.sqrt((e[:, late] ** 2).mean(axis=(0, 1)))
    return e.std(axis=0, ddof=1) / scale


def _settles(t, worst) -> str:
    out = []
    for threshold in (0.5, 0.2, 0.1, 0.05):
        above = np.flatnonzero(worst > threshold)
        out.append(f"<= {threshold:g} from {t[above[-1] + 1] if len(above) else 0.0:.3f} s")
    return ", ".join(out)


def main(path: str) -> None:
    ds = load_netcdf(path)
    period = 1.0 / parse_scene(ds.attrs["scene_toml"]).trajectory.frequency   # s
    t = ds["time"].values
    lag = int(round(period / (t[1] - t[0])))
    for q in QUANTITIES:
        e = ds["error"].sel(quantity=q).transpose("realization", "time", "direction").values
        print(f"{q}: repeats (D) " + _settles(t[:-lag], residual(e, lag).max(axis=1)))
        print(f"{q}: agrees (S) " + _settles(t, spread(e, t >= period - 1e-12).max(axis=1)))
    t_s = parse_scene(ds.attrs["scene_toml"]).simulation.steady_after
    scale = np.array([1e3, 1e3, 1e3, 1.0, 1.0, 1.0])   # m -> mm
    print(f"{'':42}" + "".join(f"{d:>10}" for d in ds["direction"].values))
    for window, rows in (("startup", t < t_s - 1e-12), ("steady", t >= t_s - 1e-12)):
        peaks = {q: np.abs(ds["error"].sel(quantity=q).transpose("realization", "time", "direction").values[:, rows])
                 .max(axis=1) for q in ("displacement", "acceleration")}
        cov = peaks["displacement"].std(axis=0, ddof=1) / peaks["displacement"].mean(axis=0)
        print(f"{window + ': displacement maxima, CoV':42}" + "".join(f"{v:10.2%}" for v in cov))
        print(f"{window + ': displacement maxima, median (mm, rad)':42}"
              + "".join(f"{v:10.4g}" for v in np.median(peaks["displacement"], axis=0) * scale))
        print(f"{window + ': acceleration maxima, median':42}"
              + "".join(f"{v:10.4g}" for v in np.median(peaks["acceleration"], axis=0)))


if __name__ == "__main__":
    main(sys.argv[1])
