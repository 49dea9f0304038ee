"""Integration domain: mask -> facets, vertices and connected components.

See :mod:`facetlift.conventions` for the facet/vertex layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .conventions import CORNER_OFFSETS

_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, eq=False)
class Domain:
    """The facets (domain pixels) and vertices of a mask.

    Attributes
    ----------
    mask : (H, W) bool
        Domain pixels; facet ``k`` is the ``k``-th True pixel in row-major order.
    """

    mask: np.ndarray

    @classmethod
    def from_mask(cls, mask: np.ndarray) -> Domain:
        mask = np.array(mask, dtype=bool, order="C", copy=True)
        mask.setflags(write=False)
        return cls(mask)

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape

    @cached_property
    def pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the facets, each (m,) int64, row-major."""
        return np.nonzero(self.mask)

    @property
    def n_facets(self) -> int:
        return int(self.pixels[0].size)

    @cached_property
    def vertex_mask(self) -> np.ndarray:
        """(H+1, W+1) bool: vertices touched by at least one facet."""
        H, W = self.shape
        vm = np.zeros((H + 1, W + 1), dtype=bool)
        for dr, dc in CORNER_OFFSETS:
            vm[dr : dr + H, dc : dc + W] |= self.mask
        return vm

    @cached_property
    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the used vertices on the (H+1, W+1) grid, each (n,), in vertex-index
        order (row-major)."""
        return np.nonzero(self.vertex_mask)

    @cached_property
    def vertex_index(self) -> np.ndarray:
        """(H+1, W+1) int64: index of each used vertex, -1 elsewhere."""
        vi = np.full(self.vertex_mask.shape, -1, dtype=np.int64)
        vi[self.vertex_mask] = np.arange(int(self.vertex_mask.sum()))
        return vi

    @property
    def n_vertices(self) -> int:
        return int(self.vertex_mask.sum())

    @cached_property
    def corners(self) -> np.ndarray:
        """(m, 4) int64 vertex indices of each facet's corners, in the conventional order."""
        H, W = self.shape
        vi = self.vertex_index
        out = np.empty((self.n_facets, 4), dtype=np.int64)
        for k, (dr, dc) in enumerate(CORNER_OFFSETS):
            out[:, k] = vi[dr : dr + H, dc : dc + W][self.mask]
        return out

    @cached_property
    def _labels(self) -> tuple[np.ndarray, int]:
        import scipy.ndimage as ndi

        labels, n = ndi.label(self.mask, structure=_EIGHT)
        return labels, int(n)

    @property
    def labels(self) -> np.ndarray:
        """(H, W) int: component label per pixel (1..n_components), 0 outside."""
        return self._labels[0]

    @property
    def n_components(self) -> int:
        return self._labels[1]

    @cached_property
    def facet_component(self) -> np.ndarray:
        """(m,) int: zero-based component of each facet."""
        r, c = self.pixels
        return self.labels[r, c] - 1

    @cached_property
    def vertex_component(self) -> np.ndarray:
        """(n,) int: zero-based component of each vertex."""
        # the facets around a vertex touch at it, so they share one 8-connected component:
        # the largest label of the four is that component (image slicing, no (m, 4) gather)
        H, W = self.shape
        lab = self.labels
        v = np.zeros((H + 1, W + 1), dtype=lab.dtype)
        for dr, dc in CORNER_OFFSETS:
            view = v[dr : dr + H, dc : dc + W]
            np.maximum(view, lab, out=view)
        return v[self.vertex_mask].astype(np.int64) - 1

    @cached_property
    def first_facets(self) -> np.ndarray:
        """(n_components,) lowest facet index of each component."""
        return _first_of(self.facet_component, self.n_components)

    @cached_property
    def first_vertices(self) -> np.ndarray:
        """(n_components,) lowest vertex index of each component."""
        return _first_of(self.vertex_component, self.n_components)

    @cached_property
    def component_sizes(self) -> np.ndarray:
        """(n_components,) number of facets in each component."""
        return np.bincount(self.facet_component, minlength=self.n_components)

    @cached_property
    def gather(self):
        """(4m, n) sparse 0/1 CSR matrix C: row 4k+i picks corner i of facet k."""
        import scipy.sparse as sp

        m, n = self.n_facets, self.n_vertices
        data = np.ones(4 * m)
        indptr = np.arange(4 * m + 1)
        return sp.csr_matrix((data, self.corners.ravel(), indptr), shape=(4 * m, n))

    def component_facets(self, shared: float | None = None) -> list:
        """The facets of each connected component, (k,) index arrays in component order; with
        `shared`, one array of every facet instead where the components' bounding boxes add
        up to more than `shared` times the union box's area (a method working box by box
        then does the union box once: interleaved stripes each span nearly all of it)."""
        order = np.argsort(self.facet_component, kind="stable")
        groups = np.split(order, np.cumsum(self.component_sizes)[:-1])
        if shared is not None and len(groups) > 1:
            r, c = self.pixels
            area = sum(int(np.ptp(r[f]) + 1) * int(np.ptp(c[f]) + 1) for f in groups)
            if area > shared * int(np.ptp(r) + 1) * int(np.ptp(c) + 1):
                return [np.arange(self.n_facets)]
        return groups

    def facet_operator(self, weights4: np.ndarray):
        """(m, n) sparse CSR matrix whose row k is ``weights4 . z[corners[k]]``."""
        import scipy.sparse as sp

        m, n = self.n_facets, self.n_vertices
        data = np.broadcast_to(np.asarray(weights4, dtype=float), (m, 4)).ravel()
        indptr = np.arange(0, 4 * m + 1, 4)
        return sp.csr_matrix((data, self.corners.ravel(), indptr), shape=(m, n))

    def facet_centres(self, vertex_values: np.ndarray) -> np.ndarray:
        """(m,) mean of each facet's four corner values."""
        return vertex_values[self.corners].mean(axis=1)

    def to_image(self, facet_values: np.ndarray, fill=np.nan) -> np.ndarray:
        """Scatter (m,) facet values into an (H, W) image, `fill` outside the domain."""
        out = np.full(self.shape, fill, dtype=np.result_type(facet_values, float))
        out[self.pixels] = facet_values
        return out

    def to_vertex_image(self, vertex_values: np.ndarray, fill=np.nan) -> np.ndarray:
        """Scatter (n,) vertex values into an (H+1, W+1) image, `fill` where unused."""
        out = np.full(self.vertex_mask.shape, fill, dtype=np.result_type(vertex_values, float))
        out[self.vertex_mask] = vertex_values
        return out


def _first_of(component: np.ndarray, n: int) -> np.ndarray:
    first = np.full(n, -1, dtype=np.int64)
    order = np.arange(component.size)[::-1]
    first[component[order]] = order  # the last write per component is its lowest index
    return first
