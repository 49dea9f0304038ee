"""Checked inputs shared by every integration method.

:func:`prepare` is the single public-boundary check: it turns user arrays into a
:class:`Problem` or raises ``ValueError`` naming the argument and what was wrong.

Bad normals
    Only pixels inside the mask are inspected. A normal there that cannot be used -- not
    finite, zero length, facing away from the camera, or grazing (the view cosine below the
    outlier threshold, Sec. 4.4 of Xie et al.), or, where the caller asks for it (the
    discontinuity route does), isolated (:func:`isolated_normals`) -- becomes a missing sample:
    counted in
    ``Problem.counts``, named in one warning (how many of each kind, where the first is), and
    integrated like a NaN normal. A job is refused only when no usable normal is left.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ._warnings import warn
from .camera import Camera, make_camera
from .domain import Domain
from .errors import CameraWarning
from .frames import EDGE_ON, GRADIENT_FIELD, flip_advice, reading, world_note

#: ``backfacing=`` choices: treat such normals as missing samples, or raise.
BACKFACING = ("missing", "error", "outlier")


#: Where the normals face the optical axis but not a pinhole camera's rays, the map is taken
#: for an orthographic one given a camera only if negating x or y alone leaves shares facing
#: away within this factor of each other (:func:`prepare`).
FLIPS_EVEN = 2.0


def _faces_the_axis(cam, nf, clear, away: float):
    """The share of the normals that face away along the optical axis (n_z < 0), where many
    face away from a pinhole camera's rays (``away`` above :data:`BACKFACING_FRAME_HINT`) but
    at most a few along the axis (that share at most the threshold and a quarter of
    ``away``): an orthographic map given a camera, or a field of view too wide, which no
    flip mends (a head-on map with a 60-degree fov was told to flip y, and came out worse,
    an audit). None otherwise."""
    if not away > BACKFACING_FRAME_HINT or not getattr(cam, "perspective", False):
        return None
    k = np.flatnonzero(clear)
    if k.size == 0:
        return None
    share = float(np.mean(nf[k, 2] < 0))
    return share if share <= min(BACKFACING_FRAME_HINT, away / 4) else None


def _flip_shares(cam, r, c, nf, clear) -> dict:
    """``{axis: share}``: the share of the `clear` normals that would face away from the
    pinhole camera with x, y or both ("xy") negated ({} without a camera or clear normals).
    Both: a y-down map read with x flipped (a DSINE map given the other estimator's flag),
    which the single flips did not mend and was called orthographic, a review."""
    k = np.flatnonzero(clear)
    if k.size == 0 or not getattr(cam, "perspective", False):
        return {}
    shares = {}
    for axis, sign in (("y", (1.0, -1.0, 1.0)), ("x", (-1.0, 1.0, 1.0)),
                       ("xy", (-1.0, -1.0, 1.0))):
        with np.errstate(invalid="ignore"):
            cf = cam.view_cosine(r[k], c[k], nf[k] * np.array(sign), unit=True)
        shares[axis] = float(np.mean(cf < 0))
    return shares


def _silhouette_right(domain, nf, known, axes: str) -> bool:
    """Whether the mask's edge, where it is a silhouette, says every axis of `axes` ("x",
    "y" or "xy") runs as read: its normals point out of the object along them
    (:func:`facetlift.frames.silhouette`). A flip that mends the facing is then no flip but a
    camera too wide for the map, e.g. an orthographic one's (a review: a right orthographic
    vase given a 90-degree field of view was told that x runs the other way, and a spot
    render that both do; following either turned the surface inside out)."""
    from .frames import _silhouette_says, silhouette_of

    sil = silhouette_of(domain, known, nf)
    return all(_silhouette_says(sil, a) == "out" for a in axes)


def _flip_mends_facing(cam, r, c, nf, clear, away: float, shares=None):
    """``(axis, share)`` where many normals face away from a pinhole camera (``away`` above
    :data:`BACKFACING_FRAME_HINT`) and negating x or y alone turns all but a few of them
    toward it (the share facing away then: at most that threshold and a quarter of
    ``away``): a map read with y (or x) the wrong way round. None otherwise, and always
    without a camera, whose view cosine is n_z whatever x and y are. `shares`: those of
    :func:`_flip_shares`, where the caller has them."""
    if not away > BACKFACING_FRAME_HINT:
        return None
    if shares is None:
        shares = _flip_shares(cam, r, c, nf, clear)
    if not shares:
        return None
    # (a single flip first, where one mends: a y-down room's front wall faces the camera
    # either way, so negating both mended it as well as y alone)
    for axes in (("x", "y"), ("xy",)):
        axis = min((a for a in axes if a in shares), key=shares.get, default=None)
        if axis is not None and shares[axis] <= min(BACKFACING_FRAME_HINT, away / 4):
            return axis, shares[axis]
    return None


#: With a pinhole camera (whose grazing rule keeps rims down to a view cosine of 1/255), no
#: isolated-normal rule given and ``steep_isolated`` (the smooth DGP's), a normal steeper
#: than this view cosine (85 deg from the ray, the orthographic default's outlier_eps) that
#: is isolated by :data:`STEEP_ISOLATED_RULE` (the discontinuity route's rule) becomes a
#: missing sample: a wrong normal nearly edge-on inside an object, not a rim, whose slope of
#: up to 255 footprints per pixel bends the whole surface (a review: 80 such pixels on the
#: DiLiGenT bear, 0.2 % of its mask, raised its MADE 0.47 -> 3.9 mm; 30 on a 256^2 render
#: 1.4 -> 6.9 mm).
STEEP_ISOLATED, STEEP_ISOLATED_RULE = float(np.cos(np.radians(85.0))), (15.0, 10.0)


#: View cosine below which a grazing normal is dropped even where :func:`prepare`'s
#: `grazing_share` keeps a component's edge-on surface: the pinhole cameras' default (slopes
#: up to 255 footprints per pixel).
GRAZING_FLOOR = 1.0 / 255.0


#: Median angle (degrees) between neighbouring grazing normals above which an edge-on
#: surface's normals are noise, not a surface, and :func:`_edge_on_kept` keeps none of them.
#: Near edge-on a normal's slope is about ``1 / cos``: a degree of noise there moves it by
#: hundreds of footprints. Measured on the held-out trays seen 1-4 deg from edge-on: exact,
#: 8- and 16-bit, smoothly correlated errors and isolated outliers 0.00-0.16 deg (90 %
#: below 0.45), 3 deg of independent noise 1.7-2.6 deg; kept, those noisy normals raised the
#: route's MADE on the tray seen 4 deg from edge-on from 1.5 to 7.4 mm.
EDGE_ON_SPREAD = 1.0


def _edge_on_kept(domain, front, grazing, cos, share, nf):
    """The grazing normals (facet mask) that `share` keeps: those at or above
    :data:`GRAZING_FLOOR` in the components where the grazing rule would drop more than
    `share` of the front-facing normals (a surface seen edge-on, not a rim) and where
    neighbouring ones (8-neighbours, as the components are connected) agree within a median
    angle of :data:`EDGE_ON_SPREAD`; None where it keeps none."""
    if share is None or not grazing.any():
        return None
    comp = domain.facet_component
    nc = domain.n_components
    dropped = np.bincount(comp[grazing], minlength=nc)
    broad = dropped > share * np.bincount(comp[front], minlength=nc)
    if not broad.any():
        return None
    kept = grazing & broad[comp] & (cos >= GRAZING_FLOOR)
    if not kept.any():
        return None
    # (the angles between neighbouring candidates, and their median per component in one
    # sort: a loop over components cost minutes on a map with thousands of speckles)
    rows = np.flatnonzero(kept)
    r, c = domain.pixels[0][rows], domain.pixels[1][rows]
    r0, c0 = int(r.min()), int(c.min())
    idx = np.full((int(r.max()) - r0 + 1, int(c.max()) - c0 + 1), -1, np.int64)
    idx[r - r0, c - c0] = rows  # (over the kept normals' box only)
    pairs = [(idx[:, :-1], idx[:, 1:]), (idx[:-1], idx[1:]),
             (idx[:-1, :-1], idx[1:, 1:]), (idx[:-1, 1:], idx[1:, :-1])]
    a = np.concatenate([x[(x >= 0) & (y >= 0)] for x, y in pairs])
    b = np.concatenate([y[(x >= 0) & (y >= 0)] for x, y in pairs])
    del idx, pairs
    with np.errstate(invalid="ignore"):
        angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", nf[a], nf[b]), -1, 1)))
    group = comp[a]
    order = np.lexsort((angle, group))
    angle, group = angle[order], group[order]
    count = np.bincount(group, minlength=nc)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    has = count > 0
    median = np.full(nc, np.inf)
    lo = start[has] + (count[has] - 1) // 2
    hi = start[has] + count[has] // 2
    median[has] = 0.5 * (angle[lo] + angle[hi])
    noisy = ~(median <= EDGE_ON_SPREAD)  # (no pair at all: not shown to be a surface)
    kept &= ~noisy[comp]
    return kept if kept.any() else None


class UnusableNormalsWarning(UserWarning):
    """Normals inside the mask that were treated as missing samples (non-finite, zero-length,
    back-facing, grazing, isolated), with their counts and the first one's place."""


#: Share of a map's finite normals facing away from the camera above which the unusable-normal
#: warning asks whether the map is in another frame (a world-frame Blender pass of the
#: DiLiGenT bear: 22 %; its own map: 0 of 40,670; the 36 DiLiGenT-like perspective renders of
#: the discontinuity benchmark quantised to 8 bits: at most 0.04 %).
BACKFACING_FRAME_HINT = 0.05

#: Share of the mask's normals dropped as back-facing or grazing without a camera (an
#: orthographic reading) at or above which the unusable-normals warning and ``info`` add that
#: a perspective photo's obliquely seen surfaces do that (:func:`no_camera_hint`; an audit: a
#: neural estimator's indoor scene lost its floor and a side wall, 82k normals, with the
#: generic warning alone).
NO_CAMERA_SHARE = 0.05


def no_camera_hint(counts: dict, perspective: bool, field: bool = False) -> str:
    """The hint, or "", that normals dropped as facing away or grazing (`counts`, as
    :attr:`Problem.counts`) without a camera may be those of a perspective photo's walls and
    floor: given where no camera (`perspective` False) and no gradient field (`field`,
    orthographic by nature) and at least :data:`NO_CAMERA_SHARE` of the mask."""
    dropped = int(counts.get("back-facing", 0)) + int(counts.get("grazing", 0))
    pixels = int(counts.get("pixels", 0))
    if perspective or field or not pixels or dropped < NO_CAMERA_SHARE * pixels:
        return ""
    return (f"{dropped / pixels:.0%} of the mask's normals face away or graze as read without "
            "a camera (orthographically, every pixel seen along the same axis): normals of "
            "surfaces that a perspective camera sees obliquely (the walls and floor of a "
            "photo) face away under an orthographic reading. If the map is of a photo, give "
            "its camera: --fov DEG (the horizontal field of view) or --K FILE (in Python "
            "K=facetlift.camera.K_from_fov(normals.shape[:2], deg) or K=)")


#: A blurred prior (``prior_blur``) with a median sample weight above this gets a warning
#: (docs/fusion.md, "Blurred priors": the benchmark's range is 0.001-0.01).
BLUR_WEIGHT_WARN = 0.03

#: ``prior_weight`` where none is given and the prior is blurred (``prior_blur``): the fusion
#: benchmark's weight for its blurred coarse prior (docs/fusion.md, "Measured: the coarse
#: prior, blurred against pixel by pixel": the fused result beats both inputs on 45 / 38 of 51
#: scenes, smooth / with discontinuities). Weight 1, the pointwise default, undoes the blur's
#: own errors (a fresh user's exact depth given as blurred by 4 px: depth from 0.25 to 6 m for
#: a scene of 0.75-1.6 m; 0.73-1.75 m at this weight).
BLURRED_PRIOR_WEIGHT = 0.003

#: A normal shorter than this fraction of the map's median normal length counts as
#: zero-length (no direction, only rounding: a (1e-12, 0, 0) was renormalised to (1, 0, 0));
#: relative, so that a map scaled as a whole keeps every normal.
ZERO_LENGTH = 1e-6


@dataclass(eq=False)
class Problem:
    """A normal-integration problem on a domain (see :mod:`facetlift.conventions`).

    Attributes
    ----------
    domain : Domain
    normals : (m, 3) float
        Unit normals of the facets (x right, y up, z toward the viewer); NaN where not given.
    known : (m,) bool
        Facets with a given, finite, front-facing normal.
    camera : Camera
        :class:`~facetlift.camera.Orthographic` or :class:`~facetlift.camera.Pinhole`.
    usable : (m,) bool
        Known facets whose normal is not grazing: the samples the methods integrate.
    counts : dict
        How many mask pixels had no usable normal, by reason (see :func:`prepare`).
    prior : (m,) float, optional
        Depth prior as values of the camera's unknown (height, or log-depth), NaN where a
        facet has none (:func:`check_prior`); None without a prior.
    prior_weight : (m,) float, optional
        Weight of each facet's prior term, 0 where it has none (docs/fusion.md: 1 counts one
        prior sample as much as one pixel's normal).
    confidence : (m,) float, optional
        Weight of each facet's normal term (> 0 at usable facets; a confidence of 0 made the
        facet a missing sample); None: all 1.
    prior_blur : float
        Standard deviation (pixels) of the blur the prior is seen through: the prior is
        compared with the result blurred alike (:class:`facetlift.operators.blur.PlaneBlur`,
        docs/fusion.md); 0 compares them pixel by pixel.
    """

    domain: Domain
    normals: np.ndarray
    known: np.ndarray
    camera: Camera = field(default_factory=make_camera)
    usable: np.ndarray | None = None
    counts: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)
    prior: np.ndarray | None = None
    prior_weight: np.ndarray | None = None
    confidence: np.ndarray | None = None
    prior_blur: float = 0.0

    def __post_init__(self):
        if self.usable is None:
            self.usable = self.known.copy()

    @property
    def perspective(self) -> bool:
        return self.camera.perspective

    @property
    def K(self) -> np.ndarray | None:
        return self.camera.K

    @property
    def pixel_size(self) -> float:
        return self.camera.pixel_size

    @cached_property
    def grid_slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """(gx, gy), each (m,): change of the unknown per pixel step along x (right) and y (up)
        implied by the usable normals (:meth:`facetlift.camera.Camera.grid_slopes`); NaN at
        facets without a usable normal."""
        r, c = self.domain.pixels
        n = np.where(self.usable[:, None], self.normals, [0.0, 0.0, 1.0])
        gx, gy = self.camera.grid_slopes(r, c, n)
        return np.where(self.usable, gx, np.nan), np.where(self.usable, gy, np.nan)

    @cached_property
    def view_cosines(self) -> np.ndarray:
        """(m,) cosine between each usable normal and the direction toward the camera
        (:meth:`facetlift.camera.Camera.view_cosine`); 0 at facets without a usable normal."""
        r, c = self.domain.pixels
        n = np.where(self.usable[:, None], self.normals, [0.0, 0.0, 1.0])
        return np.where(self.usable, self.camera.view_cosine(r, c, n, unit=True), 0.0)

    def grazing_between(self, a: float, b: float, without=None, share=None) -> int:
        """How many given normals (front-facing, not missing for another reason, confidence
        above 0, not in `without` (m,) bool) have a view cosine between the thresholds `a`
        and `b` (the larger excluded): those that one grazing threshold drops and the other
        keeps. With `share` (:func:`prepare`'s `grazing_share`, for the larger threshold)
        the normals of an edge-on surface that it keeps are not counted."""
        lo, hi = sorted((a, b))
        given, cos, kept = self._edge_on(hi, share, without)
        between = given & (cos >= lo) & (cos < hi)
        if kept is not None:
            between &= ~kept
        return int(between.sum())

    def edge_on_kept(self, eps: float, share: float, without=None) -> int:
        """How many given normals (as :meth:`grazing_between` takes them) a grazing threshold
        `eps` with :func:`prepare`'s `grazing_share` `share` keeps as a surface seen edge-on
        (``counts["grazing_kept"]`` of a problem prepared so)."""
        kept = self._edge_on(eps, share, without)[2]
        return 0 if kept is None else int(kept.sum())

    def _edge_on(self, eps: float, share, without=None):
        """(given, view cosines, kept or None) of the given normals not in `without`, and
        those a grazing threshold `eps` with `share` keeps (:func:`_edge_on_kept`)."""
        given = self._given()
        if without is not None:
            given = given & ~without
        r, c = self.domain.pixels
        n = np.where(given[:, None], self.normals, [0.0, 0.0, 1.0])
        cos = self.camera.view_cosine(r, c, n, unit=True)
        kept = _edge_on_kept(self.domain, given, given & ((cos < eps) | (cos == 0)), cos,
                             share, n)
        return given, cos, kept

    def isolated(self, rule) -> np.ndarray:
        """(m,) bool: the normals that :func:`isolated_normals` of `rule` ``(deviation,
        agreement)`` finds among this problem's front-facing ones (what a problem prepared
        without ``isolated=`` kept and the discontinuity route would drop); normals of
        confidence 0 are missing, as :func:`prepare` takes them."""
        return isolated_normals(self.domain, self.normals, self._given(), *rule)

    def _given(self) -> np.ndarray:
        """(m,) bool: the front-facing normals not missing for another reason (missing,
        non-finite, zero-length, of confidence 0): those the input rules look at."""
        gone = self.extras.get("no_normal")
        return self.known if gone is None else self.known & ~np.asarray(gone, bool)

    @property
    def slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """(p, q), each (m,): grid slopes per footprint; for an orthographic camera the height
        gradient ``p = dz/dx``, ``q = dz/dy``. NaN where not usable."""
        gx, gy = self.grid_slopes
        s = self.camera.footprint()
        return gx / s, gy / s

    @property
    def has_prior(self) -> bool:
        """Whether some facet carries a prior term with a positive weight."""
        return self.prior_weight is not None and bool((self.prior_weight > 0).any())

    @cached_property
    def prior_components(self) -> np.ndarray:
        """(n_components,) bool: components with at least one weighted prior sample (their
        constant is fixed by the prior, not by the camera's gauge)."""
        d = self.domain
        if not self.has_prior:
            return np.zeros(d.n_components, dtype=bool)
        return np.bincount(d.facet_component[self.prior_weight > 0],
                           minlength=d.n_components) > 0

    def prior_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """``(weight, target)``, each (m,): the prior term ``weight (u_f - target)^2`` of every
        facet's centre value ``u_f`` (weight 0 and target 0 where a facet has none)."""
        m = self.domain.n_facets
        if not self.has_prior:
            return np.zeros(m), np.zeros(m)
        w = self.prior_weight
        return w, np.where(w > 0, np.nan_to_num(self.prior), 0.0)

    def normal_weight(self) -> np.ndarray:
        """(m,) weight of every facet's normal term: the confidence, 1 without one."""
        if self.confidence is None:
            return np.ones(self.domain.n_facets)
        return self.confidence

    def normal_image(self) -> np.ndarray:
        """(H, W, 3) normals with NaN outside the domain and at unknown facets."""
        H, W = self.domain.shape
        out = np.full((H, W, 3), np.nan)
        out[self.domain.pixels] = self.normals
        return out

    def restrict(self, domain: Domain, camera: Camera) -> Problem:
        """The same samples on `domain`, a crop of this problem's domain with the same facet
        order (:func:`facetlift.api.crop`), seen by `camera`."""
        return Problem(
            domain=domain, normals=self.normals, known=self.known, camera=camera,
            usable=self.usable, counts=self.counts, extras=self.extras, prior=self.prior,
            prior_weight=self.prior_weight, confidence=self.confidence,
            prior_blur=self.prior_blur,
        )


