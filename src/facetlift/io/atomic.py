"""Atomic output: write a temporary file next to the target, fsync it, rename it over the target.

A failed or interrupted write never leaves a partial file behind: the target is either untouched
or complete. :class:`OutputSet` extends the promise to all the outputs of one run: they are
written into a staging folder and moved into place only when all of them succeeded; SIGTERM
removes the staging folder, and :func:`sweep` removes what killed runs (SIGKILL) left.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import signal
import socket
import threading
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def atomic_path(path):
    """Context manager yielding a temporary path next to `path`; renamed over it on success.

    The temporary file is flushed to disk (fsync) before ``os.replace``; on any exception it is
    removed and the exception re-raised, so `path` is either untouched or complete.
    """
    target = Path(path)
    if not target.parent.is_dir():  # (the error named the temporary file, not the target)
        raise FileNotFoundError(f"cannot write {target}: its folder {target.parent} does not "
                                "exist")
    # (the name cut short: a target name near the file system's limit would leave no room
    # for the temporary's prefix and suffix; cut in bytes, as the limit counts them: 80 CJK
    # characters, 240 bytes, failed when cut at 96 characters, a review)
    short = os.fsencode(target.name)[:96].decode(errors="ignore") if os.name != "nt" \
        else target.name[:96]
    tmp = target.with_name(f".{short}.{_host()}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(e, OSError) and e.errno is not None and e.filename in (None, str(tmp),
                                                                              tmp):
            # (the error named the temporary file, not the target: a read-only folder; or no
            # file at all: a full disk fails in the write itself)
            raise OSError(e.errno, e.strerror, str(target)) from e
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


class _Stream:
    """A file seen by numpy as a stream (a ``write`` method alone): :func:`numpy.save` then
    writes it in chunks through Python's ``write`` instead of ``ndarray.tofile``, whose
    OSError on a full disk or a file size limit has no errno ("313344 requested and 25584
    written": neither the file nor the cause was named) and which turned a Ctrl-C into a
    TypeError, reported as a bug (a review)."""

    def __init__(self, fh):
        self.write, self.name = fh.write, fh.name


def _save_npy(path: Path, arr: np.ndarray) -> None:
    with atomic_path(path) as tmp, open(tmp, "xb") as fh:
        np.save(_Stream(fh), arr, allow_pickle=False)


# --------------------------------------------------------------------------------------------
# output sets: every file of one run, or none


class Terminated(BaseException):
    """SIGTERM (or SIGHUP, :data:`STOP_SIGNALS`) arrived while an :class:`OutputSet` was open
    (exit code 143)."""


#: Name prefix of staging folders, ``<prefix><host>-<pid>-<hex>``; :func:`atomic_path`'s
#: temporary files are ``.<name>.<host>.<pid>.<hex>.tmp``.
STAGING_PREFIX = ".facetlift-staging-"

#: The name of a batch's cancel mark in its output folder (:class:`OutputSet`'s `cancel`):
#: ``.facetlift-cancel-<token>``; marks older than :data:`CANCEL_KEEP` seconds are removed by
#: the next batch into the folder.
CANCEL_PREFIX = ".facetlift-cancel-"
CANCEL_KEEP = 86400.0


class Cancelled(Exception):
    """An :class:`OutputSet` whose cancel mark exists: nothing was written."""


def _host() -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in socket.gethostname())[:40] or "host"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists, owned by someone else
    return True


def sweep(folder) -> list[Path]:
    """Remove the staging folders and temporary files that killed runs on this host left in
    `folder` (their process is gone); returns what was removed."""
    removed = []
    host = _host()
    tmp_file = re.compile(r"^\..+\.([^.]+)\.(\d+)\.[0-9a-f]{8}\.tmp$")
    staged = re.compile(re.escape(STAGING_PREFIX) + r"(.+)-(\d+)-[0-9a-f]{8}$")
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for p in entries:
        m = staged.match(p.name)
        if m and m.group(1) == host and not _alive(int(m.group(2))):
            _roll_back(p, Path(folder))
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
            continue
        m = tmp_file.match(p.name)
        if m and m.group(1) == host and p.is_file() and not _alive(int(m.group(2))):
            with contextlib.suppress(OSError):
                p.unlink()
                removed.append(p)
    return removed


#: The outputs a commit is moving, one JSON line each (name, and device, inode, size and
#: modification time of the staged file, which the move keeps), written into the staging
#: folder before the first move and removed right after the last (:meth:`OutputSet.commit`):
#: a run killed in the middle of its moves (a batch worker stopped by its parent, which dies
#: at once) left some outputs new and some old, and the sweep deleted the old ones kept aside
#: (an audit); :func:`sweep` now puts them back.
MOVING = ".moving"


def _roll_back(staging: Path, outdir: Path) -> None:
    """Undo the moves of a dead run's unfinished commit (:data:`MOVING`): an output that is
    still the very file the run moved in (same device, inode, size and modification time; a
    file written there since is the user's and is left alone) goes back to the file kept
    aside for it in ``.replaced``, or is removed where it had none (an inode is reused at
    once, so its size and modification time are compared too)."""
    import json

    try:
        lines = (staging / MOVING).read_text(encoding="utf-8").splitlines()
    except OSError:
        return
    aside = staging / ".replaced"
    for line in lines:
        try:
            name, *stamp = json.loads(line)
        except (ValueError, TypeError):
            continue
        if not isinstance(name, str) or Path(name).name != name or name in (".", ".."):
            continue
        target = outdir / name
        try:
            st = os.lstat(target)
        except OSError:  # (none there: an old file moved aside, where it could be neither
            # linked nor copied, goes back, it was the only copy; but not one the user
            # deleted since, a review)
            with contextlib.suppress(OSError):
                if (aside / (name + MOVED)).exists() and (aside / name).exists():
                    os.replace(aside / name, target)
            continue
        if [st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns] != stamp:
            continue  # (not moved in by that run, or replaced since: not ours to touch)
        with contextlib.suppress(OSError):
            if (aside / name).exists() or (aside / name).is_symlink():
                os.replace(aside / name, target)
            else:
                target.unlink()


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def prepare_folder(folder) -> bool:
    """Create `folder` if needed, check that files can be written there (a probe file is
    written and removed) and :func:`sweep` it; returns whether it was created.

    Raises
    ------
    ValueError
        `folder` exists and is not a directory.
    OSError
        It cannot be created or written.
    """
    f = Path(folder)
    if f.exists() and not f.is_dir():
        raise ValueError(f"`out`: {f} exists and is not a directory")
    created = not f.exists()
    try:
        f.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OSError(f"cannot create the output folder {f}: {e.strerror or e}") from None
    probe = f / f"{STAGING_PREFIX}{_host()}-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        probe.mkdir()
        probe.rmdir()
    except OSError as e:
        if created:
            with contextlib.suppress(OSError):
                f.rmdir()
        raise OSError(f"the output folder {f} is not writable: {e.strerror or e}") from None
    sweep(f)
    return created


def _keep(target: Path, to: Path) -> None:
    """A second name `to` for the file `target` (a hard link; a copy where links fail; the
    link itself for a symbolic link), which stays in place."""
    if target.is_symlink():
        os.symlink(os.readlink(target), to)
        return
    try:
        os.link(target, to)
        return
    except OSError:
        pass
    try:  # (no hard links on this file system, or protected_hardlinks: a copy)
        shutil.copy2(target, to)
    except OSError:  # (nor a copy: an unreadable file of another user; moved, as before,
        # marked first: the sweep of a run killed after the move puts it back, and only then,
        # not an output the user deleted since, a review)
        to.with_name(to.name + MOVED).touch()
        os.replace(target, to)


#: The mark beside a file that :func:`_keep` moved aside rather than linked or copied.
MOVED = ".moved"


class OutputSet:
    """All outputs of one run, written into a staging folder inside `outdir` and moved into
    place only when every one of them succeeded.

    Creating it creates `outdir` (and checks that it is writable) *before* any work, refuses
    a target that is one of `inputs`, and sweeps what killed runs left behind (:func:`sweep`).
    Used as a context manager it commits on success; on any exception, and on SIGTERM
    (raised as :class:`Terminated`), it removes the staging folder, and `outdir` too if this
    run created it and it is still empty, so a failure leaves the folder as it was.

    >>> with OutputSet("out", names=["depth.npy"], inputs=["n.png"]) as out:  # doctest: +SKIP
    ...     surface.save(out.path("depth.npy"))

    Raises
    ------
    ValueError
        `outdir` exists and is not a directory, or a target is one of `inputs`.
    OSError
        `outdir` cannot be created or written.
    """

    def __init__(self, outdir, names=(), inputs=(), cancel=None):
        self.outdir = Path(outdir)
        # (a file whose existence cancels the set before anything moves: a cluster batch's
        # interrupt, which cannot stop a running task, jobs.Job.cancel_mark)
        self.cancel = None if cancel is None else Path(cancel)
        self._check_cancel()
        for name in names:
            target = self.outdir / name
            for src in inputs:
                if src is not None and Path(src).exists() and target.exists() and _same_file(
                    target, Path(src)
                ):
                    raise ValueError(
                        f"`out`: the output {target} is the input {src}; choose another "
                        "output folder (-o)"
                    )
        # (the folders above it that this run makes too: a failed -o new/sub left new/, an
        # audit; removed on failure while empty, innermost first)
        self._made = [p for p in self.outdir.absolute().parents if not p.exists()]
        self.created = prepare_folder(self.outdir)
        token = secrets.token_hex(4)
        self.staging = self.outdir / f"{STAGING_PREFIX}{_host()}-{os.getpid()}-{token}"
        try:
            self.staging.mkdir()
        except OSError as e:
            self._remove_outdir()
            raise OSError(
                f"the output folder {self.outdir} is not writable: {e.strerror or e}"
            ) from None
        self.staged: dict[str, Path] = {}
        self._in_the_way(names)  # (before any work; commit checks again)
        self._sigterm = sigterm_raises()

    def path(self, name: str) -> Path:
        """Where to write output `name` now (inside the staging folder)."""
        p = self.staging / name
        self.staged[name] = p
        return p

    def commit(self) -> dict[str, Path]:
        """Move every staged file into `outdir`; returns name -> final path.

        All or nothing: a target that is a folder is refused before anything moves, and a
        move that fails or is interrupted (SIGTERM, Ctrl-C) puts back what the earlier ones
        replaced, so the folder is left as it was. A replaced file is kept as a second link
        (a copy where the file system has none) before the new one is renamed over it: the
        target is never absent.

        Raises
        ------
        OSError
            A target is in the way (a folder of that name) or a move failed; the message
            names it and says that the folder was left as it was.
        """
        moves = [(name, p, self.outdir / name) for name, p in self.staged.items() if p.exists()]
        self._check_cancel(abort=True)
        self._in_the_way(name for name, _, _ in moves)
        aside = self.staging / ".replaced"
        import json

        done: dict[str, Path] = {}
        kept: dict[str, Path] = {}
        try:
            # (for the sweep of a run killed mid-commit: what it was moving, _roll_back;
            # inside, so that a failure to write it aborts as any other, a review)
            listed = []
            for name, p, _ in moves:
                st = os.lstat(p)
                listed.append(json.dumps([name, st.st_dev, st.st_ino, st.st_size,
                                          st.st_mtime_ns]) + "\n")
            (self.staging / MOVING).write_text("".join(listed), encoding="utf-8")
            for name, p, target in moves:
                if target.exists() or target.is_symlink():
                    (aside / name).parent.mkdir(parents=True, exist_ok=True)
                    _keep(target, aside / name)
                    kept[name] = target
                done[name] = target  # (before the move: an interrupt right after it)
                os.replace(p, target)
            # (done: nothing to roll back; removed before the staging folder, whose removal
            # a kill may cut short, a review)
            (self.staging / MOVING).unlink()
            COMMITTED.append(self.outdir)
        except BaseException as e:
            for name, target in done.items():
                with contextlib.suppress(OSError):
                    if name in kept:
                        os.replace(aside / name, target)
                    elif not (self.staged[name]).exists():  # (moved in: taken back out)
                        target.unlink()
            self.abort()
            if isinstance(e, OSError):
                raise OSError(f"could not move the outputs into {self.outdir} "
                              f"({e.strerror or e}: {e.filename2 or e.filename or ''}); the "
                              "folder was left as it was") from None
            raise
        shutil.rmtree(self.staging, ignore_errors=True)
        return done

    def _check_cancel(self, abort: bool = False) -> None:
        """Raise :class:`Cancelled` where the cancel mark exists (having removed the staging
        folder, with `abort`)."""
        if self.cancel is not None and self.cancel.exists():
            if abort:
                self.abort()
            raise Cancelled(f"cancelled ({self.cancel} exists): nothing was written")

    def _in_the_way(self, names) -> None:
        """Refuse a target that is a folder (a user's 'mkdir out/preview.png'), before work."""
        for name in names:
            target = self.outdir / name
            if target.is_dir() and not target.is_symlink():
                self.abort()
                raise OSError(f"cannot write {target}: a folder of that name is in the way "
                              "(move it, or choose another output folder, -o); nothing was "
                              "written")

    def abort(self) -> None:
        """Remove the staging folder (and `outdir`, if this run created it and it is empty)."""
        shutil.rmtree(self.staging, ignore_errors=True)
        self._remove_outdir()

    def _remove_outdir(self) -> None:
        if self.created:
            with contextlib.suppress(OSError):
                self.outdir.rmdir()  # only when empty
                for parent in self._made:  # (innermost first; stops at one not empty)
                    parent.rmdir()

    def __enter__(self):
        self._sigterm.__enter__()
        return self

    def __exit__(self, kind, value, tb):
        try:
            if kind is None:
                self.commit()
            else:
                self.abort()
        finally:
            self._sigterm.__exit__(None, None, None)
        return False


def _raise_terminated(signum, frame):
    raise Terminated(f"terminated by signal {signum}")


#: The output folders whose sets this process moved into place, in order: a Ctrl-C that
#: lands after a commit must not say that nothing was written (``facetlift.cli``, which
#: clears it per command; a user's check).
COMMITTED: list[Path] = []

#: Whether this process is a local batch worker (:func:`die_on_sigterm`).
_WORKER = False


def die_on_sigterm() -> None:
    """In this process SIGTERM keeps its default, dying at once, also while an output set is
    open: a local batch's worker, stopped by its parent, which then sweeps what the worker
    left (:func:`facetlift.batch._stop`). Raised inside the worker instead, :class:`Terminated`
    went on through the process pool's machinery while the parent was stopping it."""
    global _WORKER
    _WORKER = True
    # (a forked worker inherits a handler the parent had installed: the default again)
    for sig in STOP_SIGNALS:
        if sig == signal.SIGTERM or signal.getsignal(sig) is _raise_terminated:
            signal.signal(sig, signal.SIG_DFL)


#: The signals :func:`sigterm_raises` turns into :class:`Terminated`: SIGTERM, and SIGHUP
#: where there is one (a closed terminal or a dropped ssh session left a partial staging
#: folder of 164 MB behind without a word, an audit).
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP")
                     if hasattr(signal, name))


@contextlib.contextmanager
def sigterm_raises():
    """SIGTERM (and SIGHUP, :data:`STOP_SIGNALS`) raises :class:`Terminated` in the main
    thread meanwhile (elsewhere, and in a batch worker, :func:`die_on_sigterm`: nothing), so
    the code inside cleans up as for an exception; the previous handlers are put back (one
    installed outside Python, which cannot be, leaves the default). A SIGHUP that was ignored
    when this began (``nohup``) stays ignored."""
    if _WORKER or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {}
    try:  # (installed inside, put back in reverse order: a signal between two installs left
        # the first handler in place for good, a review)
        for sig in STOP_SIGNALS:
            if sig != signal.SIGTERM and signal.getsignal(sig) is signal.SIG_IGN:
                continue  # (nohup's: the user asked to outlive the terminal)
            old[sig] = signal.signal(sig, _raise_terminated)
        yield
    finally:
        for sig, handler in reversed(list(old.items())):
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
