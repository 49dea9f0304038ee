"""A prior known only up to scale and shift, aligned to the normals (``prior_fit``).

Monocular depth networks give relative depth: affine-invariant depth (Marigold, DPT's
relative models: ``depth = a * P + b`` with unknown ``a > 0`` and ``b``) or affine-invariant
disparity (MiDaS, Depth Anything's relative models: ``1 / depth = a * P + b``). Fused as they
are, they pull the surface toward the wrong depths; fitted to the normals-only result over the
whole mask (the recipe before this module), the fit inherits that result's guesses where the
normals cannot decide: the offsets of pieces that a depth jump or a gap in the mask separates,
which are exactly what the prior should decide.

So the fit here uses only what the normals know, the surface's local shape. First the
differences between samples :data:`PAIR_DISTANCE` pixels apart in one connected piece of the
normals-only surface, with no cut between them (:func:`_by_pairs`): orthographic, ``P_j -
P_i = alpha (z_j - z_i)``; pinhole (the normals give ``log z`` up to a constant),
``P_j - P_i = (m + c) (log z_j - log z_i)`` for an affine depth ``z = a (P + c)``, ``m``
the pair's mean, and the like for a disparity. Neither the pieces' offsets nor the level of a
region that a jump the normals-only surface did not cut misplaced enter. Where that leaves
the scale undetermined (:data:`SE_MAX`), the shape within each piece with a free constant per
piece (orthographic ``P = alpha z + gamma_k``; pinhole ``P = s_k z + beta``); else the prior
is left out, with a warning. The remaining constant
(``a`` for a pinhole camera, the offset orthographically) makes the main piece (the one with
most of the prior's weight) agree with the normals-only surface in the median: a perspective
result keeps that surface's scale (median depth near 1; the prior has none to give), an
orthographic one its level. Every other piece is then placed by the aligned prior in the
second solve (:func:`facetlift.integrate` runs the route twice). Every fit is a Huber
regression (:data:`HUBER`, :data:`ROUNDS`: a network's errors at silhouettes, where it blends
foreground and background, do not tilt it) whose relative standard error comes from a
jackknife over image tiles (:data:`TILE`). The normals-only surface is compared through the
blur that the prior seems to have been seen through (:func:`_prior_blur`): a coarse prior's
differences are smaller than a sharp surface's, which made its scale 1.5-3x too large.
"""

from __future__ import annotations

import numpy as np

#: The values of ``prior_fit``.
KINDS = ("none", "scale", "affine", "disparity")

#: Pieces with fewer prior samples than this have no say in the fit (their constant would
#: absorb every sample) and are placed by the aligned prior alone.
MIN_SAMPLES = 3

#: Huber threshold in robust standard deviations (1.4826 MAD) of the fit's residuals, and the
#: reweighting rounds.
HUBER, ROUNDS = 1.345, 8

#: Side in pixels of the tiles whose jackknife gives the fitted scale's standard error (a
#: dense prior's residuals are correlated over its blur: an error from independent samples was
#: 10-100x too small), and at least this many blur sigmas.
TILE, TILE_BLURS = 16, 2.0

#: Distance in pixels of the pairs of samples whose differences give the scale
#: (:func:`_by_pairs`). On the benchmark's coarse priors (blurred, 63 scenes) 2, 4 and 8 were
#: alike (46, 46 and 45 scenes within 5 % of the true offset; median error 0.75 %, 0.93 %,
#: 0.71 %), 16 worse (43; pairs lost to cuts): docs/fusion.md.
PAIR_DISTANCE = 2

#: The largest relative standard error of the scale that a fit may leave; above it the next
#: fit is tried (pairs, then pieces), and the prior is left out, with a warning, where none
#: is determined.
SE_MAX = 0.1

#: A within-piece correlation between the prior and the normals-only depth at or below this
#: (with no scale determined) names the prior as running against the normals in the warning.
AGAINST = -0.5

#: Blurred, samples within this many blur sigmas of a cut or of a border between
#: pieces are not compared (the blur mixes the pieces' offsets there, which the normals-only
#: surface only guessed: a review's three parts came out 2.17 apart, at a scale 12 % off),
#: halved until a quarter of the samples are left (an object cut in many places).
BORDER_BLURS, BORDER_KEEP = 2.0, 0.25

#: Blurs (sigma, pixels) tried for the comparison, besides the ``prior_blur`` given: the one
#: whose local differences agree with the prior's at two distances is used
#: (:func:`_prior_blur`).
BLUR_CANDIDATES = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0)

#: The second distance of :func:`_prior_blur`'s check, and how much closer (in the log of the
#: two fits' relief ratio) another blur must bring them to replace the ``prior_blur`` given.
CHECK_DISTANCE, BLUR_BETTER = 8, 0.02

#: :func:`_prior_blur` compares the blurs on about this many pairs at most: the pairs whose
#: first pixel lies in a seeded random sample of the samples, the same for every blur and both
#: distances; the blur chosen is then fitted on all pairs. A dense 1280 x 720 prior has about
#: 1.5 M pairs, and the 12 comparisons on all of them took 7-16 s of the fit
#: (docs/fusion.md, "A monocular depth map").
BLUR_PAIRS = 200_000

