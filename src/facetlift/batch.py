"""Many integrations at once, on Dask: ``facetlift batch`` and :func:`facetlift.batch`.

Every item is one :class:`facetlift.jobs.Job` with its own output folder ``OUT/<name>/``.
Items run on the Dask local scheduler with one process per worker (``workers=N``), or on a
``dask.distributed`` cluster (``scheduler="tcp://host:8786"`` or a ``Client``). A failing item
never stops the others: its record says why. Every finished item appends one JSON line to the
log (``OUT/batch.jsonl``): ``item``, ``name``, ``status``, ``error``, ``exit``, ``outputs``,
``mean_deviation``, ``seconds``, ``hints`` (:mod:`facetlift.hints`, as ``integrate --json``
has them) and more (:func:`log_record`). ``resume=True`` skips the items whose last record is ``ok``
and whose outputs are all there.

Dask comes with the ``batch`` extra (``pip install 'facetlift[batch]'``) and is imported only
when more than one worker or a cluster is asked for.

Statuses: ``ok``; ``error`` (bad input or a missing extra: ValueError, OSError, ImportError;
exit 1); ``memory``
(MemoryLimitError, exit 1); ``solver`` (SolverError, exit 2); ``not_converged`` (outputs
written, exit 2); ``killed`` (a local worker process died while running it, also when run
again alone: :data:`KILLED`; a cluster's workers died running it: Dask's ``KilledWorker``;
exit 1); ``bug`` (any other exception, exit 3).
"""

from __future__ import annotations

import contextlib
import functools
import glob
import json
import os
import re
import sys
import time
import types
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

from ._warnings import recording
from .jobs import OUTPUT_STEMS, OUTPUTS, Job

#: Name of the JSON-lines log inside the batch's output folder.
LOG_NAME = "batch.jsonl"

_GLOB = set("*?[")


@dataclass(frozen=True)
class Item:
    """One input of a batch and the name of its output folder."""

    path: str
    name: str
    mask: str | None = None
    #: The map's own depth prior and normal confidence: ``NAME_prior_depth.*`` and
    #: ``NAME_confidence.*`` beside ``NAME.*`` (a video's frames, each with its monocular
    #: depth), as a dataset folder's ``prior_depth.*`` and ``confidence.*``.
    prior: str | None = None
    confidence: str | None = None
    #: The map's own colour image, ``NAME_colors.*`` beside ``NAME.*`` (an estimator's input
    #: photo, renamed after its map): it paints the item's meshes and points (--colors).
    colors: str | None = None
    #: Why the input cannot run (it does not exist, a pattern matches nothing): the batch
    #: records it as a failed item and runs the others.
    error: str | None = None
    #: ``(field, message)`` for each field (``"prior"``, ``"confidence"``) of which two files
    #: lie beside the map: the `error` is the first's, and goes where the batch reads
    #: neither (:func:`_own_files`).
    ambiguous: tuple = ()


#: A list file's comment: from a ``#`` at the start of a line or after white space.
_COMMENT = re.compile(r"(^|\s)#.*$")


def items(inputs, *, list_file=None) -> list[Item]:
    """The batch items of `inputs`: normal-map files, dataset folders (with ``normal_map.*``,
    or DiLiGenT's ``Normal_gt.mat``), folders of either (one level), glob patterns, and the
    lines of `list_file` (one path or pattern per line, relative to the list file's folder;
    ``#`` at the start of a line or after a space starts a comment).

    A file ``<stem>_mask.<ext>`` next to a normal map ``<stem>.<ext>`` is its mask, and is not
    an item unless named explicitly; so are ``<stem>_prior_depth.<ext>`` and
    ``<stem>_confidence.<ext>`` its depth prior and normal confidence (:func:`companions`: the
    formats of a dataset folder's ``prior_depth.*`` and ``confidence.*``; two of one kind
    make the item an error: which was meant?), and ``<stem>_colors.<ext>`` the image that
    paints its meshes and points (--colors; :data:`facetlift.io.colors.COLOR_FORMATS`). A
    one-channel image or 2-d array that pairs
    with no map (a stray depth map, a grey image: no normal map) is skipped with one warning
    naming them, unless named explicitly. Output names are the file stems or folder names; inputs
    sharing a stem (``a.png``, ``a.npy``) are named with their extension (``a_png``,
    ``a_npy``), and what still collides gets ``-2``, ``-3`` ... A dataset folder is named
    after the folder (DiLiGenT's ``bearPNG/``, not its ``Normal_gt.mat``: an audit's objects
    came out as ``Normal_gt``, ``Normal_gt-2`` ...), and a folder's camera file
    (``Calib_Results.mat``, :data:`facetlift.io.dataset.CAMERA_FILES`) or rotation file
    (``world_to_camera.npy``, :func:`facetlift.io.dataset.is_rotation_file`) is no item unless
    named explicitly. Paths are made absolute but
    not resolved: two links to one file are two items.

    An input that does not exist, or a pattern that matches nothing, is an item with its
    ``error`` set (a batch records it as failed and runs the others: one stale line of a long
    list must not stop the rest), after the others.

    Raises
    ------
    ValueError
        No normal map found at all (every input missing, or none holds a map).
    """
    from .io.dataset import is_rotation_file, one_channel
    from .io.images import MASK_FORMATS, NORMAL_READ_FORMATS

    if isinstance(inputs, (str, os.PathLike)):  # (one input: a str was read letter by letter)
        inputs = [inputs]
    specs = [str(s) for s in inputs]
    if list_file is not None:
        try:
            # (utf-8-sig: a BOM made the first entry "does not exist", an audit)
            lines = Path(list_file).read_text(encoding="utf-8-sig").splitlines()
        except OSError as e:
            raise ValueError(f"`list_file`: cannot read {list_file}: {e.strerror}") from None
        except UnicodeDecodeError as e:
            raise ValueError(f"`list_file`: {list_file} is no UTF-8 text list of inputs "
                             f"(byte {e.start}: {e.reason})") from None
        base = Path(list_file).parent
        for line in lines:
            # (a comment starts the line or follows a space: 'obj#3.png' is a file name)
            line = _COMMENT.sub("", line).strip()
            if line:  # (~ as a shell expands it: it was a folder named "~", a review)
                line = os.path.expanduser(line)
                specs.append(line if os.path.isabs(line) else str(base / line))
    paths: list[tuple[Path, bool]] = []  # (path, named explicitly)
    absent: list[tuple[str, str]] = []  # (the input as given, why it cannot run)
    for spec in specs:
        # (a folder that cannot be searched or listed is a failed item, not the end of the
        # batch: "[Errno 13] Permission denied" stopped it with no log, a review)
        try:
            paths += _input_paths(spec, absent)
        except OSError as e:
            absent.append((spec, f"`inputs`: {spec} cannot be read ({e.strerror or e}"
                           + (f": {e.filename}" if e.filename and str(e.filename) != spec
                              else "") + ")"))
    found, seen, lone, grey, photos = [], set(), [], [], []
    given = {os.path.abspath(p) for p, _ in paths}
    files = _Listing()  # (each folder listed once: a lookup per file was quadratic)
    for p, explicit in paths:
        # (the path as given, made absolute: links to one file are items of their own, each
        # with its own mask and name)
        key = os.path.abspath(p)
        # a mask beside its map is no item; named on its own it is (an unquoted *.png that the
        # shell expanded names X_mask.png with X.png: still X's mask)
        if key in seen or (_is_mask_file(p, NORMAL_READ_FORMATS, files) and (
                not explicit or given.intersection(_maps_of(p, NORMAL_READ_FORMATS, files)))):
            continue
        if not explicit and is_rotation_file(p):  # (world_to_camera.npy beside the maps:
            continue  # the camera's, as K.txt; _unused_folder_files names it, a review)
        if not explicit and p.stem.endswith("_mask") and one_channel(p):
            lone.append(p.name)  # (a grey X_mask.* without its map X.*: a mask, no item)
            continue
        if not explicit and p.stem.endswith("_colors") and len(p.stem) > len("_colors"):
            photos.append(p.name)  # (a photo X_colors.* without its map X.*: it ran as a
            continue  # normal map, a user's check)
        if not explicit and _grey(p):  # (a video's frame_000_prior_depth.png ran as a map
            grey.append(p.name)  # without its frame_000.png, and a stray depth map: both
            continue  # failed as "(H, W, 3) RGB" maps and the batch exited 1, an audit)
        seen.add(key)
        found.append((p, key))
    if photos:
        warnings.warn(
            f"batch: skipped {len(photos)} file(s) named like a map's colours without a map of "
            f"that name beside them ({', '.join(photos[:3])}"
            f"{', ...' if len(photos) > 3 else ''}): NAME_colors.* paints NAME.*; rename it "
            "after its map (a_normal.png pairs with a_normal_colors.jpg)", stacklevel=2)
    if lone:  # (a user's obj_normal.png + obj_mask.png: the mask ran as a map and failed)
        warnings.warn(
            f"batch: skipped {len(lone)} grey file(s) named like a mask without a map of that "
            f"name beside them ({', '.join(lone[:3])}{', ...' if len(lone) > 3 else ''}): "
            "NAME_mask.* is the mask of NAME.*: rename it after its map (obj_normal.png pairs "
            "with obj_normal_mask.png)", stacklevel=2)
    if grey:
        named = [n for n in grey if _companion(Path(n).stem) is not None]
        warnings.warn(
            f"batch: skipped {len(grey)} one-channel file(s) that pair with no normal map "
            f"({', '.join(grey[:5])}{', ...' if len(grey) > 5 else ''}): a normal map has "
            "three channels (a grey image or a depth map is none); NAME_mask.*, "
            "NAME_prior_depth.* and NAME_confidence.* beside a map NAME.* are its mask, depth "
            "prior and confidence"
            + (f" ({named[0]} has no map {_companion(Path(named[0]).stem)[0]}.* beside it: "
               "rename it after its map)" if named else "")
            + "; give such a file to every map with --mask, --prior or --confidence",
            stacklevel=2)
    names: dict[str, set] = {}
    for p, key in found:
        names.setdefault(_stem(p), set()).add(Path(key).name)
    out, taken = [], set()
    for p, key in found:
        # a stem shared by inputs of different extensions (a.png and a.npy) names each by its
        # extension too, whatever order they come in; then -2, -3 ... for what still collides
        # (one name in several folders)
        name = _stem(p) if len(names[_stem(p)]) == 1 else Path(key).name.replace(".", "_")
        name = _unique(name, taken)
        mask = None
        own = {}
        error = None
        ambiguous = []
        if p.is_file():  # (X_mask with any case of a mask extension)
            kinds = {e.lower() for e in MASK_FORMATS}
            # (absolute, as its prior's: a cluster's workers run in another folder, an audit)
            mask = next((os.path.abspath(m) for m in sorted(files.stem(p.parent,
                                                                      f"{p.stem}_mask"))
                         if m.suffix.lower() in kinds), None)
            for field, suffix, formats in companions():  # (its prior and confidence alike)
                kinds = {e.lower() for e in formats}
                them = sorted(m for m in files.stem(p.parent, f"{p.stem}{suffix}")
                              if m.suffix.lower() in kinds)
                own[field] = os.path.abspath(them[0]) if them else None
                if len(them) > 1:  # (as a dataset folder's two of a kind: which one was meant?)
                    ambiguous.append((field, (
                        f"`inputs`: {p.parent} holds {' and '.join(m.name for m in them)} "
                        f"beside {p.name}, each of them its {field}: keep one"
                        + (f" (--no-{field} reads neither)" if field != "colors" else ""))))
                    error = error or ambiguous[0][1]
        out.append(Item(path=key, name=name, mask=mask, error=error,
                        ambiguous=tuple(ambiguous), **own))
    if not out:
        if absent:
            more = f" (and {len(absent) - 1} more such input(s))" if len(absent) > 1 else ""
            raise ValueError(absent[0][1] + more)
        raise ValueError(f"`inputs`: no normal map found in {specs}")
    for spec, why in absent:
        key = os.path.abspath(spec)
        if key not in seen:  # (named twice: one record)
            seen.add(key)
            # (the log's name; no folder is made: a pattern's is "pattern")
            name = "pattern" if _GLOB & set(spec) else (Path(spec).name or "input")
            out.append(Item(path=key, name=_unique(name, taken), error=why))
    return out