def normals_from_gradients(p, q) -> np.ndarray:
    """Unit normals ``(-p, -q, 1) / |.|`` from height gradients.

    Parameters
    ----------
    p, q : (H, W) array_like of float
        ``dz/dx`` (x right) and ``dz/dy`` (y up) of the height; NaN marks missing samples.

    Returns
    -------
    (H, W, 3) float
        Normals in the facetlift convention; NaN where `p` or `q` is NaN.
    """
    if q is None:  # (said "`q` must be a real numeric array; got dtype object", an audit)
        shape = np.shape(p)
        split = (" (an (H, W, 2) array: give p[..., 0] and p[..., 1])"
                 if len(shape) == 3 and shape[-1] == 2 else "")
        raise ValueError(f"`q` is required: the slopes come as two (H, W) arrays p and q{split}")
    p = _float_array(p, "p")
    q = _float_array(q, "q")
    if p.ndim != 2:
        raise ValueError(f"`p` must be a 2-D (H, W) array; got shape {p.shape}")
    if q.shape != p.shape:
        raise ValueError(f"`q` must have the shape of `p` {p.shape}; got {q.shape}")
    n = np.stack([-p, -q, np.ones_like(p)], axis=-1)
    inf = np.isinf(p) | np.isinf(q)
    if inf.any():  # an infinite slope is a vertical facet: its normal's limit, z = 0 (a
        # grazing normal, which the grazing rule then counts as a missing sample)
        n[inf] = np.stack([-np.sign(p[inf]) * np.isinf(p[inf]),
                           -np.sign(q[inf]) * np.isinf(q[inf]), np.zeros(int(inf.sum()))], -1)
    with np.errstate(invalid="ignore"):  # (NaN rows stay NaN)
        n /= np.max(np.abs(n), axis=-1, keepdims=True)  # (no overflow in the norm: 1e300)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def gradients_from_normals(normals) -> tuple[np.ndarray, np.ndarray]:
    """``(p, q) = (-n_x / n_z, -n_y / n_z)`` for an (H, W, 3) normal map."""
    n = _float_array(normals, "normals")
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}"
                         + _channel_first_hint(n.shape))
    with np.errstate(divide="ignore", invalid="ignore"):
        return -n[..., 0] / n[..., 2], -n[..., 1] / n[..., 2]


#: The reader of each argument that a file name given as an array is pointed to.
_READERS = {"normals": "facetlift.io.read_normals", "mask": "facetlift.io.read_mask",
            "known": "facetlift.io.read_mask", "K": "facetlift.io.read_K",
            "prior": "facetlift.io.read_prior, or read_depth for a float map",
            "prior_weight": "facetlift.io.read_weights",
            "confidence": "facetlift.io.read_weights", "p": "numpy.load, or facetlift.io."
            "read_depth", "q": "numpy.load, or facetlift.io.read_depth"}


def numeric_array(a, name: str, what: str = "a real numeric array") -> np.ndarray:
    """``np.asarray(a)`` if it is a real numeric (or boolean) array, else a ValueError naming
    `name`. Shared by the input checks here and the writers in :mod:`facetlift.io`."""
    a = unmasked(a)
    if isinstance(a, (str, os.PathLike)):  # (said "got dtype <U16" to a path, an audit)
        reader = _READERS.get(name.split("[")[0], "its reader in facetlift.io")
        raise ValueError(f"`{name}` must be {what}, not a file name ({os.fspath(a)!r}): read "
                         f"the file first ({reader})")
    try:
        arr = np.asarray(a)
    except Exception as e:  # ragged lists and the like
        raise ValueError(f"`{name}` could not be read as an array: {e}") from None
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        raise ValueError(f"`{name}` must be {what}; got dtype {arr.dtype}")
    return arr


def unmasked(a, fill=np.nan):
    """A numpy masked array as a plain float array with `fill` (NaN: missing, unknown) at its
    masked entries; anything else as it is. ``np.asarray`` drops the mask: a masked array's
    masked normals were integrated as if valid (an audit)."""
    if np.ma.isMaskedArray(a) and np.ma.getmask(a) is not np.ma.nomask:
        return np.ma.filled(np.ma.asarray(a).astype(float), fill)
    return np.ma.getdata(a) if np.ma.isMaskedArray(a) else a


def finite_values(a: np.ndarray, name: str) -> np.ndarray:
    """`a`, refused (ValueError naming `name`) where it is a float array holding NaN or inf:
    a mask's or a weight's values must all be numbers."""
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ValueError(f"`{name}` contains NaN or inf")
    return a


def _float_array(a, name: str) -> np.ndarray:
    return numeric_array(a, name).astype(float, copy=True)


def _bool_image(a, name: str, shape: tuple[int, int]) -> np.ndarray:
    arr = numeric_array(unmasked(a, 0.0), name, "a boolean or numeric array")  # (masked: out)
    if arr.shape != shape:
        raise ValueError(f"`{name}` must have shape {shape} to match `normals`; got {arr.shape}")
    finite_values(arr, name)
    inside = negatives_outside(arr, f"`{name}`")
    if arr.dtype.kind == "f" and inside.any():
        # (a soft matte or a probability map: every value above 0 was inside, the domain grew
        # by 66 % on a blurred mask, an audit; read_mask warns about soft files alike)
        soft = int(np.count_nonzero((arr > 0) & (arr < 1)))
        if soft > SOFT_MASK_SHARE * int(inside.sum()):
            warn(f"`{name}` holds {soft} values between 0 and 1 (a soft matte or a "
                 "probability map?): every pixel above 0 counts as inside "
                 f"({int(inside.sum())} pixels); threshold it first (e.g. {name} > 0.5) if "
                 "that is not meant")
    return inside


#: Share of a gradient field's samples past the grazing rule above which its warning asks
#: whether the slopes are in other units (:func:`prepare`).
STEEP_FIELD = 0.5


def negatives_outside(arr: np.ndarray, name: str) -> np.ndarray:
    """(H, W) bool: the pixels of the mask values `arr` above 0, with a warning naming `name`
    where some are negative, which count as outside. A logit or a signed mask (-5 outside,
    5 inside) made every pixel inside as "nonzero", the background's NaN normals filled in
    as surface without a word (an audit)."""
    negative = int(np.count_nonzero(arr < 0)) if arr.dtype.kind in "if" else 0
    if negative:
        warn(f"{name} holds {negative} negative values (a logit or a signed map?): they count "
             f"as outside, the {int(np.count_nonzero(arr > 0))} above 0 as inside; threshold "
             "it yourself if another split is meant")
    return arr > 0


#: Share of a float mask's inside pixels with values strictly between 0 and 1 above which it
#: is warned about as soft (:func:`_bool_image`).
SOFT_MASK_SHARE = 0.01


