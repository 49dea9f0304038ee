"""Perspective intrinsics (``K.txt``) and BiNI / DiLiGenT dataset folders."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._warnings import recording
from ._paths import _existing
from .images import (
    MASK_FORMATS,
    NORMAL_READ_FORMATS,
    _loadtxt_reason,
    _text_rows,
    read_mask,
    read_normals,
)


def read_K(path) -> np.ndarray:
    """Read 3x3 perspective intrinsics (OpenCV layout) from a file.

    A text file holds the matrix as three rows (``np.loadtxt``; numbers separated by spaces,
    tabs or commas), or its nine numbers on one line (row by row), or the four numbers
    ``fx fy cx cy`` (cx a column, cy a row from the top), the four possibly under a header
    naming them in any order (``cx cy fx fy``); or JSON: a 3x3 list, nine or four numbers, or
    an object with ``fx``, ``fy``, ``cx``, ``cy``. A ``.npy`` file holds a (3, 3) array, nine or
    four numbers likewise. A MATLAB ``.mat`` file (v4 to v7) holds it as the variable ``KK``
    (the calibration toolbox's ``Calib_Results.mat``, DiLiGenT's), ``K``, or its only 3x3
    numeric variable.

    Raises
    ------
    ValueError
        Missing or unparsable file, another count of numbers, or a matrix that is not valid
        intrinsics (see :mod:`facetlift.conventions`; a transposed matrix is named so).
    """
    from ..camera import check_K

    arg = "K"
    p = _existing(path, arg)
    try:
        if p.suffix.lower() == ".mat":  # (it was read as text: "'utf-8' codec can't decode")
            K = _K_mat(p)
        elif p.suffix.lower() == ".npy":
            K = np.load(p, allow_pickle=False)
        else:
            K = _K_text(p)
        K = np.asarray(K, dtype=float)
    except _KError as e:  # (the .mat file's own message: its variables, or why unreadable)
        raise ValueError(str(e)) from None
    except Exception as e:
        if p.suffix.lower() == ".npy":  # (numpy's advice on allow_pickle means nothing here)
            raise ValueError(f"`{arg}`: cannot read {p} as a numpy array of 3x3 (or 9, or 4) "
                             "numbers: not a .npy file of numbers, or a damaged one") from None
        raise ValueError(f"`{arg}`: cannot parse {p} as a 3x3 matrix ({_loadtxt_reason(e)}): "
                         "give three rows of three numbers, nine numbers, or fx fy cx cy (under "
                         "a header naming them, or as JSON)") from None
    if K.size == 9 and K.shape != (3, 3):  # nine numbers on one line, row by row
        K = K.reshape(3, 3)
    elif K.size == 4:  # fx fy cx cy
        fx, fy, cx, cy = K.ravel()
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    elif K.shape != (3, 3):
        raise ValueError(f"`{arg}`: {p} holds {K.size} number(s) in shape {K.shape}; expected "
                         "a 3x3 matrix (three rows, or nine numbers), or the four numbers "
                         "fx fy cx cy") from None
    try:
        return check_K(K)
    except ValueError as e:  # (check_K names a transposed K)
        raise ValueError(f"`{arg}`: {p}: {e}") from None


class _KError(ValueError):
    """A K file's own message, given as it is (not as a parse error)."""


#: The names a ``.mat`` file's intrinsics go by, in order: the calibration toolbox's
#: ``Calib_Results.mat`` (Bouguet's; DiLiGenT's) holds ``KK``.
MAT_K_NAMES = ("KK", "K")


def _K_mat(p: Path) -> np.ndarray:
    """The intrinsics of a ``.mat`` file (:func:`read_K`): its variable of
    :data:`MAT_K_NAMES`, or its only 3x3 numeric one; a :class:`_KError` lists the variables
    otherwise (a calibration's file also holds each view's 3x3 rotation, Rc_1, ...)."""
    from .images import load_mat

    try:
        data = load_mat(p, "K", "save KK as a text file (np.savetxt('K.txt', KK))")
    except ValueError as e:
        raise _KError(str(e)) from None
    square = {k: np.asarray(v) for k, v in data.items() if not k.startswith("__")
              and np.shape(v) == (3, 3) and np.asarray(v).dtype.kind in "biuf"}
    name = next((n for n in MAT_K_NAMES if n in square),
                next(iter(square)) if len(square) == 1 else None)
    if name is None:
        found = {k: "x".join(map(str, np.shape(v))) for k, v in data.items()
                 if not k.startswith("__")}
        raise _KError(f"`K`: {p} must hold the 3x3 intrinsics as {' or '.join(MAT_K_NAMES)}, "
                      "or one 3x3 numeric variable; got variables "
                      + (", ".join(f"{k} ({v})" for k, v in sorted(found.items())) or "none"))
    return square[name].astype(float)


