"""What the pixel-graph methods share: set-up from a problem, and weighted least squares.

The operators themselves are in :mod:`facetlift.operators.graph`. The unknown is the camera's
(:mod:`facetlift.camera`: height, or log-depth for a pinhole camera) at the pixel centres.

Edges without data
    Edges whose two samples are both missing get a small weight :data:`FILL_WEIGHT` and target
    0: inside a region of missing samples this tends to the harmonic (membrane) fill, and it
    keeps every system non-singular.
"""

from __future__ import annotations

import numpy as np

from .. import linalg
from ..domain import Domain
from ..operators import graph as g
from ..options import Option

#: Weight of edges without a data term (both samples missing); target 0.
FILL_WEIGHT = 1e-6

#: The ``progress`` option of the pixel-graph methods that iterate or run CG.
PROGRESS = Option(
    "progress", None, "callable(iteration, value) called after every reweighting or round "
    "(value: relative change) or, for a single solve, every CG iteration (value: relative "
    "residual; a factorization reports nothing)", kind="callable", none=True,
)

#: The ``backend`` option of every pixel-graph method.
BACKEND = Option(
    "backend", "auto", "sparse solver: 'auto' picks one (facetlift.linalg.choose)",
    kind="choice", choices=("auto", "pardiso", "superlu", "amg"),
)


def edge_weights(has_data: np.ndarray, w: np.ndarray | float = 1.0) -> np.ndarray:
    """Weights ``w`` on data edges and :data:`FILL_WEIGHT` on edges without data."""
    return np.where(has_data, w, FILL_WEIGHT)


def setup(problem):
    """The common start of every pixel-graph method: ``(domain, graph, t, has, s)`` with the
    measured edge differences `t` (:func:`facetlift.operators.graph.targets`), the edges
    `has` that carry data, and the camera footprint `s` (residual / s is in slope units)."""
    graph = g.build(problem.domain)
    gx, gy = problem.grid_slopes
    t, has = g.targets(graph, gx, gy)
    return problem.domain, graph, t, has, problem.camera.footprint()


def spd_solve(K, b: np.ndarray, backend: str = "auto", *, kind: str = "graph", progress=None,
              grid=None):
    """Solve the SPD system ``K x = b`` with the solver layer's choice of backend.

    ``kind="spd"`` for systems that are not M-matrices (the prior of "regularization", the
    tensor of "diffusion"), where classical AMG converges slowly (diffusion: 12.6 s with
    Ruge-Stueben CG against SuperLU's 1.0 s at 256^2); see :func:`facetlift.linalg.choose`.
    `progress` is called after every CG iteration of a multigrid route. `grid`: the unknowns'
    grid positions (``domain.pixels``) for a factorization's ordering (:func:`facetlift.linalg.
    factorize`).
    """
    return linalg.solve(K, b, backend, kind=kind, progress=progress, grid=grid)[0]


def edge_confidence(problem, graph: g.PixelGraph) -> np.ndarray:
    """(E,) weight of each edge's data term from the normals' confidence: the mean confidence
    of the usable samples the edge's target is averaged over (1 without a confidence)."""
    if problem.confidence is None:
        return np.ones(graph.n_edges)
    c = np.where(problem.usable, problem.confidence, 0.0)
    u = problem.usable.astype(float)
    count = u[graph.tail] + u[graph.head]
    return np.where(count > 0, (c[graph.tail] + c[graph.head]) / np.maximum(count, 1), 1.0)


def prior_terms(problem):
    """``(weight, target, fixed)`` of the problem's prior at the pixels (the unknown's values,
    weight 0 without a sample) and the components it fixes; None without a prior."""
    if not problem.has_prior:
        return None
    w, t = problem.prior_terms()
    return w, t, problem.prior_components


def solve_weighted(
    domain: Domain, graph: g.PixelGraph, w: np.ndarray, t: np.ndarray, backend: str = "auto",
    *, series: linalg.Series | None = None, progress=None, prior=None,
) -> np.ndarray:
    """Unknowns (n,) minimising ``sum_e w_e (z_head - z_tail - t_e)^2`` (one pin per component),
    plus ``sum_p wp_p (z_p - tp_p)^2`` with ``prior = (wp, tp, fixed)`` (:func:`prior_terms`;
    the components it fixes are not pinned).

    `w` must be positive on a set of edges that connects each domain component. Rounds of a
    reweighting pass the same :class:`facetlift.linalg.Series` as `series` (one multigrid
    hierarchy for all rounds, warm starts); then `backend` is the series'. `progress` as in
    :func:`spd_solve` (not with `series`: the rounds report instead).
    """
    if prior is None:
        K = g.pin(domain, g.laplacian(graph, w))
        b = g.divergence(graph, w * t)
    else:
        import scipy.sparse as sp

        wp, tp, fixed = prior
        K = g.pin(domain, g.laplacian(graph, w) + sp.diags(wp, format="csr"), skip=fixed)
        b = g.divergence(graph, w * t) + wp * tp
    if series is not None:
        return series.solve(K, b)
    return spd_solve(K, b, backend, progress=progress, grid=domain.pixels)


def relative_change(z_new: np.ndarray, z: np.ndarray) -> float:
    """``||d - mean d|| / ||z_new - mean z_new||`` with ``d = z_new - z`` (0 for a flat z_new):
    the stopping measure of the iterative graph methods, blind to the free constant."""
    d = z_new - z
    spread = np.linalg.norm(z_new - z_new.mean())
    return float(np.linalg.norm(d - d.mean()) / spread) if spread > 0 else 0.0


#: ``max_iter`` and ``tol`` options of the iterative graph methods (defaults differ).
def iteration_options(max_iter: int, what: str, when=None) -> tuple[Option, Option]:
    when = {} if when is None else dict(when)
    return (
        Option("max_iter", max_iter, f"most {what}", kind="int", low=1, when=when),
        Option("tol", 1e-3, "stop when the relative change of the unknown between "
               f"{what} is below this", low=0.0, when=when),
    )
