"""Colours for meshes and point clouds: an image of the object (the photograph a neural
estimator saw, a photometric stereo's albedo or one of its images) painted onto the result.

Every pixel is a facet (docs/conventions.md), so pixel (r, c)'s colour belongs to facet (r, c):
a point of ``points.ply`` at that pixel's centre takes it as it is, and a mesh vertex takes the
mean colour of the facets that use it (on a mesh split at depth jumps, of its own side's
facets only, so that no colour bleeds across a jump).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._warnings import warn
from ._paths import _existing, _suffix

COLOR_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".npy")

#: How far float colours may lie outside [0, 1] and still be taken (clipped): rounding of
#: float32 processing (1.0000001 was refused as "from 1 to 1", a review).
FLOAT_SLACK = 1e-5

#: Largest relative difference of the two axes' scale factors for which an image of another
#: size is resampled to the normal map's (the same picture at another resolution, with each
#: side rounded to whole pixels); beyond it the image is refused as another picture.
ASPECT_TOLERANCE = 0.02


def read_colors(path, shape: tuple[int, int] | None = None, *, arg: str = "colors"
                ) -> np.ndarray:
    """An image's colours as float32 (H, W, 3) in [0, 1], as displayed (sRGB).

    PNG (8 or 16 bit), JPEG (turned as its EXIF orientation says) and TIFF are taken as
    stored, scaled by their largest value (255, 65535); a float TIFF or ``.npy`` must lie in
    [0, 1]; OpenEXR holds linear light by its convention and is encoded to sRGB (values above
    1 clipped, with a warning); a CMYK TIFF and an EXR of several colour layers are refused. A grey
    image gives grey colours; an alpha channel is dropped. With `shape` (the normal map's),
    an image of the same picture at another resolution is resampled to it (with a warning);
    one of another aspect ratio is refused.

    Raises
    ------
    ValueError
        Naming `arg`: an unreadable file, an unsupported format or layout, values outside
        [0, 1] in a float file, another picture's shape.
    """
    p = _existing(path, arg)
    ext = _suffix(p, COLOR_FORMATS, "colour image", arg)
    if ext == ".exr":
        from .images import _read_exr

        ch = _read_exr(p, arg)
        names = _exr_colour_channels(ch, p, arg)
        a = np.dstack([ch[n] for n in names]).astype(np.float64)
        a = _srgb(a, p, arg)
    elif ext == ".npy":
        from .images import _read_npy

        a = _read_npy(p, arg)
    elif ext in (".jpg", ".jpeg"):
        try:
            import imagecodecs

            data = p.read_bytes()
            a = np.asarray(imagecodecs.jpeg8_decode(data))
        except OSError as e:
            raise ValueError(f"`{arg}`: cannot read {p}: {e}") from None
        except Exception as e:  # (each codec has its own errors)
            raise ValueError(f"`{arg}`: {p} is not a readable JPEG image "
                             f"({type(e).__name__}: {e})") from None
        if not _jpeg_complete(data):  # (a cut-off file decodes its lost rows as grey
            # without an error, a user's check)
            raise ValueError(f"`{arg}`: {p} is a truncated JPEG (no end-of-image marker after "
                             "its image data); its missing rows would be painted grey")
        if a.ndim == 3 and a.shape[2] == 4:  # (its K was dropped as an alpha: grey came out
            # white, a review)
            raise ValueError(f"`{arg}`: {p} is a CMYK JPEG; convert it to RGB first")
        a = _oriented(a, _exif_orientation(data))
    else:
        from .images import _decode_image

        if ext in (".tif", ".tiff"):
            _refuse_cmyk(p, arg)
        a = _decode_image(p, ext, arg)
    return colour_image(a, shape, arg=arg, source=p)


def _exr_colour_channels(ch: dict, p: Path, arg: str) -> list[str]:
    """The EXR channels holding R, G, B (of the default layer, or of the only layer that has
    all three), or the channel of a grey image (its only one, or Y beside at most A)."""
    if all(c in ch for c in "RGB"):
        return list("RGB")
    layers = sorted({k.rsplit(".", 1)[0] for k in ch if "." in k
                     and all(f"{k.rsplit('.', 1)[0]}.{c}" in ch for c in "RGB")})
    if len(layers) == 1:
        return [f"{layers[0]}.{c}" for c in "RGB"]
    if len(layers) > 1:  # (a Blender multilayer file: which pass is the picture?)
        raise ValueError(f"`{arg}`: {p} holds several colour layers ({', '.join(layers)}); "
                         "write the one to paint with to a file of its own")
    if len(ch) == 1 or set(ch) in ({"Y"}, {"Y", "A"}):
        return ["Y" if "Y" in ch else next(iter(ch))]
    raise ValueError(f"`{arg}`: {p} must hold R, G and B channels (or one grey channel) for "
                     f"the colours; got channels {sorted(ch)}")


def _refuse_cmyk(p: Path, arg: str) -> None:
    """A CMYK (separated) TIFF read as RGBA painted red as cyan (a review): refused."""
    try:
        import tifffile

        with tifffile.TiffFile(p) as tif:
            separated = tif.pages[0].photometric == tifffile.PHOTOMETRIC.SEPARATED
    except Exception:  # (the reading proper says what is wrong)
        return
    if separated:
        raise ValueError(f"`{arg}`: {p} is a CMYK TIFF; convert it to RGB first")


#: numpy operations turning an image stored with an EXIF orientation into its displayed
#: orientation (1: as stored), as image viewers show it.
_ORIENT = {2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
           5: lambda a: a.swapaxes(0, 1), 6: lambda a: np.rot90(a, -1),
           7: lambda a: a[::-1, ::-1].swapaxes(0, 1), 8: lambda a: np.rot90(a, 1)}


def _oriented(a: np.ndarray, orientation: int) -> np.ndarray:
    """`a` turned as its EXIF `orientation` says (a phone's portrait photo is stored
    sideways: refused as another picture, or painted turned, a review)."""
    turn = _ORIENT.get(orientation)
    return a if turn is None else np.ascontiguousarray(turn(a))


def _jpeg_complete(data: bytes) -> bool:
    """Whether a JPEG's image data ends with its end-of-image marker: the segments are walked
    to the start of scan, and an ``FF D9`` must follow (inside the entropy-coded data an
    ``FF`` byte is stuffed, so that pair is the marker); data after it (a phone's trailer) is
    no matter (the last 64 bytes were looked at, and such files refused, a review)."""
    for marker, i, _ in _jpeg_headers(data):
        if marker == 0xDA:  # (start of scan)
            return data.find(b"\xff\xd9", i) >= 0
    # (the walk stopped at a stray byte between segments, which libjpeg skips: an end marker
    # after the first start of scan, a review)
    sos = data.find(b"\xff\xda")
    return sos >= 0 and data.find(b"\xff\xd9", sos) >= 0


def _jpeg_headers(data: bytes):
    """``(marker, offset, size)`` of a JPEG's segments from the start of the file up to and
    including its first start of scan (``FF DA``; fill bytes ``FF FF`` skipped); the walk
    stops at a byte that starts no marker or at the end of the data."""
    import struct

    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xFF:  # (fill bytes)
            i += 1
            continue
        (size,) = struct.unpack(">H", data[i + 2:i + 4])
        yield marker, i, size
        if marker in (0xD9, 0xDA):  # (end of image, start of scan: no more headers)
            return
        i += 2 + size


def _exif_orientation(data: bytes) -> int:
    """The EXIF orientation tag (0x0112) of a JPEG's APP1 segment; 1 where it has none or the
    segment cannot be read."""
    import struct

    for marker, i, size in _jpeg_headers(data):
        if marker == 0xE1 and data[i + 4:i + 10] == b"Exif\0\0":
            tiff = data[i + 10:i + 2 + size]
            try:
                order = {b"II": "<", b"MM": ">"}[tiff[:2]]
                (ifd,) = struct.unpack(order + "I", tiff[4:8])
                (count,) = struct.unpack(order + "H", tiff[ifd:ifd + 2])
                for k in range(count):
                    at = ifd + 2 + 12 * k
                    tag, kind = struct.unpack(order + "HH", tiff[at:at + 4])
                    if tag == 0x0112 and kind == 3:  # (SHORT)
                        (value,) = struct.unpack(order + "H", tiff[at + 8:at + 10])
                        return int(value) if 1 <= value <= 8 else 1
            except (KeyError, struct.error):
                return 1
            return 1
    return 1


def _srgb(a: np.ndarray, p, arg: str) -> np.ndarray:
    """Linear light (an EXR's) encoded as sRGB in [0, 1]; values above 1 clipped with a
    warning, negative or non-finite ones set to 0."""
    bad = ~np.isfinite(a)
    a = np.where(bad, 0.0, np.maximum(a, 0.0))
    over = a > 1.0
    if over.any():
        warn(f"`{arg}`: {p} is linear light with {over.mean():.2%} of its values above 1; "
             "they are clipped to white (tone-map it first to keep the highlights)")
    a = np.minimum(a, 1.0)
    return np.where(a <= 0.0031308, 12.92 * a, 1.055 * a ** (1 / 2.4) - 0.055)


def colour_image(image, shape: tuple[int, int] | None = None, *, arg: str = "colors",
                 source=None) -> np.ndarray:
    """`image` (an array, or a file's path: :func:`read_colors`) as float32 (H, W, 3) in
    [0, 1]: uint8 and uint16 scaled by 255 and 65535,
    floats as they are (they must lie in [0, 1]; NaN is black), grey repeated, alpha
    dropped; resampled to `shape` where it is the same picture at another resolution
    (:data:`ASPECT_TOLERANCE`). ValueError naming `arg` otherwise."""
    where = f" ({source})" if source is not None else ""
    if isinstance(image, (str, os.PathLike)):  # (the command line's --colors FILE, a user's
        # natural Surface.save(..., colors="photo.jpg"))
        return read_colors(image, shape, arg=arg)
    a = np.asarray(image)
    if a.dtype.kind == "b" or a.dtype.kind not in "uif":
        raise ValueError(f"`{arg}`{where} must hold numbers (uint8, uint16 or floats in "
                         f"[0, 1]); got {a.dtype}")
    if a.ndim == 3 and a.shape[2] in (2, 4):  # (grey + alpha, RGBA: the alpha dropped)
        a = a[..., :a.shape[2] - 1]
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"`{arg}`{where} must be an (H, W, 3) colour or (H, W) grey image; "
                         f"got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"`{arg}`{where} is empty (shape {a.shape})")
    if a.dtype.kind in "ui":
        if a.dtype not in (np.uint8, np.uint16):  # (int16 was scaled by 65535, a review)
            raise ValueError(f"`{arg}`{where}: integer colours must be uint8 or uint16; got "
                             f"{a.dtype} (convert, or give floats in [0, 1])")
        c = a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max)
    else:
        c = a.astype(np.float32)
        c = np.where(np.isfinite(c), c, np.float32(0.0))
        lo, hi = float(c.min()), float(c.max())
        if lo < -FLOAT_SLACK or hi > 1 + FLOAT_SLACK:
            raise ValueError(f"`{arg}`{where}: float colours must lie in [0, 1]; got values "
                             f"from {lo:.9g} to {hi:.9g} (scale them, or give uint8)")
        c = np.clip(c, 0.0, 1.0)  # (rounding's overshoot, within FLOAT_SLACK)
    if shape is not None and c.shape[:2] != tuple(shape):
        c = _resampled(c, tuple(shape), arg, where)
    return np.ascontiguousarray(c)


def _resampled(c: np.ndarray, shape: tuple[int, int], arg: str, where: str) -> np.ndarray:
    """`c` (h, w, 3) resampled to `shape` (H, W): the same picture at another resolution
    (:func:`_axis_weights` along each axis); another aspect ratio is a ValueError."""
    (h, w), (H, W) = c.shape[:2], shape
    sy, sx = H / h, W / w
    # (each side rounded to whole pixels: the scales may differ by one pixel's worth)
    slack = max(ASPECT_TOLERANCE, 1.0 / min(h, w, H, W))
    if abs(sy - sx) > slack * max(sy, sx):
        raise ValueError(f"`{arg}`{where} is {h} x {w} pixels, the normal map {H} x {W}: "
                         "another picture (its aspect ratio differs); give the image the "
                         "normals were estimated from, at their size or scaled")
    warn(f"`{arg}`{where}: the image is {h} x {w} pixels and the normal map {H} x {W}; its "
         "colours are resampled to the map's size")
    Ry, Rx = _axis_weights(h, H), _axis_weights(w, W)
    out = np.empty((H, W, 3), np.float32)
    for k in range(3):
        out[..., k] = (Ry @ (Rx @ c[..., k].T).T)
    return np.clip(out, 0.0, 1.0)


def _axis_weights(n: int, N: int):
    """(N, n) sparse weights resampling one axis of n pixels to N: where it shrinks, each new
    pixel the mean of the old ones it covers, by the length of their overlap (an area
    average); where it grows, linear interpolation between the old pixel centres."""
    import scipy.sparse as sp

    if N < n:
        lo, hi = np.arange(N) * (n / N), np.arange(1, N + 1) * (n / N)
        rows, cols, vals = [], [], []
        for i in range(N):
            k = np.arange(int(np.floor(lo[i])), min(n, int(np.ceil(hi[i]))))
            overlap = np.minimum(k + 1, hi[i]) - np.maximum(k, lo[i])
            rows.append(np.full(k.size, i))
            cols.append(k)
            vals.append(overlap / overlap.sum())
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))), shape=(N, n))
    x = np.clip((np.arange(N) + 0.5) * (n / N) - 0.5, 0, n - 1)  # (old pixel coordinates)
    k = np.minimum(np.floor(x).astype(int), max(n - 2, 0))
    t = x - k
    nxt = np.minimum(k + 1, n - 1)
    return sp.csr_matrix((np.r_[1 - t, t], (np.r_[np.arange(N), np.arange(N)], np.r_[k, nxt])),
                         shape=(N, n))


def point_colors(surface, colors) -> np.ndarray:
    """(n, 3) float colours of :meth:`facetlift.Surface.points`' pixels (the mask's, in
    row-major order) from an (H, W, 3) image of the surface's shape (:func:`colour_image`)."""
    c = colour_image(colors, surface.shape)
    return c[surface.mask]


def mesh_colors(surface, colors) -> np.ndarray:
    """(n, 3) float colours of :meth:`facetlift.Surface.to_mesh`'s vertices: each vertex the
    mean colour of the facets that use it (of its side's facets where the mesh is split at
    jumps, :func:`facet_corners`)."""
    c = point_colors(surface, colors).astype(np.float64)
    corners = facet_corners(surface)
    n = int(corners.max()) + 1 if corners.size else 0
    flat = corners.ravel()
    count = np.bincount(flat, minlength=n)
    out = np.empty((n, 3))
    for k in range(3):
        out[:, k] = np.bincount(flat, weights=np.repeat(c[:, k], corners.shape[1]),
                                minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= count[:, None]
    return np.clip(np.nan_to_num(out, nan=0.0), 0.0, 1.0)


def facet_corners(surface) -> np.ndarray:
    """(m, 4) vertex indices of each facet's corners, as :meth:`facetlift.Surface.to_mesh`
    numbers its vertices (the split mesh's where the surface has jumps)."""
    if getattr(surface, "split", None) is not None:
        return surface.split[0]
    from ..domain import Domain

    return Domain.from_mask(surface.mask).corners
