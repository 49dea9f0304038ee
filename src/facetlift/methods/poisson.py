"""Poisson integration: least squares of the gradient residual on the pixel graph.

Energy
    ``min_z sum_e (z_head - z_tail - t_e)^2`` over the 4-neighbour edges of the mask (plus the
    pinch diagonals, see :mod:`facetlift.methods._graph`), where ``t_e = h (dx p + dy q)`` is
    the edge's measured height difference averaged over its two samples. The normal equations
    are the discrete Poisson equation ``L z = div t`` with natural (Neumann) boundary
    conditions: an edge exists only when both pixels are in the mask, so any mask shape works.
    Unknowns are heights at pixel centres; the result is ``depth = -height``.

Missing samples
    An edge with one known sample uses that sample; an edge with none has no data term and
    gets the tiny fill weight of :data:`facetlift.methods._graph.FILL_WEIGHT` toward a zero
    difference (a membrane fill of regions without samples).

Depth prior and confidence (docs/fusion.md)
    ``prior`` adds ``sum_p w_p (z_p - z_prior_p)^2`` at the pixels with a sample (a component
    with a sample is not pinned: the prior fixes its constant); ``confidence`` scales each
    edge's data term by the mean confidence of the samples its target comes from.

Options
    Declared in :data:`OPTIONS`: ``backend`` (see :mod:`facetlift.linalg`).

Reference
    A. Agrawal, R. Raskar, R. Chellappa. What is the range of surface reconstructions from a
    gradient field? ECCV 2006 (the Poisson solver, ``D = I`` in its generalized equation).
"""

from __future__ import annotations

import time

from ..problem import Problem
from . import MethodResult
from . import _graph as g

OPTIONS = (g.BACKEND, g.PROGRESS)


def run(problem: Problem, *, backend: str, progress) -> MethodResult:
    """Integrate `problem` by least squares on the pixel graph; values (m,) at pixel centres."""
    t0 = time.perf_counter()
    _, graph, t, has, _ = g.setup(problem)
    t1 = time.perf_counter()
    w = g.edge_weights(has, g.edge_confidence(problem, graph))
    z = g.solve_weighted(problem.domain, graph, w, t, backend, prior=g.prior_terms(problem),
                         progress=progress)
    t2 = time.perf_counter()
    info = {
        "iterations": 1,
        "converged": True,
        "edges": graph.n_edges,
        "edges_without_data": int((~has).sum()),
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return MethodResult(values=z, info=info)
