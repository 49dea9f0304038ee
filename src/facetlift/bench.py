"""Reproduce the experiments of Xie et al. (CVPR 2014, Sec. 5): tables and figures.

:func:`run_bench` runs the registered methods (``facetlift.methods.REGISTRY``) on synthetic
ground truth (:mod:`facetlift.synthetic`) and on the normal maps of a data folder, and writes CSV
and Markdown tables and PNG figures into one output folder:

``table1``  timings of the DGP loop (factorization, local and global step) at 128, 256, 512
``fig4``    convergence with and without mean subtraction
``fig5``    a fraction of the normals perturbed by up to 20 degrees, kept as inliers or removed
``maps``    error maps of every method on a saddle, a sharp-crease surface and a face (Figs. 6-8)
``fig9``    mean normalised error of every method over >= 20 models, noise-free and 5-degree
            noise; also on the largest jump-free region of every rendered mesh (``fig9cont``)
``fig10``   angular error of every method on real normal maps without ground truth
``bear``    MADE on the perspective DiLiGenT bear for the methods that take perspective input

A method whose module is missing or that raises is recorded as ``unavailable`` / ``failed`` in
the tables; the run goes on. Every file is written atomically.
"""

from __future__ import annotations

import csv
import importlib
import io as _stdio
import logging
import os
import platform
import time
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import methods as _methods
from . import metrics, synthetic

log = logging.getLogger(__name__)

EXPERIMENTS = ("table1", "fig4", "fig5", "maps", "fig9", "fig10", "bear")

#: Table 1 of the paper (ms): factorization, local shaping per step, global blending per step.
PAPER_TABLE1 = {128: (187, 0.62, 6.21), 256: (905, 3.42, 25.2), 512: (4961, 17.5, 101.8)}
#: Fig. 5 of the paper: iterations with perturbed samples as inliers / removed as outliers.
PAPER_FIG5 = {0.15: (5, 18), 0.30: (5, 38), 0.50: (5, 143), 0.55: (5, 195)}
#: Figs. 6-8: (figure, analytic surface); two sharp-feature surfaces for Fig. 7: diagonal creases
#: (pyramid) and creases along pixel edges (ramps).
MAP_FIGURES = (("fig6", "saddle"), ("fig7", "pyramid"), ("fig7b", "ramps"), ("fig8", "face"))
#: Analytic surfaces of the Fig. 9 data set.
FIG9_ANALYTIC = ("saddle", "pyramid", "ramps", "face", "sphere", "vase", "tent")
#: Views of every mesh in the Fig. 9 data set.
FIG9_VIEWS = ("front", "oblique")
#: Real normal maps (folders of the data directory) for Fig. 10 and the perspective test.
FIG10_DATA = ("bini_human_ortho_real", "bini_supp_tent_ortho")
BEAR = "diligent_bear"
SEED = 20140623


@dataclass
class Settings:
    """Sizes and subsets of one bench run (see :func:`run_bench`)."""

    table1_sizes: tuple = (128, 256, 512)
    table1_steps: int = 50
    table1_repeats: int = 3
    fig4_size: int = 128
    fig4_max_iter: int = 5000
    fig5_size: int = 128
    fig5_fractions: tuple = (0.15, 0.30, 0.50, 0.55)
    maps_size: int = 128
    fig9_size: int = 128
    fig9_analytic: tuple = FIG9_ANALYTIC
    fig9_views: tuple = FIG9_VIEWS
    fig9_meshes: int | None = None  # None: all meshes of the data folder
    fig9_continuous: bool = True
    noise_deg: float = 5.0
    real_stride: dict = field(default_factory=dict)  # data folder name -> subsampling stride
    bear_stride: int = 1
    methods: tuple | None = None  # None: the whole registry

    @classmethod
    def quick(cls) -> Settings:
        return cls(
            table1_sizes=(32, 64),
            table1_steps=10,
            table1_repeats=1,
            fig4_size=32,
            fig4_max_iter=300,
            fig5_size=32,
            maps_size=32,
            fig9_size=32,
            fig9_analytic=("saddle", "sphere"),
            fig9_views=("front",),
            fig9_meshes=1,
            fig9_continuous=False,
            real_stride={"bini_human_ortho_real": 8, "bini_supp_tent_ortho": 2},
            bear_stride=8,
            methods=("dgp", "poisson", "frankot_chellappa"),
        )


# ----------------------------------------------------------------------------------------------
# running one method


@dataclass
class Run:
    """The outcome of one method on one input."""

    label: str
    status: str  # ok | failed | unavailable | unsupported
    surface: object = None
    message: str = ""
    seconds: float = float("nan")
    warnings: tuple = ()


