"""Photometric stereo: a robust least-squares fit of normals from images, and a simulation of
such images from a ground truth, so that benchmarks can feed the integrators normals whose
errors look like a photometric stereo's (shadows, highlights, image noise) instead of
independent angular noise.

Frames follow :mod:`facetlift.conventions`: light directions and normals have x right, y up
and z toward the viewer; a light direction points from the surface toward the (distant)
light.

:func:`fit`
    Lambertian least squares per pixel over the observations that are neither shadowed
    (darker than ``shadow`` of the brightest) nor saturated, then again without the
    observations brighter than the first fit by more than ``highlight`` of the albedo (a
    highlight), for ``passes`` fits in all; NaN observations are left out too. Returns unit
    normals (NaN where fewer than three usable lights, or a badly conditioned set of them, are
    left) and a confidence in (0, 1] from the fit's residual: 1 where the residual is typical,
    1/2 at three times the median and where only three lights were usable.
    This is the fit of docs/recipes.md, "A photometric-stereo pipeline in Python"; its
    thresholds were the first ones tried and are not tuned.

:func:`simulate`
    Images of a :class:`facetlift.synthetic.GroundTruth` under distant lights: a smooth
    random albedo, Lambertian shading, Blinn-Phong highlights, attached shadows, shadows cast
    by the visible surface (marched over the ground-truth depth map in the image: geometry the
    camera does not see casts none), saturation, Gaussian image noise and quantisation.
    Each pixel is shaded with its ground-truth normal (for renders with several rays per pixel,
    their mean) and shadowed from its centre's point. Interreflections are not modelled.
"""

from __future__ import annotations

import numpy as np

from ._warnings import warn

__all__ = ["cast_shadows", "fit", "lights_on_cap", "simulate"]

#: Residuals (RMS over the albedo) below this count as an exact fit in :func:`fit`'s
#: confidence: a fit to rounding errors is not spread over (0, 1] by their size.
RESIDUAL_FLOOR = 1e-6

#: :func:`fit`'s confidence of a pixel fitted to exactly three observations: they fit any
#: normal exactly, so no residual checks it (such pixels lie next to shadows, where a
#: photometric stereo is least reliable); the confidence a residual of three times the median
#: gets.
UNCHECKED = 0.5


def lights_on_cap(count: int, spread_deg: float = 40.0, rng=None) -> np.ndarray:
    """(count, 3) unit light directions spread evenly (a Fibonacci spiral, turned at random
    by `rng`) over the spherical cap within `spread_deg` degrees of the viewing axis, as the
    lights of a photometric-stereo rig around its camera."""
    if not (isinstance(count, (int, np.integer)) and count >= 3):
        raise ValueError(f"`count` must be an integer >= 3; got {count!r}")
    if not (np.isfinite(spread_deg) and 0 < spread_deg < 90):
        raise ValueError(f"`spread_deg` must be in (0, 90) degrees; got {spread_deg!r}")
    rng = np.random.default_rng(rng)
    i = np.arange(count) + 0.5
    cos_min = np.cos(np.radians(spread_deg))
    z = 1.0 - (1.0 - cos_min) * i / count  # (equal areas of the cap)
    phi = i * np.pi * (3.0 - np.sqrt(5.0)) + rng.uniform(0, 2 * np.pi)
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _check_lights(lights, images=None, least: int = 3) -> np.ndarray:
    try:  # (a string or a ragged list: numpy's own words, which named no argument, an audit)
        L = np.asarray(lights, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"`lights` must be a (k, 3) array of k >= {least} directions; got "
                         f"{type(lights).__name__} that is no array of numbers") from None
    if L.ndim != 2 or L.shape[1] != 3 or len(L) < least:
        turned = (" (it looks transposed: give lights.T)"
                  if L.ndim == 2 and L.shape[0] == 3 and L.shape[1] >= least else "")
        raise ValueError(f"`lights` must be a (k, 3) array of k >= {least} directions; got "
                         f"shape {L.shape}{turned}")
    if images is not None and len(L) != len(images):
        layout = (" (the images look (H, W, k), one per light along the last axis: give "
                  "them as (k, H, W), np.moveaxis(images, -1, 0))"
                  if images.ndim == 3 and images.shape[-1] == len(L) else "")
        raise ValueError(f"`lights` has {len(L)} directions but `images` {len(images)} images"
                         + layout)
    norm = np.linalg.norm(L, axis=1)
    if not (np.isfinite(L).all() and (norm > 0).all()):
        raise ValueError("`lights` must be finite, non-zero directions")
    if images is not None and float(norm.max()) > LENGTHS_DIFFER * float(norm.min()):
        # (intensities folded into the directions' lengths were dropped without a word: the
        # normals 18 deg off, an audit)
        warn(f"`lights` have lengths from {norm.min():.4g} to {norm.max():.4g}: only their "
             "directions are used; if the lengths are the lights' intensities, divide each "
             "image by its own (or give them as intensities=)")
    if images is not None and (L[:, 2] < 0).all():
        warn("every one of the `lights` has z < 0, behind the surface seen from the viewer: "
             "facetlift's lights are x right, y up, z toward the viewer; lights in a camera "
             "frame with z away (OpenCV's) are L * (1, -1, -1)")
    return L / norm[:, None]


