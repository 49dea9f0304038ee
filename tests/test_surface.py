"""facetlift.Surface: depth/height/vertex depth, points and meshes."""

from __future__ import annotations

import re
import warnings

import meshio
import numpy as np
import pytest

import facetlift
from facetlift import synthetic
from facetlift.domain import Domain


def ring_mask(shape=(12, 15)):
    m = np.zeros(shape, bool)
    m[1:11, 2:14] = True
    m[4:7, 6:9] = False
    return m


@pytest.fixture
def plane_surface(make_plane):
    f = make_plane(0.3, -0.2)
    mask = ring_mask()
    h = 0.4
    return facetlift.integrate(f.normals(mask.shape, h), mask, pixel_size=h), f, h


def test_arrays_shapes_and_nan_outside(plane_surface):
    s, _, _ = plane_surface
    H, W = s.shape
    assert s.depth.shape == s.height.shape == s.mask.shape == (H, W)
    assert s.vertex_depth.shape == (H + 1, W + 1)
    assert np.array_equal(np.isfinite(s.depth), s.mask)
    assert np.array_equal(np.isfinite(s.vertex_depth), Domain.from_mask(s.mask).vertex_mask)
    np.testing.assert_array_equal(s.height, -s.depth)
    assert s.pixel_size == 0.4 and s.K is None
    assert abs(np.nanmean(s.depth)) < 1e-12  # the orthographic constant: zero mean


def test_facet_depth_is_mean_of_corner_depths(wave):
    """Conventions: the facet centre is the mean of its four corners."""
    s = facetlift.integrate(wave.normals((9, 11), 0.2), pixel_size=0.2)
    v = s.vertex_depth
    corners = (v[:-1, :-1] + v[:-1, 1:] + v[1:, 1:] + v[1:, :-1]) / 4
    np.testing.assert_allclose(s.depth, corners, rtol=0, atol=1e-12)


def test_points_facets_orthographic(plane_surface):
    s, f, h = plane_surface
    pts = s.points("facets")
    r, c = np.nonzero(s.mask)
    assert pts.shape == (r.size, 3)
    np.testing.assert_allclose(pts[:, 0], (c + 0.5) * h, rtol=1e-15)
    np.testing.assert_allclose(pts[:, 1], -(r + 0.5) * h, rtol=1e-15)
    np.testing.assert_allclose(pts[:, 2], s.height[r, c], rtol=1e-15)
    # the points lie on the input plane z = 0.3 x - 0.2 y (+ a constant)
    resid = pts[:, 2] - f.z(pts[:, 0], pts[:, 1])
    assert np.ptp(resid) < 1e-12
    assert s.points().shape == pts.shape  # "facets" is the default


def test_points_vertices_orthographic(plane_surface):
    s, f, h = plane_surface
    pts = s.points("vertices")
    i, j = np.nonzero(np.isfinite(s.vertex_depth))
    assert pts.shape == (i.size, 3)
    np.testing.assert_allclose(pts[:, 0], j * h, rtol=1e-15)
    np.testing.assert_allclose(pts[:, 1], -i * h, rtol=1e-15)
    np.testing.assert_allclose(pts[:, 2], -s.vertex_depth[i, j], rtol=1e-15)
    assert np.ptp(pts[:, 2] - f.z(pts[:, 0], pts[:, 1])) < 1e-12


def test_points_bad_where(plane_surface):
    with pytest.raises(ValueError, match="`where` must be 'facets' or 'vertices'; got 'edges'"):
        plane_surface[0].points("edges")


def test_points_perspective_project_back_to_pixels():
    """Facet points project to their pixel centre (integer index), vertex points to the
    pixel corners (half-integers), through K."""
    rng = np.random.default_rng(0)
    mask = ring_mask((6, 8))
    d = Domain.from_mask(mask)
    K = np.array([[300.0, 0.5, 3.2], [0.0, 280.0, 2.7], [0.0, 0.0, 1.0]])
    vdep = d.to_vertex_image(rng.uniform(5.0, 9.0, d.n_vertices))
    s = facetlift.Surface(depth=d.to_image(rng.uniform(5.0, 9.0, d.n_facets)),
                          vertex_depth=vdep, mask=mask, K=K)
    for where, off in (("facets", 0.0), ("vertices", -0.5)):
        pts = s.points(where)
        cam = pts * [1.0, -1.0, -1.0]  # OpenCV camera frame: y down, z forward
        uvw = cam @ K.T
        col, row = uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]
        img = s.depth if where == "facets" else s.vertex_depth
        r, c = np.nonzero(np.isfinite(img))
        np.testing.assert_allclose(col, c + off, atol=1e-12)
        np.testing.assert_allclose(row, r + off, atol=1e-12)
        np.testing.assert_allclose(cam[:, 2], img[r, c], rtol=1e-15)


