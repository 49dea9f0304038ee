"""Camera models: the one place that knows whether a view is orthographic or perspective.

Every method integrates one *unknown* on the image grid, defined up to an additive constant
per connected component, and a :class:`Camera` says what that unknown is and how it relates
to the normals, to depth and to 3-D points:

===================  ===================================  ======================================
                     :class:`Orthographic` (pixel size h)  :class:`Pinhole` (intrinsics K)
===================  ===================================  ======================================
unknown              height ``z = -depth``                 log-depth ``log Z``
grid slopes          ``h (p, q) = h (-n_x, -n_y) / n_z``   exact ``d log Z`` per pixel from ``n``
footprint            ``h``                                 ``1 / sqrt(fx fy)``
depth                ``-unknown``                          ``exp(unknown)``
gauge (no prior)     mean facet depth 0 per component      median facet depth 1 per component
view cosine          ``n_z``                               ``n . (direction to the camera)``
===================  ===================================  ======================================

Grid coordinates
    Positions are given as ``(i, j)`` on the (H+1) x (W+1) vertex grid of
    :mod:`facetlift.conventions`: vertex ``(i, j)`` is at ``(i, j)``, the centre of pixel
    ``(r, c)`` at ``(r + 1/2, c + 1/2)``. An orthographic camera places ``(i, j)`` at
    ``x = j h``, ``y = -i h``; a pinhole camera at image coordinates
    ``(row, col) = (i - 1/2, j - 1/2)`` (OpenCV: pixel centres at integer indices).

Grid slopes
    The change of the unknown per pixel step along ``x`` (right, +column) and ``y`` (up,
    -row) implied by a normal, ``(gx, gy)``. Divided by the footprint they are slopes in the
    units of a height field seen head-on (for a pinhole camera ``f d log Z / du = dZ/dX`` on
    the optical axis), so angles and thresholds mean the same for both cameras.

Perspective slopes
    The surface point of pixel ``(u, v) = (col, row)`` is ``X = Z r`` with the viewing ray
    ``r = K^{-1} (u, v, 1)`` (OpenCV frame: x right, y down, z forward). A normal ``m`` in that
    frame (``m = (n_x, -n_y, -n_z)`` for facetlift's x right, y up, z toward the viewer) is
    orthogonal to ``X_u = Z_u r + Z K^{-1} e_u`` and ``X_v``, so exactly::

        d log Z / du = -(m . K^{-1} e_u) / (m . r),   d log Z / dv = -(m . K^{-1} e_v) / (m . r).

    No small-angle or weak-perspective approximation; the slopes are finite unless the surface
    is seen edge-on (``m . r = 0``). The grazing test is therefore the cosine between the
    normal and the direction toward the camera, not ``n_z``.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .conventions import OUTLIER_EPS

#: Default grazing threshold on the view cosine for a pinhole camera: half a quantisation step
#: of an 8-bit normal map (indistinguishable from edge-on). In log-depth every camera-facing
#: normal has finite slopes, and the steep normals at silhouettes are what links the depth of
#: an occluding surface to the one behind it (see docs/perspective.md).
PINHOLE_GRAZING = 1.0 / 255


def _unit(normals: np.ndarray) -> np.ndarray:
    n = np.asarray(normals, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


class Camera:
    """Interface shared by :class:`Orthographic` and :class:`Pinhole` (see module docstring)."""

    #: True for a perspective camera (the unknown is log-depth, defined up to scale).
    perspective: bool = False
    #: Default threshold of :meth:`view_cosine` below which a normal counts as grazing.
    grazing: float = OUTLIER_EPS
    #: What the unknown is, for messages and ``info``.
    unknown: str = "height"
    #: "orthographic" or "perspective", for ``info``.
    projection: str = "orthographic"
    #: Each component's free constant as :meth:`gauge` fixes it, for ``info``.
    gauge_name: str = "mean depth 0"
    #: Whether depth must be positive (the unknown is its logarithm).
    positive_depth: bool = False

    def footprint(self) -> float:
        """Width of one pixel in the unknown's units (see module docstring)."""
        raise NotImplementedError

    def view_cosine(self, rows, cols, normals, *, unit: bool = False) -> np.ndarray:
        """(m,) cosine between each normal and the direction toward the camera.

        `rows`, `cols` are pixel indices (integer centres); `normals` (m, 3) in the facetlift
        convention, any length (``unit=True``: already unit length, skips normalising). 1
        head-on, 0 edge-on, < 0 back-facing; NaN for NaN normals.
        """
        raise NotImplementedError

    def grid_slopes(self, rows, cols, normals) -> tuple[np.ndarray, np.ndarray]:
        """(gx, gy), each (m,): change of the unknown per pixel step along x (right) and y (up)
        implied by the normals of pixels (`rows`, `cols`); inf/NaN where edge-on or NaN."""
        raise NotImplementedError

    def to_depth(self, unknown: np.ndarray) -> np.ndarray:
        """Depth along the viewing axis from values of the unknown."""
        raise NotImplementedError

    def from_depth(self, depth: np.ndarray) -> np.ndarray:
        """Values of the unknown from depth (NaN where `depth` is NaN or not a valid depth)."""
        raise NotImplementedError

    def gauge(self, facet_values: np.ndarray, component: np.ndarray, n: int) -> np.ndarray:
        """(n,) per-component constant to subtract from the unknown when nothing else fixes it
        (orthographic: the mean, so mean depth 0; perspective: the median, so median depth 1)."""
        raise NotImplementedError

    def points(self, i, j, depth) -> np.ndarray:
        """(N, 3) points, x right, y up, z toward the viewer, of grid positions (`i`, `j`) at
        `depth` (see "Grid coordinates")."""
        raise NotImplementedError

    def cropped(self, r0: int, c0: int) -> Camera:
        """The same camera for the sub-image whose top-left pixel is (`r0`, `c0`)."""
        raise NotImplementedError

    def subsampled(self, stride: int) -> Camera:
        """The camera of the image subsampled with ``img[::stride, ::stride]`` (`stride` a
        positive integer)."""
        raise NotImplementedError

    #: Intrinsics (3, 3) of a pinhole camera, None for an orthographic one.
    K: np.ndarray | None = None
    #: Pixel width in world units (orthographic); 1.0 for a pinhole camera.
    pixel_size: float = 1.0


