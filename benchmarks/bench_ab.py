"""A/B of two settings of the discontinuity route on the development benchmark as a whole.

This is how the route's defaults are chosen (docs/results.md, "Discontinuities: the
development benchmark"): a change is run against the current settings on the scenes of the
development benchmark (``facetlift bench --experiments discontinuities``: every group by
default), or of a held-out set (``--heldout-seed``), under the conditions given
(``--conditions``, default ``exact,8bit,noise3``), in one process, and judged on all of them at
once, never on one object. The errors are deterministic, so the two sides need no repeats; the
times are printed only as totals (each scene's first run alternates between the sides).

Each side is the current defaults plus a list of ``KEY=VALUE`` settings (``--a``, ``--b``;
side A is the defaults alone unless ``--a`` is given):

* an option of :func:`facetlift.integrate`, e.g. ``discontinuity_k=3`` (checked before any
  run);
* a module constant by its dotted path, e.g.
  ``facetlift.methods.dgp.discontinuous.STEEP_TAU=0.05``: set for that side's runs and
  restored afterwards. Only a constant the route reads when it runs can be changed so: one
  bound as a default argument or imported by value (``DEFAULT_K``, ``DEFAULT_ITER``,
  ``DEFAULT_TOL``; set those through their options) changes nothing, and where a side with
  constants ties the other on every run the script says so.

Values are Python literals (``3``, ``0.05``, ``True``, ``(1, 2)``); a constant's value must be
of its current kind (a number for a number, ``True`` / ``False`` for a flag); an option's
other values are strings. Printed: how many runs B makes better or worse than A by more than
``--margin`` (relative), how many failed on each side, the mean error per group and condition
on each side and their ratio (B / A), the mean of those ratios (the *mean group ratio*, below
1 when B is better) and the runs that moved most (by ratio). ``--csv`` writes every run.
Errors are MADE in mm for the pinhole groups and the paper's normalised error in % for
``ortho``, as in the benchmark. Renders are cached in ``--cache`` (``$FACETLIFT_BENCH_CACHE``,
the benchmark's own cache; built on first use: about 5 minutes for the development set on the
2-core VM, 2 for a held-out set).

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_ab.py \\
        --b facetlift.methods.dgp.discontinuous.STEEP_TAU=0.05 --conditions exact,noise3,noise6
    .venv/bin/python benchmarks/bench_ab.py --heldout-seed 393807 --b discontinuity_k=3
    .venv/bin/python benchmarks/bench_ab.py --groups perspective,wide --models spot,cow \\
        --a discontinuity_k=4 --b discontinuity_k=2 --csv /tmp/ab.csv
"""

from __future__ import annotations

import ast
import contextlib
import csv
import importlib
import logging
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent


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


def _same_kind(current, value) -> bool:
    """Whether `value` may replace a constant's `current` value: a flag by a flag, a number by
    a number (not a flag), anything else by anything."""
    if isinstance(current, bool):
        return isinstance(value, bool)
    if isinstance(current, (int, float)):
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return True


def split_settings(items) -> tuple[dict, list[tuple[object, str, object]]]:
    """``(options, constants)`` of the settings `items` (``KEY=VALUE`` strings): options of
    :func:`facetlift.integrate` (a key without a dot) and ``(module, name, value)`` of the
    module constants (a dotted key), each checked to exist and to keep its kind
    (:func:`_same_kind`: ``GROW=false`` or ``STEEP_TAU=0.O5`` would be a string)."""
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
        current = getattr(module, name)
        if not _same_kind(current, value):
            raise ValueError(f"setting {text!r}: {name} is {current!r} "
                             f"({type(current).__name__}); {value!r} is not of that kind")
        constants.append((module, name, value))
    return options, constants