#: The names a K file's header or JSON object may give its four numbers.
_K_NAMES = ("fx", "fy", "cx", "cy")


def _K_text(p: Path):
    """The numbers of a text K file (:func:`read_K`): JSON, a header of names over the four
    numbers (a user's 'fx fy cx cy' first line was refused), or plain rows."""
    import json

    text = p.read_text(encoding="utf-8-sig").strip()
    if text[:1] in "[{":
        data = json.loads(text)
        if isinstance(data, dict):
            low = {str(k).lower(): v for k, v in data.items()}
            missing = [k for k in _K_NAMES if k not in low]
            if missing:
                raise ValueError(f"a JSON object needs {', '.join(_K_NAMES)}; {missing} missing")
            data = [low[k] for k in _K_NAMES]
        return np.asarray(data, dtype=float)
    rows = _text_rows(p)
    head = rows[0].split() if rows else []
    if head and all(w.strip("\"'").lower() in _K_NAMES for w in head):
        names = [w.strip("\"'").lower() for w in head]
        if sorted(names) != sorted(_K_NAMES):
            raise ValueError(f"a header must name {', '.join(_K_NAMES)} once each; got {head}")
        values = np.loadtxt(rows[1:], dtype=float, ndmin=2)
        if values.shape != (1, 4):
            raise ValueError(f"one line of four numbers under the header; got shape "
                             f"{values.shape}")
        return np.array([values[0, names.index(k)] for k in _K_NAMES])
    return np.loadtxt(rows, dtype=float, ndmin=2)


def _find(folder: Path, stem: str, formats: tuple[str, ...]) -> Path | None:
    """The folder's one ``stem.<ext>`` file, or None; a ValueError naming `folder` when it has
    several (which one was meant?) or one that is not a file (a folder named K.txt was
    skipped in silence, and the job ran without it)."""
    found = [folder / f"{stem}{ext}" for ext in formats if (folder / f"{stem}{ext}").exists()]
    for p in found:
        if not p.is_file():
            raise ValueError(f"`folder`: {p} is not a file")
    if len(found) > 1:
        raise ValueError(f"`folder`: {folder} holds {' and '.join(p.name for p in found)}; "
                         "keep one (or give the files themselves)")
    return found[0] if found else None


def dataset_files(folder, *, with_prior: bool = True, with_confidence: bool = True
                  ) -> list[Path]:
    """The files of `folder` that :func:`read_dataset` reads (its normal map, mask, K and,
    where wanted, prior and confidence): what a job's outputs must not overwrite. Its other
    files, an earlier run's outputs among them, are not inputs. Where a name is ambiguous
    (two ``mask`` files) every candidate counts (read_dataset refuses the folder anyway)."""
    f = Path(folder)
    skip = {"prior_depth": not with_prior, "confidence": not with_confidence}
    return [f / f"{stem}{ext}" for stem, formats in _dataset_formats().items()
            if not skip.get(stem) for ext in formats if (f / f"{stem}{ext}").is_file()]


def _dataset_formats() -> dict[str, tuple[str, ...]]:
    """The files a dataset folder may hold, ``stem -> extensions`` (:func:`read_dataset`)."""
    from .images import PRIOR_FORMATS, PRIOR_POINT_FORMATS

    return {"normal_map": NORMAL_READ_FORMATS, "mask": MASK_FORMATS, "K": (".txt",),
            "prior_depth": PRIOR_FORMATS + PRIOR_POINT_FORMATS, "confidence": PRIOR_FORMATS}


