"""Real normal maps: Fig. 10 (angular error, no ground truth) and the DiLiGenT bear (MADE)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from .. import metrics
from . import plots
from .core import Context, bar, disc_spec
from .tables import md_table, write_csv, write_text

#: Real normal maps (folders of ``normal_maps/`` in the data directory) for Fig. 10.
FIG10_DATA = ("bini_human_ortho_real", "bini_supp_tent_ortho")
#: The perspective data set with ground-truth depth.
BEAR = "diligent_bear"


def read_folder(folder: Path, stride: int):
    """-> (normals, mask, K, depth_gt, back-facing pixels removed) of a data folder.

    Every `stride`-th pixel is kept (K scaled to match); back-facing normals are removed from
    the mask, the mask is cleaned of tiny pieces and the normals outside it set to NaN.
    """
    from ..camera import Pinhole
    from ..io import read_dataset
    from ..problem import clean_mask

    ds = read_dataset(folder)
    n, mask, K = ds["normals"], ds["mask"], ds["K"]
    if mask is None:
        mask = np.isfinite(n).all(-1)
    depth_gt = None
    if (folder / "depth_gt.npz").is_file():
        with np.load(folder / "depth_gt.npz") as z:
            depth_gt = np.asarray(z["depth_gt"], float)
    back = mask & ~(n[..., 2] > 0)
    nback = int(back.sum())
    if stride > 1:
        sub = (slice(None, None, stride),) * 2
        n, mask, back = n[sub], mask[sub], back[sub]
        if depth_gt is not None:
            depth_gt = depth_gt[sub]
        if K is not None:
            K = Pinhole(K).subsampled(stride).K
    mask = clean_mask(mask & ~back, min_size=2)
    n = np.where(mask[..., None], n, np.nan)
    return n, mask, K, depth_gt, nback


def fig10(ctx: Context) -> None:
    """Angular error of every method on the real normal maps (and ``ctx.extra_normal_maps``)."""
    folders = []
    if ctx.data is not None:
        folders += [ctx.data / "normal_maps" / d for d in FIG10_DATA
                    if (ctx.data / "normal_maps" / d).is_dir()]
    folders += [Path(p) for p in ctx.extra_normal_maps]
    specs = ctx.specs()
    rows, panels = [], []
    for folder in bar(folders, ctx.progress, "fig10"):
        stride = int(ctx.settings.real_stride.get(folder.name, 1))
        try:
            n, mask, K, _, nback = read_folder(folder, stride)
        except Exception as e:
            rows.append({"data": folder.name, "method": "", "status": "unreadable",
                         "message": str(e)})
            continue
        angles = partial(metrics.angular_error, normals=n, mask=mask)
        runs = []
        for spec in specs:
            r, res = ctx.measure(spec, n, mask, angles, K=K)
            mean, mx, amap = res or (None, None, None)
            runs.append((r, amap))
            rows.append({"data": folder.name, "size": f"{mask.shape[0]}x{mask.shape[1]}",
                         "stride": stride, "pixels": int(mask.sum()),
                         "backfacing_removed": nback, "method": spec.label,
                         "status": r.status, "mean_deg": mean, "max_deg": mx,
                         "seconds": r.seconds, "message": r.message})
        panels.append((folder.name, runs))
    write_csv(ctx.out / "fig10.csv", rows)
    cols = ["data", "size", "pixels", "method", "status", "mean_deg", "max_deg", "seconds"]
    text = md_table([r for r in rows if r.get("method")], cols)
    unread = [r for r in rows if r.get("status") == "unreadable"]
    if unread:  # (shown only in fig10.csv before, an audit)
        text += "\n\nNot read: " + "; ".join(f"{r['data']} ({r['message']})"
                                              for r in unread) + "\n"
    if not folders:
        text = "No normal-map folders found (pass `extra_normal_maps` or a data folder).\n"
    write_text(ctx.out / "fig10.md", text)
    for name, runs in panels:
        plots.angle_maps(ctx.out / f"fig10_{name}.png", runs)
    ctx.add("Fig. 10: angular error (deg) of the reconstructed facets vs the input normals", text)


def bear(ctx: Context) -> None:
    """MADE on the perspective DiLiGenT bear for the methods that take perspective input."""
    folder = None if ctx.data is None else ctx.data / "normal_maps" / BEAR
    if folder is None or not folder.is_dir():
        ctx.add("DiLiGenT bear (perspective)", "Skipped: data folder not found.\n")
        return
    stride = ctx.settings.bear_stride
    n, mask, K, depth_gt, _ = read_folder(folder, stride)
    specs = ctx.specs(variants=False)
    if any(sp.method == "dgp" for sp in specs) and not ctx.status.get("dgp"):
        disc = disc_spec()
        if disc is not None:
            specs.append(disc)
    made = partial(_made, truth=depth_gt, mask=mask)
    rows, runs = [], []
    for spec in bar(specs, ctx.progress, "bear"):
        r, res = ctx.measure(spec, n, mask, made, K=K)
        val, emap = res or (None, None)
        runs.append((r, emap))
        rows.append({"method": spec.label, "status": r.status, "made_mm": val,
                     "seconds": r.seconds, "message": r.message})
    rows.append({"method": "BiNI k=2 (reference, from SOURCES.md)", "status": "reference",
                 "made_mm": 0.334})
    write_csv(ctx.out / "bear.csv", rows)
    text = md_table(rows, ["method", "status", "made_mm", "seconds", "message"])
    text = (f"Resolution {mask.shape[0]}x{mask.shape[1]} (stride {stride}), "
            f"{int(mask.sum())} pixels.\n\n" + text)
    write_text(ctx.out / "bear.md", text)
    plots.made_maps(ctx.out / "bear.png", runs)
    ctx.add("DiLiGenT bear (perspective): MADE (mm)", text)


def _made(surface, truth, mask):
    """MADE (mm) and its map (:func:`facetlift.metrics.made`) of `surface` against `truth`."""
    return metrics.made(surface.depth, truth, mask)
