"""Error measures for reconstructed surfaces.

Depth maps are ``(H, W)`` arrays in the convention of :mod:`facetlift.conventions` (NaN
outside the domain). Orthographic depth is defined up to one constant per connected component,
so :func:`normalized_error`, :func:`rmse` and :func:`mae` first align the estimate to the ground
truth by subtracting the mean difference on every 8-connected component of the mask (the paper
moves the reconstruction so that its centre coincides with the ground truth's, Sec. 5).
Perspective depth is defined up to a scale, which :func:`made` fixes with BiNI's median ratio.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "align",
    "angular_error",
    "diagnose",
    "evaluate",
    "facet_normals",
    "input_deviation",
    "made",
    "mae",
    "normalized_error",
    "rmse",
]


def _depth_of(estimate):
    """A Surface's depth map, or `estimate` itself (an audit: made(surface, ...) raised a
    bare TypeError)."""
    return estimate.depth if hasattr(estimate, "depth") and hasattr(estimate, "mask") \
        else estimate


def _as_mask(mask):
    """A scoring mask as bool: values above 0 inside, negative ones outside with a warning, as
    integrate and read_mask take masks (a logit mask scored twice its pixels here, a
    review); None stays None."""
    from .problem import negatives_outside

    return None if mask is None else negatives_outside(np.asarray(mask), "`mask`")


def _pair(estimate, truth, mask):
    est = np.asarray(_depth_of(estimate), dtype=float)
    gt = np.asarray(_depth_of(truth), dtype=float)
    if est.ndim != 2:
        raise ValueError(f"`estimate` must be an (H, W) depth map; got shape {est.shape}")
    if gt.shape != est.shape:
        swapped = (" (`estimate`'s transposed: one stored as (W, H)?)"
                   if est.ndim == 2 and gt.shape == est.shape[::-1] else "")
        raise ValueError(f"`truth` must have the shape of `estimate` {est.shape}; got "
                         f"{gt.shape}{swapped}")
    if mask is None:
        m = np.isfinite(gt)
    else:
        m = np.asarray(mask)
        if m.shape != est.shape:
            raise ValueError(f"`mask` must have shape {est.shape}; got {m.shape}")
        m = _as_mask(m) & np.isfinite(gt)
    m = m & np.isfinite(est)
    if not m.any():
        raise ValueError("no pixel where `mask`, `estimate` and `truth` are all defined"
                         if mask is not None else
                         "no pixel where `estimate` and `truth` are both defined")
    return est, gt, m


def align(estimate, truth, mask=None, *, region=None) -> tuple[np.ndarray, np.ndarray]:
    """Shift `estimate` on each of its pieces (the 8-connected components of its defined
    pixels) by its mean difference to `truth` over the compared pixels of that piece.

    The pieces are the estimate's own, not those of the compared pixels: a ground truth
    with a hole across a connected result (a sensor's missing column) would otherwise let
    each side take its own offset and hide a false step there (26 % error scored as 0, an
    audit).

    Parameters
    ----------
    estimate, truth : (H, W) array_like of float
    mask : (H, W) array_like of bool, optional
        Pixels to compare; default: where both are finite.

    Returns
    -------
    aligned : (H, W) float
        The shifted estimate, NaN outside the compared pixels.
    mask : (H, W) bool
        The compared pixels.
    """
    est, gt, m = _pair(estimate, truth, mask)
    k, n = _pieces(m, _region(est, mask) if region is None else region)
    r, c = np.nonzero(m)
    diff = est[r, c] - gt[r, c]
    shift = np.bincount(k, diff, n) / np.maximum(np.bincount(k, minlength=n), 1)
    out = np.full(est.shape, np.nan)
    out[r, c] = est[r, c] - shift[k]
    return out, m


def _piece_centred(est, gt, m, region) -> tuple[np.ndarray, np.ndarray]:
    """The depths of `est` and `gt` at `m`, each less its mean over each of the result's
    pieces (:func:`_pieces` of `region`)."""
    k, n = _pieces(m, region)
    size = np.maximum(np.bincount(k, minlength=n), 1)
    e, g = est[m], gt[m]
    return e - (np.bincount(k, e, n) / size)[k], g - (np.bincount(k, g, n) / size)[k]


#: Share of the finite result pixels outside the scoring mask that hold one exact value from
#: which :func:`_region` takes that value for a background stored as a number (a surface
#: seldom repeats one float exactly; a background stored as 0 beside objects the mask cuts
#: into held 43 % of them, and joined the objects at 0.5, a review).
BACKGROUND_SHARE = 0.05


def _region(est, mask) -> np.ndarray:
    """The pixels whose 8-connected components are the result's pieces: its finite ones,
    less, where `mask` is given, the pixels outside it that hold a background stored as a
    number (one value held by :data:`BACKGROUND_SHARE` of the finite pixels outside the
    mask, e.g. 0: it would join separate objects, a review). The rest of the result outside
    the mask joins its pieces: a mask with a gap across a connected result (columns left
    out) scored a false step there as 0 when the pieces were cut at the mask (a review)."""
    fin = np.isfinite(est)
    if mask is None:
        return fin
    mask = np.asarray(mask, bool)
    if mask.shape != fin.shape:  # (_pair names the shapes)
        return fin
    outside = est[fin & ~mask]
    if outside.size:
        values, counts = np.unique(outside, return_counts=True)
        if counts.max() >= max(2, BACKGROUND_SHARE * outside.size):
            fin &= mask | (est != values[counts.argmax()])
    return fin


def _pieces(m, region) -> tuple[np.ndarray, int]:
    """``(labels, count)``: the piece of the result (an 8-connected component of `region`,
    :func:`_region`: its finite pixels, less a background stored as a number outside the
    mask, which would join separate objects, a review) of each pixel of `m` in row-major
    order, and how many pieces there are."""
    from .domain import Domain

    d = Domain.from_mask(region)
    comp = np.full(region.shape, -1, dtype=np.int64)
    comp[d.pixels] = d.facet_component
    return comp[m], d.n_components


def normalized_error(estimate, truth, mask=None) -> tuple[float, np.ndarray]:
    """The paper's error: |aligned depth error| at facet centres / ground-truth depth range.

    Returns
    -------
    mean : float
        Mean normalised error over the compared pixels (multiply by 100 for percent).
    error : (H, W) float
        Per-pixel normalised error, NaN outside.

    Raises
    ------
    ValueError
        Shape mismatch, no common pixel, or a flat ground truth (zero depth range).
    """
    return _normalized(*_offset_aligned(estimate, truth, mask))


def _normalized(aligned, gt, m) -> tuple[float, np.ndarray]:
    """:func:`normalized_error` of an offset-aligned estimate (:func:`_offset_aligned`)."""
    rng = float(gt[m].max() - gt[m].min())
    if rng <= 0:
        raise ValueError("`truth` has zero depth range on the mask: the error is undefined")
    err = np.full(gt.shape, np.nan)
    err[m] = np.abs(aligned[m] - gt[m]) / rng
    return float(err[m].mean()), err


def rmse(estimate, truth, mask=None) -> float:
    """Root-mean-square depth error after :func:`align` (units of `truth`)."""
    aligned, gt, m = _offset_aligned(estimate, truth, mask)
    return float(np.sqrt(np.mean((aligned[m] - gt[m]) ** 2)))


def mae(estimate, truth, mask=None) -> float:
    """Mean absolute depth error after :func:`align` (units of `truth`)."""
    aligned, gt, m = _offset_aligned(estimate, truth, mask)
    return float(np.mean(np.abs(aligned[m] - gt[m])))


#: :func:`rmse`, :func:`mae` and :func:`normalized_error` compare after an offset only; an
#: estimate whose depth spread is this many times the truth's, or this many times less, is
#: warned about (an audit: a perspective result, median depth 1, scored 10.5 mm RMSE against
#: the DiLiGenT bear in mm without a word, where made gives 0.468).
SCALE_MISMATCH = 10.0


#: :func:`evaluate` of an orthographic result warns where the result's depth range (1st to
#: 99th percentile over the pixels scored) is more than this many times the truth's, or this
#: many times less: the normalised error then compares two units. A second audit: the DiLiGenT
#: bear integrated orthographically in pixels spans 105 units, its truth 44 mm (2.3 x), and
#: scored 26.5 % without a word; with --pixel-size 0.397 (mm per pixel) 2.3 %, its range
#: 0.94 of the truth's (1.00 with --discontinuities). On the discontinuity benchmark's 12
#: orthographic renders in their units (exact and 3-deg noise, smooth and with
#: --discontinuities, 2026-12-06) no result spans more than 1.13 times the truth; smooth
#: results flattened across depth jumps span less (fandisk 0.47, mountain 0.54, spot 0.66),
#: and a view whose depth is made by jumps alone (featuretype's plates) 0.005: below, the
#: warning names the jumps too.
RANGE_MISMATCH = 1.5


def _offset_aligned(estimate, truth, mask, check: bool = True, region=None):
    """``(aligned, truth, mask)`` of :func:`align` for the offset-aligned errors, with
    :func:`_scale_check` (unless not `check`: :func:`evaluate` has said it its own way)."""
    aligned, m = align(estimate, truth, mask, region=region)
    gt = np.asarray(_depth_of(truth), dtype=float)
    if check:
        _scale_check(aligned, gt, m)
    return aligned, gt, m


def _range_ratio(est, gt, m, region) -> float | None:
    """The estimate's depth range over the truth's, each from the 1st to the 99th percentile
    over `m` (a few outliers do not make the range) of the depths less their mean on each of
    the estimate's pieces (:func:`_pieces`: separate objects integrated without a prior
    have mean depth 0 each, the truth keeps the gaps between them; a correct result was told
    its units were 18 times off, an audit); None where the truth's is 0."""
    e, g = _piece_centred(est, gt, m, region)
    lo, hi = np.percentile(e, [1, 99])
    glo, ghi = np.percentile(g, [1, 99])
    flat = ghi - glo <= 1e-9 * max(1.0, abs(glo), abs(ghi))  # (rounding in a flat truth)
    return None if flat else float((hi - lo) / (ghi - glo))


