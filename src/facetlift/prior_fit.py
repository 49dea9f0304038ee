"""A prior known only up to scale and shift, aligned to the normals (``prior_fit``).

Monocular depth networks give relative depth: affine-invariant depth (Marigold, DPT's
relative models: ``depth = a * P + b`` with unknown ``a > 0`` and ``b``) or affine-invariant
disparity (MiDaS, Depth Anything's relative models: ``1 / depth = a * P + b``). Fused as they
are, they pull the surface toward the wrong depths; fitted to the normals-only result over the
whole mask (the recipe before this module), the fit inherits that result's guesses where the
normals cannot decide: the offsets of pieces that a depth jump or a gap in the mask separates,
which are exactly what the prior should decide.

So the fit here uses only what the normals know: the shape *within* each piece of the
normals-only surface (its connected parts: mask components, and the pieces of the split mesh
with ``discontinuities=True``). Each piece gets its own free constant, the one thing the
normals leave open, and the prior's scale (and shift) are shared:

- orthographic, ``"affine"`` or ``"scale"``: ``P = alpha * z + gamma_k`` (depth known up to an
  offset per piece); the aligned prior is ``(P - gamma_main) / alpha`` (``"affine"``), or
  ``P / alpha`` (``"scale"``: the prior's zero is depth zero);
- perspective, ``"affine"``: ``P = s_k * z + beta`` (a pinhole piece is known up to a scale);
  aligned ``(P - beta) / s_main``; ``"scale"``: ``P = s_k * z``, aligned ``P / s_main``;
- perspective, ``"disparity"``: ``P = t_k / z + delta``; aligned ``t_main / (P - delta)``
  where that is positive.

``main`` is the piece holding most of the prior's weight: the aligned prior agrees with the
normals-only surface there, so a perspective result keeps that surface's scale (median depth
near 1; the prior had none to give) and an orthographic one its depth units. Every other piece
is then placed by the aligned prior in the second solve (:func:`facetlift.integrate` runs
the route twice). The per-piece constants are eliminated in closed form, so the fit is a few
sums per piece, repeated for a Huber reweighting (:data:`HUBER`, :data:`ROUNDS`) that keeps
a network's errors at silhouettes (foreground and background blended) from tilting it.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

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

#: The largest relative standard error of the scale that the pieces' shapes may leave; above
#: it (a flat view, parallel planes, a noisy prior on a shallow surface) the scale is fitted
#: over the whole surface instead (the normals-only depth on the prior, which shrinks an
#: undetermined prior toward a flat one rather than blowing it up), and where that is not
#: determined either (:data:`SE_WHOLE`) the prior is left out, with a warning.
SE_MAX, SE_WHOLE = 0.1, 0.25

#: Where the pieces leave the scale undetermined, it is fitted from the prior's own slopes
#: against the normals' (:func:`_by_gradients`), kept where its relative standard error is
#: at most this; normals less head-on than GRADIENT_COS give no slope there.
SE_GRADIENTS, GRADIENT_COS = 0.1, 0.3

#: A within-piece correlation between the prior and the normals-only depth at or below this
#: (with no scale determined) names the prior as running against the normals in the warning.
AGAINST = -0.5

#: Compare the prior with the normals-only surface blurred by ``prior_blur`` where one is
#: given, as the solve does.
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
    sharing a corner vertex (of the split mesh where the surface is cut at jumps)."""
    mask = surface.mask
    if surface.split is not None:
        corners = surface.split[0]
    else:
        from .domain import Domain

        corners = Domain.from_mask(mask).corners
    m = corners.shape[0]
    n = int(corners.max()) + 1 if m else 0
    rows = np.repeat(np.arange(m), 4)
    A = sp.csr_matrix((np.ones(4 * m), (rows, corners.ravel())), shape=(m, n))
    _, lab = connected_components(A @ A.T, directed=False)
    out = np.full(mask.shape, -1, dtype=np.int64)
    out[mask] = lab
    return out


