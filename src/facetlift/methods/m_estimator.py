"""M-estimator integration: iteratively reweighted least squares on the edge residuals.

Energy
    ``min_z sum_e rho(r_e / s)`` with the edge residual in slope units
    ``r_e = (z_head - z_tail - t_e) / h`` over the data edges of the pixel graph
    (:mod:`facetlift.methods._graph`), a robust loss ``rho`` and a scale ``s``. It is solved by
    IRLS: starting from the Poisson solution, each iteration solves the weighted Poisson
    problem ``sum_e w_e (z_head - z_tail - t_e)^2`` with ``w_e = psi(u_e) / u_e`` at the
    current residuals ``u_e = r_e / s``. In the generalized equation of Agrawal et al. this is
    ``D = diag(w_x, w_y)`` on both sides.

Weight functions (`weight`, with constant `k`, default the usual 95%-efficiency value)
    ``"huber"`` (default, as in the ECCV 2006 code): ``w = 1`` for ``|u| <= k``, else
    ``k / |u|``; ``k = 1.345``. Convex, so the fixed point is unique and the start does not
    matter.
    ``"fair"``: ``w = 1 / (1 + |u| / k)``; ``k = 1.3998`` (the code's second choice).
    ``"cauchy"`` (Lorentzian): ``w = 1 / (1 + (u / k)^2)``; ``k = 2.3849``. Not convex: the
    result depends on the (Poisson) start.

Scale `s`
    ``1.0`` (default, as in the ECCV 2006 code: the constant applies to raw residuals in
    slope units, so with Huber only slope errors above 1.345 -- the slope of a 53-degree
    incline -- are down-weighted), any positive number, or ``"mad"``: ``1.4826 * MAD`` of the
    data-edge residuals of the Poisson start, estimated once (floored at 1e-12 times the
    median measured slope magnitude, to stay finite on exact data). Re-estimating it every
    iteration lets the scale collapse toward zero when most gradients are exact, turning the
    estimator into a badly conditioned L1 fit; a scale from the initial fit is the usual
    remedy. Weights are divided by the largest one (which leaves the weighted least-squares
    solution unchanged) and floored at the fill weight of :mod:`facetlift.methods._graph`
    (1e-6), so that no edge leaves the graph and the system stays non-singular.

Stopping
    When ``||z_k - z_{k-1}|| / ||z_k - mean(z_k)|| < tol`` (default ``1e-3``, about the ECCV
    code's test that the mean squared relative change is below 1e-6) or after `max_iter`
    (default 50, as in the code) iterations; ``info`` records ``iterations`` and
    ``converged``. Each iteration is one sparse solve.

Masks and missing samples
    As :mod:`facetlift.methods.poisson`: natural boundary, one-sided targets on edges with one
    missing sample, the tiny fill weight (never reweighted) on edges with none.

Differences from the ECCV 2006 code
    The code starts from z = 0 (so its first weights down-weight steep correct gradients); we
    start from the Poisson solution, which for Huber reaches the same unique minimiser. The
    code stops on the relative change of heights ``mean(((z_k - z_{k-1}) / z_k)^2) < 1e-6``;
    we use the norm ratio above, which does not blow up where the height is near zero.

Options
    Declared in :data:`OPTIONS`.

Reference
    A. Agrawal, R. Raskar, R. Chellappa. What is the range of surface reconstructions from a
    gradient field? ECCV 2006.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from .. import linalg
from .._warnings import warn
from ..errors import ConvergenceWarning
from ..operators import graph as pg
from ..options import Option
from . import MethodResult
from . import _graph as g

log = logging.getLogger(__name__)

WEIGHTS = {"huber": 1.345, "fair": 1.3998, "cauchy": 2.3849}

OPTIONS = (
    Option("weight", "huber", "robust weight function", kind="choice", choices=tuple(WEIGHTS)),
    Option("k", None, "the weight function's constant (default: its 95%-efficiency value)",
           low=0.0, low_open=True, none=True),
    Option("scale", 1.0, "residual scale in slope units, or 'mad' (from the Poisson start)",
           low=0.0, low_open=True, choices=("mad",)),
    *g.iteration_options(50, "reweightings"),
    g.BACKEND,
    g.PROGRESS,
)


def weights(u: np.ndarray, weight: str, k: float) -> np.ndarray:
    """IRLS weights ``psi(u) / u`` of the named function at scaled residuals `u`."""
    a = np.minimum(np.abs(u) / k, 1e150)  # no overflow in the square
    if weight == "huber":
        return np.where(a <= 1.0, 1.0, 1.0 / np.maximum(a, 1e-300))
    if weight == "fair":
        return 1.0 / (1.0 + a)
    return 1.0 / (1.0 + a**2)


def run(problem, *, weight, k, scale, max_iter, tol, backend, progress) -> MethodResult:
    """Integrate `problem` with a robust M-estimator (IRLS); values (m,) at pixel centres."""
    k = WEIGHTS[weight] if k is None else k

    t0 = time.perf_counter()
    domain, graph, t, has, h = g.setup(problem)
    floor = 1e-12 * max(float(np.median(np.abs(t[has]))) / h if has.any() else 0.0, 1.0)
    # one multigrid hierarchy for every reweighting
    series = linalg.Series(backend, grid=domain.pixels)
    conf = g.edge_confidence(problem, graph)
    prior = g.prior_terms(problem)
    z = g.solve_weighted(domain, graph, g.edge_weights(has, conf), t, series=series, prior=prior)
    changes = []
    converged = False
    if scale == "mad":  # once, from the residuals of the Poisson start
        r = pg.residuals(graph, z, t)[has] / h
        s = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), floor) if r.size else 1.0
    else:
        s = float(scale)
    for it in range(1, int(max_iter) + 1):
        r = pg.residuals(graph, z, t)[has] / h
        w = np.full(graph.n_edges, g.FILL_WEIGHT)
        wd = weights(r / s, weight, k)
        w[has] = np.maximum(wd / wd.max(), g.FILL_WEIGHT) if wd.size else wd
        robust = w[has] < 1.0  # (the edges the M-estimator turned down: not the confidence's)
        w[has] *= conf[has]
        z_new = g.solve_weighted(domain, graph, w, t, series=series, prior=prior)
        change = g.relative_change(z_new, z)
        changes.append(change)
        z = z_new
        log.debug("m_estimator iteration %d: relative change %.3g", it, change)
        if progress is not None:
            progress(it, change)
        if change < tol:
            converged = True
            break
    if not converged:
        warn(
            f"m_estimator: no convergence in {max_iter} iterations (last relative change "
            f"{changes[-1]:.3g} >= tol={tol}); raise `max_iter`", ConvergenceWarning
        )
    t1 = time.perf_counter()
    info = {
        "iterations": it,
        "converged": converged,
        "weight": weight,
        "k": float(k),
        "scale": float(s),
        "changes": changes,
        "downweighted": int(robust.sum()),
        "seconds": {"solve": t1 - t0},
    }
    return MethodResult(values=z, info=info)
