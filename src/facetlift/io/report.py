"""A one-page PNG report of a result, to judge it at a glance (needs matplotlib).

Panels: the surface shaded by two lights (upper left and lower right, so a bent or inside-out
result shows), the depth colour-mapped with a colour bar, the angular deviation between the
input normals and the result's facets, and the depth discontinuities where the result has them
(``Surface.discontinuities`` or ``Surface.info["discontinuities"]``, an (H, W) map).
"""

from __future__ import annotations

import io as _bytes_io
from pathlib import Path

import numpy as np

from ._paths import _suffix
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


def write_report(path, surface, normals=None, *, dpi: int = 100) -> Path:
    """Write the report PNG (see the module docstring).

    Parameters
    ----------
    path : str or Path
        ``.png`` file.
    surface : facetlift.Surface
    normals : (H, W, 3) array_like, optional
        The input normals (facetlift frame); without them the deviation panel is left out.
    dpi : int

    Raises
    ------
    ImportError
        matplotlib is missing (``pip install 'facetlift[plot]'``).
    """
    p = Path(path)
    _suffix(p, (".png",), "report", "path")
    try:
        from matplotlib.figure import Figure  # no pyplot: no backend, no global state
    except ImportError as e:
        raise ImportError(
            "the report (--save report) needs matplotlib, which comes with the plot extra: "
            "pip install 'facetlift[plot]'"
        ) from e
    from ..metrics import angular_error

    panels = [(f"shaded, light {i + 1}", shade(surface, light=L), "gray", None)
              for i, L in enumerate(LIGHTS)]
    panels.append(("depth", np.where(surface.mask, surface.depth, np.nan), "viridis", "depth"))
    if normals is not None:
        mean, _, err = angular_error(surface, normals)
        panels.append((f"deviation from input (mean {mean:.2f} deg)", err, "magma", "degrees"))
    jumps = discontinuity_map(surface)
    if jumps is not None:
        panels.append(("discontinuities", np.where(surface.mask, jumps, np.nan), "inferno",
                       None))
    H, W = surface.shape
    cols = 2 if len(panels) <= 4 else 3
    rows = -(-len(panels) // cols)
    aspect = H / max(W, 1)
    fig = Figure(figsize=(4.2 * cols, 4.2 * rows * min(max(aspect, 0.3), 3.0) + 0.6))
    info = surface.info if isinstance(surface.info, dict) else {}
    fig.suptitle(f"{H}x{W}, {int(surface.mask.sum())} facets, method {info.get('method', '?')}")
    for k, (title, img, cmap, label) in enumerate(panels):
        ax = fig.add_subplot(rows, cols, k + 1)
        kw = {"vmin": 0.0, "vmax": 1.0} if cmap == "gray" else {}
        im = ax.imshow(np.ma.masked_invalid(img), cmap=cmap, interpolation="nearest", **kw)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
        if label is not None:
            fig.colorbar(im, ax=ax, shrink=0.8, label=label)
    buf = _bytes_io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    _write_bytes(p, buf.getvalue())
    return p
