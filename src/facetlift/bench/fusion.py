"""The fusion benchmark (``facetlift bench --experiments fusion``): normals with a depth prior.

Scenes are the discontinuity development scenes (:func:`facetlift.bench.discontinuities.scenes`:
DiLiGenT-like perspective renders of the data folder's meshes, orthographic renders and the
analytic jump scenes), exact normals. Every scene is integrated with each prior of
:func:`priors`:

``sparse f%``
    A fraction f (0.1 %, 1 %, 5 %) of the mask pixels with their exact depth (seeded).
``noisy f%``
    The same samples with Gaussian noise of 1 % of the scene's depth range.
``coarse``
    A monocular-network-like dense prior: the true depth averaged over 8 x 8 blocks, blurred
    by a Gaussian of one block and upsampled bilinearly.
``coarse blur``
    The same coarse prior given as what it is, a blurred one (``prior_blur`` =
    :data:`BLUR_SIGMA`, docs/fusion.md, "Blurred priors"): compared with the result blurred
    alike. Only for the columns whose method has the ``prior_blur`` capability.
``conf``
    A planted disk of corrupted normals (rotated by 30 degrees about a random axis) with the
    1 % exact samples, three ways: the corrupted normals as they are, the same with confidence
    0 on the disk, and the disk's normals missing (NaN).

Reported per run, for the fused result and the prior alone (sparse samples interpolated
linearly over the mask, nearest-neighbour fill outside their hull): the error as it is, without
any alignment (orthographic: mean absolute depth error in % of the depth range; perspective:
MADE in mm, the render's units), which is what the prior buys; and the error after the
alignment every method gets alike (:func:`aligned_error`: best offset per connected component
orthographically, median scale in perspective), beside the normals-only error after that same
alignment. "Beats both" compares the aligned figures, like for like. Also the MADE (scene
units), the time, the time of the same integration without a prior and the CG iterations.
``coarse w=...`` rows repeat the coarse prior at the other weights of
``Settings.fusion_coarse_weights`` (the sweep its default weight was chosen from).
"""

from __future__ import annotations

import logging
import time
import warnings
import zlib

import numpy as np

from .. import methods
from . import discontinuities as disc
from .core import SEED, Context
from .tables import md_table, write_csv, write_text

log = logging.getLogger(__name__)

#: The integrations compared: (label, method, options).
COLUMNS = (("dgp", "dgp", {}), ("dgp-disc", "dgp", {"discontinuities": True}),
           ("poisson", "poisson", {}))

#: Prior weight of the benchmark's runs, per kind of prior (docs/fusion.md: exact samples
#: are trusted far more than one pixel's normal; noisy and coarse priors less). The coarse
#: prior's weight was chosen on the whole benchmark (every scene, both dgp routes) from the
#: sweep of ``fusion_coarse_weights``, not on one scene: docs/fusion.md, "Dense priors"; the
#: blurred one's likewise from ``fusion_blur_weights`` (docs/fusion.md, "Blurred priors").
WEIGHTS = {"sparse": 100.0, "noisy": 1.0, "coarse": 1e-2, "conf": 100.0, "blur": 3e-3}

#: Noise of the ``noisy`` priors, as a share of the depth range; block size of ``coarse``.
NOISE, BLOCK = 0.01, 8

#: The coarse prior's blur as one Gaussian (``prior_blur`` of the ``coarse blur`` rows): the
#: standard deviations of its three stages added in quadrature, block means (``BLOCK^2 /
#: 12``), the Gaussian of one block (``BLOCK^2``) and the bilinear upsampling (``BLOCK^2 / 6``):
#: 8.94 px for blocks of 8. What a user knows of a depth map upsampled from a coarse grid.
BLUR_SIGMA = BLOCK * float(np.sqrt(1 / 12 + 1 + 1 / 6))

#: Corruption of the ``conf`` scenes: disk radius (share of the mask's extent), rotation.
CORRUPT_RADIUS, CORRUPT_DEG = 0.15, 30.0


def _rng(name: str, what: str) -> np.random.Generator:
    return np.random.default_rng([SEED, zlib.crc32(f"{name}:{what}".encode())])


