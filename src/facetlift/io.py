"""Reading normal maps, masks and intrinsics; writing depth maps, meshes and previews.

Formats and the libraries behind them (imported on first use, so ``import facetlift`` stays
cheap):

================  =====================================  ======================================
what              formats                                library
================  =====================================  ======================================
normal maps       PNG 8/16 bit, TIFF, OpenEXR, ``.npy``  imagecodecs (libpng), tifffile, OpenEXR
masks             PNG, TIFF, ``.npy``                    imagecodecs, tifffile
intrinsics ``K``  text, 3 x 3                            numpy
depth maps        ``.npy``, OpenEXR, TIFF, ``.npz``      numpy, OpenEXR, tifffile
meshes            PLY (binary), OBJ; quads or triangles  meshio
previews          PNG                                    imagecodecs, matplotlib colormaps
================  =====================================  ======================================

Integer normal maps are decoded per channel as ``n = v / maxval * 2 - 1`` (``maxval`` 255 or
65535) with R, G, B = x, y, z in the facetlift convention (x right, y up, z toward the viewer;
see :mod:`facetlift.conventions`). Pillow is not used for PNG because it silently reduces
16-bit RGB PNGs to 8 bits. A pixel of an integer map whose decoded vector has a length outside
:data:`ENCODED_LENGTH_RANGE` does not encode a normal (black, white or mid-grey background
fill) and decodes as NaN, i.e. a missing sample.

Every writer is atomic: it writes a temporary file in the target directory, flushes it to disk
and renames it over the target, so a failed write never leaves a partial file behind.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path

import numpy as np

from .problem import numeric_array

#: Decoded integer pixels whose vector length lies outside this range are not normals (NaN).
ENCODED_LENGTH_RANGE = (0.5, 1.5)

NORMAL_READ_FORMATS = (".png", ".tif", ".tiff", ".exr", ".npy")
NORMAL_WRITE_FORMATS = (".png", ".tif", ".tiff", ".exr", ".npy")
MASK_FORMATS = (".png", ".tif", ".tiff", ".npy")
DEPTH_FORMATS = (".npy", ".exr", ".tif", ".tiff")
MESH_FORMATS = (".ply", ".obj")
SURFACE_FORMATS = DEPTH_FORMATS + (".npz",) + MESH_FORMATS + (".png",)


# --------------------------------------------------------------------------------------------
# helpers


def _suffix(path: Path, allowed: tuple[str, ...], what: str, arg: str) -> str:
    ext = path.suffix.lower()
    if ext not in allowed:
        raise ValueError(
            f"`{arg}`: unsupported {what} format {ext or '(no extension)'!r} for {path}; "
            f"supported: {', '.join(allowed)}"
        )
    return ext


def _existing(path, arg: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise ValueError(f"`{arg}`: file {p} does not exist")
    if p.is_dir():
        raise ValueError(f"`{arg}`: {p} is a directory, not a file")
    return p


def _decode_image(path: Path, ext: str, arg: str) -> np.ndarray:
    """Pixels of a PNG or TIFF file as stored (no conversion); ValueError if unreadable."""
    try:
        if ext == ".png":
            import imagecodecs

            data = path.read_bytes()
            return np.asarray(imagecodecs.png_decode(data))
        import tifffile

        return np.asarray(tifffile.imread(path))
    except OSError as e:
        raise ValueError(f"`{arg}`: cannot read {path}: {e}") from None
    except Exception as e:  # corrupt or truncated files: each library has its own errors
        raise ValueError(
            f"`{arg}`: {path} is not a readable {ext[1:].upper()} image ({type(e).__name__}: {e})"
        ) from None


def _read_exr(path: Path, arg: str) -> dict[str, np.ndarray]:
    try:
        import OpenEXR

        with OpenEXR.File(str(path), separate_channels=True) as f:
            return {k: np.asarray(v.pixels) for k, v in f.channels().items()}
    except Exception as e:
        raise ValueError(
            f"`{arg}`: {path} is not a readable OpenEXR image ({type(e).__name__}: {e})"
        ) from None


def _read_npy(path: Path, arg: str) -> np.ndarray:
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as e:
        raise ValueError(
            f"`{arg}`: {path} is not a readable .npy array ({type(e).__name__}: {e})"
        ) from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "biuf":
        raise ValueError(f"`{arg}`: {path} must hold a numeric array; got {arr.dtype}")
    return arr


def _decode_unit(pixels: np.ndarray, path: Path, arg: str) -> np.ndarray:
    """uint8/uint16 -> [-1, 1] per channel; float passes through; other dtypes are refused."""
    if pixels.dtype == np.uint8 or pixels.dtype == np.uint16:
        maxval = float(np.iinfo(pixels.dtype).max)
        n = pixels.astype(np.float64) / maxval * 2.0 - 1.0
        length = np.linalg.norm(n, axis=-1)
        lo, hi = ENCODED_LENGTH_RANGE
        n[(length < lo) | (length > hi)] = np.nan
        return n
    if pixels.dtype.kind == "f":
        return pixels.astype(np.float64)
    raise ValueError(
        f"`{arg}`: {path} has pixel type {pixels.dtype}; normal maps must be uint8, uint16 "
        "or floating point"
    )


def _split_alpha(pixels: np.ndarray, path: Path, arg: str):
    if pixels.ndim != 3 or pixels.shape[-1] not in (3, 4) or min(pixels.shape[:2]) < 1:
        channels = pixels.shape[-1] if pixels.ndim == 3 else (1 if pixels.ndim == 2 else None)
        raise ValueError(
            f"`{arg}`: {path} must be an (H, W, 3) RGB or (H, W, 4) RGBA normal map; got "
            f"shape {pixels.shape}"
            + (f" ({channels} channel(s))" if channels is not None else "")
        )
    if pixels.shape[-1] == 4:
        return pixels[..., :3], pixels[..., 3] > 0
    return pixels, None


# --------------------------------------------------------------------------------------------
# readers


def read_normals(path, *, y_down: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a normal map.

    Parameters
    ----------
    path : str or Path
        ``.png`` (8 or 16 bit RGB/RGBA), ``.tif``/``.tiff`` (uint8, uint16 or float, 3 or 4
        channels), ``.exr`` (channels R, G, B or X, Y, Z, optionally A) or ``.npy`` ((H, W, 3)
        or (H, W, 4)).
    y_down : bool
        The file stores y pointing *down* (DirectX / OpenCV style); the y component is negated
        to give the facetlift convention (y up).

    Returns
    -------
    normals : (H, W, 3) float64
        Normals, x right, y up, z toward the viewer, as decoded (not renormalised: that is
        done by :func:`facetlift.prepare`); NaN where an integer pixel holds no normal.
    alpha_mask : (H, W) bool or None
        ``alpha > 0`` where the file has an alpha channel, else None.

    Raises
    ------
    ValueError
        Missing, corrupt or truncated file, wrong number of channels, unsupported pixel type
        or extension. The message names the path.
    """
    arg = "path"
    p = _existing(path, arg)
    ext = _suffix(p, NORMAL_READ_FORMATS, "normal map", arg)
    if ext in (".png", ".tif", ".tiff"):
        pixels = _decode_image(p, ext, arg)
        rgb, alpha = _split_alpha(pixels, p, arg)
        n = _decode_unit(rgb, p, arg)
    elif ext == ".exr":
        ch = _read_exr(p, arg)
        for names in (("R", "G", "B"), ("X", "Y", "Z")):
            if all(c in ch for c in names):
                break
        else:
            raise ValueError(
                f"`{arg}`: {p} must have channels R, G, B or X, Y, Z; got {sorted(ch)}"
            )
        n = np.stack([ch[c] for c in names], axis=-1).astype(np.float64)
        alpha = ch["A"] > 0 if "A" in ch else None
    else:
        arr = _read_npy(p, arg)
        rgb, alpha_v = _split_alpha(arr, p, arg)
        n = rgb.astype(np.float64)
        alpha = None if alpha_v is None else alpha_v
    if y_down:
        n[..., 1] = -n[..., 1]
    return n, alpha