def _input_paths(spec: str, absent: list) -> list[tuple[Path, bool]]:
    """The ``(path, named explicitly)`` of one input `spec` of :func:`items`; where it
    names nothing, ``(spec, why)`` added to `absent`. An OSError where a folder cannot be
    searched or listed."""
    from .io.dataset import is_dataset

    paths: list[tuple[Path, bool]] = []
    if _GLOB & set(spec) and not Path(spec).exists():  # (a file named 'a[1].png' is one)
        # (`**` any depth of folders, as shells with globstar read it: it matched one level
        # alone, and 'maps/**/*.png' skipped maps/a.png without a word, a review)
        found = sorted(glob.glob(spec, recursive=True))
        if not found:
            absent.append((spec, f"`inputs`: the pattern {spec!r} matches nothing"))
        for f in map(Path, found):  # (a matched folder is read as a named one: 'in/*' made
            # in/a and in/b failed items, an audit; the batch's own OUT is skipped)
            if f.is_dir() and not is_dataset(f):
                if not (f / LOG_NAME).is_file():
                    paths += _folder_items(f)
            elif not _batch_output(f):
                paths.append((f, False))
        return paths
    p = Path(spec)
    if not p.exists():
        absent.append((spec, f"`inputs`: {p} does not exist"))
    elif p.is_dir() and not is_dataset(p):
        paths += _folder_items(p)
    else:
        paths.append((p, True))
    return paths


def _folder_items(p: Path) -> list[tuple[Path, bool]]:
    """The items a plain folder given as an input holds, one level deep: its dataset
    folders and map files (not a camera file or facetlift's own outputs), with a warning
    naming the outputs and the subfolders of maps it skips."""
    from .io.dataset import CAMERA_FILES, OTHER_CAMERA_FILES, is_dataset
    from .io.images import NORMAL_READ_FORMATS

    kinds = NORMAL_READ_FORMATS + (".mat",)
    children = sorted(p.iterdir())
    folders = {c: is_dataset(c) for c in children if c.is_dir()}
    # (DiLiGenT's Calib_Results.mat beside its object folders is their camera: it
    # ran as a normal map and failed, an audit)
    outputs = set(OUTPUTS.values())
    # (K.npy, intrinsics.npy too: a camera, named by _unused_folder_files, not a failed map)
    cameras = {n.lower() for n in CAMERA_FILES + OTHER_CAMERA_FILES}
    out = [(c, False) for c in children if folders.get(c)
           or (c.is_file() and c.suffix.lower() in kinds
               and c.name.lower() not in cameras and c.name not in outputs)]
    ours = [c.name for c in children if c.is_file() and c.name in outputs]
    if ours:  # (an integrate -o into the maps' folder: its preview.png and
        # report.png ran as maps, its depth.exr failed the batch, an audit)
        warnings.warn(
            f"batch: {p}: skipped {len(ours)} file(s) named like facetlift's outputs "
            f"({', '.join(ours[:4])}{', ...' if len(ours) > 4 else ''}): name one as "
            "an input to integrate it", stacklevel=3)
    deeper = [c.name for c, dataset in folders.items()
              if not dataset and _holds_maps(c)]
    locked = [c.name for c, dataset in folders.items() if not dataset and _unlistable(c)]
    if locked:  # (skipped without a word before, a review)
        warnings.warn(
            f"batch: {p}: skipped {len(locked)} subfolder(s) that cannot be read "
            f"({', '.join(locked[:3])}{', ...' if len(locked) > 3 else ''}): check their "
            "permissions", stacklevel=3)
    if deeper:  # (a user's folder of days, each a folder of maps: silently skipped)
        warnings.warn(
            f"batch: {p}: skipped {len(deeper)} subfolder(s) holding maps but no "
            f"normal_map.* or Normal_gt.mat ({', '.join(deeper[:3])}"
            f"{', ...' if len(deeper) > 3 else ''}): a folder is read one level "
            f"deep; name each as an input (facetlift batch {p / deeper[0]} ...)",
            stacklevel=3)
    return out


def _own_files(found: list[Item], template: Job) -> list[Item]:
    """`found` with each item's own prior and confidence (``NAME_prior_depth.*``,
    ``NAME_confidence.*``) kept only where `template` takes them: not with ``--no-prior`` /
    ``--no-confidence`` (asked for: no word), nor where ``--prior`` / ``--confidence`` gives
    one file for every item, which takes precedence, as over a dataset folder's own, with one
    warning naming the items' files it leaves unread (a per-frame depth replaced by one
    file must not pass unsaid)."""
    from .jobs import COLOURED, DEFAULT_SAVE

    out = []
    unread: dict = {"prior": [], "confidence": []}
    # (an item's NAME_colors.* only where an output is painted: two of them failed an item
    # that saved only depth, a review)
    painted = bool(set(template.save or DEFAULT_SAVE) & COLOURED)
    for it in found:
        for field, given, wanted in (
                ("prior", template.prior, template.dataset_prior),
                ("confidence", template.confidence, template.dataset_confidence),
                ("colors", None, painted)):
            own = getattr(it, field)
            if own is None:
                continue
            if given is not None:
                unread[field].append(Path(own).name)
            if given is not None or not wanted:
                it = replace(it, **{field: None})
                if any(f == field for f, _ in it.ambiguous):  # (two files of which neither
                    # is read: no error then, unless the other kind is ambiguous too, a review)
                    rest = tuple(a for a in it.ambiguous if a[0] != field)
                    it = replace(it, ambiguous=rest, error=rest[0][1] if rest else None)
        out.append(it)
    for field, names in unread.items():
        if names:
            stem = "prior_depth" if field == "prior" else "confidence"
            warnings.warn(
                f"batch: `{field}` {getattr(template, field)} is used for every item, in place "
                f"of the NAME_{stem}.* files of {len(names)} item(s) ({', '.join(names[:3])}"
                f"{', ...' if len(names) > 3 else ''}): leave `{field}` out to give each map "
                "its own", stacklevel=3)
    return out


def _unlistable(folder: Path) -> bool:
    """Whether `folder` (not hidden) cannot be listed (its permissions)."""
    if folder.name.startswith("."):
        return False
    try:
        with os.scandir(folder) as it:
            next(it, None)
    except OSError:
        return True
    return False


