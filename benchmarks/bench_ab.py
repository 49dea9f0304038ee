"""A/B of two settings of the discontinuity route on the development benchmark as a whole.

This is how the route's defaults are chosen (docs/results.md, "Discontinuities: the
development benchmark"): a change is run against the current settings on every scene and
condition of the development benchmark (``facetlift bench --experiments discontinuities``),
or of a held-out set (``--heldout-seed``), in one process, and judged on all of them at once,
never on one object. The errors are deterministic, so the two sides need no repeats; the
times are printed only as totals.

Each side is a list of ``KEY=VALUE`` settings (``--a``, ``--b``; side A defaults to nothing,
the current defaults):

* an option of :func:`facetlift.integrate`, e.g. ``discontinuity_k=3``;
* a module constant by its dotted path, e.g.
  ``facetlift.methods.dgp.discontinuous.STEEP_TAU=0.05``: set for that side's runs and
  restored afterwards.

Values are Python literals (``3``, ``0.05``, ``True``, ``(1, 2)``); anything else is taken
as a string. Every scene and condition runs side A, then side B. Printed:

* the runs where B is better or worse than A by more than ``--margin`` (relative);
* the mean error per group and condition on each side, and their ratio (B / A);
* the mean of those ratios (the *mean group ratio*, below 1 when B is better);
* the runs that moved most.

``--csv`` writes every run. Errors are MADE in mm for the pinhole groups and the paper's
normalised error in % for ``ortho``, as in the benchmark. Renders are cached where
``FACETLIFT_BENCH_CACHE`` points (built on first use: about 10 minutes for the development
set on the 2-core VM, 3 for a held-out set).

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_ab.py \\
        --b facetlift.methods.dgp.discontinuous.STEEP_TAU=0.05 --conditions exact,noise3,noise6
    .venv/bin/python benchmarks/bench_ab.py --heldout-seed 393807 --b discontinuity_k=3
    .venv/bin/python benchmarks/bench_ab.py --groups perspective,wide --models spot,cow \\
        --a discontinuity_k=4 --b discontinuity_k=2 --csv /tmp/ab.csv
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import csv
import importlib
import logging
import os
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"


def parse_setting(text: str) -> tuple[str, object]:
    """``(key, value)`` of one ``KEY=VALUE`` (the value a Python literal, else a string)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ValueError(f"a setting must read KEY=VALUE; got {text!r}")
    try:
        value = ast.literal_eval(raw.strip())
    except (ValueError, SyntaxError):
        value = raw.strip()
    return key, value


def split_settings(items) -> tuple[dict, list[tuple[object, str, object]]]:
    """``(options, constants)`` of the settings `items` (``KEY=VALUE`` strings): options of
    :func:`facetlift.integrate` (a key without a dot) and ``(module, name, value)`` of the
    module constants (a dotted key), each checked to exist."""
    options, constants = {}, []
    for text in items or ():
        key, value = parse_setting(text)
        if "." not in key:
            options[key] = value
            continue
        path, _, name = key.rpartition(".")
        try:
            module = importlib.import_module(path)
        except ImportError as e:
            raise ValueError(f"setting {text!r}: no module {path!r} ({e})") from None
        if not hasattr(module, name):
            raise ValueError(f"setting {text!r}: module {path!r} has no {name!r}")
        constants.append((module, name, value))
    return options, constants


@contextlib.contextmanager
def applied(constants):
    """Set the module constants ``(module, name, value)`` for the block, then restore them."""
    old = [(m, n, getattr(m, n)) for m, n, _ in constants]
    try:
        for m, n, v in constants:
            setattr(m, n, v)
        yield
    finally:
        for m, n, v in reversed(old):
            setattr(m, n, v)


def summarize(rows, margin: float = 0.01) -> dict:
    """Counts and ratios of the runs `rows` (dicts with ``group``, ``scene``, ``condition``,
    ``a`` and ``b``, the two sides' errors; runs where either is not finite are left out):
    ``better`` / ``worse`` (B against A by more than `margin`, relative), ``groups`` (a list
    of ``(group, condition, n, mean A, mean B, ratio)``), ``mean_ratio`` (the mean of the
    ratios, NaN without a group), ``movers`` (the rows by B - A, largest gain first) and
    ``left_out`` (the runs not counted)."""
    import math

    ok = [r for r in rows if math.isfinite(r["a"]) and math.isfinite(r["b"])]
    better = sum(r["b"] < r["a"] * (1.0 - margin) for r in ok)
    worse = sum(r["b"] > r["a"] * (1.0 + margin) for r in ok)
    keys = sorted({(r["group"], r["condition"]) for r in ok})
    groups = []
    for g, c in keys:
        sel = [r for r in ok if r["group"] == g and r["condition"] == c]
        ma = sum(r["a"] for r in sel) / len(sel)
        mb = sum(r["b"] for r in sel) / len(sel)
        groups.append((g, c, len(sel), ma, mb, mb / ma if ma > 0 else math.nan))
    ratios = [x[5] for x in groups if math.isfinite(x[5])]
    return {"better": better, "worse": worse, "runs": len(ok), "groups": groups,
            "mean_ratio": sum(ratios) / len(ratios) if ratios else math.nan,
            "movers": sorted(ok, key=lambda r: r["b"] - r["a"]),
            "left_out": len(rows) - len(ok)}


