"""Exact fast solves of the mean-subtracted facet operator on a full rectangle.

On a rectangle of ``H x W`` facets whose facets all carry the block ``N = I - 11^T/4``, the
operator ``K = sum_f C_f^T N C_f`` on the ``(H+1) x (W+1)`` vertex grid separates:

    K = D_r (x) D_c - 1/4 T_r (x) T_c,

where, per axis with ``m`` facets, ``T = S^T S`` (``S`` the m x (m+1) two-point sum) and
``D = diag(T) = diag(1, 2, ..., 2, 1)``. ``D^{-1} T = I + D^{-1} A`` (``A`` the path adjacency)
is diagonalised by the DCT-I basis ``v_k(j) = cos(pi k j / m)`` with eigenvalues
``1 + cos(pi k / m)``. Hence ``K x = b`` is solved by two 2-D DCT-I transforms:
``x = V diag(1 / (1 - lambda_r lambda_c / 4)) V^{-1} (D_r (x) D_c)^{-1} b``, the constant mode
(``lambda_r = lambda_c = 2``) dropped. This is the global step of the paper's loop for every
rectangular input, and the whole direct solve when every normal is known: O(n log n) instead of a
sparse factorization.
"""

from __future__ import annotations

import threading

import numpy as np
import scipy.fft as sfft


def fft_workers() -> int:
    """Threads for the transforms: every core, unless the machine is busy (load average
    at least the number of cores minus one half), where a second thread only waits for a
    core: measured at 2048^2 under a load of 2.5 on 2 cores, 2 threads 4.05 s against 1
    thread 3.84 s for a disk, 3.77 against 3.67 s for the torus."""
    import os

    from .._threads import cores

    n = cores()
    try:
        busy = os.getloadavg()[0] >= n - 0.5
    except OSError:  # pragma: no cover - no load average on this platform
        busy = False
    return 1 if busy or n == 1 else -1


class RectangleSolver:
    """Pseudo-inverse of the mean-subtracted facet operator on an H x W facet rectangle.

    ``solve(b)`` takes (n,) with n = (H+1)(W+1) in row-major vertex order and returns the
    solution with zero D-weighted mean (the constant is free).
    """

    backend = "spectral"

    def __init__(self, H: int, W: int, workers: int | None = None, dtype=np.float64,
                 shift: float = 0.0):
        self.H, self.W = H, W
        self.workers = workers if workers is not None else fft_workers()
        self.dtype = np.dtype(dtype)
        lr = 1.0 + np.cos(np.pi * np.arange(H + 1) / H)
        lc = 1.0 + np.cos(np.pi * np.arange(W + 1) / W)
        # the operator is D V diag(denom) V^-1 (D: facets per vertex); `shift` c adds c D,
        # which moves every eigenvalue by c (a uniform lumped prior mass, docs/fusion.md)
        denom = 1.0 - 0.25 * np.outer(lr, lc) + shift
        if shift <= 0:
            denom[0, 0] = np.inf  # the constant mode
        self._gain = 1.0 / denom
        dr = np.full(H + 1, 2.0)
        dr[[0, -1]] = 1.0
        dc = np.full(W + 1, 2.0)
        dc[[0, -1]] = 1.0
        self._inv_d = 1.0 / np.outer(dr, dc)
        # dct1(dct1(x)) = 2m x along an axis of m+1 points; V^{-1} y = D V D y / (2m) with
        # dct1(y) = V D y, and V c = dct1(D^{-1} c): the D factors between the two transforms
        # cancel, leaving one scaled gain
        self._gain /= 4.0 * H * W
        self._gain = self._gain.astype(self.dtype)
        self._inv_d = self._inv_d.astype(self.dtype)

    def solve(self, b: np.ndarray, overwrite: bool = False) -> np.ndarray:
        """(n,) solution in the solver's dtype (float32 transforms are twice as fast). With
        `overwrite`, a C-contiguous `b` of the solver's dtype is the workspace: the solution
        is formed in its memory and shares it (the same numbers, no new arrays); a `b` of
        another dtype or layout, and any `b` without `overwrite`, is left untouched."""
        H, W = self.H, self.W
        b = np.asarray(b)
        if overwrite and b.dtype == self.dtype and b.flags.c_contiguous:
            y = b.reshape(H + 1, W + 1)
            y *= self._inv_d
        else:
            y = b.reshape(H + 1, W + 1) * self._inv_d
        c = sfft.dctn(y, type=1, workers=self.workers, overwrite_x=True)
        c *= self._gain
        return sfft.dctn(c, type=1, workers=self.workers, overwrite_x=True).ravel()


class BoxPreconditioner:
    """Preconditioner for facet operators on any mask: the exact rectangle pseudo-inverse on
    the domain's bounding box, restricted to the domain's vertices.

    Extending a residual by zeros to the box, solving there with :class:`RectangleSolver` and
    restricting back is a fictitious-domain preconditioner. For the mean-subtracted operator
    of the DGP method, conjugate gradients with it converge in a number of iterations that
    does not grow with the resolution (about 25 to a relative residual of 1e-12 on masks with
    holes, from 128^2 to 1024^2; more with many missing normals), and in one iteration when
    the domain is the full box and every normal is known.
    """

    def __init__(self, domain, workers: int | None = None, dtype=np.float64,
                 shift: float = 0.0):
        self.domain = domain
        vm = domain.vertex_mask
        rows = np.nonzero(vm.any(axis=1))[0]
        cols = np.nonzero(vm.any(axis=0))[0]
        box = vm[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
        self.exact = bool(box.all() and domain.mask.all())
        if not self.exact:
            # any larger box is as good a fictitious domain; pick one whose DCT-I length
            # (2 x facets) has small prime factors: 461 facets (prime) cost 4x more than 462
            hb = sfft.next_fast_len(box.shape[0] - 1, real=True)
            wb = sfft.next_fast_len(box.shape[1] - 1, real=True)
            box = np.pad(box, ((0, hb + 1 - box.shape[0]), (0, wb + 1 - box.shape[1])))
        self._inside = box.ravel()
        # (the domain fills its box, e.g. a rectangle with missing normals: no scatter into a
        # zeroed box and no gather back, the same numbers)
        self._fills = bool(self._inside.all())
        self._work = threading.local()
        if shift > 0:
            self.exact = False
        self._solver = RectangleSolver(box.shape[0] - 1, box.shape[1] - 1, workers, dtype,
                                       shift)
        self._size = box.size

    def __call__(self, r: np.ndarray) -> np.ndarray:
        # the box's vector is a workspace kept per thread: a large map's CG would otherwise
        # take one or two new box-sized arrays per iteration, whose fresh pages cost system
        # (page-fault) time (docs/benchmarks.md, "Temporaries of the CG loop"). The result is
        # always a new array (astype copies, the gather copies): the caller keeps it (CG's
        # flexible update holds the last one) while the next call reuses the workspace
        full = getattr(self._work, "box", None)
        if full is None:
            full = self._work.box = np.empty(self._size, dtype=self._solver.dtype)
        if self._fills:
            np.copyto(full, r, casting="same_kind")
            return self._solver.solve(full, overwrite=True).astype(float)
        full.fill(0)
        full[self._inside] = r
        return self._solver.solve(full, overwrite=True)[self._inside].astype(float, copy=False)