def _holds_maps(folder: Path) -> bool:
    """Whether `folder` (not hidden, no facetlift output folder) holds a file that may be a
    normal map: an extension of one, and neither a mask, a camera or rotation file nor an
    output's name; False where it cannot be listed."""
    from .io.dataset import CAMERA_FILES, OTHER_CAMERA_FILES, is_rotation_file
    from .io.images import NORMAL_READ_FORMATS

    cameras = {n.lower() for n in CAMERA_FILES + OTHER_CAMERA_FILES}
    if folder.name.startswith(".") or folder.name.endswith("_facetlift"):
        return False
    kinds = NORMAL_READ_FORMATS + (".mat",)
    try:
        with os.scandir(folder) as it:
            names = [e.name for e in it if e.is_file()]
    except OSError:
        return False
    if "batch.jsonl" in names:
        return False
    return any(Path(n).suffix.lower() in kinds and Path(n).stem not in OUTPUT_STEMS
               and Path(n).stem.lower() != "mask" and _companion(Path(n).stem) is None
               and n.lower() not in cameras and not is_rotation_file(n) for n in names)


def _batch_output(f: Path) -> bool:
    """Whether `f` is a batch's own output (an item's preview.png, depth.npy ... in
    OUT/NAME/, beside OUT's log): 'maps/**/*.png' with -o maps/out took a first run's
    previews as maps on --resume (a review)."""
    return f.stem in OUTPUT_STEMS and (f.parent.parent / LOG_NAME).is_file()


def _stem(p: Path) -> str:
    """The folder name an input gives its results: of the absolute path (``.`` and ``..``
    named the cwd's results ``""`` and ``..``, written into OUT itself or beside it, an
    audit); ``input`` where that has no name (the root)."""
    q = Path(os.path.abspath(p))
    return (q.name if p.is_dir() else q.stem) or "input"


def _unique(name: str, taken: set) -> str:
    """`name`, or `name-2`, `name-3` ... whichever is not in `taken` (then added to it)."""
    new, k = name, 1
    while new in taken:
        k += 1
        new = f"{name}-{k}"
    taken.add(new)
    return new


def _unused_folder_files(found, template: Job) -> None:
    """Warn once per folder that holds a ``K.txt``, a ``mask.*`` or a rotation file
    (``world_to_camera.*``, ``camera_to_world.*``) beside normal-map files:
    only a dataset folder's (with ``normal_map.*``) are read, so its maps would be integrated
    orthographically (a user's rig: 583 mm MADE instead of 1.88 mm, and no word) and
    without that mask (an audit: docs/cli.md said a folder's mask.png was its maps' mask)."""
    from .io.dataset import is_dataset
    from .jobs import camera_unset, rotation_field, rotation_files, rotation_flag, unread_files

    by_folder: dict = {}
    for it in found:
        if it.error is None and Path(it.path).is_file():
            by_folder.setdefault(Path(it.path).parent, []).append(it)
    camera = camera_unset(template)
    if camera:  # (other tools' camera files, which only --K reads: the items, which do not
        # look beside themselves in a batch, ran orthographically without a word, a review)
        from .io.dataset import unread_camera_advice, unread_camera_files

        for folder in sorted(by_folder):
            others = unread_camera_files(folder)
            if others:
                warnings.warn(
                    f"batch: {folder} holds {' and '.join(p.name for p in others)} beside its "
                    f"normal maps, {unread_camera_advice(others, every=True)}", stacklevel=3)
    # (a dataset folder's own normal_map.* given as a file is warned about by its item,
    # jobs._beside_dataset_files, which names the folder's mask too: not twice)
    for folder in sorted(f for f in by_folder if not is_dataset(f)):
        # (the mask only where a map of the folder has none of its own, NAME_mask.*)
        mask = template.mask is None and any(it.mask is None for it in by_folder[folder])
        unread = unread_files(folder, None, mask=mask, camera=camera,
                              rotation=rotation_field(template) is None)
        turns = rotation_files(unread)
        for name in turns:  # (world-space maps integrated as camera-frame ones)
            flag = rotation_flag(name)
            warnings.warn(
                f"batch: {folder} holds {name} beside its normal maps, but only a dataset "
                "folder's rotation file (with normal_map.* or Normal_gt.mat) is read: these "
                f"maps' normals are read as the camera's; give {flag} {folder / name} "
                f"({Path(name).stem}=) to use it for every map", stacklevel=3)
        if "K.txt" in unread:
            warnings.warn(
                f"batch: {folder} holds K.txt beside its normal maps, but only a dataset "
                "folder's K.txt (with normal_map.* or Normal_gt.mat) is read: these maps are "
                f"integrated orthographically; give --K {folder / 'K.txt'} (K=) to use that "
                "camera",
                stacklevel=3)
        for name in (n for n in unread if n != "K.txt" and n not in turns):
            warnings.warn(
                f"batch: {folder} holds {name} beside its normal maps, but it is no map's mask: "
                "only a dataset folder's (with normal_map.* or Normal_gt.mat) is read, and "
                f"NAME_mask.* beside NAME.*; give --mask {folder / name} (mask=) to use it for "
                "every map, or name it after its map", stacklevel=3)


class _Listing:
    """The files of each folder by stem, each folder listed once (os.scandir)."""

    def __init__(self):
        self._by_folder: dict = {}

    def stem(self, folder: Path, stem: str) -> list:
        if folder not in self._by_folder:
            table: dict = {}
            with contextlib.suppress(OSError), os.scandir(folder) as entries:
                for e in entries:
                    if e.is_file():
                        p = Path(e.path)
                        table.setdefault(p.stem, []).append(p)
            self._by_folder[folder] = table
        return self._by_folder[folder].get(stem, [])


def _is_mask_file(p: Path, formats, files: _Listing) -> bool:
    """``mask.*``, or ``X_mask.*`` beside a normal map ``X.*`` (``_mask`` as written, the
    extension in any case), or ``X_prior_depth.*`` / ``X_confidence.*`` beside it
    (:func:`companions`): a map's mask, prior or confidence, not an item, in a folder or a
    pattern's matches (named explicitly, only where ``X.*`` is named too: :func:`items`)."""
    if not p.is_file():
        return False
    if p.stem.lower() == "mask":
        return True
    return bool(_maps_of(p, formats, files))


@functools.cache
def companions() -> tuple:
    """The files beside a normal map ``NAME.*`` that are its own, as ``(field, suffix,
    formats)``: the :class:`Item` and :class:`facetlift.jobs.Job` field, the stem's suffix
    and the extensions of a dataset folder's ``prior_depth.*`` and ``confidence.*``
    (:func:`facetlift.io.dataset.dataset_files`), named after one map of a folder of maps (a
    video's frames, each with its monocular depth). ``NAME_mask.*`` is looked for apart
    (:func:`items`), as before these."""
    from .io.colors import COLOR_FORMATS
    from .io.dataset import _dataset_formats

    formats = _dataset_formats()
    return (("prior", "_prior_depth", formats["prior_depth"]),
            ("confidence", "_confidence", formats["confidence"]),
            ("colors", "_colors", COLOR_FORMATS))


def _companion(stem: str) -> tuple[str, str] | None:
    """``(X, suffix)`` where `stem` is ``X_mask``, ``X_prior_depth``, ``X_confidence`` or
    ``X_colors`` (a non-empty X), else None."""
    for suffix in ("_mask",) + tuple(s for _, s, _ in companions()):
        if stem.endswith(suffix) and len(stem) > len(suffix):
            return stem[:-len(suffix)], suffix
    return None


def _maps_of(p: Path, formats, files: _Listing) -> list:
    """The absolute paths of the normal maps ``X.*`` that ``X_mask.*`` (or
    ``X_prior_depth.*``, ``X_confidence.*`` of their formats) may belong to."""
    pair = _companion(p.stem)
    if pair is None:
        return []
    stem, suffix = pair
    allowed = next((f for _, s, f in companions() if s == suffix), None)
    if allowed is not None and p.suffix.lower() not in {e.lower() for e in allowed}:
        return []
    kinds = {e.lower() for e in formats + (".mat",)}
    return [os.path.abspath(c) for c in files.stem(p.parent, stem)
            if c.suffix.lower() in kinds]


def _grey(p: Path) -> bool:
    """Whether `p` is a one-channel image or array by its header
    (:func:`facetlift.io.dataset.one_channel`: a grey or grey + alpha PNG, a 2-d ``.npy``, a
    one-sample TIFF), which no normal map is; not a two-sample TIFF, which
    ``--normal-encoding xy`` reads as one."""
    from .io.dataset import one_channel

    if not p.is_file() or not one_channel(p):
        return False
    if p.suffix.lower() in (".tif", ".tiff"):
        try:
            import tifffile

            with tifffile.TiffFile(p) as t:
                return t.pages[0].samplesperpixel == 1
        except Exception:  # (one_channel read it: not for here to say)
            return False
    return True


