"""The DCT-I solver of the facet operator and the box preconditioner."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from facetlift.domain import Domain
from facetlift.linalg import cg
from facetlift.linalg.spectral import BoxPreconditioner, RectangleSolver
from facetlift.operators.stencil import N_MEAN_FREE, facet_form


@pytest.mark.parametrize("H,W", [(1, 1), (1, 5), (4, 3), (17, 9), (32, 32)])
def test_rectangle_solver_inverts_operator_on_mean_free_rhs(H, W):
    d = Domain.from_mask(np.ones((H, W), bool))
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    b = np.random.default_rng(3).standard_normal(d.n_vertices)
    b -= b.mean()  # the range of K: orthogonal to constants
    x = RectangleSolver(H, W).solve(b)
    assert np.abs(K @ x - b).max() < 1e-12 * max(1, np.abs(b).max()) * 10


@pytest.mark.parametrize("H,W", [(1, 1), (4, 3), (17, 9)])
def test_shifted_rectangle_solver_inverts_operator_plus_shift_times_facet_counts(H, W):
    # K + c D, D the facets per vertex: a uniform lumped prior mass (linalg.facet)
    d = Domain.from_mask(np.ones((H, W), bool))
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    D = np.outer(np.r_[1, np.full(H - 1, 2), 1][: H + 1], np.r_[1, np.full(W - 1, 2), 1][: W + 1])
    b = np.random.default_rng(4).standard_normal(d.n_vertices)  # constants included
    x = RectangleSolver(H, W, shift=0.3).solve(b)
    assert np.abs(K @ x + 0.3 * D.ravel() * x - b).max() < 1e-11


def test_box_preconditioner_exact_only_for_full_masks():
    m = np.ones((5, 5), bool)
    assert BoxPreconditioner(Domain.from_mask(m)).exact
    m[2, 2] = False
    assert not BoxPreconditioner(Domain.from_mask(m)).exact


def _disk_with_hole(s):
    r, c = np.mgrid[0:s, 0:s]
    disk = (r - s / 2) ** 2 + (c - s / 2) ** 2 < (0.45 * s) ** 2
    return disk & ~(((r - s / 2) ** 2 + (c - s / 3) ** 2) < (0.1 * s) ** 2)


@pytest.mark.parametrize("s", [32, 64, 128])
def test_box_preconditioner_iterations_do_not_grow_with_resolution(s):
    d = Domain.from_mask(_disk_with_hole(s))
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    rng = np.random.default_rng(0)
    b = K @ rng.standard_normal(d.n_vertices)  # consistent right-hand side
    pre = BoxPreconditioner(d)
    assert not pre.exact
    x, info = cg(K, b, pre, rtol=1e-10)
    assert info.converged
    assert np.linalg.norm(K @ x - b) <= 1e-9 * np.linalg.norm(b)
    assert info.iterations <= 40


def test_box_preconditioner_is_exact_on_full_rectangle():
    d = Domain.from_mask(np.ones((20, 30), bool))
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    b = K @ np.random.default_rng(1).standard_normal(d.n_vertices)
    pre = BoxPreconditioner(d)
    assert pre.exact
    assert np.abs(K @ pre(b) - b).max() < 1e-10


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_a_box_the_domain_fills_skips_the_scatter_with_the_same_numbers(dtype):
    # a full rectangle (e.g. with missing normals, which leaves the mask whole) fills its
    # box: the preconditioner hands the residual to the transforms without a zeroed copy
    d = Domain.from_mask(np.ones((20, 30), bool))
    pre = BoxPreconditioner(d, dtype=dtype)
    assert pre._fills
    r = np.random.default_rng(3).standard_normal(d.n_vertices)
    kept = r.copy()
    x = pre(r)
    np.testing.assert_array_equal(r, kept)  # (the residual is not written into)
    assert x.dtype == np.float64 and x.shape == r.shape
    pre._fills = False  # the general path: scatter into the box, gather back
    np.testing.assert_array_equal(x, pre(r))
    # each result is its own array: the next call reuses the workspace, not the result
    for fills in (True, False):
        pre._fills = fills
        x1 = pre(r)
        kept = x1.copy()
        pre(2.0 * r + 1.0)
        np.testing.assert_array_equal(x1, kept)
        assert not np.shares_memory(x1, pre._work.box)
    m = np.ones((20, 30), bool)
    m[3, 4] = False  # (a hole of one pixel leaves every vertex: the box still filled)
    assert BoxPreconditioner(Domain.from_mask(m))._fills
    m[0, 0] = False  # (a corner pixel takes its corner vertex with it)
    assert not BoxPreconditioner(Domain.from_mask(m))._fills


def test_box_preconditioner_is_symmetric_positive_semidefinite():
    d = Domain.from_mask(_disk_with_hole(16))
    pre = BoxPreconditioner(d)
    n = d.n_vertices
    P = np.column_stack([pre(e) for e in np.eye(n)])
    assert np.allclose(P, P.T, atol=1e-12)
    assert np.linalg.eigvalsh(P).min() > -1e-10


def test_cropping_to_bounding_box_matches_direct_solve():
    m = np.zeros((40, 50), bool)
    m[10:30, 5:20] = True
    m[12:25, 22:45] = True
    d = Domain.from_mask(m)
    K = facet_form(d, [(1.0, N_MEAN_FREE)])
    b = K @ np.random.default_rng(2).standard_normal(d.n_vertices)
    x, info = cg(K, b, BoxPreconditioner(d), rtol=1e-12)
    assert info.converged
    # compare with a factorized solve with the two constants pinned, up to the constants
    Kp = K.tolil()
    for comp in range(d.n_components):
        v = np.nonzero(d.vertex_component == comp)[0][0]
        Kp[v, v] += 1.0
    y = spla.spsolve(Kp.tocsc(), b)
    for comp in range(d.n_components):
        sel = d.vertex_component == comp
        diff = (x - y)[sel]
        assert np.ptp(diff) < 1e-8