def report(summary: dict, margin: float, top: int = 8) -> str:
    """The printed summary of :func:`summarize`."""
    lines = [f"runs {summary['runs']}: B better than A in {summary['better']}, worse in "
             f"{summary['worse']} (by more than {margin:.0%})"
             + (f"; {summary['left_out']} left out (a side failed)" if summary["left_out"]
                else ""),
             "",
             "| group | condition | scenes | A | B | B / A |",
             "|---|---|---|---|---|---|"]
    for g, c, n, ma, mb, ratio in summary["groups"]:
        lines.append(f"| {g} | {c} | {n} | {ma:.4f} | {mb:.4f} | {ratio:.3f} |")
    lines += ["", f"mean group ratio {summary['mean_ratio']:.4f}"]
    movers = summary["movers"]
    if movers:
        lines += ["", "largest gains and losses of B:"]
        picked = movers[:top] + [r for r in movers[-top:] if r not in movers[:top]]
        for r in picked:
            lines.append(f"  {r['group']:12s} {r['scene']:40s} {r['condition']:8s} "
                         f"{r['a']:9.4f} -> {r['b']:9.4f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", action="append", default=[], metavar="KEY=VALUE",
                    help="a setting of side A (repeatable); none: the current defaults")
    ap.add_argument("--b", action="append", default=[], metavar="KEY=VALUE",
                    help="a setting of side B (repeatable)")
    ap.add_argument("--conditions", default="exact,noise3",
                    help="comma-separated conditions of the benchmark (exact, 16bit, 8bit, "
                    "noise3, noise6, smooth3, outliers, blur1.5, blur3)")
    ap.add_argument("--heldout-seed", type=int, default=None,
                    help="a held-out set's scenes instead of the development benchmark's")
    ap.add_argument("--groups", default=None,
                    help="comma-separated groups to keep (perspective, wide, ortho, tabletop, "
                    "room, vessel; heldout)")
    ap.add_argument("--models", default=None,
                    help="comma-separated scene or mesh names to keep (e.g. spot, cow@left)")
    ap.add_argument("--quick", action="store_true",
                    help="the benchmark's --quick settings (small scenes; a smoke test)")
    ap.add_argument("--margin", type=float, default=0.01,
                    help="relative change counted as better or worse (default 0.01)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--csv", type=Path, default=None, help="write every run here")
    args = ap.parse_args(argv)

    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings, Spec, run_method

    try:
        sides = [split_settings(args.a), split_settings(args.b)]
    except ValueError as e:
        ap.error(str(e))
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    unknown = [c for c in conditions if c not in D.CONDITIONS]
    if unknown:
        ap.error(f"--conditions: unknown {', '.join(unknown)}; known: "
                 f"{', '.join(D.CONDITIONS)}")
    settings = Settings.quick() if args.quick else Settings()
    if args.heldout_seed is not None:
        settings.heldout_seed = args.heldout_seed
    data = args.data if args.data is not None and args.data.is_dir() else None
    ctx = Context(out=Path(os.environ.get("TMPDIR", "/tmp")), settings=settings, data=data,
                  models=tuple(args.models.split(",")) if args.models else None)
    scenes = D.heldout_scenes(ctx) if args.heldout_seed is not None else D.scenes(ctx)
    if args.groups:
        keep = set(args.groups.split(","))
        scenes = [t for t in scenes if t[0] in keep]
    if not scenes:
        print("no scene selected (is ../shared/data there? see --data, --groups, --models)",
              file=sys.stderr)
        return 1
    specs = [Spec(label, "dgp", (("discontinuities", True),) + tuple(opts.items()))
             for label, (opts, _) in zip("AB", sides, strict=True)]
    rows, seconds, said = [], [0.0, 0.0], [False, False]
    writer = None
    fh = open(args.csv, "w", newline="") if args.csv else None
    try:
        if fh is not None:
            writer = csv.writer(fh)
            writer.writerow(["group", "scene", "condition", "a", "b", "a_seconds",
                             "b_seconds"])
        logging.disable(logging.WARNING)
        for group, name, gt in D.usable(ctx, scenes, "scenes"):
            for cond in conditions:
                normals = D.condition(gt, cond, f"{group}:{name}")
                err, secs = [], []
                for i, spec in enumerate(specs):
                    with applied(sides[i][1]), warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        t = time.perf_counter()
                        r = run_method(spec, normals, gt.mask, pixel_size=gt.pixel_size,
                                       K=gt.K)
                        secs.append(time.perf_counter() - t)
                    err.append(D.error_of(gt, r.surface.depth) if r.status == "ok"
                               else float("nan"))
                    if r.status != "ok" and not said[i]:  # (once per side: e.g. a wrong option)
                        said[i] = True
                        print(f"side {'AB'[i]}: {name} {cond}: {r.status}: {r.message}",
                              file=sys.stderr)
                    seconds[i] += secs[-1]
                row = {"group": group, "scene": name, "condition": cond, "a": err[0],
                       "b": err[1]}
                rows.append(row)
                if writer is not None:
                    writer.writerow([group, name, cond, err[0], err[1], secs[0], secs[1]])
                    fh.flush()
    finally:
        logging.disable(logging.NOTSET)
        if fh is not None:
            fh.close()
    summary = summarize(rows, args.margin)
    print(report(summary, args.margin))
    print(f"\ntime: A {seconds[0]:.1f} s, B {seconds[1]:.1f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
