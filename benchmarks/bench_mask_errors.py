"""Masks as users draw them: the discontinuity route and BiNI with a mask one pixel off.

A real mask is hand-drawn or thresholded, so its edge is rarely the object's silhouette: it
takes in a ring of background pixels, or cuts a ring of the object off. On the renders of the
development benchmark (``facetlift bench --experiments discontinuities``; every ``--step``-th
scene of ``--groups``, exact normals), each method integrates the map with

* ``true``: the render's own mask;
* ``dil_flat``: the mask grown by one pixel (8-connected), the new ring's normals facing the
  camera (a flat background, as a photometric stereo or a network estimates it there);
* ``dil_copy``: the same ring with the normal of the nearest object pixel (an estimate that
  smears the object's normals outward);
* ``eroded``: the mask shrunk by one pixel.

Printed per scene and per variant: MADE in mm (median scale, as BiNI) for the pinhole groups,
the paper's normalised error in % for ``ortho``, over the render's mask within the one used;
then the mean per variant and method, and the scenes each method wins by more than 1 %.
Nothing is tuned on it (docs/results.md, "Discontinuities: masks one pixel off").

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_mask_errors.py \\
        --groups perspective,wide,ortho --step 3
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
VARIANTS = ("true", "dil_flat", "dil_copy", "eroded")
METHODS = (("dgp-disc", {"method": "dgp", "discontinuities": True}),
           ("bini", {"method": "bini"}))


def variants(gt) -> dict:
    """``{variant: (normals, mask)}`` of the render `gt` (module docstring)."""
    from scipy import ndimage

    m, n = gt.mask, gt.normals
    ring = ndimage.binary_dilation(m, np.ones((3, 3), bool)) & ~m
    flat = n.copy()
    flat[ring] = (0.0, 0.0, 1.0)
    _, (rr, cc) = ndimage.distance_transform_edt(~m, return_indices=True)
    copied = n.copy()
    copied[ring] = n[rr[ring], cc[ring]]
    return {"true": (n, m), "dil_flat": (flat, m | ring), "dil_copy": (copied, m | ring),
            "eroded": (n, ndimage.binary_erosion(m, np.ones((3, 3), bool)))}


def error(gt, depth, used) -> float:
    """The benchmark's error of `depth` over the render's mask within the mask `used`."""
    from facetlift import metrics

    keep = gt.mask & used & np.isfinite(depth)
    if gt.K is not None:
        return metrics.made(depth, gt.depth, keep)[0]
    return 100.0 * metrics.normalized_error(depth, gt.depth, keep)[0]


def compare(argv, doc: str, make_variants, names, groups: str = "perspective") -> int:
    """Integrate every ``--step``-th render of ``--groups`` in each variant of
    ``make_variants(gt)`` (``{variant: (normals, mask, K)}``, in the order of `names`) with
    the discontinuity route and BiNI; print each scene's errors, then each group's means and
    wins. Shared by this script and ``bench_camera_errors.py``."""
    sys.path.insert(0, str(HERE))
    import warnings

    from bench_jump_free import context, scene_arguments

    import facetlift
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import method_status

    ap = scene_arguments(doc.split("\n\n")[0])
    ap.set_defaults(step=3, groups=groups)
    args = ap.parse_args(argv)
    ctx = context(args)
    ctx.status = method_status(["dgp"])
    ctx.models = None
    groups = [g.strip() for g in args.groups.split(",") if g.strip()]
    scenes = [t for t in D.scenes(ctx) if t[0] in groups][::max(args.step, 1)]
    rows = []
    for group, name, gt in D.usable(ctx, scenes, "scenes"):
        line = [f"{group} {name}"]
        for variant, (normals, mask, K) in make_variants(gt).items():
            for label, kw in METHODS:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        s = facetlift.integrate(normals, mask, K=K,
                                                pixel_size=gt.pixel_size, **kw)
                    e = error(gt, s.depth, mask)
                except (ValueError, facetlift.SolverError) as ex:
                    e = math.nan
                    print(f"{name} {variant} {label}: {ex}", file=sys.stderr)
                rows.append((group, name, variant, label, e))
                line.append(f"{variant}:{label}={e:.3f}")
        print(" ".join(line), flush=True)
    print("\n| group | variant | dgp-disc | BiNI | dgp-disc wins / losses (> 1 %) |")
    print("|---|---|---|---|---|")
    for group in groups:
        for variant in names:
            got = {lab: [r[4] for r in rows if r[0] == group and r[2] == variant and r[3] == lab]
                   for lab, _ in METHODS}
            a, b = got["dgp-disc"], got["bini"]
            if not a:
                continue
            wins = sum(x < 0.99 * y for x, y in zip(a, b, strict=True))
            losses = sum(x > 1.01 * y for x, y in zip(a, b, strict=True))
            print(f"| {group} | {variant} | {np.nanmean(a):.3f} | {np.nanmean(b):.3f} | "
                  f"{wins} / {losses} of {len(a)} |")
    return 0


def main(argv=None) -> int:
    return compare(argv, __doc__,
                   lambda gt: {k: (n, m, gt.K) for k, (n, m) in variants(gt).items()},
                   VARIANTS)


if __name__ == "__main__":
    sys.exit(main())
