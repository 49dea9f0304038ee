"""Warnings that point at the caller's line, not at facetlift's internals."""

from __future__ import annotations

import contextlib
import os
import re
import sys
import threading
import warnings

_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def warn(message: str, category: type[Warning] = UserWarning, **fields) -> None:
    """``warnings.warn`` with the stack level of the first frame outside facetlift, computed
    by walking the stack (as scikit-image does), so the warning names the user's line.
    `fields` go to the category's constructor (its attributes: a reader of the recorded
    warning need not parse the message); the warning is marked ``from_facetlift``."""
    frame = sys._getframe(1)
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE):
        frame = frame.f_back
        level += 1
    rename = getattr(_LOCAL, "rename", None)
    if rename is not None:  # (renamed: a dataset folder's file for `prior`, jobs.run)
        message = rename(message)
    w = category(message, **fields)
    w.from_facetlift = True  # (told from others' warnings where facetlift re-emits a record)
    stack = getattr(_LOCAL, "stack", None)
    if stack:  # (a recording thread: straight to its record, past the filters and the
        # registries, so that no earlier display of the same line keeps it out of a record)
        where = ("sys", 1) if frame is None else (frame.f_code.co_filename, frame.f_lineno)
        stack[-1](w, category, *where, None, None)
        return
    warnings.warn(w, category, stacklevel=level)


@contextlib.contextmanager
def renamed(rename):
    """Within the block, this thread's facetlift warnings have their message passed through
    `rename` (callable(str) -> str) before they are raised: a caller that knows what an
    argument's name stands for says it (a dataset folder's ``confidence.npy`` for
    `confidence`, :func:`facetlift.jobs.run`)."""
    old = getattr(_LOCAL, "rename", None)
    _LOCAL.rename = rename
    try:
        yield
    finally:
        _LOCAL.rename = old


def reemit(w) -> None:
    """Show a recorded warning (a ``warnings.WarningMessage``) as ``warnings.warn`` would
    have from the caller's line: through the filters, with the registry and module of the
    first frame outside facetlift, so that the filters' once-per-line display holds across
    calls (re-emitted without a registry, a ``prior_fit`` call's warnings came again on every
    turn of a user's loop, an audit)."""
    frame = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE):
        frame = frame.f_back
    registry = module = None
    if frame is not None:
        registry = frame.f_globals.setdefault("__warningregistry__", {})
        module = frame.f_globals.get("__name__")
    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, module=module,
                           registry=registry)


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
_SHARED: dict = {"depth": 0, "show": None, "filters": (), "seen": set()}
_LOCAL = threading.local()


#: The message pattern of the capture's own "always" filter: matches every message, and
#: tells that entry from a user's ``simplefilter("always")`` by identity.
_MARK = re.compile("")
_ALWAYS = ("always", _MARK, Warning, None, 0)


def _set_filters(entries, target=None) -> None:
    """The filter list `target` (default: the current ``warnings.filters``) holds `entries`,
    changed in place (other threads' in-place changes and their saved references keep
    referring to it). The warnings module is not told (``_filters_mutated``): that would
    empty every module's registry of warnings shown once, and each recording block then
    showed them again (a user's loop over ``prior_fit`` calls, an audit); the capture's
    "always" entry needs no emptied registry, as facetlift's own warnings reach a record past
    the registries (:func:`warn`)."""
    (warnings.filters if target is None else target)[:] = entries


def _take_down() -> None:
    """Undo the capture's own changes to the process's warning state, and nothing else:
    its "always" entry leaves whatever filter list is current, and the display is put back
    where it is still the capture's. (Restoring the state saved at installation undid the
    filters other threads set meanwhile, or made a temporary one of theirs permanent: a
    ``simplefilter("error", ...)`` inside a main thread's ``catch_warnings`` stayed after a
    ``prior_fit`` run in a worker thread ended, an audit.)"""
    # (the list it was put in too, where another thread's catch_warnings has made another
    # list current meanwhile: it restores this one when it leaves)
    for target in (warnings.filters, _SHARED.pop("list", None)):
        if target is not None and any(f[1] is _MARK for f in target):
            _set_filters([f for f in target if f[1] is not _MARK], target)
    if warnings.showwarning is _dispatch:
        warnings.showwarning = _SHARED["show"]


def _reinit_after_fork() -> None:
    """A child forked while another thread held the lock or recorded: a new lock, and the
    depth of the forking thread's own blocks (its thread-local stack goes on as it was);
    where it has none the capture is taken down (the child's filters stayed at "always"
    for its life, an audit)."""
    global _LOCK
    _LOCK = threading.Lock()
    own = len(getattr(_LOCAL, "stack", None) or ())
    if own == 0 and _SHARED["depth"] > 0:  # (installed by another thread, gone in the child)
        with contextlib.suppress(Exception):
            _take_down()
    _SHARED["depth"] = own


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reinit_after_fork)


