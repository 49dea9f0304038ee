"""Depth points in the pieces: the discontinuity route given a point in what its cuts separate.

For every ``--step``-th render of ``--groups`` under ``--conditions`` this runs ``dgp-disc``
without a prior, labels the pieces its cuts separate (:meth:`facetlift.Surface.pieces`), and
runs it again with depth points read from the ground truth at ``prior_weight`` ``--weight``:

* ``one``: a point at the middle pixel of the largest piece only. A single sample in its
  component: the route keeps the normals-only surface and moves it to the point
  (:func:`facetlift.methods.dgp.lone_samples`), so this column is the normals-only error
  wherever the scene has one component;
* ``per piece``: a point at the middle pixel of every piece of at least ``--min-piece``
  pixels (docs/recipes.md, "Parts the normals cannot place").

The middle pixel is the middle one of the piece's pixels in row-major order. Reported per
group and condition: the mean error of the normals alone and of each prior, the scenes
better / worse than the normals alone by more than 1 %, the median time ratio to the
normals-only run, and the median number of points. Errors are the benchmark's aligned ones
(:func:`facetlift.bench.discontinuities.error_of`: MADE in mm after the median scale for a
camera, the paper's error in % for ``ortho``). ``--csv`` writes every run.

Usage::

    .venv/bin/python benchmarks/bench_prior_pieces.py --cache /tmp/bcache \\
        --groups perspective,wide,ortho,tabletop,room,vessel
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

#: The priors, in the table's order (see the module docstring).
KINDS = ("one", "per piece")


def points(depth, pieces, min_size: int) -> np.ndarray:
    """(H, W) prior: `depth` at the middle pixel (row-major order) of every piece of
    `pieces` (labels, -1 outside) of at least `min_size` pixels whose depth there is finite;
    NaN elsewhere."""
    prior = np.full(pieces.shape, np.nan)
    order = np.argsort(pieces, axis=None, kind="stable")  # (row-major within a piece)
    labels = pieces.ravel()[order]
    ids = np.arange(int(pieces.max()) + 1)
    starts = np.searchsorted(labels, ids)
    for a, b in zip(starts, np.searchsorted(labels, ids, side="right"), strict=True):
        if b - a >= max(min_size, 1):
            i = order[a + (b - a) // 2]
            if np.isfinite(depth.ravel()[i]):
                prior.ravel()[i] = depth.ravel()[i]
    return prior


def run_scene(gt, normals, min_piece: int = 100, weight: float = 100.0) -> dict:
    """The normals-only error and time, and for each of :data:`KINDS` the error, the time
    and the number of points, on one scene."""
    import facetlift
    from facetlift.bench import discontinuities as D

    def timed(**kw):
        t = time.perf_counter()
        s = facetlift.integrate(normals, gt.mask, K=gt.K, pixel_size=gt.pixel_size,
                                discontinuities=True, **kw)
        return s, time.perf_counter() - t

    free, seconds = timed()
    row = {"normals only": D.error_of(gt, free.depth), "normals only s": seconds}
    pieces = free.pieces()
    largest = np.where(pieces == 0, 0, -1)
    for kind, prior in (("one", points(gt.depth, largest, 1)),
                        ("per piece", points(gt.depth, pieces, min_piece))):
        n = int(np.isfinite(prior).sum())
        if n:
            s, seconds = timed(prior=prior, prior_weight=weight)
            row[kind] = D.error_of(gt, s.depth)
            row[kind + " s"] = seconds
        else:  # (no piece large enough: nothing to give)
            row[kind], row[kind + " s"] = row["normals only"], row["normals only s"]
        row[kind + " points"] = n
    return row


def warm_up() -> None:
    """One small run of each kind, so that the first scene's normals-only run does not pay
    the process's one-time costs alone (its time ratios read 0.73 for a route that is the
    normals-only one plus a shift, a review)."""
    from facetlift import synthetic

    gt = synthetic.analytic("occluder", 32)
    run_scene(gt, gt.normals, min_piece=1)


def table(rows) -> str:
    """Markdown: each group's and condition's means, better / worse, time and points."""
    head = ("| group | condition | scenes | normals only | "
            + " | ".join(f"{k} | better / worse | time ratio | points" for k in KINDS)
            + " |\n|---|---|---|---|" + "---|---|---|---|" * len(KINDS))
    from bench_jump_free import grouped  # (on the path: main put it there)

    lines = [head]
    for cond, g, sel in grouped(rows):
        free = np.array([s["normals only"] for s in sel])
        cells = [f"{free.mean():.3f}"]
        for k in KINDS:
            e = np.array([s[k] for s in sel])
            ratio = np.array([s[k + " s"] / s["normals only s"] for s in sel])
            n = np.array([s[k + " points"] for s in sel])
            cells += [f"{e.mean():.3f}", f"{int((e < 0.99 * free).sum())} / "
                      f"{int((e > 1.01 * free).sum())}", f"{np.median(ratio):.2f}",
                      f"{np.median(n):.0f}"]
        lines.append(f"| {g} | {cond} | {len(sel)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_jump_free import conditions_of, context, run_arguments, scene_runs, selected_scenes

    ap = run_arguments(__doc__.split("\n\n")[0])
    ap.add_argument("--min-piece", type=int, default=100,
                    help="pixels of the smallest piece given a point in 'per piece' "
                    "(default 100)")
    ap.add_argument("--weight", type=float, default=100.0,
                    help="prior_weight of the points (default 100)")
    args = ap.parse_args(argv)
    conditions = conditions_of(ap, args.conditions)
    if args.min_piece < 1:
        ap.error(f"--min-piece must be 1 or more; got {args.min_piece}")
    if not (np.isfinite(args.weight) and args.weight > 0):
        ap.error(f"--weight must be a positive number; got {args.weight}")
    ctx = context(args)
    scenes = selected_scenes(ctx, args)
    if not scenes:
        return 1
    keys = ("normals only", "normals only s",
            *(f"{k}{x}" for k in KINDS for x in ("", " s", " points")))
    t0 = time.time()

    def line(group, name, cond, row):
        errors = "  ".join(f"{k} {row[k]:8.3f}" for k in ("normals only", *KINDS))
        return (f"{group:11s} {name:40s} {cond:6s} {errors}  points "
                f"{row['per piece points']}  [{time.time() - t0:.0f} s]")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        warm_up()
    rows = scene_runs(ap, ctx, scenes, conditions, args.csv, keys,
                      lambda g, n, c, gt, normals: run_scene(gt, normals, args.min_piece,
                                                             args.weight), line)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
