"""Alpha-surfaces: integrate only the gradients that the curl does not flag, kept connected.

Idea (Agrawal, Chellappa & Raskar, ICCV 2005; Agrawal, Raskar & Chellappa, ECCV 2006)
    An N-pixel grid has about 2N edge gradients for N unknowns, so not all are needed. The
    curl of the gradient field around each 2x2 loop is zero for integrable data; a loop with
    large curl contains at least one wrong gradient. Least squares over *all* edges (Poisson)
    spreads such errors over the whole surface; integrating over a subset of reliable edges
    that still connects every pixel confines them. The binary edge weights are the
    ``D = diag(w_x, w_y)``, ``w in {0, 1}`` member of the ECCV generalized equation.

What is implemented here (on the pixel graph of :mod:`facetlift.methods._graph`)
    1. Curl: ``c = (t_top + t_right - t_bottom - t_left) / h`` (slope units) around each 2x2
       block of the mask whose four edges carry data. Each data edge gets the score
       ``s_e = max |c|`` over its adjacent loops (0 when it is in none: pinch diagonals,
       one-pixel-wide strips, edges next to missing samples).
    2. Reliable edges (ICCV 2005): ``s_e <= 2 alpha``; a loop of four independent residuals of
       size ``alpha`` has a curl of standard deviation ``2 alpha``.
    3. Connect (ICCV 2005 "add a minimal set of edges so the graph is connected"): a minimum
       spanning forest of the data graph in which the components of the accepted edges are
       contracted, with edges ordered by score (then by gradient magnitude, as the ECCV code's
       MST weights). This adds the fewest, least suspicious edges that make the kept graph
       span every component of the data graph.
    4. Solve least squares over the kept edges (weight 1; rejected edges weight 0).
    5. Grow (ECCV 2006 code, ``iterative_add_gradients``): accept every data edge whose
       residual against the current surface is ``<= alpha`` (slope units), reconnect (3) and
       re-solve (4), until no edge is added, the relative height change is below `tol`, or
       `max_iter` rounds have run.

The parameter alpha (slope units)
    ``alpha = 0`` keeps a spanning tree (plus edges of exactly zero curl and residual): on
    noisy data this is integration along a minimum spanning tree. ``alpha = inf`` keeps every
    edge and is *identical* to :mod:`facetlift.methods.poisson`. In between, alpha trades
    robustness (fewer edges) for smoothness (more edges). ``alpha=None`` (default) uses the
    ECCV 2006 code's choice ``3 sigma`` with ``sigma = std(|c|) / 2`` estimated from the curl.

Differences from the papers
    The ICCV paper corrects the rejected gradients algebraically and the ECCV code integrates
    the corrected field with a Poisson solver; solving least squares on the kept edges gives
    the same surface when the kept edges are consistent, and the least-squares compromise when
    they are not. The ECCV code orders its spanning tree by gradient magnitude only; here the
    curl score comes first (the brief of the ICCV method) and magnitude breaks ties. Missing
    samples: edges without data are never kept as data; they get the tiny fill weight of
    :mod:`facetlift.methods._graph` so that regions without samples stay attached.

Options
    Declared in :data:`OPTIONS`.

References
    A. Agrawal, R. Chellappa, R. Raskar. An algebraic approach to surface reconstruction from
    gradient fields. ICCV 2005.
    A. Agrawal, R. Raskar, R. Chellappa. What is the range of surface reconstructions from a
    gradient field? ECCV 2006.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree

from .. import linalg
from .._warnings import warn
from ..errors import ConvergenceWarning
from ..operators import graph as pg
from ..options import Option
from . import MethodResult
from . import _graph as g

log = logging.getLogger(__name__)


OPTIONS = (
    Option("alpha", None, "slope tolerance of the curl test and the growing step (slope "
           "units); default 3 sigma from the curl", low=0.0, inf=True, none=True),
    *g.iteration_options(50, "growing rounds"),
    g.BACKEND,
    g.PROGRESS,
)


def edge_scores(graph: pg.PixelGraph, t: np.ndarray, has: np.ndarray, h: float):
    """Per-edge maximum |curl| (slope units) over adjacent valid loops, and the loop curls."""
    c, valid = pg.curl(graph, t, has)
    c = np.abs(c[valid]) / h
    score = np.zeros(graph.n_edges)
    np.maximum.at(score, graph.loops[valid].ravel(), np.repeat(c, 4))
    return score, c


def connectors(graph: pg.PixelGraph, accepted: np.ndarray, candidate: np.ndarray,
               order: np.ndarray) -> np.ndarray:
    """Edges of a minimum spanning forest joining the components of the `accepted` edges.

    Parameters
    ----------
    accepted, candidate : (E,) bool
        Edges already kept, and edges that may be added.
    order : (E,) float
        Positive edge costs (lower is preferred).

    Returns
    -------
    (E,) bool
        The candidate edges to add (at most ``components - 1`` per data component).
    """
    n = graph.n
    a = sp.csr_matrix(
        (np.ones(int(accepted.sum())), (graph.tail[accepted], graph.head[accepted])),
        shape=(n, n),
    )
    ncomp, lab = connected_components(a, directed=False)
    out = np.zeros(graph.n_edges, dtype=bool)
    cand = np.nonzero(candidate)[0]
    ca, cb = lab[graph.tail[cand]], lab[graph.head[cand]]
    cross = ca != cb
    cand, ca, cb = cand[cross], ca[cross], cb[cross]
    if cand.size == 0:
        return out
    lo, hi = np.minimum(ca, cb), np.maximum(ca, cb)
    key = lo.astype(np.int64) * ncomp + hi
    srt = np.lexsort((order[cand], key))  # by key, then by cost
    key, cand, lo, hi = key[srt], cand[srt], lo[srt], hi[srt]
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    key, cand, lo, hi = key[first], cand[first], lo[first], hi[first]
    cost = sp.csr_matrix((order[cand], (lo, hi)), shape=(ncomp, ncomp))
    tree = minimum_spanning_tree(cost).tocoo()
    tkey = np.minimum(tree.row, tree.col).astype(np.int64) * ncomp + np.maximum(tree.row, tree.col)
    out[cand[np.searchsorted(key, tkey)]] = True
    return out


def run(problem, *, alpha, max_iter, tol, backend, progress) -> MethodResult:
    """Integrate `problem` as an alpha-surface; values (m,) at pixel centres."""
    t0 = time.perf_counter()
    domain, graph, t, has, h = g.setup(problem)
    score, loop_curl = edge_scores(graph, t, has, h)
    if alpha is None:
        alpha = 3.0 * float(np.std(loop_curl)) / 2.0 if loop_curl.size else 0.0
    alpha = float(alpha)
    # lexicographic cost: curl score, then gradient magnitude; positive for the MST
    rank = np.empty(graph.n_edges)
    rank[np.lexsort((np.abs(t), score))] = np.arange(graph.n_edges)
    cost = 1.0 + rank

    accepted = has & (score <= 2.0 * alpha)
    kept = accepted | connectors(graph, accepted, has & ~accepted, cost)
    t1 = time.perf_counter()

    series = linalg.Series(backend, grid=domain.pixels)  # one multigrid hierarchy for every round
    conf = g.edge_confidence(problem, graph)
    prior = g.prior_terms(problem)

    def solve(kept):
        w = np.where(has, kept * conf, g.FILL_WEIGHT)
        return g.solve_weighted(domain, graph, w, t, series=series, prior=prior)

    z = solve(kept)
    rounds = 0
    converged = False
    for rounds in range(1, int(max_iter) + 1):
        res = np.abs(pg.residuals(graph, z, t)) / h
        grown = accepted | (has & (res <= alpha))
        if grown.sum() == accepted.sum():
            converged = True
            if progress is not None:
                progress(rounds, 0.0)
            break
        accepted = grown
        kept = accepted | connectors(graph, accepted, has & ~accepted, cost)
        z_new = solve(kept)
        change = g.relative_change(z_new, z)
        z = z_new
        log.debug("alpha_surface round %d: %d edges kept, change %.3g", rounds, kept.sum(), change)
        if progress is not None:
            progress(rounds, change)
        if change < tol:
            converged = True
            break
    if not converged:
        warn(f"alpha_surface: no convergence in {rounds} rounds (the kept edges still grew); "
             "raise `max_iter`", ConvergenceWarning)
    t2 = time.perf_counter()
    n_data = int(has.sum())
    info = {
        "iterations": rounds,
        "converged": converged,
        "alpha": alpha,
        "edges": n_data,
        "edges_kept": int((kept & has).sum()),
        "kept_fraction": float((kept & has).sum() / n_data) if n_data else 1.0,
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return MethodResult(values=z, info=info)
