"""Where the discontinuity route's cuts cost error: its own cuts against the true jumps.

For every ``--step``-th render of ``--groups`` under ``--conditions`` this runs ``dgp-disc``
(the route's defaults) and then the oracle's integration and occlusion rule
(:func:`facetlift.bench.discontinuities.oracle`) on other sets of cut edges, the occluding
sides decided from the route's own result (``sides=``) except in the oracle's column:

* ``own``: the route's cuts (``Surface.cuts``) through the oracle's rule: about the route's
  own error, less what its other steps (small pieces hung, the final weights) change;
* ``own near``: only those of its cuts within ``--tolerance`` pixels of a true jump (its cuts
  at creases and folds dropped);
* ``own + true``: its cuts and the true jumps' edges (the jumps it missed added);
* ``true``: the true jumps alone (:func:`facetlift.synthetic.jump_edges`), with the route's
  sides;
* ``oracle``: the true jumps with the truth's sides (the benchmark's oracle).

and the cuts' precision (the share of the route's cut edges within the tolerance of a true
jump) and recall (the share of the true jump edges within it of a cut), the table's being
means of the scenes' shares (a scene without cuts or jumps left out). Errors are the
benchmark's (MADE in mm for the pinhole groups, the paper's error in % for ``ortho``). A
diagnostic of where the cuts go wrong, for the route's development; nothing is tuned on it.

Usage::

    .venv/bin/python benchmarks/bench_cut_errors.py --cache /tmp/bcache \\
        --groups perspective,wide,ortho,tabletop,room,vessel --conditions exact
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: The columns of the error table, in order (see the module docstring).
COLUMNS = ("route", "own", "own near", "own + true", "true", "oracle")


def near(right, down, pixels, tolerance: int):
    """The edges of ``(right, down)`` both of whose pixels lie within `tolerance` pixels
    (8-connected) of a pixel of the (H, W) bool map `pixels`."""
    from scipy import ndimage

    grown = pixels if tolerance <= 0 else ndimage.binary_dilation(
        pixels, structure=np.ones((3, 3), bool), iterations=tolerance)
    return right & grown[:, :-1] & grown[:, 1:], down & grown[:-1] & grown[1:]


def touched(right, down, shape) -> np.ndarray:
    """(H, W) bool: the pixels on either side of an edge of ``(right, down)``."""
    out = np.zeros(shape, bool)
    out[:, :-1] |= right
    out[:, 1:] |= right
    out[:-1] |= down
    out[1:] |= down
    return out


def count(edges) -> int:
    return int(sum(int(e.sum()) for e in edges))


def decompose(gt, normals, surface, tolerance: int = 1) -> dict:
    """The errors of :data:`COLUMNS` (the route's from `surface`) and the cuts' counts,
    precision and recall on one scene."""
    from facetlift import synthetic
    from facetlift.bench import discontinuities as D

    own = tuple(np.asarray(e, bool) for e in surface.cuts)
    true = tuple(np.asarray(e, bool) for e in synthetic.jump_edges(gt))
    shape = gt.mask.shape
    own_near = near(*own, touched(*true, shape), tolerance)
    true_near = near(*true, touched(*own, shape), tolerance)
    sets = {
        "own": own,
        "own near": own_near,
        "own + true": (own[0] | true[0], own[1] | true[1]),
        "true": true,
    }
    row = {"route": D.error_of(gt, surface.depth)}
    for label, cuts in sets.items():
        row[label] = D.oracle(gt, normals, cuts=cuts, sides=surface.depth)[0]
    row["oracle"] = D.oracle(gt, normals)[0]
    n_own, n_true = count(own), count(true)
    row.update(cuts=n_own, jumps=n_true,
               precision=count(own_near) / n_own if n_own else math.nan,
               recall=count(true_near) / n_true if n_true else math.nan)
    return row


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_jump_free import conditions_of, context, run_arguments, scene_runs, selected_scenes

    from facetlift.bench.core import Spec, method_status

    ap = run_arguments(__doc__.split("\n\n")[0])
    ap.add_argument("--tolerance", type=int, default=1,
                    help="pixels between a cut and a true jump that still count as the same "
                    "place (default 1: a cut one pixel beside the jump, across a row of mixed "
                    "pixels, is near)")
    args = ap.parse_args(argv)
    conditions = conditions_of(ap, args.conditions)
    if args.tolerance < 0:
        ap.error(f"--tolerance must be 0 or more; got {args.tolerance}")
    ctx = context(args)
    ctx.status = method_status(["dgp"])
    scenes = selected_scenes(ctx, args)
    if not scenes:
        return 1
    spec = Spec("dgp-disc", "dgp", (("discontinuities", True),))
    keys = (*COLUMNS, "cuts", "jumps", "precision", "recall")
    t0 = time.time()

    def measure(group, name, cond, gt, normals):
        r = ctx.measure(spec, normals, gt.mask, lambda s: s, pixel_size=gt.pixel_size, K=gt.K)
        if r[0].status != "ok":
            print(f"{group} {name} {cond}: the route failed: {r[0].message}", file=sys.stderr)
            return None
        return decompose(gt, normals, r[1], args.tolerance)

    def line(group, name, cond, row):
        errors = "  ".join(f"{k} {row[k]:8.3f}" for k in COLUMNS)
        return (f"{group:11s} {name:40s} {cond:6s} {errors}  precision "
                f"{row['precision']:.2f} recall {row['recall']:.2f}  "
                f"[{time.time() - t0:.0f} s]")

    rows = scene_runs(ap, ctx, scenes, conditions, args.csv, keys, measure, line)
    print(table(rows))
    return 0


def table(rows) -> str:
    """Markdown: each group's and condition's mean of every column."""
    head = ("| group | condition | scenes | " + " | ".join(COLUMNS)
            + " | precision | recall |\n|---|---|---|" + "---|" * (len(COLUMNS) + 2))
    from bench_jump_free import grouped  # (on the path: main put it there)

    lines = [head]
    for cond, g, sel in grouped(rows):
        means = [float(np.nanmean([s[k] for s in sel])) for k in
                 (*COLUMNS, "precision", "recall")]
        lines.append(f"| {g} | {cond} | {len(sel)} | "
                     + " | ".join(f"{m:.3f}" for m in means) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
