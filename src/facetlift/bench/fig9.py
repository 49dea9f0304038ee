"""Fig. 9: mean normalised error of every method over many models, noise-free and with noise.

The models are the analytic surfaces of ``settings.fig9_analytic`` and every mesh of the data
folder (plus ``extra_meshes``) rendered from every view of ``settings.fig9_views``; with
``settings.fig9_continuous``, also the largest jump-free region of every rendered mesh.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from .. import metrics, synthetic
from . import plots
from .core import Context, noisy, pct
from .tables import md_table, pivot, write_csv, write_text


def models(ctx: Context) -> list:
    """(name, loader) pairs of the Fig. 9 data set, limited to ``ctx.models`` if given."""
    s = ctx.settings
    n = s.fig9_size
    # (named models pick among every analytic surface, as among all meshes: quick mode's two
    # left `tent` empty, a review)
    names = synthetic.ANALYTIC if ctx.models else s.fig9_analytic
    out = [(name, lambda name=name: synthetic.analytic(name, n)) for name in names]
    for path in ctx.meshes(s.fig9_meshes):
        for view in s.fig9_views:
            out.append((f"{path.stem}@{view}",
                        lambda path=path, view=view: synthetic.render_mesh(path, n, view=view)))
    if ctx.models:
        out = [(nm, f) for nm, f in out if nm in ctx.models or nm.split("@")[0] in ctx.models]
    return out


def fig9(ctx: Context) -> None:
    """Every method on every model; writes the runs, the per-model tables and the summary."""
    s = ctx.settings
    specs = ctx.specs()
    data = models(ctx)
    conds = [("noise-free", 0.0), (f"noise {s.noise_deg:g}deg", s.noise_deg)]
    domains = ["full"] + (["continuous"] if s.fig9_continuous else [])
    rows, skipped, thumbs = _run_all(ctx, data, specs, conds, domains)
    write_csv(ctx.out / "fig9_runs.csv", rows)
    write_text(ctx.out / "fig9_per_model.md", _per_model(rows, domains, conds))
    if skipped:
        write_csv(ctx.out / "fig9_skipped.csv", skipped)
    table = summary(rows, specs)
    write_csv(ctx.out / "fig9.csv", table)
    text = _summary_text(table, skipped)
    write_text(ctx.out / "fig9.md", text)
    plots.error_bars(ctx.out / "fig9.png", table, domains)
    plots.thumbnails(ctx.out / "fig9_models.png", thumbs)
    whole = sum(not r["model"].endswith(" (continuous)") for r in skipped)  # not just a domain
    ctx.add(f"Fig. 9: mean normalised error over {len(data) - whole} models "
            f"({s.fig9_size}x{s.fig9_size})", text)


def _run_all(ctx: Context, data: list, specs, conds: list, domains: list):
    """Every method on every model, domain and condition.

    Returns the rows of ``fig9_runs.csv``, the skipped models (``{"model", "reason"}``) and the
    ground truths of the full domains (for the thumbnails).
    """
    from tqdm import tqdm

    rows, skipped, thumbs = [], [], []
    per_domain = len(conds) * len(specs)
    with tqdm(total=len(data) * len(domains) * per_domain, desc="fig9", leave=False,
              disable=not ctx.progress) as progress:
        for name, load in data:
            gt_full, reason = _load(load)
            if reason:
                skipped.append({"model": name, "reason": reason})
                progress.update(len(domains) * per_domain)
                continue
            for domain in domains:
                gt, reason = _domain(name, gt_full, domain)
                if reason:
                    skipped.append({"model": name + " (continuous)", "reason": reason})
                if gt is None:
                    progress.update(per_domain)
                    continue
                if domain == "full":
                    thumbs.append(gt)
                rows += _model_rows(ctx, specs, name, gt, domain, conds, progress)
    return rows, skipped, thumbs


def _load(load):
    """-> (ground truth, None) from the loader `load`, or (None, why the model is skipped)."""
    try:
        gt = load()
        if gt.depth_range < gt.pixel_size:
            raise ValueError(f"depth range {gt.depth_range:.3g} is less than one pixel width: "
                             "nothing to normalise by")
    except Exception as e:  # a mesh that does not load or render: skipped, the run goes on
        return None, f"{type(e).__name__}: {e}"
    return gt, None


def _domain(name: str, gt, domain: str):
    """-> (ground truth on `domain`, None), or (None, why it is skipped or None if it has none).

    ``full`` is the whole rendered mask; ``continuous`` its largest jump-free region, for
    rendered meshes only (analytic surfaces are continuous already).
    """
    if domain == "full":
        return gt, None
    if "@" not in name:
        return None, None
    part = synthetic.continuous_region(gt)
    if part.depth_range < part.pixel_size:
        return None, f"largest jump-free region is flat (depth range {part.depth_range:.3g})"
    return part, None


def _model_rows(ctx: Context, specs, name: str, gt, domain: str, conds: list,
                progress) -> list[dict]:
    """One row per condition and method for model `name` (ground truth `gt`) on `domain`."""
    errors = partial(_errors, gt=gt)
    rows = []
    for cond, sigma in conds:
        nm = noisy(gt.normals, sigma, name)
        for spec in specs:
            r, res = ctx.measure(spec, nm, gt.mask, errors, pixel_size=gt.pixel_size)
            err, rm = res or (None, None)
            rows.append({
                "domain": domain, "condition": cond, "model": name,
                "pixels": int(gt.mask.sum()), "method": spec.label,
                "status": r.status, "error_pct": pct(err),
                "rmse_px": rm, "seconds": r.seconds,
                "warning": "; ".join(r.warnings)[:200], "message": r.message,
            })
            progress.update(1)
    return rows


def _errors(surface, gt) -> tuple[float, float]:
    """(normalised error, RMSE) of `surface` against the ground truth `gt`."""
    err, _ = metrics.normalized_error(surface.depth, gt.depth, gt.mask)
    return err, metrics.rmse(surface.depth, gt.depth, gt.mask)


def _per_model(rows: list[dict], domains: list, conds: list) -> str:
    """``fig9_per_model.md``: a model x method table of errors per domain and condition."""
    parts = []
    for dom in domains:
        for cond, _ in conds:
            sub = [r for r in rows if r["domain"] == dom and r["condition"] == cond]
            if sub:
                parts.append(f"### {dom} domains, {cond}\n\n" + pivot(sub, "model", "error_pct"))
    return "\n".join(parts)


def _summary_text(table: list[dict], skipped: list[dict]) -> str:
    """``fig9.md``: the summary table, then the skipped models and why."""
    cols = ["domain", "condition", "method", "models_ok", "failed", "mean_error_pct",
            "median_error_pct", "mean_error_common_pct", "common_models", "mean_seconds"]
    text = md_table(table, cols)
    if skipped:
        text += "\nSkipped models: " + ", ".join(
            f"{k['model']} ({k['reason']})" for k in skipped) + "\n"
    return text


def summary(rows: list[dict], specs) -> list[dict]:
    """One row per (domain, condition, method): models that ran, mean and median error."""
    out = []
    keys = list(dict.fromkeys((r["domain"], r["condition"]) for r in rows))
    for dom, cond in keys:
        sub = [r for r in rows if r["domain"] == dom and r["condition"] == cond]
        names = list(dict.fromkeys(r["model"] for r in sub))
        # models on which every method that could run succeeded
        ok_all = [m for m in names if all(
            r["status"] == "ok" for r in sub
            if r["model"] == m and r["status"] not in ("unavailable", "unsupported"))]
        for spec in specs:
            mine = [r for r in sub if r["method"] == spec.label]
            errs = [r["error_pct"] for r in mine if r["status"] == "ok"]
            common = [r["error_pct"] for r in mine if r["model"] in ok_all]
            secs = [r["seconds"] for r in mine if r["status"] == "ok"]
            out.append({
                "domain": dom, "condition": cond, "method": spec.label,
                "models_ok": len(errs),
                "failed": sum(r["status"] != "ok" for r in mine),
                "mean_error_pct": float(np.mean(errs)) if errs else float("nan"),
                "median_error_pct": float(np.median(errs)) if errs else float("nan"),
                "mean_error_common_pct": float(np.mean(common)) if common else float("nan"),
                "common_models": len(ok_all),
                "mean_seconds": float(np.mean(secs)) if secs else float("nan"),
                "status": "; ".join(sorted({r["status"] for r in mine})),
            })
    return out