@dataclass(frozen=True)
class Spec:
    """A table column: a registered method with fixed options."""

    label: str
    method: str
    options: tuple = ()


def method_status(names=None) -> dict[str, str]:
    """``{name: ""}`` for importable methods, ``{name: reason}`` for the others."""
    out = {}
    for name, info in _methods.REGISTRY.items():
        if names is not None and name not in names:
            continue
        try:
            mod = importlib.import_module(f"facetlift.methods.{info.module}")
            out[name] = "" if callable(getattr(mod, "run", None)) else "module has no run()"
        except Exception as e:  # a missing or broken module: not available
            out[name] = f"{type(e).__name__}: {e}"
    return out


def run_method(spec: Spec, normals, mask, *, pixel_size=1.0, K=None, status=None) -> Run:
    """Run one method through :func:`facetlift.integrate`, catching every failure."""
    from .api import integrate

    status = method_status([spec.method]) if status is None else status
    reason = status.get(spec.method, f"{spec.method!r} is not registered")
    if reason:
        return Run(spec.label, "unavailable", message=reason)
    info = _methods.REGISTRY[spec.method]
    missing = bool(mask.any() and (~np.isfinite(normals[mask]).all(-1)).any())
    if missing and not info.missing:
        return Run(spec.label, "unsupported", message="no missing-sample support")
    if K is not None and not info.perspective:
        return Run(spec.label, "unsupported", message="no perspective support")
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            surface = integrate(
                normals, mask, method=spec.method, pixel_size=pixel_size, K=K,
                **dict(spec.options),
            )
        except Exception as e:
            log.info("%s failed: %s", spec.label, e)
            return Run(spec.label, "failed", message=f"{type(e).__name__}: {e}"[:300],
                       seconds=time.perf_counter() - t0)
    msgs = tuple(dict.fromkeys(str(w.message)[:200] for w in caught))
    return Run(spec.label, "ok", surface, seconds=time.perf_counter() - t0, warnings=msgs)


def default_specs(methods=None, *, variants: bool = True) -> list[Spec]:
    """One column per registered method (registry defaults), plus the paper's DGP loop."""
    names = [n for n in _methods.REGISTRY if methods is None or n in methods]
    specs = [Spec(n, n) for n in names]
    if variants and "dgp" in names:
        specs.insert(1, Spec("dgp-iter", "dgp", (("solver", "iterative"),)))
        disc = _disc_spec()
        if disc is not None:
            specs.insert(2, disc)
    return specs


def _disc_spec() -> Spec | None:
    """DGP with ``discontinuities=True`` where the installed dgp module takes that option."""
    try:
        if "discontinuities" in _methods.REGISTRY["dgp"].options():
            return Spec("dgp-disc", "dgp", (("discontinuities", True),))
    except Exception as e:  # a missing or broken dgp module: no variant
        log.info("dgp options unreadable: %s", e)
    return None


# ----------------------------------------------------------------------------------------------
# output helpers


def _write_text(path: Path, text: str) -> Path:
    from .io import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def _fmt(v) -> str:
    if isinstance(v, float):
        if not np.isfinite(v):
            return ""
        return f"{v:.6g}"
    return "" if v is None else str(v)


def write_csv(path: Path, rows: list[dict]) -> Path:
    cols = list(dict.fromkeys(k for r in rows for k in r))
    buf = _stdio.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _fmt(r.get(k)) for k in cols})
    return _write_text(path, buf.getvalue())


def md_table(rows: list[dict], cols: list[str] | None = None, headers=None) -> str:
    cols = cols or list(dict.fromkeys(k for r in rows for k in r))
    headers = headers or cols
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c)).replace("|", "/") for c in cols) + " |")
    return "\n".join(lines) + "\n"


def _savefig(fig, path: Path) -> Path:
    from .io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=fig.dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _pct(x) -> float:
    return 100.0 * x if x is not None and np.isfinite(x) else float("nan")


def _bar(iterable, progress, desc, total=None):
    if not progress:
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False)


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


# ----------------------------------------------------------------------------------------------
# experiments


