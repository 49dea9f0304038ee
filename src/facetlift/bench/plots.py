"""Figures of the bench, written atomically as PNG. matplotlib is imported only here, when drawing.

`runs` arguments are lists of ``(Run, map)`` pairs, with ``map`` an (H, W) array or None where
the run has none (failed, unavailable, ...).
"""

from __future__ import annotations

import functools
import importlib.util
import logging
from pathlib import Path

import numpy as np

log = logging.getLogger("facetlift.bench")

#: The figures not drawn because matplotlib (the plot extra) is missing, by file name: the
#: report lists them (:func:`facetlift.bench.runner.run_bench`), and the experiments' tables
#: and CSV files are written all the same.
NOT_DRAWN: list[str] = []


def _drawn(draw):
    """`draw(path, ...)` where matplotlib is installed; else nothing drawn, None returned and
    the file named in :data:`NOT_DRAWN` (a bench without the plot extra lost finished
    experiments from its report to an ImportError, with a traceback each, an audit)."""
    @functools.wraps(draw)
    def wrapper(path, *args, **kwargs):
        if importlib.util.find_spec("matplotlib") is None:
            if not NOT_DRAWN:
                log.warning("matplotlib is not installed: the figures are not drawn "
                            "(pip install 'facetlift[plot]'); tables and CSV files are written")
            NOT_DRAWN.append(Path(path).name)
            return None
        return draw(path, *args, **kwargs)
    return wrapper


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def savefig(fig, path: Path) -> Path:
    """Write `fig` to `path` (PNG, atomically) and close it; returns `path`."""
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=fig.dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


