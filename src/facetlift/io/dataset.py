"""Perspective intrinsics (``K.txt``) and BiNI / DiLiGenT dataset folders."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._warnings import recording
from . import _kfiles
from ._kfiles import _KError
from ._paths import _existing
from .images import (
    MASK_FORMATS,
    NORMAL_READ_FORMATS,
    _loadtxt_reason,
    _text_rows,
    check_mask_size,
    read_mask,
    read_normals,
)


def read_K(path, shape=None) -> np.ndarray:
    """Read 3x3 perspective intrinsics (OpenCV layout) from a file; with `shape` (the normal
    map's (H, W), or its (H, W, 3)), refused where the file states another image size, as
    the command line's ``--K`` is (:func:`facetlift.io.dataset.read_K_stated`, which
    returns the stated size too; :func:`facetlift.camera.check_image_size`: the message gives
    K scaled for a resize).
    Without it a stated size goes unchecked (a K of the 1.5x larger image bent a surface 9x
    more than the right one in Python, while ``--K`` refused it: a perspective audit).

    A text file holds the matrix as three rows (``np.loadtxt``; numbers separated by spaces,
    tabs or commas), or its nine numbers on one line (row by row), or the four numbers
    ``fx fy cx cy`` (cx a column, cy a row from the top), the four possibly under a header
    naming them in any order (``cx cy fx fy``); or JSON: a 3x3 list, nine or four numbers, or
    an object with ``fx``, ``fy``, ``cx``, ``cy``, or with the matrix (3x3 or nine numbers)
    under ``K``, ``intrinsics``, ``camera_matrix`` or ``intrinsic_matrix``
    (:data:`JSON_K_KEYS`), either of them also in one object inside it (``{"camera": {"fx":
    ...}}``). A ``.npy`` file holds a (3, 3) array, nine or four numbers likewise. A 4x4
    matrix (ScanNet's ``intrinsic_color.txt``, text or ``.npy``) gives its top-left 3x3 where
    its last row and column are the identity's, 0 0 0 1. A MATLAB ``.mat`` file (v4 to v7)
    holds it as the variable ``KK`` (the calibration toolbox's ``Calib_Results.mat``,
    DiLiGenT's, whose ``nx`` / ``ny`` state its image's size:
    :func:`facetlift.io.dataset.read_K_stated`; its lens distortion ``kc`` is warned about
    where a coefficient exceeds :data:`MAT_DISTORTION_TOLERANCE`), ``K``, or its only 3x3
    numeric variable.

    Calibration tools' own files are read too (:mod:`facetlift.io._kfiles`):

    - OpenCV FileStorage YAML (``%YAML:1.0``; ``.yml`` / ``.yaml``) or XML (``.xml``): the
      ``opencv-matrix`` node of 3 rows and 3 cols named ``camera_matrix``, ``cameraMatrix``,
      ``K``, ``intrinsic(s)`` or ``M1`` (case aside), or the only 3x3 one; a stereo file's
      two cameras (``M1`` / ``M2``) are refused, naming them; distortion coefficients other
      than zero (``distortion_coefficients``, ``dist_coeffs``, ``D``) are warned about;
    - ROS ``camera_info`` YAML (``camera_matrix``) or a CameraInfo dump (``k:`` / ``K:``,
      nine numbers): the matrix for the raw image; where its ``projection_matrix`` (``P``)
      differs, a warning gives P's left 3x3, the rectified image's camera; distortion
      (``distortion_coefficients``, ``d`` / ``D``) other than zero is warned about;
    - COLMAP's ``cameras.txt`` (found by its lines ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS``)
      or ``cameras.bin`` (any ``.bin``: the binary model COLMAP's mapper writes):
      its camera (several only where all are the same), a pinhole model (SIMPLE_PINHOLE,
      PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV; distortion other than zero is
      warned about, fish-eye and FOV models refused), **cx and cy minus 0.5**: COLMAP puts
      the upper-left pixel's centre at (0.5, 0.5), facetlift at (0, 0);
    - a nerfstudio / instant-ngp ``transforms.json`` (``fl_x``, ``fl_y``, ``cx``, ``cy``;
      ``fl_y`` defaults to ``fl_x``), whose principal point is COLMAP's: minus 0.5 too
      (``camera_angle_x`` alone is refused: it needs the width, as ``--fov``).

    Raises
    ------
    ValueError
        Missing or unparsable file, another count of numbers, or a matrix that is not valid
        intrinsics (see :mod:`facetlift.conventions`; a transposed matrix is named so, with
        MATLAB's 1-based principal point); with `shape`, a stated image size that differs.
    """
    K, stated = read_K_stated(path)
    if shape is not None:
        from ..camera import check_image_size

        check_image_size(K, stated, tuple(int(v) for v in tuple(shape)[:2]), str(path))
    return K


def read_K_stated(path) -> tuple[np.ndarray, tuple[int, int] | None]:
    """:func:`read_K`'s K, and the image size (H, W) its calibration file states for the
    camera, or None where it states none (a text K file, ``.npy``, a ``.mat`` file without
    them): OpenCV's and ROS's ``image_width`` / ``image_height``, a CameraInfo dump's
    ``width`` / ``height``, COLMAP's WIDTH and HEIGHT, a transforms.json's ``w`` / ``h``, the
    calibration toolbox's ``nx`` / ``ny`` (a ``Calib_Results.mat``). Where K meets a normal
    map, :func:`facetlift.camera.check_image_size` compares the two."""
    from ..camera import check_K

    arg = "K"
    p = _existing(path, arg)
    size = None
    try:
        if p.suffix.lower() == ".mat":  # (it was read as text: "'utf-8' codec can't decode")
            K, size = _K_mat(p)
        elif p.suffix.lower() == ".npy":
            K = np.load(p, allow_pickle=False)
        elif p.suffix.lower() == ".xml":  # (OpenCV FileStorage's)
            K, size = _kfiles.K_xml(p)
        elif p.suffix.lower() == ".bin":  # (COLMAP's sparse model: cameras.bin)
            K, size = _kfiles.K_colmap_bin(p)
        else:
            K, size = _K_text(p)
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
    elif K.shape == (2, 2):  # (a 2x2 matrix: not fx fy cx cy,
        # which a user saw as a 3x3 matrix they never wrote, a fresh user's check)
        raise ValueError(f"`{arg}`: {p} holds a 2x2 matrix; expected a "
                         "3x3 matrix (three rows, or nine numbers), or the four numbers "
                         "fx fy cx cy (in one row or one column)") from None
    elif K.shape == (4, 4):  # (ScanNet's intrinsic_color.txt: K padded to 4x4)
        K = _K_of_4x4(K, p, arg)
    elif K.size == 4:  # fx fy cx cy
        fx, fy, cx, cy = K.ravel()
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    elif K.shape != (3, 3):
        raise ValueError(f"`{arg}`: {p} holds {K.size} number(s) in shape {K.shape}; expected "
                         "a 3x3 matrix (three rows, or nine numbers), or the four numbers "
                         "fx fy cx cy") from None
    try:
        return check_K(K), size
    except ValueError as e:  # (check_K names a transposed K)
        raise ValueError(f"`{arg}`: {p}: {e}") from None


def _K_of_4x4(K4: np.ndarray, p, arg: str = "K") -> np.ndarray:
    """The intrinsics of a 4x4 matrix (ScanNet's ``intrinsic_color.txt``): its top-left 3x3,
    where the rest is the identity's (last row and column 0 0 0 1); a ValueError naming `p`
    otherwise (a 4x4 pose, say, is no K)."""
    rest = np.concatenate([K4[:3, 3], K4[3, :]])
    if not np.allclose(rest, [0, 0, 0, 0, 0, 0, 1]):
        raise ValueError(f"`{arg}`: {p} holds a 4x4 matrix whose last row and column are not "
                         f"0 0 0 1 (row {K4[3].tolist()}, column {K4[:3, 3].tolist()}): a 4x4 "
                         "intrinsics file (ScanNet's) holds K in its top-left 3x3 and the "
                         "identity's 0 0 0 1 around it; a pose or a projection matrix is no K")
    return K4[:3, :3]


class InlineK(str):
    """A K typed inline (:func:`inline_value`): the text as typed, which a job keeps, names
    and records, with its numbers parsed once: ``K`` the checked (3, 3) intrinsics, or
    ``error`` the message of the ValueError they give (raised by :func:`inline_K`, where the
    job reads its camera, as a file's errors are)."""

    K: np.ndarray | None = None
    error: str | None = None


def inline_value(value) -> InlineK | None:
    """`value` as an :class:`InlineK` where it is intrinsics typed inline in a K file's place
    (``--K "3772 3759 305.9 255.1"``): a string that is no existing path and holds four
    numbers ``fx fy cx cy`` or the nine of the 3x3 matrix row by row, separated by spaces or
    commas (brackets aside: a pasted ``K.tolist()``), parsed and checked once, as
    :func:`read_K` checks a file's (an :class:`InlineK` is returned as it is); None for
    anything else (a file's path, to be read as one). The command line's ``--K`` keeps it,
    so that the job does not parse the text again."""
    import re

    from ..camera import check_K

    if isinstance(value, InlineK):
        return value
    if not isinstance(value, str) or os.path.exists(value):
        return None
    # (brackets too: a pasted K.tolist(), "[[600, 0, 60], [0, 450, 200], [0, 0, 1]]", was a
    # missing file, a perspective audit)
    words = [w for w in re.split(r"[\s,;\[\]()]+", value.strip()) if w]
    try:
        numbers = np.array([float(w) for w in words])
    except ValueError:
        return None
    out = InlineK(value)
    if len(words) not in (4, 9):  # (numbers all, but a count no K has: "file '943 939 76'
        # does not exist" said nothing of it, an audit)
        if len(words) < 2:
            return None
        out.error = (f"`K`: {value!r} (typed inline) holds {len(words)} numbers; give four, "
                     "fx fy cx cy, or the nine of the 3x3 matrix row by row, or a K file")
        return out
    try:
        out.K = check_K(numbers if numbers.size == 4 else numbers.reshape(3, 3))
    except ValueError as e:
        out.error = f"`K`: {value!r} (typed inline): {e}"
    return out


def inline_K(value) -> np.ndarray | None:
    """The intrinsics typed inline as a K file's place (:func:`inline_value`), checked as
    :func:`read_K` checks a file's; None for anything else (a file's path, to be read as
    one).

    Raises
    ------
    ValueError
        Four or nine numbers that are no valid intrinsics (naming `K` and the text).
    """
    inline = inline_value(value)
    if inline is not None and inline.error is not None:
        raise ValueError(inline.error)
    return None if inline is None else inline.K.copy()  # (one text, many jobs: their own)


def K_value(value) -> str | None:
    """A job's `K` (:class:`facetlift.jobs.Job`) from a ``--K`` value: a file's path as text,
    an :class:`InlineK` as it is (its numbers parsed once), None for None."""
    return None if value is None else value if isinstance(value, InlineK) else str(value)


def camera_of(value, shape, of: str = "the normal map") -> np.ndarray:
    """The camera of a ``--K`` value (a job's `K`) for an image of size `shape` (H, W, `of`
    what it is): its intrinsics typed inline (:func:`inline_K`; no stated size), else its
    file's (:func:`read_K_stated`), refused where the file states another image size
    (:func:`facetlift.camera.check_image_size`)."""
    from ..camera import check_image_size

    K = inline_K(value)
    if K is not None:
        return K
    K, stated = read_K_stated(value)
    check_image_size(K, stated, shape, str(value), of=of)
    return K


#: The names a ``.mat`` file's intrinsics go by, in order: the calibration toolbox's
#: ``Calib_Results.mat`` (Bouguet's; DiLiGenT's) holds ``KK``.
MAT_K_NAMES = ("KK", "K")

#: The variables (width, height) in which the calibration toolbox's ``Calib_Results.mat``
#: states the calibrated image's size (``[ny, nx] = size(I)``, beside ``fc``, ``cc``,
#: ``alpha_c``, ``kc``).
MAT_SIZE_NAMES = ("nx", "ny")

#: The calibration toolbox's lens distortion ``kc`` (a ``Calib_Results.mat``'s): its five
#: coefficients, in OpenCV's order (radial k1, k2, tangential p1, p2, radial k3), and the size
#: above which one is warned about (:func:`_K_mat`: K is a pinhole's, the distortion left out).
MAT_DISTORTION = ("k1", "k2", "p1", "p2", "k3")
MAT_DISTORTION_TOLERANCE = 1e-6


def _K_mat(p: Path) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of a ``.mat`` file (:func:`read_K`): its variable of
    :data:`MAT_K_NAMES`, or its only 3x3 numeric one; a :class:`_KError` lists the variables
    otherwise (a calibration's file also holds each view's 3x3 rotation, Rc_1, ...). And the
    image size (H, W) it states in :data:`MAT_SIZE_NAMES` (two positive whole numbers), or
    None (:func:`read_K_stated`). Its lens distortion ``kc``, where a coefficient exceeds
    :data:`MAT_DISTORTION_TOLERANCE`, is warned about as other calibration files' is."""
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
    # (the toolbox's 1x1 matrices as numbers; anything else is no size, as a ROS dump's 0 x 0)
    sizes = {k: np.asarray(data[k]).item() if np.size(data[k]) == 1 else None
             for k in MAT_SIZE_NAMES if k in data}
    _mat_distortion(p, data.get("kc"))
    return square[name].astype(float), _kfiles._stated_size(sizes, MAT_SIZE_NAMES)


def _mat_distortion(p: Path, kc) -> None:
    """Warn where a ``Calib_Results.mat``'s `kc` (the toolbox's distortion, 5 x 1) holds a
    coefficient beyond :data:`MAT_DISTORTION_TOLERANCE`: facetlift's camera is a pinhole, and
    the normals must be of an undistorted image (a kc that is no vector of numbers says
    nothing)."""
    try:
        kc = np.asarray(kc, dtype=float).ravel()
    except (TypeError, ValueError):
        return
    if kc.size == 0 or not (np.abs(kc) > MAT_DISTORTION_TOLERANCE).any():
        return  # (also a NaN kc: no coefficient known)
    named = {(MAT_DISTORTION[i] if i < len(MAT_DISTORTION) else f"kc({i + 1})"): float(v)
             for i, v in enumerate(kc) if abs(v) > MAT_DISTORTION_TOLERANCE}
    listed = ", ".join(f"{v:g}" for v in kc)
    _kfiles._distortion(
        str(p), named,
        f"its kc = [{listed}] (the calibration toolbox's k1, k2, p1, p2, k3, in OpenCV's "
        "order) is not modelled, facetlift's camera being an ideal pinhole: undistort the "
        "images first (the toolbox's 'Undistort image', or cv2.undistort(image, KK, kc)) and "
        "compute the normal map from the undistorted ones")


#: The names a K file's header or JSON object may give its four numbers.
_K_NAMES = ("fx", "fy", "cx", "cy")


#: The keys under which a JSON K file's object may hold the matrix (3x3 nested, or its nine
#: numbers row by row), the case of their letters aside.
JSON_K_KEYS = ("K", "intrinsics", "camera_matrix", "intrinsic_matrix")


def _json_K(data: dict):
    """The numbers of a JSON K file's object (:func:`_K_text`): ``fx``, ``fy``, ``cx``,
    ``cy``; or the matrix under one of :data:`JSON_K_KEYS`; or either of these in one object
    nested in it (``{"camera": {"fx": ...}}``). A ValueError says what it looks for where it
    finds none, or several."""
    def matrix(key: str, v):
        """The value under a matrix key: a nested fx ... cy object, OpenCV FileStorage's
        JSON matrix ({"type_id": "opencv-matrix", "rows", "cols", "data"}), or Open3D's
        column-major ``intrinsic_matrix`` (its nine numbers [fx, 0, 0, 0, fy, 0, cx, cy, 1]:
        refused as transposed, with MATLAB's advice, the diff review)."""
        if isinstance(v, dict):
            inner = {str(k).lower(): x for k, x in v.items()}
            if all(k in inner for k in _K_NAMES):
                return [inner[k] for k in _K_NAMES]
            if "data" in inner:
                return inner["data"]
            return v
        flat = np.asarray(v, dtype=object).ravel() if isinstance(v, list) else None
        if (key == "intrinsic_matrix" and flat is not None and flat.size == 9
                and all(isinstance(x, (int, float)) for x in flat)):
            a = np.asarray(flat, float)
            if (a[[1, 2, 3, 5]] == 0).all() and a[8] == 1 and (a[[6, 7]] != 0).any():
                return a.reshape(3, 3).T.ravel().tolist()  # (column-major: Open3D's)
        return v

    def own(obj: dict):
        low = {str(k).lower(): v for k, v in obj.items()}
        found = [k for k in JSON_K_KEYS if k.lower() in low]
        if len(found) > 1:
            raise ValueError(f"a JSON object holding both {' and '.join(found)}: which is K?")
        named = all(k in low for k in _K_NAMES)
        if named and found:  # (two answers: the same one, or refused, the diff review)
            from ..camera import check_K

            try:
                same = np.allclose(check_K(matrix(found[0].lower(), low[found[0].lower()])),
                                   check_K([low[k] for k in _K_NAMES]))
            except (TypeError, ValueError):
                same = False
            if not same:
                raise ValueError(f"a JSON object holding both {found[0]} and fx, fy, cx, cy, "
                                 "which differ: which is K?")
        if named:
            return [low[k] for k in _K_NAMES]
        return matrix(found[0].lower(), low[found[0].lower()]) if found else None

    top = own(data)
    if top is not None:
        return top
    nested = {str(k): v for k, v in data.items() if isinstance(v, dict)}
    inner = {k: got for k, v in nested.items() if (got := own(v)) is not None}
    if len(inner) == 1:
        return next(iter(inner.values()))
    if len(inner) > 1:
        raise ValueError(f"a JSON object with several cameras ({', '.join(inner)}): which is "
                         "the image's? Save that one as a K file of its own")
    low = {str(k).lower() for k in data}
    missing = [k for k in _K_NAMES if k not in low]
    raise ValueError(f"a JSON object needs {', '.join(_K_NAMES)}; {missing} missing (or the "
                     f"matrix under {', '.join(JSON_K_KEYS)}, 3x3 or nine numbers row by row, "
                     "at its top or in one object inside it)")


def _K_text(p: Path):
    """The numbers of a text K file (:func:`read_K`): JSON (a nerfstudio transforms.json
    too), YAML (OpenCV's, ROS's), COLMAP's cameras.txt, a header of names over the four
    numbers (a user's 'fx fy cx cy' first line was refused), or plain rows; and the image
    size (H, W) the file states, or None (:func:`read_K_stated`)."""
    import json

    text = p.read_text(encoding="utf-8-sig").strip()
    if not text:  # ("" in "[{" is True: an empty file was read as JSON, an audit)
        raise ValueError("the file is empty: it must hold K's nine numbers (three rows), or "
                         "fx fy cx cy")
    if text[:1] in "[{":
        data = json.loads(text)
        if isinstance(data, dict) and _kfiles.is_transforms(data):
            return _kfiles.K_transforms(data, p)
        if isinstance(data, dict):
            data = _json_K(data)
        return np.asarray(data, dtype=float), None
    if _kfiles.is_yaml(p, text):
        return _kfiles.K_yaml(p, text)
    rows = _text_rows(p)
    cameras = _kfiles.colmap_lines(rows)
    if cameras:
        return _kfiles.K_colmap(p, cameras)
    head = rows[0].split() if rows else []
    if head and all(w.strip("\"'").lower() in _K_NAMES for w in head):
        names = [w.strip("\"'").lower() for w in head]
        if sorted(names) != sorted(_K_NAMES):
            raise ValueError(f"a header must name {', '.join(_K_NAMES)} once each; got {head}")
        values = np.loadtxt(rows[1:], dtype=float, ndmin=2)
        if values.shape != (1, 4):
            raise ValueError(f"one line of four numbers under the header; got shape "
                             f"{values.shape}")
        return np.array([values[0, names.index(k)] for k in _K_NAMES]), None
    return np.loadtxt(rows, dtype=float, ndmin=2), None


#: The flags (fields) that give a rotation file, and which way it turns: ``world_to_camera``
#: holds the rotation from world to the camera frame; ``camera_to_world`` the camera's pose
#: (Blender's ``matrix_world``), transposed when read (:func:`read_rotation`).
ROTATION_FIELDS = ("world_to_camera", "camera_to_world")

#: The extensions of a dataset folder's rotation file, ``world_to_camera.*`` or
#: ``camera_to_world.*`` (:func:`read_dataset`).
ROTATION_FORMATS = (".txt", ".json", ".npy")


def is_rotation_file(path) -> bool:
    """Whether `path` is named as a rotation file (``world_to_camera.*`` or
    ``camera_to_world.*`` of :data:`ROTATION_FORMATS`): a camera's, as ``K.txt`` is, and no
    normal map even where it is a ``.npy`` beside maps (:func:`facetlift.batch.items`)."""
    p = Path(path)
    return p.stem in ROTATION_FIELDS and p.suffix.lower() in ROTATION_FORMATS


#: The keys of a JSON object's matrix that say which way it turns (:func:`read_rotation`):
#: a camera-to-world key in a file given as world-to-camera, or the reverse, is refused.
#: ``transform_matrix`` is a NeRF ``transforms.json`` frame's pose (camera to world).
_C2W_KEYS = ("camera_to_world", "matrix_world", "c2w", "cam2world", "transform_matrix")
_W2C_KEYS = ("world_to_camera", "w2c", "world2cam")
#: ... and the keys that say nothing of the direction but name a rotation.
_ROTATION_KEYS = ("r", "rotation")

#: The shapes a rotation file may hold: a rotation, or a pose whose upper-left 3x3 is one.
_POSE_SHAPES = {9: (3, 3), 12: (3, 4), 16: (4, 4)}


def read_rotation(path, *, camera_to_world: bool = False, arg: str | None = None
                  ) -> np.ndarray:
    """Read a camera's rotation for normals given in world space
    (:func:`facetlift.integrate`'s ``normal_rotation``), as the rotation from world to the
    camera frame.

    The file holds a 3x3 rotation, or a 3x4 or 4x4 pose of which the upper-left 3x3 is used:
    as text (three or four rows; numbers separated by spaces, tabs or commas, ``#``
    comments; or the 9, 12 or 16 numbers on one line, row by row), as a ``.npy`` array, or as
    JSON: a nested list, or an object with one matrix-valued key (``matrix_world``, ``R``,
    ``rotation``, ``world_to_camera``, ``camera_to_world``, ...; where it has several, the one
    that names a rotation, else an error naming them).

    Parameters
    ----------
    path : str or Path
    camera_to_world : bool
        The file holds the camera's pose, camera to world (Blender's ``matrix_world``, a NeRF
        ``transform_matrix``): its rotation is transposed. A JSON key that says the other way
        (``matrix_world`` read as world to camera, ``world_to_camera`` read as camera to
        world) is refused.
    arg : str, optional
        The argument named in the errors (default ``camera_to_world`` or
        ``world_to_camera``: the command line names the flag).

    Raises
    ------
    ValueError
        A missing or unparsable file, another count of numbers, or a matrix that is no rotation
        (:func:`facetlift.frames.check_rotation`), naming `arg` and the file.
    """
    from ..frames import check_rotation

    arg = arg or ROTATION_FIELDS[int(bool(camera_to_world))]
    p = _existing(path, arg)
    what = ("a 3x3 rotation or a 3x4 / 4x4 pose (three or four rows of numbers, or 9, 12 or 16 "
            "numbers), a .npy array of one, or JSON (a nested list, or an object with one "
            "matrix such as \"R\" or \"matrix_world\")")
    try:
        if p.suffix.lower() == ".npy":
            m = np.load(p, allow_pickle=False)
        else:
            m = _rotation_text(p, arg, camera_to_world)
        m = np.asarray(m, dtype=float)
    except _KError as e:  # (the file's own message: its keys)
        raise ValueError(str(e)) from None
    except Exception as e:
        reason = _loadtxt_reason(e) if p.suffix.lower() != ".npy" else "not a .npy file of numbers"
        raise ValueError(f"`{arg}`: cannot read {p} as a matrix ({reason}): give {what}"
                         ) from None
    if m.ndim <= 2 and m.size in _POSE_SHAPES and m.shape != _POSE_SHAPES[m.size] and (
            m.ndim == 1 or 1 in m.shape):
        m = m.reshape(_POSE_SHAPES[m.size])  # (the numbers on one line, row by row)
    try:
        R = check_rotation(m, arg)
    except ValueError as e:  # (the file named after the flag: which of several it was)
        text = str(e)
        head = f"`{arg}`"
        raise ValueError(f"{head} {p}{text[len(head):]}" if text.startswith(head)
                         else f"{head}: {p}: {text}") from None
    return R.T.copy() if camera_to_world else R


def _rotation_text(p: Path, arg: str, camera_to_world: bool):
    """The numbers of a text or JSON rotation file (:func:`read_rotation`)."""
    import json

    text = p.read_text(encoding="utf-8-sig").strip()
    if not text:
        raise ValueError("the file is empty")
    if p.suffix.lower() == ".json" or text[0] in "[{":
        data = json.loads(text)
        return _json_matrix(data, p, arg, camera_to_world) if isinstance(data, dict) else data
    rows = _text_rows(p)
    if not rows:
        raise ValueError("no numbers in it, only comments")
    return np.loadtxt(rows, dtype=float, ndmin=2)


def _json_matrix(data: dict, p: Path, arg: str, camera_to_world: bool):
    """The matrix of a JSON object (:func:`read_rotation`): its one matrix-valued key, or of
    several the one that names a rotation; a key that names the other direction than `arg`'s
    is refused (a :class:`_KError`, given as it is)."""
    def matrix(v):
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            return False
        return a.shape in _POSE_SHAPES.values() or (a.ndim == 1 and a.size in _POSE_SHAPES)

    found = [k for k, v in data.items() if matrix(v)]
    named = [k for k in found if str(k).lower() in _C2W_KEYS + _W2C_KEYS + _ROTATION_KEYS]
    if len(found) == 1:
        key = found[0]
    elif len(named) == 1:
        key = named[0]
    else:
        listed = ", ".join(f'"{k}"' for k in (found or list(data))) or "none"
        raise _KError(
            f"`{arg}`: {p} must hold one matrix (a key such as \"R\", \"rotation\", "
            "\"world_to_camera\", \"camera_to_world\" or \"matrix_world\"); "
            + (f"it holds several, {listed}: which one is the camera's rotation? Keep that one"
               if found else f"it holds no 3x3, 3x4 or 4x4 matrix (keys: {listed})"))
    low = str(key).lower()
    other = _W2C_KEYS if camera_to_world else _C2W_KEYS
    if low in other:
        flag = "--world-to-camera" if camera_to_world else "--camera-to-world"
        raise _KError(
            f"`{arg}`: {p} holds \"{key}\", which turns "
            + ("world to camera" if camera_to_world else "camera to world")
            + f", but was given as the other direction: give it with {flag} "
            f"(facetlift.io.read_rotation(path, camera_to_world={not camera_to_world}))")
    return data[key]


def _named(folder: Path, name: str, names: list[str] | None = None) -> Path | None:
    """`folder`'s entry named `name`, the case of its letters aside (a Windows user's
    ``K.TXT``, ``mask.PNG`` or ``Normal_Map.png`` was skipped in silence: the job ran
    orthographic, without its mask, an audit); the exact name first; None where there is
    none or the folder cannot be listed. `names`: the folder's listing where the caller has
    it (one listing for many names). A ValueError naming `folder` where two entries differ
    only in case and neither is the exact name."""
    exact = folder / name
    if name in names if names is not None else os.path.lexists(exact):
        return exact
    if names is None:
        try:
            names = os.listdir(folder)
        except OSError:
            return None
    low = name.lower()
    hits = [n for n in names if n.lower() == low]
    if len(hits) > 1:
        raise ValueError(f"`folder`: {folder} holds {' and '.join(sorted(hits))}, names that "
                         "differ only in case: keep one")
    return folder / hits[0] if hits else None


def _find(folder: Path, stem: str, formats: tuple[str, ...]) -> Path | None:
    """The folder's one ``stem.<ext>`` file (the case of its letters aside, :func:`_named`),
    or None; a ValueError naming `folder` when it has several (which one was meant?) or one
    that is not a file (a folder named K.txt was skipped in silence, and the job ran without
    it)."""
    try:  # (listed once for every extension)
        names = os.listdir(folder)
    except OSError:  # (not listable: the exact names alone)
        names = None
    found = list(dict.fromkeys(p for ext in formats
                               if (p := _named(folder, f"{stem}{ext}", names)) is not None))
    for p in found:
        if not p.is_file():
            raise ValueError(f"`folder`: {p} is not a file")
    if len(found) > 1:
        raise ValueError(f"`folder`: {folder} holds {' and '.join(p.name for p in found)}; "
                         "keep one (or give the files themselves)")
    return found[0] if found else None


def dataset_files(folder, *, with_prior: bool = True, with_confidence: bool = True
                  ) -> list[Path]:
    """The files of `folder` that :func:`read_dataset` reads (its normal map, mask, K, rotation
    file and, where wanted, prior and confidence; a DiLiGenT folder's ``Normal_gt.mat`` and its
    parent's camera file too): what a job's outputs must not overwrite, and what a batch's
    ``--resume`` looks at. Its other files, an earlier run's outputs among them, are not
    inputs. Where a name is ambiguous (two ``mask`` files) every candidate counts
    (read_dataset refuses the folder anyway)."""
    f = Path(folder)
    skip = {"prior_depth": not with_prior, "confidence": not with_confidence}
    own = list(dict.fromkeys(p for stem, formats in _dataset_formats().items()
                             if not skip.get(stem) for ext in formats
                             if (p := _named(f, f"{stem}{ext}")) is not None and p.is_file()))
    return own + [p for p in camera_files(f) if p.parent != f]


def _dataset_formats() -> dict[str, tuple[str, ...]]:
    """The files a dataset folder may hold, ``stem -> extensions`` (:func:`read_dataset`)."""
    from .images import PRIOR_FORMATS, PRIOR_POINT_FORMATS

    return {"normal_map": NORMAL_READ_FORMATS, "Normal_gt": (".mat",), "mask": MASK_FORMATS,
            "K": (".txt",), "Calib_Results": (".mat",),
            **{name: ROTATION_FORMATS for name in ROTATION_FIELDS},
            "prior_depth": PRIOR_FORMATS + PRIOR_POINT_FORMATS, "confidence": PRIOR_FORMATS}


#: The DiLiGenT release's ground-truth normals: ``<obj>PNG/Normal_gt.mat``, variable
#: ``Normal_gt``, (H, W, 3) in facetlift's frame (x right, y up, z toward the camera; BiNI's
#: ``normal_map.png`` files of DiLiGenT objects were made from them and verify so against
#: the depth, ../shared/data/SOURCES.md), (0, 0, 0) outside the object. A folder holding it
#: is in the DiLiGenT layout.
DILIGENT_NORMALS = "Normal_gt.mat"
#: The camera files of a dataset folder, in the order looked for: BiNI's ``K.txt`` and the
#: calibration toolbox's ``Calib_Results.mat`` (DiLiGenT's, variable ``KK``; :func:`read_K`).
CAMERA_FILES = ("K.txt", "Calib_Results.mat")


#: Camera files other tools write (COLMAP, OpenCV, ROS, nerfstudio, ScanNet, a user's own),
#: which :func:`read_dataset` does not read by itself beside a normal map, but which
#: :func:`read_K` (``--K FILE``) reads: :func:`unread_camera_files` finds them, so that a job
#: without a camera can name them (a folder holding cameras.txt ran orthographically with no
#: word, a review). Not read automatically: which of them, and whether the map is the
#: calibrated image's, is the user's to say.
OTHER_CAMERA_FILES = (
    "cameras.txt", "cameras.bin",  # COLMAP's sparse model
    "calib.yml", "calib.yaml", "calib.xml",  # OpenCV FileStorage
    "camera_info.yaml", "camera_info.yml",  # ROS
    "transforms.json",  # nerfstudio, instant-ngp
    "K.json", "K.npy", "K.yml", "K.yaml", "K.xml",  # K.txt in another format
    "intrinsics.txt", "intrinsics.json", "intrinsics.npy",
    "intrinsic_color.txt",  # ScanNet's (4x4)
)


def unread_camera_advice(found, every: bool = False) -> str:
    """The words on other tools' camera files `found` (paths) that no K was read from: not
    read by themselves, so the map (`every`: every map of a folder) is integrated
    orthographically, and what to give instead."""
    one = len(found) == 1
    maps = "these maps are" if every else "the map is"
    return (f"{'a camera file that is' if one else 'camera files that are'} not read by "
            f"{'itself' if one else 'themselves'} (only a dataset folder's K.txt or "
            f"Calib_Results.mat is), so without a camera {maps} integrated orthographically; "
            f"give --K {found[0]} (K=facetlift.io.read_K(path) in Python) to use "
            f"{'it' if one else 'one of them'}{' for every map' if every else ''}, or "
            "--orthographic if orthographic is meant")


def unread_camera_files(folder) -> list[Path]:
    """The files of `folder` named in :data:`OTHER_CAMERA_FILES` (the case of their letters
    aside), which no reading takes by itself: without --K their camera goes unused. An empty
    list where it holds none, or cannot be listed."""
    f = Path(folder)
    try:  # (listed once for every name)
        names = os.listdir(f)
    except OSError:
        return []
    found = []
    for name in OTHER_CAMERA_FILES:
        try:
            p = _named(f, name, names)
        except ValueError:  # (two names that differ only in case: both are named)
            found += [f / n for n in names if n.lower() == name.lower()]
            continue
        if p is not None and p.is_file():
            found.append(p)
    return found


def normals_file(folder) -> Path | None:
    """The normal map :func:`read_dataset` reads from `folder`: its ``normal_map.*``, else its
    ``Normal_gt.mat`` (:data:`DILIGENT_NORMALS`), else None. A ValueError naming `folder`
    where it holds several ``normal_map.*``."""
    f = Path(folder)
    found = _find(f, "normal_map", NORMAL_READ_FORMATS)
    gt = _named(f, DILIGENT_NORMALS) if found is None else None
    return gt if gt is not None and gt.is_file() else found


def is_dataset(folder) -> bool:
    """Whether `folder` is a dataset folder (:func:`read_dataset`): it holds a
    ``normal_map.*`` or a ``Normal_gt.mat``. False where it cannot be read."""
    f = Path(folder)
    try:  # (one listing, the case of the names aside: _named)
        listing = os.listdir(f)
    except OSError:
        return False
    names = {n.lower() for n in listing}
    wanted = [f"normal_map{ext}".lower() for ext in NORMAL_READ_FORMATS]
    try:  # (os.path.isfile: False for a folder that cannot be read, where Path.is_file raises)
        return any(w in names and os.path.isfile(_named(f, w, listing)) for w in wanted) or (
            DILIGENT_NORMALS.lower() in names
            and os.path.isfile(_named(f, DILIGENT_NORMALS, listing)))
    except ValueError:  # (two names that differ only in case: a dataset, whose reading says
        return True  # which, a review)


def camera_files(folder) -> list[Path]:
    """The camera files :func:`read_dataset` reads for `folder` (:data:`CAMERA_FILES`): the
    folder's own (both where it has both, which must agree), else, in the DiLiGenT layout
    only (a ``Normal_gt.mat`` or a ``light_directions.txt`` in the folder), its parent's: the
    release keeps one
    ``Calib_Results.mat`` beside its object folders. Not a BiNI folder's parent: a BiNI
    folder without ``K.txt`` is orthographic, and a camera file above it must not make it
    perspective without a word. An empty list: orthographic."""
    f = Path(folder)
    # (the parent too in a photometric-stereo folder of the release, light_directions.txt, whose
    # estimated normal_map.png the user saved there as told: it ran orthographic, an audit)
    release = any((p := _named(f, name)) is not None and p.is_file()
                  for name in (DILIGENT_NORMALS, "light_directions.txt"))
    for where in (f, f.parent) if release else (f,):
        found = [p for name in CAMERA_FILES if (p := _named(where, name)) is not None]
        for p in found:
            if not p.is_file():
                raise ValueError(f"`folder`: {p} is not a file")
        if found:
            return found
    return []


def _read_camera(paths: list[Path], shape=None) -> np.ndarray | None:
    """The K of a dataset folder's camera files (:func:`camera_files`); where there are two
    (K.txt beside Calib_Results.mat) they must agree: which one was meant, otherwise? A file
    stating an image size other than `shape` (H, W), the normal map's, is refused
    (:func:`facetlift.camera.check_image_size`)."""
    from ..camera import check_image_size

    read = [read_K_stated(p) for p in paths]
    if shape is not None:
        for p, (K, stated) in zip(paths, read, strict=True):
            check_image_size(K, stated, shape, str(p), arg="folder")
    Ks = [K for K, _ in read]
    if len(Ks) > 1 and not np.allclose(Ks[0], Ks[1], rtol=1e-6, atol=1e-6):
        raise ValueError(f"`folder`: {paths[0]} and {paths[1]} hold different intrinsics "
                         f"({Ks[0].tolist()} and {Ks[1].tolist()}); keep one, or give the "
                         "camera with --K (K= in Python)")
    return Ks[0] if Ks else None


def _read_mat_normals(p: Path, frame: str | None, encoding: str = "xyz",
                      normal_range: str = "signed", mask=None) -> np.ndarray:
    """The (H, W, 3) normals of a DiLiGenT ``Normal_gt.mat``: its variable ``Normal_gt``, or
    its only (H, W, 3) numeric one, converted from `frame` (decoded as ``2 v - 1`` first with
    ``normal_range="unsigned"``, its signs counted inside `mask`, then z rebuilt with
    ``encoding="xy"``, as :func:`facetlift.io.read_normals` does)."""
    from .. import frames
    from .images import load_mat

    data = load_mat(p, "folder", "pass the normals to facetlift.integrate")
    maps = {k: np.asarray(v) for k, v in data.items() if not k.startswith("__")
            and np.ndim(v) == 3 and np.shape(v)[-1] == 3 and np.asarray(v).dtype.kind in "biuf"}
    name = "Normal_gt" if "Normal_gt" in maps else (next(iter(maps)) if len(maps) == 1
                                                    else None)
    if name is None:
        found = {k: "x".join(map(str, np.shape(v))) for k, v in data.items()
                 if not k.startswith("__")}
        raise ValueError(f"`folder`: {p} must hold the normals as Normal_gt, or one (H, W, 3) "
                         "numeric variable; got variables "
                         + (", ".join(f"{k} ({v})" for k, v in sorted(found.items())) or "none")
                         + ": integrate it by its path with --mat-keys NAME")
    n = maps[name]
    if normal_range == "unsigned":  # (refuses an integer variable; x, y alone for "xy", as
        # a file's: its third channel counted in the length made flat normals NaN, a review)
        n = frames.decode_unsigned(n, f"`folder`: {p}'s {name}", mask,
                                   channels=2 if encoding == "xy" else 3)
    n = n.astype(np.float64)
    if encoding == "xy":
        n = frames.decode_xy(n, frame=frame)
    return frames.to_facetlift(n, frame)


def _other_maps(f: Path) -> list[str]:
    """The files of `f` that may be normal maps by name and header, for read_dataset's error:
    not its masks, priors, confidences or camera files, not facetlift's outputs, and not a
    one-channel image or a 2-d array (a depth map: an audit's ``depth_gt.npy`` was listed as a
    map to integrate)."""
    from ..jobs import OUTPUT_STEMS

    other = {"mask", "prior_depth", "confidence", *ROTATION_FIELDS} | OUTPUT_STEMS
    cameras = {name.lower() for name in CAMERA_FILES}
    out = []
    for p in sorted(f.iterdir()):
        ext = p.suffix.lower()
        if (not p.is_file() or ext not in NORMAL_READ_FORMATS + (".mat",)
                or p.stem.lower() in other or p.stem.endswith("_mask")
                or p.name.lower() in cameras or p.stem.lower().startswith("depth")
                or one_channel(p)):
            continue
        out.append(p.name)
    return out


def one_channel(p: Path) -> bool:
    """Whether `p` is a one-channel (or grey + alpha) PNG, a one- or two-sample TIFF or a
    2-d ``.npy``, from its header: a mask or a depth map, no normal map (unreadable or other
    files: False). Also what a batch takes ``X_mask.*`` beside ``X.*`` by."""
    try:
        ext = p.suffix.lower()
        if ext == ".png":
            with open(p, "rb") as fh:
                head = fh.read(26)
            return len(head) == 26 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[25] in (0, 4)
        if ext == ".npy":
            return np.load(p, mmap_mode="r", allow_pickle=False).ndim == 2
        if ext in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(p) as t:
                return t.pages[0].samplesperpixel in (1, 2)
    except Exception:  # (unreadable: not for this message to say)
        pass
    return False


def read_dataset(folder, *, frame: str | None = None, y_down: bool = False,
                 prior_scale: float | None = None, with_prior: bool = True,
                 with_confidence: bool = True, with_rotation: bool = True,
                 encoding: str = "xyz", normal_range: str = "signed", mask=None,
                 prior_zero_unknown: bool = True) -> dict:
    """Read a folder in the BiNI / DiLiGenT layout.

    The folder holds ``normal_map.png`` (or ``.tif``, ``.tiff``, ``.exr``, ``.npy``), usually
    ``mask.png`` (or ``.tif``, ``.tiff``, ``.npy``) and, for a perspective camera, ``K.txt``
    or ``Calib_Results.mat`` (its ``KK``; where it has both, they must agree). Without one the
    view is orthographic; other tools' camera files (:data:`OTHER_CAMERA_FILES`: COLMAP's
    ``cameras.txt``, OpenCV's ``calib.yml``, a ``transforms.json``, ``K.npy`` ...) are not
    read by themselves (``K=read_K(path)``; the command line names them and ``--K``).
    Pixels outside the mask may hold anything.

    The DiLiGenT release's object folders (``<obj>PNG/``) are read as they are: without a
    ``normal_map.*``, the normals are those of ``Normal_gt.mat`` (:data:`DILIGENT_NORMALS`,
    in facetlift's frame), and without a camera file of its own, such a folder's camera is
    its parent's ``K.txt`` or ``Calib_Results.mat``, where the release keeps it
    (:func:`camera_files`; a BiNI folder without ``K.txt`` stays orthographic).

    `frame`, `y_down`, `encoding` and `normal_range` are those of
    :func:`~facetlift.io.read_normals`. A depth prior
    ``prior_depth.*`` and a normal confidence ``confidence.*`` (``.npy``, ``.exr``, ``.tif``,
    ``.png``; the prior also as a points file, ``.csv`` or ``.txt``, returned as a map, or
    as its points with their weights where it has a weight column; docs/fusion.md) are
    picked up like ``K.txt``; `prior_scale` is that of :func:`~facetlift.io.read_prior`
    (required for a 16-bit PNG prior); `with_prior` and `with_confidence` False leave those
    files unread (``None``). For normals in world space, ``world_to_camera.*`` (the rotation
    from world to the camera frame `frame` names) or ``camera_to_world.*`` (the camera's
    pose, Blender's ``matrix_world``: transposed), as ``.txt``, ``.json`` or ``.npy``
    (:func:`read_rotation`), are picked up like ``K.txt`` too (one of them; `with_rotation`
    False leaves them unread). `mask` ((H, W) bool, optional): a mask given in place of the
    folder's ``mask.*`` (``facetlift integrate FOLDER --mask M``), which is then not read; it
    is returned as ``mask``, and as :func:`~facetlift.io.read_normals`' `mask` its pixels are
    those the map's checks look at (an 8/16-bit map's unit-length share and zero plateaus, the
    grey check, the components ``normal_range="unsigned"`` counts), as the folder's
    ``mask.*``'s are (its size is the caller's to check: the command line names its file).

    Returns
    -------
    dict
        ``normals`` (H, W, 3) float64, ``mask`` (H, W) bool (the mask file, else the normal
        map's alpha channel, else None), ``K`` (3, 3) or None, ``K_file`` the camera file
        it came from (a Path) or None, ``rotation`` (3, 3) from world to the camera frame
        `frame` names, or None and ``rotation_file`` (a Path) or None, ``prior`` (H, W) depth with
        NaN where unknown, or None, and ``confidence`` (H, W) or None; ``prior_file`` and
        ``confidence_file`` the files these came from (Paths) or None. The command line
        uses them (``facetlift integrate FOLDER``, which names the files in its summary);
        pass them to :func:`facetlift.integrate` as ``prior=`` and ``confidence=`` to do
        the same, and the rotation as ``normal_rotation=frames.rotation_in_facetlift(
        ds["rotation"], frame)`` (:func:`facetlift.frames.rotation_in_facetlift`): the
        normals returned were converted from `frame` already, the rotation was not (with the
        default frame the two are the same; with ``frame="opencv"`` and COLMAP's R,
        ``normal_rotation=ds["rotation"]`` turns them wrong).

    Raises
    ------
    ValueError
        If the folder or its normal map is missing, or any file is unreadable.
    """
    f = Path(folder)
    if not f.exists():  # (a FileNotFoundError as every other reader's, a review)
        from ..errors import InputFileNotFound

        raise InputFileNotFound(f"`folder`: {f} does not exist")
    if not f.is_dir():
        raise ValueError(f"`folder`: {f} is not a directory")
    formats = _dataset_formats()
    npath = normals_file(f)
    if npath is None:
        raise ValueError(_no_normals(f))
    mpath = _find(f, "mask", formats["mask"]) if mask is None else None
    # (read before the map: an "unsigned" map's signs are counted inside it, not in a fill
    # outside it, a review)
    if mpath is not None:
        mask = read_mask(mpath)
    if npath.suffix.lower() == ".mat":
        from .. import frames

        normals = _read_mat_normals(npath, frames.resolve(frame, y_down),
                                    frames.normal_encoding(encoding),
                                    frames.normal_range(normal_range), mask)
        alpha = None
    else:  # (the folder's mask replaces the map's alpha: no word on the alpha then)
        normals, alpha = read_normals(npath, frame=frame, y_down=y_down,
                                      check_alpha=mask is None, encoding=encoding,
                                      normal_range=normal_range, mask=mask)
    if mpath is not None:
        mask = check_mask_size(mask, mpath, normals.shape)
    elif mask is None:
        mask = alpha
    kpaths = camera_files(f)
    K = _read_camera(kpaths, normals.shape[:2])
    rotation, rpath = _read_folder_rotation(f) if with_rotation else (None, None)
    from ..problem import prior_image, prior_samples
    from .images import read_prior, read_weights

    H, W = normals.shape[:2]
    extra = {}  # the folder's own prior and confidence: a file at fault can be left unread
    for name, stem, wanted, reader in (
            ("prior", "prior_depth", with_prior,
             lambda p: read_prior(p, prior_scale, arg="prior",
                                  zero_unknown=prior_zero_unknown)),
            ("confidence", "confidence", with_confidence,
             lambda p: read_weights(p, arg="confidence"))):
        path = _find(f, stem, formats[stem]) if wanted else None
        extra[name] = None
        extra[f"{name}_file"] = path
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
    return {"normals": normals, "mask": mask, "K": K,
            "K_file": kpaths[0] if kpaths else None, "rotation": rotation,
            "rotation_file": rpath, **extra}


def _read_folder_rotation(f: Path) -> tuple[np.ndarray | None, Path | None]:
    """A dataset folder's rotation for normals in world space (:func:`read_dataset`), from
    world to the camera frame, and its file; ``(None, None)`` without one. Two of them
    (``world_to_camera.txt`` beside ``camera_to_world.txt``) are refused: which one was
    meant?"""
    found = [(name, p) for name in ROTATION_FIELDS
             if (p := _find(f, name, ROTATION_FORMATS)) is not None]
    if len(found) > 1:
        raise ValueError(f"`folder`: {f} holds {' and '.join(p.name for _, p in found)}, each "
                         "a rotation of the camera: keep one (a rotation given with "
                         "--world-to-camera or --camera-to-world replaces them)")
    if not found:
        return None, None
    name, p = found[0]
    return read_rotation(p, camera_to_world=name == "camera_to_world"), p


def _no_normals(f: Path) -> str:
    """read_dataset's message for a folder without a normal map: the maps it may mean (not
    its depth maps, which an audit saw offered as maps, with a `facetlift batch` of the
    folder that would have run them as normal maps), or, in a photometric-stereo folder,
    that its images are photographs."""
    looked = (f"looked for normal_map with extension {', '.join(NORMAL_READ_FORMATS)}, or "
              f"DiLiGenT's {DILIGENT_NORMALS}")
    jpeg = sorted(p.name for p in f.glob("normal_map.*") if p.suffix.lower() in (".jpg", ".jpeg"))
    if jpeg:  # (it was not named: a review)
        looked += (f"; {jpeg[0]} is a JPEG, which is not read: its lossy 8 bits still "
                   "integrate well, convert it to normal_map.png first, e.g. with Pillow, "
                   "Image.open(p).save(q)")
    if (f / "light_directions.txt").is_file():  # (DiLiGenT's 001.png ... are photographs)
        return (f"`folder`: {f} has no normal_map file ({looked}): it looks like a photometric "
                "stereo folder (light_directions.txt), whose images are photographs, not "
                "normal maps; save the estimated normals there as normal_map.png (or .npy, "
                "(H, W, 3) floats, x right, y up, z toward the camera) and give the folder "
                "again, or integrate the normal map by its path")
    try:  # (the release's pmsData: its object folders, an audit)
        objects = [c.name for c in sorted(f.iterdir()) if c.is_dir() and is_dataset(c)]
    except OSError:
        objects = []
    if objects:
        return (f"`folder`: {f} has no normal_map file ({looked}); it holds dataset folders "
                f"({', '.join(objects[:3])}{', ...' if len(objects) > 3 else ''}): integrate "
                f"one (facetlift integrate {f / objects[0]}), or all of them with `facetlift "
                f"batch {f} -o OUT`")
    maps = _other_maps(f)
    named = f"{', '.join(maps[:3])}{', ...' if len(maps) > 3 else ''}"
    mat = " (a .mat file with --mat-keys where it holds several arrays)" if any(
        m.lower().endswith(".mat") for m in maps[:3]) else ""
    # (a batch of the folder runs every such file: offered only where those are the maps)
    extra = [n for n in _batch_would_run(f) if n not in maps]
    batch = (f", or all of them with `facetlift batch {f} -o OUT`" if not extra else
             f"; `facetlift batch {f}` would run {', '.join(extra[:3])}"
             f"{', ...' if len(extra) > 3 else ''} as normal maps too: give it the maps by "
             "name")
    return (f"`folder`: {f} has no normal_map file ({looked})"
            + (f"; it holds other files that may be normal maps ({named}): integrate one by "
               f"its path (facetlift integrate {f / maps[0]}){mat}{batch}" if maps else ""))


def _batch_would_run(f: Path) -> list[str]:
    """The names of the files of `f` that ``facetlift batch`` makes items of: its own
    :func:`facetlift.batch.items` (a copy of its filter could drift from it), quietly; none
    where it finds none."""
    import warnings

    from ..batch import items

    try:
        with warnings.catch_warnings():  # (its notes on subfolders are for a batch's run)
            warnings.simplefilter("ignore")
            found = items([f])
    except ValueError:  # (no map at all)
        return []
    return sorted(Path(it.path).name for it in found
                  if it.error is None and Path(it.path).is_file())