#: The settings :func:`_range_check`'s warning names, in the words of its caller: Python's
#: arguments (:func:`evaluate`), the command line's flags (``facetlift evaluate``: it was
#: told of perspective=True, a review) or both (a job's own scoring, run from either).
_WORDS = {
    "python": {"camera": "perspective=True, or K=K", "pixel": "pixel_size",
               "set": "pixel_size={:.3g}", "jumps": "discontinuities=True"},
    "command line": {"camera": "--K, or --fov as integrate took it", "pixel": "--pixel-size",
                     "set": "--pixel-size {:.3g}", "jumps": "--discontinuities"},
    "both": {"camera": "in Python perspective=True or K=K; on the command line --K or --fov",
             "pixel": "pixel_size; --pixel-size on the command line",
             "set": "--pixel-size {:.3g}", "jumps": "discontinuities=True, --discontinuities"},
}


def _range_check(est, gt, m, words: str = "python", region=None,
                 against: bool = False) -> float | None:
    """:func:`evaluate`'s warning on an orthographic result in other units than the truth
    (:data:`RANGE_MISMATCH`), naming the settings in `words` (:data:`_WORDS`); the ratio of
    the ranges (:func:`_range_ratio`). `against`: the result's depths run against the
    truth's (a height): positive ones are then not taken for a perspective result's."""
    from ._warnings import warn

    ratio = _range_ratio(est, gt, m, _region(est, None) if region is None else region)
    if ratio is None or 1.0 / RANGE_MISMATCH <= ratio <= RANGE_MISMATCH:
        return ratio
    if ratio == 0:  # (a flat result: 1 / ratio raised ZeroDivisionError, and a dataset
        # folder's integrate with a depth_gt exited 3, a review)
        warn(f"the result is flat: its depths do not vary over the {int(m.sum())} pixels "
             "scored (1st to 99th percentile), where the ground truth's do; its errors are "
             "those of a plane (were its normals all facing the camera?)")
        return ratio
    say = _WORDS[words]
    head = (f"the result's depth range (1st to 99th percentile over the {int(m.sum())} pixels "
            f"scored) is {ratio:.3g} times the ground truth's: the normalised error compares "
            "them as stored, in units that then differ, and means little")
    if (est[m] > 0).all() and not against:  # (positive depths: a perspective result, up to
        # scale; not a positive height, which was told to give --K, a review)
        warn(f"{head}. Its depths are all > 0, as a perspective result's are (defined up to "
             f"scale, median depth 1): score it with its camera ({say['camera']}), after a "
             "median scale (MADE)")
    else:
        jumps = ("; or, if the units are right, the result is flattened across depth jumps "
                 f"(a smooth one bends across them: {say['jumps']} keeps those the normals "
                 "show)" if ratio < 1 else "")
        warn(f"{head}. An orthographic result's depth is in the units of the pixel size it "
             f"was integrated with ({say['pixel']}: the world width of a pixel, 1 by default, "
             "so depth in pixels): integrate again with the ground truth's, about "
             f"{1.0 / ratio:.3g} times the one used (e.g. {say['set'].format(1.0 / ratio)} "
             "where it was 1; a factor read from the two ranges, not measured: where the "
             f"ground truth's pixel size is known, give that){jumps}")
    return ratio


