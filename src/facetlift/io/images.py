"""Normal maps, masks and depth maps as PNG, TIFF, OpenEXR and ``.npy`` files.

PNG goes through imagecodecs (libpng: 8 and 16 bit kept as stored), TIFF through tifffile and
OpenEXR through the OpenEXR bindings, each imported on first use. The decoding rule for integer
normal maps is in :mod:`facetlift.io`.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import threading
import zipfile
from pathlib import Path

import numpy as np

from .. import frames
from .._warnings import warn
from ..frames import ENCODED_LENGTH_RANGE  # noqa: F401  (re-exported by facetlift.io)
from ..problem import numeric_array
from ._paths import _existing, _file_name, _suffix
from .atomic import _save_npy, _write_bytes, atomic_path

NORMAL_READ_FORMATS = (".png", ".tif", ".tiff", ".exr", ".npy", ".pfm")
NORMAL_WRITE_FORMATS = (".png", ".tif", ".tiff", ".exr", ".npy")
MASK_FORMATS = (".png", ".tif", ".tiff", ".npy", ".pfm")
MASK_WRITE_FORMATS = (".png", ".tif", ".tiff", ".npy")
DEPTH_FORMATS = (".npy", ".exr", ".tif", ".tiff")


# --------------------------------------------------------------------------------------------
# decoding


class _Refused(Exception):
    """A readable file :func:`_decode_image` refuses, with its message."""


def _decode_image(path: Path, ext: str, arg: str) -> np.ndarray:
    """Pixels of a PNG, TIFF or PFM file as stored (no conversion); ValueError if
    unreadable."""
    if ext == ".pfm":  # (its own messages: a damaged header, a truncated file)
        return _read_pfm(path, arg)
    try:
        if ext == ".png":
            import imagecodecs

            data = path.read_bytes()
            return np.asarray(imagecodecs.png_decode(data))
        import tifffile

        with tifffile.TiffFile(path) as tif:
            a = np.asarray(tif.asarray())
            planar = tif.pages[0].planarconfig == tifffile.PLANARCONFIG.SEPARATE
            pages = len(tif.pages)
        # (refused by its shape alone before, a review; an (H, W, 2) map is stored as H
        # pages of (W, 2) by tifffile: no stack)
        if pages > 1 and a.shape[0] == pages and (a.ndim == 4 or (
                a.ndim == 3 and a.shape[-1] > 4)):
            raise _Refused(f"`{arg}`: {path} holds {pages} pages (a stack of images, shape "
                           f"{a.shape}); one image per file is read: save the page you mean "
                           "alone, e.g. tifffile.imwrite(q, tifffile.imread(p, key=0))")
        if planar and a.ndim == 3 and a.shape[0] in (2, 3, 4):  # (C, H, W) -> (H, W, C)
            a = np.moveaxis(a, 0, -1)
        return a
    except _Refused as e:
        raise ValueError(str(e)) from None
    except OSError as e:
        raise ValueError(f"`{arg}`: cannot read {path}: {e}") from None
    except Exception as e:  # corrupt or truncated files: each library has its own errors
        raise ValueError(
            f"`{arg}`: {path} is not a readable {ext[1:].upper()} image ({type(e).__name__}: {e})"
        ) from None


_REDIRECT = {"lock": threading.Lock(), "depth": 0, "saved": None, "caught": None,
             "enabled": False}


def protect_stdout(enabled: bool = True) -> None:
    """Whether the readers catch the C libraries' own prints while they run
    (:func:`_library_quiet`): the command line turns it on (its stdout carries the --json
    object alone, its stderr one line per error), a library caller's descriptors are left
    alone (file descriptors 1 and 2 are the whole process's: a host thread printing meanwhile
    would have its words caught)."""
    _REDIRECT["enabled"] = bool(enabled)


class _Said:
    """What a C library printed inside a :func:`_library_quiet` block, its stdout and stderr
    together: ``text``, set as the block is left ('' where nothing was caught)."""

    text = ""


@contextlib.contextmanager
def _library_quiet():
    """The C library's own prints go to a temporary file meanwhile, where
    :func:`protect_stdout` is on, and come back as the yielded :class:`_Said`'s ``text``:
    a reader puts them in its one-line error, or passes them on to stderr after a read that
    worked (:func:`_pass_on`). OpenEXR, given a truncated file, printed a line on stdout and
    another on stderr before facetlift's error, which itself ended "Invalid part index '0':
    file has 0 parts" (a review); and stdout carries the command line's --json object alone.
    File descriptors 1 and 2 are the process's: overlapping readers (threads) share one
    redirection, undone by the last to leave, which is given all that was caught."""
    said = _Said()
    if not _REDIRECT["enabled"]:
        yield said
        return
    with _REDIRECT["lock"]:
        if _REDIRECT["depth"] == 0:
            _REDIRECT["saved"], _REDIRECT["caught"] = _catch_prints()
        _REDIRECT["depth"] += 1
    try:
        yield said
    finally:
        with _REDIRECT["lock"]:
            _REDIRECT["depth"] -= 1
            if _REDIRECT["depth"] == 0 and _REDIRECT["saved"] is not None:
                said.text = _release_prints(_REDIRECT["saved"], _REDIRECT["caught"])
                _REDIRECT["saved"] = _REDIRECT["caught"] = None


class _Into:
    """A text stream that writes into the file descriptor `fd` (:func:`_catch_prints`)."""

    encoding, errors = "utf-8", "replace"

    def __init__(self, fd: int):
        self.fd = fd

    def write(self, text: str) -> int:
        with contextlib.suppress(OSError):
            os.write(self.fd, str(text).encode("utf-8", "replace"))
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False


_INTO = _Into(-1)


def _catch_prints():
    """``(saved, caught)``: file descriptors 1 and 2 sent to a temporary file `caught`, and
    Python's sys.stdout and sys.stderr too (OpenEXR's bindings print through Python's print:
    a host's streams, pytest's or a notebook's, need not write to fds 1 and 2), their old
    targets in `saved` ({fd: duplicate, "streams": (stdout, stderr)}); ``(None, None)``
    where no descriptor could be (no real stdout or stderr, no temporary file: the prints go
    where they went)."""
    import tempfile

    for stream in (sys.stdout, sys.stderr):  # (what Python holds goes out first)
        with contextlib.suppress(Exception):
            stream.flush()
    _flush_c_stdio()
    try:
        caught = tempfile.TemporaryFile()
    except OSError:
        return None, None
    saved = {}
    for fd in (1, 2):
        try:
            old = os.dup(fd)
        except (OSError, ValueError):
            continue
        try:
            os.dup2(caught.fileno(), fd)
        except (OSError, ValueError):
            os.close(old)
            continue
        saved[fd] = old
    if not saved:
        caught.close()
        return None, None
    saved["streams"] = sys.stdout, sys.stderr
    # (one stream object for the process, kept alive: print() in another thread holds only a
    # borrowed reference to sys.stdout, and a fresh object freed on restore crashed it, the
    # diff review; a late write after the restore meets a closed descriptor and is dropped)
    _INTO.fd = caught.fileno()
    sys.stdout = sys.stderr = _INTO
    return saved, caught


def _release_prints(saved: dict, caught) -> str:
    """Undo :func:`_catch_prints`; the text caught."""
    sys.stdout, sys.stderr = saved.pop("streams")
    _INTO.fd = -1  # (a late write is dropped, not sent to a file that reuses the number)
    _flush_c_stdio()  # (what the library buffered goes into the file, not after it)
    for fd, old in saved.items():
        os.dup2(old, fd)
        os.close(old)
    try:
        caught.seek(0)
        return caught.read().decode("utf-8", "replace")
    except OSError:
        return ""
    finally:
        caught.close()


def _pass_on(text: str) -> None:
    """Write what a library printed during a read that worked to stderr (its warnings are
    still the user's to see; on stdout they would break --json)."""
    if text:
        with contextlib.suppress(Exception):
            sys.stderr.write(text if text.endswith("\n") else text + "\n")
            sys.stderr.flush()


def _flush_c_stdio() -> None:
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None).fflush(None)


def _exr_quantity(path: Path) -> str | None:
    """The :data:`EXR_QUANTITY` of an EXR file's header (None where it has none or cannot be
    read: the reading itself says why, so what the library printed then is dropped)."""
    value = None
    with _library_quiet() as said:
        try:
            import OpenEXR

            with OpenEXR.File(str(path), header_only=True) as f:
                value = f.header().get(EXR_QUANTITY)
        except Exception:
            said = None
    if said is not None:
        _pass_on(said.text)
    return value if isinstance(value, str) else None


#: The first four bytes of every OpenEXR file.
EXR_MAGIC = b"\x76\x2f\x31\x01"


