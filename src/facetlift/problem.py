"""Checked inputs shared by every integration method.

:func:`prepare` is the single public-boundary check: it turns user arrays into a
:class:`Problem` or raises ``ValueError`` naming the argument and what was wrong.

Bad normals
    Only pixels inside the mask are inspected. A normal there that cannot be used -- not
    finite, zero length, facing away from the camera, or grazing (the view cosine below the
    outlier threshold, Sec. 4.4 of Xie et al.) -- becomes a missing sample: counted in
    ``Problem.counts``, named in one warning (how many of each kind, where the first is), and
    integrated like a NaN normal. A job is refused only when no usable normal is left.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ._warnings import warn
from .camera import Camera, make_camera
from .domain import Domain

#: ``backfacing=`` choices: treat such normals as missing samples, or raise.
BACKFACING = ("missing", "error", "outlier")


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
    """

    domain: Domain
    normals: np.ndarray
    known: np.ndarray
    camera: Camera = field(default_factory=make_camera)
    usable: np.ndarray | None = None
    counts: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)

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

    @property
    def slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """(p, q), each (m,): grid slopes per footprint; for an orthographic camera the height
        gradient ``p = dz/dx``, ``q = dz/dy``. NaN where not usable."""
        gx, gy = self.grid_slopes
        s = self.camera.footprint()
        return gx / s, gy / s

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
            usable=self.usable, counts=self.counts, extras=self.extras,
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
    p = _float_array(p, "p")
    q = _float_array(q, "q")
    if p.ndim != 2:
        raise ValueError(f"`p` must be a 2-D (H, W) array; got shape {p.shape}")
    if q.shape != p.shape:
        raise ValueError(f"`q` must have the shape of `p` {p.shape}; got {q.shape}")
    if np.isinf(p).any() or np.isinf(q).any():
        raise ValueError("`p` and `q` must not contain inf (use NaN for missing samples)")
    n = np.stack([-p, -q, np.ones_like(p)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def gradients_from_normals(normals) -> tuple[np.ndarray, np.ndarray]:
    """``(p, q) = (-n_x / n_z, -n_y / n_z)`` for an (H, W, 3) normal map."""
    n = _float_array(normals, "normals")
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}")
    with np.errstate(divide="ignore", invalid="ignore"):
        return -n[..., 0] / n[..., 2], -n[..., 1] / n[..., 2]


def numeric_array(a, name: str, what: str = "a real numeric array") -> np.ndarray:
    """``np.asarray(a)`` if it is a real numeric (or boolean) array, else a ValueError naming
    `name`. Shared by the input checks here and the writers in :mod:`facetlift.io`."""
    try:
        arr = np.asarray(a)
    except Exception as e:  # ragged lists and the like
        raise ValueError(f"`{name}` could not be read as an array: {e}") from None
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        raise ValueError(f"`{name}` must be {what}; got dtype {arr.dtype}")
    return arr


def _float_array(a, name: str) -> np.ndarray:
    return numeric_array(a, name).astype(float, copy=True)


def _bool_image(a, name: str, shape: tuple[int, int]) -> np.ndarray:
    arr = numeric_array(a, name, "a boolean or numeric array")
    if arr.shape != shape:
        raise ValueError(f"`{name}` must have shape {shape} to match `normals`; got {arr.shape}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError(f"`{name}` contains NaN or inf")
    return arr != 0


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
) -> Problem:
    """Check user inputs and build a :class:`Problem`.

    Parameters
    ----------
    normals : (H, W, 3) array_like of float
        Normal map (x right, y up, z toward the viewer); need not be unit length. NaN marks a
        missing sample inside the mask. Pixels outside the mask may hold anything.
    mask : (H, W) array_like of bool, optional
        Integration domain. Default: pixels whose normal is finite and non-zero.
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the others in the mask are missing samples.
    pixel_size : float
        Pixel width in world units (orthographic views).
    K : (3, 3) array_like, optional
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

    Raises
    ------
    ValueError
        On a wrong shape or dtype, an empty mask, a mask of another size, one-pixel
        components, a bad pixel size, `K` or `outlier_eps`, no usable normal at all, or
        back-facing normals with ``backfacing="error"``.
    """
    n = numeric_array(normals, "normals").astype(float, copy=False)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}")
    H, W = n.shape[:2]
    if H < 1 or W < 1:
        raise ValueError(f"`normals` must have at least one pixel; got shape {n.shape}")
    if backfacing not in BACKFACING:
        raise ValueError(f"`backfacing` must be one of {BACKFACING[:2]}; got {backfacing!r}")
    cam = make_camera(pixel_size, K) if camera is None else camera
    eps = cam.grazing if outlier_eps is None else _check_eps(outlier_eps)

    if mask is None:
        with np.errstate(over="ignore", invalid="ignore"):
            length2 = np.einsum("ijk,ijk->ij", n, n)
        m = (np.isfinite(length2) & (length2 > 0)) | _huge(n, length2)
        if not m.any():
            raise ValueError("`normals` has no finite, non-zero normal: nothing to integrate")
    else:
        m = _bool_image(mask, "mask", (H, W))
        if not m.any():
            raise ValueError("`mask` is empty: no pixel to integrate")
    domain = Domain.from_mask(m)
    _check_components(domain)
    # from here on only the mask's pixels, as (k,) facet arrays in row-major order
    nf = n[m]
    given = np.ones(len(nf), bool) if known is None else _bool_image(known, "known", (H, W))[m]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        length = np.sqrt(np.einsum("ij,ij->i", nf, nf))
        huge = _huge(nf, length)  # (0, 1e200, 1e200) is a fine normal: scale it first
        if huge.any():
            nf[huge] /= np.abs(nf[huge]).max(axis=1, keepdims=True)
            length[huge] = np.sqrt(np.einsum("ij,ij->i", nf[huge], nf[huge]))
        nf /= length[:, None]
    nan = given & np.isnan(length)
    bad = {
        "non-finite": given & ~nan & ~np.isfinite(length),
        "zero-length": given & (length == 0),
    }
    ok = given & np.isfinite(length) & (length > 0)
    r, c = domain.pixels
    with np.errstate(invalid="ignore"):
        cos = np.where(ok, cam.view_cosine(r, c, nf, unit=True), 0.0)
    bad["back-facing"] = ok & (cos <= 0)
    if backfacing == "error" and bad["back-facing"].any():
        raise ValueError(
            "`normals` has back-facing normals (facing away from the camera) inside the mask "
            f"at {_where_facets(domain, bad['back-facing'])}; mask them out or pass "
            "backfacing='missing'"
        )
    front = ok & (cos > 0)
    bad["grazing"] = front & (cos < eps)
    usable = front & ~bad["grazing"]

    counts = {"pixels": int(m.sum()), "missing": int((~given | nan).sum())}
    counts.update({k: int(v.sum()) for k, v in bad.items()})
    counts["usable"] = int(usable.sum())
    counts["outlier_eps"] = float(eps)
    problems = {k: v for k, v in bad.items() if v.any()}
    if problems:
        first = int(np.flatnonzero(np.logical_or.reduce(list(problems.values())))[0])
        counts["first_unusable"] = [int(r[first]), int(c[first])]
        what = ", ".join(f"{int(v.sum())} {k}" for k, v in problems.items())
        warn(
            f"{sum(int(v.sum()) for v in problems.values())} normal(s) inside the mask cannot be "
            f"used and were treated as missing samples ({what}; grazing: view cosine < "
            f"{eps:.4g}); first at (row {r[first]}, col {c[first]})"
        )
    if not usable.any():
        raise ValueError(
            "`normals` has no usable normal inside the mask (all missing, non-finite, "
            f"back-facing or grazing: {counts})"
        )
    nf[~front] = np.nan
    return Problem(
        domain=domain, normals=nf, known=front, camera=cam, usable=usable, counts=counts,
    )


