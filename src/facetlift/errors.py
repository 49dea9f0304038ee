"""The exceptions facetlift raises besides ``ValueError`` (bad input, naming the argument):
:class:`SolverError`, :class:`MemoryLimitError` and, from :func:`facetlift.batch`,
:class:`WorkersDied`.

Kept in a module without heavy imports, so the command line can catch them cheaply.
"""

from __future__ import annotations


class SolverError(RuntimeError):
    """The solver failed: a singular matrix, no convergence, a backend error, or a result that
    is not finite inside the mask."""


class WorkersDied(RuntimeError):
    """The local worker processes of a batch died before finishing (killed, out of memory, or
    started from a script without a ``__main__`` guard); the batch log keeps what finished, so
    ``resume=True`` goes on. The command line reports it in one line, exit code 1."""


class MemoryLimitError(MemoryError):
    """The planned peak memory of a job exceeds the limit (``max_memory``): the message names
    the estimate, the limit and what to do instead."""
