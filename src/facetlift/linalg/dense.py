"""Dense products over many rows, on the calling thread.

numpy hands ``a @ b`` and ``numpy.dot`` to BLAS, which splits a long product across its
threads (OpenBLAS: a dot product of more than 10,000 numbers, a matrix-vector product of more
than about 9,000 entries). On a machine whose other cores are busy, each such call waits for
a time slice: on the 2-core VM with both cores loaded, the discontinuity route's energy trace
(two dot products of 4 x 65k numbers per reweighting) took 0.5-1.5 s of a 3-7 s run on the
DiLiGenT-size bunny, and about 0.03 s with BLAS on one thread. A process-wide BLAS limit is
not an option in a library (:mod:`facetlift._threads`), so the hot products of the facet
routes go through here: dot products by ``einsum`` (no BLAS), products of an (m, k) array
with a small (k,) or (k, j) one in row blocks that BLAS runs on one thread
(:data:`ROW_BLOCK`), as fast as one BLAS thread on the whole and never waiting for another.
"""

from __future__ import annotations

import math

import numpy as np

#: Rows per BLAS call of :func:`rowwise`: 2048 rows of 4 numbers stay below OpenBLAS's
#: threshold for threading a matrix-vector product (2304 x 4 entries) and a matrix product
#: (65536 x 4 multiply-adds).
ROW_BLOCK = 2048


def dot(u, v) -> float:
    """``u . v`` of two 1-D arrays, on the calling thread."""
    return float(np.einsum("i,i->", u, v))


def norm(v) -> float:
    """The 2-norm of a vector, on the calling thread. ``numpy.linalg.norm`` goes to BLAS,
    which splits a long dot product across its threads: on the 2-core VM with the other
    core busy each such call waited for a time slice (6 ms for 66k numbers in a profile of
    the discontinuity route with a depth prior, 0.6 s of its 4.1 s; three per reweighting),
    where this takes 0.04 ms loaded or idle."""
    return math.sqrt(max(dot(v, v), 0.0))


def rowwise(a, b, out=None):
    """``a @ b`` for an (m, k) array `a` and a small (k,) or (k, j) array `b`, in blocks of
    :data:`ROW_BLOCK` rows (each one BLAS call on the calling thread); into `out` where
    given."""
    a = np.asarray(a)
    b = np.asarray(b)
    m = a.shape[0]
    if out is None:
        out = np.empty((m,) + b.shape[1:], dtype=np.result_type(a, b))
    for s0 in range(0, m, ROW_BLOCK):
        s1 = min(s0 + ROW_BLOCK, m)
        np.matmul(a[s0:s1], b, out=out[s0:s1])
    return out