def run_item(job: Job, threads: int | None = None) -> dict:
    """Run one job and return its record; never raises (the record's ``status`` says why it
    failed). Runs in the worker processes, where `threads` limits the BLAS threads (one worker
    process per core: more threads would only compete)."""
    from .errors import MemoryLimitError, SolverError
    from .io.atomic import Cancelled
    from .jobs import finished_unconverged, run

    t0 = time.perf_counter()
    rec = {"status": "ok", "error": None, "exit": 0}
    caught = []  # (a failed item's warnings too: e.g. a gradient layout's, which may say why)
    try:
        with recording() as caught:
            if threads is None:
                result = run(job)
            else:
                from ._threads import blas_limit

                # (shared: items overlapping in one worker's threads, e.g. a Dask cluster's,
                # put the process's setting back in the right order)
                with blas_limit(threads):
                    result = run(job)
        rec.update(result)
        if not result["converged"] and not finished_unconverged(result["info"]):
            rec.update(status="not_converged", exit=2, error="did not converge")
    except MemoryLimitError as e:
        rec.update(status="memory", error=str(e), exit=1)
        from . import memory

        if memory._SHARE > 1 and job.options.get("max_memory") is None:
            rec["retry_alone"] = True  # (refused by this worker's share: _on_processes)
    except (ValueError, OSError, ImportError) as e:
        rec.update(status="error", error=str(e), exit=1)
    except SolverError as e:
        rec.update(status="solver", error=str(e), exit=2)
    except Cancelled as e:  # (its batch was interrupted: _on_cluster)
        rec.update(status="cancelled", error=str(e), exit=1)
    except MemoryError as e:
        rec.update(status="memory", error=f"out of memory ({e})", exit=1)
    except Exception as e:
        rec.update(status="bug", error=f"{type(e).__name__}: {e}", exit=3)
    rec["seconds"] = time.perf_counter() - t0
    # (integrate --json's hints, where they apply: a batch's records had none, an audit of a
    # video's frames; facetlift.hints words them with the command line's flags)
    rec["hints"] = []
    if isinstance(rec.get("info"), dict):
        from .hints import job_hints

        try:
            rec["hints"] = job_hints(job, rec["info"], rec.get("camera_warned", False),
                                     bool(rec.get("gradient_field")))
        except Exception:  # pragma: no cover - (a hint never fails a finished item)
            pass
    if "warnings" not in rec:  # (a successful run's record has its own, in order)
        rec["warnings"] = list(dict.fromkeys(str(w.message) for w in caught))
    if "camera_warned" not in rec:  # (a failed run's, from its warnings as jobs.run's)
        from .errors import CameraWarning

        rec["camera_warned"] = any(issubclass(w.category, CameraWarning) for w in caught)
    rec.setdefault("mean_deviation", None)
    rec.setdefault("outputs", {})
    return rec


def _owners(records: list[dict]) -> dict[str, dict]:
    """Output folder name -> the log record whose results are in it: the last ``ok`` record
    of `records` (a log's, :func:`_finished_records`) naming that folder, while some of its
    outputs are still there (a later failed run of the same input leaves them: an output set
    fails whole, a review)."""
    last: dict[str, dict] = {}
    for rec in records:
        if rec.get("status") == "ok" and isinstance(rec.get("name"), str):
            last[rec["name"]] = rec
    return {name: rec for name, rec in last.items()
            if isinstance(rec.get("outputs"), dict) and rec["outputs"]
            and any(Path(p).is_file() for p in rec["outputs"].values())}


def _real(path: str) -> str:
    """`path` as the file system names it: links resolved, the case aside where it ignores
    it."""
    return os.path.normcase(os.path.realpath(path))


def _folders_of(owners: dict[str, dict], found: list, stamps: dict) -> dict[str, str]:
    """Input path -> its folder by the log (:func:`_owners`): the folder whose record is of
    the same input, by its real path (:func:`_real`), or of an input since moved or renamed
    whose files are the same (its path gone, its ``input_stamp`` equal to the input's: `mv
    maps maps2` gave every item a new folder and resumed none, a review); the first such
    folder. One pass over each, through dicts of the inputs' real paths and stamps."""
    by_real, by_stamp = {}, {}
    for it in found:
        by_real.setdefault(_real(it.path), it.path)
        if stamps.get(it.path):
            by_stamp.setdefault(json.dumps(stamps[it.path]), it.path)
    mine: dict[str, str] = {}
    for name, rec in owners.items():
        item = rec.get("item")
        if not isinstance(item, str):
            continue
        path = by_real.get(_real(item))
        if path is None and not os.path.exists(item) and rec.get("input_stamp"):
            path = by_stamp.get(json.dumps(rec["input_stamp"]))
        if path is not None and path not in mine:
            mine[path] = name
    return mine


def _finished_records(log: Path):
    """Every record of an existing log, in order (unreadable lines skipped)."""
    if log.is_file():
        for line in log.read_text(encoding="utf-8", errors="replace").splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut by a killed run
            if isinstance(rec, dict) and "item" in rec:
                yield rec


#: Method options that do not change an item's result (a memory limit: retrying the items
#: that failed for memory with a larger one must not run the others again).
NEUTRAL_OPTIONS = ("max_memory",)


def settings(job: Job) -> dict:
    """What a batch's template asks of every item that shapes its result (all but the
    item's input and output folder and :data:`NEUTRAL_OPTIONS`; the outputs as a sorted set),
    as the log records it: ``--resume`` skips only items finished with the same."""
    from dataclasses import asdict

    from . import frames
    from .jobs import jsonable

    # (unread_beside: which warnings are given, not the result)
    # (beside: which of an item's files came from beside its map, the item's own)
    out = {k: v for k, v in asdict(job).items()
           if k not in ("normals", "gradients", "outdir", "unread_beside", "beside",
                        "cancel_mark")}
    out["options"] = {k: v for k, v in job.options.items() if k not in NEUTRAL_OPTIONS}
    out["save"] = sorted(set(job.save))
    for key in ("fov", "output_frame", "height_range", "world_to_camera",
                "camera_to_world", "colors"):  # (unset: as in a log written before they existed)
        if out.get(key) is None:
            out.pop(key, None)
    if not out.get("strict"):  # (off: as in a log written before it existed)
        out.pop("strict", None)
    if out.get("normal_encoding") == "xyz":  # (the default: as before it existed)
        out.pop("normal_encoding", None)
    if out.get("normal_range") == "signed":  # (the default: as before it existed)
        out.pop("normal_range", None)
    if out.get("prior_weight") is None:  # (the default, as the result takes it: 1, as logs
        # before the blurred prior's own default recorded it, or that one; a review)
        from .problem import default_prior_weight

        try:
            out["prior_weight"] = default_prior_weight(None, job.prior_blur)
        except ValueError:  # (a bad prior_blur: the item's own run says so)
            out["prior_weight"] = 1.0
    if "output_frame" in out:  # (its spellings alike: "OpenCV", "opencv", "x,-y,-z")
        out["output_frame"] = frames.axis_string(out["output_frame"])
        if out["output_frame"] == "x,y,z":
            out.pop("output_frame")
    return jsonable(out)


def _comparable(asked) -> dict | None:
    """A log's settings (:func:`settings`) as a resume compares them: the options given at
    their method's defaults left out, and the normal frame by its axes (the identity as
    None): ``--solver direct`` or ``--normal-frame gl`` asked the same as before and ran
    every item again (a review). Applied to the recorded settings too, so older logs
    compare alike."""
    if not isinstance(asked, dict):
        return None
    from . import frames
    from .methods import get

    out = dict(asked)
    try:
        defaults = get(out.get("method", "dgp")).options()
    except (ValueError, TypeError):  # (an unknown method: the items' own runs say so)
        defaults = {}
    if isinstance(out.get("options"), dict):
        out["options"] = {k: v for k, v in out["options"].items()
                          if not (k in defaults and _same_value(v, defaults[k]))}
    if out.get("normal_frame") is not None:
        with contextlib.suppress(ValueError, TypeError):  # (a bad frame: the runs say so)
            out["normal_frame"] = frames.axis_string(out["normal_frame"])
            if out["normal_frame"] == "x,y,z":
                out["normal_frame"] = None
    return out


def _same_value(a, b) -> bool:
    """Whether an option's value `a` is its default `b` (of the same type: True is no 1)."""
    try:
        return type(a) is type(b) and bool(a == b)
    except Exception:  # (arrays and the like: not a default)
        return False


#: The template's fields that name a file read for every item (:func:`fingerprint`).
TEMPLATE_FILES = ("mask", "K", "prior", "prior_weight_map", "confidence", "world_to_camera",
                  "camera_to_world")


def fingerprint(item: Item, template: Job | None = None) -> list:
    """What an item's inputs are now: ``[name, size, mtime_ns]`` of its file (a dataset
    folder: of each file in it) and of its mask file, and ``[absolute path, size,
    mtime_ns]`` of the files `template` gives every item (``--mask``, ``--K``, ``--prior``
    ...: edited, or a relative path run from another folder, they were compared by their
    path's text only, an audit); ``--resume`` runs an item again when they changed (a map
    replaced under the same name)."""
    files = [Path(item.path)]
    if files[0].is_dir():  # (and a DiLiGenT folder's camera file in its parent)
        from .io.dataset import camera_files

        folder = files[0]
        # (not the outputs a batch writes there: with OUT the folder that holds the dataset
        # folders, each item's own outputs changed its inputs and --resume ran it again every
        # time, a review)
        ours = set(OUTPUTS.values()) | {LOG_NAME}
        files = sorted(f for f in folder.iterdir() if f.is_file() and f.name not in ours
                       and not f.name.startswith(".facetlift"))
        with contextlib.suppress(ValueError):  # (the item's own reading says why)
            files += [c for c in camera_files(folder) if c.parent != folder]
    # (its mask, prior and confidence beside it: a frame's depth replaced is a new input)
    files += [Path(f) for f in (item.mask, item.prior, item.confidence, item.colors)
              if f is not None]
    out = []
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        out.append([f.name, st.st_size, st.st_mtime_ns])
    for field in TEMPLATE_FILES if template is not None else ():
        value = getattr(template, field, None)
        if isinstance(value, (str, os.PathLike)) and os.path.isfile(value):
            st = os.stat(value)
            out.append([os.path.abspath(value), st.st_size, st.st_mtime_ns])
    return out


