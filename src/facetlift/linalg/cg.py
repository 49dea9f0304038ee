"""Preconditioned conjugate gradients returning ``(x, info)``, in the style of scipy and pyamg.

No state is kept between calls: the iteration count and the residual history come back in
:class:`CGInfo`. Inner products use ``einsum`` rather than BLAS: multi-threaded BLAS dot
products on vectors of this size cost more in thread wake-ups than they save (measured up to
8 ms each on a loaded 2-core machine), while the work is in the matrix and the preconditioner.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .dense import dot, norm  # noqa: F401  (norm: imported from here elsewhere)
from .matvec import SplitProduct, parallel


@dataclass
class CGInfo:
    """What one :func:`cg` call did.

    Attributes
    ----------
    iterations : int
        Matrix-vector products after the initial residual.
    converged : bool
        ``|r| <= rtol |b|`` was reached (or `b` is zero), confirmed on the true residual
        ``b - A x`` to within a factor 10 (CG restarts from it, at most 3 times, otherwise);
        or a residual :data:`GROWTH` times the smallest so far sent CG back to that smallest
        one's iterate, whose true residual is within that factor 10 (with `reduction`: within
        the stopping threshold itself, the larger of ``rtol |b|`` and ``reduction |r_0|``), or
        `maxiter` stopped CG far above its smallest residual, whose iterate is returned and
        within that factor 10 (not with `reduction`).
    residuals : list of float
        ``|r_k| / |b|`` before the first and after every iteration; a solve that a
        factorization finished (:func:`facetlift.linalg.facet.solve`) appends that solution's
        true residual, without counting an iteration.
    breakdown : bool
        The search direction lost positive curvature (``d^T K d <= 0``): a singular system
        whose right-hand side is not in its range, or a preconditioner that is not SPD.
    """

    iterations: int = 0
    converged: bool = False
    residuals: list = field(default_factory=list)
    breakdown: bool = False

    @property
    def relative_residual(self) -> float:
        return self.residuals[-1] if self.residuals else 0.0


_dot = dot  # (the inner products of :func:`cg`)


#: A residual this many times the smallest one so far means that CG has lost its way: the
#: iteration restarts from the iterate of that smallest residual (its true residual, a fresh
#: direction; at most :data:`RETREATS` times per call), and stops there if that residual is
#: within the factor 10 of the tolerance that a converged CG's true residual may have (with a
#: forcing term `reduction`: within the tolerance). A CG stopped by `maxiter` returns that
#: iterate where the last one is ten times worse (converged if its true residual is within
#: 10x the tolerance). Near the attainable accuracy, with a preconditioner
#: that is SPD only up to rounding (float32 transforms), the recursive residual can climb by
#: orders of magnitude after its smallest value: on the human mask at 4096^2 with 30 %
#: missing normals the box reached 1.9e-11 (rtol 1e-11), climbed to 6e-7 by its iteration
#: limit, and multigrid then took 105 iterations to come back (docs/benchmarks.md); back at
#: 1.9e-11 the depth equalled the one multigrid finished to 9e-12 of its range. CG's error in
#: the energy norm falls even where its residual rises, so the factor is large: a retreat for
#: a smaller rise (100 where the smallest was within 10x the tolerance) returned a surface 3x
#: further from the exact solution on the human mask at 512^2 (a review's measurement: 91x
#: there), and was dropped; a retreat that stops only at the tolerance itself, not within
#: 10x, never stopped there at 4096^2 (the box's attainable residual is about 1e-11) and took
#: 270 iterations.
GROWTH = 1e3
RETREATS = 3


def cg(
    A,
    b: np.ndarray,
    M: Callable[[np.ndarray], np.ndarray] | None = None,
    *,
    x0: np.ndarray | None = None,
    rtol: float = 1e-10,
    maxiter: int = 2000,
    callback: Callable[[np.ndarray], None] | None = None,
    flexible: bool = False,
    progress: Callable[[int, float], None] | None = None,
    reduction: float | None = None,
) -> tuple[np.ndarray, CGInfo]:
    """Solve ``A x = b`` for a symmetric positive (semi-)definite `A` by preconditioned CG.

    Parameters
    ----------
    A : (n, n) sparse matrix or object with ``A @ x``
    b : (n,) float
    M : callable, optional
        Preconditioner ``z = M(r)``, symmetric positive definite (identity if None).
    x0 : (n,) float, optional
        Start (zero if None); not modified.
    rtol : float
        Stop at ``|r| <= rtol |b|``.
    maxiter : int
        Most iterations; the result after them is returned with ``converged=False`` (the
        iterate of the smallest residual where the last is ten times worse, and converged if
        its true residual is within 10x the tolerance, without `reduction`: :data:`GROWTH`).
    callback : callable(x), optional
        Called after every iteration with the current iterate.
    flexible : bool
        Polak-Ribiere update ``beta = r_k . (z_k - z_{k-1}) / r_{k-1} . z_{k-1}``: robust to a
        preconditioner that is SPD only up to rounding (e.g. float32 transforms), at the cost
        of one more vector and inner product.
    progress : callable(iteration, relative residual), optional
        Called after every iteration with the iteration count and ``|r| / |b|`` (the
        progress-bar hook of the methods, ``progress=``).
    reduction : float, optional
        Also stop at ``|r| <= reduction |r_0|``, the residual of the start, if that comes
        first (a forcing term for a warm-started solve inside an outer iteration).

    Returns
    -------
    x : (n,) float
    info : CGInfo
    """
    A = parallel(A)  # (large CSR matrices: the products on two threads where a core is free)
    b = np.asarray(b, dtype=float)
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    r = b - A @ x if x0 is not None else b.copy()
    bnorm = np.sqrt(_dot(b, b))
    info = CGInfo()
    if bnorm == 0:
        info.converged = True
        info.residuals.append(0.0)
        return np.zeros_like(b), info
    rnorm = np.sqrt(_dot(r, r))
    stop = rtol * bnorm if reduction is None else max(rtol * bnorm, reduction * rnorm)
    info.residuals.append(rnorm / bnorm)
    if rnorm <= stop:
        info.converged = True
        return x, info
    z = r.copy() if M is None else M(r)
    d = z.copy()
    rz = _dot(r, z)
    restarts = retreats = 0
    # the smallest residual so far and its iteration; its iterate is saved (in one buffer)
    # when the residual first rises after it: x - alpha d then
    best, best_at, saved, buf = rnorm, 0, False, None
    # (alpha d and alpha A d formed in one reused buffer: the same numbers as the expressions,
    # without two new n-vectors per iteration, whose fresh pages cost system (page-fault) time
    # on a large map: docs/benchmarks.md, "Temporaries of the CG loop")
    step = np.empty_like(x)
    # (and A d into one buffer, where the operator is the two-thread product of a square
    # matrix; any other operator makes its own vector)
    into = A.product if isinstance(A, SplitProduct) and A.shape == (b.size, b.size) else None
    Ad = np.empty_like(x) if into is not None else None
    for it in range(1, maxiter + 1):
        Ad = A @ d if into is None else into(d, out=Ad)
        dAd = _dot(d, Ad)
        if not dAd > 0:
            info.breakdown = True
            break
        alpha = rz / dAd
        np.multiply(d, alpha, out=step)
        x += step
        np.multiply(Ad, alpha, out=step)
        r -= step
        info.iterations = it
        rnorm = np.sqrt(_dot(r, r))
        info.residuals.append(rnorm / bnorm)
        if rnorm < best:
            best, best_at, saved = rnorm, it, False
        elif best_at == it - 1 and not saved:
            buf = np.empty_like(x) if buf is None else buf
            np.multiply(d, -alpha, out=buf)
            buf += x  # (the best iterate, one step back)
            saved = True
        if saved and rnorm > GROWTH * best and retreats < RETREATS:
            # lost: back to the best iterate, from its true residual and a fresh direction
            retreats += 1
            np.copyto(x, buf)
            r = b - A @ x
            rnorm = np.sqrt(_dot(r, r))
            best, best_at, saved = rnorm, it, False
            info.residuals[-1] = rnorm / bnorm  # (the state this iteration leaves)
            if callback is not None:
                callback(x)
            if progress is not None:
                progress(it, info.residuals[-1])
            # (as a converged CG's true residual: within 10x the tolerance; with a forcing
            # term, whose 10x would take the start itself, within it)
            if rnorm <= (stop if reduction is not None else 10 * stop):
                info.converged = bool(np.all(np.isfinite(x)))
                break
            z = r.copy() if M is None else M(r)
            d = z.copy()
            rz = _dot(r, z)
            continue
        if callback is not None:
            callback(x)
        if progress is not None:
            progress(it, info.residuals[-1])
        if rnorm <= stop:
            # the recursive residual can drift from the true one (rounding in an
            # ill-conditioned system, a preconditioner SPD only up to rounding): check it once
            # and restart from the true residual if it is not small enough
            r = b - A @ x
            rnorm = np.sqrt(_dot(r, r))
            info.residuals[-1] = rnorm / bnorm
            if rnorm <= 10 * stop or restarts >= 3:
                info.converged = bool(rnorm <= 10 * stop and np.all(np.isfinite(x)))
                break
            restarts += 1
            best, best_at, saved = rnorm, it, False  # (the true residual from here)
            z = r.copy() if M is None else M(r)
            d = z.copy()
            rz = _dot(r, z)
            continue
        z_old = z if flexible else None
        z = r.copy() if M is None else M(r)
        rz_new = _dot(r, z)
        if rz == 0:  # a residual the (float32) preconditioner rounds to zero: stop here
            info.converged = bool(rnorm <= 10 * stop and np.all(np.isfinite(x)))
            info.breakdown = not info.converged
            break
        beta = (rz_new - _dot(r, z_old)) / rz if flexible else rz_new / rz
        d *= beta
        d += z
        rz = rz_new
    if not info.converged and not info.breakdown and saved and rnorm > 10 * best:
        # (stopped far above its best: that iterate, with its true residual; converged if
        # that is within 10x the tolerance, as after a retreat)
        r = b - A @ buf
        true = np.sqrt(_dot(r, r))
        if true < rnorm:
            x = buf
            info.residuals[-1] = true / bnorm
            info.converged = bool(reduction is None and true <= 10 * stop
                                  and np.all(np.isfinite(x)))
    return x, info
