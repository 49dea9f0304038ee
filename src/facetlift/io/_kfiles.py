"""Perspective intrinsics from calibration tools' own files (:func:`facetlift.io.read_K`):
OpenCV FileStorage YAML and XML, ROS ``camera_info`` YAML and CameraInfo dumps, COLMAP's
``cameras.txt`` and ``cameras.bin``, and nerfstudio / instant-ngp ``transforms.json``. Small
targeted readers, no YAML library (PyYAML cannot read OpenCV's ``%YAML:1.0`` files
anyway)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .._warnings import warn


class _KError(ValueError):
    """A K file's own message, given as it is (not as a parse error)."""


def _stated_size(mapping: dict, *keys: tuple[str, str]) -> tuple[int, int] | None:
    """The (H, W) of the first pair of `keys` (width key, height key) that `mapping` holds
    as two positive whole numbers (OpenCV's and ROS's ``image_width`` / ``image_height``, a
    CameraInfo's ``width`` / ``height``, nerfstudio's ``w`` / ``h``); None otherwise (a ROS
    dump's 0 x 0: not calibrated)."""
    for wkey, hkey in keys:
        w, h = mapping.get(wkey), mapping.get(hkey)
        try:
            w, h = float(w), float(h)
        except (TypeError, ValueError):
            continue
        if w > 0 and h > 0 and w.is_integer() and h.is_integer():
            return int(h), int(w)
    return None


# ------------------------------------------------------------------ YAML (OpenCV, ROS)

#: The keys a calibration's intrinsics go by (case aside): OpenCV's samples and
#: calibrateCamera scripts (``camera_matrix``, ``cameraMatrix``, ``K``, ``intrinsic(s)``),
#: ROS camera_info (``camera_matrix``) and CameraInfo (``k``, ``K`` in ROS 1), and one camera
#: of several (a stereo calibration's ``M1`` / ``M2``, ``K1`` / ``K2``, ``camera_matrix_left``,
#: ...): where two such are found, which one is the image's?
_CAMERA_KEY = re.compile(r"^(m|k|camera_?matrix|intrinsics?)[_-]?(\d+|left|right|l|r)?$")


def is_yaml(p: Path, text: str) -> bool:
    """Whether a K file is YAML: named ``.yml`` / ``.yaml``, headed ``%YAML`` or ``---``, or
    with a line ``camera_matrix:`` or ``k:`` (a CameraInfo dump saved as .txt); never a file
    without a ``key:`` line (three rows of numbers saved as ``K.yml`` are read as text, as
    before these readers)."""
    first = text.lstrip().split("\n", 1)[0].strip()
    if re.search(r"(?m)^[ \t]*[^\s#%:-][^#\n]*:", text) is None:
        return False  # (no key at all: a plain K file, e.g. three rows of numbers in a .yml)
    return (p.suffix.lower() in (".yml", ".yaml") or first.startswith("%YAML") or first == "---"
            or re.search(r"(?m)^\s*(camera_?matrix|cameraMatrix|k|K)\s*:", text) is not None)


def _yaml_lines(text: str) -> list[tuple[int, str]]:
    """(indent, content) of a YAML subset's lines: the first document only (a ``rostopic
    echo`` dump ends each message with ``---``), comments and directives cut, a flow list over
    several lines (OpenCV's ``data: [ ... ]``) joined into one."""
    out: list[tuple[int, str]] = []
    started = False
    depth = 0
    for raw in text.splitlines():
        line = re.sub(r"(^|\s)#.*$", "", raw).rstrip()
        if depth > 0:  # (inside a flow list begun above)
            out[-1] = (out[-1][0], out[-1][1] + " " + line.strip())
            depth += line.count("[") - line.count("]")
            continue
        if not line.strip() or line.startswith("%"):
            continue
        if line.strip() in ("---", "...") or line.startswith("--- "):
            if started:
                break  # (the next document)
            continue
        started = True
        out.append((len(line) - len(line.lstrip()), line.strip()))
        depth = line.count("[") - line.count("]")
    return out


def _yaml_scalar(s: str):
    """A scalar or a flow list (of scalars) of the YAML subset, numbers as floats where they
    parse (``0.`` and ``5.2e+02`` as OpenCV writes them)."""
    s = s.strip()
    if s.startswith("["):
        return [_yaml_scalar(v) for v in s.strip("[] ").split(",") if v.strip()]
    s = s.strip("\"'")
    try:
        return float(s)
    except ValueError:
        return s


