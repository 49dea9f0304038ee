"""Round trips and error paths of facetlift.io."""

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import io

DATA = Path(__file__).parents[1] / ".." / "shared" / "data" / "normal_maps"


def bump_normals(H=24, W=30):
    """Analytic normals of a Gaussian bump (x right, y up), plus its mask with a hole."""
    r, c = np.mgrid[0:H, 0:W] + 0.5
    x, y = c, -r
    z = 3 * np.exp(-((x - W / 2) ** 2 + (y + H / 2) ** 2) / 40)
    p = z * -2 * (x - W / 2) / 40
    q = z * -2 * (y + H / 2) / 40
    n = facetlift.normals_from_gradients(p, q)
    mask = np.ones((H, W), bool)
    mask[8:12, 10:14] = False
    return n, mask


@pytest.fixture
def normals():
    return bump_normals()


@pytest.fixture
def surface(normals):
    n, mask = normals
    return facetlift.integrate(n, mask)


# ------------------------------------------------------------------------------ normal maps


@pytest.mark.parametrize("bits", [8, 16])
def test_png_round_trip_exact_to_quantisation(tmp_path, normals, bits):
    n, _ = normals
    path = io.write_normals(tmp_path / "n.png", n, bits=bits)
    back, alpha = io.read_normals(path)
    assert alpha is None
    assert back.dtype == np.float64 and back.shape == n.shape
    step = 2.0 / (2**bits - 1)  # one quantisation level in [-1, 1]
    err = np.abs(back - n).max()
    assert err <= step / 2 + 1e-12
    if bits == 16:  # a 16-bit file read as 8 bit would be off by up to 1/255
        assert err < 2e-5


def test_png_16bit_stays_16bit(tmp_path):
    """Values that differ only below 8-bit precision survive the round trip."""
    v = np.array([[[40000, 40001, 65535]]], np.uint16)
    n = v / 65535 * 2 - 1
    io.write_normals(tmp_path / "n.png", n, bits=16)
    back, _ = io.read_normals(tmp_path / "n.png")
    assert back[0, 0, 0] != back[0, 0, 1]
    np.testing.assert_allclose(back, n, atol=1e-12)


@pytest.mark.parametrize("ext", [".png", ".tif", ".exr", ".npy"])
def test_alpha_channel_becomes_mask(tmp_path, normals, ext):
    n, mask = normals
    io.write_normals(tmp_path / f"n{ext}", n, mask)
    back, alpha = io.read_normals(tmp_path / f"n{ext}")
    np.testing.assert_array_equal(alpha, mask)
    np.testing.assert_allclose(back, n, atol=2e-5)


@pytest.mark.parametrize("ext", [".png", ".tif", ".exr", ".npy"])
@pytest.mark.parametrize("value", [True, False])
def test_alpha_the_same_everywhere_is_no_mask(tmp_path, normals, ext, value):
    # an opaque export (alpha 255 over the background too, as editors and OpenCV write it)
    # integrated its background fill as missing normals inside the mask (a user's check);
    # fully transparent was refused as an empty mask
    n, mask = normals
    io.write_normals(tmp_path / f"n{ext}", n, np.full(mask.shape, value))
    back, alpha = io.read_normals(tmp_path / f"n{ext}")
    assert alpha is None
    np.testing.assert_allclose(back, n, atol=2e-5)


def test_a_height_in_the_alpha_is_warned_about_and_an_antialiased_edge_is_not(tmp_path):
    """An audit: a "normal + height" texture (the height in the alpha, many grey levels) had
    every alpha > 0 pixel taken as the mask without a word; 15 % of it was integrated. An
    antialiased object edge (in-between levels along the edge, here 61 of them on 7 % of a
    small image) stays silent; so does the alpha where a mask file replaces it (check_alpha
    False, or a mask given to read_normals)."""
    import warnings

    import imagecodecs

    H = W = 32
    px = np.zeros((H, W, 4), np.uint8)
    px[..., :3] = (128, 128, 255)
    ss = 16  # (an exact antialiased ellipse: its coverage of each pixel, 1/256 steps)
    yy, xx = (np.mgrid[0:H * ss, 0:W * ss] + 0.5) / ss
    inside = (yy - H / 2 - 0.37) ** 2 / 1.3 + (xx - W / 2 - 0.21) ** 2 < 9.3**2
    coverage = inside.reshape(H, ss, W, ss).mean(axis=(1, 3))
    px[..., 3] = np.round(coverage * 255)
    between = (px[..., 3] > 0) & (px[..., 3] < 255)
    assert between.mean() > 0.05 and np.unique(px[..., 3][between]).size > 16
    (tmp_path / "aa.png").write_bytes(imagecodecs.png_encode(px))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, alpha = io.read_normals(tmp_path / "aa.png")
    np.testing.assert_array_equal(alpha, coverage > 0)
    # a height in the alpha: 0 on most of the image, smooth bumps elsewhere
    r, c = np.mgrid[0:H, 0:W]
    height = 200 * np.exp(-((r - 10) ** 2 + (c - 12) ** 2) / 40) - 20
    px[..., 3] = np.clip(np.round(height), 0, 255)
    (tmp_path / "height.png").write_bytes(imagecodecs.png_encode(px))
    with pytest.warns(UserWarning, match=r"height.png: its alpha channel holds \d+ distinct "
                      r"levels between 0 and its largest, 180, on \d+% of the pixels.*height "
                      r".*every pixel with alpha > 0 inside \(\d+ of 1024\).*--mask FILE.*"
                      r"your own `mask`") as rec:
        _, alpha = io.read_normals(tmp_path / "height.png")
    assert len(rec) == 1 and alpha.mean() < 0.3
    with warnings.catch_warnings():  # (the caller has a mask of its own)
        warnings.simplefilter("error")
        io.read_normals(tmp_path / "height.png", check_alpha=False)
        io.read_normals(tmp_path / "height.png", mask=np.ones((H, W), bool))
        io.write_mask(tmp_path / "all.png", np.ones((H, W), bool))
        from facetlift import jobs

        inp = jobs.read(jobs.Job(normals=str(tmp_path / "height.png"),
                                 mask=str(tmp_path / "all.png")))
        assert inp.mask.all()


def test_a_height_on_bevelled_bricks_in_the_alpha_is_warned_about(tmp_path, brick_texture):
    """A second audit: bricks whose alpha is 0 in the groove bottoms and 255 on the faces,
    with 6-texel bevels, have their in-between values within 2 px of both on all but 4.4 % of
    the pixels (6 levels) and went unwarned; the middles of ramps wider than an antialiased
    edge count too. A feathered edge (a mask blurred with sigma 3 px) is such a ramp and is
    warned about (its soft band is taken as inside, past the object); flat translucent areas
    with antialiased edges are not, nor is a 1-px-feathered edge on a small share."""
    import imagecodecs
    from scipy import ndimage

    h, n = brick_texture(size=256)
    px = np.round((n * [1, -1, 1] + 1) / 2 * 255).astype(np.uint8)

    def read(name, alpha):
        (tmp_path / name).write_bytes(imagecodecs.png_encode(
            np.ascontiguousarray(np.dstack([px, np.round(alpha).astype(np.uint8)]))))
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            io.read_normals(tmp_path / name, frame="directx")
        return [str(w.message) for w in rec if "alpha channel" in str(w.message)]

    said = read("bricks.png", h / h.max() * 255)
    assert len(said) == 1 and re.search(r"holds 1\d distinct levels between 0 and its largest, "
                                        r"255, on 1\d% of the pixels, away from its edge or on "
                                        r"ramps wider than an antialiased edge \(a height", said[0])
    ss = 8  # (an antialiased ellipse 140 px across: its exact coverage)
    yy, xx = (np.mgrid[0:256 * ss, 0:256 * ss] + 0.5) / ss

    def cover(radius):
        inside = (yy - 128.37) ** 2 / 2.3 + (xx - 128.21) ** 2 < radius**2
        return inside.reshape(256, ss, 256, ss).mean(axis=(1, 3))

    outer, inner = cover(70.3), cover(40)
    assert read("aa.png", outer * 255) == []
    for width, diagonal in ((2, True), (3, True), (4, True), (2, False)):  # (a review: a
        # chain-link fence's antialiased wires, 45 degrees, counted as ramps once)
        d1, d2 = (xx + yy, xx - yy) if diagonal else (xx * np.sqrt(2), yy * np.sqrt(2))
        d1, d2 = np.mod(d1 / np.sqrt(2), 12), np.mod(d2 / np.sqrt(2), 12)
        on = (np.minimum(d1, 12 - d1) < width / 2) | (np.minimum(d2, 12 - d2) < width / 2)
        assert read(f"wires{width}{diagonal}.png",
                    on.reshape(256, ss, 256, ss).mean(axis=(1, 3)) * 255) == [], width
    assert read("translucent.png", outer * 255 - inner * 127) == []  # (128 inside, AA edges)
    assert read("feather1.png", ndimage.gaussian_filter((outer > 0.5) * 255.0, 1)) == []
    said = read("feather3.png", ndimage.gaussian_filter((outer > 0.5) * 255.0, 3))
    assert len(said) == 1 and "or a feathered edge, whose whole soft band" in said[0]
    assert "its alpha thresholded at half its largest" in said[0]


def test_a_height_in_a_float_alpha_with_nan_is_warned_about(tmp_path):
    """A review: the check took the alpha's largest value with max(), NaN for a float alpha
    holding one NaN, and a height in such an alpha went unwarned. NaN alpha is transparent
    (outside the mask, as alpha > 0 makes it), and the largest is the mask's."""
    H = W = 32
    r, c = np.mgrid[0:H, 0:W]
    height = np.clip(0.8 * np.exp(-((r - 10) ** 2 + (c - 12) ** 2) / 40) - 0.08, 0, None)
    px = np.zeros((H, W, 4))
    px[..., 2] = 1.0
    px[..., 3] = height
    px[0, 0, 3] = px[12, 12, 3] = np.nan  # (one in the background, one in the bump)
    np.save(tmp_path / "h.npy", px)
    with pytest.warns(UserWarning, match=r"h.npy: its alpha channel holds \d+ distinct levels "
                      r"between 0 and its largest, 0.72, on \d+% of the pixels") as rec:
        _, alpha = io.read_normals(tmp_path / "h.npy")
    assert len(rec) == 1
    assert not alpha[0, 0] and not alpha[12, 12]  # (NaN: transparent)
    np.testing.assert_array_equal(alpha, np.nan_to_num(px[..., 3]) > 0)


@pytest.mark.parametrize(
    "ext, bits, atol", [(".exr", 32, 1e-7), (".npy", 32, 0), (".tif", 32, 1e-7),
                        (".tif", 16, 2e-5), (".tif", 8, 4e-3)]
)
def test_float_and_tiff_round_trips(tmp_path, normals, ext, bits, atol):
    n, _ = normals
    io.write_normals(tmp_path / f"n{ext}", n, bits=bits)
    back, alpha = io.read_normals(tmp_path / f"n{ext}")
    assert alpha is None
    np.testing.assert_allclose(back, n, atol=atol)


def test_exr_xyz_channels(tmp_path, normals):
    import OpenEXR

    n, _ = normals
    ch = {k: n[..., i].astype(np.float32) for i, k in enumerate("XYZ")}
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(hdr, ch).write(str(tmp_path / "n.exr"))
    back, alpha = io.read_normals(tmp_path / "n.exr")
    assert alpha is None
    np.testing.assert_allclose(back, n, atol=1e-7)


def test_an_exr_data_window_is_placed_in_its_display_window(tmp_path, normals):
    """A compositor's bounding-box crop stores the pixels of part of the frame (its data
    window): it was read at that part's size, so a K or a mask of the frame missed it by
    the window's offset (a review). Now placed in the frame, NaN (alpha 0) around it."""
    import OpenEXR

    n, _ = normals
    H, W = n.shape[:2]
    part = n[2:H - 3, 3:W - 1].astype(np.float32)
    ch = {k: np.ascontiguousarray(part[..., i]) for i, k in enumerate("RGB")}
    ch["A"] = np.ones(part.shape[:2], np.float32)
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
           "dataWindow": (np.array([3, 2], np.int32), np.array([W - 2, H - 4], np.int32)),
           "displayWindow": (np.array([0, 0], np.int32), np.array([W - 1, H - 1], np.int32))}
    OpenEXR.File(hdr, ch).write(str(tmp_path / "crop.exr"))
    back, alpha = io.read_normals(tmp_path / "crop.exr")
    assert back.shape == n.shape
    np.testing.assert_allclose(back[2:H - 3, 3:W - 1], part, atol=1e-7)
    inside = np.zeros((H, W), bool)
    inside[2:H - 3, 3:W - 1] = True
    assert np.isnan(back[~inside]).all()
    np.testing.assert_array_equal(alpha, inside)
    # a data window reaching past the display window: the shared part
    hdr["dataWindow"] = (np.array([-2, -1], np.int32), np.array([W - 3, H - 2], np.int32))
    ch = {k: np.ascontiguousarray(n[..., i].astype(np.float32)) for i, k in enumerate("RGB")}
    OpenEXR.File(hdr, ch).write(str(tmp_path / "over.exr"))
    back, _ = io.read_normals(tmp_path / "over.exr")
    np.testing.assert_allclose(back[:-1, :-2], n[1:, 2:], atol=1e-7)
    assert np.isnan(back[-1]).all() and np.isnan(back[:, -2:]).all()


