"""A sparse prior's outlier samples: found and left out (``prior_outliers="remove"``, the
default) against every sample used (``"keep"``).

Scenes of the discontinuity benchmark (``facetlift bench --experiments discontinuities``: the
DiLiGenT-like and wide-angle perspective renders and the orthographic ones), every
``--step``-th from ``--offset``, with the normals' ``--normals`` condition. Priors drawn as
the fusion benchmark draws them (:func:`facetlift.bench.fusion.sparse_prior`), each at its
weight:

- ``exact`` 1 % of the pixels at weight 100, ``exact0.1`` 0.1 % at 100, ``noisy`` 1 % with
  noise of 1 % of the depth range at weight 1 (clean priors: nothing should change);
- ``outl`` 1 % with 3 % of the samples moved each on its own (2-5 % of the median depth with a
  camera, 5-20 % of the depth range without) at weights 1 and 100, and 5 % at 0.01;
- ``clust`` 1 % with groups of 2-12 neighbouring samples moved together (about 4 % of them),
  as occluded LiDAR points lie side by side (at weight 1).

Per run: the samples removed that were moved (found) and that were not (false), and the mean
absolute error without alignment (perspective in mm, orthographic in % of the depth range)
with ``keep`` and ``remove``. The summary gives per group, prior and column the means, the runs
better / worse by more than 1 %, found / planted, false / samples and the median times. Renders
are cached where ``FACETLIFT_BENCH_CACHE`` points (built on first use, minutes).

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_prior_outliers.py \\
        --step 1 --columns dgp-disc --json po.jsonl
    .venv/bin/python benchmarks/bench_prior_outliers.py --step 2 --offset 1 --columns dgp \\
        --normals 8bit
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
COLUMNS = {"dgp": {}, "dgp-disc": {"discontinuities": True}}
#: (label, share of the pixels sampled, noise (share of the depth range), weight)
PRIORS = [("exact", 0.01, 0.0, 100.0), ("exact0.1", 0.001, 0.0, 100.0),
          ("noisy", 0.01, 0.01, 1.0), ("outl", 0.01, 0.0, 1.0), ("outl", 0.01, 0.0, 100.0),
          ("outl5", 0.05, 0.0, 0.01), ("clust", 0.01, 0.0, 1.0)]
OUTLIER_SHARE, CLUSTER_SHARE = 0.03, 0.04


def corrupt(gt, prior, kind: str, rng) -> np.ndarray:
    """Move some samples of `prior` in place (``outl``: each on its own; ``clust``: in groups
    of 2-12 neighbours); returns the (H, W) bool map of those moved."""
    fin = np.isfinite(prior)
    moved = np.zeros(prior.shape, bool)

    def offset():
        if gt.K is not None:
            return float(np.nanmedian(gt.depth[gt.mask]) * rng.uniform(0.02, 0.05))
        return float(gt.depth_range * rng.uniform(0.05, 0.2))

    if kind.startswith("outl"):
        moved = fin & (rng.random(prior.shape) < OUTLIER_SHARE)
        r, c = np.nonzero(moved)
        for i in range(r.size):
            prior[r[i], c[i]] += rng.choice([-1.0, 1.0]) * offset()
    elif kind == "clust":
        r, c = np.nonzero(fin)
        goal = max(2, int(CLUSTER_SHARE * r.size))
        while moved.sum() < goal:
            k = rng.integers(r.size)
            near = np.argsort((r - r[k]) ** 2 + (c - c[k]) ** 2)[:int(rng.integers(2, 13))]
            near = near[~moved[r[near], c[near]]]
            prior[r[near], c[near]] += rng.choice([-1.0, 1.0]) * offset()
            moved[r[near], c[near]] = True
    return moved


def main(argv=None) -> int:
    import facetlift
    from facetlift.bench import discontinuities as bd
    from facetlift.bench import fusion as bf
    from facetlift.bench.core import Context, Settings
    from facetlift.problem import prepare

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=2, help="every step-th scene")
    ap.add_argument("--offset", type=int, default=0, help="the first scene taken")
    ap.add_argument("--columns", default="dgp,dgp-disc")
    ap.add_argument("--normals", default="exact", choices=("exact", "16bit", "8bit", "noise3"))
    ap.add_argument("--priors", default=None,
                    help="labels of PRIORS to run (comma-separated; default all)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    columns = args.columns.split(",")
    wanted = None if args.priors is None else set(args.priors.split(","))
    priors = [p for p in PRIORS if wanted is None or p[0] in wanted]
    # (the scenes as documented: without the tabletop and vessel groups, which came later)
    ctx = Context(out=Path("/tmp/facetlift-bench-prior-outliers"),
                  settings=Settings(disc_tabletop=0, disc_vessels=()), data=args.data)
    scenes = bd.scenes(ctx)[args.offset::args.step]
    out = None if args.json is None else args.json.open("w")
    rows = []
    print("| group | scene | prior | weight | samples | moved | found | false | column | "
          "keep | remove |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for group, name, gt in bd.usable(ctx, scenes, "prior-outliers"):
        normals = bd.condition(gt, args.normals, name)
        for label, share, noise, weight in priors:
            rng = bf._rng(name, f"outliers:{label}:{share}")
            prior = bf.sparse_prior(gt, share, rng, noise)
            moved = corrupt(gt, prior, label, rng)
            p = prepare(normals, gt.mask, pixel_size=gt.pixel_size, K=gt.K, prior=prior,
                        prior_weight=weight)
            sample = np.isfinite(p.prior)
            gone = sample & (p.prior_weight == 0)
            truth = moved[gt.mask]  # (the facets are the mask's pixels in row-major order)
            row = dict(group=group, scene=name, prior=label, share=share, weight=weight,
                       normals=args.normals, samples=int(sample.sum()),
                       moved=int(truth.sum()), found=int((gone & truth).sum()),
                       false=int((gone & ~truth).sum()))
            for col in columns:
                for mode in ("keep", "remove"):
                    t = time.perf_counter()
                    s = facetlift.integrate(normals, gt.mask, pixel_size=gt.pixel_size, K=gt.K,
                                            prior=prior, prior_weight=weight,
                                            prior_outliers=mode, **COLUMNS[col])
                    row[f"{col} t_{mode}"] = time.perf_counter() - t
                    row[f"{col} {mode}"] = error(gt, s.depth)
                print(f"| {group} | {name} | {label} | {weight:g} | {row['samples']} | "
                      f"{row['moved']} | {row['found']} | {row['false']} | {col} | "
                      f"{row[col + ' keep']:.4f} | {row[col + ' remove']:.4f} |", flush=True)
            rows.append(row)
            if out is not None:
                out.write(json.dumps(row) + "\n")
                out.flush()
    summary(rows, columns)
    return 0


def error(gt, depth) -> float:
    """Mean absolute error without alignment: mm with a camera, else % of the depth range."""
    e = float(np.nanmean(np.abs(depth - gt.depth)[gt.mask]))
    return e if gt.K is not None else 100.0 * e / gt.depth_range


def summary(rows: list[dict], columns: list[str]) -> None:
    """Per group (perspective with wide, orthographic), prior, weight and column."""
    groups = defaultdict(list)
    for r in rows:
        g = "ortho" if r["group"] == "ortho" else "pinhole"
        groups[(g, r["prior"], r["weight"])].append(r)
    print("\n| group | prior | weight | runs | found / moved | false / samples | column | "
          "mean keep → remove | better / worse | median s keep / remove |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (g, label, w), rs in sorted(groups.items()):
        found = sum(r["found"] for r in rs)
        moved = sum(r["moved"] for r in rs)
        false = sum(r["false"] for r in rs)
        n = sum(r["samples"] for r in rs)
        for col in columns:
            k = np.array([r[f"{col} keep"] for r in rs])
            m = np.array([r[f"{col} remove"] for r in rs])
            better, worse = int((m < 0.99 * k).sum()), int((m > 1.01 * k).sum())
            tk = np.median([r[f"{col} t_keep"] for r in rs])
            tr = np.median([r[f"{col} t_remove"] for r in rs])
            print(f"| {g} | {label} | {w:g} | {len(rs)} | {found} / {moved} | {false} / {n} | "
                  f"{col} | {k.mean():.4f} → {m.mean():.4f} | {better} / {worse} | "
                  f"{tk:.3f} / {tr:.3f} |")


if __name__ == "__main__":
    raise SystemExit(main())