def fit(prior_img: np.ndarray, weight, surface, kind: str, perspective: bool,
        blur: float = 0.0, normals=None):
    """The prior aligned to `surface` (normals only): ``(aligned (H, W) or None, details)``.

    `prior_img` (H, W) raw prior values, NaN where unknown; `weight` a scalar or (H, W) map
    (the prior's weights, which weigh the fit too); `normals` (H, W, 3) in facetlift's frame
    (for the slopes' fit, :func:`_by_gradients`); `blur` the ``prior_blur`` sigma (pixels):
    the prior is then fitted to the surface blurred alike (:class:`~facetlift.operators.blur.
    PlaneBlur`), as the solve compares them. `aligned` is None where the prior could not be
    aligned (the caller returns the normals-only surface). `details` (for
    ``info["prior"]["fit"]``): ``kind``, ``used``, ``scale`` and ``shift`` (depth = scale * P
    + shift; for "disparity" 1 / depth = scale * P + shift), ``samples``, ``pieces`` that took
    part, ``scale_error`` (relative standard error of the scale, by a jackknife over tiles),
    ``down_weighted`` (samples the Huber weights reduced below one half), ``residual`` (robust
    RMS of the fit in the aligned prior's depth units, at the median sample for a disparity),
    ``dropped`` (samples whose aligned depth was not positive, perspective only),
    ``correlation`` (of the prior with the normals-only depth within the pieces) and
    ``whole`` (the scale was fitted over the whole surface, :data:`SE_MAX`). A prior whose
    scale neither fit determines is left out with a warning (a few bad samples or a poor
    prior never refuse the job). Raises ValueError naming `prior` where too few samples lie
    on the surface.
    """
    from ._warnings import warn

    z = surface.depth
    if blur > 0 and MATCH_BLUR:
        from .operators.blur import PlaneBlur

        z = PlaneBlur(surface.mask, blur)(np.where(surface.mask, z, 0.0))
    lab = pieces(surface)
    w_img = np.broadcast_to(np.asarray(weight, float), prior_img.shape)
    ok = np.isfinite(prior_img) & (lab >= 0) & np.isfinite(z) & (w_img > 0)
    if perspective:
        ok &= z > 0
    if ok.sum() < 2 * MIN_SAMPLES:
        raise ValueError(f"`prior` with prior_fit={kind!r}: only {int(ok.sum())} sample(s) "
                         f"with a weight > 0 lie on the surface; at least {2 * MIN_SAMPLES} "
                         "are needed to fit its scale")
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
    big = np.bincount(k)[k] >= MIN_SAMPLES
    per_offset = not perspective  # (orthographic: a constant per piece; pinhole: a scale)
    model = ("offset" if per_offset else ("scale" if kind == "scale" else "slope"))
    whole = big.sum() < 2 * MIN_SAMPLES  # (every sample on a small piece of its own)
    first = corr = None
    method = "pieces"
    if not whole:
        _, kk = np.unique(k[big], return_inverse=True)
        r = _robust(x[big], y[big], kk, tile[big], om[big], model)
        theta, first = r["theta"], r["error"]
        corr = _within_correlation(x[big], y[big], kk, om[big] * r["rob"])
        whole = not (theta > 0 and first <= SE_MAX)
    if not whole:
        scale = 1.0 / theta
        shift = 0.0 if model == "scale" or kind == "scale" else (
            -r["each"][r["main"]] * scale if per_offset else -r["common"] * scale)
        samples, pieces_used, error = int(big.sum()), int(kk.max()) + 1, first
        rms, down = r["rms"] * scale, int((r["rob"] < 0.5).sum())
    else:
        g = None
        if normals is not None:
            g = _by_gradients(prior_img, normals, surface, lab, kind, perspective,
                              blur if MATCH_BLUR else 0.0, w_img, side)
        if g is not None and g["scale"] > 0 and g["error"] <= SE_GRADIENTS:
            method = "gradients"
            scale, shift, error = g["scale"], g["shift"], g["error"]
            samples, pieces_used, rms, down = g["samples"], 0, None, g["down"]
        else:  # the normals' depth (or 1 / depth) on the prior, over every sample: one piece
            method = "whole"
            kk = np.zeros(y.size, dtype=np.int64)
            r = _robust(y, x, kk, tile, om, "scale" if model == "scale" else "offset")
            if corr is None:
                corr = _within_correlation(x, y, kk, om * r["rob"])
            if not (r["theta"] > 0 and r["error"] <= SE_WHOLE):
                why = (f"it runs against the normals (correlation {corr:.2f} with the "
                       "normals-only depth within its pieces): " + _against_hint(kind)
                       if corr is not None and corr <= AGAINST else
                       "neither the normals' shape within the surface's pieces, nor their "
                       "slopes, nor the whole surface determine its scale (relative errors "
                       f"{_fmt(first)}, {_fmt(None if g is None else g['error'])} and "
                       f"{_fmt(r['error'])}): a flat view, parallel planes, or a prior unlike "
                       "the normals' surface")
                warn(f"`prior` with prior_fit={kind!r} was left out: {why}; the surface is "
                     "the normals-only one")
                return None, {"kind": kind, "used": False, "correlation": _num(corr),
                              "scale_error": _num(first), "whole_error": _num(r["error"]),
                              "samples": int(y.size)}
            scale, error = r["theta"], r["error"]
            shift = 0.0 if model == "scale" or (kind == "scale" and per_offset) else \
                r["each"][0]
            samples, pieces_used, rms, down = int(y.size), 1, r["rms"], int(
                (r["rob"] < 0.5).sum())
            warn(f"`prior` with prior_fit={kind!r}: neither the normals' shape within the "
                 "surface's pieces nor their slopes determine the prior's scale (relative "
                 f"errors {_fmt(first)} and {_fmt(None if g is None else g['error'])}: a flat "
                 "view, parallel planes, a noisy prior on a shallow surface), so it was fitted "
                 "over the whole surface: the pieces keep the normals' own placement")
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
    elif kind == "scale":
        aligned = scale * prior_img  # (the prior's zero is depth zero)
    # (the residual in the aligned prior's depth units, at the median sample for disparity)
    unit = float(np.median(z[ok])) ** 2 if kind == "disparity" else 1.0
    details = {"kind": kind, "used": True, "method": method, "scale": float(scale),
               "shift": float(shift), "correlation": _num(corr), "samples": samples,
               "pieces": pieces_used, "scale_error": float(error), "down_weighted": down,
               "residual": None if rms is None else float(abs(rms) * unit),
               "dropped": dropped}
    return aligned, details


