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

import sys


def announce(progress, name: str) -> None:
    """Tell `progress` (a progress callable or None) that the stage `name` starts."""
    stage = getattr(progress, "stage", None)
    if callable(stage):
        stage(name)


class Rising:
    """A progress callable whose iteration count keeps rising across passes that each count
    from 1 (the discontinuity route's prior-free pass, then its pass with the prior; a
    blurred prior's retry): each pass continues where the last one stopped. With a depth
    prior the command line's bar ran backwards, and a callable heard 1, 2, 1, 2, 3, ... (a
    review). The stage protocol (:func:`announce`) is passed through."""

    def __init__(self, progress):
        self.progress = progress
        self.base = 0
        self.last = 0

    def __call__(self, iteration, value):
        if iteration <= self.last:  # (a new pass)
            self.base += self.last
        self.last = iteration
        return self.progress(self.base + iteration, value)

    @property
    def stage(self):
        return getattr(self.progress, "stage", None)


def rising(progress):
    """:class:`Rising` of `progress`, or None for None."""
    return None if progress is None else Rising(progress)


#: Seconds between redraws of the progress bar while a stage without iterations runs (its
#: elapsed time keeps counting).
_TICK = 1.0

#: What the reported value is, per stage that reports one (shown beside it in the bar): the
#: discontinuity route's weight change falls toward `discontinuity_tol` while it reweights;
#: its crack growth reports how far a weight fell (a cut opening: up to 4), which read as a
#: divergence unlabelled (a user's check).
_STAGE_VALUES = {"reweighting": "largest weight change", "crack growth": "largest weight fall"}

#: Stages that count iterations; the others show their name and the elapsed time only (a
#: user's check read "writing outputs: 51it [00:27, 3.64it/s]", the reweightings' count), and
#: so does "integrating" until a method reports its first iteration (a direct solve read
#: "integrating: 0it [00:00, ?it/s]").
_COUNTED = ("reweighting", "crack growth")
_UNCOUNTED_FORMAT = "{desc} [{elapsed}]{postfix}"


def _bar_format(stage: str) -> str | None:
    """tqdm's format for a stage: its own (a count) where the stage counts, else the name and
    the elapsed time."""
    return None if stage in _COUNTED else _UNCOUNTED_FORMAT


def progress_bar(total: int | None):
    """(bar, update): a tqdm bar on stderr that appears at the first update or stage (a
    route that reports neither shows nothing); ``bar.close()`` is safe either way. The
    command line's ``--progress``, and ``progress=True`` in the API.

    ``update.stage(name)`` (facetlift._progress) names the step that starts in the bar's
    description, and a thread redraws the bar every :data:`_TICK` seconds so that its
    elapsed time runs on through steps that report no iteration (a large map's smooth start,
    final solve and writing)."""
    import threading

    from tqdm import tqdm

    state = {}
    stop = threading.Event()

    def bar(desc="integrating"):
        if "bar" not in state:
            state["bar"] = tqdm(total=total, desc=desc, unit="it", file=sys.stderr,
                                leave=False, bar_format=_bar_format(desc))
        return state["bar"]

    def tick(b):
        while not stop.wait(_TICK):
            b.refresh()

    class _Bar:
        def close(self):
            stop.set()
            if "ticker" in state:
                state["ticker"].join()
            if "bar" in state:
                state["bar"].close()

    def update(iteration, value):
        b = bar()
        if state.get("stage", "integrating") == "integrating" and not state.get("counted"):
            state["counted"] = True
            b.bar_format = None  # (iterations reported: counted from here)
        label = _STAGE_VALUES.get(state.get("stage"))
        # (the value first: the update redraws, and the bar showed the last iteration's value,
        # an audit)
        b.set_postfix_str(f"{label} {value:.3g}" if label else f"{value:.4g}", refresh=False)
        b.update(iteration - b.n)

    def stage(name):
        state["stage"] = name
        b = bar(name)
        b.set_postfix_str("", refresh=False)  # (the last stage's value is not this one's)
        b.bar_format = _bar_format(name)
        b.set_description_str(name)  # (redraws)
        if "ticker" not in state:
            state["ticker"] = threading.Thread(target=tick, args=(b,), daemon=True,
                                               name="facetlift-progress")
            state["ticker"].start()

    update.stage = stage
    return _Bar(), update