def _huge(n, length2) -> np.ndarray:
    """Pixels whose (squared) length overflows although every component is finite."""
    over = np.isinf(length2)
    if over.any():
        over &= np.isfinite(n).all(-1)
    return over


def _where_facets(domain: Domain, bad: np.ndarray) -> str:
    r, c = domain.pixels
    k = np.flatnonzero(bad)
    return f"{k.size} pixel(s), first at (row {r[k[0]]}, col {c[k[0]]})"


def _check_eps(value) -> float:
    from .options import Option

    return Option("outlier_eps", None, "", low=0.0, high=1.0, high_open=True).check(value)


def _check_components(domain: Domain) -> None:
    small = np.nonzero(domain.component_sizes < 2)[0]
    if small.size:
        rr, cc = np.nonzero(np.isin(domain.labels, small + 1))
        raise ValueError(
            f"`mask` has {small.size} one-pixel component(s) (first at row {rr[0]}, col {cc[0]}); "
            "an isolated pixel has no neighbour to fix its depth: remove it from the mask "
            "(facetlift.clean_mask does this)"
        )


def clean_mask(mask, min_size: int = 2) -> np.ndarray:
    """Remove 8-connected components with fewer than `min_size` pixels from a mask."""
    m = np.asarray(mask) != 0
    d = Domain.from_mask(m)
    keep = np.concatenate([[False], d.component_sizes >= min_size])
    return keep[d.labels]
