"""Integration methods and their registry.

A method is a module with a function ``run(problem, **options) -> MethodResult`` and a tuple
``OPTIONS`` of :class:`facetlift.options.Option` declarations. One :func:`register` line gives
its capabilities, so that :func:`facetlift.solve` refuses inputs a method cannot take and
validates every option before the method runs. Method modules are imported lazily: importing
facetlift stays cheap. See docs/architecture.md, "Adding a method".
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..options import Option

#: Grazing threshold (view cosine) of dgp's discontinuity route on every camera, cos 87.5 deg:
#: normals more nearly edge-on are missing samples. A jump that fades out ends in a strip of
#: nearly edge-on surface whose slopes (about ``1 / cos``) would bridge it. Chosen on the
#: discontinuity benchmark as a whole (2026-12-05: 71 renders at exact, 8-bit and 3-deg-noise
#: normals, one interleaved A/B per threshold, docs/results.md "Discontinuities: the grazing
#: rule"): against the paper's cos 85 deg, cos 87.5 deg lowered the mean error in all 12
#: group-conditions (perspective exact 2.493 -> 2.388 mm, 14 scenes better / 5 worse by more
#: than 1 %; orthographic 7.202 -> 6.803 %), cos 86.5 deg less so, and cos 88.5 and 89 deg
#: raised it with noise (perspective 2.458 -> 2.619 / 2.609 mm). It costs the DiLiGenT bear
#: 0.025 -> 0.046 mm MADE (its neck's fading ends keep a few more normals).
JUMP_GRAZING = 0.0436194

#: The grazing rule above is for rims: the narrow strips where a surface turns away from the
#: camera. Where it would drop more than this share of a connected component's front-facing
#: normals, the component is a surface seen edge-on, not a rim, and its normals are kept down
#: to the pinhole default (:data:`facetlift.problem.GRAZING_FLOOR`). On the 85 renders of the
#: discontinuity benchmark the rule drops at most 0.63 % of a scene's normals (rim bands one
#: or two pixels wide); on random views of the flat ``tray_bottom`` it dropped 52 % of the
#: tray seen nearly edge-on, and the route's MADE was 11.2 and 19.9 mm where BiNI, which keeps
#: them, had 2.6 and 8.5 (docs/results.md, "Discontinuities: held-out views").
JUMP_GRAZING_SHARE = 0.1

#: Isolated normals of ``discontinuities=True``: a normal more than 15 deg from the median of
#: its eight neighbours, which agree with that median within 10 deg (all but the farthest), is
#: a missing sample, filled like one. An outlier (a photometric stereo's shadow or highlight)
#: otherwise bends the surface around it and its cuts can join or part pieces across a jump.
#: Chosen on the discontinuity benchmark (2026-12-05, one interleaved A/B on the 51 perspective
#: and orthographic renders at exact, 3-deg-noise and 2 %-outlier normals; docs/results.md
#: "Discontinuities: isolated normals"): with outliers perspective 2.677 -> 2.543 mm (19
#: better / 9 worse by more than 1 %), orthographic 6.999 -> 6.847 % (8 / 1); exact and noisy
#: normals lose one scene (mountain@left, one normal dropped, 10.69 -> 12.16 mm) and gain 8; the
#: DiLiGenT bear 0.046 -> 0.020 mm (3 normals). 10 / 6 deg was worse with outliers.
JUMP_ISOLATED = (15.0, 10.0)

#: Capabilities a method may declare (``facetlift methods`` shows them).
CAPABILITIES = ("masks", "missing", "perspective", "discontinuities", "prior", "confidence",
                "prior_blur")


@dataclass
class MethodResult:
    """What a method returns: values of the camera's unknown, plus diagnostics.

    ``values`` is (m,) at facet centres and ``vertex_values`` (n,) at the domain's vertices
    (see :class:`facetlift.domain.Domain`); a method fills at least one. The unknown is the
    problem camera's (:mod:`facetlift.camera`: height, or log-depth for a pinhole camera) and
    may carry any constant per connected component: :func:`facetlift.solve` converts it to
    depth and fixes the constants.
    """

    values: np.ndarray | None = None
    vertex_values: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    #: Arrays for the Surface beyond depth (e.g. ``corner_weights`` (m, 4) of the
    #: discontinuity-preserving route), in the problem's facet order.
    extras: dict = field(default_factory=dict)


@dataclass(frozen=True)
class MethodInfo:
    """A registered method and what it can take."""

    name: str
    module: str
    summary: str
    reference: str
    masks: bool = True
    missing: bool = False
    perspective: bool = False
    discontinuities: bool = False
    #: Takes a depth prior (``prior=``, docs/fusion.md).
    prior: bool = False
    #: Takes per-pixel weights of the normal term (``confidence=``).
    confidence: bool = False
    #: Compares a blurred prior with the result blurred alike (``prior_blur=``).
    prior_blur: bool = False
    #: Grazing threshold (view cosine) that ``discontinuities=True`` uses for every camera
    #: when the caller gives no ``outlier_eps``; None: the camera's own default.
    jump_grazing: float | None = None
    #: The most of a component's front-facing normals that rule may drop
    #: (:data:`JUMP_GRAZING_SHARE`); None: no limit.
    jump_grazing_share: float | None = None
    #: ``(deviation, agreement)`` in degrees: with ``discontinuities=True``, a normal farther
    #: than `deviation` from the median of its eight neighbours, which agree within
    #: `agreement`, is a missing sample (:func:`facetlift.problem.isolated_normals`); None: kept.
    jump_isolated: tuple | None = None
    #: Without ``discontinuities``: with a pinhole camera, lone normals more than 85 deg from
    #: their ray are missing samples (:data:`facetlift.problem.STEEP_ISOLATED`).
    steep_isolated: bool = False
    #: With ``discontinuities=True`` the surface carries its cut edges and jump map
    #: (``Surface.discontinuities``, ``--save discontinuities``) and a mesh split at them.
    jump_map: bool = False

    def _module(self):
        return importlib.import_module(f"facetlift.methods.{self.module}")

    @property
    def run(self) -> Callable:
        return self._module().run

    def specs(self) -> tuple[Option, ...]:
        """The method's option declarations (:class:`facetlift.options.Option`)."""
        return tuple(getattr(self._module(), "OPTIONS", ()))

    def options(self) -> dict:
        """Method-specific keyword options and their defaults."""
        return {o.name: o.default for o in self.specs()}

    def capabilities(self) -> dict[str, bool]:
        return {c: bool(getattr(self, c)) for c in CAPABILITIES}