@_drawn
def convergence(path: Path, curves: dict, shape) -> Path:
    """Fig. 4: deviation per iteration; `curves` maps mean subtraction (bool) to the curve."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 3.2), dpi=100)
    for ms, dev in curves.items():
        ax.plot(np.arange(1, len(dev) + 1), dev,
                label="with mean subtraction" if ms else "without mean subtraction")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("average angular deviation (deg)")
    ax.set_title(f"Fig. 4: convergence (face, {shape[0]}x{shape[1]})", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return savefig(fig, path)


@_drawn
def perturbation(path: Path, maps: list, rows: list[dict]) -> Path:
    """Fig. 5: per fraction, the perturbation angles and the error maps as inliers / outliers.

    `maps` holds ``(fraction, angles, {"inliers": error, "outliers": error})`` and `rows` the
    matching table rows (iterations and error of each case).
    """
    plt = _plt()
    k = len(maps)
    fig, axes = plt.subplots(3, k, figsize=(2.2 * k + 0.8, 6.6), dpi=80, squeeze=False)
    vmax = max(np.nanmax(e[c]) for _, _, e in maps for c in e) * 100
    for j, (frac, angles, emaps) in enumerate(maps):
        im0 = axes[0, j].imshow(np.where(angles > 0, angles, np.nan), cmap="viridis",
                                vmin=0, vmax=20, interpolation="nearest")
        axes[0, j].set_title(f"(a) {frac:.0%} perturbed", fontsize=8)
        for i, case in ((1, "inliers"), (2, "outliers")):
            im = axes[i, j].imshow(100 * emaps[case], cmap="jet", vmin=0, vmax=vmax)
            r = rows[j]
            axes[i, j].set_title(
                f"({'b' if i == 1 else 'c'}) {case}: {r[f'{case}_iterations']} it, "
                f"{r[f'{case}_error_pct']:.2f}%", fontsize=8)
    for a in axes.flat:
        a.axis("off")
    fig.colorbar(im0, ax=axes[0, :].tolist(), shrink=0.8, label="deg")
    fig.colorbar(im, ax=axes[1:, :].ravel().tolist(), shrink=0.8, label="error %")
    return savefig(fig, path)


@_drawn
def error_maps(path: Path, gt, runs: list, cond: str = "") -> Path:
    """Figs. 6-8: the ground-truth height, then the normalised error map (%) of every run."""
    finite = [e for r, e in runs if e is not None]
    vmax = max([float(np.nanpercentile(e, 99)) for e in finite] + [1e-6]) * 100
    return _map_grid(path, runs, first=(-gt.depth, f"{gt.name} ({cond})"), scale=100, vmax=vmax,
                     title=lambda r, e: f"{r.label}: {100 * np.nanmean(e):.2f}%", title_size=8,
                     label="error % of depth range")


@_drawn
def angle_maps(path: Path, runs: list) -> Path:
    """Fig. 10: the angular error map (deg) of every run."""
    return _map_grid(path, runs, vmax=20, title_size=7, label="deg (clipped at 20)",
                     title=lambda r, a: f"{r.label}: {np.nanmean(a):.2f}°/{np.nanmax(a):.0f}°")


def _map_grid(path: Path, runs: list, *, vmax: float, title, title_size: float, label: str,
              scale: float = 1.0, first=None) -> Path:
    """A grid of panels, five a row, with one colour bar.

    `first`, an ``(image, title)`` pair, is drawn in grey in the first panel. Then each run
    shows ``scale * map`` (jet, 0 to `vmax`) titled ``title(run, map)``, or its status where it
    has no map. The colour bar, labelled `label`, is left out where no run has a map.
    """
    plt = _plt()
    k = len(runs) + (first is not None)
    ncol = min(k, 5)
    nrow = -(-k // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(2.0 * ncol + 0.6, 2.2 * nrow), dpi=80,
                             squeeze=False)
    cells = list(axes.flat)
    if first is not None:
        image, text = first
        cells[0].imshow(image, cmap="gray")
        cells[0].set_title(text, fontsize=8)
        cells = cells[1:]
    im = None
    for a, (r, m) in zip(cells, runs, strict=False):
        if m is None:
            a.text(0.5, 0.5, r.status, ha="center", va="center", fontsize=9)
            a.set_title(r.label, fontsize=8)
            continue
        im = a.imshow(scale * m, cmap="jet", vmin=0, vmax=vmax)
        a.set_title(title(r, m), fontsize=title_size)
    for a in axes.flat:
        a.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label=label)
    return savefig(fig, path)


@_drawn
def error_bars(path: Path, summary: list[dict], domains: list[str]) -> Path:
    """Fig. 9: mean normalised error per method and condition, one panel per domain."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(domains), figsize=(6.5 * len(domains), 3.8), dpi=80,
                             squeeze=False)
    for ax, dom in zip(axes[0], domains, strict=False):
        sub = [r for r in summary if r["domain"] == dom]
        conds = list(dict.fromkeys(r["condition"] for r in sub))
        labels = list(dict.fromkeys(r["method"] for r in sub))
        x = np.arange(len(labels))
        w = 0.8 / max(len(conds), 1)
        allv = [r["mean_error_pct"] for r in sub if np.isfinite(r["mean_error_pct"])]
        top = min(max(allv), 3 * float(np.median(allv))) * 1.15 if allv else 1.0
        for i, c in enumerate(conds):
            vals = np.array([next((r["mean_error_pct"] for r in sub
                                   if r["method"] == m and r["condition"] == c), np.nan)
                             for m in labels])
            xs = x + (i - (len(conds) - 1) / 2) * w
            ax.bar(xs, np.minimum(vals, top), w, label=c)
            for xi, v in zip(xs, vals, strict=True):
                if np.isfinite(v):
                    ax.text(xi, min(v, top), f"{v:.2g}", ha="center", va="bottom",
                            fontsize=6, rotation=90)
                else:
                    ax.text(xi, 0, "n/a", ha="center", va="bottom", fontsize=6,
                            rotation=90)
        ax.set_ylim(0, top * 1.2)
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel("mean normalised error (%)")
        ax.set_title(f"Fig. 9 ({dom} rendered domains; bars clipped at the top)",
                     fontsize=9)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return savefig(fig, path)


@_drawn
def thumbnails(path: Path, gts: list) -> Path | None:
    """The normal maps of the ground truths `gts` (nothing written where there is none)."""
    if not gts:
        return None
    plt = _plt()
    ncol = min(len(gts), 8)
    nrow = -(-len(gts) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(1.3 * ncol, 1.45 * nrow), dpi=72,
                             squeeze=False)
    for a in axes.flat:
        a.axis("off")
    for a, gt in zip(axes.flat, gts, strict=False):
        a.imshow(np.where(gt.mask[..., None], np.nan_to_num(gt.normals) * 0.5 + 0.5, 1.0))
        a.set_title(gt.name, fontsize=6)
    fig.tight_layout()
    return savefig(fig, path)


@_drawn
def made_maps(path: Path, runs: list) -> Path | None:
    """The bear: the MADE map (mm) of every run that has one (nothing written where none has)."""
    ok = [(r, e) for r, e in runs if e is not None]
    if not ok:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, len(ok), figsize=(2.6 * len(ok) + 0.6, 2.6), dpi=80,
                             squeeze=False)
    for a, (r, e) in zip(axes[0], ok, strict=False):
        im = a.imshow(e, cmap="jet", vmin=0, vmax=2.0)
        a.set_title(f"{r.label}: MADE {np.nanmean(e):.3f} mm", fontsize=8)
        a.axis("off")
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="mm (clipped at 2)")
    return savefig(fig, path)