class Bench:
    """State of one bench run: settings, output folder, methods, collected report sections."""

    def __init__(self, out: Path, settings: Settings, data_dir: Path | None, progress: bool):
        self.out = out
        self.s = settings
        self.data = data_dir
        self.progress = progress
        self.status = method_status(settings.methods)
        self.sections: list[tuple[str, str]] = []

    def specs(self, variants=True) -> list[Spec]:
        return default_specs(self.s.methods, variants=variants)

    def add(self, title: str, text: str) -> None:
        self.sections.append((title, text))

    # -- Table 1 ------------------------------------------------------------------------------
    def table1(self):
        from .api import integrate

        rows = []
        jobs = [(n, b) for n in self.s.table1_sizes for b in ("auto", "superlu")]
        for n, backend in _bar(jobs, self.progress, "table1"):
            gt = synthetic.analytic("face", n)
            fac, loc, glo = [], [], []
            for _ in range(self.s.table1_repeats):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # tol=0: no convergence warning wanted
                    s = integrate(gt.normals, gt.mask, method="dgp", solver="iterative",
                                  max_iter=self.s.table1_steps, tol=0.0, backend=backend)
                it = s.info["iterations"]
                sec = s.info["seconds"]
                fac.append(1e3 * sec["factorization"])
                loc.append(1e3 * sec["local"] / it)
                glo.append(1e3 * sec["global"] / it)
            paper = PAPER_TABLE1.get(n, (np.nan,) * 3)
            rows.append({
                "resolution": f"{n}x{n}",
                "unknowns": int(np.isfinite(s.vertex_depth).sum()),
                "factorization_ms": float(np.median(fac)),
                "local_ms_per_step": float(np.median(loc)),
                "global_ms_per_step": float(np.median(glo)),
                "steps": it,
                "repeats": self.s.table1_repeats,
                "backend": f"{backend} -> {s.info.get('backend', '')}",
                "paper_factorization_ms": paper[0],
                "paper_local_ms": paper[1],
                "paper_global_ms": paper[2],
            })
        write_csv(self.out / "table1.csv", rows)
        text = md_table(rows)
        _write_text(self.out / "table1.md", text)
        self.add("Table 1: DGP timings in ms (face surface, full rectangle; median of repeats)",
                 text)

    # -- Fig. 4 -------------------------------------------------------------------------------
    def fig4(self):
        from .api import integrate

        gt = synthetic.analytic("face", self.s.fig4_size)
        curves, rows = {}, []
        for ms in _bar((True, False), self.progress, "fig4"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = integrate(gt.normals, gt.mask, method="dgp", solver="iterative",
                              mean_subtraction=ms, max_iter=self.s.fig4_max_iter, tol=1e-3)
            dev = list(s.info["deviation"])
            curves[ms] = dev
            err, _ = metrics.normalized_error(s.depth, gt.depth, gt.mask)
            rows.append({
                "mean_subtraction": ms, "iterations": s.info["iterations"],
                "converged": s.info["converged"], "final_deviation_deg": dev[-1],
                "error_pct": _pct(err),
            })
        long = [{"iteration": i + 1, "mean_subtraction": ms, "deviation_deg": d}
                for ms, dev in curves.items() for i, d in enumerate(dev)]
        write_csv(self.out / "fig4.csv", long)
        text = md_table(rows)
        _write_text(self.out / "fig4.md", text)
        plt = _plt()
        fig, ax = plt.subplots(figsize=(5, 3.2), dpi=100)
        for ms, dev in curves.items():
            ax.plot(np.arange(1, len(dev) + 1), dev,
                    label="with mean subtraction" if ms else "without mean subtraction")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("iteration")
        ax.set_ylabel("average angular deviation (deg)")
        ax.set_title(f"Fig. 4: convergence (face, {gt.shape[0]}x{gt.shape[1]})", fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        _savefig(fig, self.out / "fig4.png")
        self.add("Fig. 4: convergence with and without mean subtraction (face, noise-free)", text)

    # -- Fig. 5 -------------------------------------------------------------------------------
    def fig5(self):
        from .api import integrate

        gt = synthetic.analytic("face", self.s.fig5_size)
        rows, maps = [], []
        for frac in _bar(self.s.fig5_fractions, self.progress, "fig5"):
            rng = np.random.default_rng([SEED, int(round(frac * 1000))])
            noisy, chosen, angles = synthetic.perturb_fraction(gt.normals, frac, max_deg=20.0,
                                                               rng=rng)
            removed = noisy.copy()
            removed[chosen] = np.nan
            row = {"fraction": frac}
            emaps = {}
            for case, nm in (("inliers", noisy), ("outliers", removed)):
                for solver in ("iterative", "direct"):
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        s = integrate(nm, gt.mask, method="dgp", solver=solver, tol=1e-3,
                                      max_iter=5000)
                    err, emap = metrics.normalized_error(s.depth, gt.depth, gt.mask)
                    if solver == "iterative":
                        row[f"{case}_iterations"] = s.info["iterations"]
                        row[f"{case}_converged"] = s.info["converged"]
                        row[f"{case}_error_pct"] = _pct(err)
                        emaps[case] = emap
                    else:
                        row[f"{case}_direct_error_pct"] = _pct(err)
            paper = PAPER_FIG5.get(round(frac, 2), (None, None))
            row["paper_inlier_iterations"], row["paper_outlier_iterations"] = paper
            rows.append(row)
            maps.append((frac, angles, emaps))
        write_csv(self.out / "fig5.csv", rows)
        text = md_table(rows)
        _write_text(self.out / "fig5.md", text)
        plt = _plt()
        k = len(maps)
        fig, axes = plt.subplots(3, k, figsize=(2.2 * k + 0.8, 6.6), dpi=80, squeeze=False)
        vmax = max(np.nanmax(e[c]) for _, _, e in maps for c in e) * 100
        for j, (frac, angles, emaps) in enumerate(maps):
            im0 = axes[0, j].imshow(np.where(angles > 0, angles, np.nan), cmap="viridis",
                                    vmin=0, vmax=20, interpolation="nearest")
            axes[0, j].set_title(f"(a) {frac:.0%} perturbed", fontsize=8)
            for i, case in ((1, "inliers"), (2, "outliers")):
                im = axes[i, j].imshow(100 * emaps[case], cmap="jet", vmin=0, vmax=vmax)
                r = rows[j]
                axes[i, j].set_title(
                    f"({'b' if i == 1 else 'c'}) {case}: {r[f'{case}_iterations']} it, "
                    f"{r[f'{case}_error_pct']:.2f}%", fontsize=8)
        for a in axes.flat:
            a.axis("off")
        fig.colorbar(im0, ax=axes[0, :].tolist(), shrink=0.8, label="deg")
        fig.colorbar(im, ax=axes[1:, :].ravel().tolist(), shrink=0.8, label="error %")
        _savefig(fig, self.out / "fig5.png")
        self.add("Fig. 5: perturbed samples as inliers vs removed as outliers (face)", text)

    # -- Figs. 6-8 ----------------------------------------------------------------------------
    def maps(self):
        specs = self.specs(variants=False)
        rows = []
        jobs = [(f, m, c) for f, m in MAP_FIGURES for c in (0.0, self.s.noise_deg)]
        for figname, model, sigma in _bar(jobs, self.progress, "figs6-8"):
            gt = synthetic.analytic(model, self.s.maps_size)
            cond = "noise-free" if sigma == 0 else f"noise {sigma:g}deg"
            rng = np.random.default_rng([SEED, zlib.crc32(model.encode())])
            nm = gt.normals if sigma == 0 else synthetic.add_angular_noise(gt.normals, sigma, rng)
            runs = []
            for spec in specs:
                r = run_method(spec, nm, gt.mask, pixel_size=gt.pixel_size, status=self.status)
                err = emap = None
                if r.status == "ok":
                    try:
                        err, emap = metrics.normalized_error(r.surface.depth, gt.depth, gt.mask)
                    except ValueError as e:
                        r.status, r.message = "failed", f"metric: {e}"
                runs.append((r, emap))
                rows.append({"figure": figname, "model": model, "condition": cond,
                             "case": f"{model}, {cond}", "method": spec.label,
                             "status": r.status, "error_pct": _pct(err),
                             "seconds": r.seconds, "message": r.message})
            name = figname if sigma == 0 else f"{figname}_noise"
            self._map_figure(name, gt, runs, cond)
        write_csv(self.out / "figs6-8.csv", rows)
        table = self._pivot(rows, "case", "error_pct")
        _write_text(self.out / "figs6-8.md", table)
        self.add("Figs. 6-8: mean normalised error (%) on saddle, pyramid, ramps, face", table)

    def _map_figure(self, figname, gt, runs, cond=""):
        plt = _plt()
        k = len(runs) + 1
        ncol = min(k, 5)
        nrow = -(-k // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(2.0 * ncol + 0.6, 2.2 * nrow), dpi=80,
                                 squeeze=False)
        axes[0, 0].imshow(-gt.depth, cmap="gray")
        axes[0, 0].set_title(f"{gt.name} ({cond})", fontsize=8)
        finite = [e for r, e in runs if e is not None]
        vmax = max([float(np.nanpercentile(e, 99)) for e in finite] + [1e-6]) * 100
        im = None
        for a, (r, emap) in zip(axes.flat[1:], runs, strict=False):
            if emap is None:
                a.text(0.5, 0.5, r.status, ha="center", va="center", fontsize=9)
                a.set_title(r.label, fontsize=8)
                continue
            im = a.imshow(100 * emap, cmap="jet", vmin=0, vmax=vmax)
            a.set_title(f"{r.label}: {100 * np.nanmean(emap):.2f}%", fontsize=8)
        for a in axes.flat:
            a.axis("off")
        if im is not None:
            fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="error % of depth range")
        _savefig(fig, self.out / f"{figname}.png")

    def _pivot(self, rows, key, value, fmt="{:.3g}"):
        """Markdown: one row per `key`, one column per method."""
        methods = list(dict.fromkeys(r["method"] for r in rows))
        keys = list(dict.fromkeys(r[key] for r in rows))
        out = []
        for k in keys:
            line = {key: k}
            for r in rows:
                if r[key] == k:
                    v = r.get(value)
                    line[r["method"]] = (fmt.format(v) if r["status"] == "ok" and v is not None
                                         and np.isfinite(v) else r["status"])
            out.append(line)
        return md_table(out, [key] + methods)

    # -- Fig. 9 -------------------------------------------------------------------------------
    def fig9_models(self, models=None, extra_meshes=()):
        """(name, loader) pairs of the Fig. 9 data set."""
        n = self.s.fig9_size
        out = [(name, lambda name=name: synthetic.analytic(name, n))
               for name in self.s.fig9_analytic]
        meshes = []
        if self.data is not None and (self.data / "meshes").is_dir():
            meshes = sorted((self.data / "meshes").glob("*.ply"))
            if self.s.fig9_meshes is not None:
                meshes = meshes[: self.s.fig9_meshes]
        meshes += [Path(p) for p in extra_meshes]
        for path in meshes:
            for view in self.s.fig9_views:
                out.append((f"{path.stem}@{view}",
                            lambda path=path, view=view: synthetic.render_mesh(path, n, view=view)))
        if models:
            out = [(nm, f) for nm, f in out if nm in models or nm.split("@")[0] in models]
        return out

    def fig9(self, models=None, extra_meshes=()):
        specs = self.specs()
        data = self.fig9_models(models, extra_meshes)
        rows, skipped, thumbs = [], [], []
        conds = [("noise-free", 0.0), (f"noise {self.s.noise_deg:g}deg", self.s.noise_deg)]
        domains = ["full"] + (["continuous"] if self.s.fig9_continuous else [])
        total = len(data) * len(conds) * len(domains) * len(specs)
        bar = None
        if self.progress:
            from tqdm import tqdm

            bar = tqdm(total=total, desc="fig9", leave=False)
        for name, load in data:
            try:
                gt_full = load()
                if gt_full.depth_range < gt_full.pixel_size:
                    raise ValueError(f"depth range {gt_full.depth_range:.3g} is less than one "
                                     "pixel width: nothing to normalise by")
            except Exception as e:
                skipped.append({"model": name, "reason": f"{type(e).__name__}: {e}"})
                if bar is not None:
                    bar.update(len(conds) * len(domains) * len(specs))
                continue
            for domain in domains:
                gt = gt_full
                if domain == "continuous":
                    reason = None
                    if "@" in name:  # analytic surfaces are continuous already
                        gt = synthetic.continuous_region(gt_full)
                        if gt.depth_range < gt.pixel_size:
                            reason = (f"largest jump-free region is flat (depth range "
                                      f"{gt.depth_range:.3g})")
                            skipped.append({"model": name + " (continuous)", "reason": reason})
                    if "@" not in name or reason:
                        if bar is not None:
                            bar.update(len(conds) * len(specs))
                        continue
                elif domain == "full":
                    thumbs.append(gt)
                for cond, sigma in conds:
                    rng = np.random.default_rng([SEED, zlib.crc32(name.encode())])
                    nm = gt.normals if sigma == 0 else synthetic.add_angular_noise(
                        gt.normals, sigma, rng)
                    for spec in specs:
                        r = run_method(spec, nm, gt.mask, pixel_size=gt.pixel_size,
                                       status=self.status)
                        err = rm = None
                        if r.status == "ok":
                            try:
                                err, _ = metrics.normalized_error(r.surface.depth, gt.depth,
                                                                  gt.mask)
                                rm = metrics.rmse(r.surface.depth, gt.depth, gt.mask)
                            except ValueError as e:
                                r.status, r.message = "failed", f"metric: {e}"
                        rows.append({
                            "domain": domain, "condition": cond, "model": name,
                            "pixels": int(gt.mask.sum()), "method": spec.label,
                            "status": r.status, "error_pct": _pct(err),
                            "rmse_px": rm, "seconds": r.seconds,
                            "warning": "; ".join(r.warnings)[:200], "message": r.message,
                        })
                        if bar is not None:
                            bar.update(1)
        if bar is not None:
            bar.close()
        write_csv(self.out / "fig9_runs.csv", rows)
        per_model = []
        for dom in domains:
            for cond, _ in conds:
                sub = [r for r in rows if r["domain"] == dom and r["condition"] == cond]
                if sub:
                    per_model.append(f"### {dom} domains, {cond}\n\n"
                                     + self._pivot(sub, "model", "error_pct"))
        _write_text(self.out / "fig9_per_model.md", "\n".join(per_model))
        if skipped:
            write_csv(self.out / "fig9_skipped.csv", skipped)
        summary = self._fig9_summary(rows, specs)
        write_csv(self.out / "fig9.csv", summary)
        cols = ["domain", "condition", "method", "models_ok", "failed", "mean_error_pct",
                "median_error_pct", "mean_error_common_pct", "common_models", "mean_seconds"]
        text = md_table(summary, cols)
        if skipped:
            text += "\nSkipped models: " + ", ".join(
                f"{s['model']} ({s['reason']})" for s in skipped) + "\n"
        _write_text(self.out / "fig9.md", text)
        self._fig9_plot(summary, domains)
        self._thumbnails(thumbs)
        self.add(f"Fig. 9: mean normalised error over {len(data) - len(skipped)} models "
                 f"({self.s.fig9_size}x{self.s.fig9_size})", text)

    @staticmethod
    def _fig9_summary(rows, specs):
        out = []
        keys = list(dict.fromkeys((r["domain"], r["condition"]) for r in rows))
        for dom, cond in keys:
            sub = [r for r in rows if r["domain"] == dom and r["condition"] == cond]
            models = list(dict.fromkeys(r["model"] for r in sub))
            # models on which every method that could run succeeded
            ok_all = [m for m in models if all(
                r["status"] == "ok" for r in sub
                if r["model"] == m and r["status"] not in ("unavailable", "unsupported"))]
            for spec in specs:
                mine = [r for r in sub if r["method"] == spec.label]
                errs = [r["error_pct"] for r in mine if r["status"] == "ok"]
                common = [r["error_pct"] for r in mine if r["model"] in ok_all]
                secs = [r["seconds"] for r in mine if r["status"] == "ok"]
                out.append({
                    "domain": dom, "condition": cond, "method": spec.label,
                    "models_ok": len(errs),
                    "failed": sum(r["status"] != "ok" for r in mine),
                    "mean_error_pct": float(np.mean(errs)) if errs else float("nan"),
                    "median_error_pct": float(np.median(errs)) if errs else float("nan"),
                    "mean_error_common_pct": float(np.mean(common)) if common else float("nan"),
                    "common_models": len(ok_all),
                    "mean_seconds": float(np.mean(secs)) if secs else float("nan"),
                    "status": "; ".join(sorted({r["status"] for r in mine})),
                })
        return out

    def _fig9_plot(self, summary, domains):
        plt = _plt()
        fig, axes = plt.subplots(1, len(domains), figsize=(6.5 * len(domains), 3.8), dpi=80,
                                 squeeze=False)
        for ax, dom in zip(axes[0], domains, strict=False):
            sub = [r for r in summary if r["domain"] == dom]
            conds = list(dict.fromkeys(r["condition"] for r in sub))
            labels = list(dict.fromkeys(r["method"] for r in sub))
            x = np.arange(len(labels))
            w = 0.8 / max(len(conds), 1)
            allv = [r["mean_error_pct"] for r in sub if np.isfinite(r["mean_error_pct"])]
            top = min(max(allv), 3 * float(np.median(allv))) * 1.15 if allv else 1.0
            for i, c in enumerate(conds):
                vals = np.array([next((r["mean_error_pct"] for r in sub
                                       if r["method"] == m and r["condition"] == c), np.nan)
                                 for m in labels])
                xs = x + (i - (len(conds) - 1) / 2) * w
                ax.bar(xs, np.minimum(vals, top), w, label=c)
                for xi, v in zip(xs, vals, strict=True):
                    if np.isfinite(v):
                        ax.text(xi, min(v, top), f"{v:.2g}", ha="center", va="bottom",
                                fontsize=6, rotation=90)
                    else:
                        ax.text(xi, 0, "n/a", ha="center", va="bottom", fontsize=6,
                                rotation=90)
            ax.set_ylim(0, top * 1.2)
            ax.set_xticks(x)
            ax.set_xticklabels(labels, rotation=35, ha="right", fontsize=8)
            ax.set_ylabel("mean normalised error (%)")
            ax.set_title(f"Fig. 9 ({dom} rendered domains; bars clipped at the top)",
                         fontsize=9)
            ax.legend(fontsize=8)
        fig.tight_layout()
        _savefig(fig, self.out / "fig9.png")

    def _thumbnails(self, gts):
        """fig9_models.png: the normal maps of the Fig. 9 data set."""
        if not gts:
            return
        plt = _plt()
        ncol = min(len(gts), 8)
        nrow = -(-len(gts) // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(1.3 * ncol, 1.45 * nrow), dpi=72,
                                 squeeze=False)
        for a in axes.flat:
            a.axis("off")
        for a, gt in zip(axes.flat, gts, strict=False):
            a.imshow(np.where(gt.mask[..., None], np.nan_to_num(gt.normals) * 0.5 + 0.5, 1.0))
            a.set_title(gt.name, fontsize=6)
        fig.tight_layout()
        _savefig(fig, self.out / "fig9_models.png")

    # -- Fig. 10 ------------------------------------------------------------------------------
    def _read_folder(self, folder: Path, stride: int):
        from .io import read_dataset
        from .problem import clean_mask

        ds = read_dataset(folder)
        n, mask, K = ds["normals"], ds["mask"], ds["K"]
        if mask is None:
            mask = np.isfinite(n).all(-1)
        depth_gt = None
        if (folder / "depth_gt.npz").is_file():
            with np.load(folder / "depth_gt.npz") as z:
                depth_gt = np.asarray(z["depth_gt"], float)
        back = mask & ~(n[..., 2] > 0)
        nback = int(back.sum())
        if stride > 1:
            sub = (slice(None, None, stride),) * 2
            n, mask, back = n[sub], mask[sub], back[sub]
            if depth_gt is not None:
                depth_gt = depth_gt[sub]
            if K is not None:
                K = K.copy()
                K[:2] /= stride  # pixel centres at integer indices: index i -> i / stride
        mask = clean_mask(mask & ~back, min_size=2)
        n = np.where(mask[..., None], n, np.nan)
        return n, mask, K, depth_gt, nback

    def fig10(self, extra=()):
        folders = []
        if self.data is not None:
            folders += [self.data / "normal_maps" / d for d in FIG10_DATA
                        if (self.data / "normal_maps" / d).is_dir()]
        folders += [Path(p) for p in extra]
        specs = self.specs()
        rows, panels = [], []
        for folder in _bar(folders, self.progress, "fig10"):
            stride = int(self.s.real_stride.get(folder.name, 1))
            try:
                n, mask, K, _, nback = self._read_folder(folder, stride)
            except Exception as e:
                rows.append({"data": folder.name, "method": "", "status": "unreadable",
                             "message": str(e)})
                continue
            runs = []
            for spec in specs:
                r = run_method(spec, n, mask, K=K, status=self.status)
                mean = mx = None
                amap = None
                if r.status == "ok":
                    try:
                        mean, mx, amap = metrics.angular_error(r.surface, n, mask)
                    except ValueError as e:
                        r.status, r.message = "failed", f"metric: {e}"
                runs.append((r, amap))
                rows.append({"data": folder.name, "size": f"{mask.shape[0]}x{mask.shape[1]}",
                             "stride": stride, "pixels": int(mask.sum()),
                             "backfacing_removed": nback, "method": spec.label,
                             "status": r.status, "mean_deg": mean, "max_deg": mx,
                             "seconds": r.seconds, "message": r.message})
            panels.append((folder.name, runs))
        write_csv(self.out / "fig10.csv", rows)
        cols = ["data", "size", "pixels", "method", "status", "mean_deg", "max_deg", "seconds"]
        text = md_table([r for r in rows if r.get("method")], cols)
        if not folders:
            text = "No normal-map folders found (pass `extra_normal_maps` or a data folder).\n"
        _write_text(self.out / "fig10.md", text)
        for name, runs in panels:
            self._angle_figure(name, runs)
        self.add("Fig. 10: angular error (deg) of the reconstructed facets vs the input normals",
                 text)

    def _angle_figure(self, name, runs):
        plt = _plt()
        k = len(runs)
        ncol = min(k, 5)
        nrow = -(-k // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(2.0 * ncol + 0.6, 2.2 * nrow), dpi=80,
                                 squeeze=False)
        im = None
        for a, (r, amap) in zip(axes.flat, runs, strict=False):
            if amap is None:
                a.text(0.5, 0.5, r.status, ha="center", va="center", fontsize=9)
                a.set_title(r.label, fontsize=8)
                continue
            im = a.imshow(amap, cmap="jet", vmin=0, vmax=20)
            a.set_title(f"{r.label}: {np.nanmean(amap):.2f}°/{np.nanmax(amap):.0f}°", fontsize=7)
        for a in axes.flat:
            a.axis("off")
        if im is not None:
            fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="deg (clipped at 20)")
        _savefig(fig, self.out / f"fig10_{name}.png")

    # -- DiLiGenT bear --------------------------------------------------------------------------
    def bear(self):
        folder = None if self.data is None else self.data / "normal_maps" / BEAR
        if folder is None or not folder.is_dir():
            self.add("DiLiGenT bear (perspective)", "Skipped: data folder not found.\n")
            return
        n, mask, K, depth_gt, _ = self._read_folder(folder, self.s.bear_stride)
        specs = self.specs(variants=False)
        if any(sp.method == "dgp" for sp in specs) and not self.status.get("dgp"):
            disc = _disc_spec()
            if disc is not None:
                specs.append(disc)
        rows, runs = [], []
        for spec in _bar(specs, self.progress, "bear"):
            r = run_method(spec, n, mask, K=K, status=self.status)
            val = emap = None
            if r.status == "ok":
                try:
                    val, emap = metrics.made(r.surface.depth, depth_gt, mask)
                except ValueError as e:
                    r.status, r.message = "failed", f"metric: {e}"
            runs.append((r, emap))
            rows.append({"method": spec.label, "status": r.status, "made_mm": val,
                         "seconds": r.seconds, "message": r.message})
        rows.append({"method": "BiNI k=2 (reference, from SOURCES.md)", "status": "reference",
                     "made_mm": 0.334})
        write_csv(self.out / "bear.csv", rows)
        text = md_table(rows, ["method", "status", "made_mm", "seconds", "message"])
        text = (f"Resolution {mask.shape[0]}x{mask.shape[1]} (stride {self.s.bear_stride}), "
                f"{int(mask.sum())} pixels.\n\n" + text)
        _write_text(self.out / "bear.md", text)
        ok = [(r, e) for r, e in runs if e is not None]
        if ok:
            plt = _plt()
            fig, axes = plt.subplots(1, len(ok), figsize=(2.6 * len(ok) + 0.6, 2.6), dpi=80,
                                     squeeze=False)
            for a, (r, e) in zip(axes[0], ok, strict=False):
                im = a.imshow(e, cmap="jet", vmin=0, vmax=2.0)
                a.set_title(f"{r.label}: MADE {np.nanmean(e):.3f} mm", fontsize=8)
                a.axis("off")
            fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="mm (clipped at 2)")
            _savefig(fig, self.out / "bear.png")
        self.add("DiLiGenT bear (perspective): MADE (mm)", text)