def _yaml_block(lines, i: int, indent: int):
    """The mapping or block sequence at `indent` from line `i`: (value, next line)."""
    if lines[i][1].startswith("-"):
        seq = []
        while i < len(lines) and lines[i][0] == indent and lines[i][1].startswith("-"):
            seq.append(_yaml_scalar(lines[i][1][1:]))
            i += 1
            while i < len(lines) and lines[i][0] > indent:  # (an item's own block: not read)
                i += 1
        return seq, i
    mapping: dict = {}
    while i < len(lines) and lines[i][0] >= indent:
        ind, content = lines[i]
        i += 1
        key, colon, rest = content.partition(":")
        if ind > indent or not colon:  # (what this subset does not read)
            continue
        rest = re.sub(r"^!+[\w.:/-]*\s*", "", rest.strip())  # (a tag: !!opencv-matrix)
        if rest:
            mapping[key.strip().strip("\"'")] = _yaml_scalar(rest)
        elif i < len(lines) and (lines[i][0] > ind or (
                lines[i][0] == ind and lines[i][1].startswith("-"))):
            mapping[key.strip().strip("\"'")], i = _yaml_block(lines, i, lines[i][0])
        else:
            mapping[key.strip().strip("\"'")] = None
    return mapping, i


def _matrix(node, shape: tuple[int, int]):
    """`node` as a matrix of `shape`, or None: an OpenCV / ROS matrix node (``rows``,
    ``cols``, ``data``) or a flat list of numbers (a CameraInfo dump's ``k``)."""
    if isinstance(node, dict) and isinstance(node.get("data"), list):
        rows, cols = node.get("rows"), node.get("cols")
        if (rows, cols) != (None, None) and (rows, cols) != shape:
            return None
        node = node["data"]
    if isinstance(node, list) and len(node) == shape[0] * shape[1] and all(
            isinstance(v, float) for v in node):
        return np.array(node, dtype=float).reshape(shape)
    return None


def _walk(tree: dict, prefix: str = ""):
    """(dotted name, value, parent mapping) of every mapping entry of `tree`."""
    for k, v in tree.items():
        yield prefix + str(k), v, tree
        if isinstance(v, dict) and not isinstance(v.get("data"), list):
            yield from _walk(v, prefix + str(k) + ".")


def pick_K(found: dict[str, np.ndarray], p: Path, fmt: str) -> tuple[str, np.ndarray]:
    """The one intrinsics matrix of a calibration file's 3x3 matrices `found` (name ->
    matrix): the only one named as a camera's (:data:`_CAMERA_KEY`, or one of a stereo pair's),
    else the only 3x3; otherwise a :class:`_KError` listing them."""
    cams = [n for n in found if _CAMERA_KEY.match(n.rsplit(".", 1)[-1].lower())]
    if len(cams) == 1:
        return cams[0], found[cams[0]]
    if not cams and len(found) == 1:
        name = next(iter(found))
        return name, found[name]
    if not found:
        raise _KError(f"`K`: {p} holds no 3x3 matrix ({fmt}: a node such as camera_matrix "
                      "with rows 3, cols 3 and its nine numbers as data)")
    listed = ", ".join(cams or list(found))
    stereo = " (a stereo calibration holds one per camera: M1 / K1 the first's)" \
        if len(cams) > 1 else ""
    raise _KError(f"`K`: {p} holds several 3x3 matrices, {listed}{stereo}: which is the "
                  "image's camera? Copy that one out into a K file of its own (its nine "
                  "numbers row by row, or fx fy cx cy as text)")