def _exr_unreadable(path: Path, arg: str, error: Exception, said: str) -> str:
    """The one-line error for an EXR file OpenEXR could not read: not an EXR at all (no
    signature), or truncated or corrupt, with the library's own line where it printed one
    (the exception's text, "Invalid part index '0': file has 0 parts" for a truncated file,
    says less), else the exception's."""
    if isinstance(error, ImportError):
        return f"`{arg}`: reading {path} needs the OpenEXR package ({error})"
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError:
        head = EXR_MAGIC
    if head != EXR_MAGIC:
        return (f"`{arg}`: {path} is not an OpenEXR file: "
                + ("it is empty (0 bytes)" if not head else
                   "it does not begin with the EXR signature (76 2f 31 01)"))
    lines = [x.strip() for x in said.splitlines() if x.strip()]
    line = next((x for x in lines if "EXR_ERR" in x), lines[0] if lines else "")
    for prefix in (f"{path}: ", f"{path.name}: "):
        line = line[len(prefix):] if line.startswith(prefix) else line
    code = re.match(r"\((EXR_ERR_\w+)\)\s*(.*)", line)
    reason = (f"{code[2]} ({code[1]})" if code else line) or (
        "no part of the image could be read" if "has 0 parts" in str(error)  # (the bindings'
        else f"{type(error).__name__}: {error}")  # words for a truncated file's pixels)
    if len(reason) > 200:
        reason = reason[:197] + "..."
    return f"`{arg}`: {path} is truncated or corrupt; OpenEXR: {reason}"


def _read_exr(path: Path, arg: str) -> dict[str, np.ndarray]:
    failed = None
    with _library_quiet() as said:
        try:
            import OpenEXR

            with OpenEXR.File(str(path), separate_channels=True) as f:
                header = dict(f.header())  # (before channels(), after which it lacks the
                ch = {k: np.asarray(v.pixels) for k, v in f.channels().items()}  # windows)
        except Exception as e:
            failed = e
    if failed is not None:
        raise ValueError(_exr_unreadable(path, arg, failed, said.text)) from None
    _pass_on(said.text)
    return _in_display_window(ch, header)


def _in_display_window(ch: dict[str, np.ndarray], header: dict) -> dict[str, np.ndarray]:
    """The channels `ch` of an EXR file placed in its display window (the image's size and
    place), where its data window (the pixels stored) differs: NaN outside the data window
    (0 in integer channels and alphas). A compositor's bounding-box crop (Nuke) stores only
    part of the frame: it was read at the data window's size, so a K or a mask of the frame
    missed it by the window's offset, without a word (a review)."""
    data, shown = header.get("dataWindow"), header.get("displayWindow")
    if data is None or shown is None:
        return ch
    (x0, y0), (x1, y1) = (tuple(int(v) for v in corner) for corner in data)
    (u0, v0), (u1, v1) = (tuple(int(v) for v in corner) for corner in shown)
    if (x0, y0, x1, y1) == (u0, v0, u1, v1):
        return ch
    H, W = v1 - v0 + 1, u1 - u0 + 1
    # the rows and columns the two windows share, in the display window's pixels
    r0, r1, c0, c1 = max(y0, v0), min(y1, v1), max(x0, u0), min(x1, u1)
    out = {}
    for name, a in ch.items():
        if a.shape[:2] != (y1 - y0 + 1, x1 - x0 + 1):  # (a subsampled channel: as stored)
            out[name] = a
            continue
        alpha = name.rpartition(".")[2].upper() in ("A", "ALPHA")
        fill = np.nan if a.dtype.kind == "f" and not alpha else 0
        placed = np.full((H, W) + a.shape[2:], fill, dtype=a.dtype)
        if r0 <= r1 and c0 <= c1:
            placed[r0 - v0:r1 - v0 + 1, c0 - u0:c1 - u0 + 1] = \
                a[r0 - y0:r1 - y0 + 1, c0 - x0:c1 - x0 + 1]
        out[name] = placed
    return out


def _normal_layer(layer: str) -> bool:
    """Whether an EXR layer's name says it holds normals: "normal" in it (Blender's
    ``ViewLayer.Normal``), or the whole name "N" or "nrm" (a compositor's ``N.X``, ``N.Y``,
    ``N.Z``, refused before, an audit; not ``Diffuse.N``), case aside."""
    return "normal" in layer.lower() or layer.lower() in ("n", "nrm")


#: EXR channel names (their last part, case aside) by the component they hold: Nuke writes
#: ``red``, ``green``, ``blue``, renderers ``R``/``r``, ``X``/``x`` (refused before, an audit).
_EXR_COMPONENTS = {"R": "R", "RED": "R", "G": "G", "GREEN": "G", "B": "B", "BLUE": "B",
                   "X": "X", "Y": "Y", "Z": "Z", "A": "A", "ALPHA": "A"}


def _exr_normal_channels(ch: dict, p: Path, arg: str,
                         count: int = 3) -> tuple[tuple[str, ...], str]:
    """The `count` channels of an EXR normal map (R, G, B or X, Y, Z, case aside, also
    ``red``/``green``/``blue``; the first two for a two-channel map) and its alpha's name. A
    multilayer file (Blender's: ``ViewLayer.Normal.X``, ...) without such bare channels gives
    its one layer whose name holds "normal" (case aside; or is called "N" or "nrm",
    :func:`_normal_layer`), or among several the one whose last part is "Normal" itself
    (Cycles writes ``ViewLayer.Denoising Normal`` beside it, refused before, an audit);
    otherwise the message lists the layers that could be it (a layer not named so, e.g. a
    File Output node's ``Image`` or a render's ``Combined``, is never guessed)."""
    layers: dict = {}  # layer -> {component: channel name}
    for key in ch:
        layer, _, last = key.rpartition(".")
        comp = _EXR_COMPONENTS.get(last.upper())
        if comp is not None:
            layers.setdefault(layer, {}).setdefault(comp, key)

    def alpha(layer):
        return layers[layer].get("A", f"{layer}.A" if layer else "A")

    bare = layers.get("", {})
    for axes in (("R", "G", "B")[:count], ("X", "Y", "Z")[:count]):
        if all(a in bare for a in axes):
            return tuple(bare[a] for a in axes), alpha("")
    found = [(layer, axes) for layer, have in sorted(layers.items()) if layer
             for axes in (("X", "Y", "Z")[:count], ("R", "G", "B")[:count])
             if set(axes) <= set(have)]
    normal = [(layer, axes) for layer, axes in found if _normal_layer(layer)]
    own = [(layer, axes) for layer, axes in normal
           if layer.rpartition(".")[2].strip().lower() == "normal"]
    pick = normal if len(normal) == 1 else own if len(own) == 1 else []
    if pick:
        layer, axes = pick[0]
        return tuple(layers[layer][a] for a in axes), alpha(layer)
    which = ("; a multilayer file needs one layer named normal (or N) with them, and its layers "
             f"with {('two', 'three')[count - 2]} components are "
             f"{', '.join(layer for layer, _ in found)}"
             + (" (more than one named normal or N: save the one you mean alone)"
                if len(normal) > 1 else ": save the normal pass alone, or as its own file")
             if found else "")
    want = "R, G, B or X, Y, Z" if count == 3 else "R, G or X, Y (a two-channel map)"
    if count == 3 and not which and any(all(c in bare for c in two) for two in (("R", "G"),
                                                                                 ("X", "Y"))):
        # (x and y alone: a two-channel map, read with the encoding that rebuilds z; named as
        # for a two-channel .npy or TIFF, a user's check)
        which = ("; x and y alone are a two-channel (BC5/RG) map: read it with "
                 "--normal-encoding xy (encoding='xy'), which rebuilds z")
    raise ValueError(f"`{arg}`: {p} must have channels {want}; got {sorted(ch)}{which}")


_PFM_HEADER = re.compile(rb"(PF|Pf)\s+(\d+)\s+(\d+)\s+([-+0-9.eE]+)\s")


def _pfm_header(data: bytes, path: Path, arg: str) -> tuple[int, int, int, bool, int]:
    """``(channels, width, height, little_endian, end)`` of a Portable Float Map's header in
    `data` (its first bytes; 256 hold any header), `end` where its pixels may begin."""
    head = _PFM_HEADER.match(data[:256])
    if head is None:
        raise ValueError(f"`{arg}`: {path} is not a Portable Float Map (it does not start with "
                         "'PF' or 'Pf', the width, the height and the scale; 'PF4', four "
                         "channels, is not read)")
    width, height = int(head[2]), int(head[3])
    try:
        scale = float(head[4])
    except ValueError:
        scale = float("nan")
    if not (np.isfinite(scale) and scale != 0):
        raise ValueError(f"`{arg}`: {path} has a scale of {head[4].decode()!r} in its header; "
                         "its sign gives the byte order (negative: little-endian), so it "
                         "must be a non-zero number")
    if width == 0 or height == 0:
        raise ValueError(f"`{arg}`: {path} declares an empty image ({width} x {height})")
    return 3 if head[1] == b"PF" else 1, width, height, scale < 0, head.end()