def default_data_dir() -> Path | None:
    """``$FACETLIFT_DATA`` if set, else a ``shared/data`` folder beside the checkout, else None."""
    env = os.environ.get("FACETLIFT_DATA")
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for p in here.parents[2:4]:
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
    progress: bool = True,
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
    progress : bool
        Show tqdm progress bars.

    Returns
    -------
    Path
        `out_dir`; ``report.md`` there collects every table.

    Raises
    ------
    ValueError
        Unknown method or experiment names, or a missing extra file.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = Settings.quick() if quick else Settings()
    if methods is not None:
        methods = tuple(methods)
        bad = [m for m in methods if m not in _methods.REGISTRY]
        if bad:
            raise ValueError(f"`methods`: unknown {bad}; registered: {sorted(_methods.REGISTRY)}")
        s.methods = methods
    elif s.methods is not None:
        s.methods = tuple(m for m in s.methods if m in _methods.REGISTRY)
    exps = EXPERIMENTS if experiments is None else tuple(experiments)
    bad = [e for e in exps if e not in EXPERIMENTS]
    if bad:
        raise ValueError(f"`experiments`: unknown {bad}; valid: {list(EXPERIMENTS)}")
    for p in extra_meshes:
        if not Path(p).is_file():
            raise ValueError(f"`extra_meshes`: {p} is not a file")
    for p in extra_normal_maps:
        if not Path(p).is_dir():
            raise ValueError(f"`extra_normal_maps`: {p} is not a folder")
    data = Path(data_dir) if data_dir is not None else default_data_dir()
    if data is not None and not data.is_dir():
        raise ValueError(f"`data_dir`: {data} is not a folder")
    b = Bench(out, s, data, progress)
    t0 = time.perf_counter()
    failures = []
    for e in _bar(exps, progress, "bench"):
        te = time.perf_counter()
        try:
            if e == "fig9":
                b.fig9(models, extra_meshes)
            elif e == "fig10":
                b.fig10(extra_normal_maps)
            else:
                getattr(b, e)()
        except Exception as exc:  # one broken experiment must not lose the others
            log.exception("experiment %s failed", e)
            failures.append((e, f"{type(exc).__name__}: {exc}"))
        log.info("%s: %.1f s", e, time.perf_counter() - te)
    avail = [{"method": m, "available": "yes" if not why else "no", "reason": why}
             for m, why in b.status.items()]
    head = [
        "# facetlift bench report\n",
        f"Machine: {_machine()}  ",
        f"Mode: {'quick' if quick else 'full'}; experiments: {', '.join(exps)}; "
        f"total {time.perf_counter() - t0:.0f} s  ",
        f"Data: {data}\n",
        "## Methods\n",
        md_table(avail),
    ]
    if failures:
        head += ["## Failed experiments\n",
                 md_table([{"experiment": e, "error": m} for e, m in failures])]
    body = [f"## {title}\n\n{text}" for title, text in b.sections]
    _write_text(out / "report.md", "\n".join(head + body))
    return out

