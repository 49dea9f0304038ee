"""Jump-free regions: is `discontinuities=True` the smooth DGP where there is nothing to cut?

Issue 9 asks that on a surface without jumps the discontinuity route equal the smooth DGP
within 1 % of the error. The discontinuity benchmark's own jump-free scenes are nearly flat;
this script takes the curved and creased surfaces of its renders instead: for every scene of
``facetlift bench --experiments discontinuities`` (perspective, wide-angle and orthographic
renders of ../shared/data/meshes, from the same cache) the largest region without a depth
jump between neighbours (:func:`facetlift.synthetic.continuous_region`), integrated alone by
``dgp`` and by ``dgp`` with ``discontinuities=True`` under each condition (exact, 16-bit,
8-bit, 3-degree noise). Reported per group and condition: the ratio of the two errors (MADE
for a camera, the paper's normalised error for orthographic views): median, mean, the number
above 1.01 and the largest (errors below :data:`EXACT` count as exact); ``--json`` writes
every region's row.

Usage::

    .venv/bin/python benchmarks/bench_jump_free.py
    .venv/bin/python benchmarks/bench_jump_free.py --step 3 --conditions exact,noise3
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

#: Errors are compared as ``(disc + EXACT) / (smooth + EXACT)``: both below this (mm of MADE,
#: or % of the depth range) are exact (the analytic scenes' planar regions come out at 1e-12
#: and 1e-7 %, a meaningless ratio of 1e5).
EXACT = 1e-4


def regions(ctx, step: int, groups):
    """(group, name, region ground truth) of every `step`-th usable scene of the benchmark."""
    from facetlift import synthetic
    from facetlift.bench import discontinuities as bd

    data = [s for s in bd.scenes(ctx) if s[0] in groups][::step]
    for group, name, gt in bd.usable(ctx, data, "regions"):
        try:
            reg = synthetic.continuous_region(gt)
        except ValueError:
            continue
        if reg.mask.sum() < ctx.settings.disc_min_pixels or reg.depth_range < bd._flat(reg):
            continue  # (too small, or a flat view: its normalised error is undefined)
        yield group, name, replace(reg, name=name)


def run(ctx, step, groups, conditions, out=None) -> list[dict]:
    from facetlift.bench import discontinuities as bd
    from facetlift.bench.core import Spec, run_method

    smooth = Spec("dgp", "dgp", ())
    disc = Spec("dgp-disc", "dgp", (("discontinuities", True),))
    rows = []
    for group, name, gt in regions(ctx, step, groups):
        for cond in conditions:
            normals = bd.condition(gt, cond, f"{group}:{name}")
            row = {"group": group, "scene": name, "condition": cond,
                   "pixels": int(gt.mask.sum())}
            for spec in (smooth, disc):
                t = time.perf_counter()
                r = run_method(spec, normals, gt.mask, pixel_size=gt.pixel_size, K=gt.K)
                row[spec.label] = (bd.error_of(gt, r.surface.depth) if r.surface is not None
                                   else float("nan"))
                row[spec.label + "_s"] = time.perf_counter() - t
            row["ratio"] = (row["dgp-disc"] + EXACT) / (row["dgp"] + EXACT)
            rows.append(row)
            if out is not None:
                out.write(json.dumps(row) + "\n")
                out.flush()
        print(f"{group} {name}", file=sys.stderr, flush=True)
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| group | condition | regions | median ratio | mean ratio | above 1.01 | largest |",
             "|---|---|---|---|---|---|---|"]
    keys = sorted({(r["group"], r["condition"]) for r in rows})
    for g, c in keys:
        ratio = np.array([r["ratio"] for r in rows if (r["group"], r["condition"]) == (g, c)
                          and np.isfinite(r["ratio"])])
        if not ratio.size:
            continue
        worst = max((r for r in rows if (r["group"], r["condition"]) == (g, c)
                     and np.isfinite(r["ratio"])), key=lambda r: r["ratio"])
        lines.append(f"| {g} | {c} | {ratio.size} | {np.median(ratio):.3f} | "
                     f"{ratio.mean():.3f} | {int((ratio > 1.01).sum())} | "
                     f"{worst['ratio']:.3f} ({worst['scene']}) |")
    return "\n".join(lines)


def scene_arguments(description: str) -> argparse.ArgumentParser:
    """A parser with the options every script over the benchmark's renders takes: --data,
    --cache, --step, --groups."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    ap.add_argument("--cache", type=Path,
                    default=Path(os.environ.get("FACETLIFT_BENCH_CACHE",
                                                "/tmp/facetlift-bench-cache/discontinuities")),
                    help="render cache (the benchmark's: $FACETLIFT_BENCH_CACHE)")
    ap.add_argument("--step", type=int, default=1, help="every STEP-th scene")
    ap.add_argument("--groups", default="perspective,wide,ortho",
                    help="comma-separated groups of the benchmark (perspective, wide, ortho, "
                    "tabletop, room, vessel)")
    return ap