def _scale_check(est, gt, m) -> None:
    from ._warnings import warn

    a, b = float(np.std(est[m])), float(np.std(gt[m]))
    if not (a > 0 and b > 0) or 1.0 / SCALE_MISMATCH <= a / b <= SCALE_MISMATCH:
        return
    # (only where a scale explains the error: a near-flat truth beside reconstruction noise
    # has spreads 187x apart and no scale error, a review)
    e, g = est[m] - est[m].mean(), gt[m] - gt[m].mean()
    s = float(np.dot(e, g) / np.dot(e, e))
    if np.sqrt(np.mean((s * e - g) ** 2)) < 0.5 * b:  # (scaled, it follows the truth)
        warn(f"the estimate's depth spread is {a / b:.3g} times the truth's: these errors "
             "align by an offset only, not a scale. A perspective result without a prior is "
             "defined up to scale (median depth 1): compare it with made() (median scale, as "
             "BiNI evaluates), or integrate with a depth prior for metric depth; an "
             "orthographic one scales with pixel_size")


def made(estimate, truth, mask=None) -> tuple[float, np.ndarray]:
    """Mean absolute depth error after a median scale fit, as BiNI evaluates perspective data.

    ``scale = nanmedian(truth / estimate)`` and ``MADE = nanmean(|scale * estimate - truth|)``
    over the mask.

    Returns
    -------
    made : float
        In the units of `truth` (mm for DiLiGenT).
    error : (H, W) float
        ``|scale * estimate - truth|``, NaN outside the mask.
    """
    value, err, _ = _made(*_pair(estimate, truth, mask))
    return value, err


def _made(est, gt, m) -> tuple[float, np.ndarray, float]:
    """:func:`made` on checked pixels (:func:`_pair`), with its median scale."""
    for which, a in (("`estimate`", est), ("`truth`", gt)):
        if np.any(a[m] <= 0):  # (an orthographic depth has mean 0)
            raise ValueError(f"made: {which} has depths <= 0 inside the mask; MADE compares "
                             "perspective z-depths (> 0) after a median scale: for "
                             "orthographic depth use rmse or mae (aligned by the best offset)")
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = float(np.nanmedian(gt[m] / est[m]))
    if not np.isfinite(scale):
        raise ValueError("`estimate` gives no finite scale to `truth` (zero or NaN depths)")
    err = np.full(gt.shape, np.nan)
    err[m] = np.abs(scale * est[m] - gt[m])
    return float(np.nanmean(err[m])), err, scale


