"""Nested dissection on the grid (facetlift.linalg.ordering) and SuperLU ordered by it."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from facetlift import linalg
from facetlift.domain import Domain
from facetlift.linalg.ordering import nested_dissection
from facetlift.methods.dgp.discontinuous import FacetBlocks


def _disk(n):
    yy, xx = np.mgrid[:n, :n]
    return (yy - n / 2) ** 2 + (xx - n / 2) ** 2 < (0.45 * n) ** 2


def _facet_system(mask, seed=0):
    d = Domain(mask)
    rng = np.random.default_rng(seed)
    blocks = np.eye(4) - 0.25  # slope + twist of a facet, scaled per facet below
    Q = np.tile(blocks, (d.n_facets, 1, 1)) * rng.uniform(0.5, 2.0, (d.n_facets, 1, 1))
    return d, FacetBlocks(d).assemble(Q)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (5, 5), (13, 8), (40, 3)])
def test_is_a_permutation(shape):
    r, c = np.nonzero(np.ones(shape, bool))
    p = nested_dissection(r + 3, c - 2, leaf=4)  # (any offset of the positions)
    assert np.array_equal(np.sort(p), np.arange(r.size))


def test_masked_and_empty():
    ring = _disk(50)
    ring[15:35, 15:35] &= ~_disk(20)  # a disk with a hole
    r, c = np.nonzero(ring)
    p = nested_dissection(r, c)
    assert np.array_equal(np.sort(p), np.arange(r.size))
    assert nested_dissection(np.zeros(0, int), np.zeros(0, int)).size == 0
    with pytest.raises(ValueError, match="rows.*cols"):
        nested_dissection(np.zeros(3, int), np.zeros(4, int))


def test_the_middle_line_comes_last_and_the_halves_before_it():
    """On a 7 x 9 grid the longer side (columns) is split by column 4: its 7 positions come
    last, every position left of it before every one right of it; each half is split by its
    middle row next (3 x 7 halves: 4 columns x 7 rows, rows split at 3)."""
    r, c = np.nonzero(np.ones((7, 9), bool))
    p = nested_dissection(r, c, leaf=4)
    rc, cc = r[p], c[p]
    assert np.all(cc[-7:] == 4)
    left = np.flatnonzero(cc < 4)
    right = np.flatnonzero(cc > 4)
    assert left.max() < right.min()
    # the left half's own separator (row 3 of columns 0-3) ends the left half
    assert np.all(rc[left[-4:]] == 3) and np.all(cc[left[-4:]] < 4)


def test_every_separator_separates():
    """The defining property: a position never couples (9-point stencil) with one ordered
    after it unless one of the two is a separator line of a box holding both, i.e. the
    elimination graph stays small -- measured as the factor's fill against the natural order
    and against SuperLU's minimum degree on a masked facet system."""
    d, K = _facet_system(_disk(128))
    opts = dict(diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    p = nested_dissection(*d.vertices)
    nd = spla.splu(sp.csc_matrix(K[p][:, p]), permc_spec="NATURAL", **opts).nnz
    natural = spla.splu(sp.csc_matrix(K), permc_spec="NATURAL", **opts).nnz
    mmd = spla.splu(sp.csc_matrix(K), permc_spec="MMD_AT_PLUS_A", **opts).nnz
    assert nd < 0.5 * natural
    assert nd < 1.05 * mmd  # (measured 0.97 at this size, 0.80 at 512^2)


def test_superlu_on_the_grid_solves_the_same_system():
    d, K = _facet_system(_disk(60) | (np.arange(60)[None, :] < 5))
    K = (K + sp.eye(K.shape[0]) * 1e-3).tocsr()
    b = np.random.default_rng(1).standard_normal(K.shape[0])
    x_mmd, info = linalg.solve(K, b, "superlu")
    x_nd, info_nd = linalg.solve(K, b, "superlu", grid=d.vertices)
    assert info.backend == info_nd.backend == "superlu"
    assert np.linalg.norm(K @ x_nd - b) <= 1e-10 * np.linalg.norm(b)
    assert np.allclose(x_nd, x_mmd, rtol=0, atol=1e-9 * np.abs(x_mmd).max())
    two = np.stack([b, 2 * b], axis=1)  # several right-hand sides at once
    f = linalg.factorize(K, "superlu", grid=d.vertices)
    assert np.allclose(f.solve(two)[:, 1], 2 * x_nd)
    with pytest.raises(ValueError, match="grid"):
        linalg.solve(K, b, "superlu", grid=(d.vertices[0][1:], d.vertices[1][1:]))


def _paths_of(r, c, leaf):
    """Each position's path of halves and lines, decoded from the order's sort key."""
    from facetlift.linalg.ordering import _paths

    key, stop, schedule, _, _ = _paths(r, c, leaf)
    total = len(schedule)
    digits = np.stack([(key // 3 ** (total - 1 - level)) % 3 for level in range(total)], axis=1)
    return digits, stop


@pytest.mark.parametrize("seed", range(6))
def test_no_coupling_crosses_a_separator(seed):
    """The defining property of the order: two positions that couple (at most one row and one
    column apart) never lie in the two different halves of a box, i.e. their paths never first
    differ as 0 (lower half) against 1 (upper half); and every path is zero after its end."""
    rng = np.random.default_rng(seed)
    H, W = rng.integers(5, 70, size=2)
    mask = rng.random((H, W)) < rng.uniform(0.3, 1.0)
    r, c = np.nonzero(mask)
    off = rng.integers(-1000, 1000, size=2)
    digits, stop = _paths_of(r + off[0], c + off[1], leaf=int(rng.choice([1, 4, 16])))
    idx = np.full((H + 2, W + 2), -1)
    idx[r + 1, c + 1] = np.arange(r.size)
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        other = idx[r + 1 + dr, c + 1 + dc]
        a, b = np.flatnonzero(other >= 0), other[other >= 0]
        if a.size == 0:
            continue
        da, db = digits[a], digits[b]
        differ = da != db
        first = np.argmax(differ, axis=1)
        some = differ.any(axis=1)
        pair = np.sort(np.stack([da[np.arange(a.size), first], db[np.arange(a.size), first]]), 0)
        assert not np.any(some & (pair[0] == 0) & (pair[1] == 1))
    levels = np.arange(digits.shape[1])[None, :]
    assert np.all(digits[levels >= stop[:, None]] == 0)


def test_superlu_factorizes_in_the_grid_order(monkeypatch):
    """With `grid` SuperLU is given the nested-dissection order (natural column order)."""
    from facetlift.linalg import direct

    d, K = _facet_system(_disk(40))
    K = (K + sp.eye(K.shape[0]) * 1e-3).tocsr()
    seen = []
    real = spla.splu

    def spy(A, permc_spec=None, **kw):
        seen.append(permc_spec)
        return real(A, permc_spec=permc_spec, **kw)

    monkeypatch.setattr(spla, "splu", spy)
    direct.superlu(K)
    f = direct.superlu(K, d.vertices)
    assert seen == ["MMD_AT_PLUS_A", "NATURAL"]
    x = np.random.default_rng(0).standard_normal(K.shape[0])
    assert np.allclose(K @ f.solve(x), x)
    order = nested_dissection(*d.vertices)
    assert not np.array_equal(order, np.arange(order.size))  # (a real reordering)
