"""Checks for method options: each raises ``ValueError`` naming the option and the value."""

from __future__ import annotations

from typing import Callable

import numpy as np


def positive_int(value, name: str) -> int:
    """`value` as an int >= 1 (floats like 5.0 accepted; bools, NaN, inf and text refused)."""
    try:
        ok = not isinstance(value, bool) and float(value) == int(value) and int(value) >= 1
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"`{name}` must be a positive integer; got {value!r}")
    return int(value)


def number(value, name: str, check: Callable[[float], bool], what: str) -> float:
    """`value` as a finite float satisfying `check`; the error says `name` must be `what`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if isinstance(value, bool) or not np.isfinite(v) or not check(v):
        raise ValueError(f"`{name}` must be {what}; got {value!r}")
    return v