def evaluate(estimate, truth, mask=None, *, perspective: bool | None = None, K=None) -> dict:
    """Score a result against a ground-truth depth map: what ``facetlift evaluate`` prints.

    Every measure is one of this module's, over the same pixels: :func:`made` (BiNI's: the
    estimate times ``scale = median(truth / estimate)``, then the mean absolute error), that
    scale, the RMSE of the same scaled estimate, the mean absolute error without any scale or
    offset (for a metric result, e.g. one fused with a depth prior: a result up to scale
    scores its scale error here), and, for an orthographic result, :func:`normalized_error`
    (the paper's: each 8-connected piece shifted by its mean difference, divided by the
    truth's depth range).

    Parameters
    ----------
    estimate : (H, W) array_like of float, or facetlift.Surface
        The result's depth, NaN where undefined.
    truth : (H, W) array_like of float
        Ground-truth depth in its units (mm for DiLiGenT), NaN where undefined.
    mask : (H, W) array_like of bool, optional
        The pixels to score; default: where both are finite. Mask pixels where either is
        undefined are left out, and counted (``uncovered``).
    perspective : bool, optional
        Whether the result is a perspective depth (a camera's z, defined up to scale). Default:
        a Surface's camera says; an array is taken as orthographic (a height, defined up to an
        offset per piece).
    K : (3, 3) array_like, nine or four numbers or facetlift.camera.Pinhole, optional
        The result's camera, as given to :func:`facetlift.integrate` (``facetlift evaluate
        --K``): the same as ``perspective=True`` (the scores need no more of it); refused
        beside ``perspective=False``, or where `estimate` is a Surface with another camera.

    Returns
    -------
    dict
        ``pixels`` (the number scored), ``uncovered`` (mask pixels left out: the estimate or
        the truth undefined there; 0 without a mask), ``perspective``, ``made``, ``scale``,
        ``rmse_scaled``, ``mae`` (unaligned), ``normalized_error`` (a fraction; None for a
        perspective result), ``coverage`` (the share of the mask's pixels with a defined truth
        that the result defines; None without a mask: below :data:`COVERAGE` a warning says
        that the pixels left out are not scored), ``correlation`` (of the result's and the
        truth's depths, each piece of the result less its mean; below
        :data:`HEIGHT_CORRELATION` a warning asks whether the result is a height or a
        disparity), ``range_ratio`` (an orthographic result's depth range over the
        truth's, 1st to 99th percentile; None for a perspective one or a flat truth: beyond
        :data:`RANGE_MISMATCH` a warning says the units differ, and names the pixel size),
        and ``notes``: why a measure is None. ``made``, ``scale`` and ``rmse_scaled`` are None
        where the result or the truth has depths <= 0 (an orthographic depth has mean 0: no
        scale applies); they are given for an orthographic result whose depths are all > 0.

    Raises
    ------
    ValueError
        Shapes that differ; no pixel where the mask, the estimate and the truth are all
        defined (with how many each has); depths <= 0 where a scale is needed: in a
        perspective result, or in the truth of one; a `K` that is no valid camera, or that
        contradicts `perspective` or the Surface's camera (an orthographic Surface has
        none).
    """
    if K is not None:  # (evaluate(depth, gt, mask, K=K) was a TypeError, a review)
        from .camera import Pinhole, check_K

        # (as integrate takes it: four numbers or a Pinhole were refused, a transposed K
        # taken, a review)
        cam = check_K(K.K if isinstance(K, Pinhole) else K)
        if perspective is False:
            raise ValueError("`K` and perspective=False contradict each other: a camera "
                             "scores the result as a perspective depth; give one of them")
        own = getattr(estimate, "K", None)
        if own is not None and not np.allclose(np.asarray(own, float), cam, rtol=1e-6):
            raise ValueError(f"`K` differs from the camera the Surface was integrated with "
                             f"({np.asarray(own).tolist()}); leave it out to use the "
                             "Surface's own")
        if own is None and hasattr(estimate, "depth") and hasattr(estimate, "K"):
            raise ValueError("`K` given for an orthographic Surface (integrated without a "
                             "camera: its depth is a height, not a camera's z); leave it out, "
                             "or integrate with K")
        perspective = True
    return _evaluate(estimate, truth, mask, perspective, "python")