def _end_line(path: Path, fh) -> None:
    """A newline into the log `fh` (open to append to `path`) where its last line was cut
    short (a disk full, a kill in a write): the next record was glued onto the fragment,
    lost, and the log kept an invalid line for good (a review)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() == 0:
                return
            f.seek(-1, os.SEEK_END)
            last = f.read(1)
    except OSError:
        return
    if last != b"\n":
        fh.write("\n")
        fh.flush()


def _settled(folder: Path, outputs) -> bool:
    """Whether an item's output `folder` holds no unfinished commit older than its record's
    `outputs`: a run killed while it moved its outputs in (kill -9, the OOM killer) left a
    set half new, half old, which a resume kept as done because its last record was ``ok``
    (a review). A dead run's of this host is rolled back here
    (:func:`facetlift.io.atomic.sweep`: the set is the earlier one again); one of another
    host's, or of a live process, leaves the item to run again, unless every output was
    written after it (a run since has committed a whole set over it: it ran again on every
    resume, a review)."""
    from .io.atomic import MOVING, STAGING_PREFIX, sweep

    sweep(folder)
    try:
        marks = [p / MOVING for p in folder.glob(STAGING_PREFIX + "*") if (p / MOVING).exists()]
        if not marks:
            return True
        newest = max(mark.stat().st_mtime_ns for mark in marks)
        return all(Path(o).stat().st_mtime_ns > newest for o in outputs)
    except OSError:
        return False


def _complete(rec: dict, wanted: dict, stamp: list | None = None) -> bool:
    """Whether an earlier record finished what is asked now: ``ok``, with the same settings
    (outputs, method, options, frames ...; a record without them, from an older log, does
    not count), the same inputs (:func:`fingerprint`, where given) and every output it wrote
    still there. `wanted`: the settings asked now, as :func:`_comparable` gives them."""
    outputs = rec.get("outputs", {})
    return (rec.get("status") == "ok" and _comparable(rec.get("settings")) == wanted
            and (stamp is None or rec.get("input_stamp") == stamp)
            and all(Path(p).is_file() for p in outputs.values())
            # (the sizes they were written with, where the record has them: older logs not)
            and ("output_bytes" not in rec or _sizes(outputs) == rec["output_bytes"]))


def _sizes(outputs: dict) -> dict:
    """Each output's size in bytes (None where it cannot be read)."""
    out = {}
    for kind, p in outputs.items():
        try:
            out[kind] = os.path.getsize(p)
        except OSError:
            out[kind] = None
    return out


def batch(inputs, out, *, job: Job | None = None, workers: int | None = None,
          scheduler=None, resume: bool = False, progress: bool = False,
          list_file=None, log=None, on_record=None, wording=None,
          **job_options) -> list[dict]:
    """Integrate many normal maps, each into ``out/<name>/``.

    Parameters
    ----------
    inputs : str, Path or a sequence of them
        Files, dataset folders, folders of them, glob patterns (see :func:`items`).
    out : str or Path
        The batch's output folder.
    job : facetlift.jobs.Job, optional
        The template for every item (method, options, outputs, frame ...); or give its fields
        as keywords (``method="dgp"``, ``save=("npy",)``, ``options={...}``); any other
        keyword is a method option (``discontinuities=True`` is ``options={"discontinuities":
        True}``), checked with the template before any item runs. (``prior`` is the Job's
        depth-prior file; regularization's smoothness prior goes in ``options``.)
    workers : int, optional
        Local worker processes (default: the CPU count, at most the item count, where Dask is
        installed, else 1); 1 runs the items one after another in this process, without
        Dask.
    scheduler : str or dask.distributed.Client, optional
        A ``dask.distributed`` scheduler address (``"tcp://host:8786"``) or client: run there
        instead. The workers must see the input and output paths.
    resume : bool
        Skip items finished in an earlier run with the same settings (their log record
        ``ok``, with this template's outputs, method, options and frames, and its outputs
        still present); the others run again.
    progress : bool
        A progress bar on stderr (library code is quiet by default; the command line shows
        it when stderr is a terminal).
    list_file : str or Path, optional
        More inputs, one per line.
    log : str or Path, optional
        The JSON-lines log; default ``out/batch.jsonl``.
    on_record : callable, optional
        Called with each item's record as soon as it is known: the resumed ones first, then
        each finished one as it finishes (in the order they finish), after its log line.
    wording : callable, optional
        ``wording(message) -> str``, applied to each finished item's error and warnings before
        its log line: the command line's names its flags, as on its stderr (a second audit:
        a corrupt Normal_gt.mat was "NORMALS: ..." on stderr and "`folder`: ..." in the log).
        Default: the library's words, naming Python arguments.

    Returns
    -------
    list of dict
        One record per item, in item order, inputs that do not exist after the others
        (skipped items: their earlier record, with ``"resumed": True``).

    Raises
    ------
    ValueError
        No items, a bad template (:func:`check_template`: method, options, frames, save) or
        `workers`, before any item runs; per-item failures are records, not raised.
    ImportError
        Dask is needed (workers > 1 or a scheduler) and not installed.
    facetlift.errors.WorkersDied
        A RuntimeError: the local worker processes died (killed, or started from a script
        without a ``__main__`` guard); the log keeps what finished, so ``resume=True`` goes
        on.
    """
    from .io.atomic import prepare_folder, sigterm_raises

    if job is not None and job_options:
        raise ValueError(f"give `job` or job options, not both; got {sorted(job_options)}")
    if job is None:  # method options given as keywords (discontinuities=True) go to options
        from dataclasses import fields

        known = {f.name for f in fields(Job)}
        extra = {k: v for k, v in job_options.items() if k not in known}
        job_options = {k: v for k, v in job_options.items() if k in known}
        if extra:
            clash = sorted(set(extra) & set(job_options.get("options") or {}))
            if clash:
                raise ValueError(f"{clash} given both as keywords and in `options`")
            job_options["options"] = {**(job_options.get("options") or {}), **extra}
    if isinstance(job_options.get("save"), (str, os.PathLike)):  # (one output, not letters)
        job_options["save"] = (str(job_options["save"]),)
    if "save" in job_options and job_options["save"] is None:  # (the default, as jobs.run)
        del job_options["save"]
    template = job if job is not None else Job(**job_options)
    # once, before any item: a bad template is no per-item failure (a report's matplotlib is
    # the workers' affair on a cluster)
    check_template(template, local=scheduler is None)
    if workers is not None:  # (checked before the output folder is made: an audit)
        _workers(workers, 1)
        if scheduler is not None:  # (ignored without a word before, a review)
            warnings.warn(f"batch: `workers` {workers} is not used with a `scheduler`: the "
                          "cluster's own workers run the items", stacklevel=2)
    found = _own_files(items(inputs, list_file=list_file), template)
    _unused_folder_files(found, template)
    root = Path(out).resolve()
    new = [p for p in (root, *root.parents) if not p.exists()]  # (the folders it will make)
    prepare_folder(root)  # created and checked before any work
    log_path = root / LOG_NAME if log is None else Path(log)
    records = list(_finished_records(log_path))  # (the log read once)
    earlier = {rec["item"]: rec for rec in records} if resume else {}  # (each item's last)
    # (which input's results each folder holds, by the log: a batch of other inputs into the
    # same OUT wrote b's map.png over a's map/ without a word, and a later --resume of a kept
    # b's results as a's, an audit)
    owners = _owners(records)
    asked = settings(template)
    jobs, results = [], {}
    stamps = {it.path: fingerprint(it, template) for it in found}
    mine = _folders_of(owners, found, stamps)  # (each input's folder by the log)
    wanted = _comparable(asked)  # (once: each record is compared with it)
    for it in found:
        rec = earlier.get(it.path)
        # (settled first: its roll-back may take out an output, which _complete then misses)
        if rec is not None and mine.get(it.path) == rec.get("name") and _settled(
                root / rec["name"], rec.get("outputs", {}).values()) and _complete(
                rec, wanted, stamps[it.path]):
            results[it.path] = dict(rec, resumed=True)
    # the folders of the items kept from an earlier run are theirs, and so are the folders
    # the log gives to inputs not run now: an item run now that would take one of those names
    # (a new a.npy beside a kept a.png) is named anew. An item run again takes its own folder
    # first, whatever items() named it (two runs naming b/m and a/m apart swapped their
    # folders, a review)
    claimed = set(mine.values())
    reserved = {results[p]["name"] for p in results} | set(owners)
    pending = [it for it in found if it.path not in results and it.error is None]
    # (the names items() gave the others are taken too: a renamed one must not land on one)
    taken = reserved | {it.name for it in pending if it.path not in mine}
    moved = []
    # (the prior's settings apply to the maps with a prior; where some have none, those run
    # from their normals alone with a warning: a video's frames without a network's depth
    # failed, a user's check. Where no map can have one, each is refused as a job is)
    optional = template.prior is None and template.dataset_prior and any(
        it.prior is not None or _folder_prior(it.path) for it in found)
    for it in pending:
        if it.path in mine:
            it = replace(it, name=mine[it.path])
        elif it.name in reserved:
            old = it.name
            it = replace(it, name=_unique(it.name, taken))
            if old in owners and old not in claimed:
                moved.append((old, owners[old]["item"], it))
        # (the files beside it that it does not read: named once per folder, above)
        j = replace(template.with_input(it.path, root / it.name), unread_beside=False,
                    prior_optional=optional)
        if it.mask is not None and template.mask is None:
            j = replace(j, mask=it.mask)
        # (its own prior and confidence, NAME_prior_depth.* and NAME_confidence.*: where the
        # template takes them, _own_files left them on the item)
        own = {k: getattr(it, k) for k, _, _ in companions() if getattr(it, k)}
        if own:
            j = replace(j, beside=tuple(own), **own)
        jobs.append((it, j))
    if moved:
        old, other, it = moved[0]
        warnings.warn(
            f"batch: {len(moved)} item(s) named like a folder of {root} that holds another "
            f"input's results ({LOG_NAME}) were given new folders: {old}/ holds {other}, so "
            f"{it.path} is written to {it.name}/"
            + (f" (and {len(moved) - 1} more)" if len(moved) > 1 else ""), stacklevel=2)
    n_workers = _workers(workers, len(jobs))
    if on_record is not None:
        for it in found:
            if it.path in results:
                on_record(results[it.path])
    client = own = None
    if jobs and scheduler is not None:  # (before the log is made: nothing left if it fails)
        try:
            client, own = _connect(scheduler)
        except BaseException:
            with contextlib.suppress(OSError):  # (and the parents it made, a review)
                for folder in new:
                    folder.rmdir()  # (only if empty; the deepest first)
            raise
        jobs = _for_cluster(jobs, template, root)
    _drop_old_cancel_marks(root)
    with contextlib.ExitStack() as stack:
        if own:
            stack.callback(client.close)
        fh = stack.enter_context(open(log_path, "a", encoding="utf-8"))
        _end_line(log_path, fh)
        bar = stack.enter_context(_Bar(len(found), len(results), bool(progress)))

        def done(it: Item, rec: dict) -> None:
            rec = dict(rec, item=it.path, name=it.name, settings=asked,
                       input_stamp=stamps[it.path])
            if rec.get("status") == "ok":  # (for --resume: a truncated output, a disk full
                # or a copy cut short, was taken as done, a review)
                rec["output_bytes"] = _sizes(rec.get("outputs") or {})
            if wording is not None:
                rec["warnings"] = [wording(str(w)) for w in rec.get("warnings") or ()]
                if rec.get("error") is not None:
                    rec["error"] = wording(str(rec["error"]))
            results[it.path] = rec
            fh.write(json.dumps(log_record(rec)) + "\n")
            fh.flush()
            bar.update(rec["status"])
            if on_record is not None:
                on_record(rec)

        for it in found:  # (missing inputs: failed records, nothing to run)
            if it.error is not None and it.path not in results:
                done(it, _failed("error", it.error, seconds=0.0))
        existed = {j.outdir for _, j in jobs if Path(j.outdir).exists()}
        try:
            # (SIGTERM as an exception, like Ctrl-C: the workers are stopped, not orphaned)
            with sigterm_raises():
                if client is not None:
                    _on_cluster(jobs, client, done)
                elif jobs and n_workers > 1:
                    _on_processes(jobs, n_workers, done)
                else:
                    for it, j in jobs:
                        done(it, run_item(j))
        except BaseException:  # (an interrupt: the abandoned items leave no folder behind)
            _clean_abandoned([j.outdir for it, j in jobs if it.path not in results], existed)
            raise
    return [results[it.path] for it in found]