def _stride(stride) -> int:
    """`stride` of :meth:`Camera.subsampled` as a positive integer, or a ValueError naming it
    (0 was "`K` contains NaN or inf" and 1.5 was taken, an audit: ``img[::1.5]`` is no
    subsampling)."""
    ok = isinstance(stride, (int, np.integer)) and not isinstance(stride, bool) and stride >= 1
    if not ok:
        raise ValueError(f"`stride` must be a positive integer (img[::stride, ::stride]); "
                         f"got {stride!r}")
    return int(stride)


def _components_mean(values, component, n):
    return np.bincount(component, values, n) / np.maximum(np.bincount(component, minlength=n), 1)


@dataclass(frozen=True, eq=False)
class Orthographic(Camera):
    """Parallel projection along -z with square pixels of width `pixel_size` world units."""

    pixel_size: float = 1.0

    perspective = False
    grazing = OUTLIER_EPS
    unknown = "height"

    def __post_init__(self):
        # (a pixel size of -1 turned the surface inside out, 0 flattened it: an audit)
        h = self.pixel_size
        if isinstance(h, bool) or not isinstance(h, (int, float, np.integer, np.floating)) \
                or not np.isfinite(h) or not h > 0:
            raise ValueError(f"`pixel_size` must be a positive finite number; got {h!r}")

    def footprint(self) -> float:
        return float(self.pixel_size)

    def view_cosine(self, rows, cols, normals, *, unit=False):
        n = np.asarray(normals, dtype=float)
        return n[..., 2] if unit else _unit(n)[..., 2]

    def grid_slopes(self, rows, cols, normals):
        n = np.asarray(normals, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            h = self.pixel_size
            return -h * n[..., 0] / n[..., 2], -h * n[..., 1] / n[..., 2]

    def to_depth(self, unknown):
        # ("0.0 -": a flat map's height 0 gave depth -0.0, written so in depth_range, an audit)
        return 0.0 - np.asarray(unknown, dtype=float)

    def from_depth(self, depth):
        return 0.0 - np.asarray(depth, dtype=float)

    def gauge(self, facet_values, component, n):
        return _components_mean(facet_values, component, n)

    def points(self, i, j, depth):
        h = self.pixel_size
        return np.column_stack([np.asarray(j, float) * h, -np.asarray(i, float) * h,
                                -np.asarray(depth, float)])

    def cropped(self, r0, c0):
        return self

    def subsampled(self, stride):
        return Orthographic(self.pixel_size * _stride(stride))

    def __repr__(self) -> str:
        return f"Orthographic(pixel_size={self.pixel_size:g})"


@dataclass(frozen=True, eq=False)
class Pinhole(Camera):
    """Perspective camera with intrinsics `K` (OpenCV layout, see :mod:`facetlift.conventions`)."""

    K: np.ndarray

    perspective = True
    grazing = PINHOLE_GRAZING
    unknown = "log-depth"
    projection = "perspective"
    gauge_name = "median depth 1"
    positive_depth = True
    pixel_size = 1.0

    def __post_init__(self):
        # (checked as integrate checks K: four numbers gave numpy's LinAlgError and a
        # transposed K was taken with cx = cy = 0, an audit)
        K = np.array(check_K(self.K), dtype=float)
        K.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "_Kinv", np.linalg.inv(K))

    def footprint(self) -> float:
        return 1.0 / float(np.sqrt(self.K[0, 0] * self.K[1, 1]))

    def rays(self, rows, cols) -> np.ndarray:
        """(m, 3) viewing rays ``K^{-1} (col, row, 1)`` in the OpenCV camera frame (unit z), for
        image coordinates (pixel centres at integer indices)."""
        rows = np.asarray(rows, dtype=float)
        cols = np.asarray(cols, dtype=float)
        Ki = self._Kinv  # (per component: no (m, 3) stack of the coordinates)
        out = np.empty(np.broadcast_shapes(rows.shape, cols.shape) + (3,))
        for i in range(3):
            out[..., i] = Ki[i, 0] * cols + Ki[i, 1] * rows + Ki[i, 2]
        return out

    def view_cosine(self, rows, cols, normals, *, unit=False):
        r = self.rays(rows, cols)
        m = np.asarray(normals, dtype=float) * np.array([1.0, -1.0, -1.0])
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = -np.einsum("...i,...i->...", m, r) / np.linalg.norm(r, axis=-1)
            return cos if unit else cos / np.linalg.norm(m, axis=-1)

    def log_depth_slopes(self, rows, cols, normals):
        """``(d log Z / d col, d log Z / d row)`` per pixel (see module docstring)."""
        r = self.rays(rows, cols)
        m = np.asarray(normals, dtype=float) * np.array([1.0, -1.0, -1.0])
        mr = np.einsum("...i,...i->...", m, r)
        with np.errstate(divide="ignore", invalid="ignore"):
            return -(m @ self._Kinv[:, 0]) / mr, -(m @ self._Kinv[:, 1]) / mr

    def grid_slopes(self, rows, cols, normals):
        du, dv = self.log_depth_slopes(rows, cols, normals)
        return du, -dv  # the grid's y axis points up, against the row index

    def to_depth(self, unknown):
        return np.exp(np.asarray(unknown, dtype=float))

    def from_depth(self, depth):
        d = np.asarray(depth, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(d > 0, np.log(np.where(d > 0, d, 1.0)), np.nan)

    def gauge(self, facet_values, component, n):
        from scipy import ndimage

        return np.atleast_1d(ndimage.median(facet_values, component + 1, np.arange(1, n + 1)))

    def points(self, i, j, depth):
        K = self.K
        fx, s, cx = K[0]
        fy, cy = K[1, 1], K[1, 2]
        d = np.asarray(depth, float)
        row = np.asarray(i, float) - 0.5
        col = np.asarray(j, float) - 0.5
        Y = (row - cy) * d / fy
        X = ((col - cx) * d - s * Y) / fx
        return np.column_stack([X, -Y, -d])

    def cropped(self, r0, c0):
        if r0 == 0 and c0 == 0:
            return self
        K = self.K.copy()
        K[0, 2] -= c0
        K[1, 2] -= r0
        return Pinhole(K)

    def subsampled(self, stride):
        K = self.K.copy()
        K[:2] /= _stride(stride)  # pixel centres at integer indices: index i -> i / stride
        return Pinhole(K)

    def __repr__(self) -> str:
        K = self.K
        # (as it is made, every digit and the skew: "Pinhole(fx=60, ...)" was refused by the
        # constructor and hid the skew, an audit)
        return f"Pinhole({K.tolist()!r})"


#: A field of view (degrees) below which :func:`K_from_fov` asks whether it was given in
#: radians (pi rad is 180 deg; a phone's 1.2 rad, 69 deg, read as 1.2 deg gave fx = 14,323).
FOV_RADIANS = 3.2


def K_from_fov(shape, fov: float) -> np.ndarray:
    """A pinhole K for an (H, W) image from its horizontal field of view `fov` (degrees,
    across the width, the W columns): ``fx = fy = (W / 2) / tan(fov / 2)``, the principal
    point at the image's centre ``((W - 1) / 2, (H - 1) / 2)`` (OpenCV layout). A phone's
    35 mm-equivalent focal length ``f35`` gives ``2 atan(18 / f35)`` across the long side:
    for a portrait photo (H > W) the width's is ``2 atan((W / H) tan(fov_long / 2))``
    (docs/conventions.md).

    Warns (once per call) where `fov` looks like radians (below :data:`FOV_RADIANS`) or is
    wider than :data:`facetlift.problem.FOV_WIDE` (what that implies); :func:`facetlift.
    integrate` then does not ask whether this K's focal lengths are in mm (:func:`fov_of`),
    unless the map is of another size than `shape`."""
    try:
        H, W = (int(v) for v in tuple(shape)[:2])
        ok = len(tuple(shape)) >= 2 and H > 0 and W > 0 and (H, W) == tuple(shape)[:2]
    except (TypeError, ValueError):
        ok = False
    if not ok:
        text = repr(shape)  # (an image given for its shape printed 12k characters: an audit)
        text = text if len(text) <= 80 else f"{type(shape).__name__} of shape {np.shape(shape)}"
        raise ValueError(f"`shape` must be the image's (H, W), two positive integers; got "
                         f"{text}")
    value = fov_degrees(fov)
    f = (W / 2.0) / np.tan(np.radians(value) / 2.0)
    from ._warnings import warn
    from .errors import CameraWarning
    from .problem import FOV_WIDE

    if value < FOV_RADIANS:  # (a field of view in radians read as degrees: a telescope)
        warn(f"`fov` {value:g} deg is a telescope's field of view: is it in radians? Give "
             f"degrees ({np.degrees(value):.4g} deg for {value:g} rad)", CameraWarning)
    elif value > FOV_WIDE:  # (said here, as a field of view: integrate asked a --fov 170
        # user whether the focal lengths were in mm, an audit)
        edge = 1.0 / np.cos(np.radians(value) / 2.0) ** 2
        warn(f"`fov` {value:g} deg is an extreme field of view for a pinhole camera (fx = fy = "
             f"{f:.4g} pixels for this {W}-pixel-wide image): at the image's left and right "
             f"edges the rays are {value / 2:g} deg off the axis, where the image is stretched "
             f"{edge:.0f}x against its centre and a surface facing the camera's axis is seen "
             "nearly edge-on (its normals turn grazing or back-facing). A lens that wide is a "
             "fish-eye, which is no pinhole: undistort the image first. The field of view is "
             "the width's, not the diagonal's (a 35 mm-equivalent focal length f35 gives "
             "2 atan(18 / f35) across the long side)", CameraWarning)
    K = np.array([[f, 0.0, (W - 1) / 2.0], [0.0, f, (H - 1) / 2.0], [0.0, 0.0, 1.0]])
    key = id(K)
    _FROM_FOV[key] = (weakref.ref(K, lambda _: _FROM_FOV.pop(key, None)), K.copy(), value,
                      (H, W))
    return K


#: :func:`K_from_fov`'s results still alive: id -> (weak reference, the values it returned,
#: the field of view, the (H, W) it was made for). Only for :func:`fov_of`: the
#: focal-length check's words.
_FROM_FOV: dict = {}


def fov_of(K, shape) -> float | None:
    """The field of view (degrees) :func:`K_from_fov` made `K` from for an image of `shape`
    (H, W), or None for any other K (a copy, one changed since, or one made for another
    image's size included): a K that wide was asked for as a field of view, and
    :func:`K_from_fov` said what it implies (not a focal length in mm). The size matters: a
    K made for a 30 x 40 image used on a 300 x 400 one is a K for a much smaller image, which
    the focal-length check exists to ask about (a review: matched by id only, it was silent).
    """
    entry = _FROM_FOV.get(id(K))
    if entry is None or entry[0]() is not K or not np.array_equal(entry[1], K):
        return None
    if entry[3] != tuple(int(v) for v in tuple(shape)[:2]):
        return None
    return entry[2]


def fov_degrees(fov) -> float:
    """`fov` as a float, checked as a horizontal field of view in degrees (> 0, < 180), or a
    ValueError; no warning (:func:`K_from_fov` gives those, once: a command line's checks
    before reading the map said its radians warning three times, an audit)."""
    try:
        value = float(fov)
    except (TypeError, ValueError):
        value = float("nan")
    if isinstance(fov, bool) or not (np.isfinite(value) and 0.0 < value < 180.0):
        raise ValueError(f"`fov` must be a horizontal field of view in degrees, > 0 and < 180; "
                         f"got {fov!r}")
    return value


def make_camera(pixel_size=1.0, K=None) -> Camera:
    """:class:`Pinhole` for intrinsics `K` (checked), else :class:`Orthographic`.

    Raises
    ------
    ValueError
        A non-positive or non-finite `pixel_size`, `K` that is not valid intrinsics, or a
        `pixel_size` other than 1 with `K` (ignored before, silently).
    """
    if isinstance(K, Pinhole):  # (a camera object: its intrinsics)
        K = K.K
    if isinstance(pixel_size, (str, bytes)):  # (float("1") would take it)
        raise ValueError(f"`pixel_size` must be a positive number; got {pixel_size!r}")
    if K is not None:
        try:
            one = not isinstance(pixel_size, bool) and float(pixel_size) == 1.0
        except (TypeError, ValueError, OverflowError):
            one = False
        if not one:
            raise ValueError(f"`pixel_size` {pixel_size!r} applies to orthographic input; with "
                             "`K` the scale comes from the intrinsics: leave pixel_size at 1, "
                             "or drop K (--orthographic ignores a dataset folder's K.txt)")
        return Pinhole(check_K(K))
    try:
        h = float(pixel_size)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"`pixel_size` must be a positive number; got {pixel_size!r}") from None
    if isinstance(pixel_size, bool) or not (np.isfinite(h) and h > 0):
        raise ValueError(f"`pixel_size` must be a positive finite number; got {pixel_size!r}")
    lo, hi = PIXEL_SIZE_RANGE
    if not lo <= h <= hi:
        raise ValueError(f"`pixel_size` must lie in [{lo:g}, {hi:g}] (beyond, the arithmetic "
                         f"under- or overflows; choose other units); got {pixel_size!r}")
    return Orthographic(h)