def _read_pfm(path: Path, arg: str) -> np.ndarray:
    """A Portable Float Map as (H, W) (``Pf``) or (H, W, 3) (``PF``) float32, rows from the top
    (the file stores them from the bottom). A negative scale means little-endian; its size is a
    brightness factor for HDR pictures, left out here (MiDaS writes 1)."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ValueError(f"`{arg}`: cannot read {path}: {e}") from None
    channels, width, height, little, end = _pfm_header(data, path, arg)
    want = width * height * channels * 4
    body = data[end:]
    if len(body) > want and not body[:len(body) - want].strip():
        body = body[len(body) - want:]  # (a header line ended by CR LF or trailing spaces)
    if len(body) != want:
        raise ValueError(f"`{arg}`: {path} holds {len(body):,} bytes of pixels where its "
                         f"header ({width} x {height}, {channels} channel(s)) asks for "
                         f"{want:,}: " + ("a truncated file" if len(body) < want else
                                          "bytes after the pixels: a damaged file"))
    a = np.frombuffer(body, dtype="<f4" if little else ">f4")
    a = a.reshape(height, width, channels)[::-1].astype(np.float32)
    return a[..., 0] if channels == 1 else a


def _read_npy(path: Path, arg: str) -> np.ndarray:
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError:
        magic = b"\x93NUMPY"  # (np.load says what is wrong)
    if magic.startswith(b"PK\x03\x04"):  # (an .npz archive named .npy, a review)
        raise ValueError(f"`{arg}`: {path} is an .npz archive (several arrays, zipped), not a "
                         ".npy file: save the one array with numpy.save")
    if magic != b"\x93NUMPY":  # (a text or other file named .npy: numpy spoke of pickled
        # data and allow_pickle, an audit)
        raise ValueError(f"`{arg}`: {path} is not a .npy file (it does not start with numpy's "
                         f"header; {'empty' if not magic else f'it starts with {magic!r}'}): "
                         "save the array with numpy.save")
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as e:
        raise ValueError(
            f"`{arg}`: {path} is not a readable .npy array ({type(e).__name__}: {e})"
        ) from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "biuf":
        raise ValueError(f"`{arg}`: {path} must hold a numeric array; got {arr.dtype}")
    return arr


def _check_png_normals(data: bytes, path: Path, arg: str) -> None:
    """Refuse palette and sub-8-bit PNGs as normal maps, from the IHDR chunk (greyscale ones
    fail the channel check)."""
    if len(data) < 26 or data[12:16] != b"IHDR":
        return  # not a PNG header; the decoder says what is wrong
    depth, colour = data[24], data[25]
    if colour == 3 or depth < 8:
        what = "palette (indexed colour)" if colour == 3 else f"{depth}-bit"
        raise ValueError(
            f"`{arg}`: {path} is a {what} PNG ({depth} bit per sample); a normal map must be "
            "8- or 16-bit RGB or RGBA (R, G, B = x, y, z)"
        )


def _counted(mask, alpha, shape) -> np.ndarray | None:
    """The pixels a normal map's checks look at (:func:`read_normals`: the grey check, the
    8/16-bit decode's unit-length share and zero plateaus, ``"unsigned"``'s signs): `mask`,
    given apart from the file (it replaces the alpha: the fill outside it may hold anything),
    else the file's `alpha` mask (None: every pixel). A `mask` of another size than `shape`
    ((H, W)) selects none: its caller refuses it naming its file, where a word on the pixels
    would mislead."""
    if mask is None:
        return alpha
    m = np.asarray(mask)
    return m.astype(bool) if m.shape == tuple(shape) else np.zeros(shape, bool)


def _decode_unit(pixels: np.ndarray, path: Path, arg: str, where=None, encoding: str = "xyz",
                 frame=None, normal_range: str = "signed") -> np.ndarray:
    """uint8/uint16 -> [-1, 1] per channel (:func:`facetlift.frames.decode`, its unit-length
    check and zero plateaus among `where`, the pixels :func:`_counted` names); float passes
    through, or with `normal_range` ``"unsigned"`` is decoded as ``2 v - 1``
    (:func:`facetlift.frames.decode_unsigned`, which refuses an integer map, and counts the
    signs among `where`); other dtypes are refused. `encoding` ``"xy"``: x and y alone, z
    rebuilt to face the viewer in `frame` (:func:`facetlift.frames.decode_xy`)."""
    # (another pixel type is refused below as it is without the option: the type is wrong)
    pixels = frames.native(pixels)  # (a big-endian >u2 .npy was refused as "not uint16")
    if normal_range == "unsigned" and (pixels.dtype.kind == "f"
                                       or pixels.dtype in frames.ENCODED_DTYPES):
        pixels = frames.decode_unsigned(pixels, f"`{arg}`: {path}", where,  # (refuses 8/16
                                        2 if encoding == "xy" else 3)  # bits)
        return frames.decode_xy(pixels, frame=frame) if encoding == "xy" else pixels
    if encoding == "xy" and (pixels.dtype in frames.ENCODED_DTYPES or pixels.dtype.kind == "f"):
        return frames.decode_xy(pixels, where=where, frame=frame)
    if pixels.dtype in frames.ENCODED_DTYPES:
        n = frames.decode(pixels, where=where, frame=frame)
        inside = frames._inside(n, where, sample=frames.CHECK_SAMPLE)
        if inside is not None and len(inside) and inside.min() >= -frames.UNSIGNED_STRAY:
            frames.check_integer_encoding(inside, f"`{arg}`: {path}")
        return n
    if pixels.dtype.kind == "f":
        return pixels.astype(np.float64)
    raise ValueError(
        f"`{arg}`: {path} has pixel type {pixels.dtype}; normal maps must be uint8, uint16 "
        "or floating point"
    )


def _split_alpha(pixels: np.ndarray, path: Path, arg: str, check: bool = True,
                 encoding: str = "xyz"):
    """``(colour channels, alpha mask or None)`` of a normal map's pixels: (H, W, 3) or
    (H, W, 4), or with `encoding` ``"xy"`` also (H, W, 2) from a .npy or TIFF file (x, y
    alone, no alpha). A two-channel PNG is grey + alpha (PNG has no two-colour format): refused
    for ``"xy"`` too, saying so; a two-channel array without ``"xy"`` is refused naming it."""
    png = path.suffix.lower() == ".png"
    two = pixels.ndim == 3 and pixels.shape[-1] == 2 and min(pixels.shape[:2]) >= 1
    if two and encoding == "xy" and not png:
        return pixels, None
    if pixels.ndim != 3 or pixels.shape[-1] not in (3, 4) or min(pixels.shape[:2]) < 1:
        channels = pixels.shape[-1] if pixels.ndim == 3 else (1 if pixels.ndim == 2 else None)
        if two and png:  # (a two-channel (x, y) map saved as PNG: its grey and alpha)
            why = ("; a two-channel PNG is grey + alpha, not x, y (PNG has no two-colour "
                   "format): store x, y in R and G of an RGB PNG (B is ignored with "
                   "--normal-encoding xy, encoding='xy'), or as a two-channel .npy, TIFF or "
                   "EXR file")
        elif two:
            # (a gradient field stacked as (H, W, 2) was told of normal maps alone, a review)
            why = ("; a two-channel map storing x and y alone (BC5, RG) is read with "
                   "--normal-encoding xy (encoding='xy'), which rebuilds z; a gradient field "
                   "(p, q) stacked so is given as two files, --gradients P Q "
                   "(integrate_gradients(a[..., 0], a[..., 1]) in Python)")
        else:
            first = pixels.ndim == 3 and pixels.shape[0] in (2, 3, 4) and pixels.shape[-1] > 4
            xy = (" (x, y alone: then (H, W, 2) with --normal-encoding xy)"
                  if first and pixels.shape[0] == 2 else "")
            why = ("; it looks channel-first (C, H, W): transpose it to (H, W, C), e.g. "
                   f"numpy.moveaxis(a, 0, -1){xy}" if first else "")
            if first:  # (not "(612 channel(s))" before the channel-first advice, an audit)
                channels = None
            elif pixels.ndim == 3 and pixels.shape[0] == 1 and pixels.shape[-1] > 4:
                channels = None  # (one grey image with a leading axis, a review)
                why = ("; it looks like one grey image (1, H, W): a height or a grey map "
                       "holds no normals (slopes p, q: --gradients P Q)")
            if pixels.ndim == 4 and pixels.shape[0] == 1:  # (a batch of one, an audit)
                channels = None
                why = ("; it looks like a batch of one (1, H, W, C): save a[0] instead"
                       + (" and read it with --normal-encoding xy (x, y alone)"
                          if pixels.shape[-1] == 2 and encoding != "xy" else "")
                       if pixels.shape[-1] in (2, 3, 4) else "; it looks like a batch of "
                       "one: save a[0] (moved to (H, W, 3) if channel-first) instead")
        raise ValueError(
            f"`{arg}`: {path} must be an (H, W, 3) RGB or (H, W, 4) RGBA normal map"
            + (", or (H, W, 2) x, y with --normal-encoding xy (.npy or TIFF)"
               if encoding == "xy" else "")
            + f"; got shape {pixels.shape}"
            + (f" ({channels} channel(s))" if channels is not None else "") + why
        )
    if pixels.shape[-1] == 4:
        return pixels[..., :3], _alpha_mask(pixels[..., 3], path, arg, check)
    return pixels, None


def _alpha_mask(alpha: np.ndarray, path=None, arg: str = "path",
                check: bool = True) -> np.ndarray | None:
    """``alpha > 0``, or None where that is the same everywhere: an opaque export (editors and
    OpenCV write alpha 255 over the background too) or a fully transparent one hold no mask,
    and the valid-normals rule decides (as for a mask file, :func:`read_mask`). With `check`,
    an alpha that looks like data rather than a mask is warned about (:func:`_alpha_levels`)."""
    m = alpha > 0
    if (m == m.flat[0]).all():
        return None
    if check:
        _alpha_levels(alpha, m, path, arg)
    return m


#: An alpha that makes the mask (:func:`_alpha_mask`) is warned about as holding data (a
#: height, as "normal + height" textures pack it) where its values strictly between 0 and its
#: largest cover more than ALPHA_DATA_SHARE of the image in more than ALPHA_DATA_LEVELS
#: distinct values, counting the pixels more than ALPHA_EDGE pixels from a transparent one and
#: from one at the largest value, and those ALPHA_RAMP pixels or more (Euclidean) from every
#: transparent pixel and every one at the largest value: the middle of a ramp wider than an
#: antialiased edge's band. (An audit: such a map integrated 15 % of its pixels, without a
#: word; a second: bricks with 5.5-texel bevels, 0 in the grooves and the largest on the
#: faces, had their in-between values within 2 px of both on all but 4.4 % of the pixels, in 6
#: levels, and went unwarned; their ramps' middles add 8 %, in 11 levels. A first ramp rule,
#: distances from any locally flat pixel, counted the middles of antialiased diagonal wires
#: 2-4 px wide, a chain-link fence's or a hair card's alpha: a review.) Measured
#: (2026-12-05): an antialiased ellipse's edge (exact coverage), the same edge blurred by a 2-
#: or 3-px box, and antialiased wires 1-6 px wide every 8-16 px, axis-aligned and at 45°,
#: have no in-between pixel 2 px from both extremes: silent. A feathered edge (a mask blurred
#: with a Gaussian of sigma 3 px) is a ramp too and warned about where it covers that share
#: (an ellipse 140 px across in a 256^2 image): every pixel of its soft band is taken as
#: inside, past the object; sigma 1 px stays silent. The levels: an alpha of flat translucent
#: areas (one or two values, besides 0 and its largest, with antialiased edges) stays silent;
#: a height has more, even bricks of three face heights.
ALPHA_DATA_SHARE, ALPHA_DATA_LEVELS, ALPHA_EDGE, ALPHA_RAMP = 0.05, 2, 2, 2


def _alpha_levels(alpha: np.ndarray, m: np.ndarray, p, arg: str) -> None:
    """Warn where the alpha that makes the mask `m` (``alpha > 0``) holds many grey levels
    away from its edge or on wide ramps (:data:`ALPHA_DATA_SHARE`): a height or other data in
    the alpha, or a feathered edge, of which every non-zero pixel is taken as inside. An
    antialiased object edge (a pixel or two wide, between the transparent and the opaque
    pixels) is no such sign."""
    from scipy import ndimage

    a = np.asarray(alpha)
    with np.errstate(invalid="ignore"):
        # (the largest over the mask: a NaN alpha is transparent, as ``alpha > 0`` makes it;
        # a.max() was NaN with one NaN pixel, and a height with NaN where the texture had
        # none was never warned about, a review)
        top = np.where(m, a, 0).max()
        between = m & (a < top)
    if between.sum() <= ALPHA_DATA_SHARE * a.size:  # (quick: most alphas are 0 and the max)
        return
    edge = ndimage.binary_dilation(~m | (a == top), iterations=ALPHA_EDGE)
    # (a ramp's middle: no transparent pixel and none at the largest value nearer than
    # ALPHA_RAMP; measured from any locally flat pixel instead, the middles of antialiased
    # diagonal wires 2-4 px wide, a chain-link fence's alpha, counted, a review)
    extreme = ~m | (a == top)
    k = int(np.ceil(ALPHA_RAMP)) - 1  # (a disk's dilation, a sixth of an exact distance's
    r, c = np.indices((2 * k + 1, 2 * k + 1)) - k  # time at 4096^2)
    near = r * r + c * c < ALPHA_RAMP**2
    ramp = ndimage.maximum_filter(extreme.view(np.uint8), footprint=near, mode="constant") == 0
    away = between & (~edge | ramp)
    if away.sum() <= ALPHA_DATA_SHARE * a.size:
        return
    levels = np.unique(a[away]).size
    if levels <= ALPHA_DATA_LEVELS:
        return
    warn(f"`{arg}`: {p}: its alpha channel holds {levels} distinct levels between 0 and its "
         f"largest, {top:g}, on {away.mean():.0%} of the pixels, away from its edge or on "
         "ramps wider than an antialiased edge (a height or other data packed in the alpha, "
         "as 'normal + height' textures do, or a feathered edge, whose whole soft band then "
         "counts as inside?): the alpha is "
         f"taken as the mask, every pixel with alpha > 0 inside ({int(m.sum())} of {m.size}) "
         "and the others left out. If the alpha is no mask, give one instead, which replaces "
         "it: --mask FILE (e.g. an image of the map's size, white where to integrate; for a "
         "feathered edge, its alpha thresholded at half its largest), or in Python your own "
         "`mask` to facetlift.integrate (None: every pixel with a valid normal)")


# --------------------------------------------------------------------------------------------
# readers


def read_normals(
    path, *, frame: str | None = None, y_down: bool = False, check_alpha: bool = True,
    encoding: str = "xyz", normal_range: str = "signed", mask=None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a normal map.

    Parameters
    ----------
    path : str or Path
        ``.png`` (8 or 16 bit RGB/RGBA), ``.tif``/``.tiff`` (uint8, uint16 or float, 3 or 4
        channels), ``.exr`` (HALF or FLOAT channels R, G, B or X, Y, Z, optionally A) or
        ``.npy`` ((H, W, 3) or (H, W, 4); float, or uint8/uint16 decoded like PNG pixels) or
        ``.pfm`` (a three-channel Portable Float Map, as stored; rows read the right way up).
        Palette and 1/2/4-bit PNGs, UINT EXR channels and other integer types are refused.
    frame : str, optional
        The frame the file stores: ``"opengl"`` (default: x right, y up, z toward the
        viewer), ``"directx"``, ``"opencv"`` or an axis string such as ``"x,-y,-z"``
        (:mod:`facetlift.frames`); the normals are converted to facetlift's.
    y_down : bool
        Alias of ``frame="directx"``: the file stores y pointing *down*.
    check_alpha : bool
        Warn where the alpha that makes `alpha_mask` holds many grey levels away from its
        edge (:func:`_alpha_levels`: a height packed in the alpha, all of it > 0 taken as
        inside). False where the caller has a mask of its own, which replaces the alpha (a
        given `mask` leaves the alpha unchecked too).
    encoding : {"xyz", "xy"}
        ``"xyz"`` (default): x, y, z in R, G, B. ``"xy"``: a two-channel map (BC5, "RG", as
        game engines compress tangent-space maps) storing x and y alone in R and G (8/16-bit
        values decoded as ``v / max * 2 - 1``, floats as stored; EXR channels R, G or X, Y;
        an (H, W, 2) .npy or two-channel TIFF, or the first two channels of an RGB(A) file:
        a two-channel PNG is grey + alpha and is refused);
        z is rebuilt as ``sqrt(max(0, 1 - x^2 - y^2))``, facing the viewer, and B, if any,
        is ignored (:func:`facetlift.frames.decode_xy`). An integer pixel whose x, y are
        longer than unit length (black or white fill) holds no normal; a mid-grey fill reads
        as a flat normal, so such a map needs its mask.
    normal_range : {"signed", "unsigned"}
        ``"signed"`` (default): float components stored as they are, in [-1, 1].
        ``"unsigned"``: a float map (EXR, float TIFF, .npy) storing ``(n + 1) / 2`` in [0, 1],
        as many renderers and networks write it, decoded as ``2 v - 1`` before anything else
        (with ``encoding="xy"``, x and y, before z is rebuilt); like an integer map's, a
        decoded vector that holds no normal (black, white or mid-grey fill) is NaN
        (:func:`facetlift.frames.decode_unsigned`). 8/16-bit maps are always decoded from
        their integer range and refuse it.
    mask : (H, W) array_like of bool, optional
        The object's mask where it is given apart from the file (a mask file's: ``--mask``, a
        dataset folder's ``mask.*``), which replaces the alpha: the checks look at the pixels
        inside it alone (the grey check; an 8/16-bit map's share of vectors longer than unit
        length, warned about, and its 8-bit zero plateaus, :func:`facetlift.frames.decode`;
        the components ``"unsigned"`` counts), so a fill outside it may hold anything (with a
        mask of another size none is looked at: the caller's size check refuses it, naming
        its file). It is not returned: `alpha_mask` is the file's.

    Returns
    -------
    normals : (H, W, 3) float64
        Normals, x right, y up, z toward the viewer, as decoded (not renormalised: that is
        done by :func:`facetlift.prepare`); NaN where an integer pixel holds no normal.
    alpha_mask : (H, W) bool or None
        ``alpha > 0`` where the file has an alpha channel that is not the same everywhere;
        None without one, or where every pixel is opaque (or every pixel transparent): such an
        alpha holds no mask, and the valid-normals rule of :func:`facetlift.prepare` decides.

    Raises
    ------
    ValueError
        Missing, corrupt or truncated file, wrong number of channels, unsupported pixel type
        or extension, a bad `frame`, `encoding` or `normal_range`; ``"unsigned"`` for an
        integer map, or for one with negative components (beyond
        :data:`facetlift.frames.UNSIGNED_SLACK`: signed normals); a grey image saved as RGB
        (R = G = B at every pixel inside `mask`, else inside the alpha where there is one:
        :func:`facetlift.frames.grey_check`).
        The message names the path.
    """
    arg = "path"
    frame = frames.resolve(frame, y_down)
    frames.parse(frame)
    encoding = frames.normal_encoding(encoding)
    normal_range = frames.normal_range(normal_range)
    p = _existing(path, arg)
    ext = _suffix(p, NORMAL_READ_FORMATS, "normal map", arg, reading_map=True)
    if ext in (".png", ".tif", ".tiff"):
        if ext == ".png":
            with open(p, "rb") as fh:
                _check_png_normals(fh.read(26), p, arg)
        pixels = _decode_image(p, ext, arg)
        rgb, alpha = _split_alpha(pixels, p, arg, check_alpha and mask is None, encoding)
        counted = _counted(mask, alpha, rgb.shape[:2])
        if rgb.shape[-1] == 3:  # (R = G = B: no two-channel map's sign)
            frames.grey_check(rgb, counted, f"`{arg}`: {p}")
        n = _decode_unit(rgb, p, arg, counted, encoding, frame, normal_range)
    elif ext == ".exr":
        ch = _read_exr(p, arg)
        names, alpha_name = _exr_normal_channels(ch, p, arg, 2 if encoding == "xy" else 3)
        ints = [c for c in names if ch[c].dtype.kind in "iu"]
        if ints:
            raise ValueError(
                f"`{arg}`: {p} has integer (UINT) channel(s) {ints}; normal maps in EXR must be "
                "HALF or FLOAT, holding the components themselves"
            )
        n = np.stack([ch[c] for c in names], axis=-1).astype(np.float64)
        alpha = (_alpha_mask(ch[alpha_name], p, arg, check_alpha and mask is None)
                 if alpha_name in ch else None)
        counted = _counted(mask, alpha, n.shape[:2])
        frames.grey_check(n, counted, f"`{arg}`: {p}")
        if normal_range == "unsigned":
            n = frames.decode_unsigned(n, f"`{arg}`: {p}", counted, n.shape[-1])
        if encoding == "xy":
            n = frames.decode_xy(n, frame=frame)
    else:  # (.npy, or a Portable Float Map: float, as stored)
        arr = _read_npy(p, arg) if ext == ".npy" else _decode_image(p, ext, arg)
        rgb, alpha = _split_alpha(arr, p, arg, check_alpha and mask is None, encoding)
        counted = _counted(mask, alpha, rgb.shape[:2])
        if rgb.shape[-1] == 3:
            frames.grey_check(rgb, counted, f"`{arg}`: {p}")
        # (uint8/uint16 arrays decode like PNG pixels)
        n = _decode_unit(rgb, p, arg, counted, encoding, frame, normal_range)
    return frames.to_facetlift(n, frame), alpha


