"""The result of an integration: depth map, vertex depths, points and meshes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from . import frames
from .camera import Camera, make_camera
from .domain import Domain
from .operators.split import _pieces
from .operators.split import split as split_mesh


class Surface:
    """A reconstructed surface (see :mod:`facetlift.conventions`).

    Attributes
    ----------
    depth : (H, W) float
        Depth at facet centres (larger is farther), NaN outside the domain.
    vertex_depth : (H+1, W+1) float
        Depth at the facet corners, NaN where no facet touches (a method that solves for pixel
        values only gets them derived: :func:`facetlift.api.vertex_values`). Where the
        surface is cut at depth jumps (:attr:`cuts`) a vertex on a cut has one copy per side
        in the mesh (:meth:`to_mesh`), and this keeps one glued value that is neither side's
        (docs/conventions.md).
    mask : (H, W) bool
        The integration domain.
    info : dict
        Method diagnostics: ``method``, ``iterations`` (1 for a direct method),
        ``converged``, ``deviation`` (average angular deviation in degrees per iteration, for
        the DGP routes; the discontinuity route's one value is of the surface returned),
        ``seconds``
        per phase, ``input`` (counts of unusable normals, :func:`facetlift.prepare`),
        ``mean_deviation`` (mean angle in degrees between the input normals and the result's
        facets), ``deviation_over_10`` (the share of them deviating by more than 10 degrees),
        ``integrability`` (:func:`facetlift.frames.flip_check`), and method-specific
        entries (every key: docs/cli.md, "Surface.info").
    camera : facetlift.camera.Camera
        The camera the depth is measured in; give it, or `pixel_size` and `K` (read back as
        properties).
    cuts : (right, down) or None
        Where the surface is cut by a depth jump (discontinuity-preserving methods): ``right``
        (H, W-1) bool between pixel (r, c) and (r, c+1), ``down`` (H-1, W) between (r, c) and
        (r+1, c). :meth:`to_mesh` splits the mesh there; ``depth`` is the mean of each facet's
        four mesh corners (perspective: their geometric mean), so the two agree everywhere.
    discontinuities : (H, W) float or None
        Per pixel, the largest depth jump across its cut edges (0 where none, NaN outside).
    split : (corners, i, j, depth) or None
        The split mesh behind `cuts`: facet corners (m, 4) into split vertices, their grid
        positions (i, j) and depths (each (n,)); :meth:`to_mesh` uses it.

    The arrays belong together: :meth:`to_mesh` and ``points("vertices")`` read
    `vertex_depth` (or `split`), ``points()`` reads `depth`, so editing one of them in place
    leaves the others as they were (a depth multiplied by 1000 beside a mesh still in metres,
    an audit). For other units use :meth:`scaled`; for a depth from elsewhere,
    :meth:`from_depth`.
    """

    def __init__(
        self, depth, vertex_depth, mask, info=None, *, pixel_size: float = 1.0, K=None,
        camera: Camera | None = None, cuts=None, discontinuities=None, split=None,
    ):
        # (as arrays: lists made repr, points() and the mesh writers fail, an audit)
        self.depth = np.asarray(depth, dtype=float)
        self.vertex_depth = np.asarray(vertex_depth, dtype=float)
        self.mask = np.asarray(mask, dtype=bool)
        # (shapes that disagree were cropped by points() or failed deep inside it, and saved
        # a surface.npz that load_surface refused, a review)
        if self.depth.ndim != 2:
            raise ValueError(f"`depth` must be an (H, W) array; got shape {self.depth.shape}")
        H, W = self.depth.shape
        if self.mask.shape != (H, W):
            raise ValueError(f"`mask` must have the shape of `depth`, {(H, W)}; got "
                             f"{self.mask.shape}")
        if self.vertex_depth.shape != (H + 1, W + 1):
            raise ValueError(f"`vertex_depth` must be (H + 1, W + 1) = {(H + 1, W + 1)} for a "
                             f"depth of {(H, W)} (the facets' corners); got "
                             f"{self.vertex_depth.shape}")
        self.info = {} if info is None else info
        self.camera = make_camera(pixel_size, K) if camera is None else camera
        self.cuts = cuts
        self.discontinuities = discontinuities
        self.split = split

    @classmethod
    def from_depth(cls, depth, mask=None, *, pixel_size: float = 1.0, K=None) -> Surface:
        """A Surface of a depth map from elsewhere (a ground truth, a sensor's, another
        tool's), to mesh it or compare it like a result: `depth` (H, W) in the convention of
        :attr:`depth` (larger is farther; for a pinhole camera `K`, z-depth > 0), `mask`
        (default: where it is finite, and positive with `K`). Each vertex takes the mean of the
        pixels around it, each carried to that corner by half its central difference (one-sided
        at the mask's edge), in the camera's unknown (height, or log-depth); no cuts. `depth`
        is kept as given, so the mesh's facet centres (the means of their corners) meet it to
        second order only (a sphere of 48^2: 4e-5 of the depth range in the median, 2 % at
        its steep rim), not exactly as a result's do.

        Raises
        ------
        ValueError
            A `depth` that is no (H, W) array, a `mask` of another shape, or a mask pixel
            whose depth is not finite (or not positive with `K`).
        """
        from .problem import _bool_image, _short, numeric_array, unmasked

        # (as integrate reads its arrays: a masked array's masked pixels unknown, a NaN mask
        # refused, a soft one warned about, a string named; np.asarray took the masked
        # values and every nonzero mask value, NaN included, an audit)
        d = numeric_array(unmasked(depth), "depth").astype(float)
        if d.ndim != 2:
            raise ValueError(f"`depth` must be an (H, W) array; got {_short(depth)}")
        camera = make_camera(pixel_size, K)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(d) & (d > 0 if camera.perspective else True)
        if mask is None:
            m = ok
        else:
            shape = np.shape(unmasked(mask, 0.0))
            if shape != d.shape:
                raise ValueError(f"`mask` must have the shape of `depth` {d.shape}; got "
                                 f"{shape}")
            m = _bool_image(mask, "mask", d.shape)
        if (m & ~ok).any():
            r, c = np.argwhere(m & ~ok)[0]
            what = "finite and positive (a pinhole camera's z-depth)" if camera.perspective \
                else "finite"
            raise ValueError(f"`depth` must be {what} inside the mask; got {d[r, c]!r} at "
                             f"(row {r}, col {c})")
        if not m.any():
            raise ValueError("`mask` is empty: no pixel to make a surface of" if mask is not None
                             else "`depth` has no finite" + (" positive" if camera.perspective
                                                            else "") + " value")
        u = np.where(m, camera.from_depth(np.where(m, d, 1.0)), np.nan)
        H, W = d.shape
        pad = np.pad(u, 1, constant_values=np.nan)
        c0 = pad[1:-1, 1:-1]

        def slope(before, after):  # (central, else one-sided, else flat)
            central = (after - before) / 2.0
            one = np.where(np.isfinite(after - c0), after - c0, c0 - before)
            out = np.where(np.isfinite(central), central, one)
            return np.where(np.isfinite(out), out, 0.0)

        gx = slope(pad[1:-1, :-2], pad[1:-1, 2:])  # (along the columns)
        gr = slope(pad[:-2, 1:-1], pad[2:, 1:-1])  # (along the rows)
        total = np.zeros((H + 1, W + 1))
        count = np.zeros((H + 1, W + 1))
        for dr in (0, 1):
            for dc in (0, 1):
                carried = c0 + 0.5 * ((2 * dc - 1) * gx + (2 * dr - 1) * gr)
                total[dr:dr + H, dc:dc + W] += np.where(m, carried, 0.0)
                count[dr:dr + H, dc:dc + W] += m
        with np.errstate(invalid="ignore"):
            vu = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        vdepth = np.where(count > 0, camera.to_depth(np.where(count > 0, vu, 0.0)), np.nan)
        return cls(np.where(m, d, np.nan), vdepth, m, camera=camera)

    def scaled(self, factor: float) -> Surface:
        """The same surface in other units: every depth (`depth`, `vertex_depth`, the split
        mesh's, the jump heights of `discontinuities`) times `factor`, and an orthographic
        pixel size too, so that its points and mesh scale as one (a pinhole camera's K is in
        pixels and stays). Metres to millimetres: ``s.scaled(1000)``. `info` is shared.

        Raises
        ------
        ValueError
            A `factor` that is no positive finite number.
        """
        try:
            f = float(factor)
        except (TypeError, ValueError):
            f = float("nan")
        if isinstance(factor, (bool, np.bool_, str, bytes)) or not (np.isfinite(f) and f > 0):
            # (a string was converted, "2" taken as 2, a review)
            raise ValueError(f"`factor` must be a positive finite number; got {factor!r}")
        cam = self.camera
        camera = cam if cam.perspective else make_camera(cam.pixel_size * f)
        split = None if self.split is None else (*self.split[:3], self.split[3] * f)
        return Surface(self.depth * f, self.vertex_depth * f, self.mask, self.info,
                       camera=camera, cuts=self.cuts, split=split,
                       discontinuities=None if self.discontinuities is None
                       else self.discontinuities * f)

    @property
    def pixel_size(self) -> float:
        """Pixel width in world units (orthographic; 1.0 for a pinhole camera)."""
        return self.camera.pixel_size

    @property
    def K(self) -> np.ndarray | None:
        """Intrinsics (3, 3) of a perspective surface, None for an orthographic one."""
        return self.camera.K

    @property
    def height(self) -> np.ndarray:
        """(H, W) height ``-depth`` (orthographic convention)."""
        return -self.depth

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape

    def points(self, where: str = "facets", frame=None) -> np.ndarray:
        """(N, 3) points: x right, y up, z toward the viewer, or in `frame`.

        ``where="facets"`` gives one point per domain pixel at its centre (row-major);
        ``"vertices"`` one per used vertex (row-major). Orthographic:
        ``(x, y) = (col, -row) * pixel_size`` on the vertex grid, a pixel centre at
        ``col + 0.5``; perspective: back-projected with `K` (pixel centres at integer indices),
        see :mod:`facetlift.camera`. `frame`: the points in another frame, named as a normal
        map's (:mod:`facetlift.frames`): ``"opencv"`` gives the camera frame of OpenCV and
        COLMAP (x right, y down, z away from the viewer: ``(x, -y, -z)``).
        """
        if where == "facets":
            r, c = np.nonzero(self.mask)
            pts = self.camera.points(r + 0.5, c + 0.5, self.depth[r, c])
        elif where == "vertices":
            i, j = self._vertices()
            pts = self.camera.points(i, j, self.vertex_depth[i, j])
        else:
            raise ValueError(f"`where` must be 'facets' or 'vertices'; got {where!r}")
        return frames.from_facetlift(pts, frame, "frame")

    def _vertices(self, domain: Domain | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Grid positions (i, j) of the corners of the mask's facets, row-major: the vertices
        :meth:`to_mesh`'s faces index (numbered from the mask, not from where `vertex_depth`
        is finite: a mask narrowed after the solve, or a foreign depth finite beyond it,
        would otherwise number the vertices apart from the faces).

        Raises
        ------
        ValueError
            Naming `vertex_depth`, where it is not finite at such a corner.
        """
        vm = (Domain.from_mask(self.mask) if domain is None else domain).vertex_mask
        if self.vertex_depth.shape != vm.shape:
            raise ValueError(f"`vertex_depth` must have shape {vm.shape} (one more row and "
                             f"column than the mask); got {self.vertex_depth.shape}")
        bad = vm & ~np.isfinite(self.vertex_depth)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(
                f"`vertex_depth` is not finite at {int(bad.sum()):,} corner(s) of the mask's "
                f"facets (the first at vertex ({i}, {j})): no mesh or vertex points of it; "
                "narrow `mask` to the facets whose four corners have a depth")
        return np.nonzero(vm)

    def pieces(self) -> np.ndarray:
        """(H, W) int: the mesh piece of every pixel of the mask, -1 outside it; 0 is the
        largest piece, 1 the next largest, and so on (ties by their first pixel, row-major).

        A piece is what the mesh (:meth:`to_mesh`) holds together: facets sharing a corner,
        and with depth jumps (:attr:`cuts`) not across a cut, so a cut that closes around a
        part makes it a piece of its own. Normals fix a piece's shape but not where it lies
        against the others (one depth offset per piece, a scale with a camera): those the
        occlusion rule or the solve chose (docs/perspective.md, "Separated pieces"), which a
        depth sample on the piece decides instead (docs/fusion.md). Without cuts the pieces
        are the mask's components (8-connected).
        """
        r, c = np.nonzero(self.mask)
        out = np.full(self.mask.shape, -1, dtype=np.int64)
        if r.size == 0:
            return out
        split = self.split
        if split is not None and np.shape(split[0])[0] != r.size:
            split = None  # (a mask changed after the solve: the split's facets are not its own)
        if split is None and self.cuts is None:  # (the mask's 8-connected components)
            labels = ndimage.label(self.mask, structure=np.ones((3, 3), bool))[0][r, c]
        else:
            if split is not None:
                corners = np.asarray(split[0])
            else:  # (the cuts on this mask: a surface saved without its split mesh)
                corners = split_mesh(Domain.from_mask(self.mask), *self.cuts).corners
            labels, _ = _pieces(corners, int(corners.max()) + 1)  # (of the vertices)
            labels = labels[corners[:, 0]]  # (a facet's corners are one piece)
        _, first, piece = np.unique(labels, return_index=True, return_inverse=True)
        sizes = np.bincount(piece)
        order = np.lexsort((first, -sizes))  # (largest first; ties by the first pixel)
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        out[r, c] = rank[piece]
        return out

    def to_mesh(self, triangles: bool = False, frame=None) -> tuple[np.ndarray, np.ndarray]:
        """The facet mesh: vertices (n, 3) and faces (m, 4) quads or (2m, 3) triangles
        (int32 indices; int64 from 2^31 vertices).

        Vertices are those of ``points("vertices")``, or, where the surface has depth jumps
        (:attr:`cuts`), the split vertices: one copy per side of a jump, so that no face is
        stretched across it. Faces list corners counter-clockwise seen from the viewer, so face
        normals point toward the viewer; facets in row-major pixel order. `frame`: the
        vertices in another frame (:meth:`points`); in a mirrored one (``directx``) the faces
        are listed the other way round, so that they still face the viewer.
        """
        if not isinstance(triangles, (bool, np.bool_)):
            raise ValueError(f"`triangles` must be True or False; got {triangles!r}")
        if self.split is not None:
            corners, i, j, depth = self.split
            verts = frames.from_facetlift(self.camera.points(i, j, depth), frame, "frame")
        else:
            domain = Domain.from_mask(self.mask)
            corners = domain.corners
            i, j = self._vertices(domain)
            verts = frames.from_facetlift(self.camera.points(i, j, self.vertex_depth[i, j]),
                                          frame, "frame")
        # conventional corner order (r,c),(r,c+1),(r+1,c+1),(r+1,c) is clockwise seen from the
        # viewer (y up); reverse it for outward (viewer-facing) normals. 32-bit indices where
        # they hold the vertices (every mesh format's; a 2048^2 map's triangles took 200 MB
        # in 64 bits)
        quads = corners[:, ::-1].astype(np.int32 if len(verts) < 2**31 else np.int64)
        if not triangles:
            faces = quads
        else:
            a, b, c, d = quads.T
            # split along the diagonal from (r+1, c) to (r, c+1)
            faces = np.empty((2 * len(quads), 3), dtype=quads.dtype)
            faces[0::2] = np.column_stack([a, b, c])
            faces[1::2] = np.column_stack([a, c, d])
        if frame is not None and frames.mirrors(frame):  # (still facing the viewer)
            faces = np.ascontiguousarray(faces[:, ::-1])
        return verts, faces

    def save(self, path, **kwargs) -> Path:
        """Write the surface; the format follows the extension.

        ``.npy``, ``.exr``, ``.tif``/``.tiff``: the depth map (float32 for EXR/TIFF);
        ``.npz``: depth, vertex depth, mask, pixel size and K (3 x 3 NaN for an orthographic
        surface: test ``np.isnan(K).all()``), and where the surface has
        depth jumps the cut edges ``cuts_right``, ``cuts_down``, the ``discontinuities``
        map and the split mesh (``split_*``; :func:`facetlift.io.load_surface` reads it all
        back); ``.ply``/``.obj``/``.stl``: the mesh, split at the jumps (``.ply`` quads and
        ``.obj`` triangles unless ``triangles=`` says otherwise; ``.stl`` a binary STL of
        triangles only, facet normals toward the viewer, coordinates in the units of
        `pixel_size` (orthographic) or of the depth (with `K`): STL states none); ``.png``: a
        shaded preview (the map
        of the jumps is :func:`facetlift.io.write_discontinuities`, as ``--save
        discontinuities`` writes it), but ``height.png`` (also ``heightmap``, ``height_map``,
        ``displacement``) the 16-bit height map of ``--save height`` (keyword
        ``height_range``). ``frame=`` writes a mesh in another frame
        (:meth:`to_mesh`); ``colors=`` an image of the object, (H, W, 3) or (H, W) (also
        (H, W, 2) or (H, W, 4), grey or RGB with an alpha that is dropped), painted on a
        mesh's vertices or ``points.ply``'s points; non-finite colours are painted black
        (:func:`facetlift.io.colors.colour_image`; files through
        :func:`facetlift.io.read_colors`).

        The command line's own file names write what its ``--save`` writes under them
        (:data:`facetlift.io.surface.CLI_NAMES`): ``points.ply`` the point cloud of ``-s
        points`` (not the mesh; keywords ``frame``, ``normals``, the input normals
        (H, W, 3) to give each point, and ``colors``), ``discontinuities.png`` the jump map of ``-s
        discontinuities`` (refused for a surface without one), ``report.png`` the report of
        ``-s report`` (needs matplotlib; keywords ``normals``, ``dpi``) and ``height.exr``
        the heights of ``-s height-exr`` (not the depth). Every other name keeps its
        extension's meaning; ``depth.png`` is a shaded preview with a warning (the command
        line writes no depth PNG: depth goes to .npy, .exr, .tif). Files are written
        atomically. Returns the path written.
        """
        from . import io

        return io.save_surface(self, path, **kwargs)

    def __repr__(self) -> str:
        H, W = self.shape
        it = self.info.get("iterations")
        return (
            f"Surface({H}x{W}, {int(self.mask.sum())} facets, method={self.info.get('method')!r}"
            + (f", iterations={it}" if it is not None else "")
            + ")"
        )
