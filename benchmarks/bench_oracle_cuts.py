"""The development benchmark's oracle with two sets of "true" jump edges.

The oracle (docs/results.md, "Discontinuities: the development benchmark") integrates a scene
with its jump edges cut. Its cuts come from a test on the depth and normals at the pixel
centres (:func:`facetlift.synthetic.jump_edges`), which a review found approximate on the
renders: it cuts continuous surfaces (curved parts, silhouette pixels whose supersampled
normal mixes two surfaces) and misses grazing jumps. The renders also carry their jumps from
the geometry (``render_perspective(..., jumps=True)``: rays between the pixel centres,
:func:`facetlift.synthetic._jump_sizes`). This script runs the oracle with each set of cuts
and ``dgp-disc`` (the route's defaults) on every ``--step``-th render of ``--groups`` under
``--conditions`` (the analytic scenes, whose cuts the test finds exactly, are left out), and
prints each scene's cut counts and errors (MADE in mm for the pinhole
groups, the paper's error in % for the orthographic one), then the group means and the
route's ratio to each oracle. Nothing is tuned on it (docs/results.md, "Known limits").

Usage::

    .venv/bin/python benchmarks/bench_oracle_cuts.py --cache /tmp/bcache \\
        --groups perspective,wide,ortho,tabletop,room,vessel --conditions exact,8bit
"""

from __future__ import annotations

import csv
import logging
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_jump_free import add_conditions, conditions_of, context, scene_arguments

    from facetlift import synthetic
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Settings, Spec, method_status

    ap = scene_arguments(__doc__.split("\n\n")[0])
    ap.set_defaults(groups="perspective,wide,ortho,tabletop,room,vessel")
    add_conditions(ap, "exact")
    ap.add_argument("--heldout-seed", type=int, default=None,
                    help="a held-out set's scenes instead of the development benchmark's")
    ap.add_argument("--csv", type=Path, default=None, help="write every run here")
    args = ap.parse_args(argv)
    conditions = conditions_of(ap, args.conditions)
    ctx = context(args)
    ctx.settings = Settings()
    ctx.status = method_status(["dgp"])
    if args.heldout_seed is not None:
        ctx.settings.heldout_seed = args.heldout_seed
    ctx.models = None
    scenes = D.heldout_scenes(ctx) if args.heldout_seed is not None else D.scenes(ctx)
    groups = [g.strip() for g in args.groups.split(",") if g.strip()]
    scenes = [t for t in scenes if t[0] in groups or t[0] == "heldout"][::max(args.step, 1)]
    spec = Spec("dgp-disc", "dgp", (("discontinuities", True),))
    logging.disable(logging.INFO)
    rows = []
    fh = open(args.csv, "w", newline="") if args.csv else None
    writer = csv.writer(fh) if fh else None
    if writer:
        writer.writerow(["group", "scene", "condition", "cuts_centres", "cuts_geometry",
                         "oracle_centres", "oracle_geometry", "dgp_disc"])
    t0 = time.time()
    try:
        for group, name, gt in D.usable(ctx, scenes, "scenes"):
            if gt.jump_sizes is None:  # (an analytic scene: the test is exact there)
                continue
            cuts = [int(sum(e.sum() for e in synthetic.jump_edges(gt, geometric=g)))
                    for g in (False, True)]
            for cond in conditions:
                normals = D.condition(gt, cond, f"{group}:{name}")
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    old = D.oracle(gt, normals)[0]
                    new = D.oracle(gt, normals, geometric=True)[0]
                    r, err = ctx.measure(spec, normals, gt.mask,
                                         lambda s, gt=gt: D.error_of(gt, s.depth),
                                         pixel_size=gt.pixel_size, K=gt.K)
                route = err if r.status == "ok" else math.nan
                row = (group, name, cond, *cuts, old, new, route)
                rows.append(row)
                if writer:
                    writer.writerow(row)
                    fh.flush()
                print(f"{group:12s} {name:40s} {cond:6s} cuts {cuts[0]:5d} -> {cuts[1]:5d}  "
                      f"oracle {old:8.4f} -> {new:8.4f}  dgp-disc {route:8.4f}  "
                      f"[{time.time() - t0:.0f} s]", flush=True)
    finally:
        if fh:
            fh.close()
    print("\n| group | condition | scenes | cuts (centres / geometry) | oracle, centres | "
          "oracle, geometry | dgp-disc | ratio (centres / geometry) |\n|---|---|---|---|---|"
          "---|---|---|")
    for cond in conditions:
        for g in dict.fromkeys(r[0] for r in rows):
            sel = [r for r in rows if r[0] == g and r[2] == cond]
            if not sel:
                continue
            c0, c1 = (round(float(np.mean([r[i] for r in sel]))) for i in (3, 4))
            o0, o1 = (float(np.mean([r[i] for r in sel])) for i in (5, 6))
            d = float(np.nanmean([r[7] for r in sel]))
            print(f"| {g} | {cond} | {len(sel)} | {c0} / {c1} | {o0:.3f} | {o1:.3f} | {d:.3f} | "
                  f"{d / o0:.3f} / {d / o1:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