def newell_normals(verts, faces):
    """Unnormalised face normals of planar or non-planar polygons (Newell's method)."""
    n = np.zeros((len(faces), 3))
    k = faces.shape[1]
    for a in range(k):
        p, q = verts[faces[:, a]], verts[faces[:, (a + 1) % k]]
        n += np.cross(p, q)
    return n


@pytest.mark.parametrize("triangles", [False, True])
def test_mesh_counts_and_orientation(wave, triangles):
    mask = ring_mask()
    h = 0.25
    s = facetlift.integrate(wave.normals(mask.shape, h, (-1.5, 1.5)), mask, pixel_size=h)
    verts, faces = s.to_mesh(triangles=triangles)
    m = int(mask.sum())
    np.testing.assert_array_equal(verts, s.points("vertices"))
    assert faces.shape == ((2 * m, 3) if triangles else (m, 4))
    assert faces.min() == 0 and faces.max() == len(verts) - 1
    assert faces.dtype == np.int32  # (32-bit below 2^31 vertices: half the memory)
    n = newell_normals(verts, faces)
    assert np.all(n[:, 2] > 0)  # toward the viewer (+z)
    # counter-clockwise seen from the viewer: positive signed area in the xy plane
    area = n[:, 2] / 2
    expected = h * h / (2 if triangles else 1)
    np.testing.assert_allclose(area, expected, rtol=1e-12)


@pytest.mark.parametrize("triangles", [False, True])
def test_mesh_of_a_plane_has_the_input_normal(make_plane, triangles):
    f = make_plane(0.6, 1.1)
    mask = ring_mask()
    s = facetlift.integrate(f.normals(mask.shape, 0.5), mask, pixel_size=0.5)
    verts, faces = s.to_mesh(triangles=triangles)
    n = newell_normals(verts, faces)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(n, np.tile([-0.6, -1.1, 1.0] / np.sqrt(1 + 0.36 + 1.21),
                                          (len(n), 1)), atol=1e-12)


def test_mesh_quads_are_the_facets(plane_surface):
    """Quad k has the four corners of pixel k (row-major), reversed to be counter-clockwise."""
    s, _, h = plane_surface
    verts, quads = s.to_mesh()
    r, c = np.nonzero(s.mask)
    xy = verts[quads][:, :, :2]
    # corners (r+1, c), (r+1, c+1), (r, c+1), (r, c)
    np.testing.assert_allclose(xy[:, 0], np.column_stack([c, -(r + 1)]) * h)
    np.testing.assert_allclose(xy[:, 1], np.column_stack([c + 1, -(r + 1)]) * h)
    np.testing.assert_allclose(xy[:, 2], np.column_stack([c + 1, -r]) * h)
    np.testing.assert_allclose(xy[:, 3], np.column_stack([c, -r]) * h)
    _, tris = s.to_mesh(triangles=True)
    # triangles 2k and 2k+1 split quad k along one of its diagonals
    for quad, pair in zip(quads, tris.reshape(-1, 2, 3), strict=True):
        assert set(pair.ravel()) == set(quad)
        shared = set(pair[0]) & set(pair[1])
        assert len(shared) == 2 and shared in ({quad[0], quad[2]}, {quad[1], quad[3]})

