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
from ...linalg.amg import hierarchy, vcycle
from ...linalg.facet import FacetPreconditioner, thin
from ...linalg.spectral import RectangleSolver
from ...operators.stencil import (
    E_TWIST,
    E_X,
    E_Y,
    facet_form,
    grid_scatter,
    pin_components,
    prior_form,
)
from .common import average_deviation, empty_components, flatten

#: Facet blocks of the fixed point: slopes (known facets) and twist (every facet).
SLOPE_BLOCK = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
TWIST_BLOCK = np.outer(E_TWIST, E_TWIST)

#: Relative residual at which CG stops. 1e-8 would give depth within about 5e-9 of its range
#: of an exact solve (measured on disks, tori and 30 % missing samples, 512^2-2048^2), but
#: planes and creases are promised to 1e-12 (tests/test_surface.py, test_dgp.py); 1e-11 costs
#: about 30 % more iterations than 1e-8.
RTOL = 1e-11

#: With a depth prior on at most this share of the facets (sparse samples), the facet-CG route
#: first tries CG preconditioned by a Ruge-Stueben hierarchy of its matrix, for at most
#: :data:`AMG_TRIAL` iterations, and hands its iterate to the facet preconditioner if that does
#: not converge. Measured on fusion benchmark scenes with 1 % samples (cow@oblique, cow@front,
#: spot@front, plateau): 15-38 CG iterations in 0.05-0.37 s where the facet preconditioner took
#: 82-146 (2-5x the prior-free count); with a dense coarse prior the facet preconditioner is as
#: fast (4-37 iterations: its spectral shift carries the prior), and on a square with a disk
#: of missing normals the hierarchy stalls (696 iterations), hence the trial.
SPARSE_PRIOR = 0.25
AMG_TRIAL = 60


def sparse_prior(weight, fixed) -> bool:
    """Whether a prior of facet weights `weight` (m,) that fixes the components `fixed`
    (n_components,) bool takes the multigrid trial (:data:`SPARSE_PRIOR`): samples on at most
    that share of the facets, and one in every component (the system is then definite)."""
    return bool(np.all(fixed)) and float(np.mean(weight > 0)) <= SPARSE_PRIOR


def _multigrid_trial(K, rhs, progress, rtol=RTOL):
    """CG on `K` preconditioned by a Ruge-Stueben V-cycle, at most :data:`AMG_TRIAL`
    iterations: ``(x, CGInfo)``, or ``(None, None)`` where the hierarchy cannot be built
    (a singular coarsest level). Isolated stiff samples: the box preconditioner does not see
    the smooth modes between them (2-5x the prior-free CG iterations); the hierarchy does."""
    try:
        pre = vcycle(hierarchy(K, symmetric_gs=True, interpolation="direct"))
        pre(np.zeros(K.shape[0]))  # (factorizes the coarsest level now, inside the guard)
    except RuntimeError:
        return None, None
    return linalg.cg(K, rhs, pre, rtol=rtol, maxiter=AMG_TRIAL, progress=progress)


