"""Sparse matrix-vector products on two threads, where a core is free.

scipy's CSR product runs on one core. Its compiled kernel releases the GIL, so the rows can be
split between the calling thread and one worker: each computes its half of the result into a
slice of one output array, reading the matrix's own arrays (no copy of the matrix). Measured
on the 2-core VM, otherwise idle, on a 9-point grid matrix of 2049^2 rows (38 M non-zeros):
39-41 ms on one thread, 23-29 ms on two (`docs/benchmarks.md`, "Both cores").

The split is used only for matrices of at least :data:`MIN_ROWS` rows (below that the
thread's hand-over costs more than it saves), and only while a core is free by the same rule
as the transforms' threads (:func:`facetlift.linalg.spectral.fft_workers`: the load average
below the number of cores minus one half), read once per CG solve and per V-cycle product.
scipy's kernel is private: it is checked once against scipy's own product on a small matrix,
and where it cannot be reached or disagrees, the product is scipy's own; so it is where the
worker cannot take a job (the interpreter shutting down) or for a vector of another length
(scipy's own error).
"""

from __future__ import annotations

import os
import threading

import numpy as np
import scipy.sparse as sp

try:  # scipy's compiled CSR kernel: y += A x over a range of rows, the GIL released
    from scipy.sparse._sparsetools import csr_matvec as _kernel
except ImportError:  # pragma: no cover - a scipy that moved it: scipy's own product
    _kernel = None

#: Fewest rows for which a product is split between two threads (about 5 ms on one core).
MIN_ROWS = 500_000

_POOL = {"pid": None, "pool": None}
_POOL_LOCK = threading.Lock()


def _pool():
    """One worker thread, made anew in a forked child (a pool's threads do not survive a
    fork, and a copied pool would wait on them for ever)."""
    from concurrent.futures import ThreadPoolExecutor

    with _POOL_LOCK:
        if _POOL["pid"] != os.getpid():
            _POOL["pool"] = ThreadPoolExecutor(1, thread_name_prefix="facetlift-matvec")
            _POOL["pid"] = os.getpid()
        return _POOL["pool"]


def _after_fork_in_child() -> None:  # (a lock held by another thread at the fork stays held)
    global _POOL_LOCK
    _POOL_LOCK = threading.Lock()
    _POOL.update(pid=None, pool=None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


#: The verdict of :func:`_kernel_works` (None: not checked yet).
_CHECKED = {"ok": None}


def _kernel_works() -> bool:
    """Whether scipy's private kernel computes what scipy's product does (checked once, on
    a small matrix with int32 and int64 indices, over a range of rows)."""
    global _kernel
    if _kernel is None:
        return False
    if _CHECKED["ok"] is None:
        ok = True
        try:
            A = sp.random(7, 5, density=0.6, format="csr", random_state=0)
            x = np.arange(1.0, 6.0)
            for idx in (np.int32, np.int64):
                y = np.full(7, np.nan)
                y[2:7] = 0.0
                ip, ix = A.indptr.astype(idx), A.indices.astype(idx)
                _kernel(5, 5, ip[2:8], ix, A.data, x, y[2:7])
                ok = ok and np.allclose(y[2:], (A @ x)[2:], rtol=1e-12, atol=0.0)
        except Exception:  # (any failure: scipy's own product)
            ok = False
        _CHECKED["ok"] = ok
        if not ok:
            _kernel = None
    return _CHECKED["ok"]


class SplitProduct:
    """``A @ x`` for a CSR matrix `A` and a float64 vector `x`, the rows in two halves on two
    threads; anything else (a block of vectors, another dtype) is scipy's own product."""

    def __init__(self, A: sp.csr_matrix):
        self.A = A
        self.shape = A.shape
        self.dtype = A.dtype
        n = A.shape[0]
        # halves of equal non-zeros, not of equal rows (a mask's rows differ)
        self._cut = int(np.searchsorted(A.indptr, A.indptr[-1] // 2))
        self._cut = min(max(self._cut, 1), n - 1)

    def _rows(self, a: int, b: int, x: np.ndarray, y: np.ndarray) -> None:
        A = self.A
        y[a:b] = 0.0
        _kernel(b - a, A.shape[1], A.indptr[a:b + 1], A.indices, A.data, x, y[a:b])

    def __matmul__(self, x):
        return self.product(x)

    def product(self, x, out: np.ndarray | None = None):
        """``A @ x``, into `out` where given: a solver's loop reuses one buffer instead of a
        new vector per product. `out` must be a C-contiguous float64 vector of the rows'
        length that shares no memory with `x` (the kernel writes the rows unchecked)."""
        if out is not None and not (
                isinstance(out, np.ndarray) and out.shape == (self.shape[0],)
                and out.dtype == np.float64 and out.flags.c_contiguous
                and not np.shares_memory(out, x)):
            raise ValueError(
                f"SplitProduct.product: `out` must be a C-contiguous float64 vector of "
                f"{self.shape[0]} rows that shares no memory with `x`; got "
                f"{getattr(out, 'dtype', type(out).__name__)} of shape "
                f"{getattr(out, 'shape', None)}")
        if not (isinstance(x, np.ndarray) and x.ndim == 1 and x.dtype == np.float64
                and x.flags.c_contiguous and x.shape[0] == self.shape[1]):
            if out is None:
                return self.A @ x  # (scipy's own product, and its errors)
            out[...] = self.A @ x
            return out
        y = np.empty(self.shape[0]) if out is None else out
        n, cut = self.shape[0], self._cut
        try:
            job = _pool().submit(self._rows, cut, n, x, y)
        except RuntimeError:  # (no new jobs: the interpreter is shutting down)
            self._rows(0, n, x, y)
            return y
        try:
            self._rows(0, cut, x, y)
        finally:
            job.result()
        return y


def free_core() -> bool:
    """Whether a second core is free now (the transforms' rule)."""
    from .spectral import fft_workers

    return fft_workers() != 1


def parallel(A):
    """`A` as an operator whose products use two threads where that helps (see the module
    docstring), else `A` itself."""
    if (not sp.issparse(A) or A.format != "csr" or A.shape[0] < max(MIN_ROWS, 2)
            or A.dtype != np.float64 or A.indptr.dtype != A.indices.dtype
            or not free_core() or not _kernel_works()):
        return A
    return SplitProduct(A)