def prepare(
    normals,
    mask=None,
    *,
    known=None,
    pixel_size: float = 1.0,
    K=None,
    camera: Camera | None = None,
    backfacing: str = "missing",
    outlier_eps: float | None = None,
    prior=None,
    prior_weight=None,
    confidence=None,
    grazing_note: str | None = None,
    prior_blur=None,
    prior_outliers: str = "remove",
    isolated: tuple[float, float] | None = None,
    grazing_share: float | None = None,
    steep_isolated: bool = False,
) -> Problem:
    """Check user inputs and build a :class:`Problem`.

    Parameters
    ----------
    normals : (H, W, 3) array_like of float
        Normal map (x right, y up, z toward the viewer); need not be unit length. NaN marks a
        missing sample inside the mask. Pixels outside the mask may hold anything.
    mask : (H, W) array_like of bool, optional
        Integration domain. Default: pixels whose normal is finite and non-zero (an isolated
        one, without such a neighbour, is left out with a warning; small holes of pixels
        without one inside the object are counted and warned about, larger ones counted
        apart, :data:`HOLE_PIXELS`).
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the others in the mask are missing samples.
    pixel_size : float
        Pixel width in world units (orthographic views).
    K : (3, 3) array_like, nine numbers (row by row) or four (fx, fy, cx, cy), optional
        Perspective intrinsics, OpenCV layout.
    camera : facetlift.camera.Camera, optional
        Instead of `pixel_size` and `K`.
    backfacing : {"missing", "error"}
        Normals facing away from the camera inside the domain: treat them as missing samples
        (default; "outlier" is an alias) or raise.
    outlier_eps : float in [0, 1), optional
        Normals whose cosine to the direction toward the camera is below this are grazing and
        become missing samples (the paper's outlier rule). Default: the camera's
        (cos 85 deg orthographic, 1/255 perspective; :mod:`facetlift.camera`).
        :func:`facetlift.integrate` passes the discontinuity route's own rule
        (``MethodInfo.jump_grazing``); a Problem prepared here for :func:`facetlift.solve`
        keeps what it is given.
    prior, prior_weight, confidence
        Depth prior and weights (:func:`check_prior`, :func:`check_confidence`; see
        docs/fusion.md). A pixel with confidence 0 becomes a missing sample. `prior_weight`
        None: :func:`default_prior_weight` (1, or :data:`BLURRED_PRIOR_WEIGHT` with a
        `prior_blur`).
    grazing_note : str, optional
        Where the grazing threshold comes from, for the warning.
    prior_blur : float, optional
        Standard deviation in pixels of the blur the prior is seen through
        (:func:`check_prior_blur`, docs/fusion.md); None or 0: none.
    prior_outliers : {"remove", "keep"}
        "remove" (default): samples of a sparse prior that disagree with every neighbouring
        sample along the normals, and of a dense one (a depth map) with most of the eight
        beside them, are left out, counted and named in a warning
        (:mod:`facetlift.prior_outliers`); "keep": every sample is used.
    grazing_share : float in (0, 1], optional
        The most of a connected component's front-facing normals the grazing rule may drop:
        in a component where `outlier_eps` would drop more, a surface seen edge-on rather
        than a rim, only those below :data:`GRAZING_FLOOR` are dropped where neighbouring
        normals agree within :data:`EDGE_ON_SPREAD` (counted in ``counts["grazing_kept"]``;
        noisy ones are all dropped). None: no limit. :func:`facetlift.integrate` passes the
        discontinuity route's (``MethodInfo.jump_grazing_share``): prepare with
        ``outlier_eps=METHODS["dgp"].jump_grazing, grazing_share=METHODS["dgp"].
        jump_grazing_share`` for :func:`facetlift.solve` to do as it does.
    steep_isolated : bool
        With a pinhole camera and no `isolated` rule: the front-facing normals more than 85
        deg from their ray (:data:`STEEP_ISOLATED`) that :data:`STEEP_ISOLATED_RULE` finds
        isolated become missing samples, counted as ``isolated`` (a wrong normal nearly
        edge-on inside an object, which the camera's grazing rule of 1/255 keeps).
        :func:`facetlift.integrate` passes ``MethodInfo.steep_isolated`` (the smooth DGP's).
        Default False.
    isolated : (deviation, agreement) in degrees, optional
        Front-facing normals more than `deviation` from the median of their eight
        neighbours, which agree with that median within `agreement` (all but the farthest),
        become missing samples (:func:`isolated_normals`; :func:`facetlift.integrate` passes
        the discontinuity route's ``MethodInfo.jump_isolated``). Default None: none.

    Raises
    ------
    ValueError
        On a wrong shape or dtype, an empty mask, a mask of another size, a mask of
        isolated pixels only (stray ones are left out with a warning), a bad pixel size,
        `K` or `outlier_eps`, no usable normal at all, back-facing normals with
        ``backfacing="error"``, or a bad prior, prior weight or confidence (see
        :func:`check_prior`).
    """
    n = numeric_array(normals, "normals")
    if n.dtype == bool:
        raise ValueError("`normals` is a boolean array (a mask?); give (H, W, 3) numbers")
    n = n.astype(float, copy=False)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}"
                         + (_channel_first_hint(n.shape) or (
                             "; a gradient field (p, q) stacked as (H, W, 2) is given as "
                             "facetlift.integrate_gradients(a[..., 0], a[..., 1])"
                             if n.ndim == 3 and n.shape[-1] == 2 else "")))
    H, W = n.shape[:2]
    if H < 1 or W < 1:
        raise ValueError(f"`normals` must have at least one pixel; got shape {n.shape}")
    if backfacing not in BACKFACING:
        raise ValueError(f"`backfacing` must be one of {BACKFACING[:2]}; got {backfacing!r}")
    if camera is not None:  # (K and pixel_size were dropped in silence beside it, and a
        # string failed on an attribute, an audit)
        if not isinstance(camera, Camera):
            raise ValueError(f"`camera` must be a facetlift.camera.Camera (Orthographic, "
                             f"Pinhole); got {type(camera).__name__}: give K= or pixel_size= "
                             "instead")
        if K is not None or not (isinstance(pixel_size, (int, float)) and pixel_size == 1.0):
            raise ValueError("give `camera`, or `K` / `pixel_size`, not both: the camera "
                             "holds them")
    cam = make_camera(pixel_size, K) if camera is None else camera
    if not _check_normalised(cam, H, W):
        _check_principal_point(cam, H, W)
        _check_focal_length(cam, H, W, given=K)
        _check_aspect(cam)
    eps = cam.grazing if outlier_eps is None else _check_eps(outlier_eps)
    isolated = _check_isolated(isolated)
    if grazing_share is not None and not (isinstance(grazing_share, (int, float, np.number))
                                          and 0.0 < float(grazing_share) <= 1.0):
        raise ValueError(f"`grazing_share` must be a number in (0, 1] or None; got "
                         f"{grazing_share!r}")

    if mask is None:
        with np.errstate(over="ignore", invalid="ignore"):
            length2 = np.einsum("ijk,ijk->ij", n, n)
        m = (np.isfinite(length2) & (length2 > 0)) | _huge(n, length2)
        if not m.any():  # (a gradient field's in its words: an all-NaN p was told of its
            # normals, a gradients audit)
            raise ValueError("`p` and `q` have no pixel where both are finite: nothing to "
                             "integrate" if reading() == GRADIENT_FIELD else
                             "`normals` has no finite, non-zero normal: nothing to integrate")
        # (the mask is the normals' own: a lone pixel of it is left out, said)
        m = _without_lone_pixels(
            m, "`normals`: every finite, non-zero normal is an isolated pixel (no neighbour "
            "to fix its depth); give a mask, inside which NaN normals are missing samples",
            "{n} isolated pixel(s) with a normal but no neighbour with one were left out "
            "(first at row {r}, col {c}); without a mask the domain is the finite, non-zero "
            "normals, so NaN ones are outside it: give a mask to make them missing samples "
            "inside it")
        holes, larger_holes = enclosed_gaps(m)
    else:
        holes = larger_holes = None
        m = _bool_image(mask, "mask", (H, W))
        if not m.any():
            raise ValueError("`mask` is empty: no pixel to integrate")
        # (a segmentation's stray pixels: left out, said; never the whole job)
        m = _without_lone_pixels(
            m, "`mask`: every pixel of it is isolated (no neighbour, not even at a corner, to "
            "fix its depth): nothing to integrate",
            "`mask` has {n} one-pixel component(s) (first at row {r}, col {c}): an isolated "
            "pixel has no neighbour to fix its depth, so they were left out (NaN in the "
            "output; facetlift.clean_mask removes them beforehand)")
    domain = Domain.from_mask(m)
    # (its components labelled now, before any solver's peak: labelled first inside a solve,
    # the 30 %-missing 256^2 rectangle's peak went 28.8 -> 45.8 MiB)
    domain.component_sizes  # noqa: B018
    # from here on only the mask's pixels, as (k,) facet arrays in row-major order
    nf = n[m]
    given = np.ones(len(nf), bool) if known is None else _bool_image(known, "known", (H, W))[m]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        length = np.sqrt(np.einsum("ij,ij->i", nf, nf))
        huge = _huge(nf, length)  # (0, 1e200, 1e200) is a fine normal: scale it first
        if huge.any():
            nf[huge] /= np.abs(nf[huge]).max(axis=1, keepdims=True)
            length[huge] = np.sqrt(np.einsum("ij,ij->i", nf[huge], nf[huge]))
        # (the median of at most ~65k of them: a 1e-6 threshold needs no exact one; the
        # huge ones rescaled above are lengths about 1 beside ~1e154: not short)
        typical = length[given & np.isfinite(length) & (length > 0) & ~huge]
        typical = typical[:: max(1, typical.size // 65536)]
        tiny = ZERO_LENGTH * float(np.median(typical)) if typical.size else 0.0
        short = np.isfinite(length) & (length <= tiny) & ~huge  # (tiny >= 0: zero counts)
        nf /= length[:, None]
    nan = given & np.isnan(length)
    bad = {
        "non-finite": given & ~nan & ~np.isfinite(length),
        "zero-length": given & short,
    }
    ok = given & np.isfinite(length) & ~short
    r, c = domain.pixels
    with np.errstate(invalid="ignore"):
        cos = np.where(ok, cam.view_cosine(r, c, nf, unit=True), 0.0)
    bad["back-facing"] = ok & (cos < 0)  # (exactly edge-on is grazing, e.g. an inf slope)
    if backfacing == "error" and bad["back-facing"].any():
        raise ValueError(
            "`normals` has back-facing normals (facing away from the camera) inside the mask "
            f"at {_where_facets(domain, bad['back-facing'])}; mask them out or pass "
            "backfacing='missing'"
        )
    front = ok & (cos >= 0)
    conf = None if confidence is None else check_confidence(confidence, (H, W), mask=m)[m]
    steep_only = False  # (STEEP_ISOLATED's rule took them, not a rule given)
    if isolated is not None:
        # (among the front-facing normals, grazing ones included, but not those of confidence
        # 0: missing whatever they are, so neither isolated nor anyone's neighbour; counted,
        # the fusion benchmark's corrupted disk at confidence 0 came out 2.2 % off the same
        # disk missing on one scene)
        among = front if conf is None else front & (conf > 0)
        bad["isolated"] = isolated_normals(domain, nf, among, *isolated)
        front &= ~bad["isolated"]
    elif steep_isolated and cam.perspective and eps < STEEP_ISOLATED:
        # (a pinhole camera keeps rims down to a view cosine of 1/255; an isolated normal that
        # steep is an outlier, not a rim: STEEP_ISOLATED)
        steep = front & (cos < STEEP_ISOLATED) & (cos >= eps)
        if steep.any():
            among = front if conf is None else front & (conf > 0)
            iso = steep & isolated_normals(domain, nf, among, *STEEP_ISOLATED_RULE)
            if iso.any():
                bad["isolated"] = iso
                front &= ~iso
                steep_only = True
    bad["grazing"] = front & ((cos < eps) | (cos == 0))
    # (normals of confidence 0 are missing whatever they are: not in the share either)
    among = front if conf is None else front & (conf > 0)
    kept = _edge_on_kept(domain, among, bad["grazing"] & among, cos, grazing_share, nf)
    if kept is not None:
        bad["grazing"] &= ~kept
    usable = front & ~bad["grazing"]
    conf_top = None  # (a confidence above 1 beside a prior: warned about below)
    if conf is not None:
        # (a normal of confidence 0 is missing whatever it is, also a grazing one: it is then
        # filled like one by the discontinuity route, not left as a silhouette's gap)
        zero = conf == 0
        counts_zero = usable & zero
        usable = usable & (conf > 0)
        if prior is None and usable.any():
            # without a prior only the confidences' ratios mean something: scaled to a largest
            # of 1, so 1e-12 everywhere is the same as 1 everywhere (it was flattened by the
            # solvers' own tiny regularisers against such weights)
            conf = conf / float(conf[usable].max())
        elif usable.any() and float(conf[usable].max()) > CONFIDENCE_ABOVE_ONE:
            # (with a prior the values weigh the normals against it as given: an 8-bit map
            # given as 0..255 weighed the prior 255x less, 12x the error, no word, an audit;
            # said once the prior is read, unless its samples are one per component at most,
            # whose weight does not matter: methods.dgp.lone_samples)
            conf_top = float(conf[usable].max())
        if usable.any():
            conf = _confidence_floor(conf, usable)
        # (after the scaling: the facets without a usable normal keep the weight 1 of their
        # flat and twist terms whatever the map's scale; set before it, a map scaled by 0.01
        # weighed them 100 times the best normal and moved the bear's depth by 8.5 % of its
        # range, a fresh user's check)
        conf = np.where(usable, conf, 1.0)

    counts = {"pixels": int(m.sum()), "missing": int((~given | nan).sum())}
    counts.update({k: int(v.sum()) for k, v in bad.items()})
    if conf is not None:
        counts["zero_confidence"] = int(counts_zero.sum())
    counts["usable"] = int(usable.sum())
    counts["outlier_eps"] = float(eps)
    if kept is not None:
        counts["grazing_kept"] = int(kept.sum())
    if holes is not None and holes.any():
        counts["holes"] = int(holes.sum())
    if larger_holes is not None and larger_holes.any():  # (no warning: a ring's own hole)
        counts["larger_holes"] = int(larger_holes.sum())
    if not usable.any():  # (an error alone: no warning about the same normals first)
        # (the counts in words, not a dict: a user's check)
        said = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items()
                         if k not in ("pixels", "usable", "holes", "larger_holes")
                         and isinstance(v, int) and v)
        said = f"{counts['pixels']} pixel(s): {said or 'none usable'}"
        if "grazing" in counts and counts["grazing"]:
            said += (f"; grazing: view cosine < {counts['outlier_eps']:.4g}, outlier_eps / "
                     "--outlier-eps sets another")
        if conf is not None and counts_zero.any():
            raise ValueError(
                f"`confidence` is 0 or NaN at every usable normal inside the mask "
                f"({int(counts_zero.sum())} of them): nothing is left to integrate ({said})")
        raise ValueError(
            "`normals` has no usable normal inside the mask (all missing, non-finite, "
            f"back-facing, grazing or isolated: {said})"
            + (_inverted_mask_hint(n, m) if mask is not None and known is None else "")
        )
    if mask is not None and known is None and nan.mean() > MASK_MISSING:
        _mask_fit_check(n, m, float(nan.mean()))  # (after the refusal of a map without any)
    elif mask is not None and known is None:
        _flat_mask_check(n, m)
    problems = {k: v for k, v in bad.items() if v.any()}
    # (pixels without a normal enclosed by the object, where the domain is the valid normals:
    # left out as holes; told in the same warning, once: an audit's 39 black pixels became
    # NaN holes in the depth and the mesh without a word)
    # (normals made from a gradient field are spoken of as its samples: its user was told of
    # 8/16-bit black pixels and normals, a review)
    field = reading() == GRADIENT_FIELD
    hole_note = "" if "holes" not in counts else _holes_note(holes, field)
    if hole_note and not problems:
        warn(hole_note[0].upper() + hole_note[1:], UnusableNormalsWarning)
    if problems:
        first = int(np.flatnonzero(np.logical_or.reduce(list(problems.values())))[0])
        counts["first_unusable"] = [int(r[first]), int(c[first])]
        what = ", ".join(f"{int(v.sum())} {k}" for k, v in problems.items())
        rule = ""  # (the grazing rule, where it took some)
        if "grazing" in problems:
            # (a texture artist's stamp with near-vertical walls vanished: the warning did not
            # name the option that keeps them)
            note = grazing_note if grazing_note is not None else (
                None if outlier_eps is not None else
                "outlier_eps / --outlier-eps sets another: a smaller one keeps more, 0 all")
            steep = (f" (a slope steeper than {np.sqrt(1 - eps * eps) / eps:.4g}, or "
                     "infinite)" if field and eps > 0 else "")
            share = int(problems["grazing"].sum()) / max(counts["pixels"], 1)
            if field and eps > 0 and share > STEEP_FIELD:
                # (a field in other units: a paraboloid's slopes times 100 lost 99 % of its
                # samples and came out flat, exit 0, with the rule's words alone, a review)
                steep += (f"; {share:.0%} of the field is this steep: slopes in other units? "
                          "(they are read as depth per unit of x and y, a pixel being "
                          "pixel_size / --pixel-size wide: divide slopes per pixel by it and "
                          "give it)")
            rule = (f"; grazing: view cosine < {eps:.4g}{steep}"
                    f"{'' if note is None else ', ' + note}")
        if "isolated" in problems:
            # (exact renders have them too, a detail a pixel wide: one audit's 12 of 41 exact
            # renders; dropped, their error moved within -9 / +1 %, so the attribution alone
            # was said too surely)
            if steep_only:
                rule += (f"; isolated: more than {np.degrees(np.arccos(STEEP_ISOLATED)):.3g} "
                         "deg from the ray (a pinhole camera keeps a rim that steep, not a "
                         f"lone normal) and {isolated_rule_text(STEEP_ISOLATED_RULE)}")
            else:
                rule += f"; isolated: {isolated_rule_text(isolated)}"
            rule += (" (usually an outlier of a "
                     "photometric stereo or a network, which bends the surface around it and "
                     "can join pieces across a jump; or a detail a pixel wide, little lost)")
        frame = ""  # (many facing away: a map in another frame, e.g. world coordinates)
        # (the share among the normals that are not edge-on, as the frame check counts them:
        # an indoor view's walls, z = 0 stored as 128, read -1/255 and counted back-facing)
        clear = ok & (np.abs(cos) > EDGE_ON)
        away = int((clear & (cos < 0)).sum()) / max(int(clear.sum()), 1)
        counts["facing_away"] = away  # (for info's frame guess: the same share)
        axial = _faces_the_axis(cam, nf, clear, away)
        both = False
        shares = (_flip_shares(cam, r, c, nf, clear) if away > BACKFACING_FRAME_HINT
                  else {})
        mended = _flip_mends_facing(cam, r, c, nf, clear, away, shares)
        if mended is not None and _silhouette_right(domain, nf, ok, mended[0]):
            mended = None  # (the object's own silhouette says the axes are right as read)
        if axial is not None and mended is not None:
            # (an orthographic map's silhouette faces away on every side alike, so negating x
            # or y mends it about equally; a y-down map over a floor, whose normals face the
            # axis too, is mended by one flip far more than by the other: the flip's advice,
            # as before; a review found a flipped room told it was orthographic)
            one = (shares["x"], shares["y"])  # (the single flips: both negated is no test)
            even = max(one) <= FLIPS_EVEN * min(one) + 1e-3
            if mended[0] == "xy":
                # (negating both mends an orthographic view's rim as well as a map whose x and
                # y both run the other way: the facing cannot tell them apart, so both are
                # named, the orthographic view first (a review: a room read with x and y
                # negated was told it was orthographic, and integrated so came out inside-out
                # without a word; the next review: told only of the flip, right orthographic
                # maps of uneven objects came out inside-out following it)
                both = True
            elif not (even and axial < 0.5 * mended[1]):
                axial = None
        if axial is not None:
            counts["facing_away_axial"] = axial  # (info's frame guess names it too)
            if both:
                counts["facing_away_both"] = True
            Kc = cam.K
            frame = (f"; {away:.0%} of the normals face away from the camera's rays, though "
                     f"{1 - axial:.1%} of them face the viewer along the optical axis (z > "
                     "0): a map of an orthographic view given a camera, or a camera whose "
                     f"field of view is too wide for it (fx {Kc[0, 0]:g}, fy {Kc[1, 1]:g} for "
                     f"this {W} x {H} (W x H) image): integrate it without the camera "
                     "(--orthographic; no K in Python), or check the K or --fov; "
                     + (f"or the map's x and y both run the other way (a y-down map read "
                        f"with x flipped; try {flip_advice(reading(), 'xy')}), which "
                        "negating both mends alike: the facing cannot tell these apart, the "
                        "object's silhouette can (docs/conventions.md)" if both else
                        "a flip of x or y would not mend it"))
        elif mended is not None:
            counts["facing_away_flip"] = list(mended)  # (info's frame guess names it too)
            # (a y-down map with a camera over a floor: its floor faces away, and the warning
            # asked about BGR order, world frames and K, never about y; an audit)
            axes = ("x and y", "axes", "run") if mended[0] == "xy" else (
                mended[0], "axis", "runs")
            frame = (f"; {away:.0%} of the normals face away from the camera, and with "
                     f"{axes[0]} negated {mended[1]:.1%} would: the map's {axes[0]} {axes[1]} "
                     f"probably {axes[2]} the other way: try "
                     f"{flip_advice(reading(), mended[0])}; "
                     "docs/conventions.md lists the frames of common sources")
        elif away > BACKFACING_FRAME_HINT:
            frame = (f"; {away:.0%} of the normals face away from the "
                     "camera, far more than noise or quantisation turn away: is the map in "
                     "another frame (world coordinates, a rotated export) or in BGR channel "
                     "order (OpenCV's imwrite; an axis string swaps it back: z,-y,-x for an "
                     "OpenCV-frame map, z,y,x for an OpenGL one)? "
                     "docs/conventions.md and docs/recipes.md say how to convert it; "
                     f"{world_note()}")
            Kc = getattr(cam, "K", None)
            centred = (abs(Kc[0, 2] - (W - 1) / 2) <= 1 and abs(Kc[1, 2] - (H - 1) / 2) <= 1
                       if Kc is not None else False)
            if Kc is not None and centred:  # (e.g. a K from a field of view, --fov: an audit)
                frame += (f"; or is K for another image size, or its focal length wrong (fx "
                          f"{Kc[0, 0]:g}, fy {Kc[1, 1]:g} for this {W} x {H} (W x H) image; they "
                          "scale with the image, and --fov gives them from the field of view "
                          "across the width)?")
            elif Kc is not None:  # (a K of another image turns the rays: a user's check)
                frame += (f"; or is K for another image (a crop or a resize)? Its principal "
                          f"point (cx {Kc[0, 2]:g}, cy {Kc[1, 2]:g}) is usually near the "
                          f"centre of this {W} x {H} (W x H) image, its focal lengths fx "
                          f"{Kc[0, 0]:g}, fy {Kc[1, 1]:g} scale with the image")
        hint = no_camera_hint(counts, cam.perspective, field)
        warn(
            f"{sum(int(v.sum()) for v in problems.values())} "
            f"{'gradient sample(s)' if field else 'normal(s)'} inside the mask cannot be "
            f"used and were treated as missing samples ({what}{rule}); first at "
            f"(row {r[first]}, col {c[first]}){frame}{'; ' + hint if hint else ''}"
            + (f". Also: {hole_note}" if hole_note else ""), UnusableNormalsWarning
        )
    nf[~front] = np.nan
    pv = pw = None
    if prior is not None:
        pv, pw, outside = check_prior(prior, default_prior_weight(prior_weight, prior_blur),
                                      (H, W), m, cam)
        counts["prior_samples"] = int((pw > 0).sum())
        counts["prior_outside_mask"] = outside  # (dropped: counted, not silently)
        _prior_ratio_check(pw, None if conf is None else conf[usable])
    elif not _is_default_weight(prior_weight):
        raise ValueError(f"`prior_weight` applies only with a `prior`; got {_short(prior_weight)} "
                         "and prior=None")
    prior_outliers = check_prior_outliers(prior_outliers, prior is not None)
    blur = check_prior_blur(prior_blur, prior is not None, (H, W))
    if conf_top is not None and pw is not None and (
            blur > 0 or not one_sample_per_component(domain, pw)):
        warn(f"`confidence` reaches {conf_top:.4g} (with a prior its values weigh the normals "
             f"against it as given: 1 is a normal of the prior's weight's units, so the prior "
             f"weighs {1 / conf_top:.3g} of what it would beside a confidence of 1); an 8-bit "
             "map given as 0..255? Give confidence / confidence.max(), or raise prior_weight "
             "to match (docs/fusion.md, 'Units of the weights')")
    if blur > 0 and pw is not None:
        used = pw[pw > 0]
        typical = float(np.median(used)) if used.size else 0.0
        if typical > BLUR_WEIGHT_WARN:
            warn(
                f"`prior_weight` {typical:.3g} with `prior_blur`: a blurred prior "
                "is met by undoing its blur (a deconvolution), and weights above "
                f"{BLUR_WEIGHT_WARN:g} amplify the prior's own errors: on the DiLiGenT bear "
                "with 8 x 8 block means of its depth, weight 1 gave 0.85 mm against 0.44 for "
                "the prior alone; 0.001-0.01 is the measured range (docs/fusion.md, 'Blurred "
                "priors')"
            )
    problem = Problem(
        domain=domain, normals=nf, known=front, camera=cam, usable=usable, counts=counts,
        prior=pv, prior_weight=pw, confidence=conf, prior_blur=blur,
        # (whether the grazing threshold was chosen, or the camera's: facetlift.api.solve)
        extras={"outlier_eps_given": outlier_eps is not None,
                "isolated_given": isolated is not None,
                # (facets without a normal, not for the view's sake: missing, non-finite or
                # zero-length, or of confidence 0; the discontinuity route fills the isolated
                # ones, facetlift.methods.dgp.fill_gaps)
                "no_normal": ~given | nan | bad["non-finite"] | bad["zero-length"] | (
                    False if conf is None else zero) | bad.get("isolated", False),
                # (the lone steep normals of STEEP_ISOLATED: info counts them among the
                # discontinuity route's isolated ones, which that rule finds too)
                "steep_isolated": bad["isolated"] if steep_only else None},
    )
    if problem.has_prior:
        _check_trend(problem)
        _check_relief(problem)
    if problem.has_prior and prior_outliers == "remove":
        _remove_outliers(problem)
    if problem.has_prior and not problem.prior_components.all():
        _warn_unfixed(problem)
    return problem


def one_sample_per_component(domain: Domain, weight: np.ndarray) -> bool:
    """Whether no connected component of `domain` holds more than one prior sample (a facet of
    the (m,) prior `weight` above 0): such samples fix only their components' constants, at
    any weight (:func:`facetlift.methods.dgp.lone_samples`)."""
    return bool(np.bincount(domain.facet_component[weight > 0], minlength=1).max() <= 1)


#: ``prior_outliers=`` choices (:func:`prepare`).
PRIOR_OUTLIERS = ("remove", "keep")
#: More outliers than this share of the samples checked are not removed, but warned about.
OUTLIERS_AT_MOST = 0.5


def check_prior_outliers(value, has_prior: bool = True) -> str:
    """`prior_outliers` checked: one of :data:`PRIOR_OUTLIERS` (None: "remove", the default),
    and "keep" only with a prior; raises ValueError naming it."""
    if value is None:
        return "remove"
    if not isinstance(value, str) or value not in PRIOR_OUTLIERS:
        raise ValueError(f"`prior_outliers` must be one of {', '.join(PRIOR_OUTLIERS)}; got "
                         f"{_short(value)}")
    if value != "remove" and not has_prior:
        raise ValueError(f"`prior_outliers` {value!r} applies only with a prior (`prior`, "
                         "--prior, or a dataset folder's prior_depth file)")
    return value


#: A prior whose changes between neighbouring samples follow the normals' predicted sign on
#: fewer than this share of the decided pairs (:func:`facetlift.prior_outliers.trend`: the
#: normals predict at least 0.2 %, the prior changes by half that; 30 pairs or more) runs
#: against them: a warning. Noise gives about 0.5 (a review: 0.47-0.71 on noisy samples over
#: nearly flat walls), hence well below it. Measured 2026-12-04 on every second render of the
#: discontinuity benchmark, exact / 8-bit / 3-degree normals (511 runs with a verdict): 1 % /
#: 0.1 % exact, 1 % noisy and coarse dense priors 0.73-1.0; disparity (1 / depth), dense or
#: sparse, 0-0.13; a height given as depth (orthographic) 0-0.13; a vertically mirrored
#: projection 0-1.0 (found on some).
TREND_AGREE = 0.3


def _check_trend(problem: Problem) -> None:
    """Warn where the prior's depth changes run against the normals' (:data:`TREND_AGREE`,
    :func:`facetlift.prior_outliers.trend`; ``extras["prior_trend"]``)."""
    from .prior_outliers import trend

    found = trend(problem)
    if found is None:
        return
    problem.extras["prior_trend"] = found
    agree, pairs = found["agreement"], found["pairs"]
    if agree < TREND_AGREE:
        warn(f"prior: its depth changes run against the normals': between neighbouring "
             f"samples where both change, they change the same way on only {agree:.0%} of "
             f"{pairs} pairs. Is it a disparity or inverse depth (invert it first, or give it "
             "with prior_fit='disparity', --prior-fit disparity), a height "
             "rather than a depth (larger = farther; Quéau's z0 is his z, a height), or "
             + ("is the gradient field in another layout (gradient_frame, --gradient-frame)"
                if reading() == GRADIENT_FIELD else
                "are the normals in another frame (normal_frame, --normal-frame)")
             + "? (info['prior']['trend']; docs/fusion.md, 'A prior that runs against the "
             "normals')")


#: A prior whose relief is this many times the normals' or more, or this many times less, is
#: warned about (:func:`_check_relief`; a perspective one's in log-depth): a sparse one's
#: (samples on at most a quarter of the facets), and a dense one's (RELIEF_FACTOR_DENSE more,
#: RELIEF_FACTOR_DENSE_LOW times less), whose blur, noise and jumps move the ratio more: since
#: dense priors get a ratio at all (2026-12-05; a review, over 20 noise seeds on the analytic
#: helix at 128^2: noise of 3 footprints 0.34-1.36, 5 footprints -0.1-1.59; a sphere's depth
#: blurred by 8 px 0.32) only a gross mismatch is named (the DiLiGenT bear's depth made
#: 0..1: 46 with K, 0.0067 without at pixel_size 1).
#: Measured on the fusion benchmark's 15 orthographic scenes at exact, 8-bit and 3-degree
#: normals (2026-12-04): 0.1 %, 1 % and 5 % exact samples and 1 % noisy ones 0.92-1.25 (or no
#: ratio: flat views), the coarse dense prior 0.62-1.93; the DiLiGenT bear with 400 exact
#: samples in mm 0.404 without its pixel size (0.3985 mm), 1.013 with it. (Measured with a
#: one-point-per-pixel path sum; since the ratio takes the outlier check's line integrals, on
#: 50 of those sparse priors and the bear the ratios moved by at most 4 %, the bear's to 0.403
#: and 1.012, and the flat `plateau` views gained a ratio of 1.0-1.14.)
RELIEF_FACTOR, RELIEF_FACTOR_DENSE, RELIEF_SPARSE = 2.0, 10.0, 0.25
#: ... and a dense perspective one's (log-depth) relief this many times the normals': a
#: monocular network's relative depth (0..1, min-max) read 4.6 on a review's bunny and 6.1-6.4
#: on a sphere 1.2-1.5 away (a room spanning 0.9-2.4 m, 1.75, is not told apart), where the
#: fusion benchmark's coarse dense priors read at most 2.64 (above). A metric map with a band
#: of background blended in at the silhouettes read 8.3 (named in the warning too).
RELIEF_FACTOR_DENSE_PERSPECTIVE = 4.0
RELIEF_FACTOR_DENSE_LOW = 30.0
#: A dense prior whose relief ratio is at most this (negative included) over at least
#: RELIEF_UNRELATED_PAIRS pairs does not follow the normals at all (:func:`_check_relief`): a
#: depth map of another view or not registered with the map (an audit's bear prior flipped
#: up-down gave -0.02, shifted by 30 px 0.37, with no word at 15 and 4.6 mm of error; the
#: fusion benchmark's coarse dense priors 0.64-2.64, noisy registered ones about 1).
RELIEF_UNRELATED, RELIEF_UNRELATED_PAIRS = 0.5, 1000
#: Fewest pairs whose relief ratio :func:`_check_relief` warns about (an audit: 2 % noisy
#: metric samples on a cow's side view gave 24 pairs and a ratio of 2.03, warned as relative
#: depth; exact ones there 1.5-1.84).
RELIEF_WARN_PAIRS = 50


#: A perspective prior whose relief ratio lies within these bounds reads as metric: the
#: warnings of a torn surface then do not name a relative depth among its causes
#: (:func:`relief_says_relative`; a review: a metric bunny depth with 3 mm of noise, ratio
#: 1.03, was told to fit it as relative, which loses its metric scale). Metric dense priors of
#: the same review and the fusion benchmark read 0.5-2.6; relative 0..1 maps 4.3-72 (rooms
#: 1.75-2.8, a map offset to 1..2 below 1).
RELATIVE_QUIET = (2.0 / 3.0, 1.5)


def relief_says_relative(ratio) -> bool:
    """Whether a perspective prior's relief ratio (``info["prior"]["relief_ratio"]``, None
    where it was not measured) leaves a relative depth among the causes worth naming."""
    return ratio is None or not RELATIVE_QUIET[0] <= float(ratio) <= RELATIVE_QUIET[1]


def _check_relief(problem: Problem) -> None:
    """Warn where a prior's relief differs from the normals' by a factor (a perspective
    one's relative relief: :func:`facetlift.prior_fit.relief_ratio` in log-depth, the same in
    any units, so a relative depth with an offset; measured on the fusion benchmark's 48
    perspective and wide-angle renders, 2026-12-05: 1 % exact samples 0.998-1.048, 1 % noisy
    0.891-1.198, the coarse dense prior 0.641-2.638; the DiLiGenT bear's depth 1.001, made
    0..1 by (depth - 1460) / 60 46.0; an orthographic one's
    (:data:`RELIEF_FACTOR`, :func:`facetlift.prior_fit.relief_ratio`; ``extras
    ["prior_relief"]``): a metric prior with the default pixel_size of 1 (an audit: the
    DiLiGenT bear's 400 exact samples in mm without its K came out at 2.76 mm instead of 0.04
    mm, with only the depth-jump hint). A ratio that runs the other way (height for depth) is
    :func:`_check_trend`'s."""
    from .prior_fit import relief_ratio

    got = relief_ratio(problem)
    if got is None:
        return
    ratio, pairs = got
    problem.extras["prior_relief"] = ratio
    sparse = float(np.mean(problem.prior_weight > 0)) <= RELIEF_SPARSE
    # (a declared blur lowers the relief between the pairs, so only a relief too large is
    # named then: a review's monocular 0..1 depth given with K and --prior-blur 4 was not
    # checked at all and came out hundreds of mm off, with words on noise only)
    factor = RELIEF_FACTOR if sparse else (
        RELIEF_FACTOR_DENSE_PERSPECTIVE if problem.perspective else RELIEF_FACTOR_DENSE)
    if problem.prior_blur > 0 and not ratio > factor:
        return
    if not sparse and ratio <= RELIEF_UNRELATED and pairs >= RELIEF_UNRELATED_PAIRS:
        # (the jump hint not silenced: a blurred prior reads so too, a review: a registered
        # map blurred by 4 px 0.48, by 6 px 0.31, whose cure is its blur declared)
        units = ""
        if ratio > 0:  # (a metric map without K read as this too, and was sent to a blur
            # that made it worse, 17.6 deg: an audit of the docs' claims)
            h = problem.pixel_size
            units = (("a relative depth known only up to scale and shift (prior_fit='affine', "
                      "--prior-fit affine), " if problem.perspective else
                      f"in other units than the depth's (without K the depth is orthographic "
                      f"in units of pixel_size {h:g}: a prior in other units needs a pixel_size "
                      f"of about {ratio * h:.3g} (--pixel-size), a perspective one its "
                      "camera's K (--K), one known only up to scale prior_fit='affine'), "))
        warn(f"prior: its relief hardly follows the normals' (a ratio of {ratio:.3g} over "
             f"{pairs} pairs of nearby samples, 1 where they agree): is the depth map "
             f"{units}blurred (a sensor's or an upsampled depth: give its blur, prior_blur= / "
             "--prior-blur), or of another view, or not registered with the normal map "
             "(shifted, flipped, turned, cropped differently)? Its depths pull the surface off "
             "its normals")
        return
    low = RELIEF_FACTOR if sparse else RELIEF_FACTOR_DENSE_LOW
    if pairs < RELIEF_WARN_PAIRS:  # (24 pairs of noisy metric SfM points read 2.03, and the
        return  # advice, prior_fit, then left the prior out: the result no longer metric)
    if ratio > 0 and not 1.0 / low <= ratio <= factor and problem.perspective:
        problem.extras["prior_relief_warned"] = True
        relative = ("A relative depth known only up to scale and shift (a monocular "
                    "network's, e.g. 0..1) needs prior_fit='affine' (--prior-fit affine), an "
                    "inverse depth prior_fit='disparity'")
        # (a dense map's causes, which the ratio cannot tell apart: a review's metric maps
        # blurred with their background read 4.6-24, and the advice led with prior_fit, which
        # loses a metric map's scale; the blend first where a blur was declared)
        causes = ["it is a relative depth known only up to scale and shift (a monocular "
                  "network's, e.g. 0..1: prior_fit='affine', --prior-fit affine; an inverse "
                  "depth: prior_fit='disparity')",
                  "its background is blended in at the silhouettes (fill it with the nearest "
                  "object depth, or give it zero weight, --prior-weight-map)"]
        if problem.prior_blur > 0:
            causes.reverse()
        dense = (f"A dense map reads so when {causes[0]}, when {causes[1]}, or when K's focal "
                 "length is wrong; the ratio cannot tell these apart (and fitting a metric "
                 "map, prior_fit, gives up its metric scale)")
        # (log-depth relief: the same in any units, so a metric prior gives 1 whatever they
        # are; a relative depth with an offset does not: a fresh user's 0..1 map with K cut
        # 71 % of the corners and was told of noise, not of prior_fit)
        warn(f"prior: its relative relief (of log-depth) is {ratio:.3g} times what the normals "
             f"give with this K (the median over {pairs} pairs of nearby samples): a "
             "perspective prior must be depth along the optical axis, in any units but "
             "without an offset. " + (relative + "; or is K's focal length wrong?" if sparse
                                      else dense))
    elif ratio > 0 and not 1.0 / low <= ratio <= factor:
        problem.extras["prior_relief_warned"] = True  # (the jump hint then stays quiet)
        h = problem.pixel_size
        warn(f"prior: its relief is {ratio:.3g} times what the normals give at pixel_size "
             f"{h:g} (the median over {pairs} pairs of nearby samples): without K the depth "
             "is orthographic, in units of pixel_size, so a prior in other units needs a "
             f"pixel_size of about {ratio * h:.3g} (--pixel-size), a perspective one its "
             "camera's K (--K); a prior known only up to scale, prior_fit='affine' "
             "(--prior-fit)")


def _remove_outliers(problem: Problem) -> None:
    """Give the outlier samples of the prior (:mod:`facetlift.prior_outliers`) weight 0,
    count them (``extras["prior_outliers"]``, for ``info["prior"]``) and warn."""
    from .prior_outliers import find_outliers, image_pixels

    bad, details = find_outliers(problem)
    if bad is None:
        problem.extras["prior_outliers"] = {"removed": 0, **details}
        return
    k = int(bad.sum())
    first = None
    t = details["threshold"]
    # (the tolerance in the prior's own terms: a relative depth with a camera, else depth)
    tol = (f"{np.expm1(t):.2%} of the depth" if problem.perspective
           else f"{t:.3g} (depth units)")
    if k > OUTLIERS_AT_MOST * details["checked"]:
        # (so many are the normals' or the setup's fault, not the samples'; a guard: the
        # tolerance follows the median disagreement, so this is seldom reached)
        problem.extras["prior_outliers"] = {"removed": 0, "disagreeing": k, "first": None,
                                            "pixels": [], "tolerance": tol, **details}
        whom = ("most of their neighbouring samples" if details.get("majority")
                else "every neighbouring sample")
        warn(f"prior: {k} of the {details['checked']} samples disagree with {whom} "
             "along the normals, too many to be outliers: all are used. "
             "The prior and the normals disagree; check the prior's units, `pixel_size` or "
             "`K`, and the normals' frame (info['prior']['outliers']; docs/fusion.md, "
             "'Outlier samples')")
        return
    pixels = image_pixels(problem.domain, np.flatnonzero(bad))
    if k:
        first = pixels[0]
        problem.prior_weight = np.where(bad, 0.0, problem.prior_weight)
        problem.__dict__.pop("prior_components", None)  # (cached; samples are gone)
    problem.extras["prior_outliers"] = {"removed": k, "first": first, "tolerance": tol,
                                        "pixels": pixels, **details}
    if k:
        doubt = details["unconfirmed"]
        # (those are said only beside outliers found: clean priors have a few, near rims)
        more = (f"; {doubt} more disagree with the few they could be compared with and were "
                "kept (info['prior']['outliers']['unconfirmed_pixels']; a lower prior_weight "
                "limits what they can do)" if doubt else "")
        if details.get("dense"):
            whom = ("most of their neighbouring samples (pixels)" if details.get("majority")
                    else "every neighbouring sample (pixel) they could be compared with")
            what = (f"disagree with {whom} by more than "
                    f"{tol} along the normals (the first at row {first[0]}, col {first[1]}): "
                    "left out as outliers, such as a depth sensor's flying pixels along "
                    "depth edges and silhouettes or its stray returns, or a correct sample at "
                    "the corner of a depth jump that the normals do not show")
        else:
            what = (f"disagree with every neighbouring sample they could be compared with, by "
                    f"more than {tol} along the normals (the first at row {first[0]}, col "
                    f"{first[1]}): left out as outliers, such as mismatched SfM points or a "
                    "sensor's stray returns, or a correct sample beside a depth jump that the "
                    "normals do not show (one on a piece of its own beyond the jump)")
        warn(f"prior: {k} of the {details['checked']} samples {what}{more} "
             "(all: info['prior']['outliers']['pixels'], --json; prior_outliers='keep', "
             "--prior-outliers keep, uses them; docs/fusion.md, 'Outlier samples')")


#: A pinhole K whose principal point lies outside the image, or within this share of its
#: width or height of an edge, gets a warning (:func:`_check_principal_point`).
PRINCIPAL_EDGE = 0.05


def _check_normalised(cam, H: int, W: int) -> bool:
    """A warning, and True, where a pinhole K looks normalised by the image's size (fx, fy
    below 10, cx and cy within [0, 1], as some datasets and networks store it): the principal
    point and focal length warnings then spoke of another image and of millimetres, never of
    the scale (a perspective audit)."""
    Kc = getattr(cam, "K", None)
    if Kc is None:
        return False
    fx, fy, cx, cy = (float(Kc[0, 0]), float(Kc[1, 1]), float(Kc[0, 2]), float(Kc[1, 2]))
    if not (fx < 10 and fy < 10 and 0 <= cx <= 1 and 0 <= cy <= 1 and min(H, W) > 10):
        return False
    warn(f"`K` looks normalised by the image's size (fx {fx:g}, fy {fy:g}, cx {cx:g}, cy "
         f"{cy:g}): in pixels, multiply fx and cx by the width and fy and cy by the height; "
         f"for this {W} x {H} (W x H) image fx {fx * W:.6g}, fy {fy * H:.6g}, cx "
         f"{cx * W - 0.5:.6g}, cy {cy * H - 0.5:.6g} (cx, cy as pixel centres, taking the "
         "normalised ones from the image's corner; docs/conventions.md)", CameraWarning)
    return True


def _check_principal_point(cam, H: int, W: int) -> None:
    """A warning where a pinhole camera's principal point lies outside the image or at its
    edge (:data:`PRINCIPAL_EDGE`): right for a crop of a corner with K shifted, but usually a
    K made for another image (a fresh user's
    300 x 300 crop of the bear with the full image's K: 0.661 mm MADE against 0.024 with the
    crop's K, and no word)."""
    Kc = getattr(cam, "K", None)
    if Kc is None:
        return
    cx, cy = float(Kc[0, 2]), float(Kc[1, 2])
    # (or within PRINCIPAL_EDGE of an edge: a neural-normals user's K of the photo at twice
    # the map's size put it in the map's corner, 43x the error, no word)
    # (the distance to the nearer edge against the limit, with a rounding margin: the limit
    # held on one side and not the other at some widths, a review)
    tol = 1e-9
    if (min(cx + 0.5, W - 0.5 - cx) >= PRINCIPAL_EDGE * W - tol
            and min(cy + 0.5, H - 0.5 - cy) >= PRINCIPAL_EDGE * H - tol):
        _check_swapped_axes(Kc, H, W)
        _check_scaled_centre(Kc, H, W)
        return
    inside = -0.5 <= cx <= W - 0.5 and -0.5 <= cy <= H - 0.5
    where = "lies at the edge of" if inside else "lies outside"
    warn(f"`K`: the principal point (cx {cx:g}, cy {cy:g}) {where} this {W} x {H} (W x H) image "
         "(columns 0..W-1, rows 0..H-1): is K for another image? After a crop, subtract the "
         "crop's first column and row from cx and cy; after a resize, scale fx, fy, cx and cy "
         "with the image (docs/conventions.md, 'A K for another image')", CameraWarning)


#: A pinhole K whose field of view across the image's width exceeds this many degrees gets a
#: warning (:func:`_check_focal_length`): a fish-eye's is wider, but a pinhole
#: K that wide is usually a focal length in mm (a fresh user's fx = fy = 4.2 for a 240-pixel
#: image, 176 deg: 40 % of the normals dropped as back-facing, and a warning about BGR order).
FOV_WIDE = 150.0


def _check_focal_length(cam, H: int, W: int, given=None) -> None:
    """A warning where a pinhole camera's field of view exceeds :data:`FOV_WIDE` degrees
    across the image (the focal length in mm, or a K for an image many times smaller); none
    where `given`, the K as passed, came from :func:`facetlift.camera.K_from_fov` for this
    H x W image, which said what so wide a field of view implies (a --fov 170 user was asked
    about mm, an audit); a K it made for another size is checked like any other."""
    from .camera import fov_of

    Kc = getattr(cam, "K", None)
    if Kc is None or fov_of(given, (H, W)) is not None:
        return
    fx, fy = float(Kc[0, 0]), float(Kc[1, 1])
    # (across the width, as --fov gives it: a portrait image's height sees more, and --fov 140
    # on one was questioned at 159 deg, a review)
    fov = 2 * np.degrees(np.arctan(W / (2 * fx)))
    if fov > FOV_WIDE:
        warn(f"`K`: the focal lengths fx {fx:g}, fy {fy:g} give a field of view of {fov:.0f} "
             f"deg across this {W}-pixel-wide image: are they in mm (or for a much smaller "
             "image), not pixels? In pixels, fx = the focal length in mm x the image's width "
             "in pixels / the sensor's width in mm; a camera's field of view gives it too "
             "(--fov, or fx = (W / 2) / tan(fov / 2); docs/conventions.md). A camera that "
             "wide is seldom a pinhole: if yours is, all is well", CameraWarning)


#: A pinhole K whose fx / fy differs from 1 by more than this gets a warning
#: (:func:`_check_aspect`). A camera's pixels are square within about 1 % (a calibration's fx
#: and fy agree that closely), so 5 % leaves room for a calibration's noise and names a map
#: resized in one direction without its focal length (a review: fy left as it was, 13x the
#: error, and no word; a sphere's rows halved so, 1.37 % against 0.04 % relative depth
#: error); an anamorphic lens's pixels are not square, which is why it is a warning, not an
#: error.
ASPECT_TOLERANCE = 0.05


def _check_aspect(cam) -> None:
    """A warning where a pinhole camera's fx / fy differs from 1 by more than
    :data:`ASPECT_TOLERANCE`: usually an image resized in one direction (or to another aspect
    ratio) with its focal lengths not scaled to match."""
    Kc = getattr(cam, "K", None)
    if Kc is None:
        return
    fx, fy = float(Kc[0, 0]), float(Kc[1, 1])
    ratio = fx / fy
    if abs(ratio - 1.0) <= ASPECT_TOLERANCE:
        return
    warn(f"`K`: fx {fx:g} and fy {fy:g} differ by a factor {ratio:.4g} (fx / fy), where a "
         f"camera's pixels are square within about 1 % (the check allows "
         f"{ASPECT_TOLERANCE:.0%}): was the image resized in one direction, or to another "
         "aspect ratio, without the matching focal length? A resize by sx across and sy down "
         "scales fx and cx by sx, fy and cy by sy (c -> s (c + 0.5) - 0.5). An anamorphic "
         "lens's pixels are not square: then K is right (docs/conventions.md, 'A K for "
         "another image')", CameraWarning)


#: A principal point within this share of the image's size of the centre with x and y
#: swapped (an old BiNI K.txt holds it to the half pixel), at least SWAPPED_FARTHER times
#: farther from the true centre, on an image whose sides differ by SWAPPED_SIDES of the longer
#: or more, gets a warning (:func:`_check_swapped_axes`; a review: 5 % windows overlapped on
#: nearly square images and warned on a real camera's K).
SWAPPED_CENTRE, SWAPPED_FARTHER, SWAPPED_SIDES = 0.01, 5.0, 0.1


def _check_swapped_axes(K, H: int, W: int) -> None:
    """A warning where K's principal point sits at the centre of the image with its axes
    swapped, ``(cx, cy) ~ ((H - 1) / 2, (W - 1) / 2)``, far from the true centre: the layout
    of BiNI's K.txt files before its commit 0684184 (a user's DiLiGenT object: 0.347 mm MADE
    instead of 0.025, and no word). Not on nearly square images, where both centres agree."""
    cx, cy = float(K[0, 2]), float(K[1, 2])
    cx0, cy0 = (W - 1) / 2, (H - 1) / 2
    if abs(W - H) < SWAPPED_SIDES * max(W, H):
        return
    swapped = float(np.hypot((cx - cy0) / W, (cy - cx0) / H))
    true = float(np.hypot((cx - cx0) / W, (cy - cy0) / H))
    if swapped <= SWAPPED_CENTRE and true >= SWAPPED_FARTHER * max(swapped, SWAPPED_CENTRE / 2):
        fx, fy = float(K[0, 0]), float(K[1, 1])
        warn(f"`K`: the principal point (cx {cx:g}, cy {cy:g}) lies where this {W} x {H} "
             f"(W x H) image's centre (cx {cx0:g}, cy {cy0:g}) would with x and y swapped: is K "
             "in another layout? BiNI's K.txt files before its commit 0684184 swap the axes and "
             f"count rows from the bottom: the K for facetlift (OpenCV) is then fx {fy:g}, fy "
             f"{fx:g}, cx {cy:g}, cy {H - 1 - cx:g}; where only cx and cy were swapped, cx "
             f"{cy:g}, cy {cx:g} (docs/conventions.md)", CameraWarning)


#: Image sizes, relative to the one integrated, whose centre a K's principal point is checked
#: against (:func:`_check_scaled_centre`): a K kept from the image before a resize. Not sizes
#: above 1: a right K of a crop from the top-left corner of a larger image has its principal
#: point at the centre of an image that much larger (a 1920 x 1080 camera's K on its
#: 1280 x 720 top-left crop), a review. 3/4 and 4/5 since a perspective audit (a K kept
#: from before a phone's 4/3 upsample: 7.6 % relative MADE against 0.32 % and no word).
SCALED_SIZES = (0.25, 1 / 3, 0.5, 2 / 3, 0.75, 0.8)


def _check_scaled_centre(K, H: int, W: int) -> None:
    """A warning where K's principal point sits at the centre an image `s` times this one's
    size would have (:data:`SCALED_SIZES`, within :data:`SWAPPED_CENTRE` of the size), far
    from this image's own: a K kept from before a resize (an audit: the bear at 1/4 of its
    size with the K of 1/8 of it, 5x the error and no word). A crop's K lands there only by
    chance."""
    cx, cy = float(K[0, 2]), float(K[1, 2])
    cx0, cy0 = (W - 1) / 2, (H - 1) / 2
    true = float(np.hypot((cx - cx0) / W, (cy - cy0) / H))
    for size in SCALED_SIZES:
        cxs, cys = (size * W - 1) / 2, (size * H - 1) / 2
        off = float(np.hypot((cx - cxs) / W, (cy - cys) / H))
        if off <= SWAPPED_CENTRE and true >= SWAPPED_FARTHER * max(off, SWAPPED_CENTRE / 2):
            a = 1.0 / size  # (pixel centres at integer indices: c' = (c + 0.5) a - 0.5)
            fx, fy = float(K[0, 0]), float(K[1, 1])
            warn(f"`K`: the principal point (cx {cx:g}, cy {cy:g}) lies at the centre of an "
                 f"image {size:.3g} times the size of this {W} x {H} (W x H) one (cx {cxs:g}, "
                 f"cy {cys:g}), far from its own (cx {cx0:g}, cy {cy0:g}): is K for the image "
                 f"before a resize? Scaled to this one it is fx {fx * a:.6g}, fy {fy * a:.6g}, "
                 f"cx {(cx + 0.5) * a - 0.5:.6g}, cy {(cy + 0.5) * a - 0.5:.6g}. (A crop's K, "
                 "shifted by the crop's first column and row, can sit there too: then it is "
                 "right; docs/conventions.md, 'A K for another image')", CameraWarning)
            return


def _warn_unfixed(problem: Problem) -> None:
    """A prior that fixes some components but not others: the others keep the camera's gauge
    (mean 0, or a median depth of 1 with a perspective camera), far from the prior's depths
    (a fresh user's part of the bear sat about 1 mm from the camera beside the metric rest)."""
    d = problem.domain
    free = ~problem.prior_components
    pixels = int(free[d.facet_component].sum())
    gauge = ("a median depth of 1, not metric" if problem.camera.projection == "perspective"
             else "a mean height of 0")
    warn(f"prior: {int(free.sum())} of {d.n_components} mask components ({pixels:,} of "
         f"{d.n_facets:,} pixels) hold no prior sample: their depth keeps the default "
         f"convention ({gauge}), not the prior's; info['prior']['gauged_components'] names "
         "them (give them a sample, or mask them out)")


def prior_blur_value(prior_blur) -> float:
    """`prior_blur` as a float >= 0 (None is 0); raises ValueError naming it for a bool, a
    string or another non-number, NaN, inf or a negative value."""
    if prior_blur is None:
        return 0.0
    if isinstance(prior_blur, (bool, np.bool_, str, bytes)) or not hasattr(prior_blur,
                                                                           "__float__"):
        raise ValueError(f"`prior_blur` must be a number of pixels >= 0; got {_short(prior_blur)}")
    try:
        blur = float(prior_blur)
    except (TypeError, ValueError):
        raise ValueError(f"`prior_blur` must be a number of pixels >= 0; got {_short(prior_blur)}"
                         ) from None
    if not (np.isfinite(blur) and blur >= 0):
        raise ValueError(f"`prior_blur` must be a finite number of pixels >= 0; got {blur!r}")
    return blur


def prior_weight_value(prior_weight) -> float:
    """A scalar `prior_weight` as a float, finite and >= 0 (ValueError naming it otherwise,
    in the words :func:`prepare` uses): the command line checks its --prior-weight so before
    any input is read (it was refused after the map's own warnings, a review)."""
    if isinstance(prior_weight, (bool, np.bool_, str, bytes)) or not hasattr(prior_weight,
                                                                             "__float__"):
        raise ValueError(f"`prior_weight` must be a finite number >= 0; got "
                         f"{_short(prior_weight)}")
    w = float(prior_weight)
    if not (np.isfinite(w) and w >= 0):
        raise ValueError(f"`prior_weight` must be a finite number >= 0; got {prior_weight!r}")
    return w


def check_prior_blur(prior_blur, has_prior: bool, shape=None) -> float:
    """`prior_blur` checked (:func:`prior_blur_value`); also refused without a prior and
    above the image's larger side `shape` (a blur wider than the image fits one plane to
    everything: no coarse map is that coarse)."""
    blur = prior_blur_value(prior_blur)
    if 0 < blur < 0.5:
        raise ValueError(f"`prior_blur` below half a pixel is no blur: give 0 to compare the "
                         f"prior pixel by pixel, or at least 0.5; got {blur!r}")
    if blur > 0 and not has_prior:
        raise ValueError(f"`prior_blur` {blur:g} applies only with a prior (`prior`, --prior, "
                         "or a dataset folder's prior_depth file)")
    if shape is not None and blur > max(shape):
        raise ValueError(f"`prior_blur` must be at most the image's larger side ({max(shape)} "
                         f"px); got {blur!r}")
    return blur


def _short(value) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    text = repr(value)
    return text if len(text) < 60 else text[:57] + "..."


def _is_default_weight(w) -> bool:
    return w is None or (isinstance(w, (int, float)) and not isinstance(w, bool) and w == 1.0)


def default_prior_weight(prior_weight, prior_blur):
    """`prior_weight` as given, or where it is None the default: 1 for a prior compared pixel
    by pixel, :data:`BLURRED_PRIOR_WEIGHT` for a blurred one (`prior_blur` > 0; its own errors
    are raised by :func:`prior_blur_value`)."""
    if prior_weight is not None:
        return prior_weight
    return BLURRED_PRIOR_WEIGHT if prior_blur_value(prior_blur) > 0 else 1.0


def _weight_image(a, name: str, shape: tuple[int, int]) -> np.ndarray:
    """A scalar or (H, W) map of weights >= 0 (finite) as a float array broadcast to `shape`."""
    if isinstance(a, bool):
        raise ValueError(f"`{name}` must be a number >= 0 or an {shape} array; got {a!r}")
    arr = numeric_array(a, name, "a number >= 0 or an (H, W) array of them").astype(float)
    if arr.ndim == 0:
        if not (np.isfinite(arr) and arr >= 0):
            raise ValueError(f"`{name}` must be a finite number >= 0; got {a!r}")
        return np.full(shape, float(arr))
    if arr.shape != shape:
        # (a weight per point of a (rows, cols, depths) prior: its place is the fourth array,
        # an audit)
        points = ("; a weight per point of a (rows, cols, depths) prior goes in the prior "
                  "as a fourth array, prior=(rows, cols, depths, weights)"
                  if name == "prior_weight" and arr.ndim == 1 else "")
        raise ValueError(f"`{name}` must be a number or have shape {shape} to match `normals`; "
                         f"got shape {arr.shape}{points}")
    return arr


def check_confidence(confidence, shape: tuple[int, int], mask=None) -> np.ndarray:
    """(H, W) float confidence of the normals: >= 0 and finite inside `mask` (every pixel
    without one), or a ValueError naming `confidence`, the value and what was expected. NaN
    inside the mask is 0 (a missing normal, as a missing sample of the map is); outside it
    anything goes and becomes 0."""
    c = _weight_image(confidence, "confidence", shape).astype(float, copy=True)
    inside = np.ones(shape, bool) if mask is None else np.asarray(mask, bool)
    c[~inside | np.isnan(c)] = 0.0
    bad = ~(np.isfinite(c) & (c >= 0))
    if bad.any():
        r, col = np.argwhere(bad)[0]
        where = "everywhere" if mask is None else "inside the mask (NaN there is a missing normal)"
        said = "of the map" if mask is None else "inside the mask"
        up = np.isposinf(c)
        finite = c[inside & np.isfinite(c) & (c > 0)]
        # (a few bad pixels never refuse a job: +inf, as 1 / residual gives where a fit is
        # exact, is the largest confidence of the map; a few negative values are none, as
        # NaN is; many negative values are refused: a log-confidence, another quantity)
        if (bad & ~up).sum() <= NEGATIVE_SHARE * inside.sum():
            top = float(finite.max()) if finite.size else 1.0
            warn(f"`confidence`: {int(bad.sum())} pixel(s) {said} are not "
                 f"finite and >= 0, the first {float(c[r, col])!r} at (row {r}, col {col}) "
                 f"({int(up.sum())} +inf, taken as the map's largest confidence {top:g}; "
                 f"{int((bad & ~up).sum())} negative or -inf, taken as 0: a missing normal)")
            c[up] = top
            c[bad & ~up] = 0.0
            return c
        raise ValueError(f"`confidence` must be finite and >= 0 {where}; got "
                         f"{float(c[r, col])!r} at (row {r}, col {col}) ({int(bad.sum())} such "
                         "pixel(s), more than a few bad ones)")
    return c


def _is_points(prior, shape: tuple[int, int] | None = None) -> bool:
    """Whether `prior` is a ``(rows, cols, depths)`` triple (or ``(rows, cols, depths,
    weights)``), not an (H, W) map: a nested list of `shape` (a map of 3 or 4 rows given as
    a list) is a map."""
    if not (isinstance(prior, (tuple, list)) and len(prior) in (3, 4)
            and not np.isscalar(prior[0])):
        return False
    return shape is None or not (len(prior) == shape[0] and all(
        not isinstance(v, np.ndarray) and np.ndim(v) == 1 and len(v) == shape[1]
        for v in prior))


def _unprojected_hint(prior, shape: tuple[int, int]) -> str:
    """The words, or "", on points that look unprojected, for a prior with no sample in the
    mask: where its points (2 or more) round onto one pixel, or most fall outside the image,
    as 3-D points (x, y in metres) read as columns and rows do (a CSV of three points under
    an x,y,z header in metres was told "(1 outside it)" alone, a review; the error of points
    all outside the image asked already)."""
    try:
        rows, cols = (np.asarray(v, dtype=float).ravel() for v in prior[:2])
    except (TypeError, ValueError):
        return ""
    ok = np.isfinite(rows) & np.isfinite(cols)
    if rows.shape != cols.shape or ok.sum() < 2:
        return ""
    H, W = shape
    r, c = np.rint(rows[ok]), np.rint(cols[ok])
    out = (r < 0) | (r >= H) | (c < 0) | (c >= W)
    pixels = np.unique(r[~out] * W + c[~out]).size
    if out.mean() > 0.5:
        said = f"{int(out.sum())} of its {out.size} points lie outside the {H} x {W} image"
    elif pixels == 1 and not out.any():
        said = (f"its {out.size} points all fall into one pixel (row {int(r[0])}, col "
                f"{int(c[0])})")
    else:
        return ""
    return (f"; {said}: 3-D points not projected with K (x, y in metres or mm, not the "
            "image's columns and rows)? Project them with K first (docs/fusion.md, 'Sparse "
            "SfM points projected with K')")


def _ambiguous_points(prior) -> bool:
    """Whether `prior`'s 3 or 4 sequences of 3 or 4 numbers each (not numpy arrays) could as
    well be that many points (row, col, depth[, weight]) as columns: a list of points from
    ``json.load`` or ``tolist()`` was read as columns, its depths as pixel positions."""
    lengths = {np.size(v) for v in prior}
    return (len(lengths) == 1 and lengths <= {3, 4}
            and not any(isinstance(v, np.ndarray) for v in prior))


#: A points prior of at least CROWDED_MIN samples falling into fewer pixels than
#: CROWDED_SHARE of their number, all within a box of CROWDED_BOX of the image, gets a
#: warning (points in the wrong units: a cloud's metres read as pixels land near a corner).
CROWDED_MIN, CROWDED_SHARE, CROWDED_BOX = 20, 0.1, 0.01


#: A pixel whose points' depths span more than this share of their nearest one's depth (of
#: the samples' depth range without a camera, 5th to 95th percentile) is left out: a
#: mismatched point beside a good one, or a sensor's points on both sides of an edge (keeping
#: the nearest kept a mismatch in front and dropped the good ones behind it, a user's check).
CONFLICT = 0.02


def _agreeing(idx: np.ndarray, depth: np.ndarray, n: int, positive: bool) -> np.ndarray:
    """(k,) bool: the points (pixel `idx`, `depth`) of pixels whose points lie within
    :data:`CONFLICT` of each other."""
    nearest = np.full(n, np.inf)
    farthest = np.full(n, -np.inf)
    np.minimum.at(nearest, idx, depth)
    np.maximum.at(farthest, idx, depth)
    near = nearest[idx]
    if positive:
        tol = CONFLICT * near  # (points behind the camera never get here)
    else:
        lo, hi = np.percentile(depth, [5, 95]) if depth.size else (0.0, 0.0)
        # (and a relative rounding margin: on a fronto-parallel wall the range is 0, a review)
        tol = CONFLICT * (hi - lo) + 1e-9 * (np.abs(near) + 1.0)
    return farthest[idx] - near <= tol


def prior_image(prior, shape: tuple[int, int], positive: bool = False) -> np.ndarray:
    """The prior as an (H, W) depth image, NaN where unknown: from an (H, W) array or a
    ``(rows, cols, depths)`` triple (pixel indices, rounded to the nearest pixel; depths of the
    same pixel averaged; a pixel whose points differ by more than :data:`CONFLICT` is left out,
    counted in a warning: which of them is right is unknown). With
    `positive` (a perspective camera) a triple's points with a depth <= 0 (behind the camera)
    are left out before the averaging, with a warning, unless every one is (then the caller
    refuses them). Raises ValueError naming `prior`. A fourth array of per-point weights
    (:func:`prior_samples`) weighs the average."""
    return prior_samples(prior, shape, positive)[0]


def prior_samples(prior, shape: tuple[int, int], positive: bool = False,
                  mask=None) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`prior_image` and, for ``(rows, cols, depths, weights)``, the (H, W) weights of
    its pixels (None otherwise): a pixel's depth is its points' weighted mean and its weight
    the weighted mean of their weights, ``sum w^2 / sum w`` (a doubtful point beside a good
    one does not halve its pull; points of weight 1 give what the triple gives), NaN where
    no point is. The weights must be finite and >= 0 (a ValueError names ``prior[3]``); a
    pixel whose points all weigh 0 holds no sample. They multiply ``prior_weight`` (SfM points
    by their reprojection error or track length, a LiDAR's by its return strength). A
    dense map's inf pixels are unknown depths, counted in a warning where they lie inside
    `mask` ((H, W) bool; None: anywhere): a ray caster's "no hit" outside the object is none.
    """
    H, W = shape
    if _is_points(prior, shape):
        if _ambiguous_points(prior):
            # (three points as a list of (row, col, depth) rows were read as columns: the
            # depths became pixel positions, 273 instead of 1500 and no word, a user's check;
            # a review: lists too, e.g. from json.load)
            raise ValueError(
                f"`prior`: {len(prior)} sequences of {len(prior[0])} numbers could be columns "
                "(rows, cols, depths[, weights]) or points (row, col, depth) each: give the "
                "columns as numpy arrays, prior=(np.asarray(rows), np.asarray(cols), "
                "np.asarray(depths)), or a list of points as tuple(np.asarray(points, "
                "float).T)")
        arrays = [numeric_array(v, f"prior[{k}]").astype(float).ravel()
                  for k, v in enumerate(prior)]
        rows, cols, depths = arrays[:3]
        pw = arrays[3] if len(arrays) == 4 else None
        if not rows.size == cols.size == depths.size == (rows.size if pw is None else pw.size):
            raise ValueError(
                "`prior` as (rows, cols, depths" + ("" if pw is None else ", weights")
                + f") needs {'three' if pw is None else 'four'} arrays of one length; got "
                "lengths "
                + ", ".join(str(a.size) for a in arrays))
        if pw is not None:
            bad = ~(np.isfinite(pw) & (pw >= 0))
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise ValueError(f"`prior[3]` (the points' weights) must be finite and >= 0; "
                                 f"got {float(pw[k])!r} for the point at (row {rows[k]:g}, col "
                                 f"{cols[k]:g}) ({int(bad.sum())} such point(s))")
            zero = pw == 0  # (no sample: as if it were not given)
            if zero.all():
                raise ValueError("`prior[3]`: every point's weight is 0 (no sample)")
            if zero.any():
                rows, cols, depths, pw = rows[~zero], cols[~zero], depths[~zero], pw[~zero]
        if not (np.isfinite(rows).all() and np.isfinite(cols).all()):
            raise ValueError("`prior` (rows, cols, depths): rows and cols must be finite")
        r = np.rint(rows).astype(np.int64)
        c = np.rint(cols).astype(np.int64)
        out = (r < 0) | (r >= H) | (c < 0) | (c >= W)
        if out.any():  # (a point cloud's strays: left out, said; all of them: refused)
            k = int(np.flatnonzero(out)[0])
            where = (f"{int(out.sum())} of the {out.size} sample(s) lie outside the {H} x {W} "
                     f"image, the first at (row {rows[k]:g}, col {cols[k]:g})")
            if out.all():
                raise ValueError(f"`prior` (rows, cols, depths): {where}: no sample is inside "
                                 "(points projected with another K or image size, or 3-D "
                                 "points not projected with K at all?)")
            # (most of them: a camera-frame cloud, mm or m read as pixel positions, a user's)
            hint = ("; most of them: 3-D points (x, y in metres or mm, not the image's columns "
                    "and rows)? Project them with K first (docs/fusion.md, 'Sparse SfM points "
                    "projected with K')" if out.mean() > 0.5 else "")
            warn(f"`prior` (rows, cols, depths): {where}; they were left out{hint}")
            r, c, depths = r[~out], c[~out], depths[~out]
            pw = None if pw is None else pw[~out]
        keep = np.isfinite(depths)
        if not keep.all() and keep.any():  # (counted, not silently: a user's 53 lines, 50 used)
            k = int(np.flatnonzero(~keep)[0])
            warn(f"`prior` (rows, cols, depths): {int((~keep).sum())} sample(s) with a "
                 f"non-finite depth, the first at (row {r[k]}, col {c[k]}); they were left out")
        behind = keep & (depths <= 0)
        if positive and behind.any() and (keep & ~behind).any():
            # (a point cloud's points behind the camera: left out and said, as those outside
            # the image, before the averaging mixes them with good ones; a user's LiDAR cloud
            # with 10 such points was refused whole)
            k = int(np.flatnonzero(behind)[0])
            zero = int((keep & (depths == 0)).sum())
            # (a points file made from a sensor's map keeps its 0 "unknown": named, a review)
            said = (f" ({zero} of them exactly 0: a depth sensor's or a map's mark for an "
                    "unknown depth, best left out of the points)" if zero else "")
            warn(f"`prior` (rows, cols, depths): {int(behind.sum())} sample(s) with a "
                 f"non-positive z-depth (behind the camera), the first {float(depths[k])!r} "
                 f"at (row {r[k]}, col {c[k]}){said}; they were left out")
            keep &= ~behind
        idx = r[keep] * W + c[keep]
        d = depths[keep]
        pw = None if pw is None else pw[keep]
        pixels = int(np.unique(idx).size)
        rk, ck = r[keep], c[keep]
        box = ((int(np.ptp(rk)) + 1) * (int(np.ptp(ck)) + 1)) if rk.size else 0
        # (and in a small corner of the image: a depth map at 4x the resolution given as
        # points fills every pixel 16 times, a review)
        crowded = (keep.sum() >= CROWDED_MIN and pixels < CROWDED_SHARE * keep.sum()
                   and box < CROWDED_BOX * H * W)
        if crowded:
            # (a LiDAR user's camera-frame x, y, z in metres under an x,y,z header, read as
            # pixel columns and rows: 2,900 points in 6 pixels, 500 mm off, no word)
            warn(f"`prior` (rows, cols, depths): the {int(keep.sum())} samples fall into only "
                 f"{pixels} pixel(s), averaged per pixel: are they 3-D points or in other units "
                 "(x, y as metres, not as the image's columns and rows)? Project 3-D points "
                 "with K first (docs/fusion.md, 'Sparse SfM points projected with K')")
        # a pixel's points that disagree: left out (not where the points are crowded, which
        # the warning above explains, nor where all lie behind the camera, which the caller
        # refuses: their pixels' conflicts hid both, a review)
        agree = np.ones(d.size, dtype=bool)
        if not crowded and not (positive and d.size and (d <= 0).all()):
            agree = _agreeing(idx, d, H * W, positive)
        if not agree.all():
            torn = np.unique(idx[~agree])
            k = int(torn[0])
            warn(f"`prior` (rows, cols, depths): {torn.size} pixel(s) hold points whose depths "
                 f"differ by more than {CONFLICT:.0%} of the depth"
                 + ("" if positive else " range") + f" (the first at row {k // W}, col "
                 f"{k % W}; {int((~agree).sum())} points): they were left out, which of them "
                 "is right being unknown (a mismatched point beside a good one, or a sensor's "
                 "points seen past an edge; docs/fusion.md, 'Outlier samples')")
        count = np.bincount(idx[agree], minlength=H * W)
        wk = np.ones(int(agree.sum())) if pw is None else pw[agree]
        mass = np.bincount(idx[agree], wk, minlength=H * W)
        total = np.bincount(idx[agree], wk * d[agree], minlength=H * W)
        with np.errstate(invalid="ignore", divide="ignore"):
            img = np.where(count > 0, total / np.where(count > 0, mass, 1.0), np.nan)
            # (the weights' own weighted mean: a doubtful point beside a good one does not
            # halve its pull, a review)
            wimg = None if pw is None else np.where(
                count > 0, np.bincount(idx[agree], wk * wk, minlength=H * W)
                / np.where(count > 0, mass, 1.0), np.nan).reshape(H, W)
        return img.reshape(H, W), wimg
    arr = numeric_array(prior, "prior", "an (H, W) depth map or a (rows, cols, depths) triple")
    if arr.dtype == bool:
        raise ValueError("`prior` is a boolean array (a mask?); give depths, NaN where unknown")
    if arr.shape != shape:
        hint = ("; a list of (row, col, depth) points? Give it as columns, "
                "tuple(np.asarray(points, float).T)" if arr.ndim == 2 and arr.shape[1] in (3, 4)
                else "; the rows (rows, cols, depths[, weights]) of one array? Give them as "
                "a tuple, tuple(arr)" if arr.ndim == 2 and arr.shape[0] in (3, 4) else "")
        if arr.ndim == 2 and not hint:  # (a sensor's map of lower resolution: an audit)
            hint = coarse_prior_hint(arr.shape, shape)
        raise ValueError(f"`prior` must be an (H, W) depth map of shape {shape} to match "
                         f"`normals` (NaN where unknown) or a (rows, cols, depths) triple; got "
                         f"shape {arr.shape}{hint}")
    arr = arr.astype(float)
    inf = np.isinf(arr)
    if inf.any():  # (a few bad pixels never refuse a job: left out, counted and said)
        said = inf if mask is None else inf & np.asarray(mask, bool)
        if said.any():  # (not where only the background holds them, an audit)
            r, c = np.argwhere(said)[0]
            inside = "" if mask is None else " inside the mask"
            # (-inf was said as inf, a review)
            neg, pos = bool((arr[said] < 0).any()), bool((arr[said] > 0).any())
            which = "inf or -inf" if neg and pos else ("-inf" if neg else "inf")
            warn(f"`prior`: {int(said.sum())} pixel(s){inside} hold {which}, the first at (row "
                 f"{r}, col {c}); they were left out as unknown depths (NaN is the way to mark "
                 "them)")
        arr[inf] = np.nan
    return arr, None


def coarse_factor(small, shape) -> int | None:
    """The integer factor f >= 2 by which an (h, w) map `small` is coarser than `shape`
    (H, W) in both axes, ``h f`` and ``w f`` each within one pixel of H and W (a sensor's
    128 x 153 for a 512 x 612 map: 4); None otherwise."""
    try:
        (h, w), (H, W) = (int(v) for v in small), (int(v) for v in shape)
    except (TypeError, ValueError):
        return None
    if not (0 < h < H and 0 < w < W):
        return None
    f = round(H / h)
    if f < 2 or round(W / w) != f or abs(h * f - H) > 1 or abs(w * f - W) > 1:
        return None
    return f


def coarse_prior_hint(small, shape) -> str:
    """What to do with a prior of size `small` where the normal map is of size `shape` (a
    message's tail): where it is :func:`coarse_factor` times coarser, its pixels as point
    samples at their footprints' centres (on the DiLiGenT bear a 4x coarse noisy sensor gave
    0.159 mm so, 0.376 mm upsampled to a dense map: an audit), or upsampled; of any other
    size, :func:`resize_prior_hint`; "" where `small` is no (h, w) size."""
    try:  # (turned on its side: a portrait frame's depth beside a landscape map, told to
        # resize it, which made 12 mm of error from 0.03 without a word, an audit; not a
        # square prior, nor one that is a whole factor coarser as it is, a review)
        h, w = (int(v) for v in small)
        turned = h != w and coarse_factor((h, w), shape) is None and (
            (w, h) == tuple(int(v) for v in shape) or coarse_factor((w, h), shape) is not None)
    except (TypeError, ValueError):
        turned = False
    if turned:
        return ("; it is the map's size (or a whole factor of it) turned on its side: a "
                "depth frame in the other orientation? Turn it to the normal map's "
                "(np.rot90(prior) or np.rot90(prior, -1), or prior.T for a transposed array: "
                "the one whose depths then follow the normals' shape)")
    f = coarse_factor(small, shape)
    if f is None:
        return resize_prior_hint(small, shape)
    return (f"; it is {f}x coarser in both axes (a lower-resolution sensor's depth?): give its "
            f"pixels as point samples at their footprints' centres, its pixel (i, j) at row "
            f"(i + 0.5) * {f} - 0.5, col (j + 0.5) * {f} - 0.5 of the map: a points file "
            "(--prior points.csv: a header line row,col,depth, then one sample per line, its "
            f"pixel (0, 0) as {0.5 * f - 0.5:g},{0.5 * f - 0.5:g},DEPTH) or in Python "
            "prior=(rows, cols, depths); or upsample it to "
            f"{shape[0]}x{shape[1]} yourself (with --prior-blur / prior_blur). docs/fusion.md, "
            "'A depth map of lower resolution'")


def resize_prior_hint(small, shape) -> str:
    """What to do with a dense prior of size `small` (h, w) whose size is no whole factor of
    the map's `shape` (H, W): resize it to the map's size with any image tool and say how
    blurred it then is (``prior_blur``, about 1.1 times the factor it was enlarged by, as for
    a map upsampled from a coarse grid: docs/fusion.md "Blurred priors"), and, for a
    monocular network's relative output (Depth Anything's 518 x 518 beside a 540 x 960 frame:
    an audit's, refused with the two sizes only), ``prior_fit``; where its aspect differs,
    that the network's own resize is what to undo. "" where the sizes are not two numbers
    each."""
    try:
        (h, w), (H, W) = (int(v) for v in small), (int(v) for v in shape)
    except (TypeError, ValueError):
        return ""
    if min(h, w, H, W) <= 0:
        return ""
    f = max(H / h, W / w)
    if f > 1.05 and min(H / h, W / w) >= 1.0:  # (enlarged both ways: a VGA sensor's 480 x 640
        # beside 512 x 612 is shrunk across, a review)
        blur = (f", and give --prior-blur / prior_blur about {1.1 * f:.2g} to say it is blurred "
                f"(1.1 x the {f:.2g}x it is enlarged by; more for a network's output, softer "
                "than its pixels; --prior-weight then defaults to 0.003)")
    else:  # (made smaller: no blur of its making to declare)
        blur = ""
    aspect = ""
    if abs((w / h) / (W / H) - 1) > 0.02:
        aspect = (f"; its width/height ({w / h:.3g}) is not the map's ({W / H:.3g}): undo the "
                  "resize that made it (stretch it back where the frame was squashed to the "
                  "network's input, put it in place where the frame was cropped)")
    return (f"; a depth sensor's map belongs in the normal map's camera: reproject its "
            "points with the sensor's own K and pose (a plain resize is right only where both "
            "share one camera and field of view; a sparse points prior, (rows, cols, depths), "
            "takes the reprojected points as they are); a network's or an upsampled map: "
            f"resize it to {H}x{W}, the normal map's size, with any image tool (bilinear)"
            f"{blur}"
            f"{aspect}; a monocular network's relative depth or disparity also wants "
            "--prior-fit affine or disparity (prior_fit=), which fits its scale and shift to "
            "the normals. docs/fusion.md, 'A monocular depth map' and 'Blurred priors'")


#: The smallest ratio of a confidence to the map's largest that the solvers resolve: a
#: confidence of 1e-12 beside ones of 1 flattened the half of a plane it weighed (46 % of the
#: depth range off where its normals were the only data, an audit); smaller ones are raised
#: to it, with a warning (0 stays a missing normal).
CONFIDENCE_RANGE = 1e-8

#: The smallest ratio of the largest prior weight to the largest normal weight (1, or the
#: largest confidence) that the solvers resolve: at 1e-16 the prior's offset was lost to
#: rounding (a plane 0.96 off, or a solver error that named nothing, an audit); below it the
#: prior is refused, naming both.
PRIOR_RATIO = 1e-10


def _confidence_floor(conf: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """`conf` with the usable normals' confidences below :data:`CONFIDENCE_RANGE` of the
    largest raised to it, with a warning counting them."""
    top = float(conf[usable].max())
    low = usable & (conf < CONFIDENCE_RANGE * top)
    if low.any():
        warn(f"`confidence`: {int(low.sum())} normal(s) have a confidence below "
             f"{CONFIDENCE_RANGE:g} of the largest ({top:g}); they are raised to it, as the "
             "solvers cannot weigh a wider range (0 marks a missing normal)")
        conf = np.where(low, CONFIDENCE_RANGE * top, conf)
    return conf


def _prior_ratio_check(pw: np.ndarray, conf) -> None:
    """Refuse prior weights too small against the normals' weight to be resolved
    (:data:`PRIOR_RATIO`)."""
    used = pw[pw > 0]
    if not used.size:
        return
    top = 1.0 if conf is None or not conf.size else float(conf.max())
    if float(used.max()) < PRIOR_RATIO * top:
        against = "1 (a normal's)" if conf is None else f"{top:g}, the largest `confidence`"
        raise ValueError(f"`prior_weight`: the prior's largest weight {float(used.max()):g} is "
                         f"below {PRIOR_RATIO:g} of the normals' weight {against}: the solvers "
                         "cannot resolve it and its depths would be lost to rounding; give a "
                         "larger `prior_weight` (or smaller confidences), or leave the prior "
                         "out")


#: The largest prior weight: at 1e8 the result already meets the prior where given to
#: rounding (tests/test_fusion.py); 1e300 overflowed into a depth of 0 everywhere.
MAX_PRIOR_WEIGHT = 1e10

#: The largest |depth| of a prior sample (2e200 overflowed the energy's squares).
MAX_PRIOR_DEPTH = 1e30


#: Largest confidence taken without a word beside a prior (:func:`prepare`; the values then
#: weigh the normals against the prior as given, and confidences are usually in [0, 1]).
CONFIDENCE_ABOVE_ONE = 1.5


#: Largest share of a perspective prior's nonzero samples (in the mask) that may be
#: negative and still be left out as bad pixels (:func:`check_prior`); more are refused
#: (relative depth or disparity, which ``prior_fit`` aligns).
NEGATIVE_SHARE = 0.01
#: As many negative samples as this (and less than a quarter of the samples) are left out
#: whatever their share: a sparse map of 50 metric samples with one behind the camera was
#: refused as relative depth (its points given as (rows, cols, depths) were not), a
#: perspective audit; a relative depth's or disparity's shift leaves far more of them negative.
NEGATIVE_FEW = 3


def left_out_depths(depth: np.ndarray, have: np.ndarray) -> np.ndarray | None:
    """The samples `have` of a perspective prior's `depth` that integrate leaves out, or None
    where it refuses the prior (:func:`check_prior`, and ``facetlift info``'s counts).

    A depth sensor's map marks unknown pixels by 0 (no z-depth is 0), and a few negative
    samples are bad pixels: both are left out, as points behind the camera are. Many negative
    ones (more than :data:`NEGATIVE_SHARE` of the nonzero samples and more than
    :data:`NEGATIVE_FEW`: relative depth, disparity) or none positive left are refused."""
    with np.errstate(invalid="ignore"):
        neg = have & (depth <= 0)
        zeros = have & (depth == 0)
    negative = int((neg & ~zeros).sum())
    nonzero = int((have & ~zeros).sum())
    # (the few only where they are a small share too: 3 of 6, a zero-mean network output, is
    # relative depth, a review)
    if (have & ~neg).any() and negative <= max(NEGATIVE_SHARE * nonzero,
                                               min(NEGATIVE_FEW, 0.25 * nonzero)):
        return neg
    return None


def fit_zeros(raw: np.ndarray) -> np.ndarray | None:
    """The exact zeros of a prior map given to ``prior_fit`` with a camera, which are left out
    before the alignment as unknown depths (a depth sensor's mark), or None where there are
    none or nothing else (``facetlift.integrate``'s fitted route, ``facetlift info``)."""
    zeros = raw == 0
    return zeros if zeros.any() and not zeros.all() else None


def check_prior(prior, prior_weight, shape, mask, camera):
    """Checked prior: ``(values, weights, outside)``, the first two (m,) on the facets of
    `mask`, the values in the camera's unknown (:meth:`facetlift.camera.Camera.from_depth`),
    NaN and weight 0 where there is no sample; `outside` the number of samples outside the
    mask (no normal to integrate there: dropped).

    Raises
    ------
    ValueError
        A prior of another shape, with no finite sample inside the mask, with non-positive
        depth for a perspective camera where none is positive or more than
        :data:`NEGATIVE_SHARE` of the nonzero samples are negative (fewer, and zeros, are left
        out with a warning); a weight that is negative, not finite or of another
        shape (the message names the argument, the value and what was expected).
    """
    img, own = prior_samples(prior, shape, positive=camera.positive_depth, mask=mask)
    given = _weight_image(prior_weight, "prior_weight", shape)
    # (the points' own weights: times prior_weight)
    weight = given if own is None else np.where(np.isfinite(own), given * own, given)
    depth = img[mask]
    w = weight[mask]
    have = np.isfinite(depth)
    if not have.any():
        outside = int(np.isfinite(img).sum())
        # (points all left out, e.g. every pixel's points conflicting: said so, an audit)
        points = _is_points(prior, shape)
        left = ("; its points were all left out or fell outside the mask (the warnings above "
                "say why: outside the image, behind the camera, non-finite, or disagreeing "
                "within a pixel)" if points and not outside else "")
        if points and not np.size(prior[2]):  # (no warning above to point at, an audit)
            left = "; its list of points (rows, cols, depths) is empty"
        raise ValueError(
            "`prior` has no finite depth sample inside the mask"
            + (f" ({outside} outside it)" if outside else "")
            + (left or "; give depths where the normals are, NaN elsewhere")
            + (_unprojected_hint(prior, shape) if _is_points(prior, shape) else "")
        )
    # (first: the samples a perspective prior leaves out have no weight to check, a review)
    if camera.positive_depth:
        neg = have & (depth <= 0)
        if neg.any():
            k = int(np.flatnonzero(neg)[0])
            zeros = have & (depth == 0)
            below = neg & ~zeros
            if left_out_depths(depth, have) is not None:
                r, c = np.argwhere(mask)[k]
                warn(f"`prior`: {int(neg.sum())} sample(s) in the mask with a non-positive "
                     f"z-depth for a perspective camera ({int(zeros.sum())} of them 0, as a "
                     "depth sensor marks unknown pixels, or as the near end of a relative map "
                     "normalised to 0..1, which needs prior_fit='affine'), the first "
                     f"{float(depth[k])!r} at (row {r}, col {c}); they were left out (NaN is "
                     "the way to mark unknown depths)")
                have &= ~neg
            else:
                hint = (f"; {int(zeros.sum())} of them are 0: if 0 marks an unknown depth, "
                        "write NaN there (or pass the samples as (rows, cols, depths)); a "
                        "disparity or inverse-depth map (0 at the far end) must be inverted "
                        "into depth first (docs/fusion.md, 'Recipes')" if zeros.any() else "")
                # (a few bad pixels are left out, more are refused: say where the line is,
                # and that a sentinel such as -1 is no depth; only where some are negative,
                # a review)
                if below.any():
                    hint += (f"; negative samples are left out as bad pixels while they are "
                             f"at most {NEGATIVE_SHARE:.0%} of the nonzero ones, or at most "
                             f"{NEGATIVE_FEW} and a quarter of them, and positive ones remain; "
                             "more are taken for a map that is no metric depth: if a negative "
                             "value (e.g. -1) marks unknown depths, write NaN there")
                hint += ("; relative depth or disparity from a monocular network (any sign, "
                         "up to scale and shift): prior_fit='affine' or 'disparity' "
                         "(--prior-fit)")
                raise ValueError(
                    "`prior` must hold positive z-depths for a perspective camera (`K`); got "
                    f"{float(depth[k])!r} ({int(neg.sum())} non-positive sample(s), "
                    f"{int(below.sum())} of them negative, of {int(have.sum())}){hint}"
                )
    else:
        _zero_fill_check(depth[have])
    wbad = have & ~(np.isfinite(w) & (w >= 0) & (w <= MAX_PRIOR_WEIGHT))
    if wbad.any():
        k = int(np.flatnonzero(wbad)[0])
        mine = None if own is None else own[mask][k]
        what = "`prior_weight`"
        if mine is not None and np.isfinite(mine):  # (a points file's own weight column)
            what = (f"`prior_weight` times the points' own weight (here "
                    f"{float(given[mask][k]):g} x {float(mine):g})")
        raise ValueError(f"{what} must be finite, >= 0 and <= {MAX_PRIOR_WEIGHT:g} "
                         f"where the prior has a sample; got {float(w[k])!r} "
                         f"({int(wbad.sum())} such pixel(s)); 1e8 already returns the prior "
                         "where given")
    if have.any() and not (w[have] > 0).any():  # (dropped in silence: an audit)
        warn("`prior_weight` is 0 at every sample of the prior: the prior is not used (the "
             "result keeps the camera's gauge, not its depths); give a positive weight, or "
             "leave the prior out")
    huge = have & (np.abs(depth) > MAX_PRIOR_DEPTH)
    if huge.any():
        k = int(np.flatnonzero(huge)[0])
        raise ValueError(f"`prior` depths must lie within +-{MAX_PRIOR_DEPTH:g} (beyond, the "
                         f"energy's squares overflow; choose other units); got "
                         f"{float(depth[k])!r} ({int(huge.sum())} such sample(s))")
    # (a perspective prior's zeros and negative values outside the mask are no samples
    # either: not counted as unused ones, a review)
    outside = int(np.sum(np.isfinite(img[~mask]) & ((img[~mask] > 0)
                                                   | (not camera.positive_depth))))
    if _is_points(prior, shape):  # (a user's (u, v, z) as (rows, cols, depths): 57 % fell off)
        _swapped_check(prior, mask)
    values = np.where(have, camera.from_depth(np.where(have, depth, 1.0)), np.nan)
    return values, np.where(have, w, 0.0), outside


#: Share of an orthographic prior's samples that are exactly 0, beside others all of one
#: sign and ZERO_FAR times their spread or more away from 0, above which 0 is taken for a fill
#: of the unknown pixels (:func:`_zero_fill_check`).
ZERO_FILL, ZERO_FAR = 0.25, 2.0


def _zero_fill_check(depth: np.ndarray) -> None:
    """Warn where an orthographic prior's samples `depth` look like a map whose unknown
    pixels hold 0 (a perspective one is refused: its depths must be positive): at least
    :data:`ZERO_FILL` of them exactly 0 and the others all of one sign (an audit: 400 samples
    in mm and 40,270 zeros, 30x the error and only the depth-jump hint)."""
    zeros = depth == 0
    other = depth[~zeros]
    if other.size == 0 or zeros.mean() < ZERO_FILL:
        return
    if not (np.all(other > 0) or np.all(other < 0)):
        return
    # (and the others far from 0 for their spread, as an object's depths in mm are: a relief
    # on a base plane at 0, e.g. the analytic tent, rises from it, a review)
    if not np.abs(other).min() > ZERO_FAR * float(np.ptp(other)):
        return
    warn(f"`prior`: {int(zeros.sum())} of its {depth.size} samples in the mask are exactly 0 "
         f"while the others all lie between {float(other.min()):.6g} and "
         f"{float(other.max()):.6g}: if 0 marks an unknown depth, write NaN there (or pass "
         "the samples as (rows, cols, depths)); they are used as depths")


#: Share of a given mask's pixels without a normal (NaN) above which the mask is questioned
#: where the map's background outside it is NaN and its transpose or a flip would leave half
#: as many or fewer without one (:func:`_mask_fit_check`; random gaps inside the right mask,
#: the mask suite's "missing" route, and maps with a finite background stay silent).
MASK_MISSING = 0.25


def _sampled(n: np.ndarray, where: np.ndarray, at_most: int = 65536) -> np.ndarray:
    """The normals (k, 3) of `n` (H, W, 3) at an evenly strided sample of at most about
    `at_most` of the pixels `where` (H, W): the checks' samples, without a copy of every
    pixel's normal first (400 MB at 4096^2)."""
    step = max(1, where.size // (4 * at_most))  # (the image strided first: no index array
    idx = np.flatnonzero(where.ravel()[::step]) * step  # of every pixel either)
    idx = idx[:: max(1, idx.size // at_most)]
    return n.reshape(-1, 3)[idx]


def _varied(v: np.ndarray) -> float:
    """The share of normals `v` (k, 3) that are finite, not of zero length and not the most
    common value (a background fill)."""
    if v.shape[0] == 0:
        return 0.0
    ok = np.all(np.isfinite(v), axis=-1) & (np.abs(v).max(axis=-1) > 0)
    if not ok.any():
        return 0.0
    vals, counts = np.unique(np.round(v[ok], 6), axis=0, return_counts=True)
    return float(ok.sum() - counts.max()) / v.shape[0]


def _mask_fit_check(n: np.ndarray, m: np.ndarray, share: float) -> None:
    """Warn where a mask leaves many of its pixels without a normal (`share`, the normals
    `n` (H, W, 3) NaN there): the map's background decoded to NaN under a mask of another
    map or view; its transpose (square images) or a flip that fits far better is named. An
    audit: the BiNI human map's mask transposed ran with 48 % of it missing, and the only
    word was the depth-jump hint."""
    have = np.all(np.isfinite(n), axis=-1)
    H, W = m.shape

    def background(alt) -> bool:  # (most of the map outside `alt` NaN: the map's background)
        out = ~alt
        return bool(out.any()) and float(have[out].mean()) < 0.5

    out = ~m
    # (only where it can matter: a sort of up to a sample of the outside's normals, 0.05 s a
    # run at 512^2, was made for every map with 30 % of its normals missing)
    varied = _varied(_sampled(n, out)) if share > 0.5 and out.any() else 0.0
    if share > 0.5 and varied > 0.5:
        # (most of the mask without a normal, most of its outside with varied ones, an
        # object's, not a fill: the mask of the background; one ring of the object's pixels
        # in it ran silently, a review; a zero or flat fill outside a mask with holes is no
        # object, another review)
        warn(f"`mask`: {share:.0%} of its pixels have no normal while {varied:.0%} of those "
             "outside it hold varied ones (an object's): is the mask inverted (the object "
             "must be white, or True)?")
        return
    if not background(m):
        return  # (a finite background: the NaNs inside are holes, not the map's outside)
    tries = [("flipped upside down", m[::-1]), ("flipped left to right", m[:, ::-1])]
    if H == W:
        tries.insert(0, ("transposed", m.T))
    better = []
    for what, alt in tries:
        miss = 1.0 - float(have[alt].sum()) / max(int(alt.sum()), 1)
        if miss < 0.5 * share and background(alt):
            better.append(f"{what}, {miss:.0%}")
    if not better:
        return  # (random gaps inside the right mask: missing samples, no question)
    warn(f"`mask`: {share:.0%} of its pixels have no normal (NaN: the map's background?); is "
         f"the mask this map's, not another view's? The mask {'; '.join(better)} of its "
         "pixels would have none (missing normals inside a mask are integrated as missing "
         "samples)")


def _inverted_mask_hint(n: np.ndarray, m: np.ndarray) -> str:
    """For the error of a mask without a usable normal: where most pixels outside it hold a
    finite normal, the question whether it is inverted (a fresh user's mask with the object
    black and the background white met only the count of missing normals)."""
    out = ~m
    if not out.any():
        return ""
    have = np.all(np.isfinite(n[out]), axis=-1)
    if have.mean() < 0.5:
        return ""
    return (f"; outside the mask {int(have.sum()):,} of {int(out.sum()):,} pixels hold a "
            "normal: is the mask inverted (the object must be white, or True)?")


#: :func:`_flat_mask_check`: the share of a mask's pixels holding one and the same normal
#: (a fill) above which the mask is questioned where the pixels outside it, which do not
#: reach the image's border, hold varied ones.
MASK_FLAT = 0.95


def _flat_mask_check(n: np.ndarray, m: np.ndarray) -> None:
    """Warn where nearly every pixel of the mask holds the same normal (:data:`MASK_FLAT`;
    a background fill) while most pixels outside it hold other, varied normals: an inverted
    mask integrates the flat background without a word (a fresh user's check: 'mean deviation
    0.00 deg'). A flat object masked alone on a flat background stays silent (the outside is
    not varied)."""
    out = ~m
    if m.sum() < 16 or out.sum() < 16:
        return
    # (an inverted mask is the background, around an object inside the image; a flat object
    # masked inside a scene of varied normals, a box's face or a wall, leaves out a scene that
    # reaches the border, and was questioned, a review; a close-up object filling most of the
    # image, inverted, is still questioned, another review)
    if out[0].any() or out[-1].any() or out[:, 0].any() or out[:, -1].any():
        return  # (... and the object it leaves out lies inside the image)
    inside = _sampled(n, m)
    inside = inside[np.all(np.isfinite(inside), axis=-1)]
    if inside.shape[0] < 16:
        return
    first = np.median(inside, axis=0)
    same = np.all(np.abs(inside - first) < 1e-6, axis=-1)
    if same.mean() < MASK_FLAT:
        return
    outside = _sampled(n, out)
    outside = outside[np.all(np.isfinite(outside), axis=-1)]
    other = ~np.all(np.abs(outside - first) < 1e-6, axis=-1)
    if outside.shape[0] < 16 or other.mean() < 0.5 or np.ptp(outside[other], axis=0).max() < 0.1:
        return
    warn(f"`mask`: {same.mean():.0%} of its pixels hold one and the same normal ({first[0]:.3g}, "
         f"{first[1]:.3g}, {first[2]:.3g}: a background fill?) while the pixels outside it "
         "hold varied normals: is the mask inverted (the object must be white, or True)?")


def _swapped_check(prior, mask) -> None:
    """Warn where a points prior's rows and cols look swapped: read the other way round,
    more than twice as many of its points would land on the mask (a cloud projected over a
    whole image lands mostly beside a small object either way: no warning)."""
    H, W = mask.shape
    rows, cols = (np.rint(np.asarray(v, float).ravel()) for v in prior[:2])

    def on_mask(r, c):
        ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
        return int(mask[r[ok].astype(np.int64), c[ok].astype(np.int64)].sum())

    now, swapped = on_mask(rows, cols), on_mask(cols, rows)
    if swapped > 2 * max(now, 1):
        warn(f"`prior` (rows, cols, depths): {now} of the {rows.size} sample(s) lie on the "
             f"mask, {swapped} would with rows and cols swapped: were x, y given for row, col?")


def _huge(n, length2) -> np.ndarray:
    """Pixels whose (squared) length overflows although every component is finite."""
    over = np.isinf(length2)
    if over.any():
        over &= np.isfinite(n).all(-1)
    return over


def _channel_first_hint(shape) -> str:
    """Advice for a channel-first (3, H, W) array or a batch of one, (1, H, W, 3) or (1, 3, H,
    W) (a network's output tensor, an audit), else ''."""
    shape = tuple(shape)
    if len(shape) == 4 and shape[0] == 1:
        inner = _channel_first_hint(shape[1:])
        if shape[-1] == 3:
            return ": it looks like a batch of one (1, H, W, 3); normals[0] gives (H, W, 3)"
        if inner:
            return (": it looks like a batch of one, channel-first (1, 3, H, W); "
                    "numpy.moveaxis(normals[0], 0, -1) gives (H, W, 3)")
        return ""
    if len(shape) == 3 and shape[0] == 3 and shape[-1] != 3:
        return ": it looks channel-first (3, H, W); numpy.moveaxis(normals, 0, -1) gives (H, W, 3)"
    if len(shape) == 3 and shape[-1] == 4:  # (an RGBA array: io.read_normals takes its alpha)
        return (": RGB and alpha? give normals[..., :3] and mask=normals[..., 3] > 0 (or the "
                "file to facetlift.io.read_normals, which reads an alpha as the mask)")
    return ""


def isolated_normals(domain: Domain, normals: np.ndarray, ok: np.ndarray,
                     deviation: float, agreement: float) -> np.ndarray:
    """(m,) bool: the facets whose unit normal (of `normals` (m, 3), where `ok`) lies more
    than `deviation` degrees from the component-wise median of its eight neighbours' (renormed),
    while those neighbours, all inside the mask and `ok`, agree with that median within
    `agreement` degrees (all but the one farthest from it: two outliers side by side are found
    too). A jump, a crease or a rim has neighbours on two sides that do not agree, and a mask's
    border pixel lacks some: neither is taken. ``0 <= agreement <= deviation``.

    Such a normal lies at least ``deviation - agreement`` from seven of its neighbours (the
    triangle inequality of angles): that is checked first on a float32 grid of the unit
    normals over the mask's box (about 18 bytes per pixel of the box, transient), and only the
    facets where it holds, few on any map, get the median, from `normals` themselves."""
    r, c = domain.pixels
    out = np.zeros(domain.n_facets, bool)
    if not ok.any():
        return out
    r0, c0 = int(r.min()), int(c.min())
    H, W = int(r.max()) - r0 + 1, int(c.max()) - c0 + 1
    rb, cb = r - r0 + 1, c - c0 + 1  # (in the box, padded by one all round)
    grid = np.full((H + 2, W + 2, 3), np.nan, np.float32)
    grid[rb[ok], cb[ok]] = normals[ok]
    centre = grid[1:-1, 1:-1]
    near = math.cos(math.radians(deviation - agreement)) + 1e-6  # (float32 rounding)
    far = np.zeros((H, W), np.int8)
    with np.errstate(invalid="ignore"):
        for dr, dc in _RING:
            cos = np.einsum("ijk,ijk->ij", centre, grid[1 + dr:H + 1 + dr, 1 + dc:W + 1 + dc])
            far += cos <= near  # (NaN: a neighbour outside the mask or not ok, never far)
    del grid, centre
    index = np.full((H + 2, W + 2), -1, np.int64)  # (the facet at each place of the box)
    index[rb[ok], cb[ok]] = np.flatnonzero(ok)
    rr, cc = np.nonzero(far >= len(_RING) - 1)
    rr, cc = rr + 1, cc + 1
    own = index[rr, cc]
    ring = np.stack([index[rr + dr, cc + dc] for dr, dc in _RING], axis=1)  # (k, 8)
    keep = (own >= 0) & (ring >= 0).all(axis=1)
    own, ring = own[keep], normals[ring[keep]]  # (k,), (k, 8, 3) float64
    if own.size == 0:
        return out
    med = np.median(ring, axis=1)
    med /= np.linalg.norm(med, axis=1, keepdims=True)
    agree = np.sort(np.einsum("kjc,kc->kj", ring, med), axis=1)[:, 1]  # (all but the worst)
    cos = np.einsum("kc,kc->k", normals[own], med)
    out[own[(agree >= math.cos(math.radians(agreement)))
            & (cos < math.cos(math.radians(deviation)))]] = True
    return out


def isolated_rule_text(rule) -> str:
    """The isolated-normal rule ``(deviation, agreement)`` in words, for messages."""
    return (f"more than {rule[0]:g} deg from the median of their eight neighbours, which "
            f"agree within {rule[1]:g} deg")


def _check_isolated(isolated):
    """`isolated` as ``(deviation, agreement)`` floats, or None."""
    if isolated is None:
        return None
    try:
        dev, agree = (float(v) for v in isolated)
    except (TypeError, ValueError):
        raise ValueError(f"`isolated` must be two angles in degrees (deviation, agreement) or "
                         f"None; got {isolated!r}") from None
    if not (0.0 <= agree <= dev <= 180.0):
        raise ValueError(f"`isolated` must be (deviation, agreement) with 0 <= agreement <= "
                         f"deviation <= 180 degrees; got ({dev:g}, {agree:g})")
    return dev, agree


#: The eight neighbours of a pixel, (dr, dc).
_RING = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0))


def _where_facets(domain: Domain, bad: np.ndarray) -> str:
    r, c = domain.pixels
    k = np.flatnonzero(bad)
    return f"{k.size} pixel(s), first at (row {r[k[0]]}, col {c[k[0]]})"


def _check_eps(value) -> float:
    from .options import Option

    return Option("outlier_eps", None, "", low=0.0, high=1.0, high_open=True).check(value)


#: Without a mask, the pixels without a valid normal (not finite, zero length: an 8/16-bit
#: pixel whose decoded length is far from 1, such as black (0, 0, 0), reads as NaN) are
#: outside the domain, as a background is. Those in a component (8-connected) that does not
#: touch the image's border, so that every pixel around it has a valid normal, are enclosed
#: by the object (:func:`enclosed_gaps`). Components of at most HOLE_PIXELS pixels are inside
#: the object: they are counted (``counts["holes"]``) and named in the unusable-normals
#: warning. Larger ones are taken for real holes (a ring's): counted apart
#: (``counts["larger_holes"]``, ``info``'s "larger holes"), with no warning.
HOLE_PIXELS = 64


def enclosed_gaps(m: np.ndarray, max_pixels: int = HOLE_PIXELS
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(small, larger), each (H, W) bool: the pixels outside the domain `m` (H, W) bool that
    lie in a component (8-connected) not touching the image's border, fully surrounded by the
    domain, split by its size: at most `max_pixels` pixels (:data:`HOLE_PIXELS`), and more.
    Found within the domain's bounding box, which a hole cannot leave. The one definition of
    a hole that ``integrate`` (:func:`prepare`) and ``info`` report (info's own 4-connected
    fill of any size said 109 holes where integrate counted 9, a review)."""
    from scipy import ndimage

    small = np.zeros_like(m, dtype=bool)
    larger = np.zeros_like(m, dtype=bool)
    rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    if rows.size < 3 or cols.size < 3:
        return small, larger
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    gaps = ~m[box]
    if not gaps[1:-1, 1:-1].any():
        return small, larger
    labels, k = ndimage.label(gaps, structure=np.ones((3, 3), bool))
    sizes = np.bincount(labels.ravel(), minlength=k + 1)
    enclosed = np.ones(k + 1, bool)
    # (a component on the box's edge reaches the outside, or the image's border)
    enclosed[np.unique(np.r_[labels[0], labels[-1], labels[:, 0], labels[:, -1]])] = False
    enclosed[0] = False
    small[box] = (enclosed & (sizes <= max_pixels))[labels]
    larger[box] = (enclosed & (sizes > max_pixels))[labels]
    return small, larger


def enclosed_holes(m: np.ndarray, max_pixels: int = HOLE_PIXELS) -> np.ndarray:
    """(H, W) bool: the small holes of :func:`enclosed_gaps`, components of at most
    `max_pixels` pixels outside the domain `m` fully surrounded by it."""
    return enclosed_gaps(m, max_pixels)[0]


def _holes_note(holes: np.ndarray, field: bool = False) -> str:
    """The warning's words on the enclosed pixels without a normal (:func:`enclosed_holes`);
    `field`: the normals were made from a gradient field, whose samples are named instead."""
    rr, cc = np.nonzero(holes)
    if field:
        return (f"{int(holes.sum())} pixel(s) enclosed by the object hold no gradient sample "
                "(p or q not finite) and were left out as holes, NaN in the depth and the mesh "
                f"(holes of at most {HOLE_PIXELS} pixels surrounded by valid samples); first "
                f"at (row {rr[0]}, col {cc[0]}). Without a mask the domain is the finite "
                "samples: give one (--mask, mask=) to integrate such pixels as missing "
                "samples, filled from their neighbours")
    return (f"{int(holes.sum())} pixel(s) enclosed by the object hold no normal (not finite or "
            "zero length; in an 8/16-bit file, a pixel whose decoded length is far from 1, "
            "such as black (0, 0, 0)) and were left out as holes, NaN in the depth and the "
            f"mesh (holes of at most {HOLE_PIXELS} pixels surrounded by valid normals); first "
            f"at (row {rr[0]}, col {cc[0]}). Without a mask the domain is the valid normals: "
            "give one (--mask, mask=) to integrate such pixels as missing samples, filled from "
            "their neighbours")


def _without_lone_pixels(m: np.ndarray, refused: str, left_out: str) -> np.ndarray:
    """`m` (H, W) bool without its pixels that no other touches, not even at a corner (the
    domain's one-pixel components: nothing fixes their depth). `left_out` (a format of
    ``n``, ``r``, ``c``: how many, the first's row and column) is warned when some are;
    ValueError `refused` when every pixel is."""
    lone = m & ~_has_neighbour(m)
    if not lone.any():
        return m
    if not (m & ~lone).any():
        raise ValueError(refused)
    rr, cc = np.nonzero(lone)
    warn(left_out.format(n=int(lone.sum()), r=rr[0], c=cc[0]))
    return m & ~lone


def _has_neighbour(m: np.ndarray) -> np.ndarray:
    """Where `m` (H, W) bool has one of its 8 neighbours set (no labelling pass: a second one
    cost 0.45 s of prepare's 0.88 at 2048^2)."""
    p = np.pad(m, 1)
    H, W = m.shape
    out = np.zeros_like(m)
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            if dr != 1 or dc != 1:
                out |= p[dr:dr + H, dc:dc + W]
    return out


def clean_mask(mask, min_size: int = 2) -> np.ndarray:
    """Remove 8-connected components with fewer than `min_size` pixels from a mask."""
    ok = not isinstance(min_size, bool) and isinstance(min_size, (int, float, np.integer,
                                                                   np.floating))
    if not ok or not np.isfinite(min_size) or min_size < 0:  # (0.01 * m.sum() is a float)
        raise ValueError(f"`min_size` must be a number of pixels >= 0; got {min_size!r}")
    # (NaN refused as integrate refuses it, not taken as inside, a review)
    m = finite_values(numeric_array(unmasked(mask, 0.0), "mask", "a boolean or numeric array"),
                      "mask") != 0
    if m.ndim != 2:
        raise ValueError(f"`mask` must be an (H, W) array; got shape {m.shape}")
    d = Domain.from_mask(m)
    keep = np.concatenate([[False], d.component_sizes >= min_size])
    return keep[d.labels]
