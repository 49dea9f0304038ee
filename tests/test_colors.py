"""Colours painted on meshes and point clouds (facetlift.io.colors, --colors)."""

from pathlib import Path

import imagecodecs
import meshio
import numpy as np
import pytest

import facetlift
from facetlift import io, synthetic
from facetlift.cli import main
from facetlift.io.colors import mesh_colors


@pytest.fixture(scope="module")
def cut():
    """A surface with depth jumps (its mesh split at them) and an image that changes colour
    from pixel to pixel."""
    gt = synthetic.analytic("occluder", 40)
    s = facetlift.integrate(gt.normals, gt.mask, discontinuities=True)
    assert s.split is not None and len(s.to_mesh()[0]) > (41 * 41)  # (vertices duplicated)
    rng = np.random.default_rng(3)
    img = rng.random(gt.shape + (3,))
    return s, img


def test_vertex_colours_are_the_mean_of_their_own_facets(cut):
    """Each vertex of the split mesh takes the mean colour of the facets that use it, counted
    here face by face, so a duplicated vertex on one side of a jump takes its side's only."""
    s, img = cut
    verts, faces = s.to_mesh()
    pixels = img[s.mask]  # (facets in row-major order, as to_mesh lists its faces)
    sums = np.zeros((len(verts), 3))
    counts = np.zeros(len(verts))
    for facet, face in enumerate(faces):
        for v in face:
            sums[v] += pixels[facet]
            counts[v] += 1
    np.testing.assert_allclose(mesh_colors(s, img), sums / counts[:, None], atol=1e-6)
    # a vertex copied at a jump: its copies differ where their sides' pixels do
    ij = np.round(verts[:, :2], 6)
    _, first, inverse = np.unique(ij, axis=0, return_index=True, return_inverse=True)
    copies = np.flatnonzero(np.arange(len(verts)) != first[inverse.ravel()])
    assert copies.size
    got = mesh_colors(s, img)
    assert np.abs(got[copies] - got[first[inverse.ravel()][copies]]).max() > 0.05


