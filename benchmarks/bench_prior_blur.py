"""A coarse depth prior given as blurred (``prior_blur``) against the same prior pixel by pixel.

Scenes of the fusion benchmark (``facetlift bench --experiments fusion``: the discontinuity
development renders, perspective and orthographic, and the analytic jump scenes), every
``--step``-th of them, exact normals (``--normals`` 8bit, 16bit or noise3: the discontinuity
benchmark's conditions). The prior is the benchmark's ``coarse`` one (the true
depth averaged over 8 x 8 blocks, blurred by a Gaussian of one block, upsampled bilinearly:
:func:`facetlift.bench.fusion.coarse_prior`), given either pixel by pixel at the benchmark's
weight (0.01, ``pointwise``) or with ``prior_blur`` = :data:`facetlift.bench.fusion.BLUR_SIGMA`
(8.94 px; ``--sigma`` gives another, to measure a misjudged blur) at each of ``--weights``.
Errors after the alignment every input gets alike (:func:`facetlift.bench.fusion.
aligned_error`: orthographic % of the depth range with the best offset per component,
perspective MADE in mm after the median scale), beside the normals-only result of the same
column and the prior alone. Per column and prior: the scenes where the fusion beats both
inputs, the geometric mean of its error over the better input's, and the median time over the
normals-only time (measured in this process, one run each). Renders are cached where
``FACETLIFT_BENCH_CACHE`` points (built on first use, minutes).

``--real`` runs the real normal maps with ground truth instead (the DiLiGenT bear), with the
coarse prior made from their ground truth.

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_prior_blur.py --step 2
    .venv/bin/python benchmarks/bench_prior_blur.py --real --weights 0.003,0.001
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"
COLUMNS = {"dgp": {}, "dgp-disc": {"discontinuities": True}}


def main(argv=None) -> int:
    import facetlift
    from facetlift.bench import discontinuities as bd
    from facetlift.bench import fusion as bf
    from facetlift.bench.core import Context, Settings

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=2, help="every step-th scene")
    ap.add_argument("--weights", default="0.001,0.003,0.01", help="prior weights with the blur")
    ap.add_argument("--columns", default="dgp,dgp-disc")
    ap.add_argument("--sigma", type=float, default=None,
                    help="prior_blur given (default: the prior's own, BLUR_SIGMA; another "
                    "value measures a misjudged blur)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--normals", default="exact", choices=("exact", "16bit", "8bit", "noise3"),
                    help="the normals' condition (the discontinuity benchmark's: quantised or "
                    "with 3 degrees of noise)")
    ap.add_argument("--real", action="store_true",
                    help="instead: the real normal maps with ground-truth depth (the DiLiGenT "
                    "bear), the coarse prior made from their ground truth")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.real:
        return real(args)
    weights = [float(w) for w in args.weights.split(",")]
    sigma = bf.BLUR_SIGMA if args.sigma is None else args.sigma
    columns = args.columns.split(",")
    ctx = Context(out=Path("/tmp/facetlift-bench-prior-blur"), settings=Settings(),
                  data=args.data)
    scenes = [s for s in bd.scenes(ctx) if s[0] in ctx.settings.fusion_groups][::args.step]
    labels = ["pointwise"] + [f"blur w={w:g}" for w in weights]
    stats = {(c, lab): {"ratio": [], "wins": 0, "n": 0, "time": []} for c in columns
             for lab in labels}
    print("| scene | prior | " + " | ".join(
        f"{c} normals | " + " | ".join(f"{c} {lab}" for lab in labels) for c in columns) + " |")
    print("|---|---|" + "---|" * (len(columns) * (1 + len(labels))))
    for group, name, gt in bd.usable(ctx, scenes, "prior-blur"):  # (the fusion bench's set)
        normals = bd.condition(gt, args.normals, name)
        prior = bf.coarse_prior(gt)
        e_prior = bf.aligned_error(gt, prior)
        cells = [f"{group[:5]} {name}", f"{e_prior:.3f}"]
        for col in columns:
            def run(_col=col, gt=gt, normals=normals, **kw):
                t = time.perf_counter()
                s = facetlift.integrate(normals, gt.mask, pixel_size=gt.pixel_size,
                                        K=gt.K, **COLUMNS[_col], **kw)
                return bf.aligned_error(gt, s.depth), time.perf_counter() - t, s.info

            e_n, t_n, _ = run()
            cells.append(f"{e_n:.3f}")
            for lab in labels:
                if lab == "pointwise":
                    e, t, info = run(prior=prior, prior_weight=bf.WEIGHTS["coarse"])
                else:
                    w = float(lab.split("=")[1])
                    e, t, info = run(prior=prior, prior_weight=w, prior_blur=sigma)
                st = stats[(col, lab)]
                best = min(e_n, e_prior)
                st["n"] += 1
                st["wins"] += e < best
                st["ratio"].append(math.log(max(e, 1e-12) / max(best, 1e-12)))
                st["time"].append(t / t_n)
                mark = "**" if e < best else ""
                cells.append(f"{mark}{e:.3f}{mark} ({t:.2f} s)")
        print("| " + " | ".join(cells) + " |", flush=True)
    print("\n| column | prior | beats both | geometric-mean ratio to the better input | "
          "median time / normals-only |")
    print("|---|---|---|---|---|")
    for (col, lab), st in stats.items():
        if st["n"]:
            print(f"| {col} | {lab} | {st['wins']}/{st['n']} | "
                  f"{math.exp(np.mean(st['ratio'])):.3f} | {np.median(st['time']):.2f} |")
    return 0


def real(args) -> int:
    """The real normal maps of ``--data`` with ground-truth depth (``depth_gt.npz``), read as a
    user would (:func:`facetlift.io.read_dataset`), with the coarse prior of their ground
    truth: MADE (median scale), the error without alignment and the deviation from the input,
    per column and prior."""
    from types import SimpleNamespace

    import facetlift
    from facetlift import metrics
    from facetlift.bench import fusion as bf
    from facetlift.io import read_dataset

    weights = [float(w) for w in args.weights.split(",")]
    sigma = bf.BLUR_SIGMA if args.sigma is None else args.sigma
    print("| map | column | prior | MADE mm | without alignment mm | deviation deg | s |")
    print("|---|---|---|---|---|---|---|")
    for folder in sorted(p for p in (args.data / "normal_maps").iterdir()
                         if (p / "depth_gt.npz").is_file()):
        ds = read_dataset(folder)
        with np.load(folder / "depth_gt.npz") as z:
            truth = np.asarray(z["depth_gt"], float)
        mask = ds["mask"] if ds["mask"] is not None else np.isfinite(ds["normals"]).all(-1)
        gt = SimpleNamespace(mask=mask & np.isfinite(truth), depth=truth)
        prior = bf.coarse_prior(gt)
        m = gt.mask & np.isfinite(prior)
        print(f"| {folder.name} | - | alone | {metrics.made(prior, truth, m)[0]:.4f} | "
              f"{np.mean(np.abs(prior - truth)[m]):.4f} | | |")
        runs = [("normals only", {}), ("pointwise w=0.01", {"prior": prior,
                                                            "prior_weight": 0.01})]
        runs += [(f"blur w={w:g}", {"prior": prior, "prior_weight": w, "prior_blur": sigma})
                 for w in weights]
        for col in args.columns.split(","):
            for label, kw in runs:
                t = time.perf_counter()
                s = facetlift.integrate(ds["normals"], ds["mask"], K=ds["K"], **COLUMNS[col],
                                        **kw)
                t = time.perf_counter() - t
                m = s.mask & np.isfinite(truth)
                made = metrics.made(s.depth, truth, m)[0]
                ab = f"{np.mean(np.abs(s.depth - truth)[m]):.4f}" if kw else "-"
                print(f"| {folder.name} | {col} | {label} | {made:.4f} | {ab} | "
                      f"{s.info['mean_deviation']:.2f} | {t:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
