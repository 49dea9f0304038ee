"""Facet meshes as binary PLY, OBJ or binary STL, and point clouds as binary PLY; meshes and
clouds optionally with a colour per vertex or point. Written by facetlift itself, in blocks or
as numpy records (no library's per-line Python loop, no time stamp in the files: the same
surface gives the same bytes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._paths import _file_name, _suffix
from .atomic import atomic_path

MESH_FORMATS = (".ply", ".obj", ".stl")


def write_mesh(path, vertices, faces, colors=None) -> Path:
    """Write a mesh as binary PLY, OBJ or binary STL.

    Parameters
    ----------
    path : str or Path
        ``.ply`` (binary little-endian), ``.obj`` or ``.stl`` (binary; triangles only, each
        with its facet normal by the right-hand rule of its corners' order, so a face listed
        counter-clockwise as seen by the viewer faces the viewer; (0, 0, 0) for a degenerate
        one; coordinates as float32 and without units: STL has none).
    vertices : (n, 3) float
    faces : (m, 4) quads or (m, 3) triangles of int vertex indices (0-based); triangles for
        ``.stl`` (``Surface.to_mesh(triangles=True)`` splits a facet mesh's quads)
    colors : (n, 3) optional, a colour per vertex: floats in [0, 1] or uint8 (R, G, B as
        displayed, i.e. sRGB). PLY stores them as the vertex properties ``red``, ``green``,
        ``blue`` (uint8), OBJ as three more numbers in [0, 1] on each ``v`` line (MeshLab,
        Blender, Open3D and trimesh read both); STL has no colours and refuses them.

    Raises
    ------
    ValueError
        Bad shapes, non-finite vertices, indices out of range, unknown extension, quads for
        ``.stl``, colours of another shape or outside [0, 1], colours for ``.stl``.
    """
    p = _file_name(path)
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
    if ext == ".stl" and f.shape[1] != 3:  # (meshio would drop the quads with a warning)
        raise ValueError(f"`faces`: an STL holds triangles only; got quads {f.shape}: split "
                         "them, e.g. Surface.to_mesh(triangles=True)")
    if colors is not None and ext == ".stl":
        raise ValueError("`colors`: an STL holds no colours; write the coloured mesh as .ply "
                         "or .obj")
    rgb = None if colors is None else colour_bytes(colors, len(v))
    if ext == ".stl":  # (written here, in blocks: meshio's writer held about 184 B per
        # triangle at once, 2.5 times the PLY's per pixel and more than the solve's estimate)
        with atomic_path(p) as tmp:
            _write_stl(tmp, v, f)
        return p
    if ext == ".obj":  # (our own writer: meshio's formats a line per vertex and face in
        # Python, 27 s for a 2048^2 mesh, and has no vertex colours)
        with atomic_path(p) as tmp:
            _write_obj(tmp, v, f, rgb)
        return p
    data = {} if rgb is None else {k: rgb[:, i] for i, k in enumerate(("red", "green", "blue"))}
    with atomic_path(p) as tmp:
        _write_ply(tmp, v, f, data)
    return p


#: PLY's names of the numpy types :func:`_write_ply` writes.
_PLY_TYPES = {"f8": "double", "f4": "float", "u1": "uint8", "i4": "int32"}


def _write_ply(path, v: np.ndarray, f: np.ndarray | None, props: dict) -> None:
    """Binary little-endian PLY: vertices `v` (n, 3) as ``x y z`` (double) followed by the
    vertex properties `props` (name -> (n,) float32 or uint8 array, in order), and faces `f`
    (m, 3 or 4; None: a point cloud, no face element) as ``list uint8 int32
    vertex_indices``. The layout meshio wrote before, without its time stamp."""
    if len(v) >= 2**31:
        raise ValueError(f"a PLY's int32 vertex indices hold fewer than 2^31 vertices; got "
                         f"{len(v)}")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    fields += [(k, np.dtype(a.dtype).newbyteorder("<").str) for k, a in props.items()]
    header = ["ply", "format binary_little_endian 1.0", "comment written by facetlift",
              f"element vertex {len(v)}"]
    header += [f"property {_PLY_TYPES[t[1:]]} {name}" for name, t in fields]
    if f is not None:
        header += [f"element face {len(f)}", "property list uint8 int32 vertex_indices"]
    header.append("end_header")
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        for start in range(0, len(v), PLY_BLOCK):  # (a block of records at a time)
            part = slice(start, start + PLY_BLOCK)
            rec = np.empty(len(v[part]), dtype=fields)
            rec["x"], rec["y"], rec["z"] = v[part].T
            for k, a in props.items():
                rec[k] = a[part]
            fh.write(rec.tobytes())  # (not tofile: see io.atomic._Stream)
        if f is not None:
            face = np.empty(min(len(f), PLY_BLOCK),
                            dtype=[("n", "u1"), ("v", "<i4", (f.shape[1],))])
            face["n"] = f.shape[1]
            for start in range(0, len(f), PLY_BLOCK):
                part = f[start:start + PLY_BLOCK]
                out = face[:len(part)]
                out["v"] = part
                fh.write(out.tobytes())


#: Records per block of :func:`_write_ply` (a few MiB of temporaries each).
PLY_BLOCK = 1 << 17


def colour_bytes(colors, n: int, arg: str = "colors") -> np.ndarray:
    """(n, 3) uint8 colours from `colors`: uint8 as they are, floats in [0, 1] rounded to
    0-255. ValueError naming `arg` for another shape, a non-finite value or one outside
    [0, 1]."""
    c = np.asarray(colors)
    if c.shape != (n, 3):
        raise ValueError(f"`{arg}` must have shape ({n}, 3), one colour per vertex or point; "
                         f"got {c.shape}")
    if c.dtype == np.uint8:
        return np.ascontiguousarray(c)
    if c.dtype.kind not in "fiu":
        raise ValueError(f"`{arg}` must hold numbers (floats in [0, 1] or uint8); got {c.dtype}")
    c = c.astype(np.float64)
    if not np.isfinite(c).all():
        raise ValueError(f"`{arg}` contains NaN or inf ({int((~np.isfinite(c)).sum())} values)")
    if c.size and (c.min() < 0 or c.max() > 1):
        raise ValueError(f"`{arg}` must be in [0, 1] (or uint8); got values from {c.min():g} "
                         f"to {c.max():g}")
    return np.round(c * 255).astype(np.uint8)


#: Rows per block of :func:`_write_obj`'s text.
OBJ_BLOCK = 1 << 16


def _write_obj(path, v: np.ndarray, f: np.ndarray, rgb: np.ndarray | None) -> None:
    """Wavefront OBJ of vertices `v` (n, 3), faces `f` (m, 3 or 4; 1-based in the file) and
    optional colours `rgb` (n, 3) uint8, written as ``v x y z r g b`` with r, g, b in [0, 1];
    coordinates with their shortest exact decimal form (``repr``), :data:`OBJ_BLOCK` rows of
    text at a time."""
    with open(path, "w", encoding="ascii", newline="\n") as fh:
        fh.write("# written by facetlift\n")
        for start in range(0, len(v), OBJ_BLOCK):
            rows = v[start:start + OBJ_BLOCK].tolist()
            if rgb is None:
                fh.write("".join("v %r %r %r\n" % tuple(r) for r in rows))
            else:
                cols = (rgb[start:start + OBJ_BLOCK] / 255.0).tolist()
                fh.write("".join("v %r %r %r %.4f %.4f %.4f\n" % (*r, *c)
                                 for r, c in zip(rows, cols, strict=True)))
        line = "f" + " %d" * f.shape[1] + "\n"
        for start in range(0, len(f), OBJ_BLOCK):
            rows = (f[start:start + OBJ_BLOCK].astype(np.int64) + 1).tolist()
            fh.write("".join(line % tuple(r) for r in rows))


#: A binary STL's record: facet normal, three corners (float32), attribute byte count.
STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])

#: Triangles per block of :func:`_write_stl` (about 13 MiB of temporaries each).
STL_BLOCK = 1 << 16


def _write_stl(path, v: np.ndarray, f: np.ndarray) -> None:
    """Binary STL of vertices `v` (n, 3) and triangles `f` (m, 3), written :data:`STL_BLOCK`
    triangles at a time (memory independent of `m`); the 80-byte header does not start with
    ``solid`` (which would mark an ASCII STL to some readers)."""
    if len(f) >= 2**32:
        raise ValueError(f"`faces`: a binary STL holds fewer than 2^32 triangles; got {len(f)}")
    header = b"binary STL written by facetlift".ljust(80, b" ")
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(np.array(len(f), "<u4").tobytes())
        buf = np.zeros(min(STL_BLOCK, len(f)), STL_RECORD)
        for start in range(0, len(f), STL_BLOCK):
            part = f[start:start + STL_BLOCK]
            out = buf[:len(part)]
            out["normal"] = _facet_normals(v, part)
            out["corners"] = v[part]
            fh.write(out.tobytes())  # (not tofile: see io.atomic._Stream)


def _facet_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Unit normals (m, 3) of triangles `f`, ``(b - a) x (c - a)``: toward the side from
    which the corners run counter-clockwise; (0, 0, 0) for a degenerate one (meshio's own
    gave NaN there)."""
    a = v[f[:, 0]]
    n = np.cross(v[f[:, 1]] - a, v[f[:, 2]] - a)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, n / length, 0.0)


