"""Method options, declared once: name, type, range or choices, default, one-line doc.

Every method module declares a tuple ``OPTIONS`` of :class:`Option`. :func:`validate` checks
the values a caller passed before the method runs, fills in the defaults and refuses options
that do not apply to the chosen route (``when``), so a method receives only checked values.
``facetlift methods`` and ``docs/methods.md`` (:func:`markdown`) read the same declarations.

Every refusal is a ``ValueError`` that names the option, the value received and what was
expected, e.g. ``ValueError("`tol` must be a number >= 0; got 'a'")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

_KINDS = ("int", "float", "bool", "choice", "callable")


@dataclass(frozen=True)
class Option:
    """One keyword option of a method.

    Attributes
    ----------
    name : str
    default : object
        Value used when the option is not given (``None`` where it means "automatic").
    doc : str
        One line: what it does, in which units.
    kind : {"int", "float", "bool", "choice", "callable"}
    low, high : float, optional
        Range of an "int" or "float" option.
    low_open, high_open : bool
        Whether `low` / `high` themselves are excluded.
    inf : bool
        A "float" option that accepts +inf.
    choices : tuple
        The values of a "choice" option, or extra string values a "float" option accepts
        (e.g. ``scale="mad"``).
    none : bool
        None is accepted (the default is computed).
    when : dict
        The option applies only where the other options have these values, e.g.
        ``{"solver": "iterative"}``; given for another route it is refused.
    """

    name: str
    default: Any
    doc: str
    kind: str = "float"
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    inf: bool = False
    choices: tuple = ()
    none: bool = False
    when: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in _KINDS:  # pragma: no cover - a declaration bug
            raise TypeError(f"option {self.name!r}: unknown kind {self.kind!r}")

    @property
    def expected(self) -> str:
        """What a valid value is, in words."""
        if self.kind == "bool":
            text = "True or False"
        elif self.kind == "callable":  # (integrate takes progress=True for its own bar)
            text = ("True (a progress bar on stderr), False, a callable"
                    if self.name == "progress" else "a callable")
        elif self.kind == "choice":
            text = "one of " + ", ".join(repr(c) for c in self.choices)
        else:
            text = "an integer" if self.kind == "int" else "a number"
            bounds = []
            if self.low is not None:
                bounds.append(f"{'>' if self.low_open else '>='} {self.low:g}")
            if self.high is not None:
                bounds.append(f"{'<' if self.high_open else '<='} {self.high:g}")
            if bounds:
                text += " " + " and ".join(bounds)
            if self.inf:
                text += " (inf allowed)"
            if self.choices:
                text += " or " + " or ".join(repr(c) for c in self.choices)
        return text + (" or None" if self.none else "")

    def check(self, value):
        """`value` converted to the option's type, or ``ValueError`` naming the option."""
        if value is None and self.none:
            return None
        ok, out = _convert(self, value)
        if not ok:
            raise ValueError(f"`{self.name}` must be {self.expected}; got {value!r}")
        return out


