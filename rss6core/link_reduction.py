"""Craig-Bampton (component mode synthesis) reduction of a link's beam matrices.

The link's DOFs split into boundary DOFs b (those the joints and the rest of the robot touch, kept
exact) and interior DOFs i.  The interior is represented by the static constraint modes
Psi = -K_ii^-1 K_ib (the interior's static response to each unit boundary displacement) plus the
first m fixed-interface normal modes Phi (K_ii Phi = M_ii Phi Omega^2, boundary held fixed,
mass-normalised):  [u_i; u_b] = T [q; u_b],  T = [[Phi, Psi], [0, I]]  (docs/model.md, eq. CB1),
and K_r = T^T K T, M_r = T^T M T, nodal loads f_r = T^T f (eq. CB2).  Statics is exact (every
boundary load path is in Psi); with m = all interior modes T is square and invertible, so the
reduced model is the full one in other coordinates.  Craig & Bampton, AIAA J. 6 (1968) 1313-1319.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = ["craig_bampton", "reduce_pair", "interior_count", "max_link_modes", "link_modes"]


def max_link_modes(elements: int) -> int:
    """The most Craig-Bampton modes a link of ``elements`` elements can keep: the larger of the crank's
    interior (nodes 1..n-1, 6 (n - 1) DOFs) and the rod's (its own DOFs, 5 n - 1).  A link with fewer
    interior DOFs than the modes asked keeps them all (:func:`link_modes`): it is exact."""
    return max(6 * (elements - 1), 5 * elements - 1)


def link_modes(modes: int, size: int, boundary: np.ndarray) -> int:
    """The modes a link keeps when ``modes`` are asked: at most its interior DOFs."""
    return min(modes, interior_count(size, boundary))


def interior_count(size: int, boundary: np.ndarray) -> int:
    """Number of interior DOFs of a link of ``size`` DOFs with ``boundary`` indices: the most modes
    a Craig-Bampton basis can keep."""
    return size - len(np.unique(boundary))


def _one(K: np.ndarray, M: np.ndarray, boundary: np.ndarray, modes: int) -> np.ndarray:
    """T (n, modes + nb) of one link, reduced vector [q (modes), u_b (boundary order)]."""
    n = K.shape[-1]
    interior = np.setdiff1d(np.arange(n), boundary)
    Kii = K[np.ix_(interior, interior)]
    psi = -np.linalg.solve(Kii, K[np.ix_(interior, boundary)])
    if modes:
        _, phi = scipy.linalg.eigh(Kii, M[np.ix_(interior, interior)], subset_by_index=[0, modes - 1])
    else:
        phi = np.zeros((len(interior), 0))
    phi *= np.where(phi[np.abs(phi).argmax(0), np.arange(modes)] < 0, -1.0, 1.0)   # a fixed sign per mode
    T = np.zeros((n, modes + len(boundary)))
    T[interior, :modes], T[interior, modes:] = phi, psi
    T[boundary, modes + np.arange(len(boundary))] = 1.0
    return T


def craig_bampton(K: np.ndarray, M: np.ndarray, boundary: np.ndarray, modes: int) -> np.ndarray:
    """The Craig-Bampton basis T (n, modes + nb) of a link's stiffness K and mass M (n, n), or one per
    leg (6, n, modes + nb) for per-leg matrices (6, n, n): columns [fixed-interface modes, constraint
    modes], so the reduced vector is [q, u_b] with the boundary DOFs last, in ``boundary``'s order."""
    boundary = np.asarray(boundary)
    if not 0 <= modes <= interior_count(K.shape[-1], boundary):
        raise ValueError(f"modes must lie in [0, {interior_count(K.shape[-1], boundary)}] (the link's "
                         f"interior DOFs), got {modes}")
    if K.ndim == 2:
        return _one(K, M, boundary, modes)
    return np.stack([_one(K[i], M[i], boundary, modes) for i in range(K.shape[0])])


def reduce_pair(K: np.ndarray, M: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T^T K T and T^T M T (eq. CB2), symmetrised against round-off; per leg for (6, n, n)."""
    Tt = np.swapaxes(T, -1, -2)
    Kr, Mr = Tt @ K @ T, Tt @ M @ T
    return 0.5 * (Kr + np.swapaxes(Kr, -1, -2)), 0.5 * (Mr + np.swapaxes(Mr, -1, -2))
