"""Sparse quadratic forms that sum 4x4 per-facet blocks on the vertex grid.

A facet term ``w_f * z_f^T Q z_f`` (``z_f`` the four corner values of facet ``f`` in the
conventional order) contributes ``w_f Q[a, b]`` to entry ``(corner a, corner b)``. Summed over
facets this is a 9-point stencil on the vertex grid, accumulated here with 16 grid-slice adds
and turned into CSR without a COO sort, so assembly is linear in the domain size.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..conventions import CORNER_OFFSETS
from ..domain import Domain

#: Orthonormal basis of facet corner vectors: mean, x-slope, y-slope, twist.
E_MEAN = np.array([1.0, 1.0, 1.0, 1.0]) / 2
E_X = np.array([-1.0, 1.0, 1.0, -1.0]) / 2
E_Y = np.array([1.0, 1.0, -1.0, -1.0]) / 2
E_TWIST = np.array([1.0, -1.0, 1.0, -1.0]) / 2

#: Mean subtraction N = I - 11^T / 4 (Eq. 5 of Xie et al.).
N_MEAN_FREE = np.eye(4) - np.full((4, 4), 0.25)


def facet_form(domain: Domain, terms) -> sp.csr_matrix:
    """Assemble ``sum_f sum_t w_t[f] z_f^T Q_t z_f`` as an (n, n) CSR matrix.

    Parameters
    ----------
    domain : Domain
    terms : iterable of (w, Q)
        ``w`` is a scalar or (m,) per-facet weights, ``Q`` a symmetric (4, 4) block.

    Notes
    -----
    One stencil offset at a time: the coefficient image of an offset is the sum, over the
    corner pairs ``(a, b)`` at that offset, of ``sum_t Q_t[a, b] w_t`` shifted to corner
    ``a``; it is gathered at the domain's vertices into column ``k`` of an (n, 9) table and
    dropped, so that the peak is the table plus one image (not nine), and the table is
    compacted into CSR in row blocks.
    """
    H, W = domain.shape
    weights = []
    for w, Q in terms:
        if np.isscalar(w):
            img = domain.mask * float(w)
        else:
            img = np.zeros((H, W))
            img[domain.mask] = w
        weights.append((img, np.asarray(Q, dtype=float)))
    vm = domain.vertex_mask
    n = domain.n_vertices
    vals = np.empty((n, 9))
    acc = np.empty((H + 1, W + 1))
    cache = {}  # blocks like N have few distinct entries: build each coefficient image once
    for k, (dr, dc) in enumerate((di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1)):
        acc[:] = 0.0
        for a, (ra, ca) in enumerate(CORNER_OFFSETS):
            for b, (rb, cb) in enumerate(CORNER_OFFSETS):
                if (rb - ra, cb - ca) != (dr, dc):
                    continue
                key = tuple(float(Q[a, b]) for _, Q in weights)
                if not any(key):
                    continue
                if key not in cache:
                    pairs = zip(key, weights, strict=True)
                    cache[key] = sum(c * img for c, (img, _) in pairs if c != 0)
                acc[ra : ra + H, ca : ca + W] += cache[key]
        vals[:, k] = acc[vm]
    del acc, cache, weights
    return _table_to_csr(domain, vals)


#: Rows per block when the (n, 9) stencil table is compacted into CSR.
_BLOCK = 1 << 16


def _table_to_csr(domain: Domain, vals: np.ndarray) -> sp.csr_matrix:
    """CSR from an (n, 9) table of the 9-point stencil at each vertex (row-major offsets, so
    each row's columns come out sorted); zeros are dropped except on the diagonal."""
    vi = domain.vertex_index
    vm = domain.vertex_mask
    n = domain.n_vertices
    Hv, Wv = vi.shape
    idx = np.int32 if (Hv + 2) * (Wv + 2) < 2**31 - 1 else np.int64
    padded = np.pad(vi.astype(idx), 1, constant_values=-1).ravel()
    pos = np.flatnonzero(np.pad(vm, 1).ravel()).astype(idx)
    offsets = np.array([di * (Wv + 2) + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)], dtype=idx)

    def block(lo, hi):
        cols = padded[pos[lo:hi, None] + offsets]
        keep = (cols >= 0) & (vals[lo:hi] != 0)
        keep[:, 4] = True  # the diagonal, even where zero
        return cols, keep

    # two passes over row blocks (count, then fill): no full-size temporaries besides the
    # table and the result
    counts = np.empty(n, dtype=np.int64)
    for lo in range(0, n, _BLOCK):
        counts[lo : lo + _BLOCK] = block(lo, min(lo + _BLOCK, n))[1].sum(axis=1)
    nnz = int(counts.sum())
    cidx = np.int32 if n < 2**31 - 1 and nnz < 2**31 - 1 else np.int64
    indptr = np.zeros(n + 1, dtype=cidx)
    np.cumsum(counts, out=indptr[1:])
    del counts
    data = np.empty(nnz)
    indices = np.empty(nnz, dtype=cidx)
    for lo in range(0, n, _BLOCK):
        hi = min(lo + _BLOCK, n)
        cols, keep = block(lo, hi)
        a, b = int(indptr[lo]), int(indptr[hi])
        data[a:b] = vals[lo:hi][keep]
        indices[a:b] = cols[keep]
    return sp.csr_matrix((data, indices, indptr), shape=(n, n))


