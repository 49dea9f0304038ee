"""Figs. 6-8: error maps of every method on a saddle, sharp-crease surfaces and a face."""

from __future__ import annotations

import zlib

import numpy as np

from .. import metrics, synthetic
from . import plots
from .core import SEED, Context, bar, pct, run_method
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
        rng = np.random.default_rng([SEED, zlib.crc32(model.encode())])
        nm = gt.normals if sigma == 0 else synthetic.add_angular_noise(gt.normals, sigma, rng)
        runs = []
        for spec in specs:
            r = run_method(spec, nm, gt.mask, pixel_size=gt.pixel_size, status=ctx.status)
            err = emap = None
            if r.status == "ok":
                try:
                    err, emap = metrics.normalized_error(r.surface.depth, gt.depth, gt.mask)
                except ValueError as e:
                    r.status, r.message = "failed", f"metric: {e}"
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