def _evaluate(estimate, truth, mask, perspective, words: str) -> dict:
    """:func:`evaluate`, its warnings naming the settings in `words` (:data:`_WORDS`): the
    command line's flags for ``facetlift evaluate``."""
    if perspective is None:
        perspective = getattr(estimate, "K", None) is not None
    if mask is not None and np.shape(mask) == np.shape(_depth_of(estimate)):
        mask = _as_mask(mask)  # (once: its warning, then bool below)
    est = np.asarray(_depth_of(estimate), dtype=float)
    gt = np.asarray(_depth_of(truth), dtype=float)
    if est.ndim == 2 and gt.shape == est.shape:  # (else _pair names the shapes)
        sel = np.ones(est.shape, bool) if mask is None else np.asarray(mask, bool)
        if sel.shape == est.shape and not (sel & np.isfinite(est) & np.isfinite(gt)).any():
            both = int((np.isfinite(est) & np.isfinite(gt)).sum())
            raise ValueError(
                ("no pixel where `mask`, `estimate` and `truth` are all defined: "
                 if mask is not None else "no pixel where `estimate` and `truth` are both "
                 "defined: ")
                + (f"`mask` has {int(sel.sum())} pixels, " if mask is not None else "")
                + f"`estimate` {int(np.isfinite(est).sum())} finite, `truth` "
                f"{int(np.isfinite(gt).sum())} finite, {both} both; are they of the same view "
                "and crop?")
    est, gt, m = _pair(est, gt, mask)
    region = _region(est, mask)
    if mask is None:
        _zero_background_check(est, gt, m)
    corr = _correlation(est, gt, m, region)
    out = {"pixels": int(m.sum()),
           "uncovered": 0 if mask is None else int(np.asarray(mask, bool).sum() - m.sum()),
           "coverage": None if mask is None else _coverage_check(est, gt, mask),
           "correlation": corr,
           "perspective": bool(perspective), "made": None, "scale": None,
           "rmse_scaled": None, "mae": float(np.mean(np.abs(est[m] - gt[m]))),
           "normalized_error": None, "range_ratio": None, "notes": []}
    # (depths that run against the truth's: a height or a disparity, scored as a perspective
    # depth without a word, or told to give --K as one, a review)
    against = corr is not None and corr < HEIGHT_CORRELATION
    bad = {which: int((a[m] <= 0).sum()) for which, a in (("estimate", est), ("truth", gt))}
    if perspective and any(bad.values()):
        which = "estimate" if bad["estimate"] else "truth"
        a = est if which == "estimate" else gt
        # (a result's background stored as 0 was told it might be orthographic, an audit)
        zeros = int((a[m] == 0).sum()) == bad[which]
        if (a[m] < 0).all():  # (an OpenGL or Blender camera's z, negative in front: the
            # 0? hint misled, a review)
            hint = (" (all are < 0: a camera z stored negative in front, as OpenGL's and "
                    "Blender's are? negate it)" if which == "truth" else " (an orthographic "
                    "result, or a height? score it without a camera)")
        elif which == "truth" or zeros:
            # (given with a mask, its 0s were inside it: "or give a mask" misled, a review)
            hint = (" (0 where undefined? store NaN there, or give a mask)" if mask is None
                    else " (0 where undefined? store NaN there, or leave those pixels out of "
                    "the mask" + ("" if which == "truth" else "; a relative depth scaled to "
                                  "0..1 is no camera z-depth") + ")")
        else:
            hint = " (an orthographic result? score it without a camera)"
        raise ValueError(
            f"`{which}` has {bad[which]} depths <= 0 of the {out['pixels']} scored: a "
            "perspective result is scored after a median scale, which needs z-depths > 0 in "
            "both" + hint)
    if any(bad.values()):
        out["notes"].append(
            f"no scale: the {' and the '.join(k for k, v in bad.items() if v)} "
            f"{'have' if all(bad.values()) else 'has'} depths <= 0, as an orthographic depth "
            "(mean 0, defined up to an offset) has; MADE needs z-depths > 0")
    else:
        out["made"], err, out["scale"] = _made(est, gt, m)
        out["rmse_scaled"] = float(np.sqrt(np.mean(err[m] ** 2)))
    if perspective:
        out["notes"].append("no normalised error: a perspective result is scored after a "
                            "scale (MADE), not an offset")
        if out["made"] is not None:
            _pieces_note(est, gt, m, region, out)
            if against:
                _warn_against(corr, camera=True)
    else:
        if against and out["made"] is not None:  # (positive depths against the truth's: a
            # disparity or a positive height scored without a camera was given pixel-size
            # advice and a normalised error, a review)
            _warn_against(corr, camera=False)
            out["notes"].append("no normalised error: the result's depths are all > 0 and "
                                "run against the truth's")
            return out
        out["range_ratio"] = ratio = _range_check(est, gt, m, words, region, against)
        off = ratio is not None and not 1.0 / RANGE_MISMATCH <= ratio <= RANGE_MISMATCH
        if off and not against and (est[m] > 0).all() and (gt[m] > 0).all():  # (a perspective
            # result
            # scored without its camera:
            # its "normalised error" of 20.8 % on the bear was a number without meaning, a
            # reproduction; the warning above says how to score it)
            out["notes"].append("no normalised error: the result's depths are all > 0 and "
                                "its range is not the truth's, as a perspective result "
                                "scored without its camera")
            return out
        try:  # (where the ranges differ, said above: not again as a spread)
            out["normalized_error"], _ = _normalized(*_offset_aligned(est, gt, m, not off,
                                                                      region))
        except ValueError as e:  # (a flat truth: zero depth range)
            out["notes"].append(f"no normalised error: {e}")
        else:
            _outlier_range_check(gt, m)
            _sign_check(est, gt, m, out["normalized_error"], region, corr)
            _offsets_note(est, gt, m, mask, region, out)
    return out


#: Share of the mask's pixels with a defined ground truth that the result must define before
#: :func:`evaluate` warns that it leaves many out (they are left out of every score: a result
#: that leaves its hard pixels undefined scored better, and one stored upside down lost a
#: third of the bear without a word, a review).
COVERAGE = 0.95


def _coverage_check(est, gt, mask) -> float | None:
    """The share of `mask`'s pixels with a finite truth where `est` is finite too (None where
    the truth has none), with a warning below :data:`COVERAGE`."""
    from ._warnings import warn

    known = np.asarray(mask, bool) & np.isfinite(gt)
    n = int(known.sum())
    if n == 0:
        return None
    lost = int(np.count_nonzero(known & ~np.isfinite(est)))
    if lost > (1.0 - COVERAGE) * n:
        warn(f"the result is undefined (NaN) at {lost} of the {n} mask pixels where the ground "
             f"truth is defined ({100.0 * lost / n:.3g} %): every score leaves them out, so a "
             "result that leaves its hard pixels undefined scores better than one that fills "
             "them. Is it of the same view and crop (not flipped or shifted) and of this mask?")
    return (n - lost) / n


def _correlation(est, gt, m, region) -> float | None:
    """The correlation of the result's and the truth's depths over `m`, each piece of the
    result (:func:`_pieces`) less its mean; None where either does not vary."""
    e, g = _piece_centred(est, gt, m, region)
    scale = float(np.sqrt(np.sum(e * e) * np.sum(g * g)))
    return float(np.sum(e * g)) / scale if scale > 0 else None


