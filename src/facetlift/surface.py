"""The result of an integration: depth map, vertex depths, points and meshes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .domain import Domain


@dataclass(eq=False)
class Surface:
    """A reconstructed surface (see :mod:`facetlift.conventions`).

    Attributes
    ----------
    depth : (H, W) float
        Depth at facet centres (larger is farther), NaN outside the domain.
    vertex_depth : (H+1, W+1) float
        Depth at the facet corners, NaN where no facet touches.
    mask : (H, W) bool
        The integration domain.
    info : dict
        Method diagnostics: ``method``, ``iterations``, ``converged``, ``deviation`` (average
        angular deviation in degrees per iteration, where the method iterates), ``seconds``
        per phase, and method-specific entries.
    pixel_size : float
        Pixel width in world units (orthographic).
    K : (3, 3) float or None
        Intrinsics for a perspective surface.
    """

    depth: np.ndarray
    vertex_depth: np.ndarray
    mask: np.ndarray
    info: dict = field(default_factory=dict)
    pixel_size: float = 1.0
    K: np.ndarray | None = None

    @property
    def height(self) -> np.ndarray:
        """(H, W) height ``-depth`` (orthographic convention)."""
        return -self.depth

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape

    def _xyz(self, rows, cols, depth) -> np.ndarray:
        """World coordinates, x right, y up, z toward the viewer (z = -depth)."""
        if self.K is None:
            h = self.pixel_size
            return np.column_stack([cols * h, -rows * h, -depth])
        fx, s, cx = self.K[0]
        fy, cy = self.K[1, 1], self.K[1, 2]
        Y = (rows - cy) * depth / fy
        X = ((cols - cx) * depth - s * Y) / fx
        return np.column_stack([X, -Y, -depth])

    def points(self, where: str = "facets") -> np.ndarray:
        """(N, 3) points in a right-handed frame: x right, y up, z toward the viewer.

        ``where="facets"`` gives one point per domain pixel at its centre (row-major);
        ``"vertices"`` one per used vertex. Orthographic: ``(x, y) = (col, -row) * pixel_size``
        with the pixel centre at ``col + 0.5``; perspective: back-projected with `K` (pixel
        centres at integer indices, so a facet centre is at its pixel's index).
        """
        if where == "facets":
            r, c = np.nonzero(self.mask)
            d = self.depth[r, c]
            off = 0.5 if self.K is None else 0.0
            return self._xyz(r + off, c + off, d)
        if where == "vertices":
            vm = np.isfinite(self.vertex_depth)
            r, c = np.nonzero(vm)
            off = 0.0 if self.K is None else -0.5
            return self._xyz(r + off, c + off, self.vertex_depth[r, c])
        raise ValueError(f"`where` must be 'facets' or 'vertices'; got {where!r}")

    def to_mesh(self, triangles: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The facet mesh: vertices (n, 3) and faces (m, 4) quads or (2m, 3) triangles.

        Vertices are those of ``points("vertices")``; faces list corners counter-clockwise
        seen from the viewer, so face normals point toward the viewer.
        """
        domain = Domain.from_mask(self.mask)
        verts = self.points("vertices")
        # conventional corner order (r,c),(r,c+1),(r+1,c+1),(r+1,c) is clockwise seen from the
        # viewer (y up); reverse it for outward (viewer-facing) normals
        quads = domain.corners[:, ::-1]
        if not triangles:
            return verts, quads
        a, b, c, d = quads.T
        # split along the diagonal from (r+1, c) to (r, c+1)
        tris = np.empty((2 * len(quads), 3), dtype=quads.dtype)
        tris[0::2] = np.column_stack([a, b, c])
        tris[1::2] = np.column_stack([a, c, d])
        return verts, tris

    def save(self, path, **kwargs) -> Path:
        """Write the surface; the format follows the extension.

        ``.npy``, ``.exr``, ``.tif``/``.tiff``: the depth map (float32 for EXR/TIFF);
        ``.npz``: depth, vertex depth and mask; ``.ply``/``.obj``: the mesh (quads, or
        triangles with ``triangles=True``); ``.png``: a shaded preview. Files are written
        atomically. Returns the path written.
        """
        from . import io

        return io.save_surface(self, path, **kwargs)

    def __repr__(self) -> str:
        H, W = self.shape
        it = self.info.get("iterations")
        return (
            f"Surface({H}x{W}, {int(self.mask.sum())} facets, method={self.info.get('method')!r}"
            + (f", iterations={it}" if it is not None else "")
            + ")"
        )