def read_dataset(folder, *, frame: str | None = None, y_down: bool = False,
                 prior_scale: float | None = None, with_prior: bool = True,
                 with_confidence: bool = True) -> dict:
    """Read a folder in the BiNI / DiLiGenT layout.

    The folder holds ``normal_map.png`` (or ``.tif``, ``.tiff``, ``.exr``, ``.npy``), usually
    ``mask.png`` (or ``.tif``, ``.tiff``, ``.npy``) and, for a perspective camera, ``K.txt``.
    Without ``K.txt`` the view is orthographic. Pixels outside the mask may hold anything.
    `frame` and `y_down` are those of :func:`~facetlift.io.read_normals`. A depth prior
    ``prior_depth.*`` and a normal confidence ``confidence.*`` (``.npy``, ``.exr``, ``.tif``,
    ``.png``; the prior also as a points file, ``.csv`` or ``.txt``, returned as a map, or
    as its points with their weights where it has a weight column; docs/fusion.md) are
    picked up like ``K.txt``; `prior_scale` is that of :func:`~facetlift.io.read_prior`
    (required for a 16-bit PNG prior); `with_prior` and `with_confidence` False leave those
    files unread (``None``).

    Returns
    -------
    dict
        ``normals`` (H, W, 3) float64, ``mask`` (H, W) bool (the mask file, else the normal
        map's alpha channel, else None), ``K`` (3, 3) or None, ``prior`` (H, W) depth with
        NaN where unknown, or None, and ``confidence`` (H, W) or None. The command line uses
        the last two (``facetlift integrate FOLDER``); pass them to
        :func:`facetlift.integrate` as ``prior=`` and ``confidence=`` to do the same.

    Raises
    ------
    ValueError
        If the folder or its normal map is missing, or any file is unreadable.
    """
    f = Path(folder)
    if not f.is_dir():
        raise ValueError(f"`folder`: {f} is not a directory")
    formats = _dataset_formats()
    npath = _find(f, "normal_map", formats["normal_map"])
    if npath is None:
        from ..jobs import OUTPUT_STEMS

        # (the folder's other files, and facetlift's outputs)
        other = {"mask", "prior_depth", "confidence"} | OUTPUT_STEMS
        maps = sorted(p.name for p in f.iterdir()
                      if p.is_file() and p.suffix.lower() in NORMAL_READ_FORMATS
                      and p.stem.lower() not in other and not p.stem.endswith("_mask"))
        raise ValueError(
            f"`folder`: {f} has no normal_map file (looked for normal_map with extension "
            f"{', '.join(NORMAL_READ_FORMATS)})"
            + (f"; it holds other maps ({', '.join(maps[:3])}{', ...' if len(maps) > 3 else ''})"
               ": integrate one by its path, or all of them with `facetlift batch "
               f"{f} -o OUT`" if maps else "")
        )
    mpath = _find(f, "mask", formats["mask"])
    # (the folder's mask replaces the map's alpha: no word on the alpha then)
    normals, alpha = read_normals(npath, frame=frame, y_down=y_down,
                                  check_alpha=mpath is None)
    mask = read_mask(mpath, normals.shape[:2]) if mpath is not None else alpha
    kpath = _find(f, "K", formats["K"])
    K = read_K(kpath) if kpath is not None else None
    from ..problem import prior_image, prior_samples
    from .images import read_prior, read_weights

    H, W = normals.shape[:2]
    extra = {}  # the folder's own prior and confidence: a file at fault can be left unread
    for name, stem, wanted, reader in (
            ("prior", "prior_depth", with_prior,
             lambda p: read_prior(p, prior_scale, arg="prior")),
            ("confidence", "confidence", with_confidence,
             lambda p: read_weights(p, arg="confidence"))):
        path = _find(f, stem, formats[stem]) if wanted else None
        extra[name] = None
        if path is None:
            continue
        skip = f"or leave the folder's {name} unread with --no-{name} (with_{name}=False in Python)"
        try:
            extra[name] = reader(path)
            if isinstance(extra[name], tuple) and len(extra[name]) == 3:
                # (a points file: as a map of this size; with the folder's K, points behind
                # the camera are left out here, as integrate leaves them out of a points file
                # given with --prior. With a weight column they stay points, whose weights
                # integrate applies)
                extra[name] = prior_image(extra[name], (H, W), positive=K is not None)
            elif isinstance(extra[name], tuple):  # (checked here too: its errors get the
                # folder's hint; its warnings come when integrate places the points)
                with recording(record=False, action="ignore"):
                    prior_samples(extra[name], (H, W))
        except ValueError as e:
            raise ValueError(f"{e}; {skip}") from None
        if not isinstance(extra[name], tuple) and extra[name].shape != (H, W):
            from ..problem import coarse_prior_hint

            # (a sensor's coarser depth as the folder's prior_depth.* got no remedy, which
            # --prior gives it: a review)
            hint = coarse_prior_hint(extra[name].shape, (H, W)) if name == "prior" else ""
            raise ValueError(f"`{name}`: {path} is {extra[name].shape[0]}x"
                             f"{extra[name].shape[1]} (HxW) but the normal map is {H}x{W}"
                             f"{hint}; {skip}")
    return {"normals": normals, "mask": mask, "K": K, **extra}