#: A mask whose inside pixels next to the outside (within 2 pixels) hold at least
#: SOFT_EDGE_VALUES distinct values below its largest, on SOFT_EDGE_SHARE of its inside pixels
#: or more (an antialiased or blurred edge), gets a warning (:func:`read_mask`). (Label masks,
#: 0/1/2 with every non-zero inside, have few values: no warning, a review.)
SOFT_EDGE_SHARE, SOFT_EDGE_VALUES = 0.01, 4
#: Width (pixels) of the band along the mask's edge that :func:`_soft_edge_check` looks at.
SOFT_EDGE_BAND = 8


def _soft_edge_check(plane: np.ndarray | None, m: np.ndarray, p, arg: str) -> None:
    """Warn where the mask's `plane` (its grey values, or the alpha that makes it) holds
    in-between values along its edge, as an antialiased edge does: all of them count as
    inside, a halo around the object (a user's bear mask with blurred edges grew by 2,549
    pixels, whose normals were then missing and filled)."""
    from scipy import ndimage

    if plane is None or not m.any() or m.all():
        return
    top = plane[m].max()
    # (a band of SOFT_EDGE_BAND pixels: a mask feathered by a blur of 3 px saved as 8 bits
    # holds only the levels 1-3 in its outer 2 pixels, and its 15,745 in-between pixels went
    # unwarned, an audit)
    edge = m & ndimage.binary_dilation(~m, iterations=SOFT_EDGE_BAND)
    soft = edge & (plane < top)
    if soft.sum() < SOFT_EDGE_SHARE * m.sum() or np.unique(plane[soft]).size < SOFT_EDGE_VALUES:
        return
    warn(f"`{arg}`: {p}: {int(soft.sum())} of its {int(m.sum())} inside pixels, along its edge, "
         f"hold values between 0 and its largest, {top:g} (an antialiased or blurred edge?): "
         "every non-zero pixel is inside, so the mask reaches past the object's edge; "
         f"threshold it (e.g. at half of {top:g}) if those pixels hold no normal of the object")


