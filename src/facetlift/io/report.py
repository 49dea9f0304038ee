"""A one-page PNG report of a result, to judge it at a glance (needs matplotlib).

Panels: the surface shaded by two lights (upper left and lower right, so a bent or inside-out
result shows), the depth colour-mapped with a colour bar, the angular deviation between the
input normals and the result's facets, and the depth discontinuities where the result has them
(``Surface.discontinuities`` or ``Surface.info["discontinuities"]``, an (H, W) map), with the
input normals as colours where that leaves a cell of the grid free, each cropped to the mask's
bounding box. The deviation panel's mean is the one given (the command
line gives the solve's, over the normals it used); its colour scale, and the jump map's,
end at the 99th percentile (larger values saturate), and the jump map's one-pixel lines are
widened to stay visible in a small panel.
"""

from __future__ import annotations

import io as _bytes_io
from pathlib import Path

import numpy as np

from ._paths import _file_name, _suffix
from .atomic import _write_bytes
from .preview import shade

#: The two light directions of the shaded panels (toward the light; x right, y up, z viewer).
LIGHTS = ((-1.0, 1.0, 2.0), (1.0, -1.0, 1.0))


def discontinuity_map(surface) -> np.ndarray | None:
    """The (H, W) discontinuity map of `surface`, or None where it has none."""
    d = getattr(surface, "discontinuities", None)
    if d is None and isinstance(surface.info, dict):
        d = surface.info.get("discontinuities")
    if d is None:
        return None
    d = np.asarray(d)
    return d if d.shape == surface.shape and d.dtype.kind in "biuf" else None


