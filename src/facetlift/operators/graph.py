"""Pixel-graph difference operators on a masked domain (operators only, no policy).

The comparison methods of Agrawal, Raskar & Chellappa (Poisson, alpha-surface, M-estimator,
regularization, diffusion) work on the graph whose nodes are the domain pixels (in
``domain.pixels`` order) and whose unknown is a camera's unknown at the pixel centres (height
or log-depth, :mod:`facetlift.camera`), with per-pixel grid slopes ``(gx, gy)``: the change of
the unknown per pixel step along ``x`` (right) and ``y`` (up).

Edges
    ``horizontal`` ``(r, c) -> (r, c+1)`` and ``vertical`` ``(r, c) -> (r+1, c)`` between
    4-neighbours that are both in the mask (the natural, Neumann boundary: no edge leaves the
    mask). facetlift's :class:`~facetlift.domain.Domain` joins pixels that only touch at a
    corner (8-connectivity) into one component, but the 4-neighbour graph does not. Every such
    *pinch* -- two diagonal neighbours in the mask whose two common 4-neighbours are both
    outside it, and which lie in different 4-connected components -- gets a ``diagonal`` edge
    ``(r, c) -> (r+1, c+-1)``, so the graph is connected exactly when the domain component is
    and one constant per domain component fixes the solution. Pinch edges carry the data term
    of their two samples like any other edge (they are usually bridges, which least squares
    satisfies exactly).

Edge targets
    Edge ``e`` from tail ``i`` to head ``j`` with pixel offset ``(dx, dy)`` (``x`` right, ``y``
    up, in pixels) measures ``z_j - z_i ~ t_e = dx gx + dy gy`` averaged over the two samples;
    when one sample is missing the other one is used (a first-order estimate); when both are
    missing the edge carries no data (``has_data`` False). For the saddle or any quadratic the
    two-sample average is exact (trapezoid rule), so every method here recovers quadratics to
    rounding error.

Constants
    The constant of each domain component is fixed by a unit diagonal term at its first pixel
    (:func:`pin`), which changes nothing else because the right-hand side of the normal
    equations is orthogonal to the constants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from ..domain import Domain

HORIZONTAL, VERTICAL, DIAGONAL = 0, 1, 2
FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)


@dataclass(frozen=True, eq=False)
class PixelGraph:
    """Edges of the pixel graph of a domain.

    Attributes
    ----------
    n : int
        Number of nodes (domain pixels, ``domain.pixels`` order).
    tail, head : (E,) int64
        Node indices of each edge; the edge measures ``z[head] - z[tail]``.
    dx, dy : (E,) int8
        Pixel offset from tail to head with ``x`` right and ``y`` up: (1, 0) horizontal,
        (0, -1) vertical, (+-1, -1) diagonal.
    kind : (E,) int8
        ``HORIZONTAL``, ``VERTICAL`` or ``DIAGONAL``.
    right, down : (n,) int64
        Index of the horizontal edge to the right of / vertical edge below each pixel, -1 if none.
    left, up : (n,) int64
        Index of the horizontal edge to the left of / vertical edge above each pixel, -1 if none.
    loops : (L, 4) int64
        The 2x2 pixel blocks inside the mask, as edges (top, right, bottom, left): top and
        bottom horizontal, left and right vertical.
    """

    n: int
    tail: np.ndarray
    head: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    kind: np.ndarray
    right: np.ndarray
    left: np.ndarray
    down: np.ndarray
    up: np.ndarray
    loops: np.ndarray

    @property
    def n_edges(self) -> int:
        return int(self.tail.size)


def build(domain: Domain) -> PixelGraph:
    """The pixel graph of `domain` (vectorised; see the module docstring)."""
    mask = domain.mask
    H, W = mask.shape
    m = domain.n_facets
    idx = np.full((H, W), -1, dtype=np.int64)
    idx[domain.pixels] = np.arange(m)

    hmask = mask[:, :-1] & mask[:, 1:]  # edge (r, c) -> (r, c+1)
    vmask = mask[:-1, :] & mask[1:, :]  # edge (r, c) -> (r+1, c)
    hr, hc = np.nonzero(hmask)
    vr, vc = np.nonzero(vmask)
    nh, nv = hr.size, vr.size
    tails = [idx[hr, hc], idx[vr, vc]]
    heads = [idx[hr, hc + 1], idx[vr + 1, vc]]
    dxs = [np.ones(nh), np.zeros(nv)]
    dys = [np.zeros(nh), -np.ones(nv)]
    kinds = [np.full(nh, HORIZONTAL), np.full(nv, VERTICAL)]

    # pinch diagonals between different 4-connected components
    lab4, _ = ndi.label(mask, structure=FOUR)
    a, b = mask[:-1, :-1], mask[1:, 1:]  # (r, c) -> (r+1, c+1)
    pr, pc = np.nonzero(a & b & ~mask[:-1, 1:] & ~mask[1:, :-1])
    keep = lab4[pr, pc] != lab4[pr + 1, pc + 1]
    pr, pc = pr[keep], pc[keep]
    a, b = mask[:-1, 1:], mask[1:, :-1]  # (r, c+1) -> (r+1, c)
    qr, qc = np.nonzero(a & b & ~mask[:-1, :-1] & ~mask[1:, 1:])
    keep = lab4[qr, qc + 1] != lab4[qr + 1, qc]
    qr, qc = qr[keep], qc[keep]
    tails += [idx[pr, pc], idx[qr, qc + 1]]
    heads += [idx[pr + 1, pc + 1], idx[qr + 1, qc]]
    dxs += [np.ones(pr.size), -np.ones(qr.size)]
    dys += [-np.ones(pr.size), -np.ones(qr.size)]
    kinds += [np.full(pr.size + qr.size, DIAGONAL)]

    himg = np.full((H, max(W - 1, 0)), -1, dtype=np.int64)
    himg[hr, hc] = np.arange(nh)
    vimg = np.full((max(H - 1, 0), W), -1, dtype=np.int64)
    vimg[vr, vc] = nh + np.arange(nv)
    r, c = domain.pixels
    right = np.full(m, -1, dtype=np.int64)
    left = np.full(m, -1, dtype=np.int64)
    down = np.full(m, -1, dtype=np.int64)
    up = np.full(m, -1, dtype=np.int64)
    s = c < W - 1
    right[s] = himg[r[s], c[s]]
    s = c > 0
    left[s] = himg[r[s], c[s] - 1]
    s = r < H - 1
    down[s] = vimg[r[s], c[s]]
    s = r > 0
    up[s] = vimg[r[s] - 1, c[s]]

    block = hmask[:-1, :] & hmask[1:, :] & vmask[:, :-1] & vmask[:, 1:]
    br, bc = np.nonzero(block)
    loops = np.stack(
        [himg[br, bc], vimg[br, bc + 1], himg[br + 1, bc], vimg[br, bc]], axis=1
    ).astype(np.int64)

    return PixelGraph(
        n=m,
        tail=np.concatenate(tails).astype(np.int64),
        head=np.concatenate(heads).astype(np.int64),
        dx=np.concatenate(dxs).astype(np.int8),
        dy=np.concatenate(dys).astype(np.int8),
        kind=np.concatenate(kinds).astype(np.int8),
        right=right,
        left=left,
        down=down,
        up=up,
        loops=loops.reshape(-1, 4),
    )


def targets(graph: PixelGraph, gx: np.ndarray, gy: np.ndarray):
    """Measured differences of the unknown along the edges.

    Parameters
    ----------
    graph : PixelGraph
    gx, gy : (n,) float
        Grid slopes per pixel (change of the unknown per pixel step along x right and y up),
        NaN where unknown.

    Returns
    -------
    t : (E,) float
        ``dx gx + dy gy`` averaged over the edge's known samples; 0 where it has none.
    has_data : (E,) bool
        Whether at least one of the two samples is known.
    """
    dx = graph.dx.astype(float)
    dy = graph.dy.astype(float)
    si = dx * gx[graph.tail] + dy * gy[graph.tail]
    sj = dx * gx[graph.head] + dy * gy[graph.head]
    ki, kj = np.isfinite(si), np.isfinite(sj)
    total = np.where(ki, si, 0.0) + np.where(kj, sj, 0.0)
    count = ki.astype(float) + kj
    has = count > 0
    t = np.zeros(graph.n_edges)
    t[has] = total[has] / count[has]
    return t, has


def difference(graph: PixelGraph) -> sp.csr_matrix:
    """(E, n) sparse matrix ``G`` with ``(G z)_e = z[head_e] - z[tail_e]``."""
    E = graph.n_edges
    rows = np.repeat(np.arange(E), 2)
    cols = np.stack([graph.tail, graph.head], axis=1).ravel()
    vals = np.tile([-1.0, 1.0], E)
    return sp.csr_matrix((vals, (rows, cols)), shape=(E, graph.n))


def laplacian(graph: PixelGraph, w: np.ndarray) -> sp.csr_matrix:
    """(n, n) weighted graph Laplacian ``G^T diag(w) G``."""
    n = graph.n
    i, j = graph.tail, graph.head
    deg = np.bincount(i, w, n) + np.bincount(j, w, n)
    rows = np.concatenate([i, j, np.arange(n)])
    cols = np.concatenate([j, i, np.arange(n)])
    vals = np.concatenate([-w, -w, deg])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def divergence(graph: PixelGraph, wt: np.ndarray) -> np.ndarray:
    """(n,) ``G^T wt``: the right-hand side of the weighted normal equations."""
    n = graph.n
    return np.bincount(graph.head, wt, n) - np.bincount(graph.tail, wt, n)


def pin(domain: Domain, K: sp.spmatrix, weight: float = 1.0, skip=None) -> sp.csr_matrix:
    """Add `weight` to the diagonal at the first pixel of every domain component (but those
    where `skip` (n_components,) bool is True: a prior fixes their constant)."""
    d = np.zeros(domain.n_facets)
    first = domain.first_facets if skip is None else domain.first_facets[~np.asarray(skip)]
    d[first] = weight
    return (K + sp.diags(d, format="csr")).tocsr()


def residuals(graph: PixelGraph, z: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(E,) ``z[head] - z[tail] - t``."""
    return z[graph.head] - z[graph.tail] - t


def curl(graph: PixelGraph, t: np.ndarray, has_data: np.ndarray):
    """Circulation of the measured differences around every 2x2 loop.

    Returns
    -------
    c : (L,) float
        ``t_top + t_right - t_bottom - t_left`` (grid units; divide by the camera footprint
        for slope units);
        the sum of the target differences going round the loop, zero for integrable data.
    valid : (L,) bool
        Loops whose four edges all carry data.
    """
    L = graph.loops
    c = t[L[:, 0]] + t[L[:, 1]] - t[L[:, 2]] - t[L[:, 3]]
    valid = has_data[L].all(axis=1)
    return np.where(valid, c, 0.0), valid