def test_exr_normals_under_other_channel_names_and_cycles_denoising_layers(tmp_path, normals):
    """An audit of real exports: lowercase x, y, z (N.x), Nuke's red, green, blue and a
    Cycles multilayer file with 'Denoising Data' on (ViewLayer.Denoising Normal beside
    ViewLayer.Normal) were refused; each is read now, the Normal layer itself chosen."""
    import OpenEXR

    n, _ = normals
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    files = {
        "lower.exr": {f"N.{k}": n[..., i] for i, k in enumerate("xyz")},
        "nuke.exr": {k: n[..., i] for i, k in enumerate(("red", "green", "blue"))},
        "denoise.exr": {**{f"ViewLayer.Normal.{k}": n[..., i] for i, k in enumerate("XYZ")},
                        **{f"ViewLayer.Denoising Normal.{k}": 0.5 * n[..., i]
                           for i, k in enumerate("XYZ")}},
    }
    for name, ch in files.items():
        OpenEXR.File(hdr, {k: v.astype(np.float32) for k, v in ch.items()}).write(
            str(tmp_path / name))
        np.testing.assert_allclose(io.read_normals(tmp_path / name)[0], n, atol=1e-7,
                                   err_msg=name)


def test_exr_multilayer_normal_pass(tmp_path, normals):
    """A multilayer EXR (Blender's render layers: ``ViewLayer.Normal.X``, ...) gives its one
    layer named normal, with that layer's alpha; without one, or with two, the message lists
    the layers (a fresh user's file was refused with its channels only)."""
    import OpenEXR

    n, _ = normals
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    ch = {f"ViewLayer.Normal.{k}": n[..., i].astype(np.float32) for i, k in enumerate("XYZ")}
    ch.update({f"ViewLayer.Combined.{k}": np.ones(n.shape[:2], np.float32) for k in "RGBA"})
    a = np.ones(n.shape[:2], np.float32)
    a[0, 0] = 0.0
    ch["ViewLayer.Normal.A"] = a
    OpenEXR.File(hdr, ch).write(str(tmp_path / "m.exr"))
    back, alpha = io.read_normals(tmp_path / "m.exr")
    np.testing.assert_allclose(back, n, atol=1e-7)
    assert alpha is not None and not alpha[0, 0] and alpha[1:].all()
    del ch["ViewLayer.Normal.A"]
    ch.update({f"Other.normal.{k}": n[..., i].astype(np.float32) for i, k in enumerate("XYZ")})
    OpenEXR.File(hdr, ch).write(str(tmp_path / "two.exr"))
    with pytest.raises(ValueError, match=r"layers with three components are Other.normal, "
                       r"ViewLayer.Combined, ViewLayer.Normal \(more than one named normal"):
        io.read_normals(tmp_path / "two.exr")
    only = {f"ViewLayer.Combined.{k}": np.ones(n.shape[:2], np.float32) for k in "RGB"}
    OpenEXR.File(hdr, only).write(str(tmp_path / "none.exr"))
    with pytest.raises(ValueError, match=r"one layer named normal .*are ViewLayer.Combined: "
                       r"save the normal pass alone"):
        io.read_normals(tmp_path / "none.exr")
    # a compositor's layer called N (N.X, N.Y, N.Z) is the normal pass too (an audit), a
    # render pass's sub-layer called N is not (a review)
    short = {f"N.{k}": n[..., i].astype(np.float32) for i, k in enumerate("XYZ")}
    OpenEXR.File(hdr, short).write(str(tmp_path / "short.exr"))
    np.testing.assert_allclose(io.read_normals(tmp_path / "short.exr")[0], n, atol=1e-7)
    sub = {f"Diffuse.N.{k}": n[..., i].astype(np.float32) for i, k in enumerate("XYZ")}
    OpenEXR.File(hdr, sub).write(str(tmp_path / "sub.exr"))
    with pytest.raises(ValueError, match=r"one layer named normal \(or N\)"):
        io.read_normals(tmp_path / "sub.exr")


@pytest.mark.parametrize("ext", [".png", ".npy"])
def test_y_down_flips_y_only(tmp_path, normals, ext):
    n, _ = normals
    io.write_normals(tmp_path / f"n{ext}", n, y_down=True)
    raw, _ = io.read_normals(tmp_path / f"n{ext}")
    np.testing.assert_allclose(raw[..., 1], -n[..., 1], atol=2e-5)
    back, _ = io.read_normals(tmp_path / f"n{ext}", y_down=True)
    np.testing.assert_allclose(back, n, atol=2e-5)


def test_background_fill_decodes_as_nan(tmp_path):
    px = np.zeros((2, 3, 3), np.uint8)
    px[0, 0] = (128, 128, 255)  # facing the viewer
    px[0, 1] = (127, 127, 127)  # mid-grey background
    px[0, 2] = (255, 255, 255)  # white background
    (tmp_path / "n.png").write_bytes(__import__("imagecodecs").png_encode(px))
    n, _ = io.read_normals(tmp_path / "n.png")
    assert np.isfinite(n[0, 0]).all() and n[0, 0, 2] == 1.0
    assert np.isnan(n[0, 1:]).all() and np.isnan(n[1]).all()  # black too


def test_a_grey_image_saved_as_rgb_is_refused(tmp_path, normals):
    """An audit: a height map saved as RGB (R = G = B everywhere) was integrated, ~30 % of it
    facing away, into garbage. Only the pixels inside the alpha count; a map with some grey
    pixels (a background fill) is read."""
    import imagecodecs

    r, c = np.mgrid[0:24, 0:30]
    h = (127 + 100 * np.sin(r / 5) * np.cos(c / 7)).astype(np.uint8)
    grey = np.dstack([h, h, h])
    for bits, px in ((8, grey), (16, grey.astype(np.uint16) * 257)):
        (tmp_path / f"grey{bits}.png").write_bytes(imagecodecs.png_encode(px))
        with pytest.raises(ValueError, match=rf"grey{bits}.png: R = G = B at every pixel of the "
                           r"image: a grey image \(a height map\?\), not a normal map"):
            io.read_normals(tmp_path / f"grey{bits}.png")
    np.save(tmp_path / "grey.npy", grey)
    with pytest.raises(ValueError, match=r"grey.npy: R = G = B"):
        io.read_normals(tmp_path / "grey.npy")
    # inside the alpha only: grey inside it is refused, grey outside it is background
    n, mask = normals
    io.write_normals(tmp_path / "n.png", n, mask)
    px = imagecodecs.png_decode((tmp_path / "n.png").read_bytes())
    outside = px.copy()
    outside[~mask, :3] = grey[~mask]
    (tmp_path / "outside.png").write_bytes(imagecodecs.png_encode(outside))
    back, alpha = io.read_normals(tmp_path / "outside.png")
    np.testing.assert_allclose(back[mask], n[mask], atol=4e-3)
    inside = px.copy()
    inside[mask, :3] = grey[mask]
    inside[~mask, :3] = (128, 128, 255)  # (colour outside the alpha does not count)
    (tmp_path / "inside.png").write_bytes(imagecodecs.png_encode(inside))
    with pytest.raises(ValueError, match=r"inside.png: R = G = B at every pixel inside the mask"):
        io.read_normals(tmp_path / "inside.png")
    # some grey pixels (mid-grey and black fill) in a normal map: read, as before
    some = px[..., :3].copy()
    some[~mask] = (127, 127, 127)
    some[0, :5] = 0
    (tmp_path / "some.png").write_bytes(imagecodecs.png_encode(some))
    back, _ = io.read_normals(tmp_path / "some.png")
    assert np.isfinite(back[1:][mask[1:]]).all() and np.isnan(back[0, :5]).all()


def test_nan_normals_written_to_png_read_back_as_nan(tmp_path, normals):
    n, mask = normals
    n = n.copy()
    n[~mask] = np.nan
    io.write_normals(tmp_path / "n.png", n)
    back, _ = io.read_normals(tmp_path / "n.png")
    np.testing.assert_array_equal(np.isnan(back).any(-1), ~mask)


# ------------------------------------------------------------------------------ masks and K


@pytest.mark.parametrize("ext", [".png", ".tif", ".npy"])
def test_mask_round_trip(tmp_path, normals, ext):
    _, mask = normals
    io.write_mask(tmp_path / f"m{ext}", mask)
    np.testing.assert_array_equal(io.read_mask(tmp_path / f"m{ext}", mask.shape), mask)


def test_rgb_and_rgba_masks(tmp_path):
    import imagecodecs

    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[0, 0, 2] = 9  # any channel nonzero is inside
    (tmp_path / "rgb.png").write_bytes(imagecodecs.png_encode(rgb))
    np.testing.assert_array_equal(io.read_mask(tmp_path / "rgb.png"), [[1, 0], [0, 0]])
    rgba = np.full((2, 2, 4), 255, np.uint8)
    rgba[0, 0, 3] = 0  # transparent: outside
    rgba[1, 1, :3] = 0  # opaque black: outside
    (tmp_path / "rgba.png").write_bytes(imagecodecs.png_encode(rgba))
    np.testing.assert_array_equal(io.read_mask(tmp_path / "rgba.png"), [[0, 1], [1, 0]])
    # the shape in the alpha of one colour (black): the alpha is the mask
    shape = np.zeros((2, 2, 4), np.uint8)
    shape[0, 1, 3] = shape[1, 0, 3] = 255
    (tmp_path / "alpha.png").write_bytes(imagecodecs.png_encode(shape))
    np.testing.assert_array_equal(io.read_mask(tmp_path / "alpha.png"), [[0, 1], [1, 0]])
    # the shape in the colour, alpha 0 everywhere (an export without alpha): the colour
    colour = np.zeros((2, 2, 4), np.uint8)
    colour[1, 1, :3] = 255
    (tmp_path / "colour.png").write_bytes(imagecodecs.png_encode(colour))
    np.testing.assert_array_equal(io.read_mask(tmp_path / "colour.png"), [[0, 0], [0, 1]])


def test_an_antialiased_mask_is_warned_about(tmp_path):
    """A mask with blurred edges: every non-zero pixel is inside, a halo past the object
    that a user's bear mask grew by 2,549 pixels without a word; 0/1 and 0/255 masks, and
    a few in-between pixels, are no matter."""
    import warnings

    import imagecodecs
    from scipy import ndimage

    hard = np.zeros((40, 50), np.uint8)
    hard[10:30, 12:40] = 255
    soft = np.clip(ndimage.gaussian_filter(hard.astype(float), 1.5), 0, 255).astype(np.uint8)
    (tmp_path / "soft.png").write_bytes(imagecodecs.png_encode(soft))
    with pytest.warns(UserWarning, match=r"soft.png: \d+ of its \d+ inside pixels, along its "
                      r"edge, hold values between 0 and its largest, 255 \(an antialiased"):
        m = io.read_mask(tmp_path / "soft.png")
    assert m.sum() > (hard > 0).sum()
    # the same edge in the alpha of a one-colour RGBA export
    rgba = np.zeros((40, 50, 4), np.uint8)
    rgba[..., 3] = soft
    (tmp_path / "alpha.png").write_bytes(imagecodecs.png_encode(rgba))
    with pytest.warns(UserWarning, match=r"alpha.png: \d+ of its"):
        io.read_mask(tmp_path / "alpha.png")
    few = hard.copy()
    few[10, 12] = 128
    labels = hard // 255  # a label mask: 1 and 2, every non-zero inside (a review)
    labels[10:30, 26:40] = 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name, a in (("ones.png", (hard > 0).astype(np.uint8)), ("hard.png", hard),
                        ("few.png", few), ("labels.png", labels)):
            (tmp_path / name).write_bytes(imagecodecs.png_encode(a))
            np.testing.assert_array_equal(io.read_mask(tmp_path / name), hard > 0)


def test_mask_shape_mismatch(tmp_path):
    io.write_mask(tmp_path / "m.png", np.ones((4, 5)))
    with pytest.raises(ValueError, match=r"`mask`.*size 4x5.*normal map is 6x5"):
        io.read_mask(tmp_path / "m.png", (6, 5))


def test_read_K(tmp_path):
    K = np.array([[500.0, 0, 320.5], [0, 510, 240.25], [0, 0, 1]])
    np.savetxt(tmp_path / "K.txt", K)
    np.testing.assert_array_equal(io.read_K(tmp_path / "K.txt"), K)


@pytest.mark.parametrize("text", [
    "500 0 320.5\n0 510 240.25\n0 0 1\n",  # three rows
    "# intrinsics\n500, 0, 320.5\n0, 510, 240.25\n0, 0, 1\n",  # commas, a comment
    "500 0 320.5 0 510 240.25 0 0 1\n",  # nine numbers on one line, row by row
    "500 510 320.5 240.25\n",  # fx fy cx cy
    "\ufeff500 0 320.5\r\n0 510 240.25\r\n0 0 1\r\n",  # a spreadsheet's byte-order mark, CRLF
    "500; 0; 320.5\n0; 510; 240.25\n0; 0; 1\n",  # semicolons
    "fx fy cx cy\n500 510 320.5 240.25\n",  # a header (a user's file was refused)
    "cx,cy,fx,fy\n320.5,240.25,500,510\n",  # a header in another order
    "[[500, 0, 320.5], [0, 510, 240.25], [0, 0, 1]]",  # JSON
    "[500, 510, 320.5, 240.25]",
    '{"fx": 500, "fy": 510, "cx": 320.5, "cy": 240.25}',
    "npy",
])
def test_read_K_layouts(tmp_path, text):
    """The layouts users' files come in (a user's check: K.npy failed with a utf-8 error,
    nine numbers on one line with 'got shape (1, 9)')."""
    K = np.array([[500.0, 0, 320.5], [0, 510, 240.25], [0, 0, 1]])
    if text == "npy":
        np.save(tmp_path / "K.npy", K)
        path = tmp_path / "K.npy"
    else:
        path = tmp_path / "K.txt"
        path.write_text(text)
    np.testing.assert_array_equal(io.read_K(path), K)