def test_mesh_vertices_are_numbered_from_the_mask(plane_surface):
    """A mask narrowed after the solve (or a foreign vertex depth finite beyond its mask)
    numbered the vertices from where `vertex_depth` is finite and the faces from the mask:
    294 of 296 faces of a half sphere had corners at the wrong grid points (an audit)."""
    s, _, h = plane_surface
    s.mask = s.mask & (np.arange(s.mask.shape[1])[None, :] < 8)
    verts, quads = s.to_mesh()
    r, c = np.nonzero(s.mask)
    assert len(verts) == Domain.from_mask(s.mask).n_vertices
    np.testing.assert_allclose(verts[quads][:, 3, :2], np.column_stack([c, -r]) * h)
    np.testing.assert_allclose(verts[quads][:, 1, :2], np.column_stack([c + 1, -(r + 1)]) * h)
    assert len(s.points("vertices")) == len(verts)
    s.vertex_depth = s.vertex_depth.copy()
    s.vertex_depth[r[0], c[0]] = np.nan
    with pytest.raises(ValueError, match=r"`vertex_depth` is not finite at 1 corner"):
        s.to_mesh()



def test_repr(plane_surface):
    s = plane_surface[0]
    text = repr(s)
    assert text.startswith(f"Surface(12x15, {int(s.mask.sum())} facets, method='dgp'")
    assert "iterations=1" in text


def test_save_into_a_missing_folder_names_the_target(tmp_path):
    """The error named the temporary file (.x.npy.host.pid.hex.tmp), not the path given (a
    fresh-user check)."""
    s = facetlift.integrate(np.dstack([np.zeros((5, 6, 2)), np.ones((5, 6))]))
    target = tmp_path / "nope" / "x.npy"
    with pytest.raises(FileNotFoundError, match=r"cannot write .*nope/x\.npy: its folder"):
        s.save(target)
    assert not (tmp_path / "nope").exists()


@pytest.mark.parametrize("method", ["poisson", "diffusion"])
def test_pixel_methods_edge_vertices_follow_the_normals(method):
    """A method that returns pixel values only: the mesh's edge corners are carried along each
    pixel's normal, not set to the one pixel's value (which folded every edge quad)."""
    gt = synthetic.analytic("saddle", 48)
    s = facetlift.integrate(gt.normals, gt.mask, method=method)
    assert s.info["mean_deviation"] < 1e-6  # (1.1 deg, all on the edge facets, before)
    v = s.vertex_depth
    centres = 0.25 * (v[:-1, :-1] + v[:-1, 1:] + v[1:, 1:] + v[1:, :-1])
    np.testing.assert_allclose(centres[gt.mask], s.depth[gt.mask], atol=1e-9)


def test_preview_and_mesh_keywords_are_checked(tmp_path):
    """A library user's check: bad keywords of save(".png") and to_mesh gave numpy errors,
    a 2.7 TiB allocation, an all-black PNG, or silently triangles for triangles="no"."""
    import facetlift
    from facetlift import synthetic

    g = synthetic.analytic("sphere", 24)
    s = facetlift.integrate(g.normals, g.mask)
    bad = [({"light": (1, 2)}, "`light`"), ({"light": "up"}, "`light`"),
           ({"light": (0, 0, 0)}, "`light`"), ({"light": (np.nan, 1, 1)}, "`light`"),
           ({"min_size": 10**6}, "`min_size`"), ({"min_size": "a"}, "`min_size`"),
           ({"min_size": 2.5}, "`min_size`"), ({"background": (300, 0, 0)}, "`background`"),
           ({"background": (0, 0)}, "`background`")]
    for kw, name in bad:
        with pytest.raises(ValueError, match=name):
            s.save(tmp_path / "p.png", **kw)
    assert not (tmp_path / "p.png").exists()
    s.save(tmp_path / "p.png", light=(0, 0, 1), min_size=0, background=(0, 0, 0))
    s.save(tmp_path / "q.png", min_size=300.0, background=0)  # (a whole float, a grey level)
    with pytest.raises(ValueError, match="`triangles` must be True or False"):
        s.to_mesh(triangles="no")
    for ext in (".ply", ".obj"):  # (save turned it into bool("no") before to_mesh saw it)
        with pytest.raises(ValueError, match="`triangles` must be True or False"):
            s.save(tmp_path / f"m{ext}", triangles="no")
    with pytest.raises(ValueError, match="`pixel_size` must be a positive number"):
        facetlift.integrate(g.normals, g.mask, pixel_size="1")


