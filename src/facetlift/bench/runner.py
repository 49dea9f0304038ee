"""The experiment registry and :func:`run_bench`, which runs experiments and writes the report."""

from __future__ import annotations

import logging
import os
import platform
import time
from pathlib import Path

from .. import methods as _methods
from . import discontinuities, fig9, fusion, maps, paper, plots, real
from .core import Context, Settings, bar, method_status
from .tables import md_table, write_text

log = logging.getLogger(__name__)

#: Experiment name -> function of the :class:`~facetlift.bench.core.Context`, in run order.
EXPERIMENT_FUNCTIONS = {
    "table1": paper.table1,
    "fig4": paper.fig4,
    "fig5": paper.fig5,
    "maps": maps.maps,
    "fig9": fig9.fig9,
    "fig10": real.fig10,
    "bear": real.bear,
    "discontinuities": discontinuities.discontinuities,
    "heldout": discontinuities.heldout,
    "fusion": fusion.fusion,
}
EXPERIMENTS = tuple(EXPERIMENT_FUNCTIONS)


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical CPUs, Python {platform.python_version()}"


def _provenance(ctx: Context) -> list[str]:
    """The report's lines on what produced it (a reviewer could not tell the code or the
    settings from report.md, an audit): facetlift's version and, from a checkout, its git
    commit (``-dirty`` with local changes), the libraries' versions, the date, the resolved
    data and cache folders, and the settings that choose what runs."""
    import datetime
    import subprocess

    import numpy
    import scipy

    from .. import __version__

    code = f"facetlift {__version__}"
    try:
        here = Path(__file__).resolve().parents[1]  # (the package: src/facetlift)
        top = subprocess.run(["git", "-C", str(here), "rev-parse", "--show-toplevel"],
                             capture_output=True, text=True, timeout=10)
        # (only facetlift's own checkout: an installed copy inside another project's
        # repository reported that project's commit, a review)
        if top.returncode == 0 and Path(top.stdout.strip()).resolve() / "src" / "facetlift" \
                == here:
            rev = subprocess.run(["git", "-C", str(here), "describe", "--always", "--dirty"],
                                 capture_output=True, text=True, timeout=10)
            if rev.returncode == 0 and rev.stdout.strip():
                code += f", git {rev.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        import pyamg

        libs = f"numpy {numpy.__version__}, scipy {scipy.__version__}, pyamg {pyamg.__version__}"
    except ImportError:  # pragma: no cover - (a core dependency)
        libs = f"numpy {numpy.__version__}, scipy {scipy.__version__}"
    s = ctx.settings
    cache = os.environ.get("FACETLIFT_BENCH_CACHE") or str(ctx.out / "cache")
    data = ctx.data.resolve() if ctx.data is not None else None
    return [f"Code: {code}; {libs}  ",
            f"Date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC  ",
            # (a run without a data folder said only "Data: None", and its tables of the
            # analytic surfaces alone looked whole, a packaging review)
            (f"Data: {data}; render cache: {Path(cache).resolve()}  " if data is not None else
             "Data: none found (--data, $FACETLIFT_DATA, or a shared/data folder beside the "
             "checkout): no mesh file and no real map was read; their scenes, tables and "
             "figures are missing  "),
            f"Settings: methods {', '.join(s.methods) if s.methods else 'all'}; models "
            f"{', '.join(ctx.models) if ctx.models else 'all'}; discontinuity conditions "
            f"{', '.join(s.disc_conditions)}; held-out seed {s.heldout_seed}\n"]


def default_data_dir() -> Path | None:
    """``$FACETLIFT_DATA`` if set, else a ``shared/data`` folder beside the checkout, else None."""
    env = os.environ.get("FACETLIFT_DATA")
    if env:
        return Path(env)
    here = Path(__file__).resolve()  # <checkout>/src/facetlift/bench/runner.py
    for p in here.parents[3:5]:  # the checkout and the folder above it
        cand = p / "shared" / "data"
        if cand.is_dir():
            return cand
        cand = p.parent / "shared" / "data"
        if cand.is_dir():
            return cand
    return None


