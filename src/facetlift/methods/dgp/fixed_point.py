"""The fixed point of the paper's local/global loop, solved at once (``solver="direct"``).

In the basis mean / x-slope / y-slope / twist of a facet's corner vector, ``N p_f`` of a
known facet is ``bx e_x + by e_y``, independent of the current shape, and that of an unknown
facet is the x- and y-slope part of its current ``z_f``. The loop is therefore a
preconditioned Richardson iteration whose fixed point solves the single least-squares problem
``min_z sum_known ||N z_f - b_f||^2 + sum_unknown (e_twist . z_f)^2``: at an unknown facet
only the non-planar (+-+-) part is penalised. Where the unknown facets leave it undetermined
(a band of unknown facets across a component), a tiny ``flat_weight`` on their slopes selects
the flattest solution, which is also where the loop started from a flat mesh ends.
"""

from __future__ import annotations

import time

import numpy as np

from ... import linalg
from ...linalg.spectral import BoxPreconditioner
from ...operators.stencil import E_TWIST, E_X, E_Y, facet_form, pin_components, scatter_corners
from .common import average_deviation, empty_components, flatten

#: Facet blocks of the fixed point: slopes (known facets) and twist (every facet).
SLOPE_BLOCK = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
TWIST_BLOCK = np.outer(E_TWIST, E_TWIST)


def solve_direct(
    domain, bx, by, target, backend="auto", flat_weight=1e-9, weights=None, *, h=1.0
):
    """The fixed point of the local/global loop in one sparse solve.

    Returns vertex values (n,) and an info dict. `weights` (m,) optionally scales each
    facet's terms; `h` is the camera footprint (for the reported angular deviation).
    """
    t0 = time.perf_counter()
    empty = empty_components(domain, target)
    w = np.ones(domain.n_facets) if weights is None else weights
    wk = np.where(target, w, flat_weight * w)
    rhs = scatter_corners(domain, (w * bx)[:, None] * E_X + (w * by)[:, None] * E_Y)
    # With every normal known the operator is close to that of the bounding box, and CG
    # preconditioned by the box's exact spectral solver converges in ~25-40 iterations at any
    # resolution (exact at once on a full rectangle): the solver layer is told to trust it.
    # Facets without a target carry only the twist term plus the tiny `flat_weight`: clusters
    # of them (at silhouettes) create near-null modes that CG resolves slowly (hundreds of
    # iterations on a real normal map), so then the layer factorizes unless that is too large.
    simple = weights is None and bool(target.all())
    n = domain.n_vertices
    route = linalg.choose(n, backend, preconditioner=True, trusted=simple)
    pre = BoxPreconditioner(domain) if route == "pcg" else None
    if pre is not None and pre.exact and simple:
        t1 = time.perf_counter()
        z = pre(rhs)  # the operator is the box operator itself: one exact spectral solve
        used, cg_its = "spectral", None
    else:
        K = facet_form(domain, [(wk, SLOPE_BLOCK), (w, TWIST_BLOCK)])
        if pre is None:
            K = pin_components(domain, K)
        t1 = time.perf_counter()
        z, sinfo = linalg.solve(K, rhs, route, preconditioner=pre)
        used = "pcg-spectral" if pre is not None else sinfo.backend
        cg_its = sinfo.iterations
    z = flatten(domain, z, empty)
    t2 = time.perf_counter()
    dev = average_deviation(domain, z, bx, by, target, h)
    info = {
        "solver": "direct",
        "backend": used,
        "iterations": 1,
        "converged": True,
        "deviation": [dev],
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    if cg_its is not None:
        info["cg_iterations"] = cg_its
    return z, info
