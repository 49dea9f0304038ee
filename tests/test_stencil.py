"""facetlift.stencil: per-facet 4x4 forms assembled on the vertex grid."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from facetlift.domain import Domain
from facetlift.operators.stencil import (
    E_MEAN,
    E_TWIST,
    E_X,
    E_Y,
    N_MEAN_FREE,
    facet_form,
    pin_components,
    scatter_corners,
)


def irregular_mask(seed=0, shape=(7, 9)):
    m = np.random.default_rng(seed).random(shape) < 0.6
    m[3, 1:8] = True  # make sure there is something connected
    return m


def dense_form(domain, terms):
    """sum_f sum_t w_t[f] C_f^T Q_t C_f with an explicit loop (C_f picks facet f's corners)."""
    n = domain.n_vertices
    K = np.zeros((n, n))
    for f in range(domain.n_facets):
        C = np.zeros((4, n))
        C[np.arange(4), domain.corners[f]] = 1.0
        for w, Q in terms:
            wf = w if np.isscalar(w) else w[f]
            K += wf * C.T @ Q @ C
    return K


def random_spd4(rng):
    B = rng.normal(size=(4, 4))
    return B @ B.T


def test_basis_is_orthonormal():
    E = np.stack([E_MEAN, E_X, E_Y, E_TWIST])
    np.testing.assert_allclose(E @ E.T, np.eye(4), atol=1e-15)
    np.testing.assert_allclose(N_MEAN_FREE, np.eye(4) - np.outer(E_MEAN, E_MEAN), atol=1e-15)
    np.testing.assert_allclose(
        N_MEAN_FREE,
        np.outer(E_X, E_X) + np.outer(E_Y, E_Y) + np.outer(E_TWIST, E_TWIST), atol=1e-15,
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_facet_form_equals_dense_sum(seed):
    rng = np.random.default_rng(seed)
    d = Domain.from_mask(irregular_mask(seed))
    terms = [
        (rng.uniform(0.1, 2.0, d.n_facets), random_spd4(rng)),
        (0.7, N_MEAN_FREE),
        (rng.uniform(0, 1, d.n_facets), np.outer(E_TWIST, E_TWIST)),
    ]
    K = facet_form(d, terms)
    assert sp.issparse(K) and K.format == "csr" and K.shape == (d.n_vertices,) * 2
    np.testing.assert_allclose(K.toarray(), dense_form(d, terms), rtol=1e-13, atol=1e-13)
    # a 9-point stencil: at most 9 entries per row, each to a grid neighbour
    assert np.diff(K.indptr).max() <= 9


def test_facet_form_single_facet_is_the_block():
    m = np.zeros((3, 3), bool)
    m[1, 1] = True
    d = Domain.from_mask(m)
    Q = random_spd4(np.random.default_rng(3))
    assert list(d.corners[0]) == [0, 1, 3, 2]  # vertices are numbered row-major
    K = facet_form(d, [(1.0, Q)]).toarray()
    np.testing.assert_allclose(K[np.ix_(d.corners[0], d.corners[0])], Q, rtol=1e-14)


def test_facet_form_as_energy():
    """z^T K z = sum_f w_f z_f^T Q z_f."""
    rng = np.random.default_rng(4)
    d = Domain.from_mask(irregular_mask(4))
    w = rng.uniform(0.1, 3.0, d.n_facets)
    Q = random_spd4(rng)
    z = rng.normal(size=d.n_vertices)
    zf = z[d.corners]
    K = facet_form(d, [(w, Q)])
    np.testing.assert_allclose(z @ (K @ z), np.sum(w * np.einsum("fi,ij,fj->f", zf, Q, zf)),
                               rtol=1e-12)


def test_mean_free_form_kills_constants_per_component():
    mask = np.zeros((6, 10), bool)
    mask[1:5, 1:4] = True
    mask[1:5, 6:9] = True
    d = Domain.from_mask(mask)
    assert d.n_components == 2
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    np.testing.assert_allclose(K @ np.ones(d.n_vertices), 0.0, atol=1e-14)  # rows sum to 0
    step = (d.vertex_component == 1).astype(float)  # a different constant per component
    np.testing.assert_allclose(K @ step, 0.0, atol=1e-14)
    assert np.abs(K - K.T).max() == 0
    # the null space is exactly the per-component constants: rank n - n_components
    assert np.linalg.matrix_rank(K.toarray()) == d.n_vertices - 2


def test_pin_components_makes_it_spd():
    d = Domain.from_mask(irregular_mask(5))
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    assert abs(np.linalg.eigvalsh(K.toarray())[0]) < 1e-12  # singular: constants
    P = pin_components(d, K, weight=2.5)
    L = np.linalg.cholesky(P.toarray())  # raises if not SPD
    assert np.all(np.diag(L) > 0)
    assert np.linalg.eigvalsh(P.toarray())[0] > 1e-3
    diff = (P - K).toarray()
    pinned = np.flatnonzero(np.diag(diff))
    assert np.allclose(diff[pinned, pinned], 2.5)
    assert np.count_nonzero(diff) == d.n_components == pinned.size
    # one pinned vertex per component: the lowest-numbered one
    comp = d.vertex_component
    assert sorted(comp[pinned]) == list(range(d.n_components))
    for k in range(d.n_components):
        assert pinned[comp[pinned] == k][0] == np.flatnonzero(comp == k)[0]


def test_scatter_corners_is_gather_transpose():
    rng = np.random.default_rng(6)
    d = Domain.from_mask(irregular_mask(6))
    v = rng.normal(size=(d.n_facets, 4))
    np.testing.assert_allclose(scatter_corners(d, v), d.gather.T @ v.ravel(), rtol=1e-13)
    # adjoint identity <C z, v> = <z, C^T v>
    z = rng.normal(size=d.n_vertices)
    np.testing.assert_allclose(np.sum(z[d.corners] * v), z @ scatter_corners(d, v), rtol=1e-12)


def test_facet_form_orientation():
    """Entry (corner a, corner b) receives Q[a, b] (the module docstring), also for a
    non-symmetric block."""
    rng = np.random.default_rng(7)
    d = Domain.from_mask(irregular_mask(7))
    Q = rng.normal(size=(4, 4))
    np.testing.assert_allclose(facet_form(d, [(1.0, Q)]).toarray(), dense_form(d, [(1.0, Q)]),
                               atol=1e-13)