def run_bench(
    out_dir,
    *,
    quick: bool = False,
    methods=None,
    models=None,
    experiments=None,
    extra_meshes=(),
    extra_normal_maps=(),
    data_dir=None,
    conditions=None,
    progress: bool = True,
    heldout_seed: int | None = None,
) -> Path:
    """Run the experiments and write tables and figures into `out_dir`.

    Parameters
    ----------
    out_dir : path
        Output folder (created).
    quick : bool
        Small sizes, few models and three methods: a smoke test of every experiment.
    methods : iterable of str, optional
        Registered method names to compare (default: all; with `quick`, dgp, poisson and
        frankot_chellappa).
    models : iterable of str, optional
        Subset of the Fig. 9 models: analytic names or mesh names (``stem`` or ``stem@view``).
    experiments : iterable of str, optional
        Subset of :data:`EXPERIMENTS`.
    extra_meshes : iterable of paths
        More meshes for Fig. 9 (rendered from every view).
    extra_normal_maps : iterable of paths
        More data folders (``normal_map.png`` + ``mask.png`` [+ ``K.txt``]) for Fig. 10.
    data_dir : path, optional
        Folder with ``meshes/`` and ``normal_maps/``; default :func:`default_data_dir`.
    conditions : iterable of str, optional
        Normal conditions of the discontinuities experiment, names of
        :data:`facetlift.bench.discontinuities.CONDITIONS` (default
        ``Settings.disc_conditions``; a string is split at commas); its k sweep runs on
        those of them it has.
    progress : bool
        Show tqdm progress bars.
    heldout_seed : int, optional
        Seed of the ``heldout`` experiment's random views (default
        ``Settings.heldout_seed``): a new one draws a fresh test set.

    Returns
    -------
    Path
        `out_dir`; ``report.md`` there collects every table.

    Raises
    ------
    ValueError
        Unknown method, experiment or condition names, conditions without the
        discontinuities experiment, or a missing extra file.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = _settings(quick, methods)
    if isinstance(experiments, str):
        experiments = experiments.split(",")
    # (named twice, run once: `fig4,fig4` ran it twice, an audit)
    exps = EXPERIMENTS if experiments is None else tuple(dict.fromkeys(experiments))
    if conditions is not None:
        from .discontinuities import CONDITIONS

        if isinstance(conditions, str):
            conditions = conditions.split(",")
        conditions = tuple(c.strip() for c in conditions if c.strip())
        bad = [c for c in conditions if c not in CONDITIONS]
        if bad or not conditions:
            raise ValueError(f"`conditions`: {f'unknown {bad}' if bad else 'none given'}; "
                             f"valid: {list(CONDITIONS)}")
        if not {"discontinuities", "heldout"} & set(exps):
            raise ValueError("`conditions` applies to the discontinuities and heldout "
                             "experiments only, neither of which is among the experiments "
                             f"{list(exps)}")
        s.disc_conditions = conditions
    if heldout_seed is not None:
        if "heldout" not in exps:
            raise ValueError("`heldout_seed` applies to the heldout experiment only, which is "
                             f"not among the experiments {list(exps)}")
        if int(heldout_seed) < 0:
            raise ValueError(f"`heldout_seed` must be >= 0; got {heldout_seed}")
        s.heldout_seed = int(heldout_seed)
    bad = [e for e in exps if e not in EXPERIMENTS]
    if bad:
        raise ValueError(f"`experiments`: unknown {bad}; valid: {list(EXPERIMENTS)}")
    _check_extras(extra_meshes, extra_normal_maps)
    data = Path(data_dir) if data_dir is not None else default_data_dir()
    if data is not None and not data.is_dir():
        raise ValueError(f"`data_dir`: {data} is not a folder")
    ctx = Context(out, s, data, progress, method_status(s.methods), models=models,
                  extra_meshes=tuple(extra_meshes), extra_normal_maps=tuple(extra_normal_maps))
    _check_models(ctx)
    t0 = time.perf_counter()
    failures = []
    plots.NOT_DRAWN.clear()
    mode = f"{'quick' if quick else 'full'}; experiments: {', '.join(exps)}"
    running = None
    from ..io.atomic import sigterm_raises

    # (SIGTERM raised as an exception, as Ctrl-C is: it killed the run without a report, a
    # review)
    with sigterm_raises():
        try:
            for e in bar(exps, progress, "bench"):
                running = e
                error = _run(e, ctx)
                if error:
                    failures.append((e, error))
            running = None
        finally:
            if running is not None:  # (Ctrl-C or SIGTERM: the report of what finished)
                failures.append((running, "interrupted (the experiments after it did not "
                                 "run)"))
            write_text(out / "report.md", _report(ctx, mode, failures,
                                                  time.perf_counter() - t0))
    return out


def _settings(quick: bool, methods) -> Settings:
    """The quick or full settings, limited to `methods` (checked) if given."""
    s = Settings.quick() if quick else Settings()
    if methods is not None:
        methods = tuple(methods)
        bad = [m for m in methods if m not in _methods.REGISTRY]
        if bad:
            raise ValueError(f"`methods`: unknown {bad}; registered: {sorted(_methods.REGISTRY)}")
        s.methods = methods
    elif s.methods is not None:
        s.methods = tuple(m for m in s.methods if m in _methods.REGISTRY)
    return s


def _check_extras(extra_meshes, extra_normal_maps) -> None:
    for p in extra_meshes:
        if not Path(p).is_file():
            raise ValueError(f"`extra_meshes`: {p} is not a file")
    for p in extra_normal_maps:
        if not Path(p).is_dir():
            raise ValueError(f"`extra_normal_maps`: {p} is not a folder")


def _check_models(ctx: Context) -> None:
    """Refuse `models` that name nothing this run could make (an unknown name gave empty
    tables and exit 0, an audit): a name must be one the experiments list (Fig. 9's models,
    the discontinuity and held-out scenes: ``cow@left``, ``a+b@table0``, ``cup@e35``), or
    the part of one before its ``@`` (a mesh's stem, a vessel kind)."""
    if not ctx.models:
        return
    from . import discontinuities as disc
    from . import fig9 as f9

    # (the names the experiments themselves list, their loaders lazy: a name accepted part
    # by part, cow+spot@table0, or an analytic surface no experiment renders, helix, still ran
    # nothing, a review)
    listed = [name for name, _ in f9.models(ctx)]
    listed += [name for _, name, _ in disc.scenes(ctx) + disc.heldout_scenes(ctx)]
    known = set(listed) | {n.split("@")[0] for n in listed}
    unknown = sorted(m for m in ctx.models if str(m) not in known)
    if unknown:
        raise ValueError(f"`models`: unknown {unknown}; this run knows {sorted(known)}")


def _run(name: str, ctx: Context) -> str | None:
    """Run experiment `name`; None, or the error that stopped it (logged with its traceback)."""
    t0 = time.perf_counter()
    try:
        EXPERIMENT_FUNCTIONS[name](ctx)
    except Exception as exc:  # one broken experiment must not lose the others
        log.exception("experiment %s failed", name)
        return f"{type(exc).__name__}: {exc}"
    finally:
        log.info("%s: %.1f s", name, time.perf_counter() - t0)
    return None


def _report(ctx: Context, mode: str, failures: list, seconds: float) -> str:
    """``report.md``: machine, mode and data, the methods, failed experiments, every section."""
    avail = [{"method": m, "available": "yes" if not why else "no", "reason": why}
             for m, why in ctx.status.items()]
    head = [
        "# facetlift bench report\n",
        f"Machine: {_machine()}  ",
        f"Mode: {mode}; total {seconds:.0f} s  ",
        *_provenance(ctx),
        "## Methods\n",
        md_table(avail),
    ]
    if failures:
        head += ["## Failed experiments\n",
                 md_table([{"experiment": e, "error": m} for e, m in failures])]
    if plots.NOT_DRAWN:
        head += ["## Figures not drawn\n",
                 f"matplotlib is not installed (pip install 'facetlift[plot]'): "
                 f"{', '.join(plots.NOT_DRAWN)}; the tables below and the CSV files are "
                 "complete.\n"]
    unavailable = ctx.unavailable
    if unavailable:
        head += ["## Scenes not rendered\n",
                 md_table([{"scene": k, "reason": v} for k, v in unavailable.items()])]
    body = [f"## {title}\n\n{text}" for title, text in ctx.sections]
    return "\n".join(head + body)