def _clean_abandoned(folders, existed=()) -> None:
    """Sweep the output folders of abandoned items (a killed worker cannot) of what killed
    runs left in them (:func:`facetlift.io.atomic.sweep`), and remove those the batch
    created if that left them empty (an interrupted batch left an empty folder per running
    item); a folder in `existed` stays (a review: its staging folder stayed too)."""
    from .io.atomic import sweep

    existed = {Path(f) for f in existed}
    for folder in map(Path, folders):
        if folder.is_dir():
            sweep(folder)
            if folder not in existed:
                with contextlib.suppress(OSError):
                    folder.rmdir()  # (only if empty)


def check_template(job: Job, local: bool = True) -> None:
    """Refuse a batch template that would fail every item: its method, method options,
    ``max_memory``, normal and gradient frames and output kinds are checked as
    :func:`facetlift.jobs.run` and :func:`facetlift.integrate` would check them, its
    rotation file (``world_to_camera`` / ``camera_to_world``), and
    ``prior_blur``'s value and the method's capability for it, and outputs the items could
    not make (:func:`facetlift.jobs._check_outputs`; the report's matplotlib only where the
    items run in this process or its workers: `local`).

    Raises
    ------
    ValueError
        Naming the field and what was received.
    ImportError
        ``save`` asks for the report and matplotlib is missing (with `local`).
    """
    from . import frames, memory, methods
    from .jobs import OUTPUTS
    from .options import validate

    info = methods.get(job.method)
    if not isinstance(job.options, dict):
        raise ValueError(f"`options` must be a dict of method options; got {job.options!r}")
    for name in ("mask", "K", "prior", "prior_weight_map", "confidence", "world_to_camera",
                 "camera_to_world"):
        value = getattr(job, name, None)
        if value is not None and not isinstance(value, (str, os.PathLike)):
            # (an array reached every item as a path: a TypeError 'bug' record each, an audit)
            raise ValueError(f"`{name}` of a batch is a file path read for every item; got "
                             f"{type(value).__name__}: write it to a file, or integrate each "
                             "map with facetlift.integrate, which takes arrays")
    if getattr(job, "colors", None) is not None:  # (one picture for every map: not theirs)
        raise ValueError(f"`colors` {job.colors}: a batch takes no colour image for every map "
                         "(one picture would paint them all); name each map's own NAME_colors.* "
                         "beside it (NAME.png and NAME_colors.jpg), or integrate each map with "
                         "its own (--colors; facetlift.integrate then Surface.save(..., "
                         "colors=))")
    if isinstance(job.save, (str, os.PathLike)) or not all(isinstance(k, str) for k in job.save):
        raise ValueError(f"`save` must be a sequence of output names; got {job.save!r}")
    opts = dict(job.options)
    if opts.get("max_memory") is not None:
        memory.parse_size(opts["max_memory"])
    opts.pop("max_memory", None)
    if "discontinuities" in opts and "discontinuities" not in info.options():
        # (integrate's own argument: True needs the capability, False is no-op where the
        # method has no such option, as integrate takes it)
        from .api import _check_discontinuities

        _check_discontinuities(info, opts.pop("discontinuities"))
    if opts.get("progress") is True:  # (integrate's own bar, as each item's integrate takes it)
        opts.pop("progress")
    validate(info.specs(), opts, job.method)
    if job.normal_frame is not None:
        frames.parse(job.normal_frame)
    # (values that failed every item, one record each, instead of the batch: an audit)
    import numpy as np

    for name, none in (("triangles", True), ("strict", False), ("orthographic", False)):
        value = getattr(job, name)
        if not (isinstance(value, (bool, np.bool_)) or (none and value is None)):
            raise ValueError(f"`{name}` must be True or False{' or None' if none else ''}; "
                             f"got {value!r}")
    from .problem import BACKFACING, _check_eps

    if job.backfacing not in BACKFACING:
        raise ValueError(f"`backfacing` must be one of {BACKFACING[:2]}; got "
                         f"{job.backfacing!r}")
    if job.outlier_eps is not None:
        _check_eps(job.outlier_eps)
    from .jobs import read_rotation

    read_rotation(job)  # (a file given for every item: read once, here)
    frames.normal_encoding(job.normal_encoding, "normal_encoding")
    frames.normal_range(job.normal_range)
    if job.output_frame is not None:
        frames.parse(job.output_frame, "output_frame")
    from .jobs import check_fov

    check_fov(job)
    if job.K is not None:  # (typed inline: its numbers; a file: there; each item reads it,
        # checked against its own image size)
        from .io.dataset import inline_K

        if inline_K(job.K) is None and not os.path.isfile(job.K):
            raise ValueError(f"`K`: {job.K} is no file, nor fx fy cx cy or nine numbers typed "
                             "inline")
    frames.gradient_frame(job.gradient_frame)
    if job.pixel_size is not None:
        from .camera import make_camera

        make_camera(job.pixel_size)
    if job.prior_blur is not None:  # (whether an item has a prior is the item's own)
        from .problem import prior_blur_value

        if prior_blur_value(job.prior_blur) > 0 and not info.prior_blur:
            able = sorted(k for k, v in methods.REGISTRY.items() if v.prior_blur)
            raise ValueError(f"method {job.method!r} does not take a `prior_blur`; methods "
                             f"that do: {able}")
    if job.height_range is not None:
        from .io.preview import check_height_range

        check_height_range(job.height_range)
    save = (job.save,) if isinstance(job.save, str) else tuple(job.save or ())
    unknown = [s for s in save if s not in OUTPUTS]
    if unknown:
        raise ValueError(f"`save`: unknown output(s) {unknown}; valid: {sorted(OUTPUTS)}")
    from .jobs import _check_outputs

    _check_outputs(save, job, local=local)


