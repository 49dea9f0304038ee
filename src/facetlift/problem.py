"""Checked inputs shared by every integration method.

:func:`prepare` is the single public-boundary check: it turns user arrays into a
:class:`Problem` or raises ``ValueError`` naming the argument and what was wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .domain import Domain


@dataclass(eq=False)
class Problem:
    """A normal-integration problem on a domain (see :mod:`facetlift.conventions`).

    Attributes
    ----------
    domain : Domain
    normals : (m, 3) float
        Unit normals of the facets (x right, y up, z toward the viewer); NaN where unknown.
    known : (m,) bool
        Facets with a given normal.
    pixel_size : float
        Width of a pixel in world units (orthographic only).
    K : (3, 3) float or None
        Perspective intrinsics (OpenCV layout), or None for an orthographic view.
    """

    domain: Domain
    normals: np.ndarray
    known: np.ndarray
    pixel_size: float = 1.0
    K: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    @property
    def perspective(self) -> bool:
        return self.K is not None

    @cached_property
    def slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """(p, q), each (m,): p = dz/dx, q = dz/dy of the height; NaN where unknown."""
        n = self.normals
        with np.errstate(divide="ignore", invalid="ignore"):
            p = -n[:, 0] / n[:, 2]
            q = -n[:, 1] / n[:, 2]
        p[~self.known] = np.nan
        q[~self.known] = np.nan
        return p, q

    def normal_image(self) -> np.ndarray:
        """(H, W, 3) normals with NaN outside the domain and at unknown facets."""
        H, W = self.domain.shape
        out = np.full((H, W, 3), np.nan)
        out[self.domain.pixels] = self.normals
        return out


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


def _where(bad: np.ndarray) -> str:
    r, c = np.nonzero(bad)
    return f"{r.size} pixel(s), first at (row {r[0]}, col {c[0]})"


def prepare(
    normals,
    mask=None,
    *,
    known=None,
    pixel_size: float = 1.0,
    K=None,
    backfacing: str = "error",
) -> Problem:
    """Check user inputs and build a :class:`Problem`.

    Parameters
    ----------
    normals : (H, W, 3) array_like of float
        Normal map (x right, y up, z toward the viewer); need not be unit length.
        NaN marks a missing sample inside the mask.
    mask : (H, W) array_like of bool, optional
        Integration domain. Default: pixels whose normal is finite and non-zero.
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the others in the mask are missing samples.
    pixel_size : float
        Pixel width in world units (orthographic views).
    K : (3, 3) array_like, optional
        Perspective intrinsics, OpenCV layout.
    backfacing : {"error", "outlier"}
        What to do with normals whose z-component is <= 0 inside the domain: raise, or treat
        them as missing samples.

    Raises
    ------
    ValueError
        On a wrong shape or dtype, inf values, zero-length or back-facing normals, an empty
        mask, a mask of another size, one-pixel components, a bad pixel size or bad `K`.
    """
    n = _float_array(normals, "normals")
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}")
    H, W = n.shape[:2]
    if H < 1 or W < 1:
        raise ValueError(f"`normals` must have at least one pixel; got shape {n.shape}")
    if backfacing not in ("error", "outlier"):
        raise ValueError(f"`backfacing` must be 'error' or 'outlier'; got {backfacing!r}")
    if np.isinf(n).any():
        raise ValueError(f"`normals` contains inf at {_where(np.isinf(n).any(-1))}")
    try:
        h = float(pixel_size)
    except (TypeError, ValueError):
        raise ValueError(f"`pixel_size` must be a positive number; got {pixel_size!r}") from None
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"`pixel_size` must be a positive finite number; got {pixel_size!r}")

    with np.errstate(over="ignore", invalid="ignore"):
        length2 = np.einsum("ijk,ijk->ij", n, n)
    finite = np.isfinite(length2)
    if np.isinf(length2).any():
        raise ValueError(
            f"`normals` has values too large to normalise at {_where(np.isinf(length2))}"
        )
    if mask is None:
        m = finite & (length2 > 0)
    else:
        m = _bool_image(mask, "mask", (H, W))
    if not m.any():
        raise ValueError(
            "`mask` is empty: no pixel to integrate"
            if mask is not None
            else "`normals` has no finite, non-zero normal: nothing to integrate"
        )
    kn = m & finite
    if known is not None:
        kn &= _bool_image(known, "known", (H, W))
    zero = kn & (length2 == 0)
    if zero.any():
        raise ValueError(
            f"`normals` has zero-length normals inside the mask at {_where(zero)}; "
            "use NaN (or the `known` mask) for missing samples"
        )
    Kmat = None if K is None else _check_K(K)
    if Kmat is None:
        back = kn & (n[..., 2] <= 0)
        what = "n_z <= 0"
    else:  # in a perspective view, facing away means facing away from the viewing ray
        from .perspective import view_cosine

        back = np.zeros_like(kn)
        rr, cc = np.nonzero(kn)
        back[rr, cc] = view_cosine(Kmat, rr, cc, n[rr, cc]) <= 0
        what = "facing away from the camera ray"
    if back.any():
        if backfacing == "error":
            raise ValueError(
                f"`normals` has back-facing normals ({what}) inside the mask at "
                f"{_where(back)}; mask them out or pass backfacing='outlier'"
            )
        kn &= ~back

    domain = Domain.from_mask(m)
    small = np.nonzero(domain.component_sizes < 2)[0]
    if small.size:
        rr, cc = np.nonzero(np.isin(domain.labels, small + 1))
        raise ValueError(
            f"`mask` has {small.size} one-pixel component(s) (first at row {rr[0]}, col {cc[0]}); "
            "an isolated pixel has no neighbour to fix its depth: remove it from the mask "
            "(facetlift.clean_mask does this)"
        )
    kf = kn[m]
    nf = n[m]
    with np.errstate(invalid="ignore", divide="ignore"):
        nf /= np.sqrt(length2[m])[:, None]
    nf[~kf] = np.nan
    return Problem(domain=domain, normals=nf, known=kf, pixel_size=h, K=Kmat)


def _check_K(K) -> np.ndarray:
    Km = _float_array(K, "K")
    if Km.shape != (3, 3):
        raise ValueError(f"`K` must be a 3x3 intrinsics matrix; got shape {Km.shape}")
    if not np.isfinite(Km).all():
        raise ValueError("`K` contains NaN or inf")
    if not (Km[0, 0] > 0 and Km[1, 1] > 0):
        raise ValueError(f"`K` must have positive focal lengths fx=K[0,0], fy=K[1,1]; got {Km}")
    if not np.allclose(Km[2], [0, 0, 1]) or Km[1, 0] != 0:
        raise ValueError(
            "`K` must be upper-triangular with last row [0, 0, 1] (OpenCV layout "
            f"[[fx, s, cx], [0, fy, cy], [0, 0, 1]]); got {Km.tolist()}"
        )
    return Km


def clean_mask(mask, min_size: int = 2) -> np.ndarray:
    """Remove 8-connected components with fewer than `min_size` pixels from a mask."""
    m = np.asarray(mask) != 0
    d = Domain.from_mask(m)
    keep = np.concatenate([[False], d.component_sizes >= min_size])
    return keep[d.labels]
