"""Missing normals with jumps: the discontinuity route with and without its gap fill.

A facet without a normal passes no offset between its neighbours; where a cut leaves a narrow
bridge (the DiLiGenT bear's head on its body) one missing normal in it sets a region loose.
The discontinuity route therefore fills such facets weakly from their neighbours
(``facetlift.methods.dgp.GAP_WEIGHT``). This script removes a share of the normals at random
(seeded per scene) from every render of ``facetlift bench --experiments discontinuities``
(perspective, wide-angle and orthographic; the same cache) and integrates each with
``discontinuities=True`` at every weight given (0: no fill, the route before the fill).
Reported per group and share: the mean error (MADE for a camera, the paper's normalised error
for orthographic views) per weight, and how many scenes each weight made better or worse than
weight 0 by more than 1 %, split at an error of 1 mm without the fill (the DiLiGenT-like
objects below, the large jumps above); ``--json`` writes every run's row.

Usage::

    .venv/bin/python benchmarks/bench_missing_jumps.py
    .venv/bin/python benchmarks/bench_missing_jumps.py --weights 0,0.1,1 --shares 0.01,0.05
"""

from __future__ import annotations

import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: Scenes whose error without the fill is below this (mm or %) are the DiLiGenT-like class.
SMALL = 1.0


def run(ctx, weights, shares, step, groups, out=None) -> list[dict]:
    import facetlift
    from facetlift.bench import discontinuities as bd
    from facetlift.methods import dgp

    rows = []
    scenes = [s for s in bd.scenes(ctx) if s[0] in groups][::step]
    for group, name, gt in bd.usable(ctx, scenes, "missing normals"):
        for share in shares:
            rng = np.random.default_rng([7, zlib.crc32(name.encode())])
            normals = gt.normals.copy()
            normals[(rng.random(gt.mask.shape) < share) & gt.mask] = np.nan
            for w in weights:
                saved, dgp.GAP_WEIGHT = dgp.GAP_WEIGHT, w
                try:
                    t = time.perf_counter()
                    s = facetlift.integrate(normals, gt.mask, pixel_size=gt.pixel_size, K=gt.K,
                                            discontinuities=True)
                    row = {"group": group, "scene": name, "share": share, "weight": w,
                           "error": bd.error_of(gt, s.depth),
                           "seconds": time.perf_counter() - t,
                           "filled": s.info.get("gaps_filled", 0)}
                finally:
                    dgp.GAP_WEIGHT = saved
                rows.append(row)
                if out is not None:
                    out.write(json.dumps(row) + "\n")
                    out.flush()
        print(f"{group} {name}", file=sys.stderr, flush=True)
    return rows


def table(rows: list[dict], weights) -> str:
    lines = ["| group | share | scenes | " + " | ".join(f"mean, weight {w:g}" for w in weights)
             + " | better / worse than 0: below 1 mm | at 1 mm or more |",
             "|---|---|---|" + "---|" * len(weights) + "---|---|"]
    by = {}
    for r in rows:
        by.setdefault((r["group"], r["share"], r["scene"]), {})[r["weight"]] = r["error"]
    for g, sh in sorted({(k[0], k[1]) for k in by}):
        runs = [v for k, v in by.items() if k[:2] == (g, sh) and len(v) == len(weights)]
        if not runs:
            continue
        means = " | ".join(f"{np.mean([v[w] for v in runs]):.4f}" for w in weights)
        split = []
        for small in (True, False):
            if 0.0 not in weights:  # (nothing to compare with)
                split.append("-")
                continue
            part = [v for v in runs if (v[0.0] < SMALL) == small]
            split.append(", ".join(
                f"{w:g}: {sum(v[w] < 0.99 * v[0.0] for v in part)} / "
                f"{sum(v[w] > 1.01 * v[0.0] for v in part)}" for w in weights if w != 0.0)
                or "-")
        lines.append(f"| {g} | {sh:g} | {len(runs)} | {means} | {split[0]} | {split[1]} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_jump_free import context, scene_arguments

    ap = scene_arguments(__doc__.split("\n\n")[0])
    ap.add_argument("--weights", default="0,0.1", help="GAP_WEIGHT values (0: no fill)")
    ap.add_argument("--shares", default="0.01,0.05", help="shares of the normals removed")
    ap.add_argument("--json", type=Path, help="write every run's row (one JSON per line)")
    a = ap.parse_args(argv)
    weights = [float(w) for w in a.weights.split(",")]
    shares = [float(x) for x in a.shares.split(",")]
    ctx = context(a)
    out = open(a.json, "w") if a.json else None
    try:
        rows = run(ctx, weights, shares, a.step, a.groups.split(","), out)
    finally:
        if out is not None:
            out.close()
    print(table(rows, weights))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
