"""A domain's facet mesh split along cut edges: vertices duplicated per side of a jump.

A depth jump between two neighbouring pixels means their facets must not share the two
vertices on their common edge. Given the set of *cut* edges (between 4-neighbouring pixels),
every vertex of the facet grid is split into groups: the facets around it that stay joined by
uncut edges share one copy of the vertex, the others get their own (:func:`split`). The
pieces of the split mesh are its connected parts. :func:`from_copies` derives the cut edges
from per-facet corner values (where two facets' copies of a shared vertex part), which is how
a discontinuity-preserving result becomes a mesh that is split at its jumps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..domain import Domain

#: Facets whose copies of a shared vertex differ by more than this many pixel footprints are
#: cut apart (:func:`from_copies`; the mesh of a discontinuity-preserving Surface).
GAP = 0.5

#: Slots of the four facets around a vertex: top-left, top-right, bottom-left, bottom-right.
TL, TR, BL, BR = 0, 1, 2, 3
#: Which slot a facet occupies at each of its corners 0..3 (conventional corner order).
CORNER_SLOT = (BR, BL, TL, TR)


@dataclass(frozen=True, eq=False)
class SplitMesh:
    """A domain's facet mesh with its vertices split along cut edges.

    Attributes
    ----------
    domain : Domain
    corners : (m, 4) int64
        Split-vertex index of every facet corner (conventional order).
    n_vertices : int
    vertex : (n_vertices,) int64
        The grid vertex (index into ``domain.vertex_index``) each split vertex is a copy of.
    piece : (n_vertices,) int64
        Connected piece of the split mesh of each split vertex (facets joined through shared
        split vertices), 0-based.
    n_pieces : int
    facet_piece : (m,) int64
    cut_pairs : (c, 2) int64
        Pairs of split vertices that are copies of one grid vertex on the two sides of a cut
        edge.
    right, down : bool arrays (H, W-1) and (H-1, W)
        The cut edges: between pixel (r, c) and (r, c+1), and between (r, c) and (r+1, c).
    """

    domain: Domain
    corners: np.ndarray
    n_vertices: int
    vertex: np.ndarray
    piece: np.ndarray
    n_pieces: int
    facet_piece: np.ndarray
    cut_pairs: np.ndarray
    right: np.ndarray
    down: np.ndarray

    def values_of(self, copies: np.ndarray) -> np.ndarray:
        """(n_vertices,) mean of the per-facet corner values `copies` (m, 4) that share each
        split vertex."""
        flat = self.corners.ravel()
        counts = np.bincount(flat, minlength=self.n_vertices)
        return np.bincount(flat, np.ravel(copies), self.n_vertices) / counts

    @property
    def n_cut_edges(self) -> int:
        inside_r = self.domain.mask[:, :-1] & self.domain.mask[:, 1:]
        inside_d = self.domain.mask[:-1] & self.domain.mask[1:]
        return int((self.right & inside_r).sum() + (self.down & inside_d).sum())


def split(domain: Domain, right=None, down=None) -> SplitMesh:
    """Split the facet mesh of `domain` along the cut edges `right` (H, W-1) and `down`
    (H-1, W) (see :class:`SplitMesh`); None means no cut in that direction."""
    mask = domain.mask
    H, W = mask.shape
    right = np.zeros((H, W - 1), bool) if right is None else np.asarray(right, bool)
    down = np.zeros((H - 1, W), bool) if down is None else np.asarray(down, bool)
    if right.shape != (H, W - 1) or down.shape != (H - 1, W):
        raise ValueError(
            f"cut edges must have shapes {(H, W - 1)} and {(H - 1, W)}; got {right.shape} "
            f"and {down.shape}"
        )
    mp = np.pad(mask, 1)
    rp = np.pad(right, 1)  # rp[r + 1, c + 1] = right[r, c]
    dp = np.pad(down, 1)
    # per grid vertex (i, j), i in 0..H, j in 0..W: the four facets around it
    present = np.stack([mp[:-1, :-1], mp[:-1, 1:], mp[1:, :-1], mp[1:, 1:]], axis=-1)
    big = np.int8(8)
    lab = np.where(present, np.arange(4, dtype=np.int8), big)  # (int8: 8x less traffic)
    joined = {  # slot pair -> edge between the two facets is in the mask and not cut
        (TL, TR): ~rp[:-1, :],
        (BL, BR): ~rp[1:, :],
        (TL, BL): ~dp[:, :-1],
        (TR, BR): ~dp[:, 1:],
    }
    links = []
    for (a, b), uncut in joined.items():
        links.append((a, b, present[..., a] & present[..., b] & uncut))
    # facets touching only at this corner (a pinch of the mask) stay joined
    links.append((TL, BR, present[..., TL] & present[..., BR] & ~present[..., TR]
                  & ~present[..., BL]))
    links.append((TR, BL, present[..., TR] & present[..., BL] & ~present[..., TL]
                  & ~present[..., BR]))
    for _ in range(3):  # a cycle of four slots: three passes reach every slot
        for a, b, on in links:
            low = np.minimum(lab[..., a], lab[..., b])
            lab[..., a] = np.where(on, low, lab[..., a])
            lab[..., b] = np.where(on, low, lab[..., b])
    vi = domain.vertex_index
    key = (vi[..., None] * 4 + lab.astype(np.int64))[present]  # < 4 n_vertices
    # the used keys, sorted, and every key's rank among them: a mark-and-count pass over the
    # key range (np.unique + searchsorted took 2.5 s per call at 1024^2)
    mark = np.zeros(4 * domain.n_vertices, dtype=bool)
    mark[key] = True
    used = np.flatnonzero(mark)
    n = used.size
    sidx = np.full(present.shape, -1, dtype=np.int64)
    sidx[present] = (np.cumsum(mark) - 1)[key]
    # facet corners: facet (r, c) sits in slot CORNER_SLOT[k] of its corner vertex k
    r, c = domain.pixels
    offsets = ((0, 0), (0, 1), (1, 1), (1, 0))
    corners = np.stack(
        [sidx[r + dr, c + dc, CORNER_SLOT[k]] for k, (dr, dc) in enumerate(offsets)], axis=1
    )
    vertex = used // 4
    # cut pairs: two present slots around a vertex, joined in the mask but on two sides of a cut
    pairs = []
    for (a, b), uncut in joined.items():
        sel = present[..., a] & present[..., b] & ~uncut & (sidx[..., a] != sidx[..., b])
        pairs.append(np.stack([sidx[..., a][sel], sidx[..., b][sel]], axis=1))
    cut_pairs = np.unique(np.sort(np.concatenate(pairs), axis=1), axis=0) if pairs else \
        np.zeros((0, 2), np.int64)
    piece, n_pieces = _pieces(corners, n)
    return SplitMesh(
        domain=domain, corners=corners, n_vertices=int(n), vertex=vertex, piece=piece,
        n_pieces=n_pieces, facet_piece=piece[corners[:, 0]], cut_pairs=cut_pairs,
        right=right, down=down,
    )


def _pieces(corners: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """Connected pieces of the split vertices, joined by the facets (each facet's corners
    chained by three edges: a third of the entries of the incidence product ``C^T C``)."""
    m = corners.shape[0]
    graph = sp.csr_matrix((np.ones(3 * m, np.int8), (corners[:, :3].ravel(),
                                                     corners[:, 1:].ravel())), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64), int(count)


def from_copies(domain: Domain, copies: np.ndarray, gap: float):
    """The split mesh of per-facet corner values and its vertex values.

    Parameters
    ----------
    domain : Domain
    copies : (m, 4) float
        Every facet's own value at its corners (conventional order).
    gap : float
        Two 4-neighbouring facets are cut apart where their copies of a shared vertex differ by
        more than this.

    Returns
    -------
    mesh : SplitMesh
    values : (mesh.n_vertices,) float
        Mean of the copies that share each split vertex.
    """
    H, W = domain.shape
    img = np.full((H, W, 4), np.nan)
    img[domain.pixels] = copies
    # right edge of (r, c): its corners 1 (top-right) and 2 (bottom-right) against the
    # neighbour's 0 (top-left) and 3 (bottom-left); down edge: corners 3, 2 against 0, 1
    with np.errstate(invalid="ignore"):
        right = np.maximum(np.abs(img[:, :-1, 1] - img[:, 1:, 0]),
                           np.abs(img[:, :-1, 2] - img[:, 1:, 3])) > gap
        down = np.maximum(np.abs(img[:-1, :, 3] - img[1:, :, 0]),
                          np.abs(img[:-1, :, 2] - img[1:, :, 1])) > gap
    mesh = split(domain, right, down)
    return mesh, mesh.values_of(copies)
