"""Table 1, Fig. 4 and Fig. 5: the DGP loop on the analytic face (timings, convergence, noise)."""

from __future__ import annotations

import warnings

import numpy as np

from .. import metrics, synthetic
from . import plots
from .core import SEED, Context, bar, pct
from .tables import md_table, write_csv, write_text

#: Table 1 of the paper (ms): factorization, local shaping per step, global blending per step.
PAPER_TABLE1 = {128: (187, 0.62, 6.21), 256: (905, 3.42, 25.2), 512: (4961, 17.5, 101.8)}
#: Fig. 5 of the paper: iterations with perturbed samples as inliers / removed as outliers.
PAPER_FIG5 = {0.15: (5, 18), 0.30: (5, 38), 0.50: (5, 143), 0.55: (5, 195)}


def table1(ctx: Context) -> None:
    """Timings of the DGP loop (factorization, local and global step) at every size."""
    from ..api import integrate

    s = ctx.settings
    rows = []
    jobs = [(n, b) for n in s.table1_sizes for b in ("auto", "superlu")]
    for n, backend in bar(jobs, ctx.progress, "table1"):
        gt = synthetic.analytic("face", n)
        fac, loc, glo = [], [], []
        for _ in range(s.table1_repeats):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # tol=0: no convergence warning wanted
                surf = integrate(gt.normals, gt.mask, method="dgp", solver="iterative",
                                 max_iter=s.table1_steps, tol=0.0, backend=backend)
            it = surf.info["iterations"]
            sec = surf.info["seconds"]
            fac.append(1e3 * sec["factorization"])
            loc.append(1e3 * sec["local"] / it)
            glo.append(1e3 * sec["global"] / it)
        paper = PAPER_TABLE1.get(n, (np.nan,) * 3)
        rows.append({
            "resolution": f"{n}x{n}",
            "unknowns": int(np.isfinite(surf.vertex_depth).sum()),
            "factorization_ms": float(np.median(fac)),
            "local_ms_per_step": float(np.median(loc)),
            "global_ms_per_step": float(np.median(glo)),
            "steps": it,
            "repeats": s.table1_repeats,
            "backend": f"{backend} -> {surf.info.get('backend', '')}",
            "paper_factorization_ms": paper[0],
            "paper_local_ms": paper[1],
            "paper_global_ms": paper[2],
        })
    write_csv(ctx.out / "table1.csv", rows)
    text = md_table(rows)
    write_text(ctx.out / "table1.md", text)
    ctx.add("Table 1: DGP timings in ms (face surface, full rectangle; median of repeats)", text)


def fig4(ctx: Context) -> None:
    """Convergence of the DGP loop with and without mean subtraction."""
    from ..api import integrate

    gt = synthetic.analytic("face", ctx.settings.fig4_size)
    curves, rows = {}, []
    for ms in bar((True, False), ctx.progress, "fig4"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = integrate(gt.normals, gt.mask, method="dgp", solver="iterative",
                          mean_subtraction=ms, max_iter=ctx.settings.fig4_max_iter, tol=1e-3)
        dev = list(s.info["deviation"])
        curves[ms] = dev
        err, _ = metrics.normalized_error(s.depth, gt.depth, gt.mask)
        rows.append({
            "mean_subtraction": ms, "iterations": s.info["iterations"],
            "converged": s.info["converged"], "final_deviation_deg": dev[-1],
            "error_pct": pct(err),
        })
    long = [{"iteration": i + 1, "mean_subtraction": ms, "deviation_deg": d}
            for ms, dev in curves.items() for i, d in enumerate(dev)]
    write_csv(ctx.out / "fig4.csv", long)
    text = md_table(rows)
    write_text(ctx.out / "fig4.md", text)
    plots.convergence(ctx.out / "fig4.png", curves, gt.shape)
    ctx.add("Fig. 4: convergence with and without mean subtraction (face, noise-free)", text)


def fig5(ctx: Context) -> None:
    """A fraction of the normals perturbed by up to 20 degrees, kept as inliers or removed."""
    gt = synthetic.analytic("face", ctx.settings.fig5_size)
    rows, maps = [], []
    for frac in bar(ctx.settings.fig5_fractions, ctx.progress, "fig5"):
        row, angles, emaps = _fig5_row(gt, frac)
        rows.append(row)
        maps.append((frac, angles, emaps))
    write_csv(ctx.out / "fig5.csv", rows)
    text = md_table(rows)
    write_text(ctx.out / "fig5.md", text)
    plots.perturbation(ctx.out / "fig5.png", maps, rows)
    ctx.add("Fig. 5: perturbed samples as inliers vs removed as outliers (face)", text)


def _fig5_row(gt, frac: float):
    """-> (table row, perturbation angles, {case: error map of the loop}) for one fraction."""
    from ..api import integrate

    rng = np.random.default_rng([SEED, int(round(frac * 1000))])
    noisy, chosen, angles = synthetic.perturb_fraction(gt.normals, frac, max_deg=20.0, rng=rng)
    removed = noisy.copy()
    removed[chosen] = np.nan
    row = {"fraction": frac}
    emaps = {}
    for case, nm in (("inliers", noisy), ("outliers", removed)):
        for solver in ("iterative", "direct"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                loop = {"tol": 1e-3, "max_iter": 5000} if solver == "iterative" else {}
                s = integrate(nm, gt.mask, method="dgp", solver=solver, **loop)
            err, emap = metrics.normalized_error(s.depth, gt.depth, gt.mask)
            if solver == "iterative":
                row[f"{case}_iterations"] = s.info["iterations"]
                row[f"{case}_converged"] = s.info["converged"]
                row[f"{case}_error_pct"] = pct(err)
                emaps[case] = emap
            else:
                row[f"{case}_direct_error_pct"] = pct(err)
    paper = PAPER_FIG5.get(round(frac, 2), (None, None))
    row["paper_inlier_iterations"], row["paper_outlier_iterations"] = paper
    return row, angles, emaps