#: Focal lengths (pixels) that :func:`check_K` accepts, and pixel sizes that
#: :func:`make_camera` accepts: far beyond any camera, and within them the arithmetic stays
#: finite (a focal length of 1e-300 divided by zero; 1e300 overflowed the deviation).
FOCAL_RANGE = (1e-6, 1e9)
PIXEL_SIZE_RANGE = (1e-12, 1e12)


def check_K(K) -> np.ndarray:
    """`K` as a (3, 3) float array of valid intrinsics, or a ValueError naming what is wrong.
    Four numbers ``(fx, fy, cx, cy)`` are taken too, and nine, the matrix row by row, as the
    command line's K files are (a flat ``K.ravel()`` was refused by integrate while read_K
    and --K took it, a review)."""
    from .problem import numeric_array

    if isinstance(K, Orthographic):  # (was "must be a real numeric array; got dtype object",
        # from integrate and metrics.evaluate alike, an audit)
        raise ValueError(f"`K` is an orthographic camera ({K!r}): leave K out and give "
                         f"pixel_size={K.pixel_size:g} instead")
    Km = numeric_array(K, "K").astype(float)
    if Km.shape == (4,):  # (fx, fy, cx, cy): cx a column, cy a row from the top
        fx, fy, cx, cy = Km
        Km = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    elif Km.shape == (9,):  # (the matrix row by row)
        Km = Km.reshape(3, 3)
    if Km.shape != (3, 3):
        raise ValueError(f"`K` must be a 3x3 intrinsics matrix, its nine numbers row by row, "
                         f"or four numbers (fx, fy, cx, cy); got shape {Km.shape}")
    if not np.isfinite(Km).all():
        raise ValueError("`K` contains NaN or inf")
    if not (Km[0, 0] > 0 and Km[1, 1] > 0):
        raise ValueError(f"`K` must have positive focal lengths fx=K[0,0], fy=K[1,1]; got {Km}")
    lo, hi = FOCAL_RANGE
    if not (lo <= Km[0, 0] <= hi and lo <= Km[1, 1] <= hi):
        raise ValueError(
            f"`K`'s focal lengths fx=K[0,0]={Km[0, 0]:g}, fy=K[1,1]={Km[1, 1]:g} must lie in "
            f"[{lo:g}, {hi:g}] pixels (beyond, the camera's arithmetic under- or overflows); "
            "intrinsics in other units (normalised, mm) must be converted to pixels"
        )
    if not np.allclose(Km[2], [0, 0, 1]) or Km[1, 0] != 0:
        # (named as read_K names it: K.T in Python was told the layout alone, an audit)
        transposed = np.allclose(Km[:, 2], [0, 0, 1]) and np.allclose(np.triu(Km, 1), 0)
        raise ValueError(
            "`K` must be upper-triangular with last row [0, 0, 1] (OpenCV layout "
            f"[[fx, s, cx], [0, fy, cy], [0, 0, 1]]); got {Km.tolist()}"
            + (_transposed_advice(Km) if transposed else "")
        )
    return Km


