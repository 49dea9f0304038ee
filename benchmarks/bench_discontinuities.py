"""Speed of the discontinuity-preserving DGP against the smooth DGP and BiNI, in one run.

Objects of about 50k pixels in a 512 x 612 image (the issue's size class): the DiLiGenT bear
(real, 41k pixels) and meshes of ../shared/data/meshes rendered with DiLiGenT's camera and a
larger ``fill`` (organic meshes loop-subdivided as in the discontinuity benchmark). Every
method runs `--repeat` times on the same input in this process, interleaved, and the median
wall time is reported with the ratio to BiNI measured in the same run (the machine is shared;
compare ratios, not seconds). Growth to 2048^2 and the peak memory are measured by
``bench_memory.py --cases 'dgp:rect:discontinuities;dgp:disk:discontinuities'``.

Usage::

    .venv/bin/python benchmarks/bench_discontinuities.py --repeat 3
    .venv/bin/python benchmarks/bench_discontinuities.py --meshes stanford_bunny --fill 0.8
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"

COLUMNS = (
    ("dgp", "dgp", {}),
    ("dgp-disc", "dgp", {"discontinuities": True}),
    ("bini", "bini", {}),
)


def inputs(meshes, fill: float):
    """(name, normals, mask, K, depth_gt or None) of every object."""
    from facetlift import io, synthetic
    from facetlift.bench.discontinuities import _pinhole, load_mesh

    out = []
    bear = DATA / "normal_maps" / "diligent_bear"
    if bear.is_dir():
        ds = io.read_dataset(bear)
        with np.load(bear / "depth_gt.npz") as z:
            gt = np.asarray(z["depth_gt"], float)
        out.append(("diligent_bear", ds["normals"], ds["mask"], ds["K"], gt))
    for name in meshes:
        path = DATA / "meshes" / f"{name}.ply"
        if not path.is_file():
            print(f"skipped {name}: {path} not found", file=sys.stderr)
            continue
        res = (512, 612)
        g = synthetic.render_perspective(load_mesh(path), _pinhole(res), res, fill=fill,
                                         samples=3)
        out.append((f"{name}@front", g.normals, g.mask, g.K, g.depth))
    return out


def main(argv=None) -> int:
    import facetlift
    from facetlift import metrics

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", default="stanford_bunny,armadillo,max_planck")
    ap.add_argument("--fill", type=float, default=0.85)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    print("| object | pixels | method | median s | / bini | MADE | iterations | converged |")
    print("|---|---|---|---|---|---|---|---|")
    for name, n, mask, K, gt in inputs(args.meshes.split(","), args.fill):
        times = {c[0]: [] for c in COLUMNS}
        last = {}
        for _ in range(args.repeat):
            for label, method, opts in COLUMNS:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    s = facetlift.integrate(n, mask, K=K, method=method, **opts)
                    times[label].append(time.perf_counter() - t0)
                last[label] = s
        ref = statistics.median(times["bini"])
        for label, _, _ in COLUMNS:
            s = last[label]
            t = statistics.median(times[label])
            made = metrics.made(s.depth, gt, s.mask & np.isfinite(gt))[0]
            print(f"| {name} | {int(s.mask.sum()):,} | {label} | {t:.2f} | {t / ref:.2f} | "
                  f"{made:.3f} | {s.info.get('iterations')} | {s.info.get('converged')} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