def sparse_prior(gt, fraction: float, rng, noise: float = 0.0) -> np.ndarray:
    """(H, W) prior with `fraction` of the mask's pixels (at least 3) at their true depth
    (plus Gaussian noise of `noise` times the depth range), NaN elsewhere."""
    idx = np.flatnonzero(gt.mask.ravel())
    k = max(3, int(round(fraction * idx.size)))
    pick = rng.choice(idx, size=min(k, idx.size), replace=False)
    out = np.full(gt.mask.size, np.nan)
    out[pick] = gt.depth.ravel()[pick]
    if noise:
        out[pick] += rng.normal(0.0, noise * gt.depth_range, pick.size)
    return out.reshape(gt.mask.shape)


def coarse_prior(gt, block: int = BLOCK) -> np.ndarray:
    """(H, W) dense prior: the depth downsampled `block` times (block means over the mask's
    pixels), blurred by a Gaussian of sigma one block, upsampled bilinearly, NaN outside the
    mask.

    The downsampling and blur are one normalised convolution of first order: at each block
    centre, the plane fitted to the mask's depths with the block-and-Gaussian weights. Inside
    the mask it is the plain blurred block mean (the weights are symmetric about the centre,
    so the plane's slopes drop out); at the mask's edge, where a block holds only part of its
    pixels, the plain mean would sit at their centroid, not at the block centre, and bias a
    sloped surface by up to half a block of slope. Blocks with too few pixels for a plane
    keep the mean; every value is kept within the depths of the 5 x 5 blocks around it,
    widened by half their range (a plane fitted to a sliver extrapolates); blocks with none
    take the nearest block's value.
    """
    from scipy import ndimage

    H, W = gt.mask.shape
    hb, wb = -(-H // block), -(-W // block)
    m = np.zeros((hb * block, wb * block))
    m[:H, :W] = gt.mask
    d = np.zeros_like(m)
    d[:H, :W] = np.where(gt.mask, gt.depth, 0.0)
    y, x = np.indices(m.shape, dtype=float)

    def blurred_sum(a):
        return ndimage.gaussian_filter(a.reshape(hb, block, wb, block).sum(axis=(1, 3)), 1.0)

    # weighted moments about the block centres (Y, X), in blocks (keeps the 3x3 fits scaled)
    Y = ((np.arange(hb) + 0.5) * block - 0.5)[:, None]
    X = ((np.arange(wb) + 0.5) * block - 0.5)[None, :]
    yb, xb = y / block, x / block
    s0, sx, sy = blurred_sum(m), blurred_sum(m * xb), blurred_sum(m * yb)
    sxx, sxy, syy = blurred_sum(m * xb**2), blurred_sum(m * xb * yb), blurred_sum(m * yb**2)
    sd, sdx, sdy = blurred_sum(d), blurred_sum(d * xb), blurred_sum(d * yb)
    Xb, Yb = X / block, Y / block
    A = np.empty((hb, wb, 3, 3))
    A[..., 0, 0] = s0
    A[..., 0, 1] = A[..., 1, 0] = sx - Xb * s0
    A[..., 0, 2] = A[..., 2, 0] = sy - Yb * s0
    A[..., 1, 1] = sxx - 2 * Xb * sx + Xb**2 * s0
    A[..., 1, 2] = A[..., 2, 1] = sxy - Xb * sy - Yb * sx + Xb * Yb * s0
    A[..., 2, 2] = syy - 2 * Yb * sy + Yb**2 * s0
    b = np.stack([sd, sdx - Xb * sd, sdy - Yb * sd], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.where(s0 > 1e-3, sd / s0, np.nan)
        good = (s0 > 1e-3) & (np.linalg.cond(A) < 1e6)
    low[good] = np.linalg.solve(A[good], b[good][..., None])[:, 0, 0]
    # a plane fitted to a sliver of pixels far from the centre (a grazing wall) extrapolates
    # wildly: keep the value within the depths of the blocks around (+-2, the blur's reach)
    big = np.where(m > 0, d, np.inf).reshape(hb, block, wb, block).min(axis=(1, 3))
    top = np.where(m > 0, d, -np.inf).reshape(hb, block, wb, block).max(axis=(1, 3))
    lo, hi = ndimage.minimum_filter(big, 5), ndimage.maximum_filter(top, 5)
    with np.errstate(invalid="ignore"):
        low = np.clip(low, lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))
    return _upsampled(low, gt.mask, block)


def _upsampled(low, mask, block):
    """Block values `low` (NaN where a block has none: filled from the nearest) bilinearly
    upsampled to the pixels (block centres at ``(k + 1/2) block - 1/2``), NaN off `mask`."""
    from scipy import ndimage

    if np.isnan(low).any():
        _, (ii, jj) = ndimage.distance_transform_edt(np.isnan(low), return_indices=True)
        low = low[ii, jj]
    H, W = mask.shape
    r = (np.arange(H) + 0.5) / block - 0.5
    col = (np.arange(W) + 0.5) / block - 0.5
    up = ndimage.map_coordinates(low, np.meshgrid(r, col, indexing="ij"), order=1,
                                 mode="nearest")
    return np.where(mask, up, np.nan)


def _coarse_prior_mean(gt, block: int = BLOCK) -> np.ndarray:
    """The zeroth-order construction (blurred block means of the mask's pixels), kept for the
    comparison in docs/fusion.md."""
    from scipy import ndimage

    H, W = gt.mask.shape
    hb, wb = -(-H // block), -(-W // block)
    d = np.zeros((hb * block, wb * block))
    m = np.zeros_like(d)
    d[:H, :W] = np.where(gt.mask, gt.depth, 0.0)
    m[:H, :W] = gt.mask
    s = ndimage.gaussian_filter(d.reshape(hb, block, wb, block).sum(axis=(1, 3)), 1.0)
    c = ndimage.gaussian_filter(m.reshape(hb, block, wb, block).sum(axis=(1, 3)), 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.where(c > 1e-3, s / c, np.nan)
    return _upsampled(low, gt.mask, block)


def interpolate(prior: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The prior alone as a depth map over `mask`: linear interpolation of its samples,
    nearest-sample fill outside their convex hull (dense priors are returned as they are)."""
    have = np.isfinite(prior) & mask
    if have.sum() >= 0.9 * mask.sum():
        return np.where(mask, prior, np.nan)
    from scipy.interpolate import griddata

    pts = np.argwhere(have)
    vals = prior[have]
    q = np.argwhere(mask)
    out = np.full(mask.shape, np.nan)
    lin = np.full(len(q), np.nan)
    # a triangulation needs samples that span the plane (a thin scene's few samples can lie
    # on one line: then the nearest sample everywhere)
    if len(pts) >= 4 and np.linalg.matrix_rank(pts - pts.mean(axis=0)) == 2:
        lin = griddata(pts, vals, q, method="linear")
    near = griddata(pts, vals, q, method="nearest")
    out[mask] = np.where(np.isfinite(lin), lin, near)
    return out


def corrupt(gt, rng):
    """(normals with a corrupted disk, the disk (H, W) bool)."""
    rows, cols = np.nonzero(gt.mask)
    k = rng.integers(rows.size)
    radius = CORRUPT_RADIUS * max(np.ptp(rows), np.ptp(cols), 4)
    r, c = np.indices(gt.mask.shape)
    disk = gt.mask & ((r - rows[k]) ** 2 + (c - cols[k]) ** 2 < radius**2)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    a = np.radians(CORRUPT_DEG)
    Kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(a) * Kx + (1 - np.cos(a)) * Kx @ Kx
    n = gt.normals.copy()
    bent = n[disk] @ R.T
    bent[:, 2] = np.abs(bent[:, 2]) + 0.05  # keep them facing the camera
    n[disk] = bent / np.linalg.norm(bent, axis=1, keepdims=True)
    return n, disk


def priors(gt, name: str, settings) -> list[tuple[str, str, np.ndarray, dict]]:
    """(condition, kind, prior, extra integrate kwargs) of a scene."""
    out = []
    for f in settings.fusion_fractions:
        out.append((f"sparse {100 * f:g}%", "sparse", sparse_prior(gt, f, _rng(name, f"s{f}")),
                    {}))
    for f in settings.fusion_fractions:
        out.append((f"noisy {100 * f:g}%", "noisy",
                    sparse_prior(gt, f, _rng(name, f"s{f}"), noise=NOISE), {}))
    coarse = coarse_prior(gt)
    out.append(("coarse", "coarse", coarse, {}))
    out.append(("coarse blur", "blur", coarse, {"prior_blur": BLUR_SIGMA}))
    for w in settings.fusion_blur_weights:
        if w != WEIGHTS["blur"]:
            out.append((f"coarse blur w={w:g}", "blur", coarse,
                        {"prior_weight": w, "prior_blur": BLUR_SIGMA}))
    for w in settings.fusion_coarse_weights:
        if w != WEIGHTS["coarse"]:
            out.append((f"coarse w={w:g}", "coarse", coarse, {"prior_weight": w}))
    return out


def aligned_error(gt, depth) -> float:
    """The error after the alignment every method gets alike: orthographic, the best offset
    per connected component (the paper's normalised error, in %); perspective, the median
    scale (BiNI's MADE, mm). The normals-only figure is always this one."""
    return disc.error_of(gt, depth)


def abs_errors(gt, depth) -> tuple[float, float]:
    """(error, MADE) without any alignment: error in % of the depth range (orthographic) or
    MADE (perspective); MADE the mean absolute depth error in scene units."""
    m = gt.mask & np.isfinite(depth)
    made = float(np.mean(np.abs(depth[m] - gt.depth[m])))
    err = made if gt.K is not None else 100.0 * made / gt.depth_range
    return err, made


def _integrate(gt, normals, method, options, **kw):
    from ..api import integrate

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = integrate(normals, gt.mask, method=method, pixel_size=gt.pixel_size, K=gt.K,
                      **options, **kw)
    return s, time.perf_counter() - t0


def _cg(info):
    """Total CG iterations of a result's info (a list for the reweighting route)."""
    its = info.get("cg_iterations")
    if isinstance(its, (list, tuple)):
        return int(sum(its))
    return None if its is None else int(its)


def run_scene(ctx: Context, group: str, name: str, gt) -> list[dict]:
    """Every column under every prior of one scene, and the confidence check."""
    rows = []
    base = {"group": group, "scene": name, "pixels": int(gt.mask.sum())}
    # the priors and the prior-alone errors are the same for every column
    inputs = []
    for cond, kind, prior, kw in priors(gt, name, ctx.settings):
        alone = interpolate(prior, gt.mask)
        inputs.append((cond, prior, kw.get("prior_weight", WEIGHTS[kind]),
                       abs_errors(gt, alone)[0], aligned_error(gt, alone),
                       {k: v for k, v in kw.items() if k != "prior_weight"}))
    for label, method, options in COLUMNS:
        if label not in ctx.settings.fusion_columns:
            continue
        try:
            s0, t_plain = _integrate(gt, gt.normals, method, options)
            plain = disc.error_of(gt, s0.depth)
        except Exception as e:
            rows.append({**base, "method": label, "condition": "normals only",
                         "status": "failed", "message": f"{type(e).__name__}: {e}"[:200]})
            continue
        rows.append({**base, "method": label, "condition": "normals only", "status": "ok",
                     "normals_error": plain, "seconds": t_plain, "cg_iterations": _cg(s0.info),
                     "backend": s0.info.get("backend")})
        for cond, prior, weight, perr, palign, extra in inputs:
            if "prior_blur" in extra and not methods.get(method).prior_blur:
                continue  # (the method compares a prior pixel by pixel only)
            row = {**base, "method": label, "condition": cond, "normals_error": plain,
                   "plain_seconds": t_plain,
                   "samples": int((np.isfinite(prior) & gt.mask).sum()),
                   "prior_weight": weight}
            try:
                s, sec = _integrate(gt, gt.normals, method, options, prior=prior,
                                    prior_weight=weight, **extra)
            except Exception as e:
                rows.append({**row, "status": "failed",
                             "message": f"{type(e).__name__}: {e}"[:200]})
                continue
            err, made = abs_errors(gt, s.depth)
            rows.append({**row, "status": "ok", "error": err, "made": made,
                         "prior_error": perr, "aligned_error": aligned_error(gt, s.depth),
                         "prior_aligned": palign, "seconds": sec,
                         "cg_iterations": _cg(s.info),
                         "time_ratio": sec / t_plain if t_plain > 0 else None})
        rows += confidence_rows(ctx, base, label, method, options, gt, name)
    return rows


def confidence_rows(ctx, base, label, method, options, gt, name) -> list[dict]:
    """Corrupted normals with 1 % exact samples: as they are, confidence 0 on the corrupted
    disk, and the disk's normals missing."""
    n, disk = corrupt(gt, _rng(name, "corrupt"))
    prior = sparse_prior(gt, 0.01, _rng(name, "s0.01"))
    conf = np.where(disk, 0.0, 1.0)
    missing = np.where(disk[..., None], np.nan, n)
    out = []
    for cond, normals, kw in (("corrupt", n, {}), ("corrupt conf0", n, {"confidence": conf}),
                              ("corrupt missing", missing, {})):
        row = {**base, "method": label, "condition": cond, "samples": int(disk.sum()),
               "prior_weight": WEIGHTS["conf"]}
        try:
            s, sec = _integrate(gt, normals, method, options, prior=prior,
                                prior_weight=WEIGHTS["conf"], **kw)
        except Exception as e:
            out.append({**row, "status": "failed", "message": f"{type(e).__name__}: {e}"[:200]})
            continue
        err, made = abs_errors(gt, s.depth)
        out.append({**row, "status": "ok", "error": err, "made": made,
                    "aligned_error": aligned_error(gt, s.depth), "seconds": sec})
    return out


def summary(rows: list[dict]) -> list[dict]:
    """Per group, method and condition: mean error, MADE, normals-only and prior-only error,
    the scenes where the fusion beats both, time ratio."""
    out = []
    keys = dict.fromkeys((r["group"], r["method"], r["condition"]) for r in rows)
    for group, method, cond in keys:
        sub = [r for r in rows if (r["group"], r["method"], r["condition"]) == (group, method,
                                                                                  cond)
               and r["status"] == "ok"]
        if not sub:
            continue
        row = {"group": group, "method": method, "condition": cond, "scenes": len(sub)}
        for key in ("error", "made", "aligned_error", "normals_error", "prior_error",
                    "prior_aligned", "time_ratio", "seconds"):
            vals = [r[key] for r in sub if r.get(key) is not None]
            if vals:
                row[key] = float(np.mean(vals))
        both = [r for r in sub if r.get("aligned_error") is not None
                and r.get("prior_aligned") is not None and r.get("normals_error") is not None]
        if both:  # like for like: all three after the same alignment
            wins = sum(r["aligned_error"] < min(r["prior_aligned"], r["normals_error"])
                       for r in both)
            row["beats_both"] = f"{wins}/{len(both)}"
        ratios = [r["time_ratio"] for r in sub if r.get("time_ratio") is not None]
        if ratios:
            row["max_time_ratio"] = float(np.max(ratios))
        out.append(row)
    return out


def fusion(ctx: Context) -> None:
    """Run the benchmark; writes ``fusion_runs.csv``, ``fusion.csv`` and ``fusion.md``."""
    rows = []
    data = [t for t in disc.scenes(ctx) if t[0] in ctx.settings.fusion_groups]
    for group, name, gt in disc.usable(ctx, data, "fusion"):
        rows += run_scene(ctx, group, name, gt)
        write_csv(ctx.out / "fusion_runs.csv", rows)
    table = summary(rows)
    write_csv(ctx.out / "fusion_runs.csv", rows)
    write_csv(ctx.out / "fusion.csv", table)
    n_scenes = len({(r["group"], r["scene"]) for r in rows})
    text = "\n".join([
        f"{n_scenes} scenes. error, prior_error: the fused result and the prior alone (sparse "
        "samples interpolated) without any alignment (orthographic: mean absolute depth error "
        "in % of the depth range; perspective: MADE in mm); aligned_error, prior_aligned, "
        "normals_error: the fused result, the prior alone and the same method without a prior "
        "after the same alignment (orthographic: best offset per connected component, the "
        "paper's normalised error; perspective: median scale, BiNI's MADE); beats_both: "
        "scenes where aligned_error < both prior_aligned and normals_error; made: mean "
        "absolute depth error (scene units); time_ratio: seconds with the prior / without.\n",
        md_table(table, ["group", "method", "condition", "scenes", "error", "prior_error",
                         "aligned_error", "prior_aligned", "normals_error", "beats_both",
                         "time_ratio", "max_time_ratio", "seconds"]),
        "\nPer scene:\n",
        md_table([r for r in rows if r["status"] == "ok"],
                 ["group", "scene", "method", "condition", "error", "prior_error",
                  "aligned_error", "prior_aligned", "normals_error", "time_ratio",
                  "cg_iterations"]),
    ])
    write_text(ctx.out / "fusion.md", text)
    ctx.add("Fusion: normals with a depth prior", text)