def _dispatch(message, category, filename, lineno, file=None, line=None):
    stack = getattr(_LOCAL, "stack", None)
    if stack:
        stack[-1](message, category, filename, lineno, file, line)
        return
    if not any(f[1] is _MARK for f in warnings.filters):
        # (the process's own filters judged it: no capture is installed in the current list,
        # e.g. this display was put back by another thread's catch_warnings after the
        # capture was taken down)
        _SHARED["show"](message, category, filename, lineno, file, line)
        return
    # (another thread's warning: judged by the filters as they were before the capture,
    # which replaced them with "always" for the whole process; shown unfiltered, a user's
    # simplefilter("error", ...) in one thread was ignored while another recorded, an audit)
    action = _user_action(message, category, filename, lineno)
    if action == "error":
        raise message if isinstance(message, Warning) else category(message)
    if action == "ignore":
        return
    if action in ("default", "module", "once"):
        text = str(message)
        key = {"default": (text, category, filename, lineno), "module": (text, category,
               filename), "once": (text, category)}[action]
        if key in _SHARED["seen"]:
            return
        _SHARED["seen"].add(key)
    _SHARED["show"](message, category, filename, lineno, file, line)


#: Module names by file name, for :func:`_module_of` (rebuilt where a file is not in it).
_MODULES: dict = {}


def _module_of(filename, lineno) -> str:
    """The module name ``warnings`` matches a filter's ``module`` against: the ``__name__``
    of the frame that warned (``numpy._core.fromnumeric``, ``__main__`` for a script, stdin
    or a notebook cell: the file's base name matched neither, a review), found on this
    thread's stack (the display runs in the thread that warned); else the loaded module of
    that file, or its base name (looked up once per file)."""
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_filename == filename and frame.f_lineno == lineno:
            name = frame.f_globals.get("__name__")
            if isinstance(name, str):
                return name
        frame = frame.f_back
    key = os.path.abspath(filename) if filename else ""
    if key not in _MODULES:
        for name, mod in list(sys.modules.items()):
            f = getattr(mod, "__file__", None)
            if isinstance(f, str):
                _MODULES.setdefault(os.path.abspath(f), name)
        # (a file of no module: its base name, kept, so a miss scans once, not per warning)
        _MODULES.setdefault(key, os.path.splitext(os.path.basename(filename or ""))[0]
                            or "<unknown>")
    return _MODULES[key]


def _matched(pattern, text: str) -> bool:
    """A filter's message or module `pattern` against `text`, as ``warnings`` matches them:
    None matches all, a compiled regex from its start, a plain string (Python's own default
    filter for ``__main__``'s DeprecationWarnings holds one) by equality (it raised an
    AttributeError inside any DeprecationWarning while a facetlift job recorded, a review)."""
    if pattern is None:
        return True
    if isinstance(pattern, str):
        return pattern == text
    return bool(pattern.match(text))


def _user_action(message, category, filename, lineno) -> str:
    """The action of the first of the filters saved at the capture's installation that
    matches (as ``warnings.warn_explicit`` matches them, the module taken from the file
    name); ``warnings.defaultaction`` where none does."""
    text = str(message)
    module = None  # (looked up only for a filter that names a module)
    for action, msg, cat, mod, ln in _SHARED["filters"]:
        if not (_matched(msg, text) and issubclass(category, cat)
                and (ln == 0 or lineno == ln)):
            continue
        if mod is not None:
            module = _module_of(filename, lineno) if module is None else module
            if not _matched(mod, module):
                continue
        return action
    return warnings.defaultaction


@contextlib.contextmanager
def recording(record: bool = True, action: str = "always", on_warning=None):
    """The warnings this thread raises in the block: recorded in the yielded list (`record`,
    and `action` "always"), or dropped (`action` "ignore"); `on_warning` (callable(message))
    also hears each as it comes. Other threads' warnings are shown as before, and threads
    record at the same time without taking turns (:data:`_SHARED`). facetlift's own warnings
    are recorded every time; another library's (numpy's, a callback's) as the warnings
    module lets them through: one its registry marks as shown already at that line is not
    recorded again (emptying the registries showed every warning again on each turn of a
    user's loop, an audit)."""
    caught: list = []

    def handle(message, category, filename, lineno, file=None, line=None):
        if action == "ignore":
            return
        caught.append(warnings.WarningMessage(message, category, filename, lineno, file, line))
        if on_warning is not None:
            on_warning(message)

    with _LOCK:
        if _SHARED["depth"] == 0:
            # (without a stale entry of an earlier capture, which another thread's saved
            # list can bring back: the user's filters behind it were then ignored, a review)
            _SHARED["filters"] = tuple(f for f in warnings.filters if f[1] is not _MARK)
            _SHARED["seen"] = set()
            _set_filters([_ALWAYS] + [f for f in warnings.filters if f[1] is not _MARK])
            _SHARED["list"] = warnings.filters
            if warnings.showwarning is not _dispatch:  # (left as the display by another
                # thread's catch_warnings: the display saved before is still the one)
                _SHARED["show"] = warnings.showwarning
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
                _take_down()


@contextlib.contextmanager
def said_if_raised():
    """:func:`recording` of a block whose warnings the caller says later (re-emits them);
    where the block raises, they are said before the error goes on (a prior_fit run that ran
    out of memory dropped the input's unusable-normals warning, an embedding audit; a job's
    settings warning was lost to a later check's error, a review)."""
    error = None
    with recording() as said:
        try:
            yield said
        except BaseException as e:  # (said outside the recording, then raised on)
            error = e
    if error is not None:
        for w in said:
            reemit(w)
        raise error

