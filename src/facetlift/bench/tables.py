"""Tables of the bench: CSV and Markdown from lists of row dicts, written atomically."""

from __future__ import annotations

import csv
import io as _stdio
from pathlib import Path

import numpy as np


def write_text(path: Path, text: str) -> Path:
    """Write `text` to `path` atomically; returns `path`."""
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def fmt(v) -> str:
    """A table cell: floats to 6 significant digits, NaN and None empty."""
    if isinstance(v, float):
        if not np.isfinite(v):
            return ""
        return f"{v:.6g}"
    return "" if v is None else str(v)


def columns(rows: list[dict]) -> list[str]:
    """Every key of `rows`, in order of first appearance."""
    return list(dict.fromkeys(k for r in rows for k in r))


def write_csv(path: Path, rows: list[dict]) -> Path:
    """One CSV column per key of `rows` (see :func:`columns`); returns `path`."""
    cols = columns(rows)
    buf = _stdio.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: fmt(r.get(k)) for k in cols})
    return write_text(path, buf.getvalue())


def md_table(rows: list[dict], cols: list[str] | None = None, headers=None) -> str:
    """A Markdown table of `rows` over `cols` (default: every key)."""
    cols = cols or columns(rows)
    headers = headers or cols
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c)).replace("|", "/") for c in cols) + " |")
    return "\n".join(lines) + "\n"


def pivot(rows: list[dict], key: str, value: str, number="{:.3g}") -> str:
    """Markdown: one row per `key`, one column per method; a run that is not ok shows its status."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    keys = list(dict.fromkeys(r[key] for r in rows))
    out = []
    for k in keys:
        line = {key: k}
        for r in rows:
            if r[key] == k:
                v = r.get(value)
                ok = r["status"] == "ok" and v is not None and np.isfinite(v)
                line[r["method"]] = number.format(v) if ok else r["status"]
        out.append(line)
    return md_table(out, [key] + methods)
