"""Beam elements against Euler-Bernoulli closed forms (cantilever, 8 elements)."""
import numpy as np
import pytest
import scipy.linalg

from rss6core.beam import element_matrices, link_matrices
from rss6core.sections import section_properties

E, G, RHO, L = 70e9, 26.5e9, 2700.0, 0.216
BETA_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])  # cantilever roots of cos cosh = -1


@pytest.fixture(scope="module")
def crank(paper):
    props = section_properties(paper.crank_section)
    K, M = link_matrices(props, E, G, RHO, L, 8)
    return props, K[6:, 6:], M[6:, 6:]  # clamp node 0


@pytest.mark.parametrize("dof, stiffness", [
    (0, lambda p: E * p.area / L),               # axial
    (3, lambda p: G * p.J / L),                  # torsion
    (1, lambda p: 3 * E * p.Iz / L ** 3),        # bending in x-y (about z)
    (2, lambda p: 3 * E * p.Iy / L ** 3),        # bending in x-z (about y)
])
def test_cantilever_tip_deflection(crank, dof, stiffness):
    props, K, _ = crank
    load = np.zeros(len(K))
    load[-6 + dof] = 1.0
    tip = np.linalg.solve(K, load)[-6 + dof]
    assert tip == pytest.approx(1.0 / stiffness(props), rel=1e-10)


def test_cantilever_bending_frequencies_within_half_percent(crank):
    props, K, M = crank
    omega = np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True))
    for I in (props.Iy, props.Iz):
        exact = BETA_L ** 2 / L ** 2 * np.sqrt(E * I / (RHO * props.area))
        # the nearest computed frequency to each closed-form one
        computed = np.array([omega[np.argmin(np.abs(omega - w))] for w in exact])
        assert np.abs(computed / exact - 1).max() < 0.005


def test_element_matrices_symmetric_and_rigid_body_free(paper):
    K, M = element_matrices(section_properties(paper.rod_section), E, G, RHO, 0.1)
    assert np.allclose(K, K.T) and np.allclose(M, M.T)
    rigid = np.zeros(12)
    rigid[[2, 8]] = 1.0  # translation along z
    assert np.abs(K @ rigid).max() < 1e-6 * np.abs(K).max()
    assert rigid @ M @ rigid == pytest.approx(RHO * section_properties(paper.rod_section).area * 0.1)
