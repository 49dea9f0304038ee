"""What a sparse depth prior adds to the time of the smooth DGP, per solver route, in one run.

Scenes of the fusion benchmark (``facetlift bench --experiments fusion``: the discontinuity
development renders, perspective and orthographic, and the analytic jump scenes), every
``--step``-th of them; on each, 1 % exact samples at weight 100 and 1 % samples with noise of
1 % of the depth range at weight 1 (the benchmark's own priors and seeds). Every integration
runs ``--repeat`` times and the best time counts; the ratio is to the same scene without a
prior, measured in this process. Routes: ``amg`` (the default: a Ruge-Stueben trial for sparse
samples, :data:`facetlift.methods.dgp.fixed_point.SPARSE_PRIOR`) and ``facet`` (the facet
preconditioner alone, the trial turned off). With ``--discontinuities`` the same for
``discontinuities=True`` (one route, the default). Renders are cached where
``FACETLIFT_BENCH_CACHE`` points (built on first use, minutes).

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_prior_time.py --step 3
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"


def best(repeat: int, *args, **kwargs):
    """(best wall time, surface) of ``facetlift.integrate(*args, **kwargs)``."""
    import facetlift

    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = facetlift.integrate(*args, **kwargs)
        times.append(time.perf_counter() - t)
    return min(times), out


def main(argv=None) -> int:
    from facetlift.bench import discontinuities as bd
    from facetlift.bench import fusion as bf
    from facetlift.bench.core import Context, Settings
    from facetlift.methods.dgp import fixed_point

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=3, help="every step-th scene")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--discontinuities", action="store_true",
                    help="time discontinuities=True instead of the smooth routes")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    ctx = Context(out=Path("/tmp/facetlift-bench-prior-time"), settings=Settings(),
                  data=args.data)
    scenes = [s for s in bd.scenes(ctx) if s[0] in ("perspective", "ortho")][::args.step]
    routes = ("default",) if args.discontinuities else ("amg", "facet")
    ratios = {r: [] for r in routes}
    by_prior = {}  # (route, prior) -> ratios
    print("| scene | plain s | prior | " + " | ".join(f"{r}: ratio (route, CG)" for r in routes)
          + " |")
    print("|---|---|---|" + "---|" * len(routes))
    default = fixed_point.SPARSE_PRIOR
    try:
        for group, name, load in scenes:
            gt = load()
            if gt.mask.sum() < 500:
                continue
            kw = dict(pixel_size=gt.pixel_size, K=gt.K, discontinuities=args.discontinuities)
            t0, _ = best(args.repeat, gt.normals, gt.mask, **kw)
            for cond, noise, weight in (("sparse 1%", 0.0, 100.0), ("noisy 1%", 0.01, 1.0)):
                prior = bf.sparse_prior(gt, 0.01, bf._rng(name, cond), noise)
                cells = []
                for route in routes:
                    fixed_point.SPARSE_PRIOR = 0.0 if route == "facet" else default
                    t, s = best(args.repeat, gt.normals, gt.mask, prior=prior,
                                prior_weight=weight, **kw)
                    ratios[route].append(t / t0)
                    by_prior.setdefault((route, cond), []).append(t / t0)
                    its = s.info.get("cg_iterations")
                    its = sum(its) if isinstance(its, list) else its
                    cells.append(f"{t / t0:.2f} ({s.info.get('backend', 'reweighted')}, {its})")
                print(f"| {group}:{name} | {t0:.3f} | {cond} | " + " | ".join(cells) + " |",
                      flush=True)
    finally:
        fixed_point.SPARSE_PRIOR = default
    for route, r in ratios.items():
        if r:
            print(f"\n{route}: time ratio median {np.median(r):.2f}, max {np.max(r):.2f}, "
                  f"{len(r)} runs")
            for (rt, cond), rc in by_prior.items():
                if rt == route:
                    print(f"  {cond}: median {np.median(rc):.2f}, max {np.max(rc):.2f}, "
                          f"{len(rc)} runs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
