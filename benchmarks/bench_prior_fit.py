"""A depth prior known up to scale and shift (``prior_fit``) against the metric prior, the
normals alone and the old recipe (the prior fitted to the normals-only depth over the mask).

Scenes of the discontinuity benchmark (``facetlift bench --experiments discontinuities``: the
DiLiGenT-like and wide-angle perspective renders and the orthographic ones), every
``--step``-th from ``--offset``, exact normals, the route ``--route`` (``dgp-disc`` by default:
the pieces a jump separates are what the prior is for). The prior is the fusion benchmark's
coarse one (:func:`facetlift.bench.fusion.coarse_prior`: 8 x 8 block means, blurred, as a
monocular network's depth), given

- ``metric``: as it is (the reference: what an aligned prior gives);
- ``affine`` (``prior_fit="affine"``): as ``0.37 * P - 0.5 * median depth`` (pinhole) or
  ``0.37 * P + 5 * depth range`` (orthographic): an affine-invariant depth;
- ``recipe``: the same, fitted to the normals-only depth over the whole mask by least
  squares first (``np.polyfit``, what docs/fusion.md recommended before) and fused as depth;
- ``disparity`` (``prior_fit="disparity"``, pinhole only): as ``2 / P + 0.3 / median
  depth``, an affine-invariant disparity;

each blurred (``--mode blur``: ``prior_blur`` 8.94 px, weight 0.003, the fusion benchmark's
settings) or pixel by pixel (``--mode point``: weight 0.01). Per scene: the benchmark's error
(MADE after the median scale, mm, for pinhole scenes; the normalised error in % after the best
offset per component for orthographic ones) of every column, and how the fit went (method,
relative standard error of the scale, pieces). The summary gives per group the means and the
scenes better / worse than the normals alone and than the recipe by more than 1 %. Scenes
whose view is flat (the error undefined) or too small are skipped, as in the benchmark.

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_prior_fit.py \\
        --step 1 --json pf.jsonl
    .venv/bin/python benchmarks/bench_prior_fit.py --step 3 --mode point --route dgp
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"
ROUTES = {"dgp": {}, "dgp-disc": {"discontinuities": True}}
COLUMNS = ("normals", "metric", "affine", "recipe", "disparity")


def main(argv=None) -> int:
    from facetlift.bench import discontinuities as bd
    from facetlift.bench import fusion as bf
    from facetlift.bench.core import Context, Settings

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=2, help="every step-th scene")
    ap.add_argument("--offset", type=int, default=0, help="the first scene taken")
    ap.add_argument("--mode", default="blur", choices=("blur", "point"))
    ap.add_argument("--route", default="dgp-disc", choices=sorted(ROUTES))
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    weight = (dict(prior_blur=bf.BLUR_SIGMA, prior_weight=bf.WEIGHTS["blur"])
              if args.mode == "blur" else dict(prior_weight=bf.WEIGHTS["coarse"]))
    # (the scenes as documented: without the tabletop and vessel groups, which came later)
    ctx = Context(out=Path("/tmp/facetlift-bench-prior-fit"),
                  settings=Settings(disc_tabletop=0, disc_vessels=()), data=args.data)
    scenes = bd.scenes(ctx)[args.offset::args.step]
    out = None if args.json is None else args.json.open("w")
    rows = []
    print("| group | scene | " + " | ".join(COLUMNS) + " | fit: method, scale error, pieces |")
    print("|---|---|" + "---|" * len(COLUMNS) + "---|")
    for group, name, gt in bd.usable(ctx, scenes, "prior-fit"):
        pinhole = gt.K is not None
        P = bf.coarse_prior(gt)
        med = float(np.nanmedian(gt.depth[gt.mask]))
        kw = dict(pixel_size=gt.pixel_size, K=gt.K, **ROUTES[args.route])
        row = {"group": group, "scene": name, "mode": args.mode, "route": args.route}

        s0 = _run(row, "normals", gt, kw)
        _run(row, "metric", gt, kw, prior=P, **weight)
        affine = 0.37 * P + (-0.5 * med if pinhole else 5.0 * gt.depth_range)
        _run(row, "affine", gt, kw, prior=affine, prior_fit="affine", **weight)
        ok = gt.mask & np.isfinite(affine) & np.isfinite(s0.depth)
        a, b = np.polyfit(affine[ok], s0.depth[ok], 1)
        _run(row, "recipe", gt, kw, prior=a * affine + b, **weight)
        if pinhole:
            _run(row, "disparity", gt, kw, prior=2.0 / P + 0.3 / med, prior_fit="disparity",
                 **weight)
        rows.append(row)
        f = row.get("fit_affine") or {}
        print(f"| {group} | {name} | " + " | ".join(
            f"{row[c]:.4f}" if c in row else "-" for c in COLUMNS)
            + f" | {f.get('method')}, {f.get('scale_error') or float('nan'):.3g}, "
            f"{f.get('pieces')} |", flush=True)
        if out is not None:
            out.write(json.dumps(row) + "\n")
            out.flush()
    summary(rows)
    return 0


def _run(row: dict, label: str, gt, kw: dict, **more):
    """Integrate `gt`'s normals with `kw` and `more`; the error, time and fit into `row`."""
    import facetlift
    from facetlift.bench import discontinuities as bd

    t = time.perf_counter()
    s = facetlift.integrate(gt.normals, gt.mask, **kw, **more)
    row[f"t_{label}"] = time.perf_counter() - t
    row[label] = bd.error_of(gt, s.depth)
    fit = s.info.get("prior", {}).get("fit")
    if fit is not None:
        row[f"fit_{label}"] = {k: fit.get(k) for k in (
            "used", "method", "scale_error", "pieces", "correlation")}
    return s


def summary(rows: list[dict]) -> None:
    """Per group (perspective, wide, orthographic): means and counts against the normals
    alone and the recipe (1 % margin)."""
    groups = defaultdict(list)
    for r in rows:
        groups[r["group"]].append(r)
    print("\n| group | scenes | column | mean | better / worse than normals | better / worse "
          "than recipe | fit by pairs / pieces / left out |")
    print("|---|---|---|---|---|---|---|")
    for g, rs in groups.items():
        for c in COLUMNS:
            have = [r for r in rs if c in r]
            if not have:
                continue
            v = np.array([r[c] for r in have])
            n = np.array([r["normals"] for r in have])
            rec = np.array([r["recipe"] for r in have])
            how = [((r.get(f"fit_{c}") or {}).get("method") if (r.get(f"fit_{c}") or {}).get(
                "used", True) else "out") for r in have]
            counts = "/".join(str(how.count(m)) for m in ("pairs", "pieces", "out"))
            print(f"| {g} | {len(have)} | {c} | {v.mean():.4f} | {int((v < 0.99 * n).sum())} / "
                  f"{int((v > 1.01 * n).sum())} | {int((v < 0.99 * rec).sum())} / "
                  f"{int((v > 1.01 * rec).sum())} | "
                  f"{counts if c in ('affine', 'disparity') else '-'} |")


if __name__ == "__main__":
    raise SystemExit(main())
