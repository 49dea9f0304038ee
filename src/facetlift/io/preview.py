"""Shaded PNG previews of a surface; matplotlib only for the optional colormap panel."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._warnings import warn
from ._paths import _file_name, _suffix
from .images import (
    _decode_image,
    _exr_quantity,
    _write_exr,
    _write_png,
    png_text,
    read_depth,
)

#: The most pixels a preview's shorter side is enlarged to (`min_size`), and the longest
#: side an enlargement may make (a long thin map is enlarged less).
MAX_MIN_SIZE = 8192
MAX_SIDE = 16384


def _factor(shape, min_size: int, width: int | None = None) -> int:
    """The integer enlargement of an image of `shape` (and `width` columns in all, panels
    included) for `min_size`, within :data:`MAX_SIDE`."""
    k = max(1, int(np.ceil(min_size / max(1, min(shape)))))
    longest = max(shape[0], shape[1] if width is None else width)
    return max(1, min(k, MAX_SIDE // max(1, longest)))


def _light(light) -> np.ndarray:
    try:
        L = np.asarray(light, dtype=float)
    except (TypeError, ValueError):
        L = None
    if L is None or L.shape != (3,) or not np.isfinite(L).all() or not np.any(L):
        raise ValueError(f"`light` must be 3 finite numbers, not all zero (a direction x, y, "
                         f"z); got {light!r}")
    return L / np.linalg.norm(L)


def _min_size(min_size) -> int:
    ok = (not isinstance(min_size, bool) and isinstance(min_size, (int, float, np.number))
          and np.isfinite(min_size) and float(min_size) == int(min_size)
          and 0 <= min_size <= MAX_MIN_SIZE)
    if not ok:
        raise ValueError(f"`min_size` must be a whole number from 0 to {MAX_MIN_SIZE} (pixels "
                         f"of the preview's shorter side); got {min_size!r}")
    return int(min_size)


def _background(background) -> np.ndarray:
    try:
        bg = np.asarray(background, dtype=float)
    except (TypeError, ValueError):
        bg = None
    if bg is not None and bg.shape == ():  # (one grey level)
        bg = np.full(3, float(bg))
    if bg is None or bg.shape != (3,) or not np.isfinite(bg).all() or (
            bg.min() < 0 or bg.max() > 255):
        raise ValueError(f"`background` must be 3 numbers in 0-255 (RGB), or one grey level; "
                         f"got {background!r}")
    return np.round(bg).astype(np.uint8)


def shade(surface, *, light=(-1.0, 1.0, 2.0), ambient: float = 0.15) -> np.ndarray:
    """Lambertian shading of a surface's facets, (H, W) in [0, 1], NaN outside the domain.

    Facet normals come from the reconstructed geometry: the cross product of the two
    diagonals of each quad (its corner vertices in 3-D, x right, y up, z toward the viewer;
    each facet's own corners where the surface is split at jumps), so perspective surfaces
    and cut ones shade correctly too (:func:`facetlift.metrics.surface_normals`). `light`
    points from the surface toward the light (default: upper left, in front).
    """
    from ..metrics import surface_normal_rows

    L = _light(light)
    s = np.empty(surface.mask.shape)
    for r0, r1, n in surface_normal_rows(surface):  # (by blocks: a review's 4096^2 preview
        # took 2.7 GB of temporaries for the whole frame's normals at once)
        s[r0:r1] = ambient + (1.0 - ambient) * np.clip(n @ L, 0.0, 1.0)
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
        shorter side has at least this many pixels (at most :data:`MAX_MIN_SIZE`; the
        longest side is kept within :data:`MAX_SIDE`).
    background : (3,) int, or int
        RGB colour outside the domain (one number: a grey level).

    Raises
    ------
    ImportError
        If `colormap` is given and matplotlib is not installed.
    ValueError
        A bad `light`, `colormap`, `min_size` (an integer up to :data:`MAX_MIN_SIZE`) or
        `background`, naming it.
    """
    p = _file_name(path)
    _suffix(p, (".png",), "preview", "path")
    if not all(hasattr(surface, a) for a in ("depth", "mask", "camera")):
        # (a depth array gave an AttributeError from deep inside, an audit)
        raise TypeError(f"`surface` must be a facetlift.Surface (integrate's result, or "
                        f"Surface.from_depth(depth, mask) for a depth map); got "
                        f"{type(surface).__name__}")
    min_size, bg = _min_size(min_size), _background(background)
    cmap = None
    if colormap is not None:
        try:
            import matplotlib
        except ImportError as e:
            raise ImportError(
                "write_preview(colormap=...) needs matplotlib, which comes with the plot extra: "
                "pip install 'facetlift[plot]'"
            ) from e
        try:
            cmap = matplotlib.colormaps[colormap]
        except (KeyError, TypeError):
            raise ValueError(f"`colormap` must be a matplotlib colormap name (e.g. 'viridis'); "
                             f"got {colormap!r}") from None
    s = shade(surface, light=light)
    inside = surface.mask
    img = np.empty(s.shape + (3,), dtype=np.uint8)
    img[:] = bg
    tint = np.array([0.92, 0.92, 0.97])
    img[inside] = np.round(255 * s[inside, None] * tint).astype(np.uint8)
    panels = [img]
    if cmap is not None:
        d = surface.depth
        lo, hi = np.nanmin(d[inside]), np.nanmax(d[inside])
        t = (d - lo) / (hi - lo) if hi > lo else np.zeros_like(d)
        col = np.empty_like(img)
        col[:] = bg
        col[inside] = np.round(255 * cmap(t[inside])[:, :3]).astype(np.uint8)
        gap = np.empty((img.shape[0], max(2, img.shape[1] // 32), 3), np.uint8)
        gap[:] = bg
        panels += [gap, col]
    out = np.concatenate(panels, axis=1)
    k = _factor(inside.shape, min_size, out.shape[1])
    if k > 1:
        out = np.repeat(np.repeat(out, k, axis=0), k, axis=1)
    _write_png(p, out)
    return p


#: Tints of the pieces after the largest in :func:`write_discontinuities` (RGB, in turn,
#: repeated from the ninth piece on; no red, the cuts' colour).
PIECE_TINTS = np.array([(60, 120, 230), (40, 170, 90), (170, 80, 210), (0, 170, 175),
                        (225, 165, 0), (130, 130, 40), (235, 110, 180), (120, 210, 240)])
#: Share of a tinted piece's colour that is its tint (the rest its grey shading).
PIECE_TINT = 0.55


def write_discontinuities(path, surface, *, min_size: int = 256) -> Path:
    """Write a PNG of where the surface is cut by depth jumps.

    The surface is shaded in grey (:func:`shade`) and every pixel next to a cut edge
    (:attr:`facetlift.Surface.cuts`) is drawn in red, brighter for a larger jump (relative to
    the largest); white outside the mask. Where the cuts (or the mask) leave the mesh in
    several pieces (:meth:`facetlift.Surface.pieces`), every piece but the largest is tinted
    in a colour of :data:`PIECE_TINTS`, in turn from the next largest (the eight repeat from
    the ninth piece on): where such a piece
    lies against the others the normals do not say (docs/perspective.md, "Separated
    pieces"), and one depth sample on it decides it (docs/fusion.md). No matplotlib needed.

    Raises
    ------
    ValueError
        If the surface has no discontinuity map (a method without ``discontinuities=True``).
    """
    p = _file_name(path)
    _suffix(p, (".png",), "discontinuity map", "path")
    min_size = _min_size(min_size)
    jumps = getattr(surface, "discontinuities", None)
    if jumps is None:
        from .. import methods

        method = (getattr(surface, "info", None) or {}).get("method")
        able = sorted(k for k, v in methods.REGISTRY.items() if v.jump_map)
        if method is not None and method not in able:
            # (a bini surface integrated with discontinuities=True was told to do just that,
            # an audit)
            raise ValueError(f"the surface has no discontinuity map: method {method!r} "
                             f"does not make one (it comes only from {able}, with "
                             "discontinuities=True)")
        raise ValueError(
            "the surface has no discontinuity map: integrate with discontinuities=True "
            "(--discontinuities) to get one"
        )
    s = shade(surface)
    img = np.full(s.shape + (3,), 255, dtype=np.uint8)
    inside = surface.mask
    grey = np.round(200 * np.nan_to_num(s[inside]) + 30).astype(np.uint8)
    img[inside] = grey[:, None]
    pieces = surface.pieces()
    other = pieces > 0
    if other.any():  # (the largest stays grey)
        tint = PIECE_TINTS[(pieces[other] - 1) % len(PIECE_TINTS)]
        g = img[other].astype(float)
        img[other] = np.round((1.0 - PIECE_TINT) * g + PIECE_TINT * tint).astype(np.uint8)
    cut = inside & (np.nan_to_num(jumps) > 0)
    if cut.any():
        rel = jumps[cut] / np.nanmax(jumps[cut])
        img[cut] = np.column_stack([
            np.round(150 + 105 * rel), np.round(40 * (1 - rel)), np.round(40 * (1 - rel))
        ]).astype(np.uint8)
    k = _factor(inside.shape, min_size)
    if k > 1:
        img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
    _write_png(p, img)
    return p


#: The formats :func:`write_height` writes: a 16-bit grey PNG scaled to 0..65535, and an
#: OpenEXR file of the heights themselves (float32).
HEIGHT_FORMATS = (".png", ".exr")


def check_height_range(value, name: str = "height_range") -> tuple[float, float] | None:
    """`value` checked as the heights of a height PNG's 0 and 65535, ``(low, high)``: two
    finite numbers, low below high; None passes (the map's own range). ValueError naming
    `name` otherwise."""
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        lo = hi = None
    if lo is None or not (np.isfinite(lo) and np.isfinite(hi)) or not lo < hi:
        raise ValueError(f"`{name}` must be two finite numbers LOW < HIGH, the heights (in the "
                         f"surface's depth units) written as 0 and 65535; got {value!r}")
    return lo, hi


def write_height(path, surface, *, height_range=None) -> tuple[Path, tuple[float, float] | None]:
    """Write the surface's height (``-depth``), for the displacement and height maps of game
    engines and texture tools (a texture artist's check: only a shaded 8-bit preview and
    float depth existed).

    ``.png``: 16-bit grey, scaled to 0..1 over the domain (0 at its lowest point, the largest
    depth; 65535 at its highest), or over `height_range`; with an alpha channel (0 outside
    the mask) only where the surface leaves pixels out: a map covering the image is plain
    grey, the one channel height-map imports expect (an artist's audit: an alpha of 65535
    everywhere was written, which says nothing). ``.exr``: the heights themselves, float32, in
    the depth's units, NaN outside the mask, one channel named ``Y`` (OpenEXR's luminance:
    viewers and compositors show a lone ``Y`` as grey; ``depth.exr``'s is ``Z``).

    Parameters
    ----------
    path : str or Path
        ``.png`` or ``.exr`` (:data:`HEIGHT_FORMATS`).
    surface : facetlift.Surface
    height_range : (float, float), optional
        PNG only: the heights written as 0 and 65535, in the depth's units (texels for a
        texture integrated with ``pixel_size=1``), the same for every map of a texture set;
        heights outside are clipped, with a warning counting them. Default: the map's own
        lowest and highest (one overshooting pixel then sets the scale).

    Returns
    -------
    path : Path
    range : (float, float) or None
        PNG: ``(low, high)``, the depth of the values 0 and 65535 (the displacement scale is
        ``low - high``); a flat surface is written as 0 everywhere. The PNG also holds them,
        as the text chunks ``facetlift:depth_at_0`` and ``facetlift:depth_at_65535``
        (:func:`facetlift.io.png_text`). None for EXR, whose values are the heights.

    Raises
    ------
    ValueError
        A path that is neither ``.png`` nor ``.exr``; a surface without a finite depth; a bad
        `height_range`, or one given for EXR.
    """
    p = _file_name(path)
    ext = _suffix(p, HEIGHT_FORMATS, "height map", "path")
    given = check_height_range(height_range)
    if not hasattr(surface, "depth"):  # (a bare AttributeError for an array, an audit)
        raise ValueError(f"`surface` must be a facetlift.Surface; got {type(surface).__name__}: "
                         "for an (H, W) depth array give facetlift.Surface.from_depth(depth) "
                         "(a height h is the depth -h)")
    depth = np.asarray(surface.depth, dtype=float)
    inside = np.isfinite(depth)
    if not inside.any():
        raise ValueError("the surface has no finite depth to write as a height map")
    if ext == ".exr":
        if given is not None:
            raise ValueError(f"`height_range` {height_range!r} applies to the 16-bit PNG; "
                             f"{p.name} holds the heights themselves: leave it out")
        _write_exr(p, {"Y": np.negative(depth, dtype=np.float32)}, quantity="height")
        return p, None
    if given is None:
        low, high = float(np.nanmax(depth)), float(np.nanmin(depth))
    else:  # (depths: height = -depth; "0.0 -" keeps a height of 0 from becoming -0.0)
        low, high = 0.0 - given[0], 0.0 - given[1]
    span = low - high
    whole = bool(inside.all())
    img = np.zeros(depth.shape if whole else depth.shape + (2,), dtype=np.uint16)
    grey = img if whole else img[..., 0]
    below = above = 0
    if span > 0:  # (row by row: no full-size float temporaries beside the depth)
        for r in range(depth.shape[0]):
            row = np.subtract(low, depth[r])
            row *= 65535.0 / span
            if given is not None:
                with np.errstate(invalid="ignore"):
                    below += int(np.count_nonzero(row < -0.5))
                    above += int(np.count_nonzero(row > 65535.5))
                np.clip(row, 0.0, 65535.0, out=row)
            np.rint(row, out=row)
            grey[r] = np.nan_to_num(row)
    if below or above:
        k = int(inside.sum())
        warn(f"`height_range` [{given[0]:g}, {given[1]:g}]: {below + above} of the "
             f"{k} pixels inside ({(below + above) / k:.2%}) have heights outside it "
             f"({below} below, {above} above; the heights span {-np.nanmax(depth):.6g} to "
             f"{-np.nanmin(depth):.6g}) and are clipped to 0 or 65535 in {p.name}: "
             "widen the range to keep them", UserWarning)
    if not whole:
        img[..., 1][inside] = 65535
    from .. import __version__

    # (the scale in the file itself: a height map alone could not be turned back into depth)
    _write_png(p, img, text={"Software": f"facetlift {__version__}",
                             "facetlift:depth_at_0": repr(low),
                             "facetlift:depth_at_65535": repr(high),
                             "Comment": f"height = -depth; the value 0 is depth {low!r}, "
                                        f"65535 is depth {high!r}"})
    return p, (low, high)


def read_height(path) -> np.ndarray:
    """The depth (H, W) of a height map that :func:`write_height` wrote, NaN outside its
    mask: a ``.png``'s 16-bit values scaled back by the depths of 0 and 65535 it holds as
    text (written since 2026-12-07; an older file, or another tool's, has no scale and is
    refused), or an ``.exr``'s heights negated (:func:`facetlift.io.read_depth` reads it
    alike).

    Raises
    ------
    ValueError
        Neither ``.png`` nor ``.exr``, unreadable, or a PNG without facetlift's scale.
    """
    p = Path(path)
    ext = _suffix(p, HEIGHT_FORMATS, "height map", "path")
    if ext == ".exr":
        if _exr_quantity(p) != "height":
            raise ValueError(f"`path`: {p.name} is not marked as a height map (facetlift's "
                             "height.exr is); read a depth EXR with facetlift.io.read_depth")
        return read_depth(p)
    text = png_text(p)
    try:
        low = float(text["facetlift:depth_at_0"])
        high = float(text["facetlift:depth_at_65535"])
    except (KeyError, ValueError):
        raise ValueError(f"`path`: {p.name} holds no depth scale (the text chunks "
                         "facetlift:depth_at_0 and facetlift:depth_at_65535 of a height.png "
                         "written by facetlift); scale its values yourself") from None
    img = _decode_image(p, ".png", "path")
    grey = img[..., 0] if img.ndim == 3 else img
    if grey.dtype != np.uint16:
        raise ValueError(f"`path`: {p.name} has pixel type {grey.dtype}; facetlift's height "
                         "maps are 16-bit")
    depth = low - grey.astype(float) * ((low - high) / 65535.0)
    if img.ndim == 3:
        depth[img[..., -1] == 0] = np.nan
    return depth
