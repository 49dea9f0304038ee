"""Atomic output: write a temporary file next to the target, fsync it, rename it over the target.

A failed or interrupted write never leaves a partial file behind: the target is either untouched
or complete.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def atomic_path(path):
    """Context manager yielding a temporary path next to `path`; renamed over it on success.

    The temporary file is flushed to disk (fsync) before ``os.replace``; on any exception it is
    removed and the exception re-raised, so `path` is either untouched or complete.
    """
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    with contextlib.suppress(OSError):  # persist the rename; not possible everywhere
        dfd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def _write_bytes(path: Path, data: bytes) -> None:
    with atomic_path(path) as tmp, open(tmp, "xb") as fh:
        fh.write(data)


def _save_npy(path: Path, arr: np.ndarray) -> None:
    with atomic_path(path) as tmp, open(tmp, "xb") as fh:
        np.save(fh, arr, allow_pickle=False)