def _warn_against(corr: float, *, camera: bool) -> None:
    """A result whose depths run against the truth's (:data:`HEIGHT_CORRELATION`): a height
    of 10 + (max - depth) / 0.397 scored MADE 561.7 on the bear with its camera, a disparity
    17.7, without a word (a review). Correct results can do it too, where the normals cannot
    show the depth jumps between faces tilted against them (slats, shingles: a review's
    blinds, -0.98): the warning names that as well."""
    from ._warnings import warn

    warn(f"the result's depths run against the ground truth's (correlation {corr:.2f}): a "
         "height (larger = nearer), a disparity (1 / depth), a surface integrated inside out "
         "(its normals in another frame), or depth jumps the normals cannot show (faces "
         "tilted against the jumps between them, as slats are)? "
         + ("A perspective result is the camera's z-depth, larger = farther; MADE scores it "
            "as given" if camera else "Scored as given, with no normalised error: facetlift's "
            "depth is larger = farther"))


def _offsets_note(est, gt, m, mask, region, out) -> None:
    """A note where an orthographic result has more pieces over the scored pixels than the
    ground truth: the normalised error aligns each piece of the result by its own offset, so
    a result cut by lines of undefined pixels was forgiven its offsets between them (a tilted
    face: 7.54 % whole, 1.84 % cut into 16 pieces by 1-pixel NaN lines, a review); the error
    with one offset per piece of the truth beside it."""
    def count(labels):
        return int(np.unique(labels).size)

    truth = np.isfinite(gt) if mask is None else np.asarray(mask, bool) & np.isfinite(gt)
    own, theirs = _pieces(m, region)[0], _pieces(m, truth)[0]
    if count(own) <= count(theirs):
        return
    with np.errstate(all="ignore"):
        joined, _ = _normalized(*_offset_aligned(est, gt, m, False, truth))
    out["notes"].append(
        f"the result has {count(own)} separate pieces over the scored pixels where the ground "
        f"truth has {count(theirs)}: the normalised error aligns each piece of the result by "
        "its own offset (the paper's), so the offsets between them are not scored; with one "
        f"offset per piece of the ground truth it is {100.0 * joined:.4g} % (separate objects "
        "integrated without a prior have offsets no normal shows: there the first is the "
        "fair one)")


def _pieces_note(est, gt, m, region, out) -> None:
    """A note where a perspective result has several pieces: each piece's scale is free
    unless a depth prior fixed it, and MADE's one median scale (BiNI's evaluation) then
    scores the scales between them (two exact spheres scored 1.86 with 0.0007 and 0.0016
    each, without a word, a review): MADE with one median scale per piece beside it."""
    k, n = _pieces(m, region)
    k = np.unique(k, return_inverse=True)[1].ravel()  # (the pieces with scored pixels only:
    n = int(k.max()) + 1 if k.size else 0  # one the mask leaves out was counted, a review)
    if n < 2:
        return
    from scipy import ndimage

    e, g = est[m], gt[m]
    scale = np.atleast_1d(ndimage.median(g / e, k + 1, np.arange(1, n + 1)))
    each = float(np.mean(np.abs(scale[k] * e - g)))
    out["notes"].append(
        f"the result has {n} separate pieces: without a depth prior each piece's scale is "
        "free, and MADE takes one median scale for all (as BiNI's evaluation does), so it "
        f"scores their scales too; with a median scale per piece it is {each:.6g}")


#: Share of the scored pixels at which both depths are exactly 0 above which, without a mask,
#: :func:`evaluate` warns of a background stored as 0.
ZERO_BACKGROUND = 0.05


def _zero_background_check(est, gt, m) -> None:
    """A warning where, without a mask, many scored pixels hold exactly 0 in both depths: a
    background stored as 0, scored as surface (an audit: 47 % error and advice to change
    the pixel size, 0.0146 % with NaN backgrounds)."""
    from ._warnings import warn

    both = int(np.count_nonzero((est[m] == 0) & (gt[m] == 0)))
    if both > ZERO_BACKGROUND * int(m.sum()):
        warn(f"{both} of the {int(m.sum())} pixels scored hold depth 0 in both the result and "
             "the ground truth: a background stored as 0? It is scored as surface; store NaN "
             "there, or give a mask (--mask, mask=); if the surface does lie at depth 0 there, "
             "all is well")


#: Correlation of the result's and the truth's depths (each piece less its mean) below which,
#: with the negated result scoring at most half the error, :func:`evaluate` warns that the
#: result looks like a height.
HEIGHT_CORRELATION = -0.8


def _sign_check(est, gt, m, error: float, region, corr: float | None) -> None:
    """A warning where an orthographic result looks like a height (``-depth``: another tool's
    convention, or facetlift's height map read as depth): its depths run against the truth's
    (:data:`HEIGHT_CORRELATION`) and negated it scores at most half the error (20.7 % as
    given, 0.0076 % negated, without a word, an audit)."""
    from ._warnings import warn

    if corr is None or corr > HEIGHT_CORRELATION:  # (:func:`_correlation`)
        return
    with np.errstate(all="ignore"):
        flipped, _ = _normalized(*_offset_aligned(-est, gt, m, False, region))
    if flipped <= 0.5 * error:
        warn(f"the result's depths run against the ground truth's (correlation "
             f"{corr:.2f}); negated it scores {100 * flipped:.3g} % "
             f"instead of {100 * error:.3g} %: is it a height (-depth)? (Or are there "
             "depth jumps its normals cannot show, between faces tilted against them?) "
             "facetlift's depth is "
             "larger = farther (a height map of facetlift's, height.exr, is read back as "
             "depth by facetlift.io.read_depth)")


