"""Warnings that point at the caller's line, not at facetlift's internals."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import warnings

_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def warn(message: str, category: type[Warning] = UserWarning, **fields) -> None:
    """``warnings.warn`` with the stack level of the first frame outside facetlift, computed
    by walking the stack (as scikit-image does), so the warning names the user's line.
    `fields` go to the category's constructor (its attributes: a reader of the recorded
    warning need not parse the message)."""
    frame = sys._getframe(1)
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE):
        frame = frame.f_back
        level += 1
    warnings.warn(category(message, **fields) if fields else message, category,
                  stacklevel=level)


#: Serialises the blocks that swap the process's warning state (:func:`recording`):
#: ``warnings.catch_warnings`` sets module-wide state, so two threads recording at once put
#: one item's warnings in the other's record and left the caller's display broken (an audit:
#: a Dask client with two threads per worker; ``prior_fit`` from a thread pool). Re-entrant:
#: a batch item records around an integration that records too.
RECORDING = threading.RLock()


@contextlib.contextmanager
def recording(record: bool = True, action: str = "always"):
    """``warnings.catch_warnings(record=record)`` with ``simplefilter(action)``, one thread at
    a time (:data:`RECORDING`); yields the list of caught warnings (None without
    `record`)."""
    with RECORDING, warnings.catch_warnings(record=record) as caught:
        warnings.simplefilter(action)
        yield caught