def _transposed_advice(Km: np.ndarray) -> str:
    """check_K's words for a K that looks transposed (`Km`, as given): give its transpose;
    and where it is MATLAB's ``IntrinsicMatrix`` (cameraParameters, cameraIntrinsics), whose
    image coordinates put the first pixel's centre at (1, 1) where OpenCV's and facetlift's
    put it at (0, 0), subtract 1 from cx and cy too (as MATLAB's own
    ``cameraIntrinsicsToOpenCV`` does): the transpose alone leaves the principal point a
    pixel off (a review)."""
    fx, fy, s, cx, cy = Km[0, 0], Km[1, 1], Km[1, 0], Km[2, 0], Km[2, 1]
    skew = f"s {s:g}, " if s else ""
    return ("; it looks transposed (a column-vector layout, e.g. MATLAB's IntrinsicMatrix): "
            "give its transpose, and for MATLAB's also subtract 1 from cx and cy (MATLAB "
            "counts the first pixel's centre as (1, 1), OpenCV and facetlift as (0, 0)): "
            f"fx {fx:g}, fy {fy:g}, {skew}cx {cx - 1:g}, cy {cy - 1:g} (cx {cx:g}, cy {cy:g} "
            "for a transposed K that was 0-based already)")


#: The largest numerator and denominator of a scale between a calibration's image size and
#: a normal map's that :func:`check_image_size` names as a resize (1/2, 2/3, 5/8, 4).
RESIZE_TERMS = 16