def test_a_png_named_as_depth_warns_that_it_is_a_preview(tmp_path):
    """Surface.save("depth.png") wrote a shaded picture without a word (a user's check)."""
    import warnings

    import facetlift
    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 24)
    s = facetlift.integrate(gt.normals, gt.mask)
    with pytest.warns(UserWarning, match=r"depth.png: a .png is a shaded preview .* \.exr"):
        s.save(tmp_path / "depth.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s.save(tmp_path / "preview.png")


def test_a_surface_from_a_depth_map_and_one_reloaded(tmp_path):
    """Surface.from_depth makes a depth map from elsewhere (a ground truth) a Surface to mesh
    or compare; io.load_surface gives back a saved .npz, its split mesh too (neither existed:
    a user's notebook could not mesh a ground truth or reload a run)."""
    from facetlift import io, synthetic

    gt = synthetic.analytic("occluder", 48)
    s = facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size,
                            discontinuities=True)
    assert s.cuts is not None and s.split is not None
    tmp = tmp_path
    path = s.save(tmp / "s.npz")
    back = io.load_surface(path)
    for a, b in zip(s.to_mesh(), back.to_mesh(), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(back.depth, s.depth)
    assert back.pixel_size == s.pixel_size and back.K is None
    np.savez(tmp / "other.npz", depth=s.depth)
    with pytest.raises(ValueError, match=r"no surface written by facetlift \(no \['vertex_depth'"):
        io.load_surface(tmp / "other.npz")
    # checked (a review: a wrong vertex_depth or a split without cuts loaded silently)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(tmp / "bad.npz", **{**arrays, "vertex_depth": arrays["vertex_depth"][:-1]})
    with pytest.raises(ValueError, match=r"vertex_depth \(48, 49\) \(not \(49, 49\)\)"):
        io.load_surface(tmp / "bad.npz")
    np.savez(tmp / "nocuts.npz", **{k: v for k, v in arrays.items() if not k.startswith("cuts")})
    with pytest.raises(ValueError, match="a split mesh without its cut edges"):
        io.load_surface(tmp / "nocuts.npz")
    np.savez(tmp / "old.npz", **{k: v for k, v in arrays.items() if not k.startswith("split")})
    with pytest.warns(UserWarning, match="before surfaces kept their split mesh"):
        old = io.load_surface(tmp / "old.npz")
    assert old.cuts is not None and old.split is None
    (tmp / "text.npz").write_text("not an archive")
    with pytest.raises(ValueError, match="is not a .npz archive"):
        io.load_surface(tmp / "text.npz")
    # a smooth depth map: the vertex depths agree with a smooth integration's to second order
    smooth = synthetic.analytic("sphere", 48)
    ref = facetlift.integrate(smooth.normals, smooth.mask, pixel_size=smooth.pixel_size)
    made = facetlift.Surface.from_depth(ref.depth, ref.mask, pixel_size=smooth.pixel_size)
    both = np.isfinite(made.vertex_depth) & np.isfinite(ref.vertex_depth)
    span = np.nanmax(ref.depth) - np.nanmin(ref.depth)
    diff = np.abs(made.vertex_depth - ref.vertex_depth)[both]
    # (inside to rounding of the second order, 4e-5 of the span in the median; the steep rim's
    # one-sided differences 2 %)
    assert np.median(diff) < 1e-3 * span and diff.max() < 0.05 * span
    verts, faces = made.to_mesh()
    assert np.isfinite(verts).all() and len(faces) == int(ref.mask.sum())
    with pytest.raises(ValueError, match=r"`depth` must be finite and positive .* at \(row 0"):
        facetlift.Surface.from_depth(np.zeros((4, 5)), K=np.diag([10.0, 10.0, 1.0]),
                                     mask=np.ones((4, 5), bool))
    with pytest.raises(ValueError, match=r"`mask` must have the shape of `depth`"):
        facetlift.Surface.from_depth(np.ones((4, 5)), np.ones((5, 4), bool))


def test_the_command_lines_file_names_are_saved_as_it_writes_them(tmp_path):
    """Surface.save("points.ply") wrote the mesh where -s points writes a point cloud,
    "discontinuities.png" a plain preview where -s discontinuities writes the jump map, and
    "height.exr" the depth where -s height-exr writes the heights (a review): every output
    name of the command line is written by save as the command line writes it (the same
    bytes); other names keep their extension's meaning."""
    import meshio

    from facetlift import io
    from facetlift.cli import main
    from facetlift.jobs import OUTPUTS

    gt = synthetic.analytic("steps", 24)
    np.save(tmp_path / "n.npy", gt.normals)
    io.write_mask(tmp_path / "m.png", gt.mask)
    kinds = [k for k in OUTPUTS if k != "report"]  # (the report's title needs the run's info)
    argv = ["integrate", tmp_path / "n.npy", "--mask", tmp_path / "m.png", "--discontinuities",
            "-o", tmp_path / "cli"] + [a for k in kinds for a in ("-s", k)]
    assert main([str(a) for a in argv]) == 0
    s = io.load_surface(tmp_path / "cli" / "surface.npz")
    (tmp_path / "py").mkdir()
    for kind in kinds:
        name = OUTPUTS[kind]
        kw = {"normals": gt.normals} if kind == "points" else {}
        s.save(tmp_path / "py" / name, **kw)
        a, b = ((tmp_path / w / name).read_bytes() for w in ("py", "cli"))
        if name.endswith((".ply", ".obj")):  # (meshio's header names the time of writing)
            a, b = (re.sub(rb"(comment|#) Created by meshio[^\n]*\n", b"", x) for x in (a, b))
        assert a == b, name
    cloud = meshio.read(tmp_path / "py" / "points.ply")
    assert len(cloud.points) == gt.mask.sum() and not cloud.cells
    assert "nx" in cloud.point_data
    s.save(tmp_path / "py" / "POINTS.PLY")  # (any case; no normals given: points alone)
    assert len(meshio.read(tmp_path / "py" / "POINTS.PLY").points) == gt.mask.sum()
    # other names keep their meaning: a mesh, a preview, a depth
    assert meshio.read(s.save(tmp_path / "cloud_points.ply")).cells
    s.save(tmp_path / "jumps.png")
    assert (tmp_path / "jumps.png").read_bytes() == io.write_preview(
        tmp_path / "preview.png", s).read_bytes()
    np.testing.assert_array_equal(io.read_depth(s.save(tmp_path / "d.exr")),
                                  np.float32(s.depth), strict=False)
    with pytest.raises(ValueError, match=r"points.ply \(as --save points writes it\) takes only "
                       r"\['frame', 'normals', 'colors'\]; got \['triangles'\]"):
        s.save(tmp_path / "points.ply", triangles=True)
    smooth = facetlift.integrate(gt.normals, gt.mask)
    with pytest.raises(ValueError, match="no discontinuity map: integrate with "
                       "discontinuities=True"):
        smooth.save(tmp_path / "discontinuities.png")
    pytest.importorskip("matplotlib")
    s.save(tmp_path / "report.png", normals=gt.normals)
    (tmp_path / "r").mkdir()
    assert (tmp_path / "report.png").read_bytes() == io.write_report(
        tmp_path / "r" / "report.png", s, gt.normals).read_bytes()


def test_point_normals_are_the_camera_frames_whatever_frame_was_integrated(tmp_path):
    """Surface.save("points.ply", normals=n) with the n given to integrate with a
    normal_frame or a normal_rotation wrote them in the caller's frame (an OpenCV map's
    faced away, an audit); they are turned as integrate turned them."""
    gt = synthetic.analytic("vase", (40, 48))
    want = gt.normals[gt.mask]
    th = np.radians(20)
    R = np.array([[1, 0, 0], [0, np.cos(th), -np.sin(th)], [0, np.sin(th), np.cos(th)]])
    world = np.einsum("ij,hwj->hwi", R.T, gt.normals)
    for given, kw in ((gt.normals * [1, -1, -1], {"normal_frame": "opencv"}),
                      (world, {"normal_rotation": R})):
        s = facetlift.integrate(given, gt.mask, **kw)
        # (also after a reload from .npz, which keeps the frame and the rotation, a review)
        again = facetlift.io.load_surface(s.save(tmp_path / "s.npz"))
        for surface in (s, again):
            cloud = meshio.read(surface.save(tmp_path / "points.ply", normals=given))
            got = np.column_stack([cloud.point_data[k] for k in ("nx", "ny", "nz")])
            np.testing.assert_allclose(got, want, atol=1e-6)


def test_a_height_named_depth_file_warns(tmp_path):
    """bear_height.exr held the depth without a word, where bear_height.png holds heights (a
    sign trap, an audit); height.exr itself writes the heights, as the command line."""
    gt = synthetic.analytic("vase", 24)
    s = facetlift.integrate(gt.normals, gt.mask)
    with pytest.warns(UserWarning, match="holds the depth .* not the heights"):
        s.save(tmp_path / "bear_height.exr")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s.save(tmp_path / "height.exr")
        s.save(tmp_path / "bear_depth.exr")


@pytest.mark.parametrize("K", [None, np.array([[60.0, 0, 15], [0, 60.0, 12], [0, 0, 1]])])
def test_scaled_changes_the_units_of_every_array_together(K):
    """s.depth *= 1000 left the mesh in metres (an audit): scaled() scales every depth, and
    an orthographic pixel size, so the points and the mesh follow as one."""
    from facetlift import synthetic

    g = synthetic.analytic("steps", 24) if K is None else None
    if K is None:
        s = facetlift.integrate(g.normals, g.mask, discontinuities=True)
    else:
        n = facetlift.normals_from_gradients(np.full((24, 30), 0.05), np.zeros((24, 30)))
        s = facetlift.integrate(n, K=K)
        s = facetlift.Surface(s.depth * 2.0, s.vertex_depth * 2.0, s.mask, s.info, K=K)
    t = s.scaled(1000)
    np.testing.assert_allclose(t.depth, s.depth * 1000)
    np.testing.assert_allclose(t.points(), s.points() * 1000, rtol=1e-12)
    np.testing.assert_allclose(t.to_mesh()[0], s.to_mesh()[0] * 1000, rtol=1e-12)
    np.testing.assert_allclose(t.points("vertices"), s.points("vertices") * 1000, rtol=1e-12)
    if K is None:
        assert t.pixel_size == 1000 * s.pixel_size and t.split is not None
    else:
        np.testing.assert_array_equal(t.K, K)
    for bad in (0, -1.0, float("nan"), "x", True):
        with pytest.raises(ValueError, match=r"`factor` must be a positive finite number"):
            s.scaled(bad)


def test_result_normals_come_back_in_the_frame_and_world_of_the_input(tmp_path):
    """Surface.save("result_normals.png") (--save normals): the result's normals where
    integrate was given an OpenCV-frame map turned from world space come back in that frame
    and world, within 16-bit steps of the input where the surface fits it exactly."""
    from facetlift import frames, io, synthetic

    g = synthetic.analytic("sphere", 40)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # world -> camera
    world = frames.rotate(frames.from_facetlift(g.normals, "opencv"), R.T)
    s = facetlift.integrate(world, g.mask, normal_frame="opencv", normal_rotation=R)
    s.save(tmp_path / "result_normals.png")
    back, alpha = io.read_normals(tmp_path / "result_normals.png")
    np.testing.assert_array_equal(alpha, g.mask)
    angle = np.degrees(np.arccos(np.clip(np.sum(back * world, -1), -1, 1)))[g.mask]
    assert np.median(angle) < 1.0 and np.median(angle) < 2 * s.info["mean_deviation"] + 0.01
    with pytest.raises(ValueError, match=r"takes only \['frame'\]"):
        s.save(tmp_path / "result_normals.png", bits=8)


def test_save_to_a_file_object_is_named():
    """s.save(BytesIO()) was a bare TypeError (an audit)."""
    import io as _io

    s = facetlift.integrate(facetlift.normals_from_gradients(np.zeros((5, 6)), np.zeros((5, 6))))
    with pytest.raises(ValueError, match=r"`path` must be a file name.*got BytesIO"):
        s.save(_io.BytesIO())


def test_a_surface_made_of_lists_works_as_one_of_arrays(tmp_path):
    """Surface(lists) failed in repr, points() and the mesh writers (an audit)."""
    depth = [[1.0, 2.0], [3.0, 4.0]]
    vd = np.arange(9.0).reshape(3, 3).tolist()
    s = facetlift.Surface(depth, vd, [[True, True], [True, False]])
    assert "2" in repr(s) and s.points().shape == (3, 3)
    s.save(tmp_path / "m.ply")
    assert (tmp_path / "m.ply").stat().st_size > 0


def test_integer_normals_are_decoded_by_the_scoring_and_point_writers(tmp_path):
    """angular_error, write_report and write_points decode uint8/uint16 normals as integrate
    does (an audit: the bear's raw PNG array scored 41.3 deg against 0.88, and points.ply got
    nx = 29830.0)."""
    from facetlift import io, metrics
    from facetlift.errors import FrameWarning

    gt = synthetic.analytic("sphere", 32, pixel_size=2 / 32)
    s = facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size)
    raw = np.round((np.nan_to_num(gt.normals) + 1) / 2 * 65535).astype(np.uint16)
    with pytest.warns(FrameWarning, match="decoded as v / 65535"):
        got = metrics.angular_error(s, raw)[0]
    assert got == pytest.approx(metrics.angular_error(s, gt.normals)[0], abs=0.01)
    with pytest.warns(FrameWarning):
        io.write_points(tmp_path / "p.ply", s.points(), normals=raw[s.mask])
    n = meshio.read(tmp_path / "p.ply").point_data
    assert np.abs(np.stack([n["nx"], n["ny"], n["nz"]])).max() <= 1.0