def read_mask(path, shape: tuple[int, int] | None = None, *, of: str = "the normal map"
              ) -> np.ndarray:
    """Read a mask image: a value above 0 is inside (a warning where many inside pixels hold
    values below the largest: an antialiased edge, :func:`_soft_edge_check`; and where a
    float or signed one-channel map holds negative values, which count as outside).

    Parameters
    ----------
    path : str or Path
        ``.png``, ``.tif``/``.tiff``, ``.npy`` or ``.pfm``; grey, grey+alpha, RGB or RGBA. A
        colour pixel is inside when any of its colour channels is nonzero and its alpha, if
        any, is > 0; an alpha that is the same everywhere is ignored, and with one colour
        everywhere the alpha alone is the mask.
    shape : (H, W), optional
        Required shape (that of the normal map).
    of : str
        What `shape` is the size of, for the message where the mask's differs ("the gradient
        field" for one: it was told of a normal map, a review).

    Returns
    -------
    (H, W) bool

    Raises
    ------
    ValueError
        Missing or corrupt file, unsupported extension or layout, or a shape other than `shape`.
    """
    arg = "mask"
    p = _existing(path, arg)
    ext = _suffix(p, MASK_FORMATS, "mask", arg)
    a = _decode_image(p, ext, arg) if ext != ".npy" else _read_npy(p, arg)
    plane = None  # (the values whose in-between levels would be an antialiased edge)
    if a.ndim == 3 and a.shape[-1] in (1, 2, 3, 4):
        colour = a[..., :3] if a.shape[-1] >= 3 else a[..., :1]
        m = (colour != 0).any(-1)
        plane = a[..., 0] if a.shape[-1] in (1, 2) else None
        if a.shape[-1] in (2, 4):
            alpha = a[..., -1] > 0
            if not (alpha == alpha.flat[0]).all():  # (a constant alpha, e.g. 0 in a
                # colour-only export, says nothing; with one colour everywhere the shape is
                # in the alpha alone)
                one = (colour == colour.flat[0]).all()
                m = alpha if one else m & alpha
                plane = a[..., -1] if one else plane
    elif a.ndim == 2:
        from ..problem import negatives_outside

        m = negatives_outside(a, f"`{arg}` {p}")  # (a float or signed map's negatives: out)
        plane = a
    else:
        raise ValueError(
            f"`{arg}`: {p} must be an (H, W) image or have 1-4 channels; got shape {a.shape}"
        )
    if min(m.shape) < 1:
        raise ValueError(f"`{arg}`: {p} is empty (shape {a.shape})")
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ValueError(f"`{arg}`: {p} contains NaN or inf")
    _soft_edge_check(plane, m, p, arg)
    return check_mask_size(m, p, shape, of=of)


def check_mask_size(m: np.ndarray, path, shape: tuple[int, ...] | None, *,
                    of: str = "the normal map") -> np.ndarray:
    """`m`, the mask :func:`read_mask` read from `path`, where it is of `shape` ((H, W), or
    the normal map's (H, W, C); None: any); a ValueError naming `mask`, `path`, both sizes
    and `of` otherwise. Apart from :func:`read_mask` for a mask read before its map (whose
    pixels are those its range check counts: :func:`read_normals`' `mask`)."""
    if shape is not None and len(tuple(shape)) == 3:  # (the normal map's own shape, H x W x 3)
        shape = tuple(shape)[:2]
    if shape is not None and m.shape != tuple(shape):
        raise ValueError(
            f"`mask`: {path} has size {m.shape[0]}x{m.shape[1]} (HxW) but {of} is "
            f"{shape[0]}x{shape[1]}"
        )
    return m


def read_plane(path, formats, what: str, arg: str, prefer: tuple[str, ...] = (),
               mat_names: tuple[str, ...] = (), npz_names: tuple[str, ...] = ("depth",),
               grey: bool = False) -> np.ndarray:
    """One (H, W) array as stored: ``.npy``, OpenEXR (its channel named in `prefer`, or its
    only channel), TIFF, a MATLAB ``.mat`` file (its variable named in `mat_names`, or its
    only (H, W) one) or a ``.npz`` archive (its array named first in `npz_names`, or its only
    one). Shared by :func:`read_depth` and the gradient readers."""
    p = _existing(path, arg)
    ext = _suffix(p, formats, what, arg)
    if ext == ".npy":
        a = _read_npy(p, arg)
    elif ext == ".mat":
        a = _read_mat_plane(p, arg, mat_names, what)
    elif ext == ".npz":  # (Surface.save's archive: its depth)
        a = _read_npz_depth(p, arg, npz_names)
    elif ext == ".exr":
        ch = _read_exr(p, arg)
        name = next((c for c in prefer if c in ch), next(iter(ch)) if len(ch) == 1 else None)
        if name is None and ch and grey:  # (a grey depth saved as R, G, B: one map,
            # refused before, a review; not for gradients, where R, G, B is a normal map)
            first = next(iter(ch.values()))
            if all(np.array_equal(v, first, equal_nan=True) for v in ch.values()):
                name = next(iter(ch))
        if name is None:
            wanted = f"channel {' or '.join(prefer)} or one channel" if prefer else "one channel"
            raise ValueError(f"`{arg}`: {p} must hold {wanted}; got channels {sorted(ch)}")
        a = ch[name]
    else:
        a = _decode_image(p, ext, arg)
    if a.ndim != 2:
        raise ValueError(f"`{arg}`: {p} must hold an (H, W) {what} map; got shape {a.shape}")
    return a