def _workers(workers, n_jobs: int) -> int:
    if workers is None:  # the default: every core, where Dask (the batch extra) is there
        try:
            import dask  # noqa: F401
        except ImportError:
            return 1
        return max(1, min(os.cpu_count() or 1, n_jobs))
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"`workers` must be a positive integer; got {workers!r}")
    return workers


def log_record(rec: dict) -> dict:
    """The JSON-ready record that the log keeps of an item (and ``facetlift batch --json``
    prints for every item, resumed or not)."""
    from .jobs import jsonable

    keep = ("item", "name", "status", "error", "exit", "outputs", "mean_deviation", "seconds",
            "shape", "facets", "mask_source", "converged", "warnings", "resumed", "settings",
            "input_stamp", "perspective", "camera", "prior_file", "confidence_file", "colors_file",
            "depth_range", "normals", "evaluation", "hints", "normal_rotation",
            "camera_warned", "output_bytes")
    # (mask_source: whether NAME_mask.png was used, a user asked; perspective: whether a
    # camera was used, a dataset folder's K.txt included; camera: which, a DiLiGenT folder's
    # being its parent's Calib_Results.mat; depth_range: height.png's scale;
    # normals: the mask's pixels without a usable normal, by reason; evaluation: the scores
    # against a dataset folder's depth_gt.*; prior_file, confidence_file: which files, a
    # frame's own NAME_prior_depth.* among them; hints: integrate --json's; normal_rotation:
    # the rotation that turned world-space normals, and its file, a folder's own among them)
    return jsonable({k: rec[k] for k in keep if k in rec})


def _dask():
    try:
        import dask
    except ImportError as e:
        raise ImportError(
            "facetlift batch with several workers or a cluster needs Dask, which comes with "
            "the batch extra: pip install 'facetlift[batch]' (or run with one worker: "
            "--workers 1, workers=1)"
        ) from e
    return dask


def _tracker_outlives_hangup() -> None:
    """Start multiprocessing's resource tracker with SIGHUP ignored, before the pool: a
    closed terminal sends SIGHUP to the whole process group, and the tracker, which ignores
    SIGINT and SIGTERM but not SIGHUP, died with the workers and printed five tracebacks
    about leaked resources (a review). Nothing where there is no SIGHUP or the tracker
    cannot be started here."""
    import signal

    if not hasattr(signal, "SIGHUP"):
        return
    try:
        from multiprocessing import resource_tracker

        old = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    except (ImportError, ValueError):  # (not the main thread: no handler can be set)
        return
    try:
        resource_tracker.ensure_running()
    except Exception:  # (the pool starts it as it would have)
        pass
    finally:
        signal.signal(signal.SIGHUP, old)


#: A local batch's record of an item whose worker process died while running it (killed: by
#: the out-of-memory killer or a signal, or crashed), after it was run again alone (when
#: other items were running beside it) and its worker died again.
KILLED = ("its worker process died while running it (killed, e.g. by the system's "
          "out-of-memory killer, or crashed), also when run again alone; the other items went "
          "on. A map too large for the memory: crop it, lower the memory limit (max_memory=, "
          "--max-memory) or run fewer workers (workers=, --workers)")


def _failed(status: str, error: str, exit: int = 1, seconds=None) -> dict:
    """The record of an item that failed outside :func:`run_item` (a missing input, a dead
    worker), with the keys every record has."""
    return {"status": status, "error": error, "exit": exit, "seconds": seconds,
            "warnings": [], "mean_deviation": None, "outputs": {}, "hints": [],
            "camera_warned": False}


def _on_processes(jobs, n_workers: int, done) -> None:
    """The Dask local scheduler, one process per worker; `done` runs here as items finish.

    A worker that dies (killed by the out-of-memory killer or a signal) breaks the pool: the
    items not yet started run on a new one, and the items that were running when it broke are
    run again one at a time, each alone in a pool of one; one whose worker dies again gets a
    ``killed`` record (:data:`KILLED`). One worker killed stopped the whole batch, with no
    record of the item that killed it, so every ``--resume`` died again (a review). Where no
    worker could start at all (a script without a ``__main__`` guard), :class:`WorkersDied`.
    An item refused for memory by its worker's share (:func:`facetlift.memory.share_among`)
    runs again alone, with all of it, after the others."""
    alone = []

    def shared(it, rec):  # (a refusal by the share: run again alone, not recorded yet)
        if rec.pop("retry_alone", False):
            alone.append(it)
        else:
            done(it, rec)

    def solo(it, j, ran_alone=False):  # (its worker dying alone too: the item's own doing)
        if ran_alone or _round([(it, j)], 1, done)[0]:
            done(it, _failed("killed", KILLED))

    job_of = {id(it): j for it, j in jobs}
    pending = list(jobs)
    while pending:
        lost, rest = _round(pending, n_workers, shared)
        if lost is None:
            break
        for it, j in lost:
            solo(it, j, ran_alone=len(lost) == 1 and n_workers == 1)
        pending = rest
    for it in alone:
        solo(it, job_of[id(it)])


def _workers_died() -> Exception:
    """The error of a batch whose worker processes could not start at all."""
    from .errors import WorkersDied

    return WorkersDied(
        "the batch's worker processes died before finishing (killed, out of memory, "
        + (_no_script_file() or "or started from a script without `if __name__ == "
           "'__main__':`, which worker processes need")
        + "); the log has the items that finished: rerun with resume=True, or with "
        "workers=1"
    )


def _round(jobs, n_workers: int, done):
    """Run `jobs` on a new pool of `n_workers` processes: ``(None, None)`` when all finished,
    else, where the pool broke (a worker died), ``(lost, rest)``: the jobs that were running
    then and those not started. Raises :func:`_workers_died`'s error where the pool broke
    before any worker had started (each counts itself in, :func:`_worker_start`)."""
    dask = _dask()
    from dask.callbacks import Callback

    keys = {}
    tasks = []
    for it, j in jobs:
        task = dask.delayed(run_item, pure=False)(j, 1, dask_key_name=f"item-{len(tasks)}")
        keys[task.key] = (it, j)
        tasks.append(task)
    started, finished = set(), set()

    class _Done(Callback):
        def _pretask(self, key, dsk, state):  # (in this process, as a task is handed out)
            if key in keys:
                started.add(key)

        def _posttask(self, key, result, dsk, state, worker_id):
            if key in keys:
                finished.add(key)
                done(keys[key][0], result)

    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from dask.multiprocessing import get_context

    # our own pool, so that an interrupt stops its workers: Dask's own waits for the running
    # items at shutdown, and an interrupt during a worker's start could leave the process
    # waiting for it at exit (a Ctrl-C hang, 2 of 2 tries at 3 s into a 3-map batch)
    _tracker_outlives_hangup()
    base = get_context()
    ctx = _Recording(base)  # (every worker it starts: what _stop stops)
    # (the workers that started: a task is "started" here when it is handed out, so a script
    # whose workers cannot start had every item recorded as killed, a review)
    alive = base.Value("i", 0)
    from .io.images import _REDIRECT

    pool = ProcessPoolExecutor(n_workers, mp_context=ctx, initializer=_worker_start,
                               initargs=(_REDIRECT["enabled"], n_workers, alive))
    try:
        with _Done():
            # one item per dispatch: Dask's default hands ready tasks out in chunks of 6, so a
            # batch of up to 6 items ran one after another in one worker, and every chunk's
            # records (the log, the bar) came only when all of it had finished
            dask.compute(*tasks, scheduler="processes", num_workers=n_workers, chunksize=1,
                         pool=pool)
    except BrokenProcessPool as e:
        _stop(pool, ctx.started)
        if alive.value == 0:
            raise _workers_died() from e
        return ([keys[k] for k in keys if k in started and k not in finished],
                [keys[k] for k in keys if k not in started])
    except BaseException:  # (an interrupt too: the running items are abandoned)
        _stop(pool, ctx.started)
        raise
    pool.shutdown(wait=True)
    return None, None


def _no_script_file() -> str | None:
    """Why worker processes cannot start where the main module is a script read from stdin
    (``python - <<EOF``): they re-import it from its file, and it has none (it was blamed on a
    missing ``__main__`` guard, a user's check); None otherwise (a file, ``python -c``, an
    interactive session or a notebook)."""
    import sys

    main = sys.modules.get("__main__")
    name = getattr(main, "__file__", None)
    if name is not None and str(name) in ("<stdin>", "-"):
        return ("or started from a script read from stdin (`python - <<EOF`), which worker "
                "processes cannot re-import: save it to a file and run that, with `if "
                "__name__ == '__main__':`")
    return None


def _worker_start(protect: bool = False, workers: int = 1, alive=None) -> None:
    """A batch worker process leaves Ctrl-C to the parent, which stops it (:func:`_stop`),
    dies at once on the parent's SIGTERM (:func:`facetlift.io.atomic.die_on_sigterm`), keeps
    stdout as the parent does (`protect`: the command line's, which it shares), plans its
    items against its share of the free memory, one of `workers`
    (:func:`facetlift.memory.share_among`), starts no threads of its own beside others
    (:data:`facetlift._threads.CORES`), and ends when the parent is gone
    (:func:`_orphan_exits`)."""
    import signal

    from . import _threads
    from .io.atomic import die_on_sigterm
    from .io.images import protect_stdout
    from .memory import share_among

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_on_sigterm()
    protect_stdout(protect)
    share_among(workers)
    if workers > 1:  # (one core each: a worker's own threads would only compete)
        _threads.CORES = 1
    _orphan_exits()
    if alive is not None:  # (counted in: the pool's parent tells a start from a death)
        with alive.get_lock():
            alive.value += 1