REGISTRY: dict[str, MethodInfo] = {}


def register(info: MethodInfo) -> None:
    REGISTRY[info.name] = info


def get(name: str) -> MethodInfo:
    """The registered method `name`; a ValueError listing them otherwise, with the name meant
    where another case or a misspelling gives one (--method DGP got the list alone, a
    review)."""
    if name not in REGISTRY:
        hint = ""
        if isinstance(name, str):
            import difflib

            lower = {k.lower(): k for k in REGISTRY}
            meant = ([lower[name.lower()]] if name.lower() in lower else
                     [lower[m] for m in difflib.get_close_matches(name.lower(), sorted(lower),
                                                                  n=2, cutoff=0.75)])
            if meant:
                hint = "; did you mean " + " or ".join(map(repr, meant)) + "?" + (
                    " (method names are lower case)" if name.lower() in lower else "")
        raise ValueError(f"`method` must be one of {sorted(REGISTRY)}; got {name!r}{hint}")
    return REGISTRY[name]


register(
    MethodInfo(
        name="dgp",
        module="dgp",
        summary="Discrete geometry processing: local shaping + global blending of quad facets",
        reference="Xie, Zhang, Wang & Chung, Surface-from-Gradients: An Approach Based on "
        "Discrete Geometry Processing, CVPR 2014",
        masks=True,
        missing=True,
        perspective=True,
        discontinuities=True,
        prior=True,
        confidence=True,
        prior_blur=True,
        # cos 87.5 deg on both cameras: a jump that fades out ends in a line of near-edge-on
        # normals whose huge, unreliable slopes would bridge it (docs/results.md,
        # "Discontinuities: the grazing rule"; JUMP_GRAZING)
        jump_grazing=JUMP_GRAZING,
        jump_grazing_share=JUMP_GRAZING_SHARE,
        # an isolated outlier (a shadow's or a highlight's normal) bends the surface around it
        # and can join pieces across a jump (docs/results.md, "Discontinuities: isolated
        # normals"; JUMP_ISOLATED)
        jump_isolated=JUMP_ISOLATED,
        jump_map=True,
        # a wrong normal nearly edge-on inside an object bends the whole smooth surface, which
        # the pinhole camera's grazing rule (1/255) keeps (docs/perspective.md, "Lone steep
        # normals")
        steep_isolated=True,
    )
)

