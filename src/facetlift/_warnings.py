"""Warnings that point at the caller's line, not at facetlift's internals."""

from __future__ import annotations

import os
import sys
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
