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
``conf``
    A planted disk of corrupted normals (rotated by 30 degrees about a random axis) with the
    1 % exact samples, three ways: the corrupted normals as they are, the same with confidence
    0 on the disk, and the disk's normals missing (NaN).

Reported per run: the error of the result without any alignment (orthographic: mean absolute
depth error in % of the depth range; perspective: MADE in mm, the render's units), the MADE
(mean absolute depth error in scene units) for both, the time and the time of the same
integration without a prior; beside them the normals-only error (aligned as usual: the paper's
normalised error / BiNI's median-scaled MADE) and the prior-only error (the prior alone,
sparse samples interpolated linearly over the mask with nearest-neighbour fill outside their
hull).
"""

from __future__ import annotations

import logging
import time
import warnings
import zlib
from dataclasses import replace

import numpy as np

from . import discontinuities as disc
from .core import SEED, Context, bar
from .tables import md_table, write_csv, write_text

log = logging.getLogger(__name__)

#: The integrations compared: (label, method, options).
COLUMNS = (("dgp", "dgp", {}), ("dgp-disc", "dgp", {"discontinuities": True}),
           ("poisson", "poisson", {}))

#: Prior weight of the benchmark's runs, per kind of prior (docs/fusion.md: exact samples
#: are trusted far more than one pixel's normal; noisy and coarse priors less).
WEIGHTS = {"sparse": 100.0, "noisy": 1.0, "coarse": 0.05, "conf": 100.0}

#: Noise of the ``noisy`` priors, as a share of the depth range; block size of ``coarse``.
NOISE, BLOCK = 0.01, 8

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
    """(H, W) dense prior: the depth averaged over `block` x `block` blocks (mask pixels only),
    blurred by a Gaussian of sigma one block, upsampled bilinearly, NaN outside the mask."""
    from scipy import ndimage

    H, W = gt.mask.shape
    hb, wb = -(-H // block), -(-W // block)
    d = np.zeros((hb * block, wb * block))
    m = np.zeros_like(d)
    d[:H, :W] = np.where(gt.mask, gt.depth, 0.0)
    m[:H, :W] = gt.mask
    s = d.reshape(hb, block, wb, block).sum(axis=(1, 3))
    c = m.reshape(hb, block, wb, block).sum(axis=(1, 3))
    # normalised convolution: blur the block means where there are any, fill the others
    s = ndimage.gaussian_filter(s, 1.0)
    c = ndimage.gaussian_filter(c, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.where(c > 1e-3, s / c, np.nan)
    if np.isnan(low).any():
        _, (ii, jj) = ndimage.distance_transform_edt(np.isnan(low), return_indices=True)
        low = low[ii, jj]
    # bilinear upsampling with block centres at (k + 1/2) block - 1/2
    r = (np.arange(H) + 0.5) / block - 0.5
    col = (np.arange(W) + 0.5) / block - 0.5
    up = ndimage.map_coordinates(low, np.meshgrid(r, col, indexing="ij"), order=1,
                                 mode="nearest")
    return np.where(gt.mask, up, np.nan)


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
    lin = griddata(pts, vals, q, method="linear") if len(pts) >= 4 else np.full(len(q), np.nan)
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
    out.append(("coarse", "coarse", coarse_prior(gt), {}))
    return out


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


def run_scene(ctx: Context, group: str, name: str, gt) -> list[dict]:
    """Every column under every prior of one scene, and the confidence check."""
    rows = []
    base = {"group": group, "scene": name, "pixels": int(gt.mask.sum())}
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
                     "normals_error": plain, "seconds": t_plain})
        for cond, kind, prior, kw in priors(gt, name, ctx.settings):
            row = {**base, "method": label, "condition": cond, "normals_error": plain,
                   "plain_seconds": t_plain,
                   "samples": int((np.isfinite(prior) & gt.mask).sum()),
                   "prior_weight": WEIGHTS[kind]}
            try:
                s, sec = _integrate(gt, gt.normals, method, options, prior=prior,
                                    prior_weight=WEIGHTS[kind], **kw)
            except Exception as e:
                rows.append({**row, "status": "failed",
                             "message": f"{type(e).__name__}: {e}"[:200]})
                continue
            err, made = abs_errors(gt, s.depth)
            perr, _ = abs_errors(gt, interpolate(prior, gt.mask))
            rows.append({**row, "status": "ok", "error": err, "made": made,
                         "prior_error": perr, "seconds": sec,
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
        out.append({**row, "status": "ok", "error": err, "made": made, "seconds": sec})
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
        for key in ("error", "made", "normals_error", "prior_error", "time_ratio", "seconds"):
            vals = [r[key] for r in sub if r.get(key) is not None]
            if vals:
                row[key] = float(np.mean(vals))
        both = [r for r in sub if r.get("error") is not None and r.get("prior_error") is not None
                and r.get("normals_error") is not None]
        if both:
            wins = sum(r["error"] < min(r["prior_error"], r["normals_error"]) for r in both)
            row["beats_both"] = f"{wins}/{len(both)}"
        out.append(row)
    return out


def fusion(ctx: Context) -> None:
    """Run the benchmark; writes ``fusion_runs.csv``, ``fusion.csv`` and ``fusion.md``."""
    rows = []
    data = [t for t in disc.scenes(ctx) if t[0] in ctx.settings.fusion_groups]
    for group, name, load in bar(data, ctx.progress, "fusion"):
        try:
            gt = load()
        except Exception as e:
            log.warning("scene %s unavailable: %s", name, e)
            continue
        if gt.mask.sum() < ctx.settings.disc_min_pixels or gt.depth_range < disc._flat(gt):
            continue
        gt = replace(gt, name=name)
        rows += run_scene(ctx, group, name, gt)
        write_csv(ctx.out / "fusion_runs.csv", rows)
    table = summary(rows)
    write_csv(ctx.out / "fusion_runs.csv", rows)
    write_csv(ctx.out / "fusion.csv", table)
    n_scenes = len({(r["group"], r["scene"]) for r in rows})
    text = "\n".join([
        f"{n_scenes} scenes. error: orthographic mean absolute depth error in % of the depth "
        "range, perspective MADE in mm, both without alignment; made: mean absolute depth "
        "error (scene units); normals_error: the same method without a prior (aligned: "
        "normalised error / median-scaled MADE); prior_error: the prior alone (sparse "
        "samples interpolated); time_ratio: seconds with the prior / without.\n",
        md_table(table, ["group", "method", "condition", "scenes", "error", "made",
                         "normals_error", "prior_error", "beats_both", "time_ratio",
                         "seconds"]),
        "\nPer scene:\n",
        md_table([r for r in rows if r["status"] == "ok"],
                 ["group", "scene", "method", "condition", "error", "made", "normals_error",
                  "prior_error", "time_ratio"]),
    ])
    write_text(ctx.out / "fusion.md", text)
    ctx.add("Fusion: normals with a depth prior", text)