#: Compare the prior with the normals-only surface blurred (:func:`_prior_blur`); False
#: compares them as they are (for measurements).
MATCH_BLUR = True


def check(value, has_prior: bool, perspective: bool) -> str:
    """`value` of ``prior_fit`` checked: one of :data:`KINDS` (None is "none")."""
    if value is None:
        return "none"
    if not isinstance(value, str) or value not in KINDS:
        raise ValueError(f"`prior_fit` must be one of {KINDS}; got {value!r}")
    if value == "none":
        return value
    if not has_prior:
        raise ValueError(f"`prior_fit`={value!r} needs a `prior` (the depth to align)")
    if value == "disparity" and not perspective:
        raise ValueError("`prior_fit`='disparity' needs a pinhole camera (`K`): an "
                         "orthographic depth has no zero that 1 / depth could refer to")
    return value


def pieces(surface) -> np.ndarray:
    """(H, W) int: the connected piece of every mask pixel of `surface` (-1 outside): facets
    sharing a corner vertex (of the split mesh where the surface is cut at jumps);
    :meth:`facetlift.Surface.pieces`."""
    return surface.pieces()


def fit(prior_img: np.ndarray, weight, surface, kind: str, perspective: bool,
        blur: float = 0.0):
    """The prior aligned to `surface` (normals only): ``(aligned (H, W) or None, details)``.

    `prior_img` (H, W) raw prior values, NaN where unknown; `weight` a scalar or (H, W) map
    (the prior's weights, which weigh the fit too); `blur` the ``prior_blur`` sigma (pixels):
    the prior is fitted to the surface blurred as it seems to be (:func:`_prior_blur`, which
    keeps `blur` unless another agrees clearly better; :class:`~facetlift.operators.blur.
    PlaneBlur`), away from cuts (:data:`BORDER_BLURS`). The fits,
    in turn until one determines the scale (:data:`SE_MAX`): differences of samples
    :data:`PAIR_DISTANCE` pixels apart in one piece (:func:`_by_pairs`), then the pieces'
    shapes with a free constant each. `aligned` is None where neither
    does (the caller returns the normals-only surface). `details` (for
    ``info["prior"]["fit"]``): ``kind``, ``used``, ``method`` ("pairs", "pieces"),
    ``scale`` and ``shift`` (depth = scale * P + shift; for "disparity" 1 / depth = scale * P +
    shift), ``samples``, ``scale_error`` (relative standard error of the scale, by a jackknife
    over tiles), ``down_weighted`` (samples the Huber weights reduced below one half),
    ``correlation`` (of the prior with the normals-only depth within the pieces), ``blur``
    (the one compared through) and ``dropped`` (samples whose aligned depth was not
    positive, perspective only). A prior
    that no fit aligns is left out with a warning (a poor prior never refuses the job).
    Raises ValueError naming `prior` where too few samples lie on the surface.
    """
    from ._warnings import warn

    z = surface.depth
    lab = pieces(surface)
    w_img = np.broadcast_to(np.asarray(weight, float), prior_img.shape)
    ok = np.isfinite(prior_img) & (lab >= 0) & np.isfinite(z) & (w_img > 0)
    if perspective:
        ok &= z > 0
    if MATCH_BLUR:
        blur, z = _prior_blur(prior_img, z, surface, lab, _away(surface, lab, ok, blur), blur,
                              kind, perspective, w_img, TILE)
        if blur > 0:
            ok = _away(surface, lab, ok & np.isfinite(z), blur)
    if ok.sum() < 2 * MIN_SAMPLES:
        raise ValueError(f"`prior` with prior_fit={kind!r}: only {int(ok.sum())} sample(s) "
                         f"with a weight > 0 lie on the surface; at least {2 * MIN_SAMPLES} "
                         "are needed to fit its scale")
    lo, hi = np.percentile(prior_img[ok], [5, 95])
    if not hi - lo > 1e-9 * max(abs(lo), abs(hi)):
        warn(f"`prior` with prior_fit={kind!r} was left out, the surface is the normals-only "
             f"one: it is constant over the surface ({lo:.6g}), with no scale to fit")
        return None, {"kind": kind, "used": False, "samples": int(ok.sum())}
    rows, cols = np.nonzero(ok)
    side = max(TILE, int(np.ceil(TILE_BLURS * blur)))
    tw = -(-ok.shape[1] // side)
    tile = (rows // side) * tw + cols // side
    _, tile = np.unique(tile, return_inverse=True)
    y = prior_img[ok].astype(float)
    om = w_img[ok].astype(float)
    om = om / om.mean()
    x = 1.0 / z[ok] if kind == "disparity" else z[ok].astype(float)
    k = lab[ok]
    per_offset = not perspective  # (orthographic: a constant per piece; pinhole: a scale)
    model = ("offset" if per_offset else ("scale" if kind == "scale" else "slope"))
    errors = {}
    got = _by_pairs(np.where(ok, prior_img, np.nan), z, surface, lab, kind, perspective,
                    w_img, side, PAIR_DISTANCE)
    errors["pairs"] = None if got is None else got["error"]
    method = "pairs"
    corr = None
    if not _determined(got, SE_MAX):
        method = "pieces"
        got = None
        big = np.bincount(k)[k] >= MIN_SAMPLES
        if big.sum() >= 2 * MIN_SAMPLES:
            _, kk = np.unique(k[big], return_inverse=True)
            # (a rounded level: the error's deviation is the step / sqrt 12)
            levels = np.unique(y[big])
            r = _robust(x[big], y[big], kk, tile[big], om[big], model,
                        floor=_quantum(np.diff(levels)) / np.sqrt(12.0) if levels.size > 1
                        else 0.0)
            corr = _within_correlation(x[big], y[big], kk, om[big] * r["rob"])
            if r["theta"] != 0:
                scale = 1.0 / r["theta"]
                shift = 0.0 if model == "scale" or kind == "scale" else (
                    -r["each"][r["main"]] * scale if per_offset else -r["common"] * scale)
                got = {"scale": scale, "shift": shift, "error": r["error"],
                       "samples": int(big.sum()), "down": int((r["rob"] < 0.5).sum())}
        errors["pieces"] = None if got is None else got["error"]
    if not _determined(got, SE_MAX):
        # (a fit of the whole surface on the prior, the manual recipe, gained nothing on the
        # benchmark and took a scale 50x off as determined: a fresh check)
        tried = ", ".join(f"{m} {_fmt(e)}" for m, e in errors.items())
        if corr is None:
            corr = _within_correlation(x, y, k, om)
        why = (f"it runs against the normals (correlation {corr:.2f} with the normals-only "
               "depth within its pieces): " + _against_hint(kind, perspective)
               if corr is not None and corr <= AGAINST else
               f"no fit determines its scale (relative errors: {tried}): a flat view, "
               "parallel planes, or a prior unlike the normals' surface")
        warn(f"`prior` with prior_fit={kind!r} was left out, the surface is the normals-only "
             f"one: {why}")
        return None, {"kind": kind, "used": False, "correlation": _num(corr),
                      "errors": {m: _num(e) for m, e in errors.items()}, "samples": int(y.size)}
    scale, shift = got["scale"], got["shift"]
    if not perspective and kind == "scale":
        shift = 0.0  # (the prior's zero is depth zero)
    lin = scale * prior_img + shift
    aligned = 1.0 / lin if kind == "disparity" else lin
    dropped = 0
    if perspective:
        bad = np.isfinite(prior_img) & ~(np.isfinite(aligned) & (aligned > 0))
        dropped = int((bad & (lab >= 0)).sum())
        aligned = np.where(bad, np.nan, aligned)
        if dropped:
            warn(f"`prior` with prior_fit={kind!r}: {dropped} sample(s) on the mask give a depth "
                 f"<= 0 once aligned (scale {scale:.4g}, shift {shift:.4g}) and were left out")
    details = {"kind": kind, "used": True, "method": method, "scale": float(scale),
               "shift": float(shift), "scale_error": float(got["error"]),
               "samples": got["samples"], "down_weighted": got["down"],
               "correlation": _num(corr), "dropped": dropped, "blur": float(blur)}
    return aligned, details


def _determined(got, limit) -> bool:
    return got is not None and got["scale"] > 0 and got["error"] <= limit


def _cut_counts(surface):
    """``(along_rows, along_columns)``, each (H, W): the cut edges of `surface` from the
    row's (the column's) first pixel to each pixel, whose difference counts the cuts between
    two pixels of a row (a column); ``(None, None)`` without cuts."""
    if surface.cuts is None:
        return None, None
    return (np.cumsum(np.pad(surface.cuts[0], ((0, 0), (1, 0))), axis=1),
            np.cumsum(np.pad(surface.cuts[1], ((1, 0), (0, 0))), axis=0))


def _pairs(ok, lab, surface, distance):
    """Flat indices (i, j) of the pairs of pixels `distance` apart along a row or a column,
    both `ok`, in one piece of `lab` and with no cut edge of `surface` between them."""
    H, W = ok.shape
    cut_r, cut_d = _cut_counts(surface)
    flat = np.arange(H * W).reshape(H, W)
    ii, jj = [], []
    d = int(distance)
    for axis in (0, 1):
        if (W if axis == 1 else H) <= d:
            continue
        a = (slice(None), slice(0, W - d)) if axis == 1 else (slice(0, H - d), slice(None))
        b = (slice(None), slice(d, W)) if axis == 1 else (slice(d, H), slice(None))
        pair = ok[a] & ok[b] & (lab[a] == lab[b])
        if cut_r is not None:
            cs = cut_r if axis == 1 else cut_d
            pair &= (cs[b] - cs[a]) == 0
        ii.append(flat[a][pair])
        jj.append(flat[b][pair])
    if not ii:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(ii), np.concatenate(jj)


#: Where too few samples lie :data:`PAIR_DISTANCE` apart (sparse points), each sample is paired
#: with its SPARSE_NEIGHBOURS nearest ones in the same piece, within SPARSE_REACH times the
#: median nearest-neighbour distance (:func:`_nearest_pairs`): the pieces' fit, which came
#: next, compares whole pieces of a surface that jumps the normals do not show bend (an
#: audit: 1 % exact samples of the analytic occluder and steps gave a scale 22-24 % off with
#: a jackknife error of 2-8 %).
SPARSE_PAIRS, SPARSE_NEIGHBOURS, SPARSE_REACH = True, 3, 3.0


def _nearest_pairs(ok, lab, surface):
    """Flat indices (i, j) of each `ok` pixel and its :data:`SPARSE_NEIGHBOURS` nearest `ok`
    pixels in the same piece of `lab`, within :data:`SPARSE_REACH` median nearest-neighbour
    distances, with no cut edge of `surface` on one of the two paths between them along a
    row and a column, each pair once."""
    from scipy.spatial import cKDTree

    r, c = np.nonzero(ok)
    if r.size < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pts = np.column_stack([r, c]).astype(float)
    k = min(SPARSE_NEIGHBOURS + 1, r.size)
    dist, nb = cKDTree(pts).query(pts, k=k)
    reach = SPARSE_REACH * float(np.median(dist[:, 1]))
    a = np.repeat(np.arange(r.size), k - 1)
    b, d = nb[:, 1:].ravel(), dist[:, 1:].ravel()
    keep = (d <= reach) & (lab[r[a], c[a]] == lab[r[b], c[b]])
    # (each pair once, listed by either side: the sorted unique index pairs)
    ij = np.unique(np.sort(np.column_stack([a[keep], b[keep]]), axis=1), axis=0)
    if ij.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cr, cd = _cut_counts(surface)
    if cr is not None:  # (no cut on the row-then-column or column-then-row path)
        r1, c1, r2, c2 = r[ij[:, 0]], c[ij[:, 0]], r[ij[:, 1]], c[ij[:, 1]]
        along_row1, along_row2 = cr[r1, c2] != cr[r1, c1], cr[r2, c2] != cr[r2, c1]
        along_col1, along_col2 = cd[r2, c1] != cd[r1, c1], cd[r2, c2] != cd[r1, c2]
        ij = ij[~(along_row1 | along_col2) | ~(along_col1 | along_row2)]
    flat = r * ok.shape[1] + c
    return flat[ij[:, 0]], flat[ij[:, 1]]


def _by_pairs(prior_img, z, surface, lab, kind, perspective, w_img, side, distance,
              error: bool = True, sample=None):
    """The scale from differences between samples `distance` pixels apart in one piece, with
    no cut between them (:func:`_pairs`): the normals-only surface enters only through such
    local differences, so neither the pieces' offsets nor a sub-region's level that a jump it
    did not cut misplaced (a partial cut) do. Orthographic: ``P_j - P_i = alpha (z_j -
    z_i)``; pinhole (``u = log z``): ``P_j - P_i = (m + c) (u_j - u_i)`` for an affine depth
    ``z = a (P + c)``, ``D_j - D_i = -(m + c) (u_j - u_i)`` for a disparity ``1 / z = a (D +
    c)``, ``m`` the pair's mean prior; then ``a`` so that the main piece agrees with `surface`
    in the median (:func:`_levels`). Returns a dict (``scale``, ``shift``, ``error``,
    ``samples``, ``down``) or None. `error`: with the jackknife's relative standard error
    (else inf). `sample`: a flat bool over the pixels, the pairs whose first pixel it holds
    are fitted (all of them where that leaves too few; :data:`BLUR_PAIRS`)."""
    if perspective and kind == "scale":
        return None
    W = prior_img.shape[1]
    ok = np.isfinite(prior_img) & np.isfinite(z) & (lab >= 0) & (w_img > 0)
    if perspective:
        ok &= z > 0
    u = (np.log(np.where(ok, z, 1.0)) if perspective else z).ravel()
    i, j = _pairs(ok, lab, surface, distance)
    if i.size < 6 * MIN_SAMPLES and SPARSE_PAIRS:  # (sparse samples: their nearest ones)
        i, j = _nearest_pairs(ok, lab, surface)
    if i.size < 6 * MIN_SAMPLES:
        return None
    if sample is not None:
        keep = sample[i]
        if keep.sum() >= 6 * MIN_SAMPLES:
            i, j = i[keep], j[keep]
    P = prior_img.ravel()
    dP, du, m = P[j] - P[i], u[j] - u[i], 0.5 * (P[i] + P[j])
    wv = np.minimum(w_img.ravel()[i], w_img.ravel()[j])
    wv = wv / wv.mean()
    tv = None
    if error:  # (the tiles of the jackknife)
        tw = -(-W // side)
        _, tv = np.unique((i // W // side) * tw + (i % W) // side, return_inverse=True)
    if perspective:
        sign = -1.0 if kind == "disparity" else 1.0
        yv, xv = dP - sign * m * du, sign * du  # = c * xv
    else:
        yv, xv = dP, du  # = alpha * xv
    # (a difference of two levels rounded each: the error's deviation is the step / sqrt 6)
    rfit = _robust(xv, yv, np.zeros(yv.size, dtype=np.int64), tv, wv, "scale", error=error,
                   quick=not error, floor=_quantum(dP) / np.sqrt(6.0))
    return _levels(rfit["theta"], rfit, prior_img, surface, lab, kind, perspective, ok, i.size)


def _prior_blur(prior_img, z, surface, lab, ok, given, kind, perspective, w_img, side):
    """The blur (sigma, pixels) of the normals-only surface `z` whose local differences agree
    with the prior's at two distances (:data:`PAIR_DISTANCE` and :data:`CHECK_DISTANCE`): a
    surface sharper than the prior makes the near differences too large against the prior's,
    more than the far ones, so the two fits' scales part; the blur where they agree best,
    over :data:`BLUR_CANDIDATES` and the `given` ``prior_blur`` (kept unless another agrees
    better by :data:`BLUR_BETTER`). A coarse prior given pixel by pixel came out 1.5-3x off
    on the benchmark (docs/fusion.md). A dense prior's blurs are compared on a sample of its
    pairs (:data:`BLUR_PAIRS`). Returns ``(sigma, z blurred by it)``."""
    from .operators.blur import PlaneBlur

    if perspective and kind == "scale":  # (no fit by pairs to compare the blurs through:
        # the `given` one, without the five blurs that decided nothing)
        return given, (z if given == 0 else
                       PlaneBlur(surface.mask, given)(np.where(surface.mask, z, 0.0)))
    P = np.where(ok, prior_img, np.nan)
    lo, mid, hi = np.nanpercentile(P, [5, 50, 95])
    # (a dense prior's blurs compared on a sample of its pairs: each sample has at most two
    # partners at a distance, one along its row and one along its column)
    n = int(ok.sum())
    sample = (None if 2 * n <= BLUR_PAIRS else
              np.random.default_rng(0).random(ok.size) < BLUR_PAIRS / (2 * n))
    found, blurred = {}, {}
    longest = max(surface.mask.shape) / 8
    for sigma in sorted({*BLUR_CANDIDATES, given}):
        if sigma > longest and sigma != given:
            continue
        zs = z if sigma == 0 else PlaneBlur(surface.mask, sigma)(np.where(surface.mask, z, 0.0))
        blurred[sigma] = zs
        reliefs = []
        for d in (PAIR_DISTANCE, CHECK_DISTANCE):
            got = _by_pairs(P, zs, surface, lab, kind, perspective, w_img, side, d,
                            error=False, sample=sample)
            if got is None or not got["scale"] > 0:
                break
            a, b = got["scale"], got["shift"]
            if perspective:  # (the aligned prior's relief relative to its depth)
                q = [a * v + b for v in (lo, mid, hi)]
                if kind == "disparity":
                    q = [1.0 / v if v > 0 else np.nan for v in q]
                reliefs.append(abs(q[2] - q[0]) / q[1] if q[1] > 0 else np.nan)
            else:
                reliefs.append(a)
        if len(reliefs) == 2 and np.isfinite(reliefs).all() and min(reliefs) > 0:
            found[sigma] = abs(np.log(reliefs[0] / reliefs[1]))
    best = min(found, key=found.get) if found else given
    if best != given and not found[best] < found.get(given, np.inf) - BLUR_BETTER:
        best = given  # (the given blur unless another agrees clearly better)
    return best, blurred[best]


#: The share of the main piece's aligned prior (pinhole: ``P + c``) that must be positive
#: for a pair fit to stand (:func:`_levels`). 0.99 until 2026-12-07: 2 % of samples set to an
#: invalid marker (-1) threw a right fit (c within 0.04 % of the truth) away for the pieces'
#: fallback, 6-8x the error (a review).
UNIT_POSITIVE = 0.95


def _levels(coef, rfit, prior_img, surface, lab, kind, perspective, ok, samples):
    """(scale, shift) from a fitted `coef` (pinhole: the prior's offset ``c``; orthographic:
    ``alpha``), placed so that the main piece agrees with `surface` in the median: a dict as
    :func:`_by_pairs`' or None where the fit is degenerate."""
    P = np.where(ok, prior_img, np.nan)
    main_lab = np.argmax(np.bincount(lab[np.isfinite(P) & (lab >= 0)]))
    on = (lab == main_lab) & np.isfinite(P) & np.isfinite(surface.depth)
    z0 = surface.depth[on]
    error = rfit["error"]
    if perspective:
        unit = P[on] + coef  # proportional to z (affine) or to 1 / z (disparity)
        mid = float(np.median(unit)) if unit.size else 0.0
        if not (mid > 1e-9 * float(np.max(np.abs(P[on]))) and np.mean(unit > 0) >= UNIT_POSITIVE):
            return None
        error = rfit["error"] * abs(coef) / mid
        ratio = (1.0 / z0) / unit if kind == "disparity" else z0 / unit
        lam = float(np.median(ratio[unit > 0]))
        scale, shift = lam, lam * coef
    else:
        if not coef != 0:
            return None
        scale = 1.0 / coef
        shift = 0.0 if kind == "scale" else float(np.median(z0 - scale * P[on]))
    return {"scale": scale, "shift": shift, "error": error, "samples": int(samples),
            "down": int((rfit["rob"] < 0.5).sum())}


def _away(surface, lab, ok, blur: float) -> np.ndarray:
    """`ok` without the samples within :data:`BORDER_BLURS` `blur` sigmas of a cut or of a
    border between pieces, where a blur mixes the pieces' offsets, which the normals-only
    surface only guessed (and the prior knows); the radius halved until :data:`BORDER_KEEP`
    of the samples are left."""
    radius = BORDER_BLURS * blur
    while radius >= 1.0:
        far = ok & ~_near_borders(surface, lab, radius)
        if far.sum() >= max(BORDER_KEEP * ok.sum(), 2 * MIN_SAMPLES):
            return far
        radius /= 2.0
    return ok


def _near_borders(surface, lab: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) bool: pixels within `radius` of a cut edge of `surface` or of an edge between
    two of its pieces `lab`."""
    from scipy import ndimage

    H, W = lab.shape
    edge_r = (lab[:, :-1] != lab[:, 1:]) & (lab[:, :-1] >= 0) & (lab[:, 1:] >= 0)
    edge_d = (lab[:-1] != lab[1:]) & (lab[:-1] >= 0) & (lab[1:] >= 0)
    if surface.cuts is not None:
        edge_r = edge_r | surface.cuts[0]
        edge_d = edge_d | surface.cuts[1]
    border = np.zeros((H, W), bool)
    border[:, :-1] |= edge_r
    border[:, 1:] |= edge_r
    border[:-1] |= edge_d
    border[1:] |= edge_d
    if not border.any():
        return border
    return ndimage.distance_transform_edt(~border) < radius


def _fmt(v) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v:.2g}"


def _num(v):
    return None if v is None or not np.isfinite(v) else float(v)


def _quantum(d: np.ndarray) -> float:
    """The step of the lattice the differences `d` lie on (a prior of coarse depth levels: a
    network's 8-bit map, a sensor's whole millimetres), or 0 where they lie on none: the
    smallest nonzero ``|d|`` where at least 90 % of them are whole multiples of it."""
    a = np.abs(d[np.isfinite(d)])
    pos = a[a > 0]
    if pos.size < 10:
        return 0.0
    q = float(pos.min())
    r = a / q
    return q if float(np.mean(np.abs(r - np.round(r)) <= 1e-3)) >= 0.9 else 0.0


def _robust(x, y, k, tile, om, model, error: bool = True, quick: bool = False,
            floor: float = 0.0):
    """The piece model `model` fitted to ``y`` on ``x`` with Huber weights: a dict of
    ``theta`` (the scale parameter: ``alpha`` of "offset" ``y = alpha x + gamma_k``, the main
    piece's ``s`` of "slope" ``y = s_k x + beta`` and "scale" ``y = s_k x``), ``common``,
    ``each`` (K,), ``main``, ``error`` (theta's relative standard error, a jackknife over the
    tiles `tile`: each tile left out in turn) and ``rob`` (Huber weights). `quick`: one
    group's sums by :func:`_moments`' quicker path (:func:`_prior_blur`'s comparisons; the
    fits reported keep the bincounts' arithmetic, the same numbers to the last bit).
    `floor`: the least robust standard deviation, the rounding error of a prior of coarse
    depth levels (:func:`_quantum`): without it most pairs of such a prior differ by exactly
    0, their residuals set the deviation, every pair across a level's step was weighed down
    as an outlier and the scale ran away round by round (32 levels over the analytic steps:
    224x the true scale, still reported as determined; a review)."""
    K = int(k.max()) + 1
    main = int(np.argmax(np.bincount(k, weights=om, minlength=K)))
    rob = np.ones_like(om)
    for _ in range(ROUNDS + 1):
        common, each = _params(_moments(x, y, k, om * rob, K, quick), model)
        ek = each[0] if K == 1 else each[k]  # (one group: no gather)
        res = y - (common * x + ek if model == "offset" else ek * x + common)
        ares = np.abs(res, out=res)
        sigma = max(1.4826 * float(np.median(ares)), floor)
        if not sigma > 0:
            break
        new = np.minimum(1.0, HUBER * sigma / np.maximum(ares, 1e-300, out=ares))
        done = bool(np.all(np.abs(new - rob) <= 1e-3 + 1e-5 * rob))  # (np.allclose's test)
        rob = new
        if done:
            break
    w = om * rob
    Mk = _moments(x, y, k, w, K, quick)
    common, each = _params(Mk, model)
    theta = common if model == "offset" else each[main]
    return {"theta": float(theta), "common": float(common), "each": each, "main": main,
            "error": _jackknife(x, y, k, tile, w, Mk, model, main, theta) if error else np.inf,
            "rob": rob}


def _jackknife(x, y, k, tile, w, Mk, model, main, theta) -> float:
    """Relative standard error of `theta` with each tile left out in turn. Only the pieces a
    tile holds change when it is left out, so the sums are formed per (piece, tile) group:
    memory in the samples, not in pieces times tiles."""
    T = int(tile.max()) + 1
    key = k.astype(np.int64) * T + tile
    ug, g = np.unique(key, return_inverse=True)
    gk, gt = ug // T, ug % T
    present = np.unique(gt)
    if present.size < 3 or theta == 0:
        return np.inf
    Mg = _moments(x, y, g, w, ug.size)
    rest = Mk[:, gk] - Mg  # each group's piece without that tile
    if model == "scale":
        common_t = np.zeros(T)
    else:
        A, B = _terms(Mk, model)
        Ag, Bg = _terms(Mk[:, gk], model)
        Ar, Br = _terms(rest, model)
        dA = np.bincount(gt, weights=Ag - Ar, minlength=T)
        dB = np.bincount(gt, weights=Bg - Br, minlength=T)
        with np.errstate(divide="ignore", invalid="ignore"):
            common_t = (A.sum() - dA) / (B.sum() - dB)
    if model == "offset":
        th = common_t[present]
    else:  # the main piece's slope without each tile
        Mm = np.repeat(Mk[:, main][:, None], T, axis=1)
        on = gk == main
        Mm[:, gt[on]] -= Mg[:, on]
        S1, Sx, Sy, Sxx, Sxy = Mm
        with np.errstate(divide="ignore", invalid="ignore"):
            th = ((Sxy - common_t * Sx) / Sxx)[present]
    if not np.isfinite(th).all():
        return np.inf
    n = th.size
    return float(np.sqrt((n - 1) / n * np.sum((th - th.mean()) ** 2)) / abs(theta))


def _moments(x, y, k, w, K, quick: bool = False):
    """(5, K): the weighted sums 1, x, y, x x, x y per group `k`. `quick` with one group: by
    einsum, 3-8x faster than bincounts, equal up to rounding."""
    if quick and K == 1:  # (without BLAS too, whose threads made a dot product of 2e5
        # take 8 ms on a busy 2-core machine)
        return np.array([[w.sum()]] + [[np.einsum(s, *v)] for s, v in (
            ("i,i->", (w, x)), ("i,i->", (w, y)), ("i,i,i->", (w, x, x)),
            ("i,i,i->", (w, x, y)))])
    return np.stack([np.bincount(k, weights=v, minlength=K)
                     for v in (w, w * x, w * y, w * x * x, w * x * y)])


def _terms(M, model):
    """Per piece, the numerator and denominator terms (each (K, ...)) whose sums over the
    pieces give the common parameter: "offset" alpha, "slope" beta (0 where a piece holds
    no weight)."""
    S1, Sx, Sy, Sxx, Sxy = M
    if model == "offset":
        d = np.where(S1 > 0, S1, 1.0)
        return Sxy - Sx * Sy / d, Sxx - Sx * Sx / d
    d = np.where(Sxx > 0, Sxx, 1.0)
    return Sy - Sx * Sxy / d, S1 - Sx * Sx / d


def _params(M, model):
    """(common, each (K,)) of the weighted least squares fit from the moments `M` (5, K),
    the per-piece constants eliminated in closed form. "offset" ``y = alpha x + gamma_k``:
    (alpha, gamma); "slope" ``y = s_k x + beta``: (beta, s); "scale" ``y = s_k x``: (0, s).
    Pieces without a sample (zero weight) give NaN in `each`."""
    S1, Sx, Sy, Sxx, Sxy = M
    with np.errstate(divide="ignore", invalid="ignore"):
        if model == "scale":
            return 0.0, Sxy / Sxx
        A, B = _terms(M, model)
        common = float(A.sum() / B.sum()) if B.sum() > 0 else 0.0
        if model == "offset":
            return common, (Sy - common * Sx) / S1
        return common, (Sxy - common * Sx) / Sxx


def _within_correlation(x, y, k, w) -> float | None:
    """The weighted correlation of `x` and `y` after each piece's mean is taken out."""
    S1 = np.bincount(k, weights=w)
    mx = np.bincount(k, weights=w * x) / S1
    my = np.bincount(k, weights=w * y) / S1
    dx, dy = x - mx[k], y - my[k]
    den = float(np.sqrt(np.sum(w * dx * dx) * np.sum(w * dy * dy)))
    return float(np.sum(w * dx * dy)) / den if den > 0 else None


def _against_hint(kind: str, perspective: bool = True) -> str:
    # (without a camera a disparity is no choice, prior_fit='disparity' being refused there:
    # a height map given as depth was pointed to it, a review)
    return ("is it depth rather than a disparity (then prior_fit='affine')?"
            if kind == "disparity" else
            "is it a disparity or inverse depth, near being large (then prior_fit='disparity' "
            "with a pinhole camera)?" if perspective else
            "is it a height, near being large (then its negative, -prior, is the depth)?"
            ) + " Or are the normals in another frame (normal_frame)?"


#: :func:`relief_ratio`: at most this many samples (a random subset) are paired, each with
#: its nearest other sample at least RELIEF_NEAR and at most RELIEF_FAR pixels away;
#: at least RELIEF_PAIRS pairs with a measurable relief give a ratio.
RELIEF_SAMPLES, RELIEF_NEAR, RELIEF_FAR, RELIEF_PAIRS = 3000, 8.0, 32.0, 10

#: ... among at most this many samples (a random subset: 2e5 over a 4096^2 map are about 9
#: px apart).
RELIEF_POOL = 200_000

#: ... and only where the counted pairs' mean slope along their paths is at least this (about
#: 6 degrees), in the median.
RELIEF_SLOPE = 0.1


def relief_ratio(problem) -> tuple[float, int] | None:
    """``(ratio, pairs)``: the median over pairs of nearby prior samples of the prior's depth
    difference over the one the normals predict along the straight path between them (their
    slopes summed pixel by pixel; the unknown's units, so orthographic depth in units of
    `pixel_size`); None where there are too few pairs or no measurable relief (a flat view).

    Pairs across a jump or a gap are outliers the median ignores; only the half with the
    larger predicted relief counts. A ratio far from 1 says that the prior's units are not the
    normals' (a metric prior without ``K``, or with a wrong ``pixel_size``), and a negative
    one that it runs the other way (height for depth)."""
    from scipy.spatial import cKDTree

    if problem.prior is None or problem.prior_weight is None:
        return None
    d = problem.domain
    have = np.flatnonzero(np.isfinite(problem.prior) & (problem.prior_weight > 0))
    if have.size < 2:
        return None
    # anchors, and the partners they are paired with: random subsets (seeded: the same input
    # gives the same verdict), the partners dense enough to lie within RELIEF_FAR of an
    # anchor on any map (an evenly strided subset of a dense 4096^2 prior is a lattice 57 px
    # apart, beyond it: a review)
    rng = np.random.default_rng(0)
    if have.size > RELIEF_POOL:
        have = np.sort(rng.choice(have, RELIEF_POOL, replace=False))
    anchors = (np.arange(have.size) if have.size <= RELIEF_SAMPLES else
               np.sort(rng.choice(have.size, RELIEF_SAMPLES, replace=False)))
    # (the partners of a dense prior thinned to about RELIEF_NEAR / 2 apart: its 31 nearest
    # samples lay within 3 px, none far enough to pair, and dense priors had no ratio; the
    # anchors stay as many as a sparse prior's, a review: thinned too, a 128^2 map's 77 pairs
    # gave noise-only ratios)
    thin = max(RELIEF_SAMPLES, int(d.n_facets / (RELIEF_NEAR / 2) ** 2))
    part = (np.arange(have.size) if have.size <= thin else
            np.sort(rng.choice(have.size, thin, replace=False)))
    r, c = (a[have].astype(float) for a in d.pixels)
    dist, nn = cKDTree(np.c_[r[part], c[part]]).query(np.c_[r[anchors], c[anchors]],
                                                      k=min(32, part.size))
    if np.ndim(dist) == 1:  # (k = 1)
        dist, nn = dist[:, None], nn[:, None]
    nn = part[nn]  # (indices into `have`)
    ok = (dist >= RELIEF_NEAR) & (dist <= RELIEF_FAR)  # (never the anchor itself)
    first = np.argmax(ok, axis=1)
    rows = np.flatnonzero(ok[np.arange(anchors.size), first])
    if rows.size < RELIEF_PAIRS:
        return None
    j = nn[rows, first[rows]]
    i = anchors[rows]
    # (the normals' change along the straight path: the outlier check's line integrals, NaN
    # where the path leaves the domain or crosses a facet without a slope)
    from .prior_outliers import _line_integrals

    index = np.full(d.shape, -1, dtype=np.int64)
    index[d.pixels] = np.arange(d.n_facets)
    predicted = _line_integrals(np.column_stack([r, c]), i, j, index, *problem.grid_slopes)
    steps = np.ceil(np.maximum(np.abs(r[j] - r[i]), np.abs(c[j] - c[i])))
    measured = problem.prior[have[j]] - problem.prior[have[i]]
    keep = np.isfinite(predicted) & np.isfinite(measured)
    if keep.sum() < RELIEF_PAIRS:
        return None
    predicted, measured = predicted[keep], measured[keep]
    size = np.abs(predicted)
    top = size >= np.median(size)
    # (a flat view's few-degree tilts are noise: a ratio of noise to noise says nothing)
    if not np.median(size[top] / steps[keep][top]) >= RELIEF_SLOPE * problem.camera.footprint():
        return None
    return float(np.median(measured[top] / predicted[top])), int(top.sum())
