"""What every experiment uses: the settings of a run, one method on one input, the context.

The experiments (:mod:`.paper`, :mod:`.maps`, :mod:`.fig9`, :mod:`.real`) import from here and
:mod:`.runner` imports them, so nothing here imports an experiment.
"""

from __future__ import annotations

import importlib
import logging
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import methods as _methods
from .. import synthetic
from .._warnings import recording

log = logging.getLogger(__name__)

#: Seed of every random perturbation (with the model name or fraction as a second word).
SEED = 20140623
#: Analytic surfaces of the Fig. 9 data set.
FIG9_ANALYTIC = ("saddle", "pyramid", "ramps", "face", "sphere", "vase", "tent")
#: Views of every mesh in the Fig. 9 data set.
FIG9_VIEWS = ("front", "oblique")


@dataclass
class Settings:
    """Sizes and subsets of one bench run (see :func:`facetlift.bench.run_bench`)."""

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
    # the discontinuity benchmark (facetlift.bench.discontinuities)
    disc_resolution: tuple = (512, 612)
    disc_views: tuple = ("front", "oblique", "left")
    disc_wide_views: tuple = ("front",)
    disc_ortho_views: tuple = ("front",)
    disc_ortho_size: int = 256
    disc_analytic: tuple = ("steps", "plateau", "occluder", "fold")
    disc_tabletop: int = 8  # scenes of several meshes on a table (0: none)
    disc_vessels: tuple = ("cup", "bowl", "goblet", "vase")  # synthetic.vessel kinds
    disc_vessel_elevations: tuple = (20.0, 35.0, 50.0)  # camera degrees above the horizontal
    disc_rooms: int = 6  # room corners with objects on the floor, seen from inside (0: none)
    disc_room_resolution: tuple = (256, 306)  # (a phone photo's field of view, 54 degrees)
    disc_conditions: tuple = ("exact", "16bit", "8bit", "noise3")
    disc_k_sweep: tuple = (2.0, 8.0)
    disc_sweep_conditions: tuple = ("exact", "8bit")
    disc_meshes: int | None = None  # None: every mesh of the data folder
    disc_samples: int = 3
    disc_real_stride: int = 1
    disc_min_pixels: int = 200
    # the held-out views (facetlift.bench.discontinuities.heldout): random views per mesh
    heldout_views: int = 3
    heldout_seed: int = 20261205
    # the fusion benchmark (facetlift.bench.fusion), on the discontinuity scenes
    fusion_groups: tuple = ("perspective", "ortho")
    fusion_fractions: tuple = (0.001, 0.01, 0.05)
    fusion_columns: tuple = ("dgp", "dgp-disc", "poisson")
    fusion_coarse_weights: tuple = (3e-4, 1e-3, 3e-3, 1e-2, 0.05)  # the dense-prior sweep
    fusion_blur_weights: tuple = (1e-3, 3e-3, 1e-2, 3e-2)  # ... and with prior_blur

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
            disc_resolution=(64, 76),
            disc_views=("front",),
            disc_wide_views=(),
            disc_ortho_size=48,
            disc_analytic=("occluder", "fold"),
            disc_tabletop=0,
            disc_vessels=(),
            disc_rooms=0,
            disc_conditions=("exact", "8bit"),
            disc_k_sweep=(),
            disc_meshes=2,
            disc_samples=1,
            disc_real_stride=8,
            disc_min_pixels=50,
            heldout_views=1,
            fusion_fractions=(0.01,),
            fusion_columns=("dgp", "dgp-disc"),
            fusion_coarse_weights=(),
            fusion_blur_weights=(),
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
    from ..api import integrate

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
    with recording() as caught:
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
        disc = disc_spec()
        if disc is not None:
            specs.insert(2, disc)
    return specs


def disc_spec() -> Spec | None:
    """DGP with ``discontinuities=True`` where the installed dgp module takes that option."""
    try:
        if "discontinuities" in _methods.REGISTRY["dgp"].options():
            return Spec("dgp-disc", "dgp", (("discontinuities", True),))
    except Exception as e:  # a missing or broken dgp module: no variant
        log.info("dgp options unreadable: %s", e)
    return None


# ----------------------------------------------------------------------------------------------
# the context of one bench run


def pct(x) -> float:
    """A fraction in percent; NaN for None or NaN."""
    return 100.0 * x if x is not None and np.isfinite(x) else float("nan")


def noisy(normals, sigma: float, name: str):
    """`normals` with `sigma` degrees of angular noise seeded by `name`; as given for 0."""
    if sigma == 0:
        return normals
    rng = np.random.default_rng([SEED, zlib.crc32(name.encode())])
    return synthetic.add_angular_noise(normals, sigma, rng)


def bar(iterable, progress: bool, desc: str, total=None):
    """`iterable`, behind a tqdm progress bar where `progress` is true."""
    if not progress:
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False)


@dataclass
class Context:
    """State of one bench run, handed to every experiment.

    `out` is the output folder, `data` the data folder (or None), `status` maps every method of
    ``settings.methods`` to ``""`` or the reason it is unavailable (:func:`method_status`);
    `models`, `extra_meshes` and `extra_normal_maps` are the subsets and additions of
    :func:`facetlift.bench.run_bench`. Experiments append ``(title, markdown)`` report sections
    to `sections` through :meth:`add`.
    """

    out: Path
    settings: Settings
    data: Path | None = None
    progress: bool = False
    status: dict[str, str] = field(default_factory=dict)
    models: tuple | None = None
    extra_meshes: tuple = ()
    extra_normal_maps: tuple = ()
    sections: list[tuple[str, str]] = field(default_factory=list)
    #: Scenes that could not be made (scene name -> why, e.g. the render extra missing): the
    #: report lists them, as the means are over the others.
    unavailable: dict[str, str] = field(default_factory=dict)

    def specs(self, variants: bool = True) -> list[Spec]:
        """The table columns of this run (see :func:`default_specs`)."""
        return default_specs(self.settings.methods, variants=variants)

    def meshes(self, limit: int | None = None) -> list[Path]:
        """The data folder's ``meshes/*.ply`` (sorted, the first `limit` of them, or all of them
        where the run names `models`, which the experiments pick by name: a quick run's limit
        cut them before the names were looked at, an audit) and then the extra meshes of this
        run."""
        found = []
        if self.data is not None and (self.data / "meshes").is_dir():
            found = sorted((self.data / "meshes").glob("*.ply"))
            if not self.models:  # (named models pick among all: the scenes filter by name)
                found = found[:limit]
        return found + [Path(p) for p in self.extra_meshes]

    def add(self, title: str, text: str) -> None:
        """Add a section to ``report.md``."""
        self.sections.append((title, text))

    def measure(self, spec: Spec, normals, mask, metric, **kwargs) -> tuple[Run, object]:
        """Run `spec` (:func:`run_method` with `kwargs`), then ``metric(surface)`` on its result.

        Returns the run and the metric's value, or None where the run or the metric failed; a
        metric that raises ValueError marks the run ``failed``.
        """
        r = run_method(spec, normals, mask, status=self.status, **kwargs)
        if r.status != "ok":
            return r, None
        try:
            return r, metric(r.surface)
        except ValueError as e:
            r.status, r.message = "failed", f"metric: {e}"
            return r, None
