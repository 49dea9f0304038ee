"""The exceptions facetlift raises besides ``ValueError`` (bad input, naming the argument):
:class:`SolverError` and :class:`MemoryLimitError`.

Kept in a module without heavy imports, so the command line can catch them cheaply.
"""

from __future__ import annotations


class SolverError(RuntimeError):
    """The solver failed: a singular matrix, no convergence, a backend error, or a result that
    is not finite inside the mask."""


class MemoryLimitError(MemoryError):
    """The planned peak memory of a job exceeds the limit (``max_memory``): the message names
    the estimate, the limit and what to do instead."""