def write_points(path, points, normals=None, colors=None) -> Path:
    """Write a point cloud as binary PLY: `points` (n, 3) float, optional unit `normals`
    (n, 3) as the vertex properties nx, ny, nz (CloudCompare, Open3D and PCL read both; a
    point without a finite normal gets (0, 0, 0)) and optional `colors` (n, 3), floats in
    [0, 1] or uint8, as ``red``, ``green``, ``blue`` (uchar). Points with a non-finite
    coordinate are left out."""
    p = _file_name(path)
    _suffix(p, (".ply",), "point cloud", "path")
    v = np.asarray(points, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"`points` must have shape (n, 3); got {v.shape}")
    keep = np.isfinite(v).all(axis=1)
    data = {}
    if normals is not None:
        from ..frames import as_float_normals

        # (uint8/uint16 decoded, as integrate does: written raw, 29830.0 per component, an
        # audit)
        n = np.asarray(as_float_normals(np.asarray(normals), "normals"), dtype=np.float64)
        if n.shape != v.shape:
            raise ValueError(f"`normals` must have the shape of `points` {v.shape}; got "
                             f"{n.shape}")
        n = np.where(np.isfinite(n).all(axis=1)[:, None], n, 0.0)
        data = {k: n[keep, i].astype(np.float32) for i, k in enumerate(("nx", "ny", "nz"))}
    if colors is not None:
        rgb = colour_bytes(colors, len(v))[keep]
        data.update({k: rgb[:, i] for i, k in enumerate(("red", "green", "blue"))})
    with atomic_path(p) as tmp:
        _write_ply(tmp, v[keep], None, data)
    return p