def load_mat(p: Path, arg: str, then: str = "pass the arrays") -> dict:
    """The variables of a MATLAB ``.mat`` file (v4 to v7) by :func:`scipy.io.loadmat`; a
    ValueError naming `arg` for a v7.3 (HDF5) or unreadable file (`then`: what to do with
    h5py's arrays instead)."""
    from scipy import io as sio

    try:
        return sio.loadmat(p)
    except NotImplementedError:
        raise ValueError(
            f"`{arg}`: {p} is a MATLAB v7.3 (HDF5) file, which scipy cannot read; save it "
            f"with save(..., '-v7') in MATLAB, or read it with h5py and {then} (h5py gives "
            "MATLAB's arrays transposed, (W, H): take each one's .T, e.g. f['p'][()].T)"
        ) from None
    except Exception as e:
        raise ValueError(
            f"`{arg}`: {p} is not a readable .mat file ({type(e).__name__}: {e})") from None


def _read_mat_plane(p: Path, arg: str, names: tuple[str, ...], what: str) -> np.ndarray:
    """The (H, W) numeric variable of a ``.mat`` file named first in `names`, or its only one
    (a 1 x N or scalar variable is no map: Quéau's scalar ``lambda``); a ValueError lists
    the variables otherwise."""
    data = load_mat(p, arg, "pass the array")
    plane = {k: np.asarray(v) for k, v in data.items() if not k.startswith("__")
             and np.asarray(v).ndim == 2 and min(np.shape(v)) > 1
             and np.asarray(v).dtype.kind in "biuf"}
    name = next((n for n in names if n in plane), next(iter(plane)) if len(plane) == 1 else None)
    if name is None:
        found = {k: "x".join(map(str, np.shape(v))) for k, v in data.items()
                 if not k.startswith("__")}
        raise ValueError(f"`{arg}`: {p} must hold one (H, W) numeric {what} map, or one "
                         f"named {', '.join(names)}; got variables "
                         + (", ".join(f"{k} ({v})" for k, v in sorted(found.items())) or "none"))
    return plane[name]


def _read_npz_depth(p: Path, arg: str, wanted: tuple[str, ...] = ("depth",)) -> np.ndarray:
    """The array of an ``.npz`` archive named first in `wanted` (a
    :meth:`facetlift.Surface.save` archive's ``depth``), or its only array."""
    names = None
    try:
        z = np.load(p, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):  # (a .npy saved under the .npz name)
            return np.asarray(z)
        with z:
            names = sorted(z.files)
            name = next((n for n in wanted if n in names),
                        names[0] if len(names) == 1 else None)
            if name is not None:
                return np.asarray(z[name])
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as e:
        raise ValueError(f"`{arg}`: {p} is not a readable .npz archive ({e})") from None
    raise ValueError(f"`{arg}`: {p} must hold an array named "
                     f"{' or '.join(repr(n) for n in wanted)} or a single array; got {names}")


def read_depth(path, *, npz_names: tuple[str, ...] = ("depth",), arg: str = "path",
               zero_unknown: bool = False) -> np.ndarray:
    """Read an (H, W) depth map written by :func:`write_depth` (``.npy``, ``.exr``, TIFF), a
    one-channel ``.pfm`` (Middlebury's, MiDaS's), a MATLAB ``.mat`` file (its variable named
    first in `npz_names`, else ``z`` or ``Z``, else its only (H, W) one) or the ``depth`` of a
    :meth:`facetlift.Surface.save` ``.npz``; an OpenEXR file's channel Z, its only one, or
    R, G, B that are all equal (a grey image); a ``height.exr`` of
    :func:`facetlift.io.write_height` (marked so in its header) is read back as depth.

    `npz_names`: the arrays of a ``.npz`` looked for, in order (else its only one): a
    ground truth's, e.g. ``("depth_gt", "depth")`` for BiNI's DiLiGenT ``depth_gt.npz``.
    `arg`: the argument the messages name. `zero_unknown`: in an integer array (a sensor's
    16-bit TIFF) 0 means no depth and becomes NaN."""
    # (a MATLAB .mat too: DiLiGenT's ground truth and the toolboxes' results are stored so,
    # and were refused, a review; its variable as an .npz's, or Quéau's z)
    a = read_plane(path, DEPTH_FORMATS + (".npz", ".pfm", ".mat"), "depth", arg,
                   prefer=("Z",), npz_names=tuple(npz_names),
                   mat_names=tuple(npz_names) + ("z", "Z"), grey=True)
    integer = a.dtype.kind in "ui"
    a = a.astype(np.float64)
    if Path(path).suffix.lower() == ".exr" and _exr_quantity(Path(path)) == "height":
        # (facetlift's height.exr: its heights were taken for depths, the sign silently
        # wrong, an audit; "0.0 -" keeps 0 from becoming -0.0)
        a = 0.0 - a
    if zero_unknown and integer:
        a[a == 0] = np.nan
    return a


# --------------------------------------------------------------------------------------------
# encoding


#: The EXR header attribute that marks what a one-channel image of facetlift's holds
#: (:func:`facetlift.io.write_height` writes ``"height"``: :func:`read_depth` then reads it
#: back as depth, ``-height``).
EXR_QUANTITY = "facetlift_quantity"


def _write_exr(path: Path, channels: dict[str, np.ndarray], quantity: str | None = None) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if quantity is not None:
        header[EXR_QUANTITY] = quantity
    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    with atomic_path(path) as tmp:
        try:
            with OpenEXR.File(header, data) as f:
                f.write(str(tmp))
        except RuntimeError as e:  # the bindings report every write failure this way
            # (with an errno and the target, not the temporary file: the command line then
            # says which output failed and that nothing was written, as for the others, an
            # audit)
            import errno

            why = str(e).replace(str(tmp), str(path))
            code = errno.EIO if os.access(Path(tmp).parent, os.W_OK) else errno.EACCES
            raise OSError(code, f"cannot write as OpenEXR: {why}", str(path)) from None


def _write_tiff(path: Path, arr: np.ndarray) -> None:
    import tifffile

    with atomic_path(path) as tmp:
        photometric = "rgb" if arr.ndim == 3 and arr.shape[-1] in (3, 4) else "minisblack"
        extra = "unassalpha" if arr.ndim == 3 and arr.shape[-1] == 4 else None
        tifffile.imwrite(
            tmp, arr, photometric=photometric, extrasamples=extra, compression="zlib"
        )


def _write_png(path: Path, pixels: np.ndarray, text: dict | None = None) -> None:
    """`pixels` as a PNG, with `text` (keyword: value, Latin-1) as tEXt chunks before its
    end."""
    import imagecodecs

    data = imagecodecs.png_encode(np.ascontiguousarray(pixels))
    if text:
        data = _png_text(data, text)
    _write_bytes(path, data)


def _png_text(png: bytes, text: dict) -> bytes:
    """`png` with a tEXt chunk per item of `text` inserted before its IEND chunk (the last 12
    bytes of an encoder's output)."""
    import struct
    import zlib

    end = png.rindex(b"IEND") - 4
    chunks = []
    for key, value in text.items():
        body = b"tEXt" + key.encode("latin-1") + b"\0" + str(value).encode("latin-1")
        chunks.append(struct.pack(">I", len(body) - 4) + body
                      + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF))
    return png[:end] + b"".join(chunks) + png[end:]


def png_text(path) -> dict:
    """The tEXt chunks of the PNG file `path` as a dict (keyword: value): e.g. the depths of
    ``height.png``'s 0 and 65535 (:func:`facetlift.io.write_height`)."""
    import struct

    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path} is not a PNG file")
    out, at = {}, 8
    while at + 8 <= len(data):
        size, kind = struct.unpack(">I4s", data[at:at + 8])
        if kind == b"tEXt":
            key, _, value = data[at + 8:at + 8 + size].partition(b"\0")
            out[key.decode("latin-1")] = value.decode("latin-1")
        if kind == b"IEND":
            break
        at += 12 + size
    return out


def _image_array(a, name: str, ndim: int) -> np.ndarray:
    arr = numeric_array(a, name)
    if arr.ndim != ndim or min(arr.shape[:2], default=0) < 1:
        want = "(H, W)" if ndim == 2 else "(H, W, 3)"
        raise ValueError(f"`{name}` must have shape {want}; got {arr.shape}")
    return arr


# --------------------------------------------------------------------------------------------
# writers


def write_depth(path, depth) -> Path:
    """Write an (H, W) depth map: ``.npy`` (float64), ``.exr`` (float32, channel Z) or
    ``.tif``/``.tiff`` (float32). NaN (outside the domain) is kept. Returns the path."""
    p = _file_name(path)
    ext = _suffix(p, DEPTH_FORMATS, "depth", "path")
    d = _image_array(depth, "depth", 2).astype(np.float64)
    if ext == ".npy":
        _save_npy(p, d)
    elif ext == ".exr":
        _write_exr(p, {"Z": d})
    else:
        _write_tiff(p, d.astype(np.float32))
    return p