def test_a_reloaded_surface_keeps_its_method_for_the_report_title(tmp_path):
    """The npz keeps info's method and solver (the report of a reloaded surface was titled
    'method ?', an audit)."""
    from facetlift import io

    gt = synthetic.analytic("occluder", 48)
    s = facetlift.integrate(gt.normals, gt.mask, discontinuities=True)
    s.save(tmp_path / "s.npz")
    back = io.load_surface(tmp_path / "s.npz")
    assert (back.info["method"], back.info["solver"]) == ("dgp", s.info["solver"])


@pytest.mark.parametrize("write", ["write_depth", "write_mask", "write_mesh", "write_points",
                                   "write_preview", "write_height", "write_normals"])
def test_the_writers_name_a_file_object_given_for_a_path(write):
    """A BytesIO given to a low-level writer got a bare TypeError (an audit); Surface.save
    said what to do, and now they all do."""
    import io as bytes_io

    from facetlift import io

    s = facetlift.integrate(synthetic.analytic("sphere", 16).normals)
    args = {"write_depth": (s.depth,), "write_mask": (s.mask,),
            "write_mesh": s.to_mesh(), "write_points": (s.points(),),
            "write_preview": (s,), "write_height": (s,),
            "write_normals": (np.dstack([np.zeros((4, 4, 2)), np.ones((4, 4))]),)}[write]
    with pytest.raises(ValueError, match="`path` must be a file name .* got BytesIO"):
        getattr(io, write)(bytes_io.BytesIO(), *args)