def _by_gradients(prior_img, normals, surface, lab, kind, perspective, blur, w_img, side):
    """The scale from the prior's own slopes against the normals' (pixel by pixel, no
    integration: the pieces' placement does not enter). Orthographic: ``dP = alpha * d
    depth``; pinhole: ``dP = (P + c) d log z`` (affine depth ``z = a (P + c)``), ``dD = -(D +
    c) d log z`` (disparity ``1 / z = a (D + c)``), then ``a`` so that the main piece agrees
    with `surface` in the median. Slopes of normals with a view cosine below
    :data:`GRADIENT_COS` are left out (a rim's slopes would lever the fit). Returns a dict
    (``scale``, ``shift`` as :func:`fit`'s, ``error``, ``samples``, ``rms`` in depth units,
    ``down``) or None where there are too few samples."""
    if perspective and kind == "scale":  # (no offset to find: the pieces always fit it)
        return None
    H, W = prior_img.shape
    mask = surface.mask
    r, c = np.nonzero(mask)
    n = normals[r, c]
    cam = surface.camera
    with np.errstate(invalid="ignore", divide="ignore"):
        gx, gy = cam.grid_slopes(r, c, n)
        cos = cam.view_cosine(r, c, n)
    good = np.isfinite(gx) & np.isfinite(gy) & (cos >= GRADIENT_COS)
    G = []
    for g in (gx, gy):
        img = np.full((H, W), np.nan)
        img[r[good], c[good]] = g[good]
        if blur > 0:
            from .operators.blur import PlaneBlur

            valid = np.isfinite(img)
            img = np.where(valid, PlaneBlur(valid, blur)(np.where(valid, img, 0.0)), np.nan)
        G.append(img)
    P = np.where(mask & (w_img > 0), prior_img, np.nan)
    dPx = np.full((H, W), np.nan)
    dPy = np.full((H, W), np.nan)
    dPx[:, 1:-1] = (P[:, 2:] - P[:, :-2]) / 2.0
    dPy[1:-1, :] = -(P[2:, :] - P[:-2, :]) / 2.0  # (y up)
    ys, xs, ws, ts = [], [], [], []
    tw = -(-W // side)
    for d, g in ((dPx, G[0]), (dPy, G[1])):
        ok = np.isfinite(d) & np.isfinite(g) & np.isfinite(P)
        rr, cc = np.nonzero(ok)
        if perspective:
            sign = -1.0 if kind == "disparity" else 1.0
            ys.append(d[ok] - sign * P[ok] * g[ok])  # = c * (sign * g)
            xs.append(sign * g[ok])
        else:
            ys.append(d[ok])  # = alpha * d depth = alpha * (-g) (the unknown is the height)
            xs.append(-g[ok])
        ws.append(w_img[rr, cc])
        ts.append((rr // side) * tw + cc // side)
    yv, xv, wv, tv = (np.concatenate(v) for v in (ys, xs, ws, ts))
    if yv.size < 6 * MIN_SAMPLES:
        return None
    wv = wv / wv.mean()
    _, tv = np.unique(tv, return_inverse=True)
    zero = np.zeros(yv.size, dtype=np.int64)
    rfit = _robust(xv, yv, zero, tv, wv, "scale")
    coef = rfit["theta"]
    main_lab = np.argmax(np.bincount(lab[np.isfinite(P) & (lab >= 0)]))
    on = (lab == main_lab) & np.isfinite(P) & np.isfinite(surface.depth)
    z0 = surface.depth[on]
    if perspective:
        unit = P[on] + coef  # proportional to z (affine) or to 1 / z (disparity)
        ratio = (1.0 / z0) / unit if kind == "disparity" else z0 / unit
        ratio = ratio[unit > 0]
        if ratio.size == 0 or coef == 0:
            return None
        lam = float(np.median(ratio))
        scale, shift = lam, lam * coef
    else:
        if not coef != 0:
            return None
        scale = 1.0 / coef
        shift = 0.0 if kind == "scale" else float(np.median(z0 - scale * P[on]))
    return {"scale": scale, "shift": shift, "error": rfit["error"], "samples": int(yv.size),
            "down": int((rfit["rob"] < 0.5).sum())}


def _fmt(v) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v:.2g}"


def _num(v):
    return None if v is None or not np.isfinite(v) else float(v)


def _robust(x, y, k, tile, om, model):
    """The piece model `model` fitted to ``y`` on ``x`` with Huber weights: a dict of
    ``theta`` (the scale parameter: ``alpha`` of "offset" ``y = alpha x + gamma_k``, the main
    piece's ``s`` of "slope" ``y = s_k x + beta`` and "scale" ``y = s_k x``), ``common``,
    ``each`` (K,), ``main``, ``error`` (theta's relative standard error, a jackknife over the
    tiles `tile`: each tile left out in turn), ``rob`` (Huber weights), ``rms`` (their
    weighted residual RMS, y units)."""
    K = int(k.max()) + 1
    main = int(np.argmax(np.bincount(k, weights=om, minlength=K)))
    rob = np.ones_like(om)
    for _ in range(ROUNDS + 1):
        common, each = _params(_moments(x, y, k, om * rob, K), model)
        res = y - (common * x + each[k] if model == "offset" else each[k] * x + common)
        sigma = 1.4826 * float(np.median(np.abs(res)))
        if not sigma > 0:
            break
        new = np.minimum(1.0, HUBER * sigma / np.maximum(np.abs(res), 1e-300))
        done = np.allclose(new, rob, atol=1e-3)
        rob = new
        if done:
            break
    w = om * rob
    Mk = _moments(x, y, k, w, K)
    common, each = _params(Mk, model)
    theta = common if model == "offset" else each[main]
    res = y - (common * x + each[k] if model == "offset" else each[k] * x + common)
    rms = float(np.sqrt(np.sum(w * res ** 2) / np.sum(w)))
    return {"theta": float(theta), "common": float(common), "each": each, "main": main,
            "error": _jackknife(x, y, k, tile, w, Mk, model, main, theta), "rob": rob,
            "rms": rms}


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


def _moments(x, y, k, w, K):
    """(5, K): the weighted sums 1, x, y, x x, x y per group `k`."""
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


def _against_hint(kind: str) -> str:
    return ("is it depth rather than a disparity (then prior_fit='affine')?"
            if kind == "disparity" else
            "is it a disparity or inverse depth, near being large (then prior_fit='disparity' "
            "with a pinhole camera)?") + " Or are the normals in another frame (normal_frame)?"