#: Largest ratio of the light vectors' lengths :func:`fit` takes without a word (their
#: lengths are dropped: see its `intensities`).
LENGTHS_DIFFER = 1.01


#: Ratios of the light directions' smallest singular value to their largest below which
#: :func:`fit` refuses them as coplanar (no normal is determined) and warns that they are
#: badly conditioned (noise in the images turns the normals far along the direction the
#: lights hardly span; a set spread by 0.01 across a plane: 19 deg median error with no word,
#: an audit). DiLiGenT's 96 lights within about 40 deg of the axis read about 0.3.
LIGHTS_SINGULAR, LIGHTS_ILL = 1e-6, 0.05


def _check_span(L: np.ndarray) -> float:
    """Refuse directions that span fewer than three dimensions, warn about nearly so; the
    ratio of their smallest singular value to their largest."""
    sv = np.linalg.svd(L, compute_uv=False)
    ratio = float(sv[-1] / sv[0])
    if ratio < LIGHTS_SINGULAR:
        raise ValueError("`lights` span fewer than three dimensions (all in one plane, or "
                         "along one line): no normal is determined by them; lights from "
                         "directions that do not share a plane are needed")
    if ratio < LIGHTS_ILL:
        warn(f"`lights` nearly share a plane (their smallest singular value is {ratio:.2g} of "
             "the largest): the normals are poorly determined across it, and noise in the "
             "images turns them far; spread the lights more (docs/recipes.md)")
    return ratio