def solve_direct(
    domain, bx, by, target, backend="auto", flat_weight=1e-9, weights=None, *, h=1.0,
    prior=None, progress=None, blur=None, rtol=None, offset=(0, 0),
):
    """The fixed point of the local/global loop in one sparse solve.

    Returns vertex values (n,) and an info dict. `weights` (m,) optionally scales each
    facet's terms (the normals' confidence); `h` is the camera footprint (for the reported
    angular deviation). `prior` ``(w, t, fixed)`` adds ``sum_f w_f (mean z_f - t_f)^2``
    (:func:`facetlift.operators.stencil.prior_form`); the components it fixes (``fixed``,
    (n_components,) bool) are neither pinned nor flattened. `progress` (iteration, relative
    residual) is called after every CG iteration of the facet-CG route; the spectral solve
    and the factorizations have no iterations to report. `blur`: a
    :class:`~facetlift.methods.dgp.common.BlurredPrior` of the prior (``prior_blur``): after
    the solve its target is corrected and the same system solved again (the matrix and its
    preconditioner or factorization kept, from the last solution) until it stops. `rtol`:
    the CG routes' relative residual (default :data:`RTOL`; a looser one where the solution
    only starts another solver, not with `blur`).
    """
    t0 = time.perf_counter()
    tight = RTOL if rtol is None else float(rtol)
    empty = empty_components(domain, target, offset=offset)
    fixed = None
    if prior is not None:
        pw, pt, fixed = prior
        empty = empty[~fixed[empty]]  # a prior shapes a component without normals
    w = np.ones(domain.n_facets) if weights is None else weights
    rhs = grid_scatter(domain.to_image(w * bx, fill=0.0), domain.to_image(w * by, fill=0.0))
    rhs = rhs[domain.vertex_mask]
    rhs_normals = rhs
    if prior is not None:
        KP, rP = prior_form(domain, pw, pt)
        rhs = rhs + rP
    n = domain.n_vertices
    strong = target  # components without a target come out flat (flatten below): give
    if empty.size:  # them a well-posed, trivial block
        strong = target | np.isin(domain.facet_component, empty)
    # Facet systems are preconditioned by the bounding box's exact spectral solver plus an
    # exact solve on the vertices that only facets without a target touch (the near-null
    # modes of grazing rims and gaps): CG then converges in 20-60 iterations on any mask and
    # with any share of missing normals (linalg.facet); on a full rectangle with every normal
    # known the box solver is the exact inverse (one spectral solve, no matrix). Thin domains
    # (strips a few pixels wide) are factorized: little fill, and no preconditioner of ours
    # sees their structure.
    route = linalg.choose(n, backend, kind="facet", thin=thin(domain))
    cg_its = None
    used = None
    plain = weights is None and prior is None
    if route == "pcg" and plain and bool(strong.all()) and domain.mask.all():
        t1 = time.perf_counter()
        z = RectangleSolver(*domain.shape).solve(rhs)
        used = "spectral"
    else:
        wk = np.where(strong, w, flat_weight * w)
        K = facet_form(domain, [(wk, SLOPE_BLOCK), (w, TWIST_BLOCK)])
        if prior is not None:
            K = (K + KP).tocsr()
            del KP
        z0, tried = None, 0
        resolve = factor = None  # (x0, rhs) -> (x, its): the same system again (the updates)
        if route == "pcg" and prior is not None and blur is None and sparse_prior(pw, fixed):
            t1 = time.perf_counter()
            z0, trial = _multigrid_trial(K, rhs, progress, tight)
            if trial is not None and trial.converged:
                sinfo, used = trial, "pcg-amg"
            elif trial is not None:  # the facet preconditioner goes on from its iterate
                tried = trial.iterations
                z0 = z0 if np.all(np.isfinite(z0)) else None
        if used == "pcg-amg":
            z = z0
        elif route == "pcg":
            pre = FacetPreconditioner(domain, K, strong, prior=_lumped(domain, prior))
            pre.may_factorize = backend == "auto"  # (backend="pcg": CG, as asked)
            if not tried:
                t1 = time.perf_counter()
            report = progress
            if tried and progress is not None:  # (counting on from the trial's iterations)
                def report(it, res, _p=progress, _n=tried):
                    return _p(it + _n, res)
            z, sinfo = linalg.solve(K, rhs, "pcg", preconditioner=pre, flexible=True,
                                    rtol=tight if blur is None else blur.RTOL,
                                    progress=report, x0=z0)
            # (the facet solve factorizes instead where that is predicted to be faster)
            used = "pcg-facet" if pre.direct is None else "pcg-facet+superlu"

            def resolve(x0, b):
                x, more = linalg.solve(K, b, "pcg", preconditioner=pre, rtol=blur.RTOL,
                                       flexible=True, x0=x0)
                return x, more.iterations
        else:
            K = pin_components(domain, K, skip=fixed)
            t1 = time.perf_counter()
            factor = linalg.factorize(K, route, kind="spd", grid=domain.vertices,
                                      rtol=tight if blur is None else blur.RTOL)

            def resolve(x0, b):  # (x0: a factorization needs no start)
                x = factor.solve(b)
                return x, factor.info.iterations if factor.info is not None else None

            z, its = resolve(None, rhs)
            sinfo = linalg.SolveInfo(route, its)
            used = sinfo.backend
        cg_its = sinfo.iterations
        if blur is not None:  # a blurred prior: correct its target, solve again
            last = z
            blur.accelerate = True
            while blur.update(z[domain.corners].mean(axis=1)):
                b = rhs_normals + prior_form(domain, pw, blur.target, matrix=False)
                last = z
                z, more = resolve(z, b)
                if more is not None and cg_its is not None:
                    cg_its += more
            if blur.grew:  # (the last update made it worse: the surface before it)
                z = last
        resolve = factor = None
        if tried and used.startswith("pcg-facet"):  # (the multigrid trial's iterations count too)
            cg_its += tried
        del K  # and the preconditioner: free them before the diagnostics
        pre = None
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


def _lumped(domain, prior):
    """``(mass, fixed)`` for :class:`~facetlift.linalg.facet.FacetPreconditioner`: the prior
    term's row sums per vertex (``w_f / 4`` at each corner) and the components it fixes; None
    without a prior."""
    if prior is None:
        return None
    from ...operators.stencil import scatter_corners

    pw, _, fixed = prior
    return scatter_corners(domain, np.repeat((0.25 * pw)[:, None], 4, axis=1)), fixed