def test_ply_and_obj_carry_the_colours(cut, tmp_path):
    s, img = cut
    want = np.round(mesh_colors(s, img) * 255).astype(np.uint8)
    verts, _ = s.to_mesh()
    ply = meshio.read(s.save(tmp_path / "m.ply", colors=img))
    got = np.column_stack([ply.point_data[k] for k in ("red", "green", "blue")])
    assert got.dtype == np.uint8 and np.array_equal(got, want)
    np.testing.assert_array_equal(ply.points, verts)
    # OBJ: "v x y z r g b", coordinates exact, faces as to_mesh's (1-based)
    path = s.save(tmp_path / "m.obj", colors=img)
    lines = path.read_text().splitlines()
    v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    f = np.array([[int(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
    tv, tf = s.to_mesh(triangles=True)
    np.testing.assert_array_equal(v[:, :3], tv)
    np.testing.assert_allclose(v[:, 3:], want / 255.0, atol=6e-5)
    np.testing.assert_array_equal(f - 1, tf)


def test_obj_without_colours_reads_back_in_meshio(cut, tmp_path):
    s, _ = cut
    back = meshio.read(s.save(tmp_path / "plain.obj"))
    verts, faces = s.to_mesh(triangles=True)
    np.testing.assert_array_equal(back.points, verts)
    np.testing.assert_array_equal(back.cells[0].data, faces)


def test_points_take_their_pixel_colour(cut, tmp_path):
    s, img = cut
    cloud = meshio.read(s.save(tmp_path / "points.ply", colors=img))
    got = np.column_stack([cloud.point_data[k] for k in ("red", "green", "blue")])
    assert np.array_equal(got, np.round(img[s.mask] * 255).astype(np.uint8))


def test_colour_errors(cut, tmp_path):
    s, img = cut
    with pytest.raises(ValueError, match="`colors`: an STL holds no colours"):
        s.save(tmp_path / "m.stl", colors=img)
    with pytest.raises(ValueError, match=r"`colors`: float colours must lie in \[0, 1\]"):
        s.save(tmp_path / "m.ply", colors=img * 2)
    with pytest.raises(ValueError, match="another picture"):
        s.save(tmp_path / "m.ply", colors=img[:, :20])
    with pytest.raises(ValueError, match=r"`colors` must be an \(H, W, 3\)"):
        s.save(tmp_path / "m.ply", colors=np.zeros(s.shape + (5,)))
    with pytest.raises(ValueError, match="must hold numbers"):
        s.save(tmp_path / "m.ply", colors=np.zeros(s.shape, bool))
    with pytest.raises(ValueError, match=r"`colors` must have shape \(3, 3\)"):
        io.write_points(tmp_path / "c.ply", np.zeros((3, 3)), colors=np.zeros((2, 3)))
    assert not any(p.name.startswith("m.") for p in tmp_path.iterdir())
    before = img.copy()
    s.save(tmp_path / "ok.ply", colors=img)
    assert np.array_equal(img, before)  # (the caller's image untouched)


def test_image_kinds(tmp_path):
    """uint8, uint16, grey, RGBA, a JPEG, a linear EXR and an image twice the size."""
    H, W = 6, 8
    base = np.linspace(0, 1, H * W * 3).reshape(H, W, 3)
    u16 = np.round(base * 65535).astype(np.uint16)
    (tmp_path / "c16.png").write_bytes(imagecodecs.png_encode(u16))
    np.testing.assert_allclose(io.read_colors(tmp_path / "c16.png", (H, W)), base, atol=1e-4)
    grey = (base[..., 0] * 255).astype(np.uint8)
    (tmp_path / "g.png").write_bytes(imagecodecs.png_encode(grey))
    got = io.read_colors(tmp_path / "g.png")
    assert got.shape == (H, W, 3) and np.array_equal(got[..., 0], got[..., 2])
    rgba = np.dstack([(base * 255).astype(np.uint8), np.zeros((H, W), np.uint8)])
    (tmp_path / "a.png").write_bytes(imagecodecs.png_encode(rgba))
    np.testing.assert_allclose(io.read_colors(tmp_path / "a.png"), base, atol=1 / 255)
    (tmp_path / "j.jpg").write_bytes(imagecodecs.jpeg8_encode((base * 255).astype(np.uint8),
                                                               level=95))
    assert io.read_colors(tmp_path / "j.jpg").shape == (H, W, 3)
    import OpenEXR

    linear = np.full((H, W), 0.5, np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"R": linear, "G": linear, "B": linear}) as f:
        f.write(str(tmp_path / "l.exr"))
    np.testing.assert_allclose(io.read_colors(tmp_path / "l.exr"), 0.7354, atol=1e-3)
    big = np.repeat(np.repeat(u16, 2, axis=0), 2, axis=1)
    (tmp_path / "big.png").write_bytes(imagecodecs.png_encode(big))
    with pytest.warns(UserWarning, match="resampled to the map's size"):
        got = io.read_colors(tmp_path / "big.png", (H, W))
    np.testing.assert_allclose(got, base, atol=1e-4)  # (2 x 2 blocks: their means exact)
    with pytest.raises(ValueError, match="unsupported colour image format '.gif'"):
        io.read_colors(tmp_path / "big.gif") if (tmp_path / "big.gif").write_bytes(b"x") else 0


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_colours(tmp_path, capsys):
    gt = synthetic.analytic("sphere", 24)
    normals = io.write_normals(tmp_path / "n.png", gt.normals)
    photo = np.zeros(gt.shape + (3,), np.uint8)
    photo[:, 12:, 0] = 255
    (tmp_path / "photo.png").write_bytes(imagecodecs.png_encode(photo))
    code, _, err = _run(capsys, "integrate", normals, "--colors", tmp_path / "photo.png",
                        "-s", "ply", "-s", "points", "-o", tmp_path / "out")
    assert code == 0, err
    cloud = meshio.read(tmp_path / "out" / "points.ply")
    red = cloud.point_data["red"]
    r, c = np.nonzero(gt.mask)
    assert np.array_equal(red, np.where(c >= 12, 255, 0))
    assert "red" in meshio.read(tmp_path / "out" / "mesh.ply").point_data
    code, _, err = _run(capsys, "integrate", normals, "--colours", tmp_path / "photo.png",
                        "-s", "npy", "-o", tmp_path / "out2")
    assert code == 0 and "paints only the ply, obj and points outputs" in err
    (tmp_path / "wide.png").write_bytes(imagecodecs.png_encode(photo[:, :10]))
    code, _, err = _run(capsys, "integrate", normals, "--colors", tmp_path / "wide.png",
                        "-s", "ply", "-o", tmp_path / "out3")
    assert code == 1 and "--colors" in err and "another picture" in err
    assert not (tmp_path / "out3").exists()


def test_batch_refuses_one_colour_image(tmp_path):
    from facetlift.jobs import Job

    with pytest.raises(ValueError, match="`colors`.*a batch takes no colour image"):
        facetlift.batch([str(tmp_path / "*.png")], str(tmp_path / "o"),
                        job=Job(colors=str(tmp_path / "p.png")))


def test_a_jpeg_is_turned_as_its_exif_orientation_says(tmp_path):
    """A phone's portrait photo is stored sideways with an EXIF orientation: refused as
    another picture, or painted turned (a review)."""
    import struct

    stored = np.zeros((40, 60, 3), np.uint8)
    stored[:5, :, 0] = 255  # (the stored top rows red)
    jpg = imagecodecs.jpeg8_encode(stored, level=95)
    ifd = struct.pack(">H", 1) + struct.pack(">HHII", 0x0112, 3, 1, 6 << 16) + b"\0" * 4
    tiff = b"MM" + struct.pack(">HI", 42, 8) + ifd
    app1 = b"\xff\xe1" + struct.pack(">H", len(tiff) + 8) + b"Exif\0\0" + tiff
    (tmp_path / "o6.jpg").write_bytes(jpg[:2] + app1 + jpg[2:])
    shown = io.read_colors(tmp_path / "o6.jpg", (60, 40))  # (turned 90 deg clockwise)
    assert shown[:, -3:, 0].mean() > 0.95 and shown[:, :20, 0].max() < 0.05  # (JPEG blur)


def test_odd_images_are_refused_by_name(tmp_path):
    import OpenEXR
    import tifffile

    from facetlift.io.colors import colour_image

    with pytest.raises(ValueError, match="is empty"):
        colour_image(np.zeros((0, 0, 3)))
    with pytest.raises(ValueError, match="must be uint8 or uint16; got int16"):
        colour_image(np.zeros((4, 4, 3), np.int16))
    assert colour_image(np.full((4, 4, 3), 1.0000001, np.float32)).max() == 1.0  # (rounding)
    tifffile.imwrite(tmp_path / "cmyk.tif", np.zeros((4, 4, 4), np.uint8),
                     photometric="separated")
    with pytest.raises(ValueError, match="a CMYK TIFF"):
        io.read_colors(tmp_path / "cmyk.tif")
    plane = np.zeros((4, 4), np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"X": plane, "Y": plane, "Z": plane}) as f:
        f.write(str(tmp_path / "xyz.exr"))
    with pytest.raises(ValueError, match=r"must hold R, G and B channels .*\['X', 'Y', 'Z'\]"):
        io.read_colors(tmp_path / "xyz.exr")
    layers = {f"{lay}.{c}": plane for lay in ("Combined", "DiffCol") for c in "RGB"}
    with OpenEXR.File(header, layers) as f:
        f.write(str(tmp_path / "layers.exr"))
    with pytest.raises(ValueError, match="several colour layers"):
        io.read_colors(tmp_path / "layers.exr")


def test_more_refusals_and_a_path_for_colors(cut, tmp_path, capsys):
    s, img = cut
    rgb = (img * 255).astype(np.uint8)
    data = imagecodecs.jpeg8_encode(rgb, level=95)
    (tmp_path / "cut.jpg").write_bytes(data[:len(data) // 2])
    with pytest.raises(ValueError, match="a truncated JPEG"):
        io.read_colors(tmp_path / "cut.jpg")
    (tmp_path / "photo.png").write_bytes(imagecodecs.png_encode(rgb))
    by_path = meshio.read(s.save(tmp_path / "a.ply", colors=str(tmp_path / "photo.png")))
    by_array = meshio.read(s.save(tmp_path / "b.ply", colors=rgb))
    assert np.array_equal(by_path.point_data["red"], by_array.point_data["red"])
    code = main(["batch", str(tmp_path / "photo.png"), "-o", str(tmp_path / "o"), "--colors",
                 str(tmp_path / "photo.png")])
    assert code == 1 and "a batch takes no colour image" in capsys.readouterr().err


def test_the_same_surface_gives_the_same_bytes(cut, tmp_path):
    """PLY, OBJ and points are written by facetlift without a time stamp (meshio wrote one)."""
    s, img = cut
    up = np.dstack([np.zeros(s.shape), np.zeros(s.shape), np.ones(s.shape)])
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        s.save(tmp_path / run / "mesh.ply", colors=img)
        s.save(tmp_path / run / "mesh.obj", colors=img)
        s.save(tmp_path / run / "points.ply", colors=img, normals=up)
    for name in ("mesh.ply", "mesh.obj", "points.ply"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_a_batch_paints_each_map_with_its_own_colors_file(tmp_path):
    """NAME_colors.* beside NAME.* is that map's colour image (as NAME_prior_depth.* is its
    prior): its meshes are painted, and it is no item of its own."""
    gt = synthetic.analytic("sphere", 24)
    for name, value in (("a", 40), ("b", 200)):
        io.write_normals(tmp_path / f"{name}.png", gt.normals)
        photo = np.full(gt.shape + (3,), value, np.uint8)
        (tmp_path / f"{name}_colors.png").write_bytes(imagecodecs.png_encode(photo))
    records = facetlift.batch([str(tmp_path / "*.png")], str(tmp_path / "out"),
                              save=("ply",))
    assert sorted(r["name"] for r in records) == ["a", "b"]
    assert all(r["status"] == "ok" for r in records)
    for name, value in (("a", 40), ("b", 200)):
        red = meshio.read(tmp_path / "out" / name / "mesh.ply").point_data["red"]
        assert (red == value).all()
    assert {r["name"]: Path(r["colors_file"]).name for r in records} == {
        "a": "a_colors.png", "b": "b_colors.png"}


def test_jpeg_trailers_pass_and_cmyk_is_refused(tmp_path):
    """Data after a JPEG's end-of-image marker (a phone's trailer) was refused as truncated,
    and a CMYK JPEG painted grey as white (a review)."""
    rgb = np.full((8, 8, 3), 100, np.uint8)
    data = imagecodecs.jpeg8_encode(rgb, level=95)
    (tmp_path / "t.jpg").write_bytes(data + b"SEFH" + bytes(200))
    assert abs(io.read_colors(tmp_path / "t.jpg").mean() * 255 - 100) < 3
    (tmp_path / "cut.jpg").write_bytes(data[:-1])
    with pytest.raises(ValueError, match="truncated JPEG"):
        io.read_colors(tmp_path / "cut.jpg")
    PIL = pytest.importorskip("PIL.Image")  # (with matplotlib, the test extra's)
    PIL.new("CMYK", (8, 8), (0, 0, 0, 128)).save(tmp_path / "k.jpg")
    with pytest.raises(ValueError, match="a CMYK JPEG"):
        io.read_colors(tmp_path / "k.jpg")


def test_a_batch_skips_a_colors_file_without_its_map(tmp_path):
    """A photo X_colors.png with no map X.* ran as a normal map (a user's check)."""
    gt = synthetic.analytic("sphere", 24)
    io.write_normals(tmp_path / "a.png", gt.normals)
    photo = (np.random.default_rng(0).random(gt.shape + (3,)) * 255).astype(np.uint8)
    (tmp_path / "frame_009_colors.png").write_bytes(imagecodecs.png_encode(photo))
    with pytest.warns(UserWarning, match=r"skipped 1 file\(s\) named like a map's colours"):
        records = facetlift.batch([str(tmp_path)], str(tmp_path / "out"), save=("npy",))
    assert [r["name"] for r in records] == ["a"]