def test_read_K_names_a_transposed_matrix(tmp_path):
    (tmp_path / "K.txt").write_text("500 0 0\n0 510 0\n320.5 240.25 1\n")
    with pytest.raises(ValueError, match="last row.*looks transposed"):
        io.read_K(tmp_path / "K.txt")


def test_read_K_takes_a_calibration_mat_file(tmp_path):
    """An audit: --K Calib_Results.mat (DiLiGenT's calibration: the toolbox's KK beside each
    view's 3x3 rotation Rc_1, ...) failed with "cannot parse ... ('utf-8' codec can't
    decode ...)". Its KK is read (or K, or the only 3x3 variable), checked as a text file's
    (a transposed one named so); one without such a variable lists what it holds."""
    from scipy import io as sio

    KK = np.array([[3772.08, 0, 305.875], [0, 3759.01, 255.125], [0, 0, 1]])
    rot = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])
    sio.savemat(tmp_path / "Calib_Results.mat", {"KK": KK, "Rc_1": rot, "fc": [[3772.08],
                                                 [3759.01]], "cc": [[305.875], [255.125]]})
    np.testing.assert_array_equal(io.read_K(tmp_path / "Calib_Results.mat"), KK)
    sio.savemat(tmp_path / "k.mat", {"K": KK, "R": rot})
    np.testing.assert_array_equal(io.read_K(tmp_path / "k.mat"), KK)
    sio.savemat(tmp_path / "only.mat", {"intrinsics": KK, "scale": 2.0})
    np.testing.assert_array_equal(io.read_K(tmp_path / "only.mat"), KK)
    sio.savemat(tmp_path / "t.mat", {"KK": KK.T})
    with pytest.raises(ValueError, match=r"^`K`: .*t\.mat: .*last row.*looks transposed"):
        io.read_K(tmp_path / "t.mat")
    sio.savemat(tmp_path / "two.mat", {"A": KK, "B": rot})
    with pytest.raises(ValueError, match=r"must hold the 3x3 intrinsics as KK or K, or one 3x3 "
                       r"numeric variable; got variables A \(3x3\), B \(3x3\)"):
        io.read_K(tmp_path / "two.mat")
    (tmp_path / "bad.mat").write_bytes(b"\xff\xfe not a mat file")
    with pytest.raises(ValueError, match=r"`K`: .*bad\.mat is not a readable \.mat file"):
        io.read_K(tmp_path / "bad.mat")


def test_a_transposed_K_is_named_so_in_python():
    """An audit: integrate(..., K=K.T) said "must be upper-triangular ..." without the "looks
    transposed" hint that read_K gives; a K wrong otherwise gets no such hint."""
    import facetlift

    n = np.dstack([np.zeros((20, 30, 2)), np.ones((20, 30))])
    K = np.array([[40.0, 0, 14.5], [0, 40.0, 9.5], [0, 0, 1]])
    with pytest.raises(ValueError, match=r"upper-triangular.*; it looks transposed .*give its "
                       "transpose"):
        facetlift.integrate(n, K=K.T)
    with pytest.raises(ValueError, match=r"upper-triangular with last row .*\]\]\)?$"):
        facetlift.integrate(n, K=[[40.0, 0, 14.5], [0, 40.0, 9.5], [0, 0, 2]])


@pytest.mark.parametrize(
    "text, match",
    [("1 2 3\n4 5 6\n", r"6 number\(s\).*3x3.*fx fy cx cy"), ("a b c\n", "cannot parse"),
     ("1 2\n", r"2 number\(s\)"),
     ("-1 0 0\n0 1 0\n0 0 1\n", "focal"), ("1 0 0\n0 1 0\n1 0 1\n", "last row"),
     ("fx fy cx\n1 2 3\n", r"a header must name fx, fy, cx, cy once each"),
     ('{"fx": 500, "fy": 510}', r"a JSON object needs fx, fy, cx, cy; \['cx', 'cy'\] missing"),
     ("[1, 2", "cannot parse.*as JSON")],
)
def test_read_K_errors(tmp_path, text, match):
    (tmp_path / "K.txt").write_text(text)
    with pytest.raises(ValueError, match=match):
        io.read_K(tmp_path / "K.txt")


# ------------------------------------------------------------------------------ datasets


def test_read_dataset_folder(tmp_path, normals):
    n, mask = normals
    io.write_normals(tmp_path / "normal_map.png", n, bits=8)
    io.write_mask(tmp_path / "mask.png", mask)
    ds = io.read_dataset(tmp_path)
    assert ds["K"] is None
    np.testing.assert_array_equal(ds["mask"], mask)
    np.testing.assert_allclose(ds["normals"], n, atol=1 / 255 + 1e-12)
    K = np.array([[100.0, 0, 15], [0, 100, 12], [0, 0, 1]])
    np.savetxt(tmp_path / "K.txt", K)
    np.testing.assert_array_equal(io.read_dataset(tmp_path)["K"], K)


def test_read_dataset_errors(tmp_path):
    with pytest.raises(ValueError, match="nope does not exist"):  # (InputFileNotFound)
        io.read_dataset(tmp_path / "nope")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(ValueError, match="file.txt is not a directory"):
        io.read_dataset(tmp_path / "file.txt")
    (tmp_path / "file.txt").unlink()
    with pytest.raises(ValueError, match="no normal_map"):
        io.read_dataset(tmp_path)
    # a file that cannot be used is said, not skipped; two candidates are not picked from
    n = np.dstack([np.zeros((6, 7, 2)), np.ones((6, 7))])
    np.save(tmp_path / "normal_map.npy", n)
    (tmp_path / "K.txt").mkdir()
    with pytest.raises(ValueError, match=r"`folder`: .*K.txt is not a file"):
        io.read_dataset(tmp_path)
    (tmp_path / "K.txt").rmdir()
    io.write_normals(tmp_path / "normal_map.png", n)
    with pytest.raises(ValueError, match="holds normal_map.png and normal_map.npy; keep one"):
        io.read_dataset(tmp_path)


@pytest.mark.parametrize(
    "name", ["bini_supp_tent_ortho", "bini_human_ortho_real", "diligent_bear"]
)
def test_real_datasets(name):
    folder = DATA / name
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    ds = io.read_dataset(folder)
    n, mask = ds["normals"], ds["mask"]
    assert n.shape[:2] == mask.shape and mask.any()
    length = np.linalg.norm(n[mask], axis=-1)
    # decoded inside the mask: unit length to quantisation, as in ../shared/data/SOURCES.md
    assert np.all(np.abs(length - 1) < 0.015)
    assert (ds["K"] is not None) == (folder / "K.txt").is_file()
    if name == "bini_supp_tent_ortho":  # three distinct normals: flat, and +-45 deg about x
        up = n[mask][:, 2] > 0.99
        assert up.any()
        tilted = n[mask][~up]
        np.testing.assert_allclose(np.abs(tilted[:, 1]), np.sqrt(0.5), atol=1e-3)
        np.testing.assert_allclose(tilted[:, 0], 0, atol=1e-3)
    if name == "diligent_bear":
        np.testing.assert_allclose(ds["K"][0, 2], 305.875)


# ------------------------------------------------------------------------------ surfaces


@pytest.mark.parametrize("ext, atol", [(".npy", 0), (".exr", 1e-5), (".tif", 1e-5)])
def test_depth_round_trip_keeps_nan(tmp_path, surface, ext, atol):
    path = surface.save(tmp_path / f"d{ext}")
    d = io.read_depth(path)
    np.testing.assert_array_equal(np.isnan(d), ~surface.mask)
    np.testing.assert_allclose(d[surface.mask], surface.depth[surface.mask], atol=atol)


def test_npz(tmp_path, surface):
    with np.load(surface.save(tmp_path / "s.npz")) as z:
        np.testing.assert_array_equal(z["depth"], surface.depth)
        np.testing.assert_array_equal(z["vertex_depth"], surface.vertex_depth)
        np.testing.assert_array_equal(z["mask"], surface.mask)
        assert z["pixel_size"] == surface.pixel_size and np.isnan(z["K"]).all()


@pytest.mark.parametrize("ext", [".ply", ".obj"])
@pytest.mark.parametrize("triangles", [False, True])
def test_mesh_round_trip(tmp_path, surface, ext, triangles):
    import meshio

    path = surface.save(tmp_path / f"m{ext}", triangles=triangles)
    mesh = meshio.read(path)
    verts, faces = surface.to_mesh(triangles=triangles)
    np.testing.assert_allclose(mesh.points, verts, atol=1e-12)
    assert len(mesh.cells) == 1
    assert mesh.cells[0].type == ("triangle" if triangles else "quad")
    np.testing.assert_array_equal(mesh.cells[0].data, faces)


def test_ply_is_binary(tmp_path, surface):
    head = surface.save(tmp_path / "m.ply").read_bytes()[:200]
    assert b"format binary_little_endian" in head


#: A binary STL's records after its 80-byte header and triangle count.
STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])


def test_stl_is_binary_triangles_facing_the_viewer(tmp_path, surface):
    """An STL holds two triangles per facet, the PLY's vertices (as float32) in to_mesh's
    order, and facet normals toward the viewer (+z, as the input's: a bump seen from above)."""
    import meshio

    path = surface.save(tmp_path / "m.stl")
    data = path.read_bytes()
    assert not data.startswith(b"solid")  # (binary: an ASCII STL starts so)
    count = int(np.frombuffer(data, "<u4", 1, 80)[0])
    assert count == 2 * surface.mask.sum() and len(data) == 84 + 50 * count
    rec = np.frombuffer(data, STL_RECORD, offset=84)
    verts, faces = surface.to_mesh(triangles=True)
    np.testing.assert_array_equal(rec["corners"], verts[faces].astype(np.float32))
    ply = meshio.read(surface.save(tmp_path / "m.ply"))
    assert ply.cells[0].type == "quad" and 2 * len(ply.cells[0].data) == count
    np.testing.assert_allclose(np.unique(rec["corners"].reshape(-1, 3), axis=0),
                               np.unique(np.float32(ply.points), axis=0))
    n = rec["normal"].astype(float)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-6)
    assert (n[:, 2] > 0).all()
    # each pixel's two facet normals against the input normal there (row-major facets)
    normals, mask = bump_normals()
    pair = n.reshape(-1, 2, 3).sum(axis=1)
    pair /= np.linalg.norm(pair, axis=1, keepdims=True)
    cos = np.sum(pair * normals[mask], axis=1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 2
    back = meshio.read(path)  # (its reader merges the corners that coincide)
    assert back.cells[0].type == "triangle" and len(back.cells[0].data) == count
    assert len(back.points) == len(verts)


def test_stl_takes_triangles_only(tmp_path, surface):
    with pytest.raises(ValueError, match=r"`triangles`: an STL holds triangles only"):
        surface.save(tmp_path / "m.stl", triangles=False)
    with pytest.raises(ValueError, match="`triangles` must be True or False"):
        surface.save(tmp_path / "m.stl", triangles="no")
    with pytest.raises(ValueError, match=r"`faces`: an STL holds triangles only; got quads"):
        io.write_mesh(tmp_path / "m.stl", *surface.to_mesh())
    assert list(tmp_path.iterdir()) == []
    assert surface.save(tmp_path / "m.stl", triangles=True).read_bytes() == surface.save(
        tmp_path / "n.stl").read_bytes()


def test_stl_facet_normals_follow_the_winding(tmp_path):
    """Counter-clockwise seen from +z faces +z, the other way -z; a degenerate triangle gets
    (0, 0, 0), not NaN."""
    import warnings

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], float)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        io.write_mesh(tmp_path / "t.stl", v, np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]]))
    rec = np.fromfile(tmp_path / "t.stl", STL_RECORD, offset=84)
    np.testing.assert_array_equal(rec["normal"], [[0, 0, 1], [0, 0, -1], [0, 0, 0]])


def test_stl_is_written_in_bounded_memory(tmp_path):
    """A large map's STL is written block by block: meshio's writer held about 184 B per
    triangle (a 1024^2 map's 2M triangles: 369 MiB, 3.7 times the file), more than the
    solve's estimate per pixel; the file is the same records as a whole-array write."""
    import tracemalloc

    N = 768
    r, c = np.mgrid[0:N + 1, 0:N + 1]
    v = np.column_stack([c.ravel(), -r.ravel(), 0.01 * (r * c).ravel() % 7]).astype(float)
    i = (np.arange(N)[:, None] * (N + 1) + np.arange(N)).ravel()
    q = np.column_stack([i + N + 1, i + N + 2, i + 1, i])
    f = np.empty((2 * len(q), 3), np.int64)
    f[0::2], f[1::2] = q[:, [0, 1, 2]], q[:, [0, 2, 3]]
    tracemalloc.start()
    try:
        path = io.write_mesh(tmp_path / "big.stl", v, f)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    size = path.stat().st_size
    assert size == 84 + 50 * len(f)
    assert peak < 0.5 * size, (peak / 2**20, size / 2**20)
    rec = np.fromfile(path, STL_RECORD, offset=84)
    np.testing.assert_array_equal(rec["corners"], np.float32(v[f]))
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    np.testing.assert_allclose(rec["normal"], n / np.linalg.norm(n, axis=1, keepdims=True),
                               atol=1e-6)
    assert (rec["attr"] == 0).all()