#: Ratio of the ground truth's full depth range (max - min: the normalised error's scale) to
#: its 1st-99th percentile range above which :func:`evaluate` warns that a few pixels set it.
OUTLIER_RANGE = 3.0


def _outlier_range_check(gt, m) -> None:
    """A warning where a few ground-truth pixels set the normalised error's depth range (a
    hole stored as 0 in a float map: one such pixel took the bear's error from 2.30 % to
    0.07 %, 33x lower, without a word, an audit)."""
    from ._warnings import warn

    full = float(gt[m].max() - gt[m].min())
    lo, hi = np.percentile(gt[m], [1, 99])
    if hi > lo and full > OUTLIER_RANGE * (hi - lo):
        k = int(np.argmax(np.abs(gt[m] - np.median(gt[m]))))
        r, c = np.argwhere(m)[k]
        warn(f"the ground truth's depth range over the pixels scored ({full:.4g}, which scales "
             f"the normalised error) is {full / (hi - lo):.3g} times its 1st-99th percentile "
             f"range: a few pixels set it (the farthest from the median at (row {r}, col {c}): "
             f"{float(gt[r, c])!r}), and the error reads that much lower; a hole stored as 0 "
             "or another value must be NaN, or left out of the mask")


def facet_normals(vertex_depth, *, pixel_size: float = 1.0, K=None, camera=None) -> np.ndarray:
    """Normals of the facets of a vertex depth grid, from the cross product of the diagonals.

    For an orthographic grid this is the normal ``(-s_x, -s_y, 1)`` of the facet's least-squares
    plane, ``s_x = ((z1 + z2) - (z0 + z3)) / 2h`` and ``s_y = ((z0 + z1) - (z2 + z3)) / 2h``
    (heights ``z = -depth`` at corners 0..3 in the conventional order, y up). For a perspective
    grid (`K` given) the vertices are back-projected first.

    Parameters
    ----------
    vertex_depth : (H+1, W+1) array_like of float
    pixel_size : float
    K : (3, 3) array_like, optional
    camera : facetlift.camera.Camera, optional
        Instead of `pixel_size` and `K`.

    Returns
    -------
    (H, W, 3) float
        Unit normals toward the viewer, NaN where a corner is undefined.
    """
    vd = np.asarray(vertex_depth, dtype=float)
    if vd.ndim != 2 or min(vd.shape) < 2:
        raise ValueError(f"`vertex_depth` must be an (H+1, W+1) array; got shape {vd.shape}")
    from .camera import make_camera

    cam = make_camera(pixel_size, K) if camera is None else camera
    return _grid_normals(vd, cam)


def _grid_normals(vd: np.ndarray, cam, row0: int = 0) -> np.ndarray:
    """:func:`facet_normals` of vertex rows `vd` whose first row is the grid's row `row0`."""
    i, j = np.mgrid[row0 : row0 + vd.shape[0], 0 : vd.shape[1]]
    P = cam.points(i.ravel(), j.ravel(), vd.ravel()).reshape(vd.shape + (3,))
    return _quad_normals(P[:-1, :-1], P[:-1, 1:], P[1:, 1:], P[1:, :-1])