def write_normals(
    path, normals, mask=None, *, bits: int = 16, frame: str | None = None, y_down: bool = False
) -> Path:
    """Write a normal map (the inverse of :func:`read_normals`).

    Parameters
    ----------
    path : str or Path
        ``.png`` (RGB, or RGBA with the mask as alpha), ``.tif``/``.tiff``, ``.exr`` (R, G, B
        and A for the mask) or ``.npy`` ((H, W, 3), or (H, W, 4) with the mask).
    normals : (H, W, 3) float, or uint8/uint16 encoded as ``(n + 1) / 2 * max``
        Written as given where every component lies in [-1, 1] and the length is one
        :func:`read_normals` takes for a normal; other vectors are made unit length first
        (:func:`facetlift.integrate` reads any length: only the direction counts). NaN and
        zero-length ones are written as 0 (PNG/integer TIFF: decode as NaN again). Integer
        input is decoded first, with the warning integrate gives.
    mask : (H, W) bool, optional
        Stored as the alpha channel (a mask True everywhere is stored, but reads back as no
        mask: :func:`read_normals` ignores an alpha that is the same everywhere).
    bits : {8, 16, 32}
        PNG: 8 or 16 bit per channel; TIFF: 8, 16 (integer) or 32 (float32). Ignored for EXR
        (float32) and npy (float64).
    frame : str, optional
        Store the normals in this frame (:mod:`facetlift.frames`; default facetlift's).
    y_down : bool
        Alias of ``frame="directx"``: store y pointing down.
    """
    p = _file_name(path)
    ext = _suffix(p, NORMAL_WRITE_FORMATS, "normal map", "path")
    allowed = {".png": (8, 16), ".tif": (8, 16, 32), ".tiff": (8, 16, 32)}
    if ext in allowed and bits not in allowed[ext]:  # (before any decoding and its warning)
        raise ValueError(f"`bits` must be one of {allowed[ext]} for {ext}; got {bits!r}")
    normals, hidden = frames.masked_pixels(normals)
    raw = _image_array(normals, "normals", 3)
    if raw.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {raw.shape}")
    m = None
    if mask is not None:
        from ..problem import unmasked

        m = np.asarray(unmasked(mask, 0.0)) != 0  # (a masked mask's entries: outside)
        if m.shape != raw.shape[:2]:
            raise ValueError(f"`mask` must have shape {raw.shape[:2]}; got {m.shape}")
    # (as integrate reads them: an 8/16-bit encoded map decoded, with its warning, and every
    # vector made unit length; clipped component by component, a (-p, -q, 1) field came back
    # 26 deg off and a uint8 map as all (1, 1, 1), an audit. No frame checks: a map is
    # written, not integrated)
    n = np.array(frames.as_float_normals(raw, "normals", m, hidden), dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        length = np.sqrt(np.einsum("...i,...i->...", n, n))
        # (written as given where that keeps the direction and reads back as a normal, so a
        # decoded map round-trips to the last bit; made unit where a component lies beyond
        # +-1, which the encoding would clip, or the length is one the reader takes for a
        # background fill; zero-length ones NaN)
        lo, hi = frames.ENCODED_LENGTH_RANGE
        off = ~((np.abs(n).max(axis=-1) <= 1.0) & (length >= lo) & (length <= hi))
        n = np.where(off[..., None], np.where((length > 0)[..., None],
                                              n / length[..., None], np.nan), n)
    n = frames.from_facetlift(n, frames.resolve(frame, y_down))
    if ext == ".exr":
        ch = {"R": n[..., 0], "G": n[..., 1], "B": n[..., 2]}
        if m is not None:
            ch["A"] = m.astype(np.float32)
        _write_exr(p, ch)
        return p
    if ext == ".npy":
        _save_npy(p, n if m is None else np.dstack([n, m.astype(np.float64)]))
        return p
    if bits == 32:
        px = n.astype(np.float32)
        alpha = None if m is None else m.astype(np.float32)
    else:
        dtype = np.uint8 if bits == 8 else np.uint16
        maxval = np.iinfo(dtype).max
        v = np.round((np.clip(np.nan_to_num(n, nan=-1.0), -1, 1) + 1) / 2 * maxval)
        px = v.astype(dtype)
        alpha = None if m is None else (m * maxval).astype(dtype)
    if alpha is not None:
        px = np.dstack([px, alpha])
    if ext == ".png":
        _write_png(p, px)
    else:
        _write_tiff(p, px)
    return p


def write_mask(path, mask) -> Path:
    """Write an (H, W) mask: PNG or TIFF (8-bit, 255 inside) or ``.npy`` (bool)."""
    p = _file_name(path)
    ext = _suffix(p, MASK_WRITE_FORMATS, "mask", "path")  # (a .pfm is read, not written)
    from ..problem import finite_values, unmasked

    # (masked entries: outside; NaN refused as integrate refuses it, a review)
    m = finite_values(_image_array(unmasked(mask, 0.0), "mask", 2), "mask") != 0
    if ext == ".npy":
        _save_npy(p, m)
    elif ext == ".png":
        _write_png(p, m.astype(np.uint8) * 255)
    else:
        _write_tiff(p, m.astype(np.uint8) * 255)
    return p


# --------------------------------------------------------------------------------------------
# fusion inputs: depth priors and weight maps (docs/fusion.md)

#: Formats of a depth prior (16-bit PNG needs a scale) and of weight maps (a MATLAB file:
#: the variable of one of the names :func:`read_prior` and :func:`read_weights` look for, or
#: its only (H, W) one).
PRIOR_FORMATS = (".npy", ".exr", ".tif", ".tiff", ".png", ".mat", ".pfm")

#: Variable names of a ``.mat`` depth prior (Quéau's toolbox calls it ``z0``), of the
#: normals' confidence and of the prior's weight map (Quéau's ``lambda``, the weight of
#: ``z0``: no confidence of the normals), in the order looked for.
MAT_PRIOR_NAMES = ("z0", "prior", "depth", "z", "Z")
MAT_CONFIDENCE_NAMES = ("confidence", "weights", "weight", "w")
MAT_PRIOR_WEIGHT_NAMES = ("lambda", "prior_weight", "weights", "weight", "w")


#: Text files of depth samples as points, one per line (:func:`read_prior`). (Not ``.xyz``:
#: that is usually world coordinates, which would be read as pixels where they fit.)
PRIOR_POINT_FORMATS = (".csv", ".txt")

#: Column names a points file's header may use (lower case) -> what they hold. ``x``/``u``
#: is a column (to the right), ``y``/``v`` a row (down, from the top): OpenCV's image axes.
_POINT_COLUMNS = {"row": "row", "r": "row", "y": "row", "v": "row",
                  "col": "col", "column": "col", "c": "col", "x": "col", "u": "col",
                  "depth": "depth", "z": "depth", "d": "depth",
                  "weight": "weight", "weights": "weight", "confidence": "weight"}


def read_prior(path, scale: float | None = None, *, arg: str = "prior",
               scale_arg: str = "prior_scale", zero_unknown: bool = True):
    """A depth prior: an (H, W) map, NaN where unknown, or from a points file a ``(rows,
    cols, depths)`` triple (:func:`facetlift.integrate`'s other form of `prior`).

    ``.npy``, OpenEXR (channel Z or the only one), TIFF, a one-channel PFM, a MATLAB ``.mat``
    file (its variable of :data:`MAT_PRIOR_NAMES`, e.g. Quéau's ``z0``, or its only (H, W)
    one) and a
    :meth:`facetlift.Surface.save` ``.npz`` (its ``depth``: an earlier result) hold depth as
    stored (NaN, or 0 in an integer TIFF, where unknown); a 16-bit PNG holds
    ``depth / scale`` (`scale` in depth units per count, e.g. 0.001 for millimetres stored as
    metres; 0 = unknown), and `scale` is required for it. A given `scale` multiplies the
    other formats too.

    A points file (``.csv``, ``.txt``: sparse samples, e.g. SfM or LiDAR points projected
    with K) holds one sample per line, numbers separated by commas, semicolons or white
    space, under a header line that names the columns in any order: ``row``/``y``/``v``,
    ``col``/``x``/``u`` (pixel positions from the top left, OpenCV's image axes; fractional
    ones go to the nearest pixel, samples in one pixel are averaged) and ``depth``/``z``, and
    optionally ``weight``/``confidence``: each point's weight (>= 0, times ``prior_weight``;
    the points are then returned with a fourth array, :func:`facetlift.problem.prior_samples`);
    other named columns are ignored, names may be quoted, ``#`` starts a comment. The header
    is required: ``row col depth`` and ``u v depth`` files look alike, and one read as the
    other transposes every sample.

    `arg` and `scale_arg` are the names the messages give the file and the scale (a ground
    truth read alike: ``facetlift evaluate --gt --gt-scale``). `zero_unknown` False keeps an
    integer file's 0 as a value (a relative depth or disparity scaled to start at 0, aligned
    by ``prior_fit``: its farthest or nearest samples were dropped without a word, an
    audit; with a camera the fitted route leaves exact zeros out all the same, with a
    warning that counts them).

    Raises
    ------
    ValueError
        An unreadable file, a PNG that is not 16-bit or without `scale`, or a bad `scale`; a
        points file without a header naming the three columns, with lines of other lengths or
        words, or with no sample.
    """
    p = _existing(path, arg)
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"`{scale_arg}` must be a positive number; got {scale!r}")
    if p.suffix.lower() in PRIOR_POINT_FORMATS:
        rows, cols, depths, *weights = _read_points(p, arg)
        return (rows, cols, depths if scale is None else depths * float(scale), *weights)
    maps = PRIOR_FORMATS + (".npz",)  # (an earlier result's archive: its depth)
    ext = _suffix(p, maps + PRIOR_POINT_FORMATS, "depth prior", arg)
    if ext == ".png":
        a = _decode_image(p, ext, arg)
        if a.dtype != np.uint16 or a.ndim != 2:
            # (Depth Anything's run.py writes its relative output as an 8-bit PNG: refused
            # with no way forward, an audit)
            eight = (": an 8-bit map holds too few levels for a depth (a network's relative "
                     "output as its demo writes it? save its float output as .npy, or give "
                     "this one as .npy, np.save('prior.npy', imageio.imread(path)), with "
                     "--prior-fit)" if a.dtype == np.uint8 else "")
            raise ValueError(f"`{arg}`: {p} must be a single-channel 16-bit PNG (depth / scale); "
                             f"got dtype {a.dtype}, shape {a.shape}{eight}")
        if scale is None:
            flag = "--" + scale_arg.replace("_", "-")
            where = f"{scale_arg}= in Python; " if scale_arg == "prior_scale" else ""
            raise ValueError(f"`{arg}`: {p} is a 16-bit PNG: give its depth units per count "
                             f"with {flag} ({where}e.g. 0.001 for millimetres in metres)"
                             + ("; a relative depth or disparity (a monocular network's) has "
                                "none: give --prior-fit affine or disparity instead, which takes "
                                "its scale from the normals (in Python any scale, e.g. 1, and "
                                "integrate's prior_fit=)" if scale_arg == "prior_scale" else ""))
        return np.where((a > 0) | (not zero_unknown), a * float(scale), np.nan)
    a = read_plane(p, maps, "depth prior", arg, prefer=("Z",), mat_names=MAT_PRIOR_NAMES)
    integer = a.dtype.kind in "ui"
    a = a.astype(np.float64)
    if p.suffix.lower() == ".exr" and _exr_quantity(p) == "height":  # (as read_depth)
        a = 0.0 - a
    if integer and zero_unknown:
        a[a == 0] = np.nan
    return a if scale is None else a * float(scale)