@pytest.mark.parametrize("frame", ["opencv", "directx"])
def test_stl_in_another_frame_still_faces_the_viewer(tmp_path, surface, frame):
    from facetlift import frames

    rec = np.fromfile(surface.save(tmp_path / "m.stl", frame=frame), STL_RECORD, offset=84)
    toward = frames.from_facetlift(np.array([[0.0, 0.0, 1.0]]), frame, "frame")[0]
    assert (rec["normal"] @ toward > 0).all()


def test_preview(tmp_path, surface):
    import imagecodecs

    img = imagecodecs.png_decode(surface.save(tmp_path / "p.png", min_size=1).read_bytes())
    assert img.shape == surface.shape + (3,) and img.dtype == np.uint8
    assert (img[~surface.mask] == 255).all()  # background
    inside = img[surface.mask].astype(float).mean(-1)
    assert inside.std() > 5  # the bump is shaded, not flat
    # lit from the upper left: the upper-left flank is brighter than the lower-right one
    H, W = surface.shape
    assert img[H // 2 - 4, W // 2 - 4].mean() > img[H // 2 + 4, W // 2 + 4].mean()
    big = imagecodecs.png_decode(
        io.write_preview(tmp_path / "q.png", surface, colormap="viridis").read_bytes()
    )
    assert min(big.shape[:2]) >= 256 and big.shape[1] > 2 * big.shape[0]


def test_preview_without_matplotlib(tmp_path, surface, monkeypatch):
    """The shaded preview needs no matplotlib; the colormap panel names the extra to install."""
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` now fails
    assert surface.save(tmp_path / "p.png").is_file()
    with pytest.raises(ImportError, match=r"matplotlib.*pip install 'facetlift\[plot\]'"):
        io.write_preview(tmp_path / "q.png", surface, colormap="viridis")
    assert not (tmp_path / "q.png").exists()


def test_shade_flat_plane_is_uniform():
    s = facetlift.integrate(np.dstack([np.zeros((5, 6, 2)), np.ones((5, 6))]))
    sh = io.shade(s, light=(0, 0, 1))
    np.testing.assert_allclose(sh, 1.0)


# ------------------------------------------------------------------------------ atomicity


@pytest.mark.parametrize("name", ["m.ply", "m.stl"])
def test_atomic_write_leaves_nothing_on_failure(tmp_path, surface, monkeypatch, name):
    def boom(path, *a, **k):
        Path(path).write_bytes(b"partial")
        raise RuntimeError("disk full")

    from facetlift.io import meshes

    for writer in ("_write_stl", "_write_ply", "_write_obj"):  # (block by block, here)
        monkeypatch.setattr(meshes, writer, boom)
    with pytest.raises(RuntimeError, match="disk full"):
        surface.save(tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_atomic_write_keeps_old_file_on_failure(tmp_path, surface, monkeypatch):
    target = tmp_path / "d.npy"
    surface.save(target)
    before = target.read_bytes()

    def boom(*a, **k):
        raise OSError("no space left")

    monkeypatch.setattr(np, "save", boom)
    with pytest.raises(OSError, match="no space"):
        surface.save(target)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["d.npy"]


def test_atomic_exr_failure(tmp_path, monkeypatch):
    import OpenEXR

    class Broken:
        def __init__(self, *a):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, path):
            Path(path).write_bytes(b"half")
            raise RuntimeError(f"exr failed: cannot open {path}")  # (the temporary's name)

    monkeypatch.setattr(OpenEXR, "File", Broken)
    with pytest.raises(OSError, match="cannot write as OpenEXR: exr failed.*d.exr") as e:
        io.write_depth(tmp_path / "d.exr", np.zeros((2, 2)))
    # (with an errno and the target, not the temporary file: the command line says which
    # output failed, as for the others, an audit)
    assert e.value.errno is not None and e.value.filename == str(tmp_path / "d.exr")
    assert ".tmp" not in str(e.value)
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------ errors


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match=r"`path`: file .*nope.png does not exist"):
        io.read_normals(tmp_path / "nope.png")
    with pytest.raises(ValueError, match="is a directory"):
        io.read_normals(tmp_path)


@pytest.mark.parametrize("ext", [".png", ".tif", ".exr", ".npy"])
def test_corrupt_files(tmp_path, ext):
    (tmp_path / f"bad{ext}").write_bytes(b"this is not an image at all")
    with pytest.raises(ValueError, match=r"bad\.(png|tif|exr|npy)"):
        io.read_normals(tmp_path / f"bad{ext}")


@pytest.mark.parametrize("ext", [".png", ".exr", ".tif"])
def test_truncated_files(tmp_path, normals, ext):
    path = io.write_normals(tmp_path / f"n{ext}", normals[0])
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=rf"n\{ext}"):
        io.read_normals(path)


def test_wrong_channel_counts(tmp_path):
    import imagecodecs

    (tmp_path / "g.png").write_bytes(imagecodecs.png_encode(np.zeros((3, 4), np.uint8)))
    with pytest.raises(ValueError, match=r"\(H, W, 3\) RGB.*1 channel"):
        io.read_normals(tmp_path / "g.png")
    np.save(tmp_path / "two.npy", np.zeros((3, 4, 2)))
    with pytest.raises(ValueError, match=r"2 channel"):
        io.read_normals(tmp_path / "two.npy")
    io.write_depth(tmp_path / "z.exr", np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"channels R, G, B or X, Y, Z; got \['Z'\]"):
        io.read_normals(tmp_path / "z.exr")


def test_unsupported_pixel_type(tmp_path):
    import tifffile

    tifffile.imwrite(tmp_path / "n.tif", np.zeros((3, 4, 3), np.int32), photometric="rgb")
    with pytest.raises(ValueError, match="pixel type int32"):
        io.read_normals(tmp_path / "n.tif")


def test_unknown_extensions(tmp_path, surface):
    (tmp_path / "n.jpg").write_bytes(b"x")
    # (the JPEG's advice where a map is read: it never showed, a user's audit)
    with pytest.raises(ValueError, match=r"unsupported normal map format '\.jpg'.*\.png.*"
                       r"also takes a MATLAB \.mat file and a dataset folder \(a JPEG's lossy"):
        io.read_normals(tmp_path / "n.jpg")
    with pytest.raises(ValueError, match=r"unsupported normal map format '\.jpg'.*\.npy$"):
        io.write_normals(tmp_path / "w.jpg", np.dstack([np.zeros((2, 2))] * 2 + [np.ones((2, 2))]))
    with pytest.raises(ValueError, match=r"`path`: unsupported surface format '\.off'.*\.npz"
                       r".*\.ply, \.obj, \.stl"):
        surface.save(tmp_path / "m.off")
    with pytest.raises(ValueError, match=r"`path`: unsupported mesh format '\.off'.*\.stl$"):
        io.write_mesh(tmp_path / "m.off", *surface.to_mesh())
    assert list(tmp_path.glob("m.*")) == []
    with pytest.raises(ValueError, match=r"unsupported depth format '\.png'"):
        io.write_depth(tmp_path / "d.png", surface.depth)
    with pytest.raises(ValueError, match=r"unsupported mask format"):
        io.read_mask(tmp_path / "n.jpg")
    (tmp_path / "m.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(ValueError, match=r"`mask`: .*m\.png is not a readable PNG"):
        io.read_mask(tmp_path / "m.png")


def test_writer_argument_errors(tmp_path, surface):
    with pytest.raises(ValueError, match=r"`depth` must have shape \(H, W\)"):
        io.write_depth(tmp_path / "d.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"`faces` index out of range"):
        io.write_mesh(tmp_path / "m.ply", np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(ValueError, match=r"`vertices` must have shape"):
        io.write_mesh(tmp_path / "m.ply", np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"`bits` must be one of \(8, 16\)"):
        io.write_normals(tmp_path / "n.png", np.zeros((2, 2, 3)), bits=32)
    with pytest.raises(ValueError, match=r"`mask` must have shape"):
        io.write_normals(tmp_path / "n.png", np.zeros((2, 2, 3)), np.ones((3, 2)))
    with pytest.raises(ValueError, match=r"takes only `triangles`"):
        surface.save(tmp_path / "m.ply", colormap="viridis")
    with pytest.raises(ValueError, match=r"takes no options"):
        surface.save(tmp_path / "d.npy", triangles=True)
    assert list(tmp_path.iterdir()) == []


def test_shading_of_a_surface_split_at_jumps_uses_each_facets_own_corners():
    """Facets next to a cut keep their own plane in the preview and the report (shaded from
    the glued vertex grid they spanned the jump: a speckled rim)."""
    from facetlift import integrate
    from facetlift.io import shade
    from facetlift.synthetic import analytic

    g = analytic("occluder", 64)
    s = integrate(g.normals, g.mask, discontinuities=True)
    L = np.array([-1.0, 1.0, 2.0]) / np.sqrt(6.0)
    truth = 0.15 + 0.85 * np.clip(g.normals @ L, 0, 1)
    err = np.abs(shade(s) - truth)[g.mask]
    # measured: 99th percentile 0.038, max 0.10 (one rim facet); on the vertex grid 0.21 / 0.58
    assert np.percentile(err, 99) < 0.08 and err.max() < 0.2


def test_planar_tiff_reads_as_its_contiguous_twin(tmp_path, normals):
    import tifffile

    n, _ = normals
    img = np.round((n + 1) / 2 * 65535).astype(np.uint16)
    tifffile.imwrite(tmp_path / "p.tif", np.moveaxis(img, -1, 0), planarconfig="separate",
                     photometric="rgb")
    tifffile.imwrite(tmp_path / "c.tif", img, photometric="rgb")
    a, _ = io.read_normals(tmp_path / "p.tif")
    b, _ = io.read_normals(tmp_path / "c.tif")
    assert a.shape == n.shape and np.array_equal(a, b)


def test_stdout_redirection_of_overlapping_readers_is_undone(monkeypatch):
    """The first reader leaves while the second is still inside (the order a per-reader
    save-and-restore gets wrong: fd 1 ended on stderr); stdout and stderr both come back,
    and the last to leave is given what was printed meanwhile."""
    import os
    import threading

    from facetlift.io import images

    monkeypatch.setitem(images._REDIRECT, "enabled", True)  # (the command line's setting)

    before = [os.fstat(fd) for fd in (1, 2)]
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    said = {}

    def first():
        with images._library_quiet() as s:
            os.write(2, b"from the library\n")
            first_in.set()
            second_in.wait(10)
        said["first"] = s.text
        first_out.set()

    def second():
        first_in.wait(10)
        with images._library_quiet() as s:
            second_in.set()
            first_out.wait(10)
        said["second"] = s.text

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = [os.fstat(fd) for fd in (1, 2)]
    assert [(b.st_dev, b.st_ino) for b in before] == [(a.st_dev, a.st_ino) for a in after]
    assert images._REDIRECT["depth"] == 0 and images._REDIRECT["saved"] is None
    assert said == {"first": "", "second": "from the library\n"}


def test_a_library_caller_s_stdout_is_left_alone(monkeypatch):
    """Only the command line catches stdout and stderr around the C readers: a library's
    host printing from another thread meanwhile would lose its words (fds 1 and 2 are the
    process's)."""
    import os

    from facetlift.io import images

    monkeypatch.setitem(images._REDIRECT, "enabled", False)
    before = [os.fstat(fd) for fd in (1, 2)]
    with images._library_quiet() as said:
        inside = [os.fstat(fd) for fd in (1, 2)]
        assert images._REDIRECT["depth"] == 0
    assert [(b.st_dev, b.st_ino) for b in before] == [(i.st_dev, i.st_ino) for i in inside]
    assert said.text == ""


def test_a_truncated_exr_is_one_line_naming_the_file(tmp_path, capfd):
    """A review: a truncated EXR printed OpenEXR's own lines (one on stdout, one on stderr)
    before facetlift's error, which ended "Invalid part index '0': file has 0 parts". The
    command line now prints one line naming the file as truncated or corrupt, with the
    library's reason, and nothing on stdout (--json: the object alone); Python gets the same
    words (the library's own lines are left where it prints them: the host's descriptors)."""
    import json

    from facetlift.cli import main

    r, c = np.mgrid[0:64, 0:64]
    n = np.dstack([np.sin(c / 9) * 0.4, np.cos(r / 7) * 0.3, np.ones((64, 64))])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    good = io.write_normals(tmp_path / "good.exr", n)
    data = good.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    assert main(["info", str(cut)]) == 1
    out, err = capfd.readouterr()
    assert out == "" and len(err.splitlines()) == 1, (out, err)
    assert f"{cut} is truncated or corrupt; OpenEXR: " in err and "0 parts" not in err, err
    assert main(["integrate", str(cut), "-o", str(tmp_path / "o"), "--json"]) == 1
    out, err = capfd.readouterr()
    assert "truncated or corrupt" in json.loads(out)["error"] and err.count("\n") <= 1, err
    with pytest.raises(ValueError, match=r"cut\.exr is truncated or corrupt; OpenEXR: "):
        io.read_normals(cut)
    (tmp_path / "text.exr").write_bytes(b"this is not an image at all")
    with pytest.raises(ValueError, match=r"text\.exr is not an OpenEXR file: it does not "
                       r"begin with the EXR signature"):
        io.read_normals(tmp_path / "text.exr")
    capfd.readouterr()
    assert main(["info", str(good)]) == 0  # (a whole file: nothing caught is lost or said)
    out, err = capfd.readouterr()
    assert "OpenEXR: " not in out + err and "Warning" not in out + err


def test_atomic_write_errors_name_the_target(tmp_path, monkeypatch):
    """A failed write (a read-only folder, a full disk) named the hidden temporary file; the
    error names the file asked for (a sixth fresh-user check)."""
    import errno

    from facetlift.io import atomic

    def named(fh, arr, **kw):
        raise OSError(errno.EROFS, "Read-only file system", fh.name)

    def unnamed(fh, arr, **kw):  # (a full disk fails in the write: no file named)
        raise OSError(errno.ENOSPC, "No space left on device")

    for fail in (named, unnamed):
        monkeypatch.setattr(atomic.np, "save", fail)
        with pytest.raises(OSError) as e:
            atomic._save_npy(tmp_path / "depth.npy", np.zeros(3))
        assert e.value.filename == str(tmp_path / "depth.npy") and e.value.errno
        assert list(tmp_path.iterdir()) == []
    # (a name near the file system's limit leaves the temporary room: it is cut short)
    monkeypatch.undo()
    long = tmp_path / ("d" * 240 + ".npy")
    atomic._save_npy(long, np.zeros(3))
    assert long.is_file()


def test_a_saved_npz_reads_back_as_depth_and_as_a_prior(tmp_path):
    """Surface.save's .npz could not be read by io.read_depth or given as a prior file (a
    user's check); its orthographic K is the NaN sentinel its docstring names."""
    import facetlift
    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 24)
    s = facetlift.integrate(gt.normals, gt.mask)
    s.save(tmp_path / "s.npz")
    np.testing.assert_array_equal(io.read_depth(tmp_path / "s.npz"), s.depth)
    np.testing.assert_array_equal(io.read_prior(tmp_path / "s.npz"), s.depth)
    with np.load(tmp_path / "s.npz") as z:
        assert np.isnan(z["K"]).all()
    np.savez(tmp_path / "two.npz", a=np.zeros((2, 2)), b=np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"must hold an array named 'depth' or a single array"):
        io.read_depth(tmp_path / "two.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable .npz archive"):
        io.read_prior(tmp_path / "bad.npz")


def test_height_map_png_is_16_bit_scaled_to_the_depth_range(tmp_path, capsys):
    """A texture artist had no height map for an engine (a shaded 8-bit preview and float
    depth only): height.png is 16-bit, 0..1 over the domain, alpha 0 outside, and its depth
    range is returned (and in the job record, --json)."""
    import json

    import imagecodecs

    import facetlift
    from facetlift.cli import main

    yy, xx = np.mgrid[0:24, 0:30]
    p, q = 0.1 * np.cos(xx / 4.0), 0.05 * np.ones_like(xx, float)
    n = facetlift.normals_from_gradients(p, q)
    mask = np.ones((24, 30), bool)
    mask[:3, :3] = False
    s = facetlift.integrate(n, mask)
    path, (low, high) = io.write_height(tmp_path / "h.png", s)
    img = imagecodecs.png_decode(path.read_bytes())
    assert img.dtype == np.uint16 and img.shape == (24, 30, 2)
    np.testing.assert_array_equal(img[..., 1] > 0, mask)
    h = img[..., 0] / 65535.0
    np.testing.assert_allclose(h[mask], (low - s.depth[mask]) / (low - high), atol=1e-5)
    assert h[mask].min() == 0.0 and h[mask].max() == 1.0
    with pytest.raises(ValueError, match=r"unsupported height map format '.tif'.*\.png, \.exr"):
        io.write_height(tmp_path / "h.tif", s)
    io.write_normals(tmp_path / "n.png", np.where(mask[..., None], n, np.nan), mask)
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o"), "-s",
                 "height", "-s", "npy", "--json"])
    assert code == 0 and (tmp_path / "o" / "height.png").is_file()
    rec = json.loads(capsys.readouterr().out)
    d = np.load(tmp_path / "o" / "depth.npy")
    assert rec["depth_range"] == [np.nanmax(d), np.nanmin(d)]


def test_a_two_channel_map_is_read_with_encoding_xy(tmp_path):
    """BC5 / RG maps store x, y alone: encoding="xy" reads R, G (8 and 16 bit, float EXR
    with R, G only), rebuilds z facing the viewer (also in a frame that negates z), ignores
    B, and reads black or white fill as no normal."""
    import imagecodecs
    import OpenEXR

    n, mask = bump_normals()
    for dtype in (np.uint8, np.uint16):
        top = np.iinfo(dtype).max
        v = np.round((n + 1) / 2 * top).astype(dtype)
        (tmp_path / "full.png").write_bytes(imagecodecs.png_encode(v))
        v[..., 2] = 0
        v[0, 0] = 0  # (black fill)
        v[0, 1] = top  # (white fill)
        (tmp_path / "xy.png").write_bytes(imagecodecs.png_encode(v))
        full, _ = io.read_normals(tmp_path / "full.png")
        xy, alpha = io.read_normals(tmp_path / "xy.png", encoding="xy")
        assert alpha is None and np.isnan(xy[0, :2]).all() and np.isfinite(xy[1:]).all()
        unit = full / np.linalg.norm(full, axis=-1, keepdims=True)
        step = 2.0 / top
        assert np.abs(xy[1:] - unit[1:]).max() < (8 if dtype == np.uint8 else 40) * step
        np.testing.assert_allclose(np.linalg.norm(xy[1:], axis=-1), 1.0)
        v[..., 2] = 77  # (B ignored)
        (tmp_path / "xy77.png").write_bytes(imagecodecs.png_encode(v))
        np.testing.assert_array_equal(io.read_normals(tmp_path / "xy77.png", encoding="xy")[0],
                                      xy)
    # a frame negating z (a camera frame): z is rebuilt facing the viewer all the same
    cv, _ = io.read_normals(tmp_path / "xy.png", encoding="xy", frame="opencv")
    np.testing.assert_allclose(cv[1:] * [1, -1, 1], xy[1:])
    with pytest.raises(ValueError, match=r"the frame 'z,x,y' reads z from the second"):
        io.read_normals(tmp_path / "xy.png", encoding="xy", frame="z,x,y")
    with pytest.raises(ValueError, match=r"`encoding` must be one of \['xyz', 'xy'\]"):
        io.read_normals(tmp_path / "xy.png", encoding="rg")
    # an EXR with R and G alone: floats as stored
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"R": n[..., 0].astype(np.float32),
                               "G": n[..., 1].astype(np.float32)}) as f:
        f.write(str(tmp_path / "rg.exr"))
    rg, _ = io.read_normals(tmp_path / "rg.exr", encoding="xy")
    np.testing.assert_allclose(rg, n, atol=1e-6)
    with pytest.raises(ValueError, match=r"must have channels R, G, B or X, Y, Z"):
        io.read_normals(tmp_path / "rg.exr")


def test_a_zero_one_float_map_is_read_with_normal_range_unsigned(tmp_path):
    """Float maps storing (n + 1) / 2 in [0, 1] (.npy, float TIFF, EXR, as renderers and
    networks write them) read as n with normal_range="unsigned", in any frame, with the
    alpha; black fill holds no normal; with encoding="xy" x and y are decoded before z is
    rebuilt. An 8/16-bit map or one with negative components is refused, naming it."""
    import imagecodecs
    import OpenEXR
    import tifffile

    n, mask = bump_normals()
    v = (n + 1) / 2
    v[~mask] = 0.0  # (a renderer's black background)
    np.save(tmp_path / "u.npy", v)
    np.save(tmp_path / "ua.npy", np.dstack([v, mask.astype(float)]))
    tifffile.imwrite(tmp_path / "u.tif", v.astype(np.float32), photometric="rgb")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: v[..., i].astype(np.float32)
                               for i, k in enumerate("RGB")}) as f:
        f.write(str(tmp_path / "u.exr"))
    for name, atol in (("u.npy", 1e-15), ("ua.npy", 1e-15), ("u.tif", 1e-6),
                       ("u.exr", 1e-6)):
        got, alpha = io.read_normals(tmp_path / name, normal_range="unsigned")
        assert (alpha is None) == (name != "ua.npy"), name
        assert np.isnan(got[~mask]).all() and np.isfinite(got[mask]).all(), name
        np.testing.assert_allclose(got[mask], n[mask], atol=atol, err_msg=name)
        cv, _ = io.read_normals(tmp_path / name, normal_range="unsigned", frame="opencv")
        np.testing.assert_allclose(cv[mask] * [1, -1, -1], got[mask])
    np.save(tmp_path / "uxy.npy", v[..., :2])
    with OpenEXR.File(header, {k: v[..., i].astype(np.float32) for i, k in enumerate("RG")}) as f:
        f.write(str(tmp_path / "uxy.exr"))
    for name, atol in (("uxy.npy", 1e-12), ("uxy.exr", 1e-6)):
        got, _ = io.read_normals(tmp_path / name, encoding="xy", normal_range="unsigned")
        assert np.isnan(got[~mask]).all(), name  # ((0, 0) -> (-1, -1): no normal)
        np.testing.assert_allclose(got[mask], n[mask], atol=atol, err_msg=name)
    (tmp_path / "u8.png").write_bytes(imagecodecs.png_encode(np.round(v * 255).astype(np.uint8)))
    with pytest.raises(ValueError, match=r"`path`: \S*u8.png: `normal_range` 'unsigned' "
                       r"applies to float maps stored in \[0, 1\]; this one is an 8-bit "
                       r"integer map, always decoded from its integer range"):
        io.read_normals(tmp_path / "u8.png", normal_range="unsigned")
    tifffile.imwrite(tmp_path / "u16.tif", np.round(v * 65535).astype(np.uint16),
                     photometric="rgb")
    with pytest.raises(ValueError, match=r"u16.tif: `normal_range` 'unsigned' .*16-bit"):
        io.read_normals(tmp_path / "u16.tif", normal_range="unsigned")
    np.save(tmp_path / "s.npy", n)
    k = int(np.count_nonzero(n < -facetlift.frames.UNSIGNED_SLACK))
    with pytest.raises(ValueError, match=rf"s.npy: `normal_range` 'unsigned' says the map "
                       rf"stores \(n \+ 1\) / 2 in \[0, 1\], but {k} of its"):
        io.read_normals(tmp_path / "s.npy", normal_range="unsigned")
    with pytest.raises(ValueError, match=r"`normal_range` must be one of"):
        io.read_normals(tmp_path / "u.npy", normal_range="01")


def test_a_two_channel_npy_or_tiff_is_read_with_encoding_xy(tmp_path):
    """A second audit: --normal-encoding xy took a two-channel EXR but refused an (H, W, 2)
    .npy and a two-channel float TIFF as "must be an (H, W, 3) RGB or (H, W, 4) RGBA normal
    map", without naming the flag. They are read (floats as stored, 16-bit decoded); without
    the flag the refusal names it; a two-channel PNG, grey + alpha, is refused for xy too,
    saying why."""
    import imagecodecs
    import tifffile

    n, _ = bump_normals()
    np.save(tmp_path / "xy.npy", n[..., :2])
    tifffile.imwrite(tmp_path / "xy.tif", n[..., :2].astype(np.float32))
    tifffile.imwrite(tmp_path / "xy16.tif", np.round((n[..., :2] + 1) / 2 * 65535)
                     .astype(np.uint16), photometric="minisblack", planarconfig="contig")
    for name, atol in (("xy.npy", 1e-12), ("xy.tif", 1e-6), ("xy16.tif", 1e-3)):
        got, alpha = io.read_normals(tmp_path / name, encoding="xy")
        assert alpha is None
        np.testing.assert_allclose(got, n, atol=atol, err_msg=name)
        with pytest.raises(ValueError, match=r"got shape \(\d+, \d+, 2\) \(2 channel\(s\)\); a "
                           r"two-channel map storing x and y alone \(BC5, RG\) is read with "
                           r"--normal-encoding xy \(encoding='xy'\)"):
            io.read_normals(tmp_path / name)
    la = np.round((n[..., :2] + 1) / 2 * 255).astype(np.uint8)
    (tmp_path / "la.png").write_bytes(imagecodecs.png_encode(la))
    with pytest.raises(ValueError, match=r"or \(H, W, 2\) x, y with --normal-encoding xy "
                       r"\(.npy or TIFF\); got shape .*a two-channel PNG is grey \+ alpha, not "
                       r"x, y \(PNG has no two-colour format\): store x, y in R and G of an RGB"):
        io.read_normals(tmp_path / "la.png", encoding="xy")


def _ripples(H=24, W=30):
    """Normals whose surface covers the whole image (no mask), and that surface."""
    yy, xx = np.mgrid[0:H, 0:W]
    n = facetlift.normals_from_gradients(0.1 * np.cos(xx / 4.0), 0.05 * np.sin(yy / 5.0))
    return n, facetlift.integrate(n)


def test_a_height_map_covering_the_image_is_plain_grey(tmp_path):
    """An artist's audit: height.png was grey + alpha with the alpha 65535 everywhere where
    no pixel was outside; it is one grey channel then, the same values, and keeps its alpha
    where pixels are outside."""
    import imagecodecs

    _, s = _ripples()
    path, (low, high) = io.write_height(tmp_path / "h.png", s)
    img = imagecodecs.png_decode(path.read_bytes())
    assert img.dtype == np.uint16 and img.shape == (24, 30)
    assert img.min() == 0 and img.max() == 65535
    np.testing.assert_allclose(img / 65535.0, (low - s.depth) / (low - high), atol=1e-5)
    assert (low, high) == (np.max(s.depth), np.min(s.depth))


def test_height_exr_holds_the_heights_and_round_trips(tmp_path):
    """height.exr: the heights themselves (-depth, not scaled), float32, one channel Y (the
    OpenEXR luminance a viewer shows as grey), NaN outside the mask, marked as heights in its
    header; read back by the depth reader as depth (it took the heights for depths, the sign
    wrong, an audit), and written by -s height-exr. An unmarked one-channel EXR is read as
    it is."""
    import OpenEXR

    from facetlift.cli import main

    n, mask = bump_normals()
    s = facetlift.integrate(n, mask)
    path, scale = io.write_height(tmp_path / "h.exr", s)
    assert scale is None
    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
    assert list(ch) == ["Y"] and ch["Y"].dtype == np.float32
    np.testing.assert_allclose(ch["Y"][mask], -s.depth[mask], rtol=1e-6, atol=1e-6)
    back = io.read_depth(path)
    np.testing.assert_array_equal(np.isnan(back), ~mask)
    np.testing.assert_allclose(back[mask], s.depth[mask], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(io.read_prior(path)[mask], s.depth[mask], rtol=1e-6, atol=1e-6)
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Y": ch["Y"]}) as f:  # (unmarked)
        f.write(str(tmp_path / "plain.exr"))
    np.testing.assert_array_equal(io.read_depth(tmp_path / "plain.exr"), ch["Y"])
    with pytest.raises(ValueError, match=r"`height_range` .* applies to the 16-bit PNG"):
        io.write_height(tmp_path / "h2.exr", s, height_range=(0, 1))
    io.write_normals(tmp_path / "n.png", np.where(mask[..., None], n, np.nan), mask)
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o"), "-s",
                 "height-exr", "-s", "npy"])
    assert code == 0
    d = np.load(tmp_path / "o" / "depth.npy")
    h = io.read_depth(tmp_path / "o" / "height.exr")
    np.testing.assert_array_equal(np.isnan(h), np.isnan(d))
    np.testing.assert_allclose(h[~np.isnan(d)], d[~np.isnan(d)], rtol=1e-6, atol=1e-6)


def test_a_symmetric_height_range_puts_each_maps_mean_height_at_mid_grey(tmp_path,
                                                                          brick_texture):
    """docs/cli.md's --height-range (a second audit asked what a set's range is relative
    to): each map's heights have mean 0 (the gauge, mean depth 0), so two maps of a set, one
    with deeper grooves, differ in their groove bottoms' heights; a symmetric range -R R
    gives both the same texels per code and their mean height at mid-grey."""
    import imagecodecs

    means = []
    for depth in (4.0, 6.0):
        _, n = brick_texture(size=128, brick=(64, 32), depth=depth)
        s = facetlift.integrate(n)
        assert np.mean(s.depth) == pytest.approx(0, abs=1e-9)
        path, _ = io.write_height(tmp_path / f"h{depth:g}.png", s, height_range=(-8.0, 8.0))
        img = imagecodecs.png_decode(path.read_bytes()).astype(float)
        np.testing.assert_allclose(img, (-s.depth + 8.0) / 16.0 * 65535, atol=0.5 + 1e-6)
        means.append(img.mean())
    np.testing.assert_allclose(means, 32767.5, atol=0.5)


def test_a_fixed_height_range_scales_every_map_alike_and_counts_what_it_clips(tmp_path,
                                                                              capsys):
    """A texture set was normalised map by map (one overshooting pixel set each map's
    scale): `height_range` fixes the heights of 0 and 65535, clips the rest with a warning
    that counts them, and the record's depth_range and the summary give the range used."""
    import json

    import imagecodecs

    from facetlift.cli import main

    n, s = _ripples()
    h = -s.depth
    lo, hi = float(np.percentile(h, 10)), float(np.percentile(h, 90))
    below, above = int((h < lo).sum()), int((h > hi).sum())
    with pytest.warns(UserWarning, match=rf"`height_range` \[{lo:g}, {hi:g}\]: "
                      rf"{below + above} of the 720 pixels inside .* \({below} below, "
                      rf"{above} above; .* clipped to 0 or 65535 in h.png"):
        path, (low, high) = io.write_height(tmp_path / "h.png", s, height_range=(lo, hi))
    assert (low, high) == (-lo, -hi)
    img = imagecodecs.png_decode(path.read_bytes()).astype(float)
    want = np.clip((h - lo) / (hi - lo), 0, 1) * 65535
    assert np.abs(img - want).max() <= 0.5 + 1e-6
    # inside the range: no warning, and the same heights give the same values in any map
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, same = io.write_height(tmp_path / "wide.png", s, height_range=(-10.0, 10.0))
    assert same == (10.0, -10.0)
    for bad in ((1.0, 1.0), (2.0, 1.0), (0.0, np.inf), (1.0,), "ab"):
        with pytest.raises(ValueError, match=r"`height_range` must be two finite numbers "
                           r"LOW < HIGH"):
            io.write_height(tmp_path / "bad.png", s, height_range=bad)
    # the command line: --height-range, the range in the record and the summary line
    io.write_normals(tmp_path / "n.png", n)
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o"), "-s",
                 "height", "--height-range", "-2", "2.5", "--json"])
    assert code == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["depth_range"] == [2.0, -2.5]
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o2"), "-s",
                 "height", "--height-range", "-0.1", "0.1"])
    out, err = capsys.readouterr()
    assert code == 0 and "height.png 0..65535 = height -0.1 to 0.1" in out
    assert "--height-range [-0.1, 0.1]: " in err and "clipped to 0 or 65535" in err
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o3"), "-s",
                 "npy", "--height-range", "2", "-2"])
    assert code == 1 and "--height-range must be two finite numbers LOW < HIGH" in (
        capsys.readouterr().err)
    assert not (tmp_path / "o3").exists()
    code = main(["integrate", str(tmp_path / "n.png"), "-o", str(tmp_path / "o4"), "-s",
                 "npy", "--height-range", "-2", "2"])
    assert code == 0 and "applies to height.png (save 'height'), which is not saved" in (
        capsys.readouterr().err)


def test_write_normals_keeps_the_direction_of_any_length_and_decodes_integers(tmp_path):
    """An audit: a (-p, -q, 1) field (integrate renormalises it) was clipped component by
    component (26 deg off when read back), and a uint8 map was written as all (1, 1, 1)."""
    gt = facetlift.synthetic.analytic("sphere", 32)
    n, m = gt.normals, gt.mask
    p, q = facetlift.gradients_from_normals(n)
    io.write_normals(tmp_path / "raw.png", np.dstack([-p, -q, np.ones_like(p)]), m)
    back, _ = io.read_normals(tmp_path / "raw.png")
    back = back[m] / np.linalg.norm(back[m], axis=-1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.sum(back * n[m], axis=-1), -1, 1)))
    assert angle.max() < 0.5
    u8 = np.nan_to_num(np.round((n + 1) / 2 * 255)).astype(np.uint8)
    with pytest.warns(UserWarning, match="is uint8: decoded as v / 255"):
        io.write_normals(tmp_path / "u8.png", u8, m)
    back, _ = io.read_normals(tmp_path / "u8.png")
    assert np.isfinite(back[m]).all()
    back = back[m] / np.linalg.norm(back[m], axis=-1, keepdims=True)  # (as integrate reads)
    angle = np.degrees(np.arccos(np.clip(np.sum(back * n[m], axis=-1), -1, 1)))
    assert angle.max() < 1.0


def test_masked_arrays_are_written_with_their_masked_entries_left_out(tmp_path):
    """A review: a masked uint8 map was taken as floats 0..255 (40 deg off), a masked mask
    wrote its masked entries as inside."""
    gt = facetlift.synthetic.analytic("sphere", 32)
    n8 = np.nan_to_num(np.round((gt.normals + 1) / 2 * 255)).astype(np.uint8)
    hole = np.zeros(n8.shape, bool)
    hole[10:13, 10:13] = True
    with pytest.warns(UserWarning, match="is uint8: decoded"):
        io.write_normals(tmp_path / "m.png", np.ma.masked_array(n8, hole), gt.mask)
    back, _ = io.read_normals(tmp_path / "m.png")
    assert np.isnan(back[10:13, 10:13]).all()
    assert np.isfinite(back[gt.mask & ~hole[..., 0]]).all()
    io.write_mask(tmp_path / "k.png", np.ma.masked_array(np.ones((8, 8), bool),
                                                          mask=np.eye(8, dtype=bool)))
    assert io.read_mask(tmp_path / "k.png").sum() == 56


def test_write_normals_checks_bits_first_and_never_refuses_a_frame(tmp_path):
    """A review: with integer input the decode warning came before the bits error, the
    decode's unit check counted the background, and a map facing away was refused with
    integrate's --normal-frame advice (a map is written, not integrated)."""
    import warnings

    v = np.zeros((12, 12, 3), np.uint8)
    v[...] = [128, 128, 0]  # (every normal facing away: written as it is)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match="`bits` must be one of"):
            io.write_normals(tmp_path / "a.png", v, bits=12)
        io.write_normals(tmp_path / "a.png", v)
    back, _ = io.read_normals(tmp_path / "a.png")
    assert (back[..., 2] < -0.99).all()
    v[...] = [128, 128, 255]
    v[:, :4] = [200, 200, 255]  # (a too-long fill outside the mask: no unit-length warning)
    mask = np.zeros((12, 12), bool)
    mask[:, 4:] = True
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        io.write_normals(tmp_path / "b.png", v, mask)
    assert not [w for w in caught if "longer than unit length" in str(w.message)]


def test_surface_save_height_png_writes_the_height_map_not_a_preview(tmp_path):
    """An audit: a texture artist's ``surface.save("height.png")`` got an 8-bit shaded
    preview. height.png (as the command line's --save height names it) is the 16-bit height
    map; other .png names stay previews."""
    import imagecodecs

    r, c = np.mgrid[0:24, 0:30]
    h = np.sin(c / 5.0) + 0.5 * np.cos(r / 4.0)
    p, q = np.gradient(h, axis=1), -np.gradient(h, axis=0)
    n = np.dstack([-p, -q, np.ones_like(h)])
    s = facetlift.integrate(n)
    out = s.save(tmp_path / "height.png")
    a = imagecodecs.png_decode(out.read_bytes())
    assert a.dtype == np.uint16 and a.ndim == 2 and a.min() == 0 and a.max() == 65535
    # (the height, -depth, scaled: increasing with the height)
    assert np.corrcoef(a.ravel().astype(float), s.height.ravel())[0, 1] > 0.999
    s.save(tmp_path / "displacement.png", height_range=(-5.0, 5.0))
    b = imagecodecs.png_decode((tmp_path / "displacement.png").read_bytes())
    assert b.dtype == np.uint16 and 20000 < b.mean() < 45000
    prev = imagecodecs.png_decode(s.save(tmp_path / "look.png").read_bytes())
    assert prev.dtype == np.uint8 and prev.ndim == 3
    # per object too (a user's check: tent_height.png was a silent preview)
    c = imagecodecs.png_decode(s.save(tmp_path / "tent_height.png").read_bytes())
    assert c.dtype == np.uint16 and c.ndim == 2
    with pytest.warns(UserWarning, match="shaded preview of the surface unless it is named"):
        d = imagecodecs.png_decode(s.save(tmp_path / "height_look.png").read_bytes())
    assert d.dtype == np.uint8
    with pytest.raises(ValueError, match="takes only `height_range`"):
        s.save(tmp_path / "height.png", light=(0, 0, 1))


def test_a_two_channel_exr_without_the_encoding_is_told_of_it(tmp_path):
    """A user's check: an EXR holding R and G only, read without --normal-encoding xy, was
    refused naming the channels it lacks but not the flag (a two-channel .npy or TIFF
    named it)."""
    from facetlift.io.images import _write_exr

    x = np.linspace(-0.3, 0.3, 24)[None, :] * np.ones((20, 1))
    _write_exr(tmp_path / "xy.exr", {"R": x, "G": 0.5 * x})
    with pytest.raises(ValueError, match=r"two-channel .* --normal-encoding xy"):
        io.read_normals(tmp_path / "xy.exr")
    n, _ = io.read_normals(tmp_path / "xy.exr", encoding="xy")
    assert n.shape == (20, 24, 3) and np.allclose(np.linalg.norm(n, axis=-1), 1.0)


def test_normal_range_unsigned_counts_signs_inside_the_mask_given(tmp_path):
    """read_normals(mask=) and a dataset folder's mask.* (or read_dataset(mask=), which
    replaces it) bound the pixels whose signs normal_range="unsigned" counts, as a file's alpha
    does: a signed fill (-1) outside them is no signed map; a negative inside still is. A
    mask of another size counts none (its caller refuses it)."""
    import scipy.io

    n, mask = bump_normals()
    v = np.where(mask[..., None], (n + 1) / 2, -1.0)
    np.save(tmp_path / "u.npy", v)
    with pytest.raises(ValueError, match=rf"but {3 * (~mask).sum()} of its {3 * mask.size} "
                       "components are negative"):
        io.read_normals(tmp_path / "u.npy", normal_range="unsigned")
    got, alpha = io.read_normals(tmp_path / "u.npy", normal_range="unsigned", mask=mask)
    assert alpha is None and np.isnan(got[~mask]).all()
    np.testing.assert_allclose(got[mask], n[mask], atol=1e-15)
    got, _ = io.read_normals(tmp_path / "u.npy", normal_range="unsigned", mask=mask[:-1])
    np.testing.assert_allclose(got[mask], n[mask], atol=1e-15)
    for name, write in (("normal_map.npy", lambda p: np.save(p, v)),
                        ("Normal_gt.mat", lambda p: scipy.io.savemat(p, {"Normal_gt": v}))):
        folder = tmp_path / name.split(".")[0]
        folder.mkdir()
        write(folder / name)
        with pytest.raises(ValueError, match="components are negative"):
            io.read_dataset(folder, normal_range="unsigned")
        ds = io.read_dataset(folder, normal_range="unsigned", mask=mask)
        assert ds["mask"] is mask
        np.testing.assert_allclose(ds["normals"][mask], n[mask], atol=1e-12)
        io.write_mask(folder / "mask.png", mask)
        ds = io.read_dataset(folder, normal_range="unsigned")
        np.testing.assert_array_equal(ds["mask"], mask)
        np.testing.assert_allclose(ds["normals"][mask], n[mask], atol=1e-12)
    v[mask.nonzero()[0][0], mask.nonzero()[1][0], 1] = -0.25
    np.save(tmp_path / "u.npy", v)
    with pytest.raises(ValueError, match=rf"but 1 of its {3 * mask.sum()} components are "
                       r"negative \(down to -0.25\)"):
        io.read_normals(tmp_path / "u.npy", normal_range="unsigned", mask=mask)


def test_a_dataset_mat_normal_map_is_decoded_unsigned_as_a_file_is(tmp_path):
    """A folder's Normal_gt.mat stored in [0, 1] reads as its normals with
    normal_range="unsigned"; with encoding="xy" x and y alone are decoded (its third channel,
    here a mid-grey 0.5, is ignored, as a file's is): flat normals were NaN (a review)."""
    import scipy.io

    n, mask = bump_normals()
    v = np.where(mask[..., None], (n + 1) / 2, 0.0)
    io.write_mask(tmp_path / "mask.png", mask)
    scipy.io.savemat(tmp_path / "Normal_gt.mat", {"Normal_gt": v})
    got = io.read_dataset(tmp_path, normal_range="unsigned")["normals"]
    np.testing.assert_allclose(got[mask], n[mask], atol=1e-12)
    v[..., 2] = 0.5  # (a two-channel map's unused B)
    scipy.io.savemat(tmp_path / "Normal_gt.mat", {"Normal_gt": v})
    got = io.read_dataset(tmp_path, encoding="xy", normal_range="unsigned")["normals"]
    assert np.isfinite(got[mask]).all()
    np.testing.assert_allclose(got[mask], n[mask], atol=1e-12)


def _sphere_on_fill(bits: int, fill, H: int = 64, W: int = 64):
    """An 8/16-bit encoded sphere (a continuous spread of normals, rounded as encoders do)
    inside a disk, `fill` (a colour, or "garbage": random codes) outside it; and the disk."""
    r, c = np.mgrid[0:H, 0:W] - np.array([(H - 1) / 2, (W - 1) / 2])[:, None, None]
    mask = np.hypot(r, c) < 0.3 * min(H, W)
    x, y = c / (0.38 * W), -r / (0.38 * H)
    n = np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, None))])
    top = 255 if bits == 8 else 65535
    px = np.round((n + 1) / 2 * top).astype(np.uint8 if bits == 8 else np.uint16)
    if isinstance(fill, str):
        px[~mask] = np.random.default_rng(bits).integers(0, top + 1, ((~mask).sum(), 3))
    else:
        px[~mask] = fill
    return px, mask


@pytest.mark.parametrize("ext", [".png", ".tif", ".npy"])
@pytest.mark.parametrize("bits", [8, 16])
def test_an_integer_maps_checks_look_inside_the_mask_given(tmp_path, bits, ext):
    """An 8/16-bit map's decode checks (the share of vectors longer than unit length, warned
    about) counted every pixel where the mask was given apart from the file (read_normals'
    mask=, --mask, a folder's mask.png): a fill of garbage outside the mask, as many exports
    leave, was warned about as the map's. Now the pixels inside it alone, as an alpha's; the
    same garbage inside the mask still is; a mask of another size looks at none (its caller
    refuses it). A black (all-zero) fill is no normal, NaN, and no word either way."""
    import imagecodecs
    import tifffile

    def save(name, px):
        path = tmp_path / f"{name}{ext}"
        if ext == ".png":
            path.write_bytes(imagecodecs.png_encode(px))
        elif ext == ".tif":
            tifffile.imwrite(path, px, photometric="rgb")
        else:
            np.save(path, px)
        return path

    px, mask = _sphere_on_fill(bits, "garbage")
    top = 255 if bits == 8 else 65535
    expected = px[mask] / top * 2 - 1
    path = save("garbage", px)
    with pytest.warns(facetlift.FrameWarning, match="longer than unit length"):
        io.read_normals(path)  # (no mask: the garbage is the map's)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got, alpha = io.read_normals(path, mask=mask)
        io.read_normals(path, mask=mask[:-1])
    assert alpha is None
    np.testing.assert_array_equal(got[mask], expected)
    with pytest.warns(facetlift.FrameWarning, match="longer than unit length"):
        io.read_normals(path, mask=np.ones_like(mask))  # (the garbage inside the mask)
    px, _ = _sphere_on_fill(bits, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got, _ = io.read_normals(save("zeros", px), mask=mask)
    assert np.isnan(got[~mask]).all()
    np.testing.assert_array_equal(got[mask], expected)


def test_a_dataset_folders_mask_and_the_command_lines_bound_an_integer_maps_checks(
        tmp_path, capsys):
    """As read_normals(mask=): a folder's mask.png (read_dataset) and --mask bound the pixels
    whose lengths an 8-bit map's decode counts; garbage outside them is not warned about."""
    import imagecodecs

    from facetlift.cli import main

    px, mask = _sphere_on_fill(8, "garbage")
    folder = tmp_path / "ds"
    folder.mkdir()
    io.write_mask(folder / "mask.png", mask)
    (folder / "normal_map.png").write_bytes(imagecodecs.png_encode(px))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = io.read_dataset(folder)
    np.testing.assert_array_equal(ds["mask"], mask)
    np.testing.assert_array_equal(ds["normals"][mask], px[mask] / 255 * 2 - 1)
    for argv in ([folder], [folder / "normal_map.png", "--mask", folder / "mask.png"]):
        code = main(["integrate", *map(str, argv), "-s", "npy",
                     "-o", str(tmp_path / f"out{len(argv)}")])
        err = capsys.readouterr().err
        assert code == 0 and "longer than unit length" not in err, err


@pytest.mark.parametrize("encoding", ["xyz", "xy"])
def test_an_eight_bit_fill_outside_the_mask_given_decides_no_zero_plateau(tmp_path, encoding):
    """An 8-bit map's zero plateaus (frames.decode: a spike at code 127 says the encoder
    truncates, and the whole map is decoded half a code up) were counted on every pixel where
    the mask was given apart from the file: a flat fill (127, 127, 255) outside it made a
    rounding encoder's sphere decode as a truncating one's. Now the pixels inside the mask
    decide; the same fill inside it still does."""
    import imagecodecs

    px, mask = _sphere_on_fill(8, (127, 127, 255))
    (tmp_path / "n.png").write_bytes(imagecodecs.png_encode(px))
    got, _ = io.read_normals(tmp_path / "n.png", mask=mask, encoding=encoding)
    np.testing.assert_array_equal(got[mask][:, :2], px[mask][:, :2] / 255 * 2 - 1)
    got, _ = io.read_normals(tmp_path / "n.png", mask=np.ones_like(mask), encoding=encoding)
    np.testing.assert_allclose(got[mask][:, :2], (px[mask][:, :2] + 0.5) / 255 * 2 - 1,
                               rtol=0, atol=1e-15)


def test_the_grey_check_looks_inside_the_mask_given(tmp_path):
    """The grey-image check (R = G = B with two levels or more: a height map, no normal map)
    looked at every pixel where the mask was given apart from the file: a grey image inside
    the mask passed on a coloured fill around it, and one plane whose normal is (1, 1, 1) /
    sqrt(3) (R = G = B, one level) was refused on a black fill around it. Now the pixels
    inside the mask alone, as inside an alpha."""
    import imagecodecs

    px, mask = _sphere_on_fill(8, "garbage")
    px[mask] = np.arange(mask.sum())[:, None] % 50 + 100  # (grey levels)
    (tmp_path / "grey.png").write_bytes(imagecodecs.png_encode(px))
    with pytest.warns(facetlift.FrameWarning, match="longer than unit length"):
        io.read_normals(tmp_path / "grey.png")  # (its fill's colours: no grey image)
    with pytest.raises(ValueError, match="R = G = B at every pixel inside the mask"):
        io.read_normals(tmp_path / "grey.png", mask=mask)
    px[mask], px[~mask] = 201, 0  # (201 / 255 * 2 - 1 = 0.576 = 1 / sqrt(3))
    (tmp_path / "plane.png").write_bytes(imagecodecs.png_encode(px))
    with pytest.raises(ValueError, match="R = G = B at every pixel of the image"):
        io.read_normals(tmp_path / "plane.png")
    got, _ = io.read_normals(tmp_path / "plane.png", mask=mask)
    np.testing.assert_array_equal(got[mask], np.full((mask.sum(), 3), 201 / 255 * 2 - 1))


def test_a_feathered_8_bit_mask_is_warned_about(tmp_path):
    """An audit: a mask blurred with sigma 3 px and saved as 8 bits holds only the levels 1-3
    in its outer 2 pixels, and its thousands of in-between pixels (taken as inside, past the
    object) went unwarned; a crisp mask still says nothing."""
    import warnings

    import imagecodecs
    from scipy import ndimage

    r, c = np.indices((120, 140))
    crisp = (r - 60) ** 2 / 40**2 + (c - 70) ** 2 / 50**2 < 1
    soft = np.clip(np.round(ndimage.gaussian_filter(crisp * 255.0, 3)), 0, 255).astype(np.uint8)
    (tmp_path / "soft.png").write_bytes(imagecodecs.png_encode(soft))
    (tmp_path / "crisp.png").write_bytes(imagecodecs.png_encode(crisp.astype(np.uint8) * 255))
    with pytest.warns(UserWarning, match=r"soft.png: \d+ of its \d+ inside pixels, along its "
                      r"edge, hold values between 0 and its largest"):
        got = io.read_mask(tmp_path / "soft.png")
    assert got.sum() > crisp.sum()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(io.read_mask(tmp_path / "crisp.png"), crisp)


@pytest.mark.parametrize("shape, said", [
    ((1, 20, 30, 3), r"looks like a batch of one \(1, H, W, C\): save a\[0\] instead"),
    ((1, 3, 20, 30), r"looks like a batch of one: save a\[0\] \(moved to \(H, W, 3\)"),
    ((3, 20, 30), r"got shape \(3, 20, 30\); it looks channel-first"),
    ((2, 20, 30), r"looks channel-first .* \(x, y alone: then \(H, W, 2\) with "
                  r"--normal-encoding xy\)"),
    ((1, 20, 30, 2), r"batch of one \(1, H, W, C\): save a\[0\] instead and read it with "
                     r"--normal-encoding xy"),
    ((1, 20, 30), r"looks like one grey image \(1, H, W\)"),
])
def test_a_batch_of_one_or_a_channel_first_file_is_named(tmp_path, shape, said):
    """An audit: a (1, H, W, 3) .npy got no hint, and a (3, H, W) one was said to have "30
    channel(s)" before the channel-first advice."""
    np.save(tmp_path / "a.npy", np.full(shape, 0.5))
    with pytest.raises(ValueError, match=said) as e:
        io.read_normals(tmp_path / "a.npy")
    assert "channel(s)" not in str(e.value)


def test_a_file_named_npy_that_is_no_npy_file_says_so(tmp_path):
    """An audit: a text file named .npy was told of pickled data and allow_pickle."""
    (tmp_path / "a.npy").write_text("hello\n")
    with pytest.raises(ValueError, match=r"a.npy is not a .npy file \(it does not start with "
                       r"numpy's header; it starts with b'hello\\n'\): save the array"):
        io.read_normals(tmp_path / "a.npy")
    (tmp_path / "e.npy").write_bytes(b"")
    with pytest.raises(ValueError, match=r"e.npy is not a .npy file .*empty"):
        io.read_normals(tmp_path / "e.npy")
    np.savez(tmp_path / "z.npz", a=np.zeros((4, 4, 3)))
    (tmp_path / "z.npz").rename(tmp_path / "z.npy")
    with pytest.raises(ValueError, match=r"z.npy is an .npz archive"):
        io.read_normals(tmp_path / "z.npy")


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs os.fork")
@pytest.mark.parametrize("user_wrote_since", [False, True])
def test_a_commit_killed_halfway_is_rolled_back_by_the_sweep(tmp_path, user_wrote_since):
    """A batch worker killed between two moves of its commit left one output new and one
    old, and the sweep deleted the old ones kept aside (an audit): the sweep puts the folder
    back as it was."""
    import os

    from facetlift.io import atomic

    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    pid = os.fork()
    if pid == 0:  # (the worker: stages two new files, dies after the first move)
        try:
            s = atomic.OutputSet(out, ["a.txt", "b.txt"])
            s.path("a.txt").write_text("new a")
            s.path("b.txt").write_text("new b")
            real = os.replace
            moved = []

            def die_after_one(src, dst):
                if moved:
                    os._exit(0)
                real(src, dst)
                moved.append(dst)

            os.replace = die_after_one
            s.commit()
        finally:
            os._exit(1)
    os.waitpid(pid, 0)
    assert (out / "a.txt").read_text() == "new a"  # (half-way, as the worker left it)
    if user_wrote_since:  # (a file of the user's since: not the run's to roll back, a review)
        (out / "a.txt").unlink()
        (out / "a.txt").write_text("the user's a")
    atomic.sweep(out)
    assert sorted(p.name for p in out.iterdir()) == ["a.txt"]
    assert (out / "a.txt").read_text() == ("the user's a" if user_wrote_since else "old a")


def test_the_roll_back_puts_back_an_old_file_moved_aside(tmp_path):
    """Where the old output could be neither linked nor copied aside it is moved aside; a
    run killed before its new file moved in left the folder without it, and the sweep
    deleted the only copy (a review)."""
    import json

    from facetlift.io import atomic

    staging = tmp_path / "stage"
    (staging / ".replaced").mkdir(parents=True)
    (staging / ".replaced" / "depth.npy").write_text("the old output")
    (staging / "depth.npy").write_text("the new one, not moved in")
    (staging / atomic.MOVING).write_text(json.dumps(["depth.npy", 0, 0, 0, 0]) + "\n")
    atomic._roll_back(staging, tmp_path)  # (not marked as moved aside: the user deleted it)
    assert not (tmp_path / "depth.npy").exists()
    (staging / ".replaced" / ("depth.npy" + atomic.MOVED)).touch()
    atomic._roll_back(staging, tmp_path)
    assert (tmp_path / "depth.npy").read_text() == "the old output"


def test_a_commit_that_cannot_list_its_moves_aborts_cleanly(tmp_path, monkeypatch):
    """A failure to write the list of moves left the staging folder behind (a review)."""
    import errno

    from facetlift.io import atomic

    out = atomic.OutputSet(tmp_path / "o", ["a.txt"])
    out.path("a.txt").write_text("new")
    real = Path.write_text

    def full(self, *a, **k):
        if self.name == atomic.MOVING:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(OSError, match="the folder was left as it was"):
        out.commit()
    assert not (tmp_path / "o").exists() or list((tmp_path / "o").iterdir()) == []


def test_height_png_holds_its_depth_scale_and_reads_back_as_depth(tmp_path):
    """height.png's 0 and 65535 stand for depths that only the batch record or the return
    value said: the file alone could not be turned back into depth. It holds them as PNG
    text (facetlift:depth_at_0, facetlift:depth_at_65535, also in words as a Comment, read
    by any PNG reader), and io.read_height reads it back as depth within half a count, NaN
    outside the mask; a PNG without them and an EXR not marked as heights are refused by
    name."""
    from PIL import Image

    n, mask = bump_normals()
    s = facetlift.integrate(n, mask)
    path, (low, high) = io.write_height(tmp_path / "h.png", s)
    text = io.png_text(path)
    assert float(text["facetlift:depth_at_0"]) == low
    assert float(text["facetlift:depth_at_65535"]) == high
    with Image.open(path) as im:  # (chunks with valid CRCs: another reader sees them)
        assert im.text["facetlift:depth_at_0"] == text["facetlift:depth_at_0"]
        assert "height = -depth" in im.text["Comment"]
    back = io.read_height(path)
    np.testing.assert_array_equal(np.isnan(back), ~mask)
    assert np.nanmax(np.abs(back - s.depth)) <= 0.5 * (low - high) / 65535 + 1e-12
    # a fixed range: the file holds that one
    path2, (low2, high2) = io.write_height(tmp_path / "r.png", s, height_range=(-20, 20))
    assert (low2, high2) == (20.0, -20.0)
    assert np.nanmax(np.abs(io.read_height(path2) - s.depth)) <= 40 / 65535
    # the EXR alike; refusals
    np.testing.assert_allclose(io.read_height(io.write_height(tmp_path / "h.exr", s)[0])[mask],
                               s.depth[mask], rtol=1e-6, atol=1e-6)
    io.write_mask(tmp_path / "plain.png", mask)
    with pytest.raises(ValueError, match="holds no depth scale"):
        io.read_height(tmp_path / "plain.png")
    io.write_depth(tmp_path / "d.exr", s.depth)
    with pytest.raises(ValueError, match="not marked as a height map"):
        io.read_height(tmp_path / "d.exr")


def test_a_texture_artists_maps_are_named(tmp_path, capsys):
    """A texture artist's audit: a two-channel map whose blue fill decodes between 0 and 1
    (B = 160) kept 31 % of its texels, 29.7 % RMS off, with no word; an sRGB-saved 8-bit map
    was sent from "--normal-range unsigned" to its refusal; an albedo was told to try a
    camera frame; the tileable recipe (frankot_chellappa pad=none) was hinted to dgp;
    io.write_height(path, array) raised a bare AttributeError."""
    import imagecodecs

    from facetlift.cli import main

    y, x = np.mgrid[0:96, 0:96] + 0.5
    h = 3 * np.sin(2 * np.pi * x / 32) * np.sin(2 * np.pi * y / 32)
    gr, gx = np.gradient(h)
    n = np.dstack([-gx, gr, np.ones_like(h)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    e = np.round((n * 0.5 + 0.5) * 255).astype(np.uint8)
    e[..., 2] = 160
    (tmp_path / "bc5.png").write_bytes(imagecodecs.png_encode(e))
    with pytest.warns(facetlift.FrameWarning, match=r"z channel holds one code, 160, at every "
                      r"pixel while x and y vary: is z stored\?.*--normal-encoding xy"):
        io.read_normals(tmp_path / "bc5.png")
    v = n * 0.5 + 0.5
    srgb = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    (tmp_path / "srgb.png").write_bytes(imagecodecs.png_encode(np.round(srgb * 255).astype(
        np.uint8)))
    with pytest.warns(UserWarning, match="sRGB"), pytest.raises(
            ValueError, match=r"decoded from its 8/16-bit values .* still lies in \[0, 1\] "
            r".*colour curve .*--normal-range applies to float maps only"):
        io.read_normals(tmp_path / "srgb.png")
    albedo = np.dstack([150 + 0 * h, 80 + 10 * h, 50 + 5 * h]).astype(np.uint8)
    with pytest.warns(facetlift.FrameWarning), pytest.raises(
            ValueError, match=r"is it a normal map at all\? Its vectors' median length"):
        facetlift.integrate(albedo)
    io.write_normals(tmp_path / "tile.png", n)
    code = main(["integrate", str(tmp_path / "tile.png"), "--method", "frankot_chellappa",
                 "--option", "pad=none", "-s", "height", "-o", str(tmp_path / "t")])
    assert code == 0 and "hint:" not in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"`surface` must be a facetlift.Surface; got ndarray"):
        io.write_height(tmp_path / "h.png", h)


def test_outputs_on_a_full_disk_name_the_file_and_the_cause(tmp_path):
    """npy, PLY and STL went through ndarray.tofile, whose OSError has no errno: a full disk
    or a file size limit said "313344 requested and 25584 written" and named no file (a
    review). Written through Python's write now: EFBIG (or ENOSPC), the file named."""
    import errno
    import resource
    import signal

    s = facetlift.integrate(facetlift.normals_from_gradients(np.full((60, 70), 0.1),
                                                             np.zeros((60, 70))))
    before = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    limits = resource.getrlimit(resource.RLIMIT_FSIZE)
    try:
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, limits[1]))
        for name in ("depth.npy", "mesh.ply", "mesh.stl"):
            with pytest.raises(OSError) as e:
                s.save(tmp_path / name)
            assert e.value.errno == errno.EFBIG and name in str(e.value), name
            assert not list(tmp_path.iterdir())  # (no partial file, no temporary)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, limits)
        signal.signal(signal.SIGXFSZ, before)


def test_a_long_non_ascii_output_name_is_written(tmp_path):
    """The temporary's name was cut at 96 characters, not bytes: 80 CJK characters (240
    bytes, a legal name) made it too long for the file system (a review)."""
    s = facetlift.integrate(facetlift.normals_from_gradients(np.full((6, 7), 0.1),
                                                             np.zeros((6, 7))))
    path = tmp_path / ("\u65e5" * 80 + ".npy")
    s.save(path)
    np.testing.assert_array_equal(np.load(path), s.depth)


def test_an_interrupt_while_writing_a_mesh_stays_an_interrupt(tmp_path):
    """ndarray.tofile swallowed a pending Ctrl-C and then failed as a TypeError ("expected
    str, bytes or os.PathLike object, not BufferedWriter"), which the command line reported
    as a bug (a review: 27 of 200 interrupted writes)."""
    import signal

    v = np.random.default_rng(0).random((100_000, 3))
    f = np.random.default_rng(1).integers(0, len(v), (100_000, 4))

    def stop(*a):
        raise KeyboardInterrupt

    before = signal.signal(signal.SIGALRM, stop)
    seen = set()
    try:
        for i in range(40):
            try:  # (the outer try catches an alarm that lands in the finally clause too:
                # escaped, it stopped the test run's worker)
                try:
                    signal.setitimer(signal.ITIMER_REAL, 0.001 + 0.0005 * (i % 20))
                    io.write_mesh(tmp_path / "m.ply", v, f)
                    seen.add("finished")
                finally:
                    signal.setitimer(signal.ITIMER_REAL, 0)
            except KeyboardInterrupt:
                seen.add("interrupted")
    finally:
        signal.signal(signal.SIGALRM, before)
    assert seen <= {"finished", "interrupted"} and "interrupted" in seen


def test_a_multi_page_tiff_is_named_a_stack(tmp_path):
    """A TIFF of several pages was refused by its shape alone, (3, 4, 4, 3) (a review)."""
    import tifffile

    a = np.random.default_rng(0).random((3, 4, 4, 3)).astype(np.float32)
    tifffile.imwrite(tmp_path / "stack.tif", a)
    with pytest.raises(ValueError, match=r"holds 3 pages \(a stack of images.*key=0"):
        io.read_normals(tmp_path / "stack.tif")
    tifffile.imwrite(tmp_path / "one.tif", a[0])
    assert io.read_normals(tmp_path / "one.tif")[0].shape == (4, 4, 3)


def test_surface_shapes_dataset_folder_and_nan_masks_checked(tmp_path):
    """A review: a Surface of disagreeing shapes was cropped by points() and saved as a
    surface.npz that load_surface refused; read_dataset raised a plain ValueError for a
    missing folder where every other reader raises InputFileNotFound; write_mask and
    clean_mask took a NaN as inside, where integrate refuses it."""
    import facetlift
    from facetlift.errors import InputFileNotFound

    with pytest.raises(ValueError, match=r"`mask` must have the shape of `depth`, \(4, 5\)"):
        facetlift.Surface(np.zeros((4, 5)), np.zeros((5, 6)), np.ones((3, 5), bool))
    with pytest.raises(ValueError, match=r"`vertex_depth` must be \(H \+ 1, W \+ 1\) = \(4, 4\)"):
        facetlift.Surface(np.zeros((3, 3)), np.zeros((5, 6)), np.ones((3, 3), bool))
    with pytest.raises(ValueError, match=r"`depth` must be an \(H, W\) array"):
        facetlift.Surface(np.zeros(3), np.zeros(4), np.ones(3, bool))
    s = facetlift.Surface(np.zeros((3, 4)), np.zeros((4, 5)), np.ones((3, 4), bool))
    assert len(s.points()) == 12
    with pytest.raises(InputFileNotFound, match=r"`folder`: .*nowhere does not exist"):
        io.read_dataset(tmp_path / "nowhere")
    m = np.ones((6, 6))
    m[2, 2] = np.nan
    with pytest.raises(ValueError, match=r"`mask` contains NaN or inf"):
        io.write_mask(tmp_path / "m.png", m)
    assert not (tmp_path / "m.png").exists()
    with pytest.raises(ValueError, match=r"`mask` contains NaN or inf"):
        facetlift.clean_mask(m)


def test_scaled_and_y_down_refuse_strings(tmp_path):
    """A review: Surface.scaled("2") scaled by 2 and read_normals(y_down="yes") read a
    DirectX map; both take only what their docs say now."""
    import facetlift

    s = facetlift.Surface(np.zeros((3, 4)), np.zeros((4, 5)), np.ones((3, 4), bool))
    with pytest.raises(ValueError, match=r"`factor` must be a positive finite number; got '2'"):
        s.scaled("2")
    assert s.scaled(np.float32(2)).depth.shape == (3, 4)
    n = np.dstack([np.zeros((4, 5, 2)), np.ones((4, 5))])
    path = io.write_normals(tmp_path / "n.png", n)
    with pytest.raises(ValueError, match=r"`y_down` must be True or False; got 'yes'"):
        io.read_normals(path, y_down="yes")
    np.testing.assert_allclose(io.read_normals(path, y_down=np.True_)[0], n, atol=1e-4)


def test_a_transposed_K_is_told_matlabs_one_based_principal_point():
    """A review: the transposed-K advice said to give its transpose, but not that MATLAB's
    IntrinsicMatrix counts the first pixel's centre as (1, 1): cx and cy must drop by 1 for
    the OpenCV layout (as MATLAB's cameraIntrinsicsToOpenCV does). The message gives both."""
    import facetlift

    matlab = np.array([[40.0, 0, 0], [0.5, 42.0, 0], [15.5, 10.5, 1]])  # (IntrinsicMatrix)
    with pytest.raises(ValueError, match=r"looks transposed .*give its transpose, and for "
                       r"MATLAB's also subtract 1 from cx and cy \(MATLAB counts the first "
                       r"pixel's centre as \(1, 1\), OpenCV and facetlift as \(0, 0\)\): fx 40, "
                       r"fy 42, s 0.5, cx 14.5, cy 9.5 \(cx 15.5, cy 10.5 for a transposed K "
                       r"that was 0-based already\)"):
        facetlift.camera.check_K(matlab)


def test_K_as_nine_numbers_is_taken_in_python(tmp_path):
    """A review: integrate(K=K.ravel()) was refused ("got shape (9,)") where read_K and --K
    take nine numbers row by row; it is the same camera as the matrix now."""
    import facetlift

    n = np.dstack([np.zeros((20, 30, 2)), np.ones((20, 30))])
    K = np.array([[40.0, 0, 14.5], [0, 41.0, 9.5], [0, 0, 1]])
    a = facetlift.integrate(n, K=K.ravel().tolist())
    b = facetlift.integrate(n, K=K)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(facetlift.camera.check_K(K.ravel()), K)