def _number(opt: Option, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(
        value, "__float__"
    ):
        return False, None
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        return False, None
    if math.isnan(v) or (math.isinf(v) and not (opt.inf and v > 0)):
        return False, None
    if opt.kind == "int":
        if not math.isfinite(v) or v != int(v):
            return False, None
        v = int(v)
    if opt.low is not None and (v < opt.low or (opt.low_open and v == opt.low)):
        return False, None
    if opt.high is not None and (v > opt.high or (opt.high_open and v == opt.high)):
        return False, None
    return True, v


def _convert(opt: Option, value):
    if opt.kind == "bool":
        # (numpy's bool too: its type's name, which the check read, is "bool" since numpy 2,
        # and np.True_ was refused by every bool option, an audit)
        if isinstance(value, (bool, np.bool_)):
            return True, bool(value)
        return False, None
    if opt.kind == "callable":
        return callable(value), value
    if opt.kind == "choice" or (isinstance(value, str) and opt.choices):
        try:
            return value in opt.choices, value
        except TypeError:  # unhashable or incomparable values
            return False, None
    return _number(opt, value)


def _takes(option: Option | None, value) -> bool:
    """Whether `option` (None: not a method option) accepts `value`."""
    if option is None:
        return False
    try:
        option.check(value)
    except ValueError:
        return False
    return True


def validate(options: tuple[Option, ...], given: dict, method: str,
             keywords: tuple[str, ...] = (), hints: dict | None = None) -> dict:
    """Checked values of every option of `method`: the given ones converted, defaults elsewhere.
    `keywords`: the caller's own keyword arguments, offered too where an unknown name looks
    like one of them (a misspelt ``normal_frame`` was told the method's options alone).
    `hints`: unknown name -> what to do instead, said where that name is given (a keyword
    the caller has not but users expect, e.g. integrate's ``fov``).

    Raises
    ------
    ValueError
        An unknown option name (the message lists the valid ones), a bad value, or an option
        given for a route it does not apply to.
    """
    spec = {o.name: o for o in options}
    unknown = sorted(set(given) - set(spec))
    if unknown:
        hint = ""  # (a BiNI user's k: the bilateral sharpness is discontinuity_k for dgp)
        hints = hints or {}
        rest = [u for u in unknown if u not in hints]
        if "k" in rest and "discontinuity_k" in spec:
            # (not the same weighting: BiNI itself is method='bini' with k, an audit)
            hint = (f"; this route's cut sharpness is 'discontinuity_k' (default "
                    f"{spec['discontinuity_k'].default:g}, with discontinuities; not BiNI's "
                    "weighting: BiNI itself is method='bini' with its k)")
        elif "discontinuity_k" in rest and "k" in spec:  # (bini's own sharpness)
            hint = "; this method's sigmoid sharpness is 'k' (BiNI's k)"
        else:  # (a misspelling: discontinuity=True was told the valid list alone, a user's)
            import difflib

            close = {u: difflib.get_close_matches(u, sorted((set(spec) | set(keywords))
                                                            - {u}), n=3, cutoff=0.75)
                     for u in rest}  # (not the name itself: "'solver' for 'solver'")
            # best first: an option that takes the value given, then by difflib's ratio (its
            # order): discontinuity=True was offered 'discontinuity_k' first and the one
            # option taking True, 'discontinuities', last (a review)
            close = {u: " or ".join(map(repr, sorted(m, key=lambda o, u=u: not _takes(
                spec.get(o), given[u])))) for u, m in close.items() if m}
            if close:
                hint = "; did you mean " + ", ".join(f"{m} for {u!r}"
                                                     for u, m in close.items()) + "?"
        hint += "".join(f"; {hints[u]}" for u in unknown if u in hints)
        raise ValueError(
            f"unknown option(s) {unknown} for method {method!r}; valid options: {sorted(spec)}"
            + hint
        )
    values = {name: o.default for name, o in spec.items()}
    for name, value in given.items():
        values[name] = spec[name].check(value)
    for name in given:
        if name == "discontinuities" and not values[name]:
            continue  # (integrate's own argument: False is every method's no-op, an audit)
        for other, want in spec[name].when.items():
            if values[other] != want:
                # (an audit: --max-iter with --discontinuities named only the solver; the
                # reweightings' own cap is another option)
                alike = [o for o in ("discontinuity_iter", "discontinuity_tol")
                         if o in spec and values.get("discontinuities") and o != name
                         and o.rsplit("_", 1)[1] in name]
                raise ValueError(
                    f"`{name}` applies only with {other}={want!r} (method {method!r} has "
                    f"{other}={values[other]!r}); leave it out or set {other}={want!r}"
                    + (f"; with discontinuities=True the reweightings' counterpart is "
                       f"`{alike[0]}` (--option {alike[0]}=...)" if alike else "")
                )
    return values


def markdown(options: tuple[Option, ...]) -> str:
    """A Markdown table of the options (name, default, values, applies to, doc)."""
    lines = ["| option | default | values | applies | what it does |", "|---|---|---|---|---|"]
    for o in options:
        when = ", ".join(f"{k}={v!r}" for k, v in o.when.items()) or "always"
        auto = o.default is None and o.none and o.kind != "callable"
        default = "automatic" if auto else repr(o.default)
        lines.append(f"| `{o.name}` | {default} | {o.expected} | {when} | {o.doc} |")
    return "\n".join(lines) + "\n"
