"""Integration methods and their registry.

Every method is a function ``run(problem, **options) -> MethodResult`` registered with its
capabilities, so that :func:`facetlift.integrate` can refuse inputs a method cannot take.
Method modules are imported lazily: importing facetlift stays cheap.
"""

from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass
class MethodResult:
    """What a method returns: depth at facet centres and/or vertices, plus diagnostics.

    ``depth`` is (m,) at facet centres and ``vertex_depth`` (n,) at the domain's vertices
    (see :class:`facetlift.domain.Domain`); a method fills at least one. Orthographic depths
    may carry any constant per component; perspective depths must be positive.
    """

    depth: np.ndarray | None = None
    vertex_depth: np.ndarray | None = None
    info: dict = field(default_factory=dict)


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

    @property
    def run(self) -> Callable:
        return importlib.import_module(f"facetlift.methods.{self.module}").run

    def options(self) -> dict:
        """Method-specific keyword options and their defaults."""
        sig = inspect.signature(self.run)
        return {
            k: p.default
            for k, p in list(sig.parameters.items())[1:]
            if p.kind is inspect.Parameter.KEYWORD_ONLY
        }


REGISTRY: dict[str, MethodInfo] = {}


def register(info: MethodInfo) -> None:
    REGISTRY[info.name] = info


def get(name: str) -> MethodInfo:
    if name not in REGISTRY:
        raise ValueError(f"`method` must be one of {sorted(REGISTRY)}; got {name!r}")
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
    )
)

# The paper's seven comparison methods (Sec. 5). Each module documents its energy and defaults.
# Pixel-graph methods whose energy stays meaningful on log-depth slopes take perspective input
# (facetlift.methods._graph.field); diffusion's contrast is in height-slope units, and
# Frankot-Chellappa and the kernel fit stay orthographic.
_LOG_DEPTH = {"poisson", "alpha_surface", "m_estimator", "regularization"}
for _name, _summary, _ref, _missing in [
    ("frankot_chellappa", "Projection onto integrable Fourier bases",
     "Frankot & Chellappa, A method for enforcing integrability in shape from shading "
     "algorithms, PAMI 1988", False),
    ("poisson", "Least squares of the gradient residual on the pixel graph (Poisson)",
     "Agrawal, Raskar & Chellappa, What is the range of surface reconstructions from a "
     "gradient field?, ECCV 2006", True),
    ("alpha_surface", "Curl-based removal of unreliable gradient edges, parameter alpha",
     "Agrawal, Chellappa & Raskar, An algebraic approach to surface reconstruction from "
     "gradient fields, ICCV 2005", True),
    ("m_estimator", "Robust iteratively reweighted least squares on gradient residuals",
     "Agrawal, Raskar & Chellappa, ECCV 2006", True),
    ("regularization", "Regularized least squares (smoothness prior), parameter lambda",
     "Agrawal, Raskar & Chellappa, ECCV 2006", True),
    ("diffusion", "Anisotropic diffusion with a tensor from the gradient field",
     "Agrawal, Raskar & Chellappa, ECCV 2006", True),
    ("kernel", "Gaussian-kernel fitting of the gradients, no integrability enforcement",
     "Ng, Wu & Tang, Surface-from-gradients without discrete integrability enforcement: a "
     "Gaussian kernel approach, PAMI 2010", True),
]:
    register(MethodInfo(name=_name, module=_name, summary=_summary, reference=_ref,
                        masks=True, missing=_missing, perspective=_name in _LOG_DEPTH))
