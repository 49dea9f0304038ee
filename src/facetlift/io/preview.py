"""Shaded PNG previews of a surface; matplotlib only for the optional colormap panel."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._paths import _suffix
from .images import _write_png


def shade(surface, *, light=(-1.0, 1.0, 2.0), ambient: float = 0.15) -> np.ndarray:
    """Lambertian shading of a surface's facets, (H, W) in [0, 1], NaN outside the domain.

    Facet normals come from the reconstructed geometry: the cross product of the two
    diagonals of each quad (its corner vertices in 3-D, x right, y up, z toward the viewer;
    each facet's own corners where the surface is split at jumps), so perspective surfaces
    and cut ones shade correctly too (:func:`facetlift.metrics.surface_normals`). `light`
    points from the surface toward the light (default: upper left, in front).
    """
    from ..metrics import surface_normals

    n = surface_normals(surface)
    L = np.asarray(light, dtype=float)
    L = L / np.linalg.norm(L)
    s = ambient + (1.0 - ambient) * np.clip(n @ L, 0.0, 1.0)
    s[~surface.mask] = np.nan
    return s


def write_preview(
    path,
    surface,
    *,
    light=(-1.0, 1.0, 2.0),
    colormap: str | None = None,
    min_size: int = 256,
    background=(255, 255, 255),
) -> Path:
    """Write a PNG preview: the surface shaded by a distant light, background outside the mask.

    Parameters
    ----------
    path : str or Path
        ``.png`` file.
    surface : facetlift.Surface
    light : (3,) float
        Direction toward the light, x right, y up, z toward the viewer.
    colormap : str, optional
        A matplotlib colormap name; when given, a second panel shows the depth in colour
        (near = low end of the map). Needs matplotlib (``facetlift[plot]``); the shaded panel
        alone does not.
    min_size : int
        Small surfaces are enlarged by an integer factor (nearest neighbour) so that the
        shorter side has at least this many pixels.
    background : (3,) int
        RGB colour outside the domain.

    Raises
    ------
    ImportError
        If `colormap` is given and matplotlib is not installed.
    """
    p = Path(path)
    _suffix(p, (".png",), "preview", "path")
    s = shade(surface, light=light)
    inside = surface.mask
    bg = np.asarray(background, dtype=np.uint8)
    img = np.empty(s.shape + (3,), dtype=np.uint8)
    img[:] = bg
    tint = np.array([0.92, 0.92, 0.97])
    img[inside] = np.round(255 * s[inside, None] * tint).astype(np.uint8)
    panels = [img]
    if colormap is not None:
        try:
            import matplotlib
        except ImportError as e:
            raise ImportError(
                "write_preview(colormap=...) needs matplotlib, which comes with the plot extra: "
                "pip install 'facetlift[plot]'"
            ) from e

        d = surface.depth
        lo, hi = np.nanmin(d[inside]), np.nanmax(d[inside])
        t = (d - lo) / (hi - lo) if hi > lo else np.zeros_like(d)
        cmap = matplotlib.colormaps[colormap]
        col = np.empty_like(img)
        col[:] = bg
        col[inside] = np.round(255 * cmap(t[inside])[:, :3]).astype(np.uint8)
        gap = np.empty((img.shape[0], max(2, img.shape[1] // 32), 3), np.uint8)
        gap[:] = bg
        panels += [gap, col]
    out = np.concatenate(panels, axis=1)
    k = max(1, int(np.ceil(min_size / max(1, min(inside.shape)))))
    if k > 1:
        out = np.repeat(np.repeat(out, k, axis=0), k, axis=1)
    _write_png(p, out)
    return p


def write_discontinuities(path, surface, *, min_size: int = 256) -> Path:
    """Write a PNG of where the surface is cut by depth jumps.

    The surface is shaded in grey (:func:`shade`) and every pixel next to a cut edge
    (:attr:`facetlift.Surface.cuts`) is drawn in red, brighter for a larger jump (relative to
    the largest); white outside the mask. No matplotlib needed.

    Raises
    ------
    ValueError
        If the surface has no discontinuity map (a method without ``discontinuities=True``).
    """
    p = Path(path)
    _suffix(p, (".png",), "discontinuity map", "path")
    jumps = getattr(surface, "discontinuities", None)
    if jumps is None:
        raise ValueError(
            "the surface has no discontinuity map: integrate with discontinuities=True "
            "(--discontinuities) to get one"
        )
    s = shade(surface)
    img = np.full(s.shape + (3,), 255, dtype=np.uint8)
    inside = surface.mask
    grey = np.round(200 * np.nan_to_num(s[inside]) + 30).astype(np.uint8)
    img[inside] = grey[:, None]
    cut = inside & (np.nan_to_num(jumps) > 0)
    if cut.any():
        rel = jumps[cut] / np.nanmax(jumps[cut])
        img[cut] = np.column_stack([
            np.round(150 + 105 * rel), np.round(40 * (1 - rel)), np.round(40 * (1 - rel))
        ]).astype(np.uint8)
    k = max(1, int(np.ceil(min_size / max(1, min(inside.shape)))))
    if k > 1:
        img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
    _write_png(p, img)
    return p