def write_report(path, surface, normals=None, *, dpi: int = 100,
                 mean_deviation: float | None = None) -> Path:
    """Write the report PNG (see the module docstring).

    Parameters
    ----------
    path : str or Path
        ``.png`` file.
    surface : facetlift.Surface
    normals : (H, W, 3) array_like, optional
        The input normals (facetlift frame); without them the deviation panel is left out.
    dpi : int
    mean_deviation : float, optional
        The mean deviation to title that panel with (the command line passes the solve's,
        ``info["mean_deviation"]``, over the normals it used); default: the mean over every
        finite normal given.

    Raises
    ------
    ImportError
        matplotlib is missing (``pip install 'facetlift[plot]'``).
    """
    p = _file_name(path)
    _suffix(p, (".png",), "report", "path")
    if normals is not None:  # (uint8/uint16 decoded once, for both panels, an audit)
        from ..frames import as_float_normals

        normals = np.asarray(as_float_normals(np.asarray(normals), "normals"), dtype=float)
    try:
        from matplotlib.figure import Figure  # no pyplot: no backend, no global state
    except ImportError as e:
        raise ImportError(
            "the report (--save report) needs matplotlib, which comes with the plot extra: "
            "pip install 'facetlift[plot]'"
        ) from e
    from ..metrics import angular_error

    panels = [(f"shaded, light {i + 1}", shade(surface, light=L), "gray", None, 1.0)
              for i, L in enumerate(LIGHTS)]
    panels.append(("depth", np.where(surface.mask, surface.depth, np.nan), "viridis", "depth",
                   None))
    info = surface.info if isinstance(surface.info, dict) else {}
    box = _bbox(surface.mask)  # (every panel cropped to the object, with a small margin)
    crop = (box[0].stop - box[0].start, box[1].stop - box[1].start)
    if normals is not None:
        mean, _, err = angular_error(surface, normals)
        # (the solve's figure is over the normals it used: grazing and back-facing ones are
        # missing samples, whose large angles show in the map, bright)
        if mean_deviation is not None and np.isfinite(mean_deviation):
            mean = float(mean_deviation)
        panels.append((f"deviation from input (mean {mean:.2f} deg)", err, "magma",
                       "degrees", _robust_max(np.where(_facing(surface, normals), err,
                                                       np.nan))))
    jumps = discontinuity_map(surface)
    if jumps is not None:
        shown = _thickened(np.where(surface.mask, jumps, 0.0), crop)
        panels.append(("discontinuities (jump height)", np.where(surface.mask, shown, np.nan),
                       "inferno", "depth", _robust_max(np.where(shown > 0, shown, np.nan))))
    if normals is not None and len(panels) == 5:  # (the grid's sixth cell: the input, as read
        # in facetlift's frame, RGB = (n + 1) / 2; it stayed empty, a user's check)
        n = np.asarray(normals, dtype=float)
        if n.shape == surface.shape + (3,):
            rgb = np.clip((n + 1.0) / 2.0, 0.0, 1.0)
            rgb[~(surface.mask & np.all(np.isfinite(n), axis=-1))] = 1.0
            panels.append(("input normals (x right, y up, z viewer)", rgb, None, None, None))
    H, W = surface.shape
    panels = [(t, img[box], c, lab, top) for t, img, c, lab, top in panels]
    cols = 2 if len(panels) <= 4 else 3
    rows = -(-len(panels) // cols)
    aspect = crop[0] / max(crop[1], 1)
    fig = Figure(figsize=(4.2 * cols, 4.2 * rows * min(max(aspect, 0.3), 3.0) + 0.6))
    method = info.get("method")
    if method is not None and info.get("solver") == "discontinuous":  # ("method dgp" alone
        # hid the route)
        method += ", discontinuities"
    fig.suptitle(f"{H}x{W}, {int(surface.mask.sum())} facets"
                 + ("" if method is None else f", method {method}"))
    for k, (title, img, cmap, label, top) in enumerate(panels):
        ax = fig.add_subplot(rows, cols, k + 1)
        kw = {} if top is None else {"vmin": 0.0, "vmax": top}
        im = ax.imshow(img if img.ndim == 3 else np.ma.masked_invalid(img), cmap=cmap,
                       interpolation="nearest", **kw)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
        if label is not None:
            fig.colorbar(im, ax=ax, shrink=0.8, label=label)
    buf = _bytes_io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    _write_bytes(p, buf.getvalue())
    return p


#: Colour scales end at this percentile (a few huge values, e.g. the angles of grazing normals
#: that were left out, would leave the rest of the panel black); larger values saturate.
PERCENTILE = 99.0

#: Thin features are widened to about this many image pixels per panel pixel's worth: a
#: one-pixel cut line of a 600-pixel map vanishes in a 300-pixel panel.
PANEL_PIXELS = 250


def _robust_max(img) -> float | None:
    """The colour scale's top for `img`: its :data:`PERCENTILE` (None when nothing is finite
    or it is 0: matplotlib's own scale)."""
    v = np.asarray(img, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    top = float(np.percentile(v, PERCENTILE))
    return top if top > 0 else None


#: The deviation panel's colour scale is taken over the normals at least this far from
#: grazing (the cosine of 85 degrees, the paper's rule): back-facing and grazing normals are
#: missing samples for the solve, and their angles (up to 180 degrees) set the scale of the
#: BiNI human map's panel to 64 degrees where the used normals' 99th percentile was 10.5 (an
#: audit); they still show, saturated.
FACING = 0.08716


def _facing(surface, normals) -> np.ndarray:
    """(H, W) bool: pixels whose input normal's cosine to the viewing ray is at least
    :data:`FACING` (all False where the normals cannot be compared)."""
    n = np.asarray(normals, dtype=float)
    out = np.zeros(surface.shape, dtype=bool)
    if n.shape != surface.shape + (3,):
        return out
    r, c = np.nonzero(surface.mask)
    nn = n[r, c]
    ok = np.all(np.isfinite(nn), axis=1) & (np.linalg.norm(nn, axis=1) > 0)
    cos = np.zeros(r.size)
    if ok.any():
        cos[ok] = surface.camera.view_cosine(r[ok], c[ok], nn[ok])
    out[r, c] = ok & (cos >= FACING)
    return out


def _thickened(img: np.ndarray, shape) -> np.ndarray:
    """`img` (0 where nothing) with each value spread to its neighbours by a maximum filter
    sized to the map, so that one-pixel lines stay visible in a small panel."""
    from scipy.ndimage import maximum_filter

    k = max(1, -(-max(shape) // PANEL_PIXELS))
    return maximum_filter(img, size=2 * (k // 2) + 1) if k > 1 else img


def _bbox(mask) -> tuple[slice, slice]:
    """Rows and columns of the mask's bounding box, widened by 3 % of each side (the whole
    image when the mask is empty)."""
    m = np.asarray(mask, bool)
    if not m.any():
        return slice(0, m.shape[0]), slice(0, m.shape[1])
    out = []
    for axis in (1, 0):
        idx = np.flatnonzero(m.any(axis=axis))
        pad = max(1, int(0.03 * m.shape[1 - axis]))
        out.append(slice(max(0, idx[0] - pad), min(m.shape[1 - axis], idx[-1] + 1 + pad)))
    return out[0], out[1]
