"""Path checks shared by the readers and writers: extension allowed, file present."""

from __future__ import annotations

import os
from pathlib import Path


def _suffix(path: Path, allowed: tuple[str, ...], what: str, arg: str) -> str:
    ext = path.suffix.lower()
    if ext not in allowed:
        lossy = (" (a JPEG's lossy 8 bits still integrate well: convert it to PNG first, "
                 "e.g. with Pillow, Image.open(p).save(q))"
                 if ext in (".jpg", ".jpeg") and what == "normal map" and arg != "path"
                 else "")  # (a map being read: not a mask, whose JPEG edges would grow it)
        raise ValueError(
            f"`{arg}`: unsupported {what} format {ext or '(no extension)'!r} for {path}; "
            f"supported: {', '.join(allowed)}{lossy}"
        )
    return ext


def _existing(path, arg: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"`{arg}` must be a path (str or os.PathLike); got {path!r}")
    p = Path(path)
    if not p.exists():
        raise ValueError(f"`{arg}`: file {p} does not exist")
    if p.is_dir():
        raise ValueError(f"`{arg}`: {p} is a directory, not a file")
    return p