def K_yaml(p: Path, text: str) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of an OpenCV FileStorage YAML file (``%YAML:1.0``, a
    ``!!opencv-matrix`` node), a ROS ``camera_info`` YAML (``camera_matrix``; its
    ``projection_matrix`` differing is warned about) or a CameraInfo message dump
    (``k:`` / ``K:``, nine numbers). Distortion coefficients beside the matrix that are not
    all zero are warned about (:func:`_opencv_distortion`). Returns K and the image size (H,
    W) the file states (``image_width`` / ``image_height``, a dump's ``width`` / ``height``),
    or None."""
    lines = _yaml_lines(text)
    if not lines:
        raise _KError(f"`K`: {p} is an empty YAML file")
    tree, _ = _yaml_block(lines, 0, lines[0][0])
    if not isinstance(tree, dict):
        raise _KError(f"`K`: {p} is a YAML list, not a calibration (a mapping with a "
                      "camera_matrix, K or k)")
    found, parents = {}, {}
    for name, value, parent in _walk(tree):
        m = _matrix(value, (3, 3))
        if m is not None:
            found[name], parents[name] = m, parent
    name, K = pick_K(found, p, "YAML")
    _check_projection(K, parents[name], p, name)
    parent = parents[name]
    dist = _pick_distortion({k: _vector(v) for k, v in parent.items()}, name)
    _opencv_distortion(p, dist, parent.get("distortion_model"))
    size = _stated_size(parent, ("image_width", "image_height"), ("width", "height"))
    return K, size if size is not None else _stated_size(tree, ("image_width", "image_height"))


#: The keys a calibration's distortion coefficients go by (case aside): OpenCV's samples
#: (``distortion_coefficients``, ``dist_coeffs``, ``distCoeffs``, ``D``, a stereo pair's
#: ``D1`` / ``D2``) and ROS (``distortion_coefficients``; ``d`` in ROS 2, ``D`` in ROS 1).
_DISTORTION_KEY = re.compile(
    r"^(d|dist|dist_?coeffs?|distortion(_?coeff(icient)?s)?)[_-]?(\d+|left|right|l|r)?$")

#: OpenCV's distortion coefficients in its order (calibrateCamera's 4, 5, 8, 12 or 14; ROS's
#: plumb_bob and rational_polynomial models the same), and cv2.fisheye's (ROS's
#: equidistant).
OPENCV_DISTORTION = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4",
                     "tx", "ty")
FISHEYE_DISTORTION = ("k1", "k2", "k3", "k4")


def _vector(node) -> list[float] | None:
    """`node` as a list of numbers, or None: a matrix node's data (``rows``, ``cols``,
    ``data``: OpenCV's, ROS's) or a flat list (a CameraInfo dump's ``d``)."""
    if isinstance(node, dict):
        node = node.get("data")
    if isinstance(node, list) and node and all(isinstance(v, float) for v in node):
        return node
    return None


def _pick_distortion(nodes: dict, name: str) -> list[float] | None:
    """The distortion coefficients of the camera `name` (its key, dotted) among the entries
    `nodes` (key -> list of numbers or None) of its mapping: the one named as distortion
    (:data:`_DISTORTION_KEY`) with the camera key's suffix (``D1`` for ``M1``), else the only
    one; None where there is none, or several of which none is the camera's."""
    found = {k: v for k, v in nodes.items()
             if v is not None and _DISTORTION_KEY.match(str(k).lower())}
    own = _CAMERA_KEY.match(name.rsplit(".", 1)[-1].lower())
    suffix = own.group(2) if own else None
    same = [v for k, v in found.items()
            if _DISTORTION_KEY.match(str(k).lower()).group(4) == suffix]
    if len(same) == 1:
        return same[0]
    return next(iter(found.values())) if len(found) == 1 else None


def _opencv_distortion(p: Path, dist: list[float] | None, model=None) -> None:
    """Warn where an OpenCV or ROS calibration's distortion coefficients `dist` (OpenCV's
    order; cv2.fisheye's for ROS's ``equidistant`` `model`) are not all zero, as
    :func:`_distortion` warns of COLMAP's."""
    if not dist:
        return
    fisheye = str(model or "").lower() in ("equidistant", "fisheye")
    names = FISHEYE_DISTORTION if fisheye else OPENCV_DISTORTION
    named = {(names[i] if i < len(names) else f"c{i}"): v for i, v in enumerate(dist) if v}
    how = ("undistort the image first with these coefficients (cv2.fisheye.undistortImage: "
           "an equidistant model is a fish-eye's)" if fisheye else
           "undistort the image first with these coefficients (cv2.undistort(image, K, "
           "dist); ROS's image_proc publishes it as image_rect)")
    _distortion(str(p), named, how + " and compute the normal map from the undistorted image")


def _check_projection(K: np.ndarray, parent: dict, p: Path, name: str) -> None:
    """Warn where the camera's mapping also holds a projection matrix (ROS: ``P``, whose left
    3x3 is the rectified image's intrinsics) that differs from `K` by more than 1e-6."""
    for key in ("projection_matrix", "p", "P"):
        P = _matrix(parent.get(key), (3, 4))
        if P is None or not P.any():  # (a ROS dump's all-zero P: uncalibrated)
            continue
        left = P[:, :3]
        if np.abs(left - K).max() > 1e-6 * max(np.abs(K).max(), np.abs(left).max()):
            warn(f"`K`: {p}: its {name} is the camera's for the raw (unrectified) image and "
                 f"is used; for a rectified image (image_rect) its {key}'s left 3x3 "
                 f"{left.tolist()} is the camera instead: save that as a K file (fx fy cx cy: "
                 f"{left[0, 0]:g} {left[1, 1]:g} {left[0, 2]:g} {left[1, 2]:g})")
        return


# ------------------------------------------------------------------ OpenCV XML


def K_xml(p: Path) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of an OpenCV FileStorage XML file: its ``type_id="opencv-matrix"``
    node of 3 rows and 3 cols, chosen among several as :func:`pick_K` does; its distortion
    coefficients warned about as :func:`K_yaml` warns of them. Returns K and the image size
    (H, W) its ``<image_width>`` and ``<image_height>`` state, or None."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as e:
        raise _KError(f"`K`: cannot read {p} as XML ({e})") from None
    found, vectors = {}, {}
    for el in root.iter():
        data, rows, cols = el.find("data"), el.find("rows"), el.find("cols")
        if data is None or (el.get("type_id") != "opencv-matrix" and rows is None):
            continue
        try:
            shape = (int(rows.text), int(cols.text)) if rows is not None and cols is not None \
                else (3, 3)
            values = np.array((data.text or "").split(), dtype=float)
        except (TypeError, ValueError):
            raise _KError(f"`K`: {p}: the matrix <{el.tag}> is not numbers: its rows, cols "
                          "and data must be") from None
        if shape == (3, 3) and values.size == 9:
            found[el.tag] = values.reshape(3, 3)
        elif 1 in shape and values.size == shape[0] * shape[1]:
            vectors[el.tag] = [float(v) for v in values]
    name, K = pick_K(found, p, "OpenCV XML")
    _opencv_distortion(p, _pick_distortion(vectors, name))
    stated = {el.tag: (el.text or "").strip() for el in root
              if el.tag in ("image_width", "image_height")}
    return K, _stated_size(stated, ("image_width", "image_height"))


# ------------------------------------------------------------------ COLMAP cameras.txt

#: COLMAP's camera models (``src/colmap/sensor/models.h``) with a pinhole projection: their
#: parameters' names, in order. The principal point is COLMAP's: see :func:`K_colmap`.
COLMAP_MODELS = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
#: ... and those whose image is no pinhole image (refused).
COLMAP_FISHEYE = ("SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "OPENCV_FISHEYE", "FOV",
                  "THIN_PRISM_FISHEYE", "RAD_TAN_THIN_PRISM_FISHEYE")
_UNDISTORT = ("undistort the images first with COLMAP's image_undistorter (colmap "
              "image_undistorter --image_path ... --input_path ... --output_path ...), which "
              "writes PINHOLE cameras, and compute the normal map from the undistorted image")


def colmap_lines(rows: list[str]) -> list[list[str]]:
    """The camera lines of a COLMAP ``cameras.txt`` among a text file's `rows` (comments
    cut): those whose second word is a COLMAP camera model; none in another K file."""
    return [r.split() for r in rows
            if len(r.split()) > 1 and r.split()[1] in (*COLMAP_MODELS, *COLMAP_FISHEYE)]


def K_colmap(p: Path, cams: list[list[str]]) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of a COLMAP ``cameras.txt`` (``CAMERA_ID MODEL WIDTH HEIGHT
    PARAMS[]``): its one camera, or its several where all are the same. COLMAP puts the
    upper-left pixel's centre at (0.5, 0.5), facetlift at (0, 0): cx and cy are COLMAP's
    minus 0.5. A fish-eye model is refused; distortion that is not zero is warned about.
    Returns K and the image size (H, W) of its WIDTH and HEIGHT (None where its cameras
    differ in it)."""
    def key(c):
        return c[1], tuple(c[4:])

    if len({key(c) for c in cams}) > 1:
        listed = ", ".join(f"camera {c[0]} ({c[1]}, {c[2]}x{c[3]})" for c in cams)
        raise _KError(f"`K`: {p} holds {len(cams)} different cameras, {listed}: give the "
                      "image's camera (images.txt names each image's CAMERA_ID): save its line "
                      "as a cameras.txt of its own, or its fx fy cx cy as a text file (COLMAP's "
                      "cx and cy minus 0.5)")
    cam = cams[0]
    model = cam[1]
    if model in COLMAP_FISHEYE:
        raise _KError(f"`K`: {p}: camera {cam[0]} is COLMAP's {model}, a fish-eye (or FOV) "
                      "model: a normal map needs a pinhole image; " + _UNDISTORT)
    names = COLMAP_MODELS[model]
    try:
        values = [float(v) for v in cam[4:]]
    except ValueError:
        raise _KError(f"`K`: {p}: camera {cam[0]}'s parameters are not numbers: "
                      f"{' '.join(cam[4:])}") from None
    if len(values) != len(names):
        raise _KError(f"`K`: {p}: camera {cam[0]} ({model}) must have {len(names)} "
                      f"parameters ({', '.join(names)}) after its width and height; got "
                      f"{len(values)}")
    par = dict(zip(names, values, strict=True))
    fx = par.get("fx", par.get("f"))
    fy = par.get("fy", par.get("f"))
    extra = {k: v for k, v in par.items() if k not in ("f", "fx", "fy", "cx", "cy") and v}
    _distortion(f"{p}: camera {cam[0]} ({model})", extra)
    sizes = {(c[2], c[3]) for c in cams}
    size = _stated_size(dict(zip(("w", "h"), sizes.pop(), strict=True)), ("w", "h")) \
        if len(sizes) == 1 else None
    return _K_centred(fx, fy, par["cx"], par["cy"]), size


def _distortion(who: str, dist: dict, undistort: str = _UNDISTORT) -> None:
    """Warn that `who` (a file, or a camera of one) has the lens distortion `dist` (name ->
    coefficient, the non-zero ones; nothing where empty), which K leaves out; `undistort`
    says how to undistort (COLMAP's image_undistorter by default)."""
    if dist:
        warn(f"`K`: {who} has lens distortion ({', '.join(f'{k} {v:g}' for k, v in dist.items())}"
             "), which K leaves out: the normal map must be of an undistorted image; "
             + undistort)


def _K_centred(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """The K of a principal point given as COLMAP (and nerfstudio) give it, the upper-left
    pixel's centre at (0.5, 0.5): cx and cy minus 0.5, facetlift's pixel centres being at
    integers (docs/conventions.md)."""
    return np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])


#: COLMAP's binary model ids (``cameras.bin``, as its ``read_write_model.py`` writes and reads
#: them) with their names and parameter counts.
COLMAP_IDS = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
    4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5),
    8: ("SIMPLE_RADIAL_FISHEYE", 4), 9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
}


