"""Does `discontinuities=True` keep its lead over BiNI at other image sizes?

The discontinuity benchmark (``facetlift bench --experiments discontinuities``) renders its
perspective scenes at DiLiGenT's 512 x 612 pixels, and every default of the route was chosen
there. Real maps come at other sizes (photometric-stereo rigs of 2048 x 1536 and more,
half-resolution previews), and the one parameter ``discontinuity_k`` is meant to be
scale-free (its differences are scaled by the pixel footprint). This script renders the same
meshes of ../shared/data/meshes with DiLiGenT's intrinsics scaled to another size (the object
then covers proportionally more or fewer pixels) from the given views, and integrates every
scene by ``dgp`` with ``discontinuities=True`` (defaults) and by facetlift's ``bini`` (k = 2)
under each condition (exact, 3-degree noise; the benchmark's seeded conditions). Reported
per condition: MADE (mm, BiNI's median scale) means, wins / losses by more than 1 %, summed
times; ``--json`` writes every scene's row. Renders are cached like the benchmark's (in
``$FACETLIFT_BENCH_CACHE`` or ``--cache``).

Usage::

    .venv/bin/python benchmarks/bench_resolution.py --size 1024x1224 --json r1024.jsonl
    .venv/bin/python benchmarks/bench_resolution.py --size 256x306 --views front,oblique
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1024x1224", help="H x W of the renders (default "
                    "1024x1224, twice DiLiGenT's)")
    ap.add_argument("--views", default="front,oblique")
    ap.add_argument("--conditions", default="exact,noise3")
    ap.add_argument("--min-pixels", type=int, default=500,
                    help="skip scenes with fewer mask pixels (default 500)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--cache", type=Path, default=None,
                    help="render cache (default $FACETLIFT_BENCH_CACHE, else a folder under "
                    "/tmp)")
    ap.add_argument("--json", type=Path, help="write every scene's row here (JSON lines)")
    a = ap.parse_args(argv)
    try:
        H, W = (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        ap.error(f"--size: expected HxW such as 1024x1224, got {a.size!r}")
    if a.cache is not None:
        os.environ["FACETLIFT_BENCH_CACHE"] = str(a.cache)
    warnings.simplefilter("ignore")
    import facetlift
    from facetlift.bench import discontinuities as bd
    from facetlift.bench.core import Context, Settings

    settings = replace(Settings(), disc_resolution=(H, W), disc_views=tuple(a.views.split(",")),
                       disc_wide_views=(), disc_ortho_views=(), disc_analytic=(),
                       disc_tabletop=0, disc_vessels=())
    out = Path(os.environ.get("FACETLIFT_BENCH_CACHE") or "/tmp/facetlift-bench-resolution")
    ctx = Context(out=out, settings=settings, data=a.data)
    conds = a.conditions.split(",")
    rows = []
    sink = open(a.json, "w") if a.json else None
    for group, name, load in bd.scenes(ctx):
        try:
            gt = load()
        except Exception as e:  # (e.g. a mesh that covers no pixel at a small size)
            print(f"{name:26s} skipped: {type(e).__name__}: {e}", flush=True)
            continue
        if gt.mask.sum() < a.min_pixels:
            continue
        for cond in conds:
            normals = bd.condition(gt, cond, f"{group}:{name}")
            row = {"scene": name, "condition": cond, "size": [H, W],
                   "pixels": int(gt.mask.sum())}
            for label, kw in (("dgp-disc", {"method": "dgp", "discontinuities": True}),
                              ("bini", {"method": "bini"})):
                t = time.perf_counter()
                try:
                    s = facetlift.integrate(normals, gt.mask, pixel_size=gt.pixel_size,
                                            K=gt.K, **kw)
                except Exception as e:  # recorded; the scene leaves the tables
                    row["failed"] = f"{label}: {type(e).__name__}: {e}"[:300]
                    break
                row[label + " s"] = time.perf_counter() - t
                row[label] = bd.error_of(gt, s.depth)
            if sink:
                sink.write(json.dumps(row) + "\n")
                sink.flush()
            if "failed" in row:
                print(f"{name:26s} {cond:7s} failed: {row['failed']}", flush=True)
                continue
            rows.append(row)
            print(f"{name:26s} {cond:7s} {row['pixels']:8d} px  dgp-disc {row['dgp-disc']:7.3f} "
                  f"mm {row['dgp-disc s']:6.1f} s   bini {row['bini']:7.3f} mm "
                  f"{row['bini s']:6.1f} s", flush=True)
    print(f"\n{H} x {W}, views {a.views}")
    print("| condition | scenes | dgp-disc mean MADE (mm) | BiNI | wins / losses | dgp-disc / BiNI "
          "time (s) |")
    print("|---|---|---|---|---|---|")
    for cond in conds:
        rs = [r for r in rows if r["condition"] == cond]
        if not rs:
            continue
        d = np.array([r["dgp-disc"] for r in rs])
        b = np.array([r["bini"] for r in rs])
        print(f"| {cond} | {len(rs)} | {d.mean():.3f} | {b.mean():.3f} | "
              f"{int((d < 0.99 * b).sum())} / {int((d > 1.01 * b).sum())} | "
              f"{sum(r['dgp-disc s'] for r in rs):.1f} / {sum(r['bini s'] for r in rs):.1f} |")
    if sink:
        sink.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
