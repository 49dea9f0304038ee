"""One entry point, :func:`save_surface`, that picks the writer from the file extension."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._paths import _file_name, _suffix
from .atomic import atomic_path
from .colors import mesh_colors, point_colors
from .images import DEPTH_FORMATS, write_depth
from .meshes import MESH_FORMATS, write_mesh
from .preview import write_preview

SURFACE_FORMATS = DEPTH_FORMATS + (".npz",) + MESH_FORMATS + (".png",)

#: The command line's output file names (``facetlift.jobs.OUTPUTS``) whose content is not
#: their extension's default, by ``--save`` kind: :func:`save_surface` writes these exact
#: names (in any case) as ``--save`` does. ``surface.save("points.ply")`` wrote the mesh, and
#: ``"discontinuities.png"`` a plain preview, where ``-s points`` and ``-s discontinuities``
#: write the point cloud and the jump map (a review); ``height.exr`` held the depth where
#: ``-s height-exr`` writes the heights.
CLI_NAMES = {"points.ply": "points", "discontinuities.png": "discontinuities",
             "report.png": "report", "height.exr": "height-exr",
             "result_normals.png": "normals"}


#: ``.png`` names that :func:`save_surface` writes as a 16-bit height map
#: (:func:`~facetlift.io.preview.write_height`), as ``--save height`` names its file, not as a
#: shaded preview: a texture artist's ``surface.save("height.png")`` got an 8-bit shaded
#: picture (an audit).
HEIGHT_STEMS = ("height", "heightmap", "height_map", "displacement")


def save_surface(surface, path, **kwargs) -> Path:
    """Write `surface` in the format given by the extension of `path`.

    ``.npy``, ``.exr``, ``.tif``/``.tiff``: the (H, W) depth map (:func:`write_depth`);
    ``.npz``: arrays ``depth``, ``vertex_depth``, ``mask``, ``pixel_size`` and ``K``
    (NaN-filled 3x3 when orthographic), and where the surface has depth jumps ``cuts_right``,
    ``cuts_down``, ``discontinuities`` and the split mesh (``split_corners``, ``split_i``,
    ``split_j``, ``split_depth``; :func:`load_surface` reads it all back);
    ``.ply``/``.obj``/``.stl``: the facet mesh
    (:func:`write_mesh`, split at the jumps where there are any; keyword ``triangles``: True
    splits each quad in two, False keeps quads; default quads for PLY and triangles for OBJ,
    since OBJ readers such as Open3D's take triangles only; a binary STL holds triangles only,
    with facet normals toward the viewer, and refuses ``triangles=False``; keyword
    ``colors``: an image of the object, (H, W, 3) or grey (H, W), uint8, uint16 or floats in
    [0, 1], painted on the PLY's or OBJ's vertices, each the mean of its facets' pixels, one
    side's at a jump: :mod:`facetlift.io.colors`); ``.png``: a
    shaded preview
    (:func:`write_preview`, keywords forwarded), except ``height.png``, the other names of
    :data:`HEIGHT_STEMS` and names ending in ``_height`` (``bear_height.png``; or ``-``): the
    16-bit height map of ``--save height``
    (:func:`~facetlift.io.preview.write_height`, keyword ``height_range``).

    The command line's own file names (:data:`CLI_NAMES`) write what its ``--save`` writes
    under them: ``points.ply`` the point cloud (:func:`~facetlift.io.meshes.write_points`,
    a point per pixel centre; keywords ``frame``, ``normals``, the input normals
    (H, W, 3) to give each point, and ``colors``, an image of the object whose pixels colour
    the points), ``discontinuities.png`` the map of the depth jumps
    (:func:`~facetlift.io.preview.write_discontinuities`, keyword ``min_size``; a surface
    without one is refused), ``report.png`` the report
    (:func:`~facetlift.io.report.write_report`, needs matplotlib; keywords ``normals``,
    ``dpi``), ``height.exr`` the heights (:func:`~facetlift.io.preview.write_height`) and
    ``result_normals.png`` the result's own normals (a 16-bit normal map, keyword ``frame``,
    default the ``normal_frame`` integrate was given: :func:`result_normals`);
    any other name keeps its extension's meaning (``mesh_points.ply`` is a mesh, with a
    warning that names the point cloud's writer: a name ending in ``_`` or ``-`` and one of
    those names looks meant as it). Returns the path written.

    Raises
    ------
    ValueError
        A `path` that is no file name (a file object: the extension picks the format),
        an unknown extension (the message lists the valid ones) or keywords the format does
        not take.
    """
    p = _file_name(path)  # (a BytesIO was a bare TypeError, an audit)
    ext = _suffix(p, SURFACE_FORMATS, "surface", "path")

    def no_kwargs():
        if kwargs:
            raise ValueError(f"{ext} output takes no options; got {sorted(kwargs)}")

    kind = CLI_NAMES.get(p.name.lower())
    if kind is not None:
        return _save_as_cli(surface, p, kind, kwargs)
    like = next((name for name in CLI_NAMES if name != "height.exr" and p.name.lower().endswith(
        tuple(sep + name for sep in "_-"))), None)
    if like is not None:  # (bear_report.png was a shaded preview without a word, an audit)
        from .._warnings import warn

        writer = {"points": "io.write_points", "report": "io.write_report",
                  "discontinuities": "io.write_discontinuities"}.get(CLI_NAMES[like])
        warn(f"{p.name}: only the name {like} itself writes what --save {CLI_NAMES[like]} "
             f"writes; this one keeps its extension's meaning ({ext}: "
             + ("a mesh" if ext == ".ply" else "a shaded preview") + f"): name it {like}"
             + (f", or call {writer}" if writer else ""))

    if ext in DEPTH_FORMATS:
        no_kwargs()
        if _height_named(p) and p.name.lower() not in CLI_NAMES:  # (a sign trap, an audit)
            from .._warnings import warn

            warn(f"{p.name}: a {ext} file holds the depth (larger is farther), not the "
                 "heights its name suggests; io.write_height(path, surface) writes the heights "
                 "(-depth) to .exr or a 16-bit .png, as the command line's height.exr and "
                 "height.png")
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
                **_cut_arrays(surface),
                **_frame_arrays(surface),
            )
        return p
    if ext in MESH_FORMATS:
        extra = sorted(set(kwargs) - {"triangles", "frame", "colors"})
        if extra:
            cloud = (" (a point cloud with normals is written under the name points.ply)"
                     if "normals" in extra and ext == ".ply" else "")
            raise ValueError(f"{ext} output takes only `triangles`, `frame` and `colors`; got "
                             f"{extra}{cloud}")
        triangles = kwargs.get("triangles")
        triangles = ext != ".ply" if triangles is None else triangles  # (to_mesh checks it)
        if ext == ".stl" and isinstance(triangles, (bool, np.bool_)) and not triangles:
            raise ValueError("`triangles`: an STL holds triangles only; leave it out (or True) "
                             "for .stl, or write quads to .ply or .obj")
        colors = kwargs.get("colors")
        if colors is not None and ext == ".stl":  # (before the mesh is formed)
            raise ValueError("`colors`: an STL holds no colours; write the coloured mesh as "
                             ".ply or .obj")
        verts, faces = surface.to_mesh(triangles=triangles, frame=kwargs.get("frame"))
        rgb = None if colors is None else mesh_colors(surface, colors)
        return write_mesh(p, verts, faces, rgb)
    stem = p.stem.lower()
    if _height_named(p):
        # (the command line's height.png, also per object: bear_height.png; a user's check)
        extra = sorted(set(kwargs) - {"height_range"})
        if extra:
            raise ValueError(f"{p.name} (a height map) takes only `height_range`; got {extra}")
        from .preview import write_height

        return write_height(p, surface, **kwargs)[0]
    preview_kw = {"light", "colormap", "min_size", "background"}
    extra = sorted(set(kwargs) - preview_kw)
    if extra:
        raise ValueError(f".png output takes only {sorted(preview_kw)}; got {extra}")
    if "height" in stem or "displacement" in stem:  # (not one of the names above)
        from .._warnings import warn

        warn(f"{p.name}: a .png is a shaded preview of the surface unless it is named "
             f"{', '.join(h + '.png' for h in HEIGHT_STEMS)} or ends with _height.png (or "
             "-height.png): those are the 16-bit height map (io.write_height)")
    if "depth" in stem:  # (a user's trap: "depth.png" held no depth)
        from .._warnings import warn

        warn(f"{p.name}: a .png is a shaded preview of the surface, not its depth; write "
             "depth as .exr, .tif or .npy (or .npz with the vertex depth and the mask)")
    return write_preview(p, surface, **kwargs)


#: The keywords each of :data:`CLI_NAMES`' writers takes.
_CLI_KEYWORDS = {"points": ("frame", "normals", "colors"), "discontinuities": ("min_size",),
                 "report": ("dpi", "normals"), "height-exr": (), "normals": ("frame",)}


def _height_named(p: Path) -> bool:
    """Whether `p`'s name says it holds heights: a stem of :data:`HEIGHT_STEMS` or ending in
    ``_height`` / ``-height`` (and the like)."""
    stem = p.stem.lower()
    return stem in HEIGHT_STEMS or stem.endswith(tuple(f"{sep}{h}" for h in HEIGHT_STEMS
                                                       for sep in "_-"))


def _save_as_cli(surface, p: Path, kind: str, kwargs: dict) -> Path:
    """:func:`save_surface` of one of :data:`CLI_NAMES`: as ``--save kind`` writes it."""
    extra = sorted(set(kwargs) - set(_CLI_KEYWORDS[kind]))
    if extra:
        takes = _CLI_KEYWORDS[kind]
        raise ValueError(f"{p.name} (as --save {kind} writes it) takes "
                         + (f"only {list(takes)}" if takes else "no options")
                         + f"; got {extra}")
    if kind == "points":
        from .. import frames
        from .meshes import write_points

        frame = kwargs.get("frame")
        pn = point_normals(surface, kwargs.get("normals"))
        colors = kwargs.get("colors")
        return write_points(p, surface.points(frame=frame),
                            None if pn is None else frames.from_facetlift(pn, frame, "frame"),
                            None if colors is None else point_colors(surface, colors))
    if kind == "normals":
        from .images import write_normals

        # (in the frame given, else the input's: the frame the command line read the map in,
        # or integrate's normal_frame)
        info = surface.info if isinstance(surface.info, dict) else {}
        frame = kwargs.get("frame") or info.get("input_frame") or info.get("normal_frame")
        return write_normals(p, result_normals(surface), surface.mask, bits=16, frame=frame)
    if kind == "discontinuities":
        from .preview import write_discontinuities

        return write_discontinuities(p, surface, **kwargs)
    if kind == "report":
        from .. import io as package  # (facetlift.io.write_report: the one a test replaces)

        info = surface.info if isinstance(surface.info, dict) else {}
        given = kwargs.get("normals")
        if given is not None and np.shape(given) == surface.shape + (3,):
            given = camera_normals(surface, given)  # (as the points' normals)
        return package.write_report(p, surface, given,
                            mean_deviation=info.get("mean_deviation"),
                            **({"dpi": kwargs["dpi"]} if "dpi" in kwargs else {}))
    from .preview import write_height

    return write_height(p, surface)[0]


def camera_normals(surface, normals) -> np.ndarray:
    """The (H, W, 3) normals given to :func:`facetlift.integrate` as it took them: uint8 /
    uint16 decoded (``v / max * 2 - 1``), from its ``normal_frame`` to facetlift's and turned
    by its ``normal_rotation`` (both recorded in ``surface.info``), so that the array a
    caller integrated gives the camera-frame normals of the result (they came out in the
    caller's frame: an OpenCV map's point normals faced away, an audit)."""
    from .. import frames

    n = np.asarray(normals)
    if n.dtype in (np.uint8, np.uint16):
        n = n / float(np.iinfo(n.dtype).max) * 2.0 - 1.0
    n = np.asarray(n, dtype=float)
    info = surface.info if isinstance(surface.info, dict) else {}
    frame = info.get("normal_frame")
    if frame is not None:
        n = frames.to_facetlift(n, frame)
    R = info.get("normal_rotation")
    if R is not None:
        n = frames.rotate(n, frames.rotation_in_facetlift(np.asarray(R, float), frame))
    return n


def result_normals(surface) -> np.ndarray:
    """(H, W, 3) unit normals of the result's facets (:func:`facetlift.metrics.surface_normals`:
    each facet's own corners where the surface is split at jumps), NaN outside its mask, in
    the frame the input normals were given in: ``normal_rotation`` of ``surface.info`` undone
    (a world-space map gives world-space normals back) and stored in its ``normal_frame`` by
    the writer. What ``--save normals`` writes, to set beside the input map."""
    from .. import frames
    from ..metrics import surface_normals

    n = surface_normals(surface)
    info = surface.info if isinstance(surface.info, dict) else {}
    R = info.get("normal_rotation")
    if R is not None:  # (the inverse of camera_normals' turn, a rotation: its transpose)
        turn = frames.rotation_in_facetlift(np.asarray(R, float), info.get("normal_frame"))
        n = frames.rotate(n, np.asarray(turn, float).T)
    return n


def point_normals(surface, normals):
    """The input normals at :meth:`facetlift.Surface.points`' pixels (facetlift's camera
    frame, as integrated: in the frame and with the rotation :func:`facetlift.integrate` was
    given, :func:`camera_normals`; a gradient field's from its slopes), unit length; None
    where `normals` is None. A map of another shape is a ValueError naming `normals` (a cloud
    without them had been written without a word, an audit)."""
    if normals is None:
        return None
    n = np.asarray(normals)
    if n.shape != surface.shape + (3,):
        raise ValueError(f"`normals` must be an (H, W, 3) map of the surface's shape "
                         f"{surface.shape + (3,)} for the points' normals; got {n.shape}")
    n = camera_normals(surface, n)
    r, c = np.nonzero(surface.mask)
    v = n[r, c]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # (scaled by the largest component first: a normal of 1e300 is a usable direction, a
        # review)
        v = v / np.max(np.abs(v), axis=1, keepdims=True)
        return v / np.linalg.norm(v, axis=1, keepdims=True)


def _frame_arrays(surface) -> dict:
    """``normal_frame`` and ``normal_rotation`` of ``surface.info`` where integrate was given
    them: :func:`load_surface` puts them back, so the reloaded surface turns the same normals
    for points.ply and the report (they faced away after a reload, a review)."""
    info = surface.info if isinstance(surface.info, dict) else {}
    out = {}
    if info.get("normal_frame") is not None:
        out["normal_frame"] = np.str_(info["normal_frame"])
    if info.get("input_frame") is not None:  # (the command line's, for result_normals.png)
        out["input_frame"] = np.str_(info["input_frame"])
    if info.get("normal_rotation") is not None:
        out["normal_rotation"] = np.asarray(info["normal_rotation"], float)
    for key in ("method", "solver"):  # (the report's title read "method ?" after a reload)
        if isinstance(info.get(key), str):
            out[key] = np.str_(info[key])
    return out


def _cut_arrays(surface) -> dict:
    """``cuts_right``, ``cuts_down`` and ``discontinuities`` where the surface has jumps, and
    its split mesh (``split_corners``, ``split_i``, ``split_j``, ``split_depth``: what
    :meth:`facetlift.Surface.to_mesh` needs, so that :func:`load_surface` gives the same mesh)."""
    if getattr(surface, "cuts", None) is None:
        return {}
    out = {"cuts_right": surface.cuts[0], "cuts_down": surface.cuts[1],
           "discontinuities": surface.discontinuities}
    if getattr(surface, "split", None) is not None:
        corners, i, j, depth = surface.split
        out.update(split_corners=corners, split_i=i, split_j=j, split_depth=depth)
    return out


def load_surface(path):
    """The :class:`facetlift.Surface` of a ``.npz`` written by :func:`save_surface` (``-s npz``
    on the command line): depth, vertex depth, mask, camera and, where it has jumps, its cuts,
    discontinuity map and split mesh (files written before 2026-12-05 lack the split mesh:
    their mesh is then the unsplit one). ``info`` is not stored (``--json`` has it), but its
    ``normal_frame`` and ``normal_rotation``, which :meth:`~facetlift.Surface.save`'s
    ``normals=`` needs, and its ``method`` and ``solver`` (the report's title).

    Raises
    ------
    ValueError
        A missing file, or one that is no surface ``.npz`` (the message names what is missing).
    """
    from ..surface import Surface
    from ._paths import _existing

    p = _existing(path, "path")
    _suffix(p, (".npz",), "surface", "path")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except ValueError:  # (a text file says "pickled data": it is no .npz archive at all)
        raise ValueError(f"`path`: {p} is not a .npz archive") from None
    except Exception as e:
        raise ValueError(f"`path`: {p} is not a readable .npz ({type(e).__name__}: {e})"
                         ) from None
    missing = [k for k in ("depth", "vertex_depth", "mask", "pixel_size", "K") if k not in data]
    if missing:
        raise ValueError(f"`path`: {p} is no surface written by facetlift (no {missing})")
    depth = data["depth"]
    if depth.ndim != 2:
        raise ValueError(f"`path`: {p}: its depth must be (H, W); got shape {depth.shape}")
    H, W = depth.shape
    want = {"mask": (H, W), "vertex_depth": (H + 1, W + 1), "K": (3, 3), "pixel_size": (),
            "cuts_right": (H, W - 1), "cuts_down": (H - 1, W), "discontinuities": (H, W)}
    wrong = [f"{k} {data[k].shape} (not {v})" for k, v in want.items()
             if k in data and data[k].shape != v]
    split_keys = ("split_corners", "split_i", "split_j", "split_depth")
    has_split = [k in data for k in split_keys]
    has_cuts = "cuts_right" in data and "cuts_down" in data
    if any(has_split) and not (all(has_split) and has_cuts):
        wrong.append("a split mesh without its cut edges, or in part")
    if wrong:
        raise ValueError(f"`path`: {p} is no surface written by facetlift: {'; '.join(wrong)}")
    K = data["K"]
    K = None if not np.isfinite(K).all() else K
    cuts = (data["cuts_right"].astype(bool), data["cuts_down"].astype(bool)) if has_cuts else None
    split = tuple(data[k] for k in split_keys) if all(has_split) else None
    if cuts is not None and split is None:
        from .._warnings import warn

        warn(f"`path`: {p} was written before surfaces kept their split mesh: its cuts are "
             "read, but its mesh (to_mesh, save) is not split at them; the mesh outputs of "
             "that run have the split geometry")
    info = {}  # (only how the integrated normals reach the camera frame, _frame_arrays)
    if "normal_frame" in data:
        info["normal_frame"] = str(data["normal_frame"])
    if "input_frame" in data:
        info["input_frame"] = str(data["input_frame"])
    if "normal_rotation" in data and data["normal_rotation"].shape == (3, 3):
        info["normal_rotation"] = data["normal_rotation"].tolist()
    for key in ("method", "solver"):
        if key in data:
            info[key] = str(data[key])
    return Surface(depth, data["vertex_depth"], data["mask"].astype(bool), info,
                   pixel_size=float(data["pixel_size"]) if K is None else 1.0, K=K, cuts=cuts,
                   discontinuities=data.get("discontinuities"), split=split)