def add_conditions(ap: argparse.ArgumentParser, default: str) -> None:
    """The --conditions option of a script over the benchmark's renders (read it with
    :func:`conditions_of`)."""
    from facetlift.bench.discontinuities import CONDITIONS

    ap.add_argument("--conditions", default=default,
                    help=f"comma-separated conditions of the benchmark (default {default}; "
                    f"known: {', '.join(CONDITIONS)})")


def conditions_of(ap: argparse.ArgumentParser, text: str) -> list[str]:
    """The conditions named in `text` (comma-separated), or the parser's usage error naming
    the unknown ones, or that none was given."""
    from facetlift.bench.discontinuities import CONDITIONS

    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [c for c in names if c not in CONDITIONS]
    if not names or unknown:
        ap.error(f"--conditions: {'unknown ' + ', '.join(unknown) if unknown else 'none given'}"
                 f"; known: {', '.join(CONDITIONS)}")
    return names


def run_arguments(description: str) -> argparse.ArgumentParser:
    """:func:`scene_arguments` of a script that runs every group of the renders
    (:func:`scene_runs`): also --conditions (default exact), --models and --csv."""
    ap = scene_arguments(description)
    ap.set_defaults(groups="perspective,wide,ortho,tabletop,room,vessel")
    add_conditions(ap, "exact")
    ap.add_argument("--models", default="",
                    help="comma-separated mesh or scene names (default: every scene)")
    ap.add_argument("--csv", type=Path, default=None, help="write every run here")
    return ap


def selected_scenes(ctx, a) -> list:
    """``(group, name, loader)`` of the benchmark's scenes that parsed arguments `a` of
    :func:`run_arguments` select (--groups, --models, every --step-th; `ctx.models` set),
    where none is said so on stderr."""
    from facetlift.bench import discontinuities as D

    ctx.models = tuple(m.strip() for m in a.models.split(",") if m.strip()) or None
    groups = [g.strip() for g in a.groups.split(",") if g.strip()]
    scenes = [t for t in D.scenes(ctx) if t[0] in groups][::max(a.step, 1)]
    if not scenes:
        print("no scene selected (see --data, --groups, --models)", file=sys.stderr)
    return scenes


def scene_runs(ap, ctx, scenes, conditions, csv_path, keys, measure, line) -> list:
    """Every usable scene of `scenes` (``(group, name, loader)``) under each of `conditions`:
    ``measure(group, name, condition, gt, normals)`` gives a row (a dict with `keys`; None, or
    an exception, which is printed, skips the run and the script goes on), written to
    `csv_path` (if given; an unwritable path is the parser `ap`'s error) and printed as
    ``line(group, name, condition, row)``; the solvers' notes silenced meanwhile, restored
    after (the tests run scripts in-process). Returns ``[(group, name, condition, row)]``."""
    import csv
    import logging

    from facetlift.bench import discontinuities as D

    try:
        fh = open(csv_path, "w", newline="") if csv_path else None
    except OSError as e:
        ap.error(f"--csv: {e}")
    writer = csv.writer(fh) if fh else None
    if writer:
        writer.writerow(["group", "scene", "condition", *keys])
    rows = []
    logging.disable(logging.INFO)
    try:
        for group, name, gt in D.usable(ctx, scenes, "scenes"):
            for cond in conditions:
                normals = D.condition(gt, cond, f"{group}:{name}")
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    try:
                        row = measure(group, name, cond, gt, normals)
                    except Exception as e:  # (recorded; the run goes on, as the benchmark's)
                        print(f"{group} {name} {cond}: {type(e).__name__}: {e}",
                              file=sys.stderr)
                        continue
                if row is None:
                    continue
                rows.append((group, name, cond, row))
                if writer:
                    writer.writerow([group, name, cond, *(row[k] for k in keys)])
                    fh.flush()
                print(line(group, name, cond, row), flush=True)
    finally:
        logging.disable(logging.NOTSET)
        if fh:
            fh.close()
    return rows


def grouped(rows):
    """``(condition, group, [row dicts])`` of :func:`scene_runs`' rows for every condition and
    group that has runs, each in the order first met (the scripts' tables of means)."""
    for cond in dict.fromkeys(r[2] for r in rows):
        for g in dict.fromkeys(r[0] for r in rows):
            sel = [r[3] for r in rows if r[0] == g and r[2] == cond]
            if sel:
                yield cond, g, sel


def context(a):
    """The benchmark's context for parsed :func:`scene_arguments` (warnings silenced)."""
    from facetlift.bench.core import Context, Settings

    warnings.simplefilter("ignore")
    os.environ["FACETLIFT_BENCH_CACHE"] = str(a.cache)  # (the bench's own cache variable)
    return Context(out=a.cache.parent, settings=Settings(), data=a.data)


def main(argv=None) -> int:
    ap = scene_arguments(__doc__.split("\n\n")[0])
    ap.add_argument("--conditions", default="exact,16bit,8bit,noise3")
    ap.add_argument("--json", type=Path, help="write every region's row (one JSON per line)")
    a = ap.parse_args(argv)
    ctx = context(a)
    out = open(a.json, "w") if a.json else None
    try:
        rows = run(ctx, a.step, tuple(a.groups.split(",")), tuple(a.conditions.split(",")),
                   out)
    finally:
        if out is not None:
            out.close()
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