#: Seconds between a batch worker's checks that its parent still runs (:func:`_orphan_exits`).
ORPHAN_CHECK = 1.0


def _orphan_exits() -> None:
    """A batch worker whose parent died (a SIGKILL, which no handler sees) ends itself: the
    workers finished their items and then waited for more, orphans, for good (a review).
    What an item in flight leaves, its staging folder, the next run into that folder
    sweeps (:func:`facetlift.io.atomic.sweep`)."""
    import threading

    parent = os.getppid()

    def watch():
        while True:
            time.sleep(ORPHAN_CHECK)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="facetlift-orphan-check", daemon=True).start()


#: Seconds :func:`_stop` waits for terminated workers before it kills them.
STOP_GRACE = 5.0


class _Recording:
    """A multiprocessing context that records every process made through it (the pool's
    workers, recorded before they start: an interrupt during a start still finds them), and is
    the given context in everything else. (The processes themselves are the context's own:
    a spawned one is pickled, which a class of ours defined here could not be.)"""

    def __init__(self, base):
        self._base = base
        self.started: list = []

    def Process(self, *args, **kwargs):  # noqa: N802 - (the context's own name)
        proc = self._base.Process(*args, **kwargs)
        self.started.append(proc)
        return proc

    def __getattr__(self, name):
        return getattr(self._base, name)


def _stop(pool, procs) -> None:
    """Terminate a process pool's workers `procs` at once (their items are abandoned: every
    item's outputs are written as one set, so nothing partial is left) and release the pool;
    one still alive after :data:`STOP_GRACE` seconds, or when a second interrupt cuts the
    wait short, is killed. Only these: the host's own processes are left alone."""

    def alive():
        return [p for p in list(procs) if p.pid is not None and p.is_alive()]

    def signal_all(ps, kill=False):
        for proc in ps:
            try:
                proc.kill() if kill else proc.terminate()
            except Exception:  # pragma: no cover - (gone meanwhile)
                pass

    try:
        signal_all(alive())
        pool.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + STOP_GRACE
        while (left := alive()) and time.monotonic() < deadline:
            signal_all(left)
            time.sleep(0.05)
    finally:
        signal_all(alive(), kill=True)
        # (reaped before the caller sweeps their staging folders: a worker still alive to
        # os.kill(pid, 0) keeps its folder, and a second Ctrl-C left them in the items'
        # folders, an audit)
        for proc in list(procs):
            with contextlib.suppress(Exception):
                if proc.pid is not None:
                    proc.join(STOP_GRACE)


def _connect(scheduler):
    """``(client, own)``: a ``dask.distributed`` Client for `scheduler` (an address, or a
    Client, which is used as it is: `own` False) and whether this batch must close it.

    Raises
    ------
    ImportError
        dask.distributed is not installed (naming the extra).
    ValueError
        `scheduler` is no address (naming the argument).
    OSError
        The scheduler cannot be reached (naming the argument and the address; it was a
        bare "Timed out trying to connect" after an empty batch.jsonl was made, a check).
    """
    _dask()
    try:
        from distributed import Client
    except ImportError as e:  # (dask alone is a common install: named, an audit)
        raise ImportError("facetlift batch on a cluster (a scheduler) needs dask.distributed, "
                          "which comes with the batch extra: pip install 'facetlift[batch]'"
                          ) from e
    if isinstance(scheduler, Client):
        return scheduler, False
    try:
        return Client(scheduler), True
    except (ValueError, TypeError) as e:  # (said "missing port number in address 'threads'"
        # to scheduler='threads', without naming the argument, a review)
        raise ValueError(f"`scheduler` {scheduler!r}: {e}; give a dask.distributed "
                         "scheduler's address (tcp://host:8786) or a Client, or leave it out "
                         "for local worker processes (workers=N; --workers N on the command "
                         "line)") from None
    except OSError as e:
        raise OSError(f"`scheduler` {scheduler!r}: no dask.distributed scheduler answered "
                      f"({e}); check that it runs and that its address and port are right, "
                      "or leave it out for local worker processes (workers=N; --workers N "
                      "on the command line). Nothing was run") from None


def _for_cluster(jobs, template: Job, root: Path) -> list:
    """`jobs` as a cluster runs them: the template's files as absolute paths (the workers run
    in another folder: a relative --K, --mask or --prior failed every item with "does not
    exist", a review) and a cancel mark in `root` (:attr:`Job.cancel_mark`, written when the
    batch is interrupted). The settings the log records keep the paths as given."""
    import secrets

    from .io.atomic import CANCEL_PREFIX

    fields = [f for f in (*TEMPLATE_FILES, "colors")
              if isinstance(getattr(template, f, None), (str, os.PathLike))
              and os.path.isfile(getattr(template, f))]
    mark = str(root / f"{CANCEL_PREFIX}{secrets.token_hex(6)}")
    out = []
    for it, j in jobs:
        fixed = {f: os.path.abspath(getattr(j, f)) for f in fields
                 if getattr(j, f) == getattr(template, f)}
        out.append((it, replace(j, cancel_mark=mark, **fixed)))
    return out


def _drop_old_cancel_marks(root: Path) -> None:
    """Remove the cancel marks of interrupted cluster batches into `root` older than
    :data:`facetlift.io.atomic.CANCEL_KEEP` (their tasks have long finished)."""
    from .io.atomic import CANCEL_KEEP, CANCEL_PREFIX

    now = time.time()
    with contextlib.suppress(OSError):
        for p in root.glob(CANCEL_PREFIX + "*"):
            with contextlib.suppress(OSError):
                if now - p.stat().st_mtime > CANCEL_KEEP:
                    p.unlink()


def _on_cluster(jobs, client, done) -> None:
    """Run `jobs` on a ``dask.distributed`` `client` (:func:`_connect`); `done` runs here as
    futures finish. Interrupted, it writes the jobs' cancel mark (:attr:`Job.cancel_mark`)
    before cancelling the futures: a task already running cannot be stopped, and discards
    its outputs when it finds the mark."""
    futures = {}
    try:
        for it, j in jobs:
            futures[client.submit(run_item, j, 1, pure=False)] = it
        _collect(futures, done)
    except BaseException:  # (Ctrl-C or SIGTERM: the cluster's tasks ran on, a review)
        marks = {j.cancel_mark for _, j in jobs if j.cancel_mark is not None}
        for mark in marks:
            with contextlib.suppress(OSError):
                Path(mark).touch()
        with contextlib.suppress(Exception):
            client.cancel(list(futures))
        raise


def _collect(futures, done) -> None:
    """Each finished future's record to `done` (:func:`_on_cluster`)."""
    from distributed import as_completed

    for fut in as_completed(list(futures)):
        it = futures[fut]
        try:
            rec = fut.result()
        except Exception as e:  # a worker died or the task could not run at all
            rec = _failed("bug", f"{type(e).__name__}: {e}", exit=3)
            # (a killed worker was "a bug in facetlift", exit 3, a review)
            if type(e).__name__ == "KilledWorker":
                rec.update(status="killed", exit=1, error=(
                    f"the cluster's workers running it died ({e}: killed, e.g. out of "
                    "memory, or crashed); the other items went on"))
            elif isinstance(e, ImportError):  # (a worker without facetlift or an extra)
                rec.update(status="error", exit=1, error=f"on the cluster's worker: {e}")
        done(it, rec)


class _Bar:
    """A tqdm bar over the batch's items (nothing when not shown)."""

    def __init__(self, total: int, initial: int, show: bool):
        self.total, self.initial, self.show, self.failed = total, initial, show, 0
        self.bar = None

    def __enter__(self):
        if self.show:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, initial=self.initial, desc="batch", unit="map",
                            file=sys.stderr, leave=False)
        return self

    def update(self, status: str) -> None:
        self.failed += status != "ok"
        if self.bar is not None:
            self.bar.update(1)
            if self.failed:
                self.bar.set_postfix_str(f"{self.failed} failed", refresh=False)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()
        return False


def _folder_prior(path) -> bool:
    """Whether `path` is a dataset folder holding a ``prior_depth.*`` (or more than one: the
    item then says so), for a batch's optional prior settings (every folder counted before:
    a batch of folders without a prior took --prior-fit with a warning per item, a review)."""
    from .io.dataset import _dataset_formats, _find

    p = Path(path)
    if not p.is_dir():
        return False
    try:
        return _find(p, "prior_depth", _dataset_formats()["prior_depth"]) is not None
    except ValueError:
        return True


class _CallableModule(types.ModuleType):
    """``facetlift.batch`` is this module and the function at once: ``facetlift.batch(...)``
    runs :func:`batch` whichever way the name was first imported."""

    def __call__(self, *args, **kwargs):
        return batch(*args, **kwargs)

    @property
    def __signature__(self):  # (inspect.signature and a notebook's `batch?` showed
        # (*args, **kwargs) and the module's text, an audit)
        import inspect

        return inspect.signature(batch)


_CallableModule.__call__.__doc__ = batch.__doc__
sys.modules[__name__].__class__ = _CallableModule