def read_mask(path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a mask image: nonzero is inside.

    Parameters
    ----------
    path : str or Path
        ``.png``, ``.tif``/``.tiff`` or ``.npy``; grey, grey+alpha, RGB or RGBA. A colour pixel
        is inside when any of its colour channels is nonzero (and its alpha, if any, is > 0).
    shape : (H, W), optional
        Required shape (that of the normal map).

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
    if a.ndim == 3 and a.shape[-1] in (1, 2, 3, 4):
        colour = a[..., :3] if a.shape[-1] >= 3 else a[..., :1]
        m = (colour != 0).any(-1)
        if a.shape[-1] in (2, 4):
            m &= a[..., -1] > 0
    elif a.ndim == 2:
        m = a != 0
    else:
        raise ValueError(
            f"`{arg}`: {p} must be an (H, W) image or have 1-4 channels; got shape {a.shape}"
        )
    if min(m.shape) < 1:
        raise ValueError(f"`{arg}`: {p} is empty (shape {a.shape})")
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ValueError(f"`{arg}`: {p} contains NaN or inf")
    if shape is not None and m.shape != tuple(shape):
        raise ValueError(
            f"`{arg}`: {p} has size {m.shape[0]}x{m.shape[1]} (HxW) but the normal map is "
            f"{shape[0]}x{shape[1]}"
        )
    return m


def read_K(path) -> np.ndarray:
    """Read 3x3 perspective intrinsics (OpenCV layout) from a text file (``np.loadtxt``).

    Raises
    ------
    ValueError
        Missing or unparsable file, a shape other than 3x3, or a matrix that is not valid
        intrinsics (see :mod:`facetlift.conventions`).
    """
    from .camera import check_K as _check_K

    arg = "K"
    p = _existing(path, arg)
    try:
        K = np.loadtxt(p, dtype=float, ndmin=2)
    except Exception as e:
        raise ValueError(f"`{arg}`: cannot parse {p} as a 3x3 matrix ({e})") from None
    try:
        return _check_K(K)
    except ValueError as e:
        raise ValueError(f"`{arg}`: {p}: {e}") from None


def _find(folder: Path, stem: str, formats: tuple[str, ...]) -> Path | None:
    for ext in formats:
        if (folder / f"{stem}{ext}").is_file():
            return folder / f"{stem}{ext}"
    return None


def read_dataset(folder, *, y_down: bool = False) -> dict:
    """Read a folder in the BiNI / DiLiGenT layout.

    The folder holds ``normal_map.png`` (or ``.tif``, ``.tiff``, ``.exr``, ``.npy``), usually
    ``mask.png`` (or ``.tif``, ``.tiff``, ``.npy``) and, for a perspective camera, ``K.txt``.
    Without ``K.txt`` the view is orthographic. Pixels outside the mask may hold anything.

    Returns
    -------
    dict
        ``normals`` (H, W, 3) float64, ``mask`` (H, W) bool (the mask file, else the normal
        map's alpha channel, else None) and ``K`` (3, 3) or None.

    Raises
    ------
    ValueError
        If the folder or its normal map is missing, or any file is unreadable.
    """
    f = Path(folder)
    if not f.is_dir():
        raise ValueError(f"`folder`: {f} is not a directory")
    npath = _find(f, "normal_map", NORMAL_READ_FORMATS)
    if npath is None:
        raise ValueError(
            f"`folder`: {f} has no normal_map file (looked for normal_map with extension "
            f"{', '.join(NORMAL_READ_FORMATS)})"
        )
    normals, alpha = read_normals(npath, y_down=y_down)
    mpath = _find(f, "mask", MASK_FORMATS)
    mask = read_mask(mpath, normals.shape[:2]) if mpath is not None else alpha
    kpath = f / "K.txt"
    K = read_K(kpath) if kpath.is_file() else None
    return {"normals": normals, "mask": mask, "K": K}


# --------------------------------------------------------------------------------------------
# atomic writing


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


def _write_exr(path: Path, channels: dict[str, np.ndarray]) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(str(tmp))


def _write_tiff(path: Path, arr: np.ndarray) -> None:
    import tifffile

    with atomic_path(path) as tmp:
        photometric = "rgb" if arr.ndim == 3 and arr.shape[-1] in (3, 4) else "minisblack"
        extra = "unassalpha" if arr.ndim == 3 and arr.shape[-1] == 4 else None
        tifffile.imwrite(
            tmp, arr, photometric=photometric, extrasamples=extra, compression="zlib"
        )


def _write_png(path: Path, pixels: np.ndarray) -> None:
    import imagecodecs

    _write_bytes(path, imagecodecs.png_encode(np.ascontiguousarray(pixels)))


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
    p = Path(path)
    ext = _suffix(p, DEPTH_FORMATS, "depth", "path")
    d = _image_array(depth, "depth", 2).astype(np.float64)
    if ext == ".npy":
        _save_npy(p, d)
    elif ext == ".exr":
        _write_exr(p, {"Z": d})
    else:
        _write_tiff(p, d.astype(np.float32))
    return p


def read_depth(path) -> np.ndarray:
    """Read an (H, W) depth map written by :func:`write_depth` (``.npy``, ``.exr``, TIFF)."""
    arg = "path"
    p = _existing(path, arg)
    ext = _suffix(p, DEPTH_FORMATS, "depth", arg)
    if ext == ".npy":
        d = _read_npy(p, arg)
    elif ext == ".exr":
        ch = _read_exr(p, arg)
        if "Z" in ch:
            d = ch["Z"]
        elif len(ch) == 1:
            d = next(iter(ch.values()))
        else:
            raise ValueError(f"`{arg}`: {p} has no depth channel Z; channels {sorted(ch)}")
    else:
        d = _decode_image(p, ext, arg)
    if d.ndim != 2:
        raise ValueError(f"`{arg}`: {p} must hold an (H, W) depth map; got shape {d.shape}")
    return d.astype(np.float64)


def write_mesh(path, vertices, faces) -> Path:
    """Write a mesh as binary PLY or OBJ.

    Parameters
    ----------
    path : str or Path
        ``.ply`` (binary little-endian) or ``.obj``.
    vertices : (n, 3) float
    faces : (m, 4) quads or (m, 3) triangles of int vertex indices (0-based)

    Raises
    ------
    ValueError
        Bad shapes, non-finite vertices, indices out of range, unknown extension.
    """
    import meshio

    p = Path(path)
    ext = _suffix(p, MESH_FORMATS, "mesh", "path")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"`vertices` must have shape (n, 3); got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError("`vertices` contains NaN or inf")
    if f.ndim != 2 or f.shape[1] not in (3, 4) or f.dtype.kind not in "iu":
        raise ValueError(
            f"`faces` must be an integer (m, 3) or (m, 4) array; got {f.shape} {f.dtype}"
        )
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(
            f"`faces` index out of range [0, {len(v)}): min {f.min()}, max {f.max()}"
        )
    dtype = np.int32 if len(v) < 2**31 else np.int64
    cell = "quad" if f.shape[1] == 4 else "triangle"
    mesh = meshio.Mesh(v, [(cell, f.astype(dtype))])
    fmt = "ply" if ext == ".ply" else "obj"
    with atomic_path(p) as tmp:
        if fmt == "ply":
            meshio.write(tmp, mesh, file_format="ply", binary=True)
        else:
            meshio.write(tmp, mesh, file_format="obj")
    return p


def shade(surface, *, light=(-1.0, 1.0, 2.0), ambient: float = 0.15) -> np.ndarray:
    """Lambertian shading of a surface's facets, (H, W) in [0, 1], NaN outside the domain.

    Facet normals come from the reconstructed geometry: the cross product of the two
    diagonals of each quad (its corner vertices in 3-D, x right, y up, z toward the viewer),
    so perspective surfaces shade correctly too. `light` points from the surface toward the
    light (default: upper left, in front).
    """
    H, W = surface.shape
    vd = surface.vertex_depth
    vm = np.isfinite(vd)
    P = np.full((H + 1, W + 1, 3), np.nan)
    P[vm] = surface.points("vertices")
    d1 = P[1:, 1:] - P[:-1, :-1]  # (r,c) -> (r+1,c+1)
    d2 = P[:-1, 1:] - P[1:, :-1]  # (r+1,c) -> (r,c+1)
    n = np.cross(d1, d2)
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    L = np.asarray(light, dtype=float)
    L = L / np.linalg.norm(L)
    s = ambient + (1.0 - ambient) * np.clip(n @ L, 0.0, 1.0)
    s[~surface.mask] = np.nan
    return s


def write_preview(
    path,
    surface,
    *,
    light=(-1.0, 1.0, 2.0),
    colormap: str | None = None,
    min_size: int = 256,
    background=(255, 255, 255),
) -> Path:
    """Write a PNG preview: the surface shaded by a distant light, background outside the mask.

    Parameters
    ----------
    path : str or Path
        ``.png`` file.
    surface : facetlift.Surface
    light : (3,) float
        Direction toward the light, x right, y up, z toward the viewer.
    colormap : str, optional
        A matplotlib colormap name; when given, a second panel shows the depth in colour
        (near = low end of the map).
    min_size : int
        Small surfaces are enlarged by an integer factor (nearest neighbour) so that the
        shorter side has at least this many pixels.
    background : (3,) int
        RGB colour outside the domain.
    """
    p = Path(path)
    _suffix(p, (".png",), "preview", "path")
    s = shade(surface, light=light)
    inside = surface.mask
    bg = np.asarray(background, dtype=np.uint8)
    img = np.empty(s.shape + (3,), dtype=np.uint8)
    img[:] = bg
    tint = np.array([0.92, 0.92, 0.97])
    img[inside] = np.round(255 * s[inside, None] * tint).astype(np.uint8)
    panels = [img]
    if colormap is not None:
        import matplotlib

        d = surface.depth
        lo, hi = np.nanmin(d[inside]), np.nanmax(d[inside])
        t = (d - lo) / (hi - lo) if hi > lo else np.zeros_like(d)
        cmap = matplotlib.colormaps[colormap]
        col = np.empty_like(img)
        col[:] = bg
        col[inside] = np.round(255 * cmap(t[inside])[:, :3]).astype(np.uint8)
        gap = np.empty((img.shape[0], max(2, img.shape[1] // 32), 3), np.uint8)
        gap[:] = bg
        panels += [gap, col]
    out = np.concatenate(panels, axis=1)
    k = max(1, int(np.ceil(min_size / max(1, min(inside.shape)))))
    if k > 1:
        out = np.repeat(np.repeat(out, k, axis=0), k, axis=1)
    _write_png(p, out)
    return p


def write_normals(path, normals, mask=None, *, bits: int = 16, y_down: bool = False) -> Path:
    """Write a normal map (the inverse of :func:`read_normals`).

    Parameters
    ----------
    path : str or Path
        ``.png`` (RGB, or RGBA with the mask as alpha), ``.tif``/``.tiff``, ``.exr`` (R, G, B
        and A for the mask) or ``.npy`` ((H, W, 3), or (H, W, 4) with the mask).
    normals : (H, W, 3) float
        Components in [-1, 1]; NaN is written as 0 (PNG/integer TIFF: decodes as NaN again).
    mask : (H, W) bool, optional
        Stored as the alpha channel.
    bits : {8, 16, 32}
        PNG: 8 or 16 bit per channel; TIFF: 8, 16 (integer) or 32 (float32). Ignored for EXR
        (float32) and npy (float64).
    y_down : bool
        Store y pointing down (negate the y component).
    """
    p = Path(path)
    ext = _suffix(p, NORMAL_WRITE_FORMATS, "normal map", "path")
    n = _image_array(normals, "normals", 3).astype(np.float64)
    if n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (H, W, 3); got {n.shape}")
    if y_down:
        n[..., 1] = -n[..., 1]
    m = None
    if mask is not None:
        m = np.asarray(mask) != 0
        if m.shape != n.shape[:2]:
            raise ValueError(f"`mask` must have shape {n.shape[:2]}; got {m.shape}")
    allowed = {".png": (8, 16), ".tif": (8, 16, 32), ".tiff": (8, 16, 32)}
    if ext in allowed and bits not in allowed[ext]:
        raise ValueError(f"`bits` must be one of {allowed[ext]} for {ext}; got {bits!r}")
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
    p = Path(path)
    ext = _suffix(p, MASK_FORMATS, "mask", "path")
    m = _image_array(mask, "mask", 2) != 0
    if ext == ".npy":
        _save_npy(p, m)
    elif ext == ".png":
        _write_png(p, m.astype(np.uint8) * 255)
    else:
        _write_tiff(p, m.astype(np.uint8) * 255)
    return p


def save_surface(surface, path, **kwargs) -> Path:
    """Write `surface` in the format given by the extension of `path`.

    ``.npy``, ``.exr``, ``.tif``/``.tiff``: the (H, W) depth map (:func:`write_depth`);
    ``.npz``: arrays ``depth``, ``vertex_depth``, ``mask``, ``pixel_size`` and ``K`` (NaN-filled
    3x3 when orthographic); ``.ply``/``.obj``: the facet mesh (:func:`write_mesh`; keyword
    ``triangles=True`` splits quads); ``.png``: a shaded preview (:func:`write_preview`,
    keywords forwarded). Returns the path written.

    Raises
    ------
    ValueError
        Unknown extension (the message lists the valid ones) or keywords the format does not
        take.
    """
    p = Path(path)
    ext = _suffix(p, SURFACE_FORMATS, "surface", "path")

    def no_kwargs():
        if kwargs:
            raise ValueError(f"{ext} output takes no options; got {sorted(kwargs)}")

    if ext in DEPTH_FORMATS:
        no_kwargs()
        return write_depth(p, surface.depth)
    if ext == ".npz":
        no_kwargs()
        K = np.full((3, 3), np.nan) if surface.K is None else np.asarray(surface.K, float)
        with atomic_path(p) as tmp, open(tmp, "xb") as fh:
            np.savez_compressed(
                fh,
                depth=surface.depth,
                vertex_depth=surface.vertex_depth,
                mask=surface.mask,
                pixel_size=np.float64(surface.pixel_size),
                K=K,
            )
        return p
    if ext in MESH_FORMATS:
        extra = sorted(set(kwargs) - {"triangles"})
        if extra:
            raise ValueError(f"{ext} output takes only `triangles`; got {extra}")
        verts, faces = surface.to_mesh(triangles=bool(kwargs.get("triangles", False)))
        return write_mesh(p, verts, faces)
    preview_kw = {"light", "colormap", "min_size", "background"}
    extra = sorted(set(kwargs) - preview_kw)
    if extra:
        raise ValueError(f".png output takes only {sorted(preview_kw)}; got {extra}")
    return write_preview(p, surface, **kwargs)