def _text_rows(p: Path) -> list[str]:
    """The non-blank lines of a small text table (points, intrinsics), `#` comments cut,
    commas, semicolons and tabs read as spaces, a byte-order mark dropped ("utf-8-sig": a
    spreadsheet's "CSV UTF-8" starts with one). Raises OSError or UnicodeDecodeError."""
    rows = []
    for ln in p.read_text(encoding="utf-8-sig").splitlines():
        ln = ln.split("#", 1)[0]
        for sep in ",;\t":
            ln = ln.replace(sep, " ")
        if ln.strip():
            rows.append(ln)
    return rows


def _loadtxt_reason(e: Exception) -> str:
    """numpy.loadtxt's error without its advice on its own arguments ("use `usecols`"),
    which means nothing to the reader of a file."""
    return str(e).split("; use `usecols`")[0].strip()


def _read_points(p: Path, arg: str):
    """(rows, cols, depths) of a points file (:func:`read_prior`)."""
    try:
        lines = _text_rows(p)
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"`{arg}`: cannot read {p} as a text file of points ({e})") from None
    if not lines:
        raise ValueError(f"`{arg}`: {p} holds no sample")
    header = [w.strip("\"'").lower() for w in lines[0].split()]
    names = [_POINT_COLUMNS.get(w) for w in header]
    twice = [n for n in ("row", "col", "depth", "weight") if names.count(n) > 1]
    if twice and not all(_numeric(w) for w in header):
        # (a LiDAR user's 'u,v,depth,x,y,z' and 'u,v,z,r' (r: reflectivity) were told that
        # the header was missing)
        said = "; ".join(
            f"{' and '.join(repr(w) for w, m in zip(header, names, strict=True) if m == n)} "
            f"{'both' if names.count(n) == 2 else 'all'} name the {n}" for n in twice)
        raise ValueError(
            f"`{arg}`: {p}: the header names a column twice ({said}): keep one name per "
            "column (row/y/v/r, col/x/u/c, depth/z/d, weight/confidence are taken; rename "
            "other columns, e.g. 'reflectivity', which is then ignored)")
    if all(_numeric(w) for w in header) or sorted(n for n in names if n and n != "weight") != [
            "col", "depth", "row"]:
        raise ValueError(
            f"`{arg}`: {p}: the first line must be a header naming the columns: row (or y, v), "
            "col (or x, u) and depth (or z), e.g. 'u,v,depth' or 'row col depth'; got "
            f"{lines[0].strip()!r} (without a header, 'row col depth' and 'u v depth' files "
            "look alike)")
    if len(lines) == 1:
        raise ValueError(f"`{arg}`: {p} holds no sample")
    try:
        a = np.loadtxt(lines[1:], dtype=float, ndmin=2)
    except ValueError as e:
        raise ValueError(f"`{arg}`: {p}: a line that is not {len(header)} numbers "
                         f"({_loadtxt_reason(e)})") from None
    if a.shape[1] != len(header):
        raise ValueError(f"`{arg}`: {p}: lines of {a.shape[1]} numbers under a header of "
                         f"{len(header)} columns")
    col = {n: a[:, k] for k, n in enumerate(names) if n}
    if "weight" not in col:
        return col["row"], col["col"], col["depth"]
    w = col["weight"]
    bad = ~(np.isfinite(w) & (w >= 0))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"`{arg}`: {p}: the weight column must hold finite numbers >= 0; got "
                         f"{float(w[k])!r} on data line {k + 1} ({int(bad.sum())} such line(s))")
    if not w.any():
        raise ValueError(f"`{arg}`: {p}: the weight column is 0 on every line (no sample)")
    return col["row"], col["col"], col["depth"], w


def _numeric(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def read_weights(path, *, arg: str = "weights") -> np.ndarray:
    """An (H, W) map of weights (``--confidence``, ``--prior-weight-map``; their values, >= 0
    where they apply, are checked by :func:`facetlift.integrate` against the mask, so a
    sentinel outside it is no error): ``.npy``, EXR, floating-point TIFF and PFM (Portable
    Float Map) as stored; an 8- or 16-bit image (PNG or TIFF) as ``value / 255`` or
    ``value / 65535`` (the same mask gives the same weights in either format; a TIFF
    of 255s was read as 255). A grey image stored as RGB(A), or an EXR with equal R, G, B
    channels, is read as its grey level (an EXR's Y channel where it has one); colour
    channels that differ are refused (only the first was read). A MATLAB ``.mat`` file: its
    variable of :data:`MAT_PRIOR_WEIGHT_NAMES` (Quéau's ``lambda``) for ``prior_weight_map``,
    of :data:`MAT_CONFIDENCE_NAMES` otherwise, or its only (H, W) one."""
    p = _existing(path, arg)
    ext = _suffix(p, PRIOR_FORMATS, "weight", arg)
    if ext in (".png", ".tif", ".tiff", ".pfm"):
        a = _decode_image(p, ext, arg)
        if a.ndim == 3 and a.shape[-1] in (2, 3, 4):  # (grey + alpha, RGB, RGBA)
            grey = a[..., :3] if a.shape[-1] >= 3 else a[..., :1]
            same = grey == grey[..., :1]
            if grey.dtype.kind == "f":  # (a float TIFF's or a PFM's NaN: the same unknown)
                same |= np.isnan(grey) & np.isnan(grey[..., :1])
            if not same.all():
                raise ValueError(f"`{arg}`: {p} has colour channels that differ; give a "
                                 "single-channel (grey) image of the weights")
            a = a[..., 0]
        if a.ndim != 2:
            raise ValueError(f"`{arg}`: {p} must hold an (H, W) weight map; got shape "
                             f"{a.shape}")
        if a.dtype in (np.uint8, np.uint16):
            top = np.iinfo(a.dtype).max
            if 0 < int(a.max()) <= 1:
                warn(f"`{arg}`: {p} holds only 0 and 1 as {a.dtype} values, read as 0 and "
                     f"1/{top} (value / {top}, as every 8/16-bit image): for weights of 1, "
                     f"store {top} (or give a float TIFF, EXR or .npy)")
            return a.astype(np.float64) / top
        if ext == ".png":
            raise ValueError(f"`{arg}`: {p} must be an 8- or 16-bit PNG; got dtype {a.dtype}")
        return a.astype(np.float64)
    if ext == ".exr":  # (a grey EXR stored as R = G = B, as grey PNGs are: a user's check)
        ch = _read_exr(p, arg)
        rgb = [ch.get(k) for k in ("R", "G", "B")]
        if len(ch) > 1 and "Y" not in ch and all(c is not None for c in rgb):
            if not all(np.array_equal(rgb[0], c, equal_nan=True) for c in rgb[1:]):
                raise ValueError(f"`{arg}`: {p} has colour channels R, G, B that differ; give "
                                 "a single-channel (grey) image of the weights")
            return rgb[0].astype(np.float64)
    names = MAT_PRIOR_WEIGHT_NAMES if arg == "prior_weight_map" else MAT_CONFIDENCE_NAMES
    return read_plane(p, PRIOR_FORMATS, "weight", arg, prefer=("Y",),
                      mat_names=names).astype(np.float64)