def check_options(options: dict) -> None:
    """Raise ValueError where `options` are no valid options of the discontinuity route
    (checked as :func:`facetlift.integrate` checks them, before any run)."""
    from facetlift.methods import REGISTRY
    from facetlift.options import validate

    validate(REGISTRY["dgp"].specs(), {**options, "discontinuities": True}, "dgp")


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
    ``a`` and ``b``, the two sides' errors, NaN where a side failed): ``better`` / ``worse``
    (B against A by more than `margin`, relative), ``failed`` (per side), ``groups`` (a list
    of ``(group, condition, n, mean A, mean B, ratio)`` over the runs where both sides
    succeeded), ``mean_ratio`` (the mean of the ratios, NaN without a group), ``movers`` (those
    runs by B / A, the largest gain first) and ``ties`` (runs where B equals A exactly)."""
    ok = [r for r in rows if math.isfinite(r["a"]) and math.isfinite(r["b"])]
    failed = (sum(not math.isfinite(r["a"]) for r in rows),
              sum(not math.isfinite(r["b"]) for r in rows))
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

    def ratio(r):
        return r["b"] / r["a"] if r["a"] > 0 else (1.0 if r["b"] == r["a"] else math.inf)

    return {"better": better, "worse": worse, "runs": len(ok), "failed": failed,
            "groups": groups, "mean_ratio": sum(ratios) / len(ratios) if ratios else math.nan,
            "movers": sorted(ok, key=ratio), "ties": sum(r["b"] == r["a"] for r in ok)}


def report(summary: dict, margin: float, top: int = 8) -> str:
    """The printed summary of :func:`summarize`."""
    failed = summary["failed"]
    lines = [f"runs {summary['runs']}: B better than A in {summary['better']}, worse in "
             f"{summary['worse']} (by more than {margin:.3g} relative)"
             + (f"; failed: A in {failed[0]}, B in {failed[1]} (left out)" if any(failed)
                else ""),
             "",
             "| group | condition | scenes | A | B | B / A |",
             "|---|---|---|---|---|---|"]
    for g, c, n, ma, mb, ratio in summary["groups"]:
        lines.append(f"| {g} | {c} | {n} | {ma:.4f} | {mb:.4f} | {ratio:.3f} |")
    lines += ["", f"mean group ratio {summary['mean_ratio']:.4f}"]
    movers = [r for r in summary["movers"] if r["b"] != r["a"]]
    gains = [r for r in movers if r["b"] < r["a"]][:top]
    losses = [r for r in movers if r["b"] > r["a"]][-top:]
    for title, part in (("largest gains of B (by ratio):", gains),
                        ("largest losses of B (by ratio):", losses[::-1])):
        if part:
            lines += ["", title]
            lines += [f"  {r['group']:12s} {r['scene']:40s} {r['condition']:8s} "
                      f"{r['a']:9.4f} -> {r['b']:9.4f}" for r in part]
    return "\n".join(lines)


def _names(text):
    """The comma-separated names of `text` (stripped; None for None)."""
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def _run(ctx, spec, constants, gt, normals, error_of):
    """(error or NaN, seconds, status message) of one side's run on one scene
    (:meth:`facetlift.bench.core.Context.measure`: a metric's ValueError is a failure)."""
    with applied(constants), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        r, err = ctx.measure(spec, normals, gt.mask, lambda s: error_of(gt, s.depth),
                             pixel_size=gt.pixel_size, K=gt.K)
        secs = time.perf_counter() - t
    return (err, secs, "ok") if r.status == "ok" else (math.nan, secs,
                                                       f"{r.status}: {r.message}")


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_jump_free import add_conditions, conditions_of, context, scene_arguments

    from facetlift.bench import discontinuities as D

    ap = scene_arguments(__doc__.split("\n\n")[0])
    ap.set_defaults(groups=None)  # (every group, or ``heldout`` with --heldout-seed)
    ap.add_argument("--a", action="append", default=[], metavar="KEY=VALUE",
                    help="a setting of side A (repeatable; A is the defaults plus these)")
    ap.add_argument("--b", action="append", default=[], metavar="KEY=VALUE",
                    help="a setting of side B (repeatable; B is the defaults plus these)")
    add_conditions(ap, "exact,8bit,noise3")
    ap.add_argument("--heldout-seed", type=int, default=None,
                    help="a held-out set's scenes instead of the development benchmark's")
    ap.add_argument("--models", default=None,
                    help="comma-separated scene or mesh names to keep (e.g. spot, cow@left)")
    ap.add_argument("--quick", action="store_true",
                    help="the benchmark's --quick settings (small scenes; a smoke test)")
    ap.add_argument("--margin", type=float, default=0.01,
                    help="relative change counted as better or worse (default 0.01)")
    ap.add_argument("--csv", type=Path, default=None, help="write every run here")
    args = ap.parse_args(argv)

    from facetlift.bench.core import Settings, Spec, method_status

    try:
        sides = [split_settings(args.a), split_settings(args.b)]
        for label, (options, _) in zip("AB", sides, strict=True):
            try:
                check_options(options)
            except ValueError as e:
                raise ValueError(f"--{label.lower()}: {e}") from None
    except ValueError as e:
        ap.error(str(e))
    if not 0.0 <= args.margin < 1.0:
        ap.error(f"--margin must be at least 0 and below 1; got {args.margin}")
    conditions = conditions_of(ap, args.conditions)
    if not args.data.is_dir():
        ap.error(f"--data: no folder {args.data} (the shared data: its meshes make the scenes)")
    ctx = context(args)  # (the render cache: --cache, $FACETLIFT_BENCH_CACHE)
    ctx.settings = Settings.quick() if args.quick else Settings()
    ctx.status = method_status(["dgp"])
    if args.heldout_seed is not None:
        ctx.settings.heldout_seed = args.heldout_seed
    ctx.models = tuple(_names(args.models)) if args.models else None
    scenes = D.heldout_scenes(ctx) if args.heldout_seed is not None else D.scenes(ctx)
    groups = _names(args.groups)
    if groups:
        scenes = [t for t in scenes if t[0] in groups]
    scenes = scenes[::max(args.step, 1)]
    for name in ctx.models or ():
        if not any(t[1] == name or t[1].split("@")[0] == name for t in scenes):
            print(f"--models: {name!r} matches no scene selected", file=sys.stderr)
    if not scenes:
        print("no scene selected (see --data, --groups, --models)", file=sys.stderr)
        return 1
    try:
        fh = open(args.csv, "w", newline="") if args.csv else None
    except OSError as e:
        ap.error(f"--csv: {e}")
    specs = [Spec(label, "dgp", (("discontinuities", True),) + tuple(opts.items()))
             for label, (opts, _) in zip("AB", sides, strict=True)]
    rows, seconds, said = [], [0.0, 0.0], [False, False]
    writer = None
    try:
        if fh is not None:
            writer = csv.writer(fh)
            writer.writerow(["group", "scene", "condition", "a", "b", "a_seconds",
                             "b_seconds", "a_status", "b_status"])
        logging.disable(logging.INFO)  # (the solvers' notes; a scene that fails to load warns)
        for k, (group, name, gt) in enumerate(D.usable(ctx, scenes, "scenes")):
            for cond in conditions:
                normals = D.condition(gt, cond, f"{group}:{name}")
                out = [None, None]
                for i in ((0, 1) if k % 2 == 0 else (1, 0)):  # (warm-up on either side)
                    out[i] = _run(ctx, specs[i], sides[i][1], gt, normals, D.error_of)
                    seconds[i] += out[i][1]
                    if out[i][2] != "ok" and not said[i]:
                        said[i] = True  # (the first failure of each side, e.g. a bad constant)
                        print(f"side {'AB'[i]}: {name} {cond}: {out[i][2]}", file=sys.stderr)
                rows.append({"group": group, "scene": name, "condition": cond,
                             "a": out[0][0], "b": out[1][0]})
                if writer is not None:
                    writer.writerow([group, name, cond, out[0][0], out[1][0], out[0][1],
                                     out[1][1], out[0][2], out[1][2]])
                    fh.flush()
            print(f"{group} {name}", file=sys.stderr, flush=True)
    finally:
        logging.disable(logging.NOTSET)
        if fh is not None:
            fh.close()
    summary = summarize(rows, args.margin)
    print(report(summary, args.margin))
    print(f"\ntime: A {seconds[0]:.1f} s, B {seconds[1]:.1f} s in all")
    if summary["runs"] and summary["ties"] == summary["runs"] and (sides[0][1] or sides[1][1]):
        print("B equals A on every run: is each constant set read when the route runs (not "
              "bound as a default argument or imported by value)?", file=sys.stderr)
    return 0 if summary["runs"] else 1


if __name__ == "__main__":
    sys.exit(main())