def _quad_normals(P0, P1, P2, P3) -> np.ndarray:
    """Unit normals of quads with corners P0..P3 (conventional order), toward the viewer."""
    n = np.cross(P3 - P1, P2 - P0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


#: :func:`input_deviation` averages over at most this many facets, evenly spaced. 2^16 since
#: 2026-12-03 (2^18 before; the diagnostic took a quarter of a 512^2 rectangle's run).
DEVIATION_SAMPLE = 2**16


#: Rows of facets whose normals :func:`surface_normals` and :func:`surface_normal_rows` form at
#: a time: the whole frame at once took 2.7 GB of temporaries at 4096^2 for a 0.8 MB
#: preview.png, more than the solve, and a job that fit died writing it (a review).
NORMAL_ROWS = 256


def surface_normal_rows(surface):
    """The facet normals of :func:`surface_normals` by blocks of :data:`NORMAL_ROWS` rows:
    yields ``(r0, r1, normals)``, normals (r1 - r0, W, 3)."""
    m = surface.mask
    H, W = m.shape
    split = surface.split is not None
    if split:  # (each block's facets, in the facets' row-major order over the mask)
        starts = np.concatenate([[0], np.cumsum(m.sum(axis=1))])
    for r0 in range(0, H, NORMAL_ROWS):
        r1 = min(r0 + NORMAL_ROWS, H)
        if not split:
            vd = np.asarray(surface.vertex_depth[r0:r1 + 1], dtype=float)
            yield r0, r1, _grid_normals(vd, surface.camera, r0)
            continue
        out = np.full((r1 - r0, W, 3), np.nan)
        rr, cc = np.nonzero(m[r0:r1])
        out[rr, cc] = _own_normals(surface, rr + r0, cc,
                                   np.arange(int(starts[r0]), int(starts[r1])))
        yield r0, r1, out


def surface_normals(surface) -> np.ndarray:
    """(H, W, 3) unit facet normals of a result, toward the viewer, NaN outside its mask: from
    each facet's own corners where the surface is split at jumps (``discontinuities=True``),
    else from the vertex grid (:func:`facet_normals`), formed by blocks of rows
    (:func:`surface_normal_rows`)."""
    out = np.empty((*surface.mask.shape, 3))
    for r0, r1, n in surface_normal_rows(surface):
        out[r0:r1] = n
    return out


def _own_normals(surface, r, c, k) -> np.ndarray:
    """Unit normals (n, 3) of the facets at pixels (`r`, `c`), number `k` in the surface's facet
    order (row-major over its mask): from each facet's own corners where the surface is split at
    jumps (a facet next to a cut keeps its plane), else from the vertex grid."""
    corners = ((0, 0), (0, 1), (1, 1), (1, 0))
    if surface.split is not None:
        sc, _, _, sdepth = surface.split
        P = [surface.camera.points(r + dr, c + dc, sdepth[sc[k, j]])
             for j, (dr, dc) in enumerate(corners)]
    else:
        vd = surface.vertex_depth
        P = [surface.camera.points(r + dr, c + dc, vd[r + dr, c + dc]) for dr, dc in corners]
    return _quad_normals(*P)


def input_deviation(problem, surface, *, sample: int = DEVIATION_SAMPLE) -> float:
    """Mean angle in degrees between the usable input normals and the facet normals of the
    result (from each facet's own corners where the surface is split at jumps), over at most
    `sample` usable facets evenly spaced in row-major order (exact up to 65,536); NaN when
    no facet is usable.

    Parameters
    ----------
    problem : facetlift.Problem
    surface : facetlift.Surface
        The result on the problem's domain (same shape and camera).
    """
    return _mean(_deviations(problem, surface, sample))


def _mean(values: np.ndarray) -> float:
    return float(values.mean()) if values.size else float("nan")


#: Deviation (degrees) above which a facet counts in ``info["deviation_over_10"]``.
DEVIATION_LARGE = 10.0


def _deviations(problem, surface, sample: int) -> np.ndarray:
    """The angles (degrees) of :func:`input_deviation`, one per sampled usable facet."""
    k = np.flatnonzero(problem.usable)
    if k.size == 0:
        return np.zeros(0)
    if k.size > sample:
        k = k[:: -(-k.size // sample)]
    r, c = (a[k] for a in problem.domain.pixels)
    nrec = _own_normals(surface, r, c, k)
    cos = np.clip(np.einsum("ij,ij->i", nrec, problem.normals[k]), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def diagnose(problem, surface) -> dict:
    """What :func:`facetlift.solve` adds to ``Surface.info`` about the result and its input:
    ``mean_deviation`` (:func:`input_deviation`, degrees), ``deviation_over_10`` (the share of
    those facets that deviate by more than :data:`DEVIATION_LARGE` degrees: where a smooth
    integration bends across depth jumps, the command line suggests ``--discontinuities``) and
    ``integrability`` (:func:`facetlift.frames.flip_check`, which warns when a flipped map
    would be far more integrable)."""
    from .frames import flip_check

    angles = _deviations(problem, surface, DEVIATION_SAMPLE)
    return {"mean_deviation": _mean(angles),
            "deviation_over_10": _mean(angles > DEVIATION_LARGE),
            "integrability": flip_check(problem)}


def angular_error(surface, normals, mask=None) -> tuple[float, float, np.ndarray]:
    """Angle between a reconstructed surface's facet normals and the input normals (Fig. 10).

    Parameters
    ----------
    surface : facetlift.Surface
        Uses ``vertex_depth`` and ``camera``, or each facet's own corners where the surface is
        split at jumps (``discontinuities=True``).
    normals : (H, W, 3) array_like
        The input normals (x right, y up, z toward the viewer); need not be unit; uint8 /
        uint16 decoded as :func:`facetlift.integrate` decodes them (``v / max * 2 - 1``, with
        a warning).
    mask : (H, W) array_like of bool, optional
        Default: the surface's mask.

    Returns
    -------
    mean_deg, max_deg : float
    error : (H, W) float
        Degrees, NaN outside the compared pixels.
    """
    if not all(hasattr(surface, a) for a in ("mask", "camera", "vertex_depth")):
        # (the advice was metrics.facet_normals, whose (H + 1, W + 1) corner depths another
        # tool's depth map is not, a review)
        raise ValueError(f"`surface` must be a facetlift.Surface (its camera and mask give the "
                         f"facet normals); got {type(surface).__name__}: for another "
                         "tool's depth map, facetlift.Surface.from_depth(depth, mask, K=K) "
                         "makes one")
    from .frames import as_float_normals

    # (a uint8/uint16 map decoded as integrate decodes it: taken raw, the bear's PNG read
    # 41.3 deg against its 0.88, an audit)
    nin = np.asarray(as_float_normals(np.asarray(normals), "normals"), dtype=float)
    H, W = surface.mask.shape
    if nin.shape != (H, W, 3):
        raise ValueError(f"`normals` must have shape {(H, W, 3)}; got {nin.shape}")
    nrec = surface_normals(surface)
    m = surface.mask if mask is None else np.asarray(mask, bool) & surface.mask
    with np.errstate(invalid="ignore", divide="ignore"):
        u = nin / np.linalg.norm(nin, axis=-1, keepdims=True)
        cross = np.linalg.norm(np.cross(u, nrec), axis=-1)
        ang = np.degrees(np.arctan2(cross, np.einsum("...i,...i->...", u, nrec)))
    m = m & np.isfinite(ang)
    if not m.any():
        raise ValueError("no pixel where both the surface and `normals` are defined")
    err = np.where(m, ang, np.nan)
    return float(err[m].mean()), float(err[m].max()), err