def fit(images, lights, mask=None, *, intensities=None, shadow: float = 0.02,
        saturation: float | None = 0.98, highlight: float = 0.1, dark: float = 0.2,
        passes: int = 2):
    """Normals and a confidence from images under known distant lights.

    Parameters
    ----------
    images : (k, H, W) array_like
        Linear intensities (any scale, integers or floats, not copied whole: each block of
        pixels is fitted in float64), one grey image per light, each divided by its light's
        intensity where the lights differ (DiLiGenT's ``light_intensities.txt``; a colour
        image first averaged over its channels, each divided by the light's intensity in
        that channel).
    lights : (k, 3) array_like
        Directions toward the lights (x right, y up, z toward the viewer); normalised here.
    mask : (H, W) bool, optional
        Pixels to fit; default every pixel with a finite intensity. NaN observations are left
        out of their pixel's fit.
    intensities : (k,) array_like, optional
        The lights' intensities (> 0), where `images` are the camera's values as taken: each
        image is divided by its own here, after the clipped values were found on the values
        as taken (divided first, a clipped 65535 became 65535 / E, a different value under
        every light, and most of them passed the saturation cut: 15 deg off at a highlight,
        an audit). Default: the images are already divided (or the lights equal).
    shadow, saturation : float
        Observations below ``shadow`` times the 99.9th percentile of the (divided)
        intensities inside the mask are left out (shadows), and those above ``saturation``
        times the 99.9th percentile of the values as taken (clipped highlights); beyond
        :data:`TOP_SAMPLE` observations those percentiles are taken over a seeded random
        subset of the pixels. ``saturation=None``: no observation is taken as clipped (images
        that never reached the sensor's top; a warning suggests it where the cut takes more
        than :data:`CLIPPED_WARN` of the observations). The shadow test is absolute: a cast
        shadow that keeps some light (ambient, bounced) passes it, and only `dark` takes it
        out (an audit: 5 % of the light kept in the shadows, 44 deg median error there
        without it); subtract a dark or ambient frame first, and give a mask (without one the
        background's offset gets normals too).
    highlight : float
        From the second pass on, observations brighter than the previous fit predicts by more
        than this fraction of the pixel's albedo are left out.
    dark : float
        From the second pass on, observations darker than the previous fit predicts by more
        than this fraction of the pixel's albedo are left out (0: none): a cast shadow that
        keeps some light (ambient, bounced), which the absolute `shadow` test keeps. Chosen on
        Lambertian images of the analytic `occluder` and `steps` at 128^2 (20 lights within
        40 deg, albedo 0.5-0.9, noise 0.003, 10 % of the light kept in the cast shadows: mean
        error 19.1 / 9.1 deg with 0, 7.8 / 5.7 with 0.2; 0.1 left hundreds of pixels without
        a normal, 0.3 gained less); images without a leak, and `simulate`'s of five analytic
        scenes and the DiLiGenT bear with highlights (specular 0 / 0.2 / 0.5), moved by 0.05
        deg at most (a session's `/tmp` script, 2026-12-07).
    passes : int
        Least-squares fits (>= 1).

    Returns
    -------
    normals : (H, W, 3) float
        Unit normals, NaN outside the mask and where fewer than three usable observations are
        left, or where the lights left span the directions badly (their least eigenvalue
        below :data:`LIGHTS_ILL` squared of the largest: a bar of lights with the two others
        in shadow fitted normals 118 deg off with confidence 0.94, an audit).
    confidence : (H, W) float
        ``1 / (1 + (res / (3 median res))^2)`` of the fit's residual over the albedo (its
        root of the squared residuals' sum over the observations beyond three), the median
        taken no lower than :data:`RESIDUAL_FLOOR`; :data:`UNCHECKED` where only three
        observations were used, 0 where there is no normal.

    Raises
    ------
    ValueError
        Shapes that do not match, non-finite lights or lights that share a plane, thresholds
        out of range, an empty mask, images with no positive intensity inside the mask.
    """
    try:  # (as given: each block is made float64 when it is fitted)
        I = np.asarray(images)
    except ValueError:  # (a ragged list of images: numpy's words, an audit)
        raise ValueError("`images` must be a (k, H, W) stack of numbers; got images of "
                         "different shapes") from None
    if I.ndim != 3 or not (np.issubdtype(I.dtype, np.integer)
                           or np.issubdtype(I.dtype, np.floating)):
        colour = (": colour images, (k, H, W, 3), are averaged over their channels first, "
                  "each divided by its light's intensity in that channel (clipped values "
                  "marked NaN first), e.g. (images[..., :3] / intensities[:, None, None, "
                  ":]).mean(axis=-1) with intensities (k, 3)"
                  + (" (the fourth channel, alpha, left out)" if I.shape[-1] == 4 else "")
                  if I.ndim == 4 and I.shape[-1] in (3, 4) else "")
        raise ValueError(f"`images` must be a (k, H, W) stack of numbers; got shape "
                         f"{I.shape}, dtype {I.dtype}{colour}")
    L = _check_lights(lights, I)
    # a pixel's usable lights must span the directions nearly as well as the whole set (its
    # least eigenvalue of sum l l^T, over the largest: LIGHTS_ILL^2, or a quarter of the
    # set's own where the set is narrower and only warned about: a 4-degree cone of lights
    # lost every normal to the cut, a review)
    ill = min(LIGHTS_ILL**2, 0.25 * _check_span(L) ** 2)
    H, W = I.shape[1:]
    given_mask = mask is not None
    if mask is None:
        mask = np.isfinite(I).any(axis=0)
    else:
        mask = np.asarray(mask)
        if mask.shape != (H, W):
            raise ValueError(f"`mask` must have the images' shape {(H, W)}; got {mask.shape}")
        mask = mask.astype(bool)
    # (a string: a bare TypeError)
    if not all(_number(v) for v in (shadow, 0.5 if saturation is None else saturation,
                                    highlight)):
        raise ValueError(f"`shadow`, `saturation` and `highlight` must be numbers; got "
                         f"{shadow!r}, {saturation!r}, {highlight!r}")
    if not (0 <= shadow < (1.0 if saturation is None else saturation) <= 1):
        raise ValueError(f"`shadow` and `saturation` must satisfy 0 <= shadow < saturation "
                         f"<= 1 (saturation None: no cut); got {shadow!r}, {saturation!r}")
    scale = None
    if intensities is not None:
        try:
            E = np.asarray(intensities, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ValueError("`intensities` must be numbers, one per light") from None
        if E.shape != (len(L),) or not (np.isfinite(E).all() and (E > 0).all()):
            raise ValueError(f"`intensities` must be {len(L)} finite numbers > 0, one per "
                             f"light; got {np.shape(intensities)}")
        scale = 1.0 / E
    if not (highlight > 0):
        raise ValueError(f"`highlight` must be > 0; got {highlight!r}")
    if not (_number(dark) and dark >= 0):
        raise ValueError(f"`dark` must be a number >= 0 (0: off); got {dark!r}")
    if not (isinstance(passes, (int, np.integer)) and passes >= 1):
        raise ValueError(f"`passes` must be an integer >= 1; got {passes!r}")
    normals = np.full((H, W, 3), np.nan)
    confidence = np.zeros((H, W))
    flat = I.reshape(len(L), -1)
    pix = np.flatnonzero(mask.ravel())
    if not pix.size:  # (without a mask, the images' finite pixels: none, a review)
        raise ValueError("`mask` is empty: no pixel to fit" if given_mask else
                         "`images` are NaN at every pixel (or have none): no pixel to fit")
    top = _brightness(flat, pix, scale)
    raw_top = top if scale is None else _brightness(flat, pix)
    if not top > 0:  # (all NaN with no word before: integrate then said "no usable normal")
        raise ValueError("`images` hold no positive intensity inside the mask (all dark, or "
                         "negative): nothing to fit; are they the photographs, linear, and the "
                         "mask theirs?")
    LL = (L[:, :, None] * L[:, None, :]).reshape(len(L), 9)  # (each light's l l^T)
    m = pix.size
    n = np.full((m, 3), np.nan)
    res = np.full(m, np.nan)
    spare = np.zeros(m, dtype=int)
    cut = seen = 0  # (observations taken as clipped, of the finite ones)
    for s0 in range(0, m, BLOCK):  # (blocks of pixels: memory bounded at any size)
        sl = slice(s0, s0 + BLOCK)
        n[sl], res[sl], spare[sl], counts = _fit_block(flat[:, pix[sl]], L, LL, top, shadow,
                                                       saturation, highlight, passes, scale,
                                                       raw_top, ill, dark)
        cut, seen = cut + counts[0], seen + counts[1]
    if saturation is not None and cut > CLIPPED_WARN * max(seen, 1):
        # (a flat target under a ring of lights, its values within 2 % of their 99.9th
        # percentile: every normal lost to the cut without a word, an audit)
        warn(f"photometric.fit: the saturation cut took {cut / seen:.0%} of the observations "
             f"as clipped (those at {saturation:g} of the 99.9th percentile or above); if the "
             "images were not clipped at the sensor's top, pass saturation=None")
    ok = np.isfinite(n).all(axis=1)
    checked = ok & (spare > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = max(np.nanmedian(res[checked]) if checked.any() else 0.0, RESIDUAL_FLOOR)
        conf = np.where(spare > 0, 1.0 / (1.0 + (res / (3.0 * ref)) ** 2), UNCHECKED)
    out = normals.reshape(-1, 3)
    out[pix[ok]] = n[ok]
    c = np.zeros(m)
    c[ok] = np.nan_to_num(conf[ok], nan=UNCHECKED)
    confidence.ravel()[pix] = c
    return normals, confidence


#: Share of the finite observations that :func:`fit`'s saturation cut may take as clipped
#: before it warns (a few per cent in images with real highlights; a flat target under a
#: ring of lights, whose values all lie near their 99.9th percentile, lost every one).
CLIPPED_WARN = 0.05

#: Pixels :func:`fit` solves at once (its memory is about 50 bytes per light and pixel of a
#: block, whatever the image size).
BLOCK = 1 << 15

#: Observations from which :func:`fit` takes its brightness reference (the 99.9th
#: percentile): beyond, all the observations of a seeded random subset of the pixels that have
#: a finite one, about this many in all. A DiLiGenT object (96 lights, 50k pixels) has 5M;
#: 96 lights over 1024^2 pixels 100M.
TOP_SAMPLE = 1 << 24


def _brightness(flat: np.ndarray, pix: np.ndarray, scale=None) -> float:
    """The 99.9th percentile of the finite observations `flat` (k, H*W) at pixels `pix`
    (each light's times its `scale`, (k,), where given)
    (where there are more than :data:`TOP_SAMPLE`, of a seeded random subset of the pixels
    with a finite observation: a stride could line up with the image's columns), 0 where
    there is none."""
    k = flat.shape[0]
    if k * pix.size > TOP_SAMPLE:
        has = np.concatenate([np.isfinite(flat[:, pix[s0:s0 + BLOCK]]).any(axis=0)
                              for s0 in range(0, pix.size, BLOCK)])
        pix = pix[has]
        if k * pix.size > TOP_SAMPLE:
            rng = np.random.default_rng(0)
            pix = np.sort(rng.choice(pix, -(-TOP_SAMPLE // k), replace=False))
    obs = np.asarray(flat[:, pix], dtype=float)
    if scale is not None:
        obs *= scale[:, None]
    obs = obs[np.isfinite(obs)]
    return float(np.percentile(obs, 99.9)) if obs.size else 0.0


def _fit_block(obs, L, LL, top, shadow, saturation, highlight, passes, scale=None,
               raw_top=None, ill=LIGHTS_ILL**2, dark=0.0):
    """:func:`fit` on the observations `obs` (k, c) of c pixels (as taken; times `scale`
    (k,) per light where given, after the clipped ones, above `saturation` times `raw_top`,
    are found): (c, 3) unit normals (NaN where none, or where the lights used span the
    directions worse than `ill`: least over largest eigenvalue of their sum l l^T), (c,)
    residuals over the albedo, (c,) observations beyond three, and the counts of the
    observations taken as clipped and of the finite ones."""
    obs = np.asarray(obs, dtype=float)
    finite = np.isfinite(obs)  # (a NaN observation is left out, not its whole pixel)
    obs = np.where(finite, obs, 0.0)
    clipped = (np.zeros(obs.shape, bool) if saturation is None else
               obs >= saturation * (top if raw_top is None else raw_top))
    if scale is not None:
        obs = obs * scale[:, None]
    use = finite & (obs > shadow * top) & ~clipped
    for step in range(passes):
        w = use.astype(float)
        A = (w.T @ LL).reshape(-1, 3, 3)  # (sum of l l^T over the lights used)
        b = (w * obs).T @ L
        ev = np.linalg.eigvalsh(A)  # (ascending; A is symmetric, so this is its condition)
        ok = (use.sum(axis=0) >= 3) & (ev[:, 0] > ill * ev[:, 2])
        G = np.full(b.shape, np.nan)
        G[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
        rho = np.linalg.norm(G, axis=1)
        ok &= rho > 0
        G[~ok] = np.nan
        pred = L @ G.T
        if step + 1 < passes:  # (a highlight: brighter than Lambert predicts)
            with np.errstate(invalid="ignore"):
                use &= ~(obs - pred > highlight * rho)
                if dark:  # (a cast shadow that keeps some light: darker than predicted)
                    use &= ~(pred - obs > dark * rho)
    with np.errstate(invalid="ignore", divide="ignore"):
        spare = use.sum(axis=0) - 3  # (observations beyond the three a normal needs)
        res = np.sqrt(np.einsum("km,km->m", use, np.where(use, pred - obs, 0.0) ** 2)
                      / np.maximum(spare, 1)) / rho
        return (G / rho[:, None], res, spare,
                (int((clipped & finite).sum()), int(finite.sum())))


def _points(gt) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) points in an OpenCV camera frame (x right, y down, z forward; for an
    orthographic scene x = col * pixel_size, y = row * pixel_size) and the (H, W) footprint
    of a pixel at each depth."""
    H, W = gt.mask.shape
    r, c = np.mgrid[0:H, 0:W].astype(float)
    d = gt.depth
    cam = gt.camera
    if gt.K is None:
        h = cam.footprint()
        return np.stack([c * h, r * h, d], axis=-1), np.full((H, W), h)
    return cam.rays(r, c) * d[..., None], d * cam.footprint()


def _project(gt, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of camera-frame points P (..., 3), rounded to pixels."""
    if gt.K is None:
        h = float(gt.pixel_size)
        return np.rint(P[..., 1] / h), np.rint(P[..., 0] / h)
    K = np.asarray(gt.K, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        x, y = P[..., 0] / P[..., 2], P[..., 1] / P[..., 2]
    return np.rint(K[1, 1] * y + K[1, 2]), np.rint(K[0, 0] * x + K[0, 1] * y + K[0, 2])


def _slope(depth: np.ndarray) -> np.ndarray:
    """Per pixel, the depth change per pixel of the surface it lies on: per axis the smaller
    of the two one-sided differences (a jump beside a pixel is not its slope), 0 where
    neither neighbour exists."""
    out = np.zeros(depth.shape)
    for axis in (0, 1):
        d = np.abs(np.diff(depth, axis=axis))
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        before = np.pad(d, pad, constant_values=np.nan)
        pad[axis] = (0, 1)
        after = np.pad(d, pad, constant_values=np.nan)
        with np.errstate(invalid="ignore"):
            s = np.fmin(before, after)
        out += np.nan_to_num(s) ** 2
    return np.sqrt(out)


def _number(v) -> bool:
    """Whether `v` is a real number (not a bool, a string or an array)."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def cast_shadows(gt, lights, *, thickness=None, reach: float = 256.0) -> np.ndarray:
    """(k, H, W) bool: pixels of `gt`'s mask whose point the visible surface hides from each
    light, found by marching from the point toward the light through the ground-truth depth
    map: a point is blocked where the surface seen at its projection lies in front of it by
    more than the depth error of rounding to a pixel and less than `thickness`
    (default: any amount, the visible surface taken as the front of a solid). The march takes
    steps of about one pixel in the image, growing after 16 pixels, up to `reach` pixels."""
    if not all(hasattr(gt, a) for a in ("mask", "depth", "camera")):  # (an AttributeError)
        raise ValueError(f"`gt` must be a facetlift.synthetic.GroundTruth (depth, mask, "
                         f"camera); got {type(gt).__name__}")
    if not (_number(reach) and reach >= 1):  # (below a pixel, or NaN: no shadow at all, an
        # audit)
        raise ValueError(f"`reach` must be a number of pixels >= 1; got {reach!r}")
    if thickness is not None and not (_number(thickness) and thickness > 0):
        raise ValueError(f"`thickness` must be a number > 0 (or None: a solid); got "
                         f"{thickness!r}")
    L = _check_lights(lights, least=1)
    mask = gt.mask
    depth = np.where(mask, gt.depth, np.nan)
    H, W = mask.shape
    X, foot = _points(gt)
    rows, cols = np.nonzero(mask)
    X, foot = X[rows, cols], foot[rows, cols]
    slope = _slope(depth)
    thickness = np.inf if thickness is None else float(thickness)
    pix = np.r_[np.arange(1, 17), 16 * 1.15 ** np.arange(1, 200)]
    pix = pix[pix <= reach]
    out = np.zeros((len(L), H, W), bool)
    for j, (lx, ly, lz) in enumerate(L):
        d_cam = np.array([lx, -ly, -lz])  # (toward the light, in the camera frame)
        lateral = max(np.hypot(lx, ly), 0.05)
        blocked = np.zeros(len(rows), bool)
        for s in pix:
            t = s * foot / lateral
            P = X + t[:, None] * d_cam
            rr, cc = _project(gt, P)
            inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W) & ~blocked
            if not inside.any():
                continue
            ri, ci = rr[inside].astype(int), cc[inside].astype(int)
            seen = depth[ri, ci]
            gap = P[inside, 2] - seen  # (> 0: the surface there is in front of the point)
            # (the rounding to a pixel, and a tenth of a footprint against rounding errors)
            tol = 0.1 * foot[inside] + 0.5 * slope[ri, ci]
            with np.errstate(invalid="ignore"):
                hit = (gap > tol) & (gap < thickness)
            idx = np.flatnonzero(inside)
            blocked[idx[hit]] = True
        out[j, rows, cols] = blocked
    return out


def simulate(gt, lights, rng=None, *, albedo=None, specular: float = 0.2,
             shininess: float = 100.0, noise: float = 0.005, bits: int = 16,
             shadows: bool = True, exposure: float = 0.8) -> np.ndarray:
    """(k, H, W) images of `gt` (a :class:`facetlift.synthetic.GroundTruth`) under distant
    `lights` (k, 3).

    Each pixel: ``albedo * max(0, n.l) + specular * max(0, n.h)^shininess`` (the highlight
    only where ``n.l > 0``; ``h`` halfway between the light and the direction to the camera),
    0 where the point is in a cast shadow (:func:`cast_shadows`, with `shadows`); scaled so
    that the 99.9th percentile of the diffuse part over the mask and lights is `exposure`,
    Gaussian noise of standard deviation `noise` added, clipped to [0, 1] (highlights
    saturate) and quantised to `bits` bits (0: not quantised). 0 outside the mask.

    Parameters
    ----------
    albedo : (H, W) array_like, optional
        Default: a smooth random texture in [0.4, 1] (drawn from `rng`).
    """
    from scipy.ndimage import gaussian_filter

    if not hasattr(gt, "mask") or not hasattr(gt, "normals"):  # (an AttributeError, an audit)
        raise ValueError(f"`gt` must be a facetlift.synthetic.GroundTruth (normals, depth, "
                         f"mask, camera: e.g. synthetic.analytic or render_perspective); got "
                         f"{type(gt).__name__}")
    L = _check_lights(lights, least=1)
    if not (np.isfinite(specular) and specular >= 0 and np.isfinite(shininess)
            and shininess > 0):
        raise ValueError(f"`specular` must be >= 0 and `shininess` > 0; got {specular!r}, "
                         f"{shininess!r}")
    if not (_number(noise) and np.isfinite(noise) and noise >= 0):  # (a string: numpy's
        # TypeError, an audit)
        raise ValueError(f"`noise` must be a finite number >= 0; got {noise!r}")
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 32):
        raise ValueError(f"`bits` must be an integer in [0, 32]; got {bits!r}")
    if not (np.isfinite(exposure) and exposure > 0):
        raise ValueError(f"`exposure` must be > 0; got {exposure!r}")
    rng = np.random.default_rng(rng)
    mask = gt.mask
    H, W = mask.shape
    if albedo is None:
        tex = gaussian_filter(rng.random((H, W)), 6.0)
        inside = tex[mask]
        lo, hi = (inside.min(), inside.max()) if inside.size else (0.0, 1.0)
        albedo = 0.4 + 0.6 * (tex - lo) / max(hi - lo, 1e-12)
    else:
        albedo = np.asarray(albedo, dtype=float)
        if albedo.shape != (H, W):
            raise ValueError(f"`albedo` must have the mask's shape {(H, W)}; got "
                             f"{albedo.shape}")
        if not (np.isfinite(albedo[mask]).all() and (albedo[mask] >= 0).all()):
            raise ValueError("`albedo` must be finite and >= 0 inside the mask (NaN made "
                             "every image NaN, an audit)")
    n = gt.normals[mask]
    a = albedo[mask]
    if gt.K is None:
        v = np.broadcast_to([0.0, 0.0, 1.0], n.shape)
    else:
        p = _points(gt)[0][mask]
        v = np.stack([-p[:, 0], p[:, 1], p[:, 2]], axis=1)  # (to the camera, our frame)
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
    blocked = cast_shadows(gt, L)[:, mask] if shadows else np.zeros((len(L), len(n)), bool)
    diffuse = np.clip(n @ L.T, 0.0, None).T * a  # (k, m)
    hv = L[:, None, :] + v[None]
    hv /= np.linalg.norm(hv, axis=2, keepdims=True)
    spec = specular * np.clip(np.einsum("kmi,mi->km", hv, n), 0.0, None) ** shininess
    lit = (diffuse > 0) & ~blocked
    shade = np.where(lit, diffuse + spec, 0.0)
    scale = exposure / max(np.percentile(np.where(blocked, 0.0, diffuse), 99.9), 1e-12)
    shade = shade * scale + noise * rng.normal(size=shade.shape)
    shade = np.clip(shade, 0.0, 1.0)
    if bits:
        levels = 2.0 ** bits - 1
        shade = np.rint(shade * levels) / levels
    out = np.zeros((len(L), H, W))
    out[:, mask] = shade
    return out
