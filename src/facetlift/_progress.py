"""Stages of a long job for a progress callable.

A ``progress`` callable (``progress(iteration, value)``, the methods' option) counts
iterations. Some steps of a job have none to count and can still take long on a large map:
the discontinuity route's smooth start and final solve, the placement of separated pieces,
writing the outputs (a 2048^2 map with depth jumps spends tens of seconds in them). A
progress callable may therefore also carry an attribute ``stage``, a callable taking the
stage's name, which is called when such a step starts; the command line's progress bar shows
it. Callables without it are called as before.
"""

from __future__ import annotations


def announce(progress, name: str) -> None:
    """Tell `progress` (a progress callable or None) that the stage `name` starts."""
    stage = getattr(progress, "stage", None)
    if callable(stage):
        stage(name)