def resize_ratio(stated: tuple[int, int], shape: tuple[int, int]) -> Fraction | None:
    """The simple fraction r (a :class:`fractions.Fraction`, numerator and denominator at most
    :data:`RESIZE_TERMS`, not 1) by which an image of size `stated` (H, W) was resized to
    `shape` (H, W): ``r * H`` and ``r * W`` each within one pixel of the map's (a resize
    rounds); None where no such r fits both axes."""
    (Hc, Wc), (H, W) = (int(v) for v in stated), (int(v) for v in shape)
    if min(Hc, Wc, H, W) <= 0:
        return None
    for q in range(1, RESIZE_TERMS + 1):
        for p in range(1, RESIZE_TERMS + 1):
            r = Fraction(p, q)
            if r.denominator == q and r != 1 and abs(Hc * r - H) < 1 and abs(Wc * r - W) < 1:
                return r
    return None


def check_image_size(K, stated, shape, source: str, arg: str = "K",
                     of: str = "the normal map") -> None:
    """Refuse a camera `K` whose calibration file `source` states the image size `stated`
    (H, W) where the normal map (`of`: what is compared, e.g. "the result" for evaluate) is
    of size `shape` (H, W): its K is that image's, and bends the whole surface of another (a
    fresh user's 1224 x 1024 calibration on a 612 x 512 map was caught only by chance). Where
    the map is that image resized by a simple fraction (:func:`resize_ratio`) the message
    says so and gives K scaled with it; where it is that image turned on its side, it says
    so; a K already adjusted for a crop is told to come without the stated size (a plain K
    file or inline). None where the sizes agree or `stated` is None.

    Raises
    ------
    ValueError
        Naming `arg`, `source` and both sizes.
    """
    if stated is None:
        return
    (Hc, Wc), (H, W) = (int(v) for v in stated), (int(v) for v in tuple(shape)[:2])
    if (Hc, Wc) == (H, W):
        return
    head = (f"`{arg}`: {source} is the calibration of a {Wc} x {Hc} image (W x H) but "
            f"{of} is {W} x {H}")
    plain = ("a K already adjusted for it has no image size to compare: give it as a plain K "
             "file (fx fy cx cy) or inline (--K \"fx fy cx cy\"; K= in Python)")
    if (Hc, Wc) == (W, H):
        raise ValueError(
            f"{head}: the image is turned on its side (portrait against landscape): K is "
            "for the image as calibrated; rotate the map back, or swap fx, fy and cx, cy for "
            f"a transposed image ({plain}); docs/conventions.md, 'A K for another image'")
    r = resize_ratio((Hc, Wc), (H, W))
    if r is None:
        raise ValueError(
            f"{head}: K is for another image. Give the calibration of the image the map was "
            "computed from; after a crop starting at column c0, row r0, subtract them from cx "
            f"and cy; after a resize by s, scale fx, fy, cx and cy with it; {plain} "
            "(docs/conventions.md, 'A K for another image')")
    s = float(r)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    how = (f"downsampled {1 / r}x" if r.numerator == 1 else f"upsampled {r}x"
           if r.denominator == 1 else f"resized by {r}")
    scaled = f"{s * fx:.6g} {s * fy:.6g} {s * (cx + 0.5) - 0.5:.6g} {s * (cy + 0.5) - 0.5:.6g}"
    n = r.denominator
    stride = (f"; for image[::{n}, ::{n}] (one pixel in {n} kept) K[:2] / {n} instead "
              f"(facetlift.Pinhole(K).subsampled({n}))" if r.numerator == 1 else "")
    raise ValueError(
        f"{head}: it looks like that image {how} ({W}/{Wc}, {H}/{Hc}: {r}), so K must be "
        f"scaled by {r} too: for a resize (cv2.resize, PIL) fx fy cx cy = {scaled} (fx, fy "
        f"times {r}; cx, cy as pixel centres, {r} (c + 0.5) - 0.5){stride}. Give the scaled K "
        "as a file or inline (--K \"fx fy cx cy\"; K= in Python); docs/conventions.md, 'A K "
        "for another image'")
