"""One BLAS thread while a method's own worker threads run (``kernel``'s tiles), shared by
overlapping calls.

The limit (threadpoolctl) is process-wide: two calls that each set it and put back what they
found, overlapping in threads, put it back in the wrong order and left the whole process on
one BLAS thread for good (a library user's check: then ``[1, 1]`` threads where there were
2). Here the first call to enter sets it and the last to leave puts back the process's own
setting. While any such call runs, every thread of the process has one BLAS thread: the limit
cannot be per thread. (OpenBLAS 0.3.31 with pthreads ignores a thread's setting while the
thread that set the limit is still running inside the library's limit: overlapping calls
from two threads whose first to enter leaves first can still leave one thread; the
discontinuity route, which a user may well call from threads, sets no limit.)
"""

from __future__ import annotations

import contextlib
import os
import threading

#: Cores this process may use for its own threads (the transforms' and the split sparse
#: products' second thread, ``kernel``'s tiles), or None: the machine's. A local batch's
#: worker processes set 1 (:func:`facetlift.batch._worker_start`): one process per core, where
#: each also started a thread per core for its transforms and ``kernel`` up to 8 (a review).
CORES: int | None = None


def cores() -> int:
    """:data:`CORES`, else the machine's CPU count."""
    return CORES if CORES is not None else (os.cpu_count() or 1)


_LOCK = threading.Lock()
_STATE = {"depth": 0, "limiter": None, "limit": None}
#: This thread's own depth in :func:`blas_limit` (the child of a fork keeps only the forking
#: thread's).
_MINE = threading.local()


def _after_fork_in_child() -> None:
    """A child forked while other threads were inside :func:`blas_limit` has none of them:
    its depth is the forking thread's own, and where that is 0 the process's own limits are
    put back (the child kept one BLAS thread for its life, an audit)."""
    global _LOCK
    _LOCK = threading.Lock()
    own = getattr(_MINE, "depth", 0)
    if own == 0 and _STATE["limiter"] is not None:
        try:
            _STATE["limiter"].restore_original_limits()
        except Exception:  # pragma: no cover - (a library gone in the child)
            pass
        _STATE["limiter"] = _STATE["limit"] = None
    _STATE["depth"] = own


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def single_blas_thread():
    """BLAS limited to one thread for the duration (see the module docstring)."""
    return blas_limit(1)


@contextlib.contextmanager
def blas_limit(threads: int = 1):
    """BLAS limited to `threads` for the duration, shared by overlapping calls: the first to
    enter sets its limit, the last to leave puts back the process's own (see the module
    docstring; a batch's items in one worker's threads use it too). A call inside that asks
    for fewer threads (``kernel``'s tiles inside a batch item) gets them for its own duration
    and then puts back the limit it found; one that asks for more keeps the current limit."""
    from threadpoolctl import threadpool_limits

    inner = None
    with _LOCK:
        if _STATE["depth"] == 0:
            _STATE["limiter"] = threadpool_limits(limits=threads, user_api="blas")
            _STATE["limit"] = threads
        elif threads < _STATE["limit"]:
            inner = (threadpool_limits(limits=threads, user_api="blas"), _STATE["limit"])
            _STATE["limit"] = threads
        _STATE["depth"] += 1
    _MINE.depth = getattr(_MINE, "depth", 0) + 1
    try:
        yield
    finally:
        _MINE.depth -= 1
        with _LOCK:
            _STATE["depth"] -= 1
            if inner is not None:
                inner[0].restore_original_limits()
                _STATE["limit"] = inner[1]
            if _STATE["depth"] == 0:
                _STATE["limiter"].restore_original_limits()
                _STATE["limiter"] = _STATE["limit"] = None
