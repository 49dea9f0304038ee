"""Figs. 6-8: error maps of every method on a saddle, sharp-crease surfaces and a face."""

from __future__ import annotations

from functools import partial

from .. import metrics, synthetic
from . import plots
from .core import Context, bar, noisy, pct
from .tables import pivot, write_csv, write_text

#: (figure, analytic surface); two sharp-feature surfaces for Fig. 7: diagonal creases (pyramid)
#: and creases along pixel edges (ramps).
MAP_FIGURES = (("fig6", "saddle"), ("fig7", "pyramid"), ("fig7b", "ramps"), ("fig8", "face"))


def maps(ctx: Context) -> None:
    """Every method on every surface of :data:`MAP_FIGURES`, noise-free and with noise."""
    specs = ctx.specs(variants=False)
    rows = []
    jobs = [(f, m, c) for f, m in MAP_FIGURES for c in (0.0, ctx.settings.noise_deg)]
    for figname, model, sigma in bar(jobs, ctx.progress, "figs6-8"):
        gt = synthetic.analytic(model, ctx.settings.maps_size)
        cond = "noise-free" if sigma == 0 else f"noise {sigma:g}deg"
        nm = noisy(gt.normals, sigma, model)
        error = partial(_error, gt=gt)
        runs = []
        for spec in specs:
            r, res = ctx.measure(spec, nm, gt.mask, error, pixel_size=gt.pixel_size)
            err, emap = res or (None, None)
            runs.append((r, emap))
            rows.append({"figure": figname, "model": model, "condition": cond,
                         "case": f"{model}, {cond}", "method": spec.label,
                         "status": r.status, "error_pct": pct(err),
                         "seconds": r.seconds, "message": r.message})
        name = figname if sigma == 0 else f"{figname}_noise"
        plots.error_maps(ctx.out / f"{name}.png", gt, runs, cond)
    write_csv(ctx.out / "figs6-8.csv", rows)
    table = pivot(rows, "case", "error_pct")
    write_text(ctx.out / "figs6-8.md", table)
    ctx.add("Figs. 6-8: mean normalised error (%) on saddle, pyramid, ramps, face", table)


def _error(surface, gt):
    """The paper's normalised error and its map (:func:`facetlift.metrics.normalized_error`)."""
    return metrics.normalized_error(surface.depth, gt.depth, gt.mask)