@pytest.mark.parametrize("name, writes", [("bear_report.png", "a shaded preview"),
                                          ("bear-points.ply", "a mesh"),
                                          ("obj_result_normals.png", "a shaded preview")])
def test_a_name_that_looks_like_a_cli_output_is_warned_about(tmp_path, name, writes):
    """Only the command line's own names write its special outputs; a name ending in one
    (bear_report.png) kept its extension's meaning without a word (an audit)."""
    s = facetlift.integrate(synthetic.analytic("sphere", 16).normals)
    with pytest.warns(UserWarning, match=f"keeps its extension's meaning .*: {writes}"):
        s.save(tmp_path / name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s.save(tmp_path / "mesh.ply")
        s.save(tmp_path / "preview.png")


def test_pieces_of_a_surface_without_cuts_are_its_mask_components():
    """Facets sharing a corner are one piece (a diagonal touch joins, as the mesh's shared
    vertex does); apart, the larger is piece 0; outside the mask -1."""
    mask = np.zeros((6, 9), bool)
    mask[0:2, 0:2] = True  # 4 facets
    mask[2, 2] = True  # touches the first at a corner only: the same piece
    mask[3:6, 5:9] = True  # 12 facets, apart
    s = facetlift.Surface(np.where(mask, 1.0, np.nan), np.ones((7, 10)), mask)
    lab = s.pieces()
    assert (lab[~mask] == -1).all()
    assert (lab[3:6, 5:9] == 0).all() and (lab[0:2, 0:2] == 1).all() and lab[2, 2] == 1
    empty = facetlift.Surface(np.full((3, 3), np.nan), np.ones((4, 4)), np.zeros((3, 3), bool))
    assert (empty.pieces() == -1).all()
