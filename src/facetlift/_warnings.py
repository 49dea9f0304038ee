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


#: The warning capture shared by the threads that record (:func:`recording`).
#: ``warnings.catch_warnings`` swaps process-wide state, so two threads recording at once
#: put one item's warnings in the other's record and left the caller's display broken (an
#: audit: a Dask client with two threads per worker; ``prior_fit`` from a thread pool). The
#: first thread to record installs one capture ("always" filter, a dispatching
#: ``showwarning``); each warning goes to the innermost recording block of the thread that
#: raised it, or to the display saved at installation; the last thread to leave restores
#: the state. The lock is held only to install and restore, never around the work (a lock
#: around whole jobs ran a threaded cluster's items one at a time and could deadlock, a
#: review).
_LOCK = threading.Lock()
_SHARED: dict = {"depth": 0, "restore": None, "show": None}
_LOCAL = threading.local()


def _reinit_after_fork() -> None:  # (a child forked while another thread held the lock;
    global _LOCK  # the forking thread's own blocks, in its thread-local stack, go on as they
    _LOCK = threading.Lock()  # were)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reinit_after_fork)


def _dispatch(message, category, filename, lineno, file=None, line=None):
    stack = getattr(_LOCAL, "stack", None)
    if stack:
        stack[-1](message, category, filename, lineno, file, line)
    else:
        _SHARED["show"](message, category, filename, lineno, file, line)


@contextlib.contextmanager
def recording(record: bool = True, action: str = "always", on_warning=None):
    """The warnings this thread raises in the block: recorded in the yielded list (`record`,
    and `action` "always"), or dropped (`action` "ignore"); `on_warning` (callable(message))
    also hears each as it comes. Other threads' warnings are shown as before, and threads
    record at the same time without taking turns (:data:`_SHARED`)."""
    caught: list = []

    def handle(message, category, filename, lineno, file=None, line=None):
        if action == "ignore":
            return
        caught.append(warnings.WarningMessage(message, category, filename, lineno, file, line))
        if on_warning is not None:
            on_warning(message)

    with _LOCK:
        if _SHARED["depth"] == 0:
            restore = warnings.catch_warnings()
            restore.__enter__()
            warnings.simplefilter("always")
            _SHARED["restore"], _SHARED["show"] = restore, warnings.showwarning
            warnings.showwarning = _dispatch
        _SHARED["depth"] += 1
    stack = getattr(_LOCAL, "stack", None)
    if stack is None:
        stack = _LOCAL.stack = []
    stack.append(handle)
    try:
        yield caught if record else None
    finally:
        stack.remove(handle)
        with _LOCK:
            _SHARED["depth"] -= 1
            if _SHARED["depth"] == 0:
                restore, _SHARED["restore"] = _SHARED["restore"], None
                restore.__exit__(None, None, None)
