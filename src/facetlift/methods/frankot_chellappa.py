"""Frankot-Chellappa: projection of the gradient field onto integrable Fourier bases.

Energy
    On a rectangular, periodic grid, Frankot & Chellappa (1988) find the surface ``z`` whose
    gradient is closest to the given one in the Fourier basis,
    ``min_z sum_(u,v) |j u Z - P|^2 + |j v Z - Q|^2``, which decouples per frequency:
    ``Z(u, v) = -j (u P + v Q) / (u^2 + v^2)`` and ``Z(0, 0) = 0`` (the free constant).
    ``u, v`` are the angular frequencies (radians per world unit) of ``numpy.fft.fftfreq`` on
    the grid of pixel centres, spacing ``h = problem.pixel_size``. This is the *spectral*
    derivative model: it treats the samples ``p, q`` as exact derivatives of a periodic,
    band-limited surface, so a trigonometric polynomial below the Nyquist frequency that is
    periodic on the grid is recovered to machine precision (not merely O(h^2), as a
    finite-difference model would give).

Axes
    x runs along columns, y *up*, against the row index (:mod:`facetlift.conventions`), so
    the derivative along the row axis is ``dz/d(row h) = -q``: the row-frequency term uses
    ``-q``. Nyquist terms of even-sized grids carry no derivative information; their
    imaginary part is dropped when the real part of the inverse FFT is taken.

Masks and missing samples (an extension; FC itself needs a full rectangle)
    The method works on the bounding box of each connected component of the mask, one at a
    time (the other components' pixels in that box count as outside; where the boxes overlap
    so much that their areas add up to more than :data:`SHARED_BOX_FACTOR` times the union
    box's, on the one union box, whose fill then couples the components). Gradients at box
    pixels outside the component, and at its pixels without a usable normal, are filled
    (option `fill`): ``"harmonic"``
    (default) solves Laplace's equation for p and q separately with the mask values as Dirichlet
    data (a smooth, continuous extension), ``"nearest"`` copies the nearest mask pixel,
    ``"zero"`` sets them to 0 (a flat surround, which puts a gradient jump on the mask
    boundary). The filled field is not integrable, so the projection spreads the fill's curl
    into the mask: errors concentrate within a few pixels of the mask boundary and decay
    inwards. With ``pad="mirror"`` (default) the box is reflected into a 2H x 2W grid (z even,
    so p is odd across vertical edges and q across horizontal ones) before the FFT; the
    reflected surface is continuous across the box edges, which removes the wrap-around jump of
    a non-periodic surface. The reflected gradient still jumps at an edge where the normal slope
    is non-zero, so a non-periodic surface (e.g. a saddle) is recovered to about O(h) near the
    box edges and much better inside, with the error of a spectral method applied to a kinked
    function. ``pad="none"`` is the original method: exact on periodic input, large errors on
    non-periodic input. The box's constant is arbitrary; :func:`facetlift.integrate` removes the
    per-component mean.

Options
    Declared in :data:`OPTIONS`.

Limits
    Orthographic input only; missing samples are filled like the box around the mask, which
    works for scattered gaps and poorly for large holes; least squares in
    the Fourier basis smooths sharp features and spreads errors globally (the paper's Sec. 5
    leaves FC out of its error chart for this reason). Memory and time are those of a
    (2H x 2W) FFT: O(HW log HW).

Reference
    R. T. Frankot, R. Chellappa. A method for enforcing integrability in shape from shading
    algorithms. IEEE TPAMI 10(4):439-451, 1988.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.fft
import scipy.ndimage as ndi
import scipy.sparse as sp

from .. import linalg
from ..options import Option
from ..problem import Problem
from . import MethodResult

log = logging.getLogger(__name__)

#: The components share one box when their own boxes' areas add up to more than this many
#: times the union box's (the cost of one FFT and fill per box).
SHARED_BOX_FACTOR = 4.0

PADS = ("mirror", "none")
FILLS = ("harmonic", "nearest", "zero")

OPTIONS = (
    Option("pad", "mirror", "reflect the box to 2H x 2W before the FFT, or use it periodically",
           kind="choice", choices=PADS),
    Option("fill", "harmonic", "how gradients outside the mask and at missing samples are made "
           "up", kind="choice", choices=FILLS),
)


#: With ``pad="none"`` (periodic), :func:`run` warns where the height the slopes climb across
#: the box, row by row and column by column, varies by more than this share of the height's
#: own spread: the map does not tile (a tileable map climbs 0 on every row; a constant bias
#: climbs the same on every row, which the periodic solve removes, and is no seam), and the
#: periodic solve spreads the seams' mismatch over the whole height (a non-tileable 240^2
#: crop of a brick texture: 28 % RMS error with no word, against 1.9 % by dgp; a texture
#: artist's audit). The climbs' variation is taken less its white part (noise makes a random
#: walk of each row's climb, independent from row to row). Measured: tileable bricks and weave
#: 0.000-0.001; a crop that does not tile 1.0-1.7.
TILE_SEAM = 0.8
#: With ``pad="none"``, :func:`run` warns where the map's mean slope is more than this share
#: of its RMS slope: the periodic solve drops the mean slope (a tilted plane came back flat
#: with no word, an audit). A plane's share is 1; a texture of slope amplitude 0.3 on a tilt of
#: 0.1, 0.43 (0.44 of its range off, a review); a tileable texture's is near 0, and one with a
#: 2-degree encoding bias (which a tiled texture cannot hold, and the solve rightly drops)
#: 0.08, which stays silent (test_a_map_that_does_not_tile_is_named_...).
TILT_SHARE = 0.25
#: Root-mean-square slope below which :func:`_check_tiles` does not judge (three 8-bit code
#: steps of a normal's x or y).
TILE_FLAT = 3 * 2 / 255


def _check_tiles(P: np.ndarray, Q: np.ndarray) -> None:
    """Warn where the slope maps (P, Q) of a box integrated periodically do not tile."""
    from .._warnings import warn

    if min(P.shape) < 4:
        return
    # (slopes within a few 8-bit code steps of flat: quantisation's correlated error would
    # read as a seam, a review)
    squares = np.mean(P * P), np.mean(Q * Q)  # (the flat test's, and the tilt's RMS below)
    if np.sqrt(sum(squares) / 2) < TILE_FLAT:
        return
    climbs = [P.sum(axis=1), Q.sum(axis=0)]  # (each row's and column's height across)
    rows = np.cumsum(P, axis=1)
    cols = np.cumsum(Q, axis=0)
    spread = np.sqrt((np.var(rows, axis=1).mean() + np.var(cols, axis=0).mean()) / 2)

    def smooth(c):  # (the climbs' variance less its white part: noise adds a random walk to
        # each row's climb, independent from row to row; a seam changes slowly, a review)
        return max(float(np.var(c) - np.mean(np.diff(c) ** 2) / 2), 0.0)

    varies = np.sqrt((smooth(climbs[0]) + smooth(climbs[1])) / 2)
    mean = np.hypot(P.mean(), Q.mean())
    rms = np.sqrt(sum(squares))
    if mean > TILT_SHARE * rms:
        warn(f"pad='none' integrates the map as periodic, and a periodic height has no mean "
             f"slope: the map's ({mean:.3g}, against an RMS slope of {rms:.3g}) is dropped (a "
             "tilted plane comes back flat): leave pad at its default (mirror) to keep it")
    if spread > 0 and varies > TILE_SEAM * spread:
        warn(f"pad='none' integrates the map as periodic, but it does not tile: the height its "
             f"slopes climb from one edge to the opposite one varies from row to row (or column "
             f"to column) by {varies / spread:.2g} of the height's own spread; the seams' "
             "mismatch bends the whole height: leave pad at its default (mirror), or make the "
             "texture tileable first")


def run(problem: Problem, *, pad: str, fill: str) -> MethodResult:
    """Integrate `problem` by the Frankot-Chellappa projection (see the module docstring).

    Returns heights (m,) at the facet centres and ``info`` with the box shape.
    """
    d = problem.domain
    rows, cols = d.pixels
    p, q = problem.slopes
    values = np.zeros(d.n_facets)
    # each connected component in its own box: in one box around all, the fill between
    # separate parts carried one part's slopes into the other (a plane beside a sphere came
    # back bent by 3 % of its range). Unless the boxes overlap so much that their total area
    # is far above the union box's (64 diagonal stripes at 256^2: 9.4 s against 0.26 s), where
    # the one shared box is used as before
    groups = d.component_facets(shared=SHARED_BOX_FACTOR)
    boxes, filled = [], 0
    for f in groups:
        r, c = rows[f], cols[f]
        r0, c0 = r.min(), c.min()
        H, W = r.max() - r0 + 1, c.max() - c0 + 1
        have = np.zeros((H, W), dtype=bool)
        ok = problem.usable[f]
        have[r[ok] - r0, c[ok] - c0] = True
        P = np.zeros((H, W))
        Q = np.zeros((H, W))
        P[have] = p[f[ok]]
        Q[have] = q[f[ok]]
        if not have.all():
            P, Q = _fill(P, Q, have, fill) if have.any() else (P, Q)
        if pad == "none" and len(groups) == 1:
            _check_tiles(P, Q)
        values[f] = integrate_box(P, Q, problem.pixel_size, pad=pad)[r - r0, c - c0]
        boxes.append((int(H), int(W)))
        filled += int((~have).sum())
    box = max(boxes, key=lambda b: b[0] * b[1])
    info = {"box": box, "boxes": len(boxes), "filled": filled, "pad": pad, "fill": fill}
    return MethodResult(values=values, info=info)


def integrate_box(
    P: np.ndarray, Q: np.ndarray, h: float = 1.0, *, pad: str = "mirror"
) -> np.ndarray:
    """Frankot-Chellappa on a full rectangle.

    Parameters
    ----------
    P, Q : (H, W) float
        ``dz/dx`` (x along columns) and ``dz/dy`` (y up, against rows) at pixel centres.
    h : float
        Pixel spacing.
    pad : {"mirror", "none"}
        Even reflection to (2H, 2W) first, or periodic use of the (H, W) grid.

    Returns
    -------
    (H, W) float
        Height ``z`` with zero mean over the (padded) grid.
    """
    H, W = P.shape
    G = -Q  # derivative along the row axis (downwards) of the height
    if pad == "mirror":
        # z(2H-1-r) = z(r): the row derivative is odd under the row reflection, even under the
        # column reflection (and the other way round for the column derivative).
        P = np.block([[P, -P[:, ::-1]], [P[::-1], -P[::-1, ::-1]]])
        G = np.block([[G, G[:, ::-1]], [-G[::-1], -G[::-1, ::-1]]])
    n_r, n_c = P.shape
    u = 2 * np.pi * scipy.fft.fftfreq(n_c, d=h)[None, :]
    v = 2 * np.pi * scipy.fft.fftfreq(n_r, d=h)[:, None]
    Fp = scipy.fft.fft2(P)
    Fg = scipy.fft.fft2(G)
    denom = u**2 + v**2
    denom[0, 0] = 1.0
    Z = -1j * (u * Fp + v * Fg) / denom
    Z[0, 0] = 0.0
    z = scipy.fft.ifft2(Z).real
    return z[:H, :W]


def _fill(P, Q, inside, fill):
    """Extend P, Q from `inside` to the whole box (see the module docstring)."""
    P, Q = P.copy(), Q.copy()
    out = ~inside
    if fill == "zero":
        P[out] = 0.0
        Q[out] = 0.0
    elif fill == "nearest":
        _, (ir, ic) = ndi.distance_transform_edt(out, return_indices=True)
        P = P[ir, ic]
        Q = Q[ir, ic]
    else:
        L = _grid_laplacian(*inside.shape)
        o = out.ravel()
        A = L[o][:, o].tocsc()
        B = L[o][:, ~o]
        rhs = -(B @ np.stack([P[inside], Q[inside]], axis=1))
        A = A.tocsr()
        P[out] = linalg.solve(A, rhs[:, 0])[0]
        Q[out] = linalg.solve(A, rhs[:, 1])[0]
    return P, Q


def _grid_laplacian(H: int, W: int) -> sp.csr_matrix:
    """(HW, HW) graph Laplacian (positive semi-definite) of the 4-neighbour grid."""
    def path(n):
        d = np.ones(max(n - 1, 0))
        D = sp.diags([d, d], [-1, 1], shape=(n, n))
        return sp.diags(np.asarray(D.sum(axis=1)).ravel()) - D

    return (sp.kron(path(H), sp.eye(W)) + sp.kron(sp.eye(H), path(W))).tocsr()