register(
    MethodInfo(
        name="bini",
        module="bini",
        summary="Bilateral normal integration: one-sided differences with sigmoid weights "
        "(facetlift's implementation, for comparison)",
        reference="Cao, Santo, Shi, Okura & Matsushita, Bilateral Normal Integration, ECCV 2022",
        masks=True,
        missing=True,
        perspective=True,
        discontinuities=True,
    )
)

# The paper's seven comparison methods (Sec. 5). Each module documents its energy and defaults.
# Every one takes missing samples. Pixel-graph methods whose energy stays meaningful on
# log-depth slopes take perspective input (the camera's grid slopes); diffusion's contrast is
# in height-slope units, and Frankot-Chellappa and the kernel fit stay orthographic.
_LOG_DEPTH = {"poisson", "alpha_surface", "m_estimator", "regularization"}
# A depth prior and confidences are terms of a least-squares energy on the pixel graph: the
# methods that solve one (weighted) Poisson system per round take them. Regularization and
# diffusion change the operator itself, Frankot-Chellappa and the kernel fit have no per-pixel
# terms to weight.
_FUSION = {"poisson", "alpha_surface", "m_estimator"}
for _name, _summary, _ref in [
    ("frankot_chellappa", "Projection onto integrable Fourier bases",
     "Frankot & Chellappa, A method for enforcing integrability in shape from shading "
     "algorithms, PAMI 1988"),
    ("poisson", "Least squares of the gradient residual on the pixel graph (Poisson)",
     "Agrawal, Raskar & Chellappa, What is the range of surface reconstructions from a "
     "gradient field?, ECCV 2006"),
    ("alpha_surface", "Curl-based removal of unreliable gradient edges, parameter alpha",
     "Agrawal, Chellappa & Raskar, An algebraic approach to surface reconstruction from "
     "gradient fields, ICCV 2005"),
    ("m_estimator", "Robust iteratively reweighted least squares on gradient residuals",
     "Agrawal, Raskar & Chellappa, ECCV 2006"),
    ("regularization", "Regularized least squares (smoothness prior), parameter lambda",
     "Agrawal, Raskar & Chellappa, ECCV 2006"),
    ("diffusion", "Anisotropic diffusion with a tensor from the gradient field",
     "Agrawal, Raskar & Chellappa, ECCV 2006"),
    ("kernel", "Gaussian-kernel fitting of the gradients, no integrability enforcement",
     "Ng, Wu & Tang, Surface-from-gradients without discrete integrability enforcement: a "
     "Gaussian kernel approach, PAMI 2010"),
]:
    register(MethodInfo(name=_name, module=_name, summary=_summary, reference=_ref,
                        masks=True, missing=True, perspective=_name in _LOG_DEPTH,
                        prior=_name in _FUSION, confidence=_name in _FUSION))


def markdown() -> str:
    """The capability table and every method's option table, in Markdown, from the registry
    and the option declarations (``facetlift methods --markdown``; docs/methods.md)."""
    from ..options import markdown as options_table

    head = "| method | " + " | ".join(CAPABILITIES) + " |"
    rows = [head, "|---" * (len(CAPABILITIES) + 1) + "|"]
    for name, info in REGISTRY.items():
        caps = info.capabilities()
        rows.append(f"| `{name}` | " + " | ".join("yes" if caps[c] else "no"
                                                 for c in CAPABILITIES) + " |")
    parts = ["\n".join(rows) + "\n"]
    for name, info in REGISTRY.items():
        table = options_table(info.specs())
        parts.append(f"### Options of `{name}`\n\n{info.summary}.\n\n{table}")
    return "\n".join(parts)