def K_colmap_bin(p: Path) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of a COLMAP ``cameras.bin`` (the sparse model COLMAP's mapper writes by
    default; little-endian: the number of cameras as uint64, then per camera its id and model
    id as int32, width and height as uint64 and the model's parameters as float64), read as
    :func:`K_colmap` reads the same cameras from ``cameras.txt``."""
    import struct

    data = p.read_bytes()

    def bad(why):
        return _KError(f"`K`: {p} is not a COLMAP cameras.bin ({why}); COLMAP's text export "
                       "(colmap model_converter --output_type TXT) writes cameras.txt")

    if len(data) < 8:
        raise bad(f"{len(data)} bytes")
    (count,) = struct.unpack_from("<Q", data, 0)
    at, cams = 8, []
    for _ in range(count):
        if at + 24 > len(data):
            raise bad(f"it says {count} cameras and ends after {len(cams)}")
        cid, model_id, width, height = struct.unpack_from("<iiQQ", data, at)
        at += 24
        if model_id not in COLMAP_IDS:
            raise bad(f"camera {cid} has model id {model_id}, which this reader does not know")
        name, n = COLMAP_IDS[model_id]
        if at + 8 * n > len(data):
            raise bad(f"camera {cid}'s {n} parameters run past its end")
        params = struct.unpack_from(f"<{n}d", data, at)
        at += 8 * n
        cams.append([str(cid), name, str(width), str(height), *(repr(v) for v in params)])
    if not cams:
        raise bad("it holds no camera")
    if at != len(data):
        raise bad(f"{len(data) - at} bytes after its {count} cameras")
    return K_colmap(p, cams)


# ------------------------------------------------------------------ transforms.json

#: The distortion coefficients a nerfstudio / instant-ngp transforms.json may hold.
_NERF_DISTORTION = ("k1", "k2", "k3", "k4", "p1", "p2")


#: The camera keys a transforms.json frame may hold for itself (nerfstudio's datasets of
#: several cameras give them per frame, not at the top).
_NERF_CAMERA = ("fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model", "is_fisheye",
                *_NERF_DISTORTION)


def _frame_cameras(low: dict) -> list[dict]:
    """The cameras a transforms.json's frames give for themselves (those with ``fl_x``)."""
    frames = low.get("frames")
    if not isinstance(frames, list):
        return []
    return [{k: f[k] for k in _NERF_CAMERA if k in f} for f in frames
            if isinstance(f, dict) and "fl_x" in f]


def is_transforms(data: dict) -> bool:
    """Whether a JSON object is a nerfstudio / instant-ngp ``transforms.json``'s camera
    (``fl_x`` at its top or in its frames, or ``camera_angle_x`` alone)."""
    low = {str(k).lower(): v for k, v in data.items()}
    return ("fl_x" in low or ("camera_angle_x" in low and "fx" not in low)
            or bool(_frame_cameras(low)))


def K_transforms(data: dict, p: Path) -> tuple[np.ndarray, tuple[int, int] | None]:
    """The intrinsics of a ``transforms.json`` (nerfstudio, instant-ngp): ``fl_x``, ``fl_y``
    (``fl_x`` where missing), ``cx``, ``cy``, at its top or, the same for every frame, in its
    frames. Their principal point is COLMAP's (nerfstudio
    copies COLMAP's cx, cy unchanged and casts its rays through ``pixel + 0.5``): cx and cy
    minus 0.5, as :func:`K_colmap`. ``camera_angle_x`` alone is refused (it needs the
    image's width: ``--fov``). Returns K and the image size (H, W) of its ``w`` and ``h``,
    or None."""
    import math

    low = {str(k).lower(): v for k, v in data.items()}
    frames = _frame_cameras(low) if "fl_x" not in low else []
    if frames:  # (the camera given per frame: one for all, or the image's to be named)
        distinct = {tuple(sorted((k, str(v)) for k, v in f.items())) for f in frames}
        if len(distinct) > 1:
            raise _KError(f"`K`: {p} gives its frames {len(distinct)} different cameras "
                          f"(fl_x, cx, ... per frame, {len(frames)} frames): give the image's "
                          "own as a text file, fx fy cx cy with its cx and cy minus 0.5 "
                          "(nerfstudio's principal point is COLMAP's)")
        low = {**low, **frames[0]}
    if "fl_x" not in low:
        angle = low["camera_angle_x"]
        deg = f" = {math.degrees(float(angle)):.6g} degrees" \
            if isinstance(angle, (int, float)) else ""
        raise _KError(f"`K`: {p} gives the camera as camera_angle_x ({angle} radians{deg}), "
                      "the field of view across the width, without a focal length in pixels: "
                      "give --fov with that angle in degrees instead of --K (in Python "
                      "K=facetlift.camera.K_from_fov(normals.shape[:2], degrees))")
    model = str(low.get("camera_model", "")).upper()
    fisheye = low.get("is_fisheye") in (True, 1, "true", "True")  # (instant-ngp's flag)
    if fisheye or "FISHEYE" in model or model == "EQUIRECTANGULAR":
        what = "is_fisheye is true" if fisheye else f"its camera_model is {model}"
        raise _KError(f"`K`: {p}: {what}: a normal map needs a pinhole "
                      "image; undistort the images first (COLMAP's image_undistorter writes "
                      "PINHOLE cameras)")
    missing = [k for k in ("cx", "cy") if k not in low]
    if missing:
        raise _KError(f"`K`: {p} gives fl_x but not {' and '.join(missing)}: give the "
                      "principal point (a transforms.json holds cx and cy beside fl_x)")
    try:
        fx = float(low["fl_x"])
        fy = float(low.get("fl_y", fx))
        cx, cy = float(low["cx"]), float(low["cy"])
        dist = {k: float(low[k]) for k in _NERF_DISTORTION if k in low}
    except (TypeError, ValueError):
        raise _KError(f"`K`: {p}: fl_x, fl_y, cx, cy must be numbers") from None
    _distortion(str(p), {k: v for k, v in dist.items() if v})
    return _K_centred(fx, fy, cx, cy), _stated_size(low, ("w", "h"))