def scatter_corners(domain: Domain, values: np.ndarray) -> np.ndarray:
    """``C^T v``: sum (m, 4) per-corner values onto the (n,) vertices."""
    return np.bincount(
        domain.corners.ravel(), weights=np.asarray(values, dtype=float).ravel(),
        minlength=domain.n_vertices,
    )


def pin_components(domain: Domain, K: sp.csr_matrix, weight: float = 1.0,
                   skip=None) -> sp.csr_matrix:
    """Add `weight` to the diagonal at one vertex per connected component (fixes the constant),
    except the components where `skip` (n_components,) bool is True (a prior fixes them)."""
    d = np.zeros(domain.n_vertices)
    first = domain.first_vertices if skip is None else domain.first_vertices[~np.asarray(skip)]
    d[first] = weight
    return (K + sp.diags(d, format="csr")).tocsr()


def corner_views(Z: np.ndarray):
    """The four (H, W) corner views of an (H+1, W+1) vertex image, in the conventional order."""
    return Z[:-1, :-1], Z[:-1, 1:], Z[1:, 1:], Z[1:, :-1]


def grid_slopes(Z: np.ndarray):
    """(e_x . z_f, e_y . z_f) of every facet of an (H+1, W+1) vertex image, as (H, W) images."""
    z0, z1, z2, z3 = corner_views(Z)
    s = z1 - z3
    d = z0 - z2
    return 0.5 * (s - d), 0.5 * (s + d)


def grid_scatter(gx: np.ndarray, gy: np.ndarray, centre: np.ndarray | None = None):
    """``C^T v`` on the vertex grid for facet vectors ``v_f = gx e_x + gy e_y (+ centre 1)``.

    `gx`, `gy` (and `centre`) are (H, W) facet images, zero outside the domain; returns the
    (H+1, W+1) vertex image. Equals :func:`scatter_corners` with grid slicing instead of a
    scattered sum.
    """
    H, W = gx.shape
    a = 0.5 * (gx + gy)
    b = 0.5 * (gx - gy)
    R = np.zeros((H + 1, W + 1))
    R[:-1, :-1] -= b
    R[:-1, 1:] += a
    R[1:, 1:] += b
    R[1:, :-1] -= a
    if centre is not None:
        for view in corner_views(R):
            view += centre
    return R


#: Facet block of a prior on the facet centre: ``(mean z_f)^2 = z_f^T (11^T / 16) z_f``.
CENTRE_BLOCK = np.full((4, 4), 1.0 / 16.0)


def prior_form(domain: Domain, weight: np.ndarray, target: np.ndarray, matrix: bool = True):
    """The prior term ``sum_f w_f (mean z_f - t_f)^2`` on the vertices: its matrix (n, n) CSR
    (``facet_form`` of :data:`CENTRE_BLOCK`) and right-hand side ``C^T (w t / 4)`` (n,); with
    ``matrix=False`` the right-hand side alone."""
    rhs = scatter_corners(domain, np.repeat((0.25 * weight * target)[:, None], 4, axis=1))
    if not matrix:
        return rhs
    return facet_form(domain, [(weight, CENTRE_BLOCK)]), rhs
