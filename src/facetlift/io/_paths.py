"""Path checks shared by the readers and writers: extension allowed, file present."""

from __future__ import annotations

import os
from pathlib import Path


def _suffix(path: Path, allowed: tuple[str, ...], what: str, arg: str,
            reading_map: bool = False) -> str:
    """`path`'s extension (lower case) where `allowed`, else a ValueError naming `arg`;
    `reading_map`: a normal map being read, whose refusal of a JPEG says how to convert it
    (not a mask's, whose JPEG edges would grow it, nor an output's) and names the command
    line's other inputs."""
    ext = path.suffix.lower()
    if ext not in allowed:
        lossy = (" (a JPEG's lossy 8 bits still integrate well: convert it to PNG first, "
                 "e.g. with Pillow, Image.open(p).save(q))"
                 if ext in (".jpg", ".jpeg") and reading_map else "")
        more = ("; the command line also takes a MATLAB .mat file and a dataset folder"
                if reading_map else "")
        raise ValueError(
            f"`{arg}`: unsupported {what} format {ext or '(no extension)'!r} for {path}; "
            f"supported: {', '.join(allowed)}{more}{lossy}"
        )
    return ext


def _file_name(path, arg: str = "path") -> Path:
    """`path` as a Path where it is a file name (str or os.PathLike), else a ValueError: the
    writers pick the format by the extension and write atomically by renaming, so a file object
    cannot be one (a BytesIO was a bare TypeError, an audit)."""
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"`{arg}` must be a file name (str or os.PathLike), whose extension "
                         f"picks the format; got {type(path).__name__}: write to a file, then "
                         "read it into your buffer")
    return Path(path)


def _existing(path, arg: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"`{arg}` must be a path (str or os.PathLike); got {path!r}")
    p = Path(path)
    if not p.exists():
        from ..errors import InputFileNotFound

        raise InputFileNotFound(f"`{arg}`: file {p} does not exist")
    if p.is_dir():
        raise ValueError(f"`{arg}`: {p} is a directory, not a file")
    return p
