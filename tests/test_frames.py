"""facetlift.frames: named frames and axis strings, decoding, the safety nets, the flip check;
integrate(normal_frame=...) and integrate_gradients."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import frames, io
from facetlift.problem import prepare

BEAR = str(Path(__file__).resolve().parents[2] / "shared" / "data" / "normal_maps"
           / "diligent_bear")
#: (a fresh clone without ../shared/data skips these, a review: they failed there)
NEEDS_BEAR = pytest.mark.skipif(not Path(BEAR).is_dir(), reason="../shared/data (the "
                                "DiLiGenT bear) not beside the checkout")


def bump(shape=(24, 30), h=0.1):
    """Unit normals (facetlift frame) of a smooth bump and its height."""
    r, c = np.indices(shape)
    x, y = (c + 0.5) * h, -(r + 0.5) * h
    x0, y0 = x.mean(), y.mean()
    z = np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / 0.5)
    p = -2 * (x - x0) / 0.5 * z
    q = -2 * (y - y0) / 0.5 * z
    return facetlift.normals_from_gradients(p, q), z


@pytest.mark.parametrize("frame, string", [
    ("opengl", "x,y,z"), ("directx", "x,-y,z"), ("y_down", "x,-y,z"), ("Y-Down", "x,-y,z"),
    ("opencv", "x,-y,-z"), (None, "x,y,z"), (" -x , y , z ", "-x,y,z"), ("y,-x,z", "y,-x,z"),
])
def test_names_and_axis_strings(frame, string):
    assert frames.axis_string(frame) == string


@pytest.mark.parametrize("frame", ["x,y", "x,x,z", "a,b,c", "x,y,z,w", "", "--x,y,z", 3])
def test_bad_frames_are_refused(frame):
    with pytest.raises(ValueError, match="`normal_frame` must be (one of|a frame name)"):
        frames.parse(frame)


@pytest.mark.parametrize("frame", ["opencv", "directx", "y,-x,z", "-z,x,-y"])
def test_conversion_round_trips_and_is_a_rotation_or_reflection(frame):
    n = np.random.default_rng(1).normal(size=(5, 7, 3))
    out = frames.to_facetlift(n, frame)
    np.testing.assert_allclose(frames.from_facetlift(out, frame), n)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), np.linalg.norm(n, axis=-1))


def test_opencv_frame_means_y_down_and_z_away():
    # a surface facing up-right-toward the viewer, written in the OpenCV camera frame
    cv = np.array([0.3, -0.4, -np.sqrt(1 - 0.25)])
    np.testing.assert_allclose(frames.to_facetlift(cv, "opencv"), [0.3, 0.4, np.sqrt(0.75)])


def test_y_down_is_an_alias_and_conflicts_are_refused():
    assert frames.resolve(None, True) == "directx"
    assert frames.resolve("x,-y,z", True) == "x,-y,z"
    assert frames.resolve("opencv", False) == "opencv"
    with pytest.raises(ValueError, match="conflicts with .frame. 'opencv'"):
        frames.resolve("opencv", True)


def test_integrate_in_another_frame_equals_integrate_of_the_converted_map():
    n, _ = bump()
    cv = frames.from_facetlift(n, "opencv")
    a = facetlift.integrate(n)
    b = facetlift.integrate(cv, normal_frame="opencv")
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-12)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_integer_arrays_are_decoded_with_a_warning(tmp_path, dtype):
    n, _ = bump()
    bits = 8 if dtype == np.uint8 else 16
    path = io.write_normals(tmp_path / "n.png", n, bits=bits)
    import imagecodecs

    raw = imagecodecs.png_decode(path.read_bytes())
    assert raw.dtype == dtype
    with pytest.warns(UserWarning, match=rf"is {np.dtype(dtype).name}: decoded as v / "):
        a = facetlift.integrate(raw)
    decoded, _ = io.read_normals(path)
    b = facetlift.integrate(decoded)
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-12)


def test_a_grey_image_is_refused_inside_the_mask_only():
    """An audit: a grey image (a height map saved as RGB) handed to integrate ran, ~30 % of
    it facing away, into garbage; as uint8 or as floats it is refused, naming `normals`."""
    r, c = np.mgrid[0:24, 0:30]
    h = (127 + 100 * np.sin(r / 5) * np.cos(c / 7)).astype(np.uint8)
    grey = np.dstack([h, h, h])
    for a in (grey, grey / 255.0, grey.astype(np.uint16) * 257):
        with pytest.raises(ValueError, match=r"`normals`: R = G = B at every pixel of the "
                           r"image: a grey image \(a height map\?\), not a normal map"):
            facetlift.integrate(a)
    n, _ = bump()
    mask = np.zeros(n.shape[:2], bool)
    mask[4:20, 5:25] = True
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    v[~mask] = grey[~mask]  # grey outside the mask: background, not looked at
    with pytest.warns(UserWarning, match="decoded as"):
        facetlift.integrate(v, mask)
    v[mask] = grey[mask]
    v[~mask] = (128, 128, 255)
    with pytest.raises(ValueError, match=r"R = G = B at every pixel inside the mask"):
        facetlift.integrate(v, mask)
    some = n.copy()
    some[:3] = 0.5  # (some grey pixels: a map all the same)
    facetlift.integrate(some)


def test_the_grey_check_samples_first_on_a_large_image_and_decides_on_every_pixel():
    """A review: the grey check's fast path (a strided sample of about CHECK_SAMPLE pixels,
    the full pass only where every sampled pixel is grey) had no test. At 400 x 400 the
    stride is 2 (300 x 300 would be 1: no sampling). A grey image is refused; a normal map
    with a few grey pixels passes; a grey image whose colour lies only on pixels the sample
    skips passes too (the sample alone never refuses); grey inside the mask, colour outside:
    refused."""
    H = W = 400
    assert H * W // frames.CHECK_SAMPLE == 2
    r, c = np.mgrid[0:H, 0:W]
    h = (127 + 100 * np.sin(r / 25) * np.cos(c / 35)).astype(np.uint8)
    grey = np.dstack([h, h, h])
    with pytest.raises(ValueError, match=r"`normals`: R = G = B at every pixel of the image"):
        frames.grey_check(grey, None, "`normals`")
    n = np.round((facetlift.normals_from_gradients(0.3 * np.cos(c / 30), 0.2 * np.sin(r / 40))
                  + 1) / 2 * 255).astype(np.uint8)
    some = n.copy()
    some[:2, :5] = grey[:2, :5]  # (a few grey pixels: a fill)
    frames.grey_check(some, None, "`normals`")
    only = grey.copy()  # (colour on odd flat indices alone: never in the sample)
    only.reshape(-1, 3)[1::2 * 997] = (10, 200, 30)
    assert (only.reshape(-1, 3)[::2] == only.reshape(-1, 3)[::2, :1]).all()
    frames.grey_check(only, None, "`normals`")
    mask = np.zeros((H, W), bool)
    mask[50:350, 60:340] = True
    inside = np.where(mask[..., None], grey, n)
    with pytest.raises(ValueError, match=r"R = G = B at every pixel inside the mask"):
        frames.grey_check(inside, mask, "`normals`")
    frames.grey_check(inside, None, "`normals`")  # (the colour outside counts without one)


def test_other_unsigned_integers_are_refused():
    with pytest.raises(ValueError, match="integer type uint32; integer normal maps must be"):
        facetlift.integrate(np.zeros((4, 4, 3), np.uint32))


def test_zero_one_encoded_floats_are_refused_with_the_fix():
    n, _ = bump()
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded.*n = 2 \* v - 1"):
        facetlift.integrate((n + 1) / 2)
    facetlift.integrate(2 * ((n + 1) / 2) - 1)  # the fix works


def test_a_resampled_zero_one_map_is_seen_as_encoded_and_decodes():
    """An audit: a [0, 1]-encoded map resized with a cubic kernel rings a little past 0 and 1
    (a few components in a thousand); it was integrated as signed normals without a word,
    and normal_range='unsigned' refused it as signed. A signed map is still neither."""
    from scipy import ndimage

    n, _ = bump((48, 48))
    v = (n + 1) / 2
    v[20, 20:23] = (-0.05, 1.06, 0.5)  # (the ringing: three strays among 6,912 components)
    v[30, 30, 0] = -0.02
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded.*all but a few strays"):
        facetlift.integrate(v)
    got = frames.decode_unsigned(v, "a map")  # (no refusal as signed)
    np.testing.assert_allclose(got[5, 5], n[5, 5])
    facetlift.integrate(n)  # (signed unit normals: neither refused nor decoded)
    with pytest.raises(ValueError, match="components are negative"):
        frames.decode_unsigned(n, "a map")
    big = np.stack([ndimage.zoom(v[..., i], 2.0, order=3) for i in range(3)], axis=-1)
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded"):
        facetlift.integrate(big)


def test_the_zero_one_refusal_names_the_remedy_of_where_the_map_came_from():
    """From Python (arrays: integrate has no range option) the decode, and the reader's
    argument for a file; read by a job (the command line) its flag, with the Python remedy;
    after the job's own unsigned decode, no advice to give that flag again."""
    v = (bump()[0] + 1) / 2
    with pytest.raises(ValueError, match=r"decode it first with n = 2 \* v - 1 .*"
                       r"read_normals\(path, normal_range='unsigned'\)") as e:
        facetlift.integrate(v)
    assert "--normal-range" not in str(e.value)
    with frames.read_in(None, normal_range="signed"), pytest.raises(
            ValueError, match=r"read it with --normal-range unsigned \(normal_range='unsigned' "
            r"in a facetlift.jobs.Job or facetlift.io.read_normals\), which decodes "
            r"n = 2 \* v - 1, or decode it in Python"):
        facetlift.integrate(v)
    with frames.read_in(None, normal_range="unsigned"), pytest.raises(
            ValueError, match=r"after --normal-range unsigned's decoding .*encoded twice"):
        facetlift.integrate(v)
    with frames.read_in(None, normal_range="signed"), frames.read_in("opengl"), \
            pytest.raises(ValueError, match="--normal-range unsigned"):
        facetlift.integrate(v)  # (an inner read_in without a range keeps the outer one)


def test_decode_unsigned_inverts_the_zero_one_encoding():
    """2 v - 1, exactly as a float can; fill that holds no normal (black, white, mid-grey)
    NaN as in an integer map, by length (x, y alone for a two-channel map), and NaN kept."""
    n, _ = bump()
    v = (n + 1) / 2
    v[0, 0], v[0, 1], v[0, 2], v[0, 3] = 0.0, 1.0, 0.5, np.nan
    got = frames.decode_unsigned(v, "`path`: m.npy")
    assert np.isnan(got[0, :4]).all() and np.isfinite(got[0, 4:]).all()
    np.testing.assert_allclose(got[1:], n[1:], atol=1e-15)
    xy = frames.decode_unsigned(v[..., :2], "`path`: m.npy", channels=2)
    assert xy.shape == n.shape[:2] + (2,)
    assert np.isnan(xy[0, [0, 1, 3]]).all() and np.isfinite(xy[0, 2]).all()  # (grey: flat)
    np.testing.assert_allclose(xy[1:], n[1:, :, :2], atol=1e-15)
    with pytest.raises(ValueError, match=r"`normal_range` must be one of \['signed', "
                       r"'unsigned'\]"):
        frames.normal_range("01")
    assert frames.normal_range(None) == "signed" and frames.normal_range(" Unsigned") == (
        "unsigned")


def test_decode_unsigned_refuses_integer_and_signed_maps():
    """An 8/16-bit map is decoded from its integer range, always; a map with negative
    components holds signed normals: both refused naming the option (and the count), beyond
    a rounding's slack and inside `where` alone."""
    n, _ = bump()
    for dtype, bits in ((np.uint8, "an 8"), (np.uint16, "a 16")):  # (not "an 16-bit")
        with pytest.raises(ValueError, match=rf"`path`: m.png: `normal_range` 'unsigned' "
                           rf"applies to float maps .*this one is {bits}-bit integer map, "
                           r"always decoded "
                           r"from its integer range \(v / max \* 2 - 1\): leave it out"):
            frames.decode_unsigned(np.zeros((4, 4, 3), dtype), "`path`: m.png")
    k = int(np.count_nonzero(n < -frames.UNSIGNED_SLACK))
    with pytest.raises(ValueError, match=rf"`normal_range` 'unsigned' says the map stores "
                       rf"\(n \+ 1\) / 2 in \[0, 1\], but {k} of its {n.size} components are "
                       r"negative \(down to -0\.\d+\): it holds signed normals"):
        frames.decode_unsigned(n, "`path`: m.npy")
    v = (n + 1) / 2
    v[0, 0, 0] = -0.5 * frames.UNSIGNED_SLACK  # (rounding, an unclipped network output)
    assert np.isfinite(frames.decode_unsigned(v, "m")[0, 0]).all()
    v[0, 0, 0] = -0.5  # (outside the alpha: not counted)
    where = np.ones(v.shape[:2], bool)
    where[0, 0] = False
    frames.decode_unsigned(v, "m", where)
    with pytest.raises(ValueError, match="but 1 of its"):
        frames.decode_unsigned(v, "m")


@pytest.mark.parametrize("scale, bits", [(255, 8), (65535, 16)])
def test_undecoded_integer_images_as_floats_are_refused_with_the_fix(scale, bits):
    """An 8/16-bit image read into floats and passed on: every normal would be nearly the
    same tilted vector, a silent plane."""
    n, _ = bump()
    with pytest.raises(ValueError, match=rf"undecoded {bits}-bit normal map.*"
                       rf"n = v / {scale} \* 2 - 1"):
        facetlift.integrate(np.round((n + 1) / 2 * scale))
    facetlift.integrate(np.round((n + 1) / 2 * scale) / scale * 2 - 1)  # the fix works
    facetlift.integrate(n * 100.0)  # unnormalised normals of any length are fine
    plane = 50.0 * facetlift.normals_from_gradients(np.full((12, 12), -0.3),
                                                    np.full((12, 12), -0.2))
    assert np.isfinite(facetlift.integrate(plane).depth).all()  # all >= 0 and > 1: a plane


@pytest.mark.parametrize("frame", ["opencv", "directx", "x,-y,-z"])
def test_an_encoding_is_named_before_the_frame_is_applied(frame):
    """An audit: a [0, 1]-encoded float map with normal_frame='opencv' faced away once its
    frame was applied and was told to drop the frame; only then was its encoding named (with
    'directx' it was not refused at all). The encoding checks look at the values as given."""
    n, _ = bump()
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded.*n = 2 \* v - 1"):
        facetlift.integrate((n + 1) / 2, K=[30, 30, 14.5, 11.5], normal_frame=frame)
    with pytest.raises(ValueError, match=r"undecoded 8-bit normal map"):
        facetlift.integrate(np.round((n + 1) / 2 * 255), normal_frame=frame)
    with pytest.raises(ValueError, match="face away"):  # (a map that does face away: as before)
        facetlift.integrate(n, normal_frame="opencv")


def test_unit_normals_facing_up_and_right_are_not_taken_for_an_encoding():
    plane = facetlift.normals_from_gradients(np.full((12, 12), -0.3), np.full((12, 12), -0.2))
    assert (plane >= 0).all()
    s = facetlift.integrate(plane)
    assert np.isfinite(s.depth).all()


def test_encoding_check_looks_only_inside_the_mask():
    n, _ = bump()
    enc = (n + 1) / 2
    mask = np.zeros(n.shape[:2], bool)
    mask[:6, :6] = True  # 36 pixels: too few to judge
    enc[~mask] = -5.0  # outside the mask: anything, never looked at
    assert frames.checked(enc, mask) is not None
    big = np.ones(n.shape[:2], bool)
    with pytest.raises(ValueError, match="looks"):
        frames.checked((n + 1) / 2, big)


def test_normals_facing_away_name_the_opencv_frame():
    n, _ = bump()
    with pytest.raises(ValueError, match=r"face away from the viewer.*--normal-frame opencv"):
        facetlift.integrate(frames.from_facetlift(n, "opencv"))


def test_a_truncating_encoders_two_channel_map_gets_no_frame_advice():
    """An audit of the docs' claims: a two-channel map (B = 0) from an encoder that truncates
    is decoded at the middle of each code step, (v + 0.5) / 255, off the code grid the check
    looked for, so the refusal went on to advise a frame, which recipes.md says it does not
    (none mends it). Half steps count as decoded codes too."""
    n, _ = bump()
    codes = np.floor((n + 1) / 2 * 255).astype(float)
    v = (codes + 0.5) / 255 * 2 - 1  # (x, y as the truncating encoder's decode reads them)
    v[..., 2] = (0 + 0.5) / 255 * 2 - 1
    text, decoded = frames.z_not_stored(v.reshape(-1, 3))
    assert decoded and "is z stored" in text
    with pytest.raises(ValueError, match="is z stored") as e:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            facetlift.integrate(v)
    assert "normal-frame" not in str(e.value) and "If z really" not in str(e.value)


@pytest.mark.parametrize("blue", [0, 37])
def test_a_two_channel_map_is_told_that_z_is_not_stored(blue):
    """An audit: a BC5 map (x, y in R, G; B = 0) was refused as '100 % ... face away ... try
    --normal-frame opencv', after the decode's right warning that z is not stored. A blue
    channel of one value over the mask is named as such, with the rebuild, and no frame."""
    n, _ = bump()
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    v[..., 2] = blue
    with pytest.raises(ValueError, match=r"`normals`: z is -?[\d.]+ at every pixel inside the "
                       r"mask while x and y vary: is z stored\? A two-channel map .* "
                       r"z = sqrt\(1 - x\^2 - y\^2\) must be rebuilt: read it with "
                       r"--normal-encoding xy \(facetlift\.io\.read_normals\(path, "
                       r"encoding='xy'\).*np\.sqrt\(np\.clip\(1 - ") as e:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            facetlift.integrate(v)
    assert "normal-frame" not in str(e.value) and "face away" not in str(e.value)
    # the rebuild it names works, and so does the encoding
    d = frames.decode(v)
    d[..., 2] = np.sqrt(np.clip(1 - d[..., 0]**2 - d[..., 1]**2, 0, 1))
    assert facetlift.integrate(d).info["mean_deviation"] < 1.0
    np.testing.assert_allclose(frames.decode_xy(v), d, rtol=0, atol=1e-12)
    # float normals written as (x, y, -1) may be a camera frame's: the frame comes after
    with pytest.raises(ValueError, match=r"z is -1 at every pixel .* If z really is that "
                       r"value, 100% of the normals .* face away .*--normal-frame opencv"):
        facetlift.integrate(np.dstack([n[..., :2], -np.ones(n.shape[:2])]))
    # a map facing away with a z that varies: the frame, as before
    with pytest.raises(ValueError, match="face away") as e:
        facetlift.integrate(frames.from_facetlift(n, "opencv"))
    assert "is z stored" not in str(e.value)


def test_edge_on_normals_of_an_indoor_view_do_not_count_as_facing_away(tmp_path):
    """A pinhole view of a room: walls parallel to the optical axis have z = 0, stored as 128
    in 8 bits (+-1/255 decoded). Counted by the sign of z, 53 % of a user's correct
    camera-frame map "faced away" and it was refused; only clear ones count now."""
    import imagecodecs

    from facetlift import io

    H, W = 48, 64
    n = np.zeros((H, W, 3))
    n[:, : W // 3] = [1.0, 0.0, 0.0]  # the left wall, edge-on
    n[:, 2 * W // 3:] = [-1.0, 0.0, 0.0]  # the right wall
    n[:, W // 3: 2 * W // 3] = [0.0, 0.0, 1.0]  # the far wall, facing the camera
    stored = np.rint((frames.from_facetlift(n, "opencv") + 1) / 2 * 255).astype(np.uint8)
    (tmp_path / "room.png").write_bytes(imagecodecs.png_encode(stored))
    normals, _ = io.read_normals(tmp_path / "room.png", frame="opencv")
    assert np.mean(normals[..., 2] < 0) > 0.6  # (z = 0 stored as 128: -1/255 read so)
    checked = frames.checked(normals)  # (refused before: "face away from the viewer")
    assert checked.shape == (H, W, 3)
    assert frames.facing_away(normals.reshape(-1, 3)) == 0.0
    # the camera-frame map read without its flag is still refused, naming the flag
    with pytest.raises(ValueError, match=r"100% of the normals .* not edge-on face away.*"
                                         r"--normal-frame opencv"):
        frames.checked(frames.from_facetlift(n, "opencv"))
    # integrated orthographically, the edge-on walls are unusable normals, but no sign of
    # another frame (a review: "67% ... face away ... another frame?" was printed)
    with pytest.warns(UserWarning, match="cannot be used") as rec:
        facetlift.integrate(normals)
    assert not any("another frame" in str(w.message) for w in rec)


@pytest.mark.parametrize("stored, given, hint", [
    ("opengl", "opencv", "the default frame (no --normal-frame"),  # the flag was the mistake
    ("x,y,-z", "directx", "--normal-frame x,y,-z"),
    ("opencv", "directx", "z alone negated: --normal-frame opencv"),
    ("opengl", "x,-y,-z", "the default frame"),
])
def test_the_facing_hint_is_relative_to_the_frame_given(stored, given, hint):
    """A map read in a frame that makes it face away: the hint names the frame that undoes
    the camera flips relative to the one given, not the flag the user already gave."""
    n, _ = bump()
    with pytest.raises(ValueError, match="face away") as e:
        facetlift.integrate(frames.from_facetlift(n, stored), normal_frame=given)
    assert hint in str(e.value) and f"as read in the frame {frames.axis_string(given)}" in str(
        e.value)
    # the hint is right: one of the two frames it names reads the map as it was stored
    devs = [facetlift.integrate(frames.from_facetlift(n, stored), normal_frame=fixed)
            .info["mean_deviation"] for fixed in (frames.negated(given, a) for a in ("yz", "z"))
]
    assert min(devs) == pytest.approx(facetlift.integrate(n).info["mean_deviation"], abs=1e-9)


def test_negated_frames_and_their_flags():
    assert frames.negated(None, "yz") == "opencv" and frames.negated("opencv", "yz") == "opengl"
    assert frames.negated("directx", "y") == "opengl" and frames.negated(None, "y") == "directx"
    assert frames.negated("y,-x,z", "x") == "-y,-x,z"
    assert frames.flag("-y,-x,z") == "--normal-frame=-y,-x,z (normal_frame='-y,-x,z')"
    assert frames.flag("opengl").startswith("the default frame")


def test_flip_check_warns_on_a_y_flipped_map_and_names_the_flag():
    n, _ = bump((40, 48))
    flipped = n * [1, -1, 1]
    # (a map filling its image: no silhouette, and without a camera the flips tie: both named)
    with pytest.warns(UserWarning, match=r"more integrable with x or y flipped.*wrong in x or "
                      r"in y: try --normal-frame directx.* or --normal-frame=-x,y,z.*bulges"):
        s = facetlift.integrate(flipped)
    ic = s.info["integrability"]
    assert ic["curl_y_flipped"] < frames.FLIP_RATIO * ic["curl"]
    # read in another frame, the hint is relative to it (not the flag given)
    with pytest.warns(UserWarning, match=r"frame \(read in the frame x,-y,z\) is probably "
                      r"wrong in x or in y: try the default frame") as rec:
        facetlift.integrate(frames.from_facetlift(flipped, "directx"), normal_frame="directx")
    assert "try --normal-frame directx" not in str(rec[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        good = facetlift.integrate(n)
    assert good.info["integrability"]["curl"] < 0.05
    assert good.info["mean_deviation"] < s.info["mean_deviation"]


def test_flip_check_names_the_axis_whose_flip_decided_with_a_camera():
    """A review: with a pinhole camera the two flips differ; an x-flipped map (0.65 as given,
    0.68 with y flipped, 0.0005 with x flipped) was told to try the y flip."""
    from facetlift import describe
    from facetlift.errors import FrameWarning
    from facetlift.perspective import normals_from_depth

    H, W = 120, 160
    K = np.array([[60.0, 0, 79.5], [0, 60.0, 59.5], [0, 0, 1]])
    r, c = np.indices((H, W))
    depth = 3.0 + 0.4 * np.cos(c / 9.0) * np.sin(r / 11.0)
    n = normals_from_depth(depth, K) * [-1, 1, 1]
    with pytest.warns(FrameWarning, match=r"far more integrable with x flipped .*"
                      r"with x flipped, .* with y flipped\).*wrong in x: try "
                      r"--normal-frame=-x,y,z") as rec:
        s = facetlift.integrate(n, K=K)
    ic = s.info["integrability"]
    assert ic["curl_x_flipped"] < frames.FLIP_RATIO * ic["curl"] < ic["curl_y_flipped"]
    assert len([w for w in rec if issubclass(w.category, FrameWarning)]) == 1
    guess = describe._frame_guess(n, None, K, prepare(n, K=K), frame=None, layout=None)
    assert guess["likely"].startswith("x flipped") and "curl_x_flipped" in guess


@NEEDS_BEAR
def test_flip_check_on_the_real_bear_as_read_and_flipped():
    data = io.read_dataset(BEAR)
    ok = frames.flip_check(prepare(data["normals"], data["mask"], K=data["K"]))
    assert ok["curl"] < frames.FLIP_MIN_CURL
    with pytest.warns(UserWarning, match="with y flipped"):
        frames.flip_check(prepare(data["normals"] * [1, -1, 1], data["mask"], K=data["K"]))


def test_relative_curl_sampling_agrees_with_the_full_field():
    n, _ = bump((96, 96))
    noisy = n + np.random.default_rng(3).normal(scale=0.05, size=n.shape)
    pr = prepare(noisy)
    full = frames.relative_curl(pr)
    sampled = frames.relative_curl(pr, sample=96 * 20)
    assert abs(full - sampled) < 0.1 * full
    assert frames.relative_curl(prepare(n)) < 0.02


def test_mean_deviation_is_reported_and_rises_with_noise():
    n, _ = bump()
    rng = np.random.default_rng(4)
    noisy = n + rng.normal(scale=0.2, size=n.shape)
    a, b = facetlift.integrate(n), facetlift.integrate(noisy)
    assert 0 <= a.info["mean_deviation"] < 0.5 < b.info["mean_deviation"]
    assert "diagnose" in b.info["seconds"]


@pytest.mark.parametrize("frame", ["xy", "rowcol", "queau", "numpy", "image", "MATLAB",
                                   "opencv"])
def test_integrate_gradients_in_every_layout(frame, rel_err):
    """Each gradient frame and alias reads its layout: `matlab` is MATLAB's own
    [FX, FY] = gradient(Z) (columns first, rows down; it meant `rowcol` before, and MATLAB's
    gradient came out wrong without a word, an audit), `numpy` np.gradient's rows first."""
    r, c = np.indices((24, 30))
    z = 3 * np.exp(-((r - 11.5) ** 2 + (c - 14.5) ** 2) / 40) + 0.01 * r * c
    dz_drow, dz_dcol = np.gradient(z)  # (central differences at the pixel centres)
    p, q = {"xy": (dz_dcol, -dz_drow), "rowcol": (dz_drow, dz_dcol),
            "image": (dz_dcol, dz_drow)}[frames.gradient_frame(frame)]
    s = facetlift.integrate_gradients(p, q, gradient_frame=frame)
    inner = (slice(2, -2), slice(2, -2))
    assert rel_err(s.height[inner], z[inner]) < 0.05


def test_a_gradient_field_in_the_other_layout_is_named():
    """p = dz/d(row) read as dz/dx turns the field by 90 degrees (no flip of the normals
    undoes it, and the surface came out with no warning): the layout check names the flag;
    the right layout is silent."""
    r, c = np.indices((24, 30))
    z = 3 * np.exp(-((r - 11.5) ** 2 + (c - 14.5) ** 2) / 40)
    zr = np.pad(z, 1, mode="edge")
    dz_dcol = (zr[1:-1, 2:] - zr[1:-1, :-2]) / 2
    dz_drow = (zr[2:, 1:-1] - zr[:-2, 1:-1]) / 2
    with pytest.warns(UserWarning, match=r"other layout.*--gradient-frame rowcol"):
        facetlift.integrate_gradients(dz_drow, dz_dcol)  # a row/column field read as xy
    with pytest.warns(UserWarning, match=r"other layout.*--gradient-frame xy"):
        facetlift.integrate_gradients(dz_dcol, -dz_drow, gradient_frame="queau")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = frames.layout_check(dz_drow, dz_dcol, "rowcol")
    assert out["curl"] < 0.05 < 0.3 < out["curl_other_layout"]
    assert np.isnan(frames.layout_curls(np.full((4, 4), np.nan), np.zeros((4, 4)))).all()
    r, c = np.indices((30, 36)) + 0.5  # a slope of the wrong sign is not taken for a layout
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frames.layout_check(np.cos(c / 4) * np.cos(r / 5), -0.8 * np.sin(c / 4) * np.sin(r / 5))
    # fields integrable in both layouts are silent: a saddle (no divergence either), a
    # paraboloid read right, both with a little noise (a saddle's noise-over-noise curl of
    # 0.71 warned before), and a plane
    y, x = np.indices((96, 128)) * [[[-1]], [[1]]]
    rng = np.random.default_rng(0)
    noise = [1e-3 * rng.standard_normal(x.shape) for _ in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in (0.3, 1.0):
            frames.layout_check(k * x + noise[0], -k * y + noise[1])  # z = k/2 (x^2 - y^2)
            frames.layout_check(k * x + noise[0], k * y + noise[1])  # z = k/2 (x^2 + y^2)
        frames.layout_check(np.full(x.shape, 0.2), np.full(x.shape, -0.1))
    with pytest.warns(UserWarning, match="--gradient-frame rowcol"):  # (the paraboloid turned)
        frames.layout_check(-(0.3 * y), 0.3 * x)


def test_p_and_q_given_the_other_way_round_are_named():
    """Slopes given in the wrong order (--gradients Q P) came out bent with a hint to keep
    depth jumps (an audit): the layout check names the exchange, in every frame, and stays
    silent on the right order."""
    r, c = np.indices((40, 48))
    z = 3 * np.exp(-((r - 18.5) ** 2 / 60 + (c - 20.5) ** 2 / 30)) + 0.01 * r * c
    dz_drow, dz_dcol = np.gradient(z)
    for frame, (p, q) in {"xy": (dz_dcol, -dz_drow), "rowcol": (dz_drow, dz_dcol),
                          "image": (dz_dcol, dz_drow)}.items():
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert frames.layout_check(p, q, frame)["suggested"] is None
        with pytest.warns(frames.LayoutWarning, match=r"p and q look exchanged.*--gradients Q P"):
            out = frames.layout_check(q, p, frame)
        assert out["suggested"] == "swapped" and out["curl_swapped"] < 0.05 < out["curl"]
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            s = facetlift.integrate_gradients(q, p, gradient_frame=frame)
        said = [str(w.message) for w in got]
        assert any("exchanged" in m for m in said), said
        assert not any("--discontinuities" in h for h in s.info.get("hints", ())), said


def _sphere_rowcol(size=64):
    """A sphere cap's slopes stored as row/column derivatives (p = dz/d(row), q = dz/d(col)),
    from synthetic's analytic height, and its mask."""
    from facetlift import synthetic

    r, c = np.indices((size, size))
    x, y = c + 0.5 - size / 2, -(r + 0.5 - size / 2)
    _, gx, gy, inside = synthetic.analytic_height("sphere", x, y, scale=size / 2)
    return np.where(inside, -gy, np.nan), np.where(inside, gx, np.nan), inside


def test_a_field_in_the_other_layout_gets_the_layout_warning_alone():
    """A row/column field read as xy was told both 'try --gradient-frame rowcol' and 'negate
    q' (the flip check after the solve, a review): the layout warning alone, and the
    integrability record says which layout was named; in the right layout, neither."""
    p, q, mask = _sphere_rowcol()
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = facetlift.integrate_gradients(p, q, mask)
    said = [str(w.message) for w in rec]
    assert len(said) == 1 and "--gradient-frame rowcol" in said[0], said
    assert s.info["integrability"]["other_layout"] == "rowcol"
    assert s.info["integrability"]["curl"] > 0.5  # (the curls are still recorded)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = facetlift.integrate_gradients(p, q, mask, gradient_frame="rowcol")
    assert "other_layout" not in s.info["integrability"]
    # a slope of the wrong sign in the right layout is still named by the flip check
    with pytest.warns(UserWarning, match=r"negate p \(q with --gradient-frame rowcol\)|"
                      r"negate q \(p with") as rec:
        facetlift.integrate_gradients(-p, q, mask, gradient_frame="rowcol")
    assert not any("other layout" in str(w.message) for w in rec)


def test_integrate_gradients_refusals():
    p = np.zeros((5, 5))
    with pytest.raises(ValueError, match="`gradient_frame` must be one of"):
        facetlift.integrate_gradients(p, p, gradient_frame="yx")
    with pytest.raises(ValueError, match="`K` does not apply to a gradient field"):
        facetlift.integrate_gradients(p, p, K=np.eye(3))
    with pytest.raises(ValueError, match="`q` must have the shape of `p`"):
        facetlift.integrate_gradients(p, np.zeros((4, 5)))


@NEEDS_BEAR
def test_relative_curl_of_a_pinhole_does_not_depend_on_the_object_place():
    """The same perspective view padded with empty columns on the left (and cx moved with it):
    the same curl (the strips' crop once fed shifted columns to the camera); 0.219 over every
    row pair of the object (0.222 when it was sampled as a part of the 512 x 612 image)."""
    data = io.read_dataset(BEAR)
    n, m, K = data["normals"], data["mask"], np.array(data["K"], float)
    pad = 37
    n2 = np.concatenate([np.full((n.shape[0], pad, 3), np.nan), n], axis=1)
    m2 = np.concatenate([np.zeros((m.shape[0], pad), bool), m], axis=1)
    K2 = K.copy()
    K2[0, 2] += pad
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = frames.relative_curl(prepare(n, m, K=K))
        b = frames.relative_curl(prepare(n2, m2, K=K2))
    assert a == pytest.approx(0.2190, abs=2e-3) and b == pytest.approx(a, rel=1e-9)


@NEEDS_BEAR
def test_facing_away_is_judged_on_the_object_without_a_mask():
    """An OpenCV-frame map with a zero background and no mask: the object (13 % of the image)
    faces away; the background's zeros are no normals and must not outvote it."""
    data = io.read_dataset(BEAR)
    n = np.where(data["mask"][..., None], data["normals"], 0.0) * [1.0, -1.0, -1.0]
    with pytest.raises(ValueError, match=r"face away from the viewer.*--normal-frame opencv"):
        facetlift.integrate(n)


def test_relative_curl_sample_is_not_hidden_by_a_periodic_mask():
    """Sampled rows are taken among the rows that hold the object: a mask of two-row bands
    every 16 rows, sampled every 91st image row, was missed entirely (NaN: no check) when the
    rows were spaced over the image."""
    H = W = 600
    r, c = np.mgrid[0:H, 0:W]
    mask = (r % 16 == 5) | (r % 16 == 6)
    x, y = (c - W / 2) / W, (H / 2 - r) / H
    n = np.stack([-0.5 * y, -0.5 * x, np.ones_like(x)], -1)  # z = x y / 2 (cross derivatives)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = prepare(n / np.linalg.norm(n, axis=-1, keepdims=True), mask)
    sampled = frames.relative_curl(p, sample=1000)
    assert np.isfinite(sampled) and sampled < 0.05
    assert frames.relative_curl(p) == pytest.approx(sampled, abs=0.05)


def test_flip_hint_on_a_noisy_map_with_jumps():
    """A y-down map of an object with jumps and some noise: its flipped field's curl is 0.58-0.70
    of its own (the jumps and the noise keep the right frame's own curl up), where the rule
    (below half) said nothing; it now gets the hint (below three quarters), not the claim;
    read in its right frame the ratio is 1.4-1.7 (nothing said)."""
    from facetlift import synthetic
    from facetlift.errors import FrameWarning

    gt = synthetic.analytic("occluder", 128)
    n = gt.normals + 0.015 * np.random.default_rng(0).standard_normal(gt.normals.shape)
    with pytest.warns(FrameWarning, match="more integrable with y flipped .* not by the margin"
                      r".* try --normal-frame directx"):
        facetlift.integrate(n * [1.0, -1.0, 1.0], gt.mask)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FrameWarning)
        s = facetlift.integrate(n, gt.mask)
    ratio = s.info["integrability"]["curl_y_flipped"] / s.info["integrability"]["curl"]
    assert 1.2 < ratio < 2.0


def test_decoded_normals_far_from_unit_length_are_warned_about():
    """A texture artist's map with the blue channel fixed at 255 (two-channel bakes are often
    filled so) read as consistent and lost 29 % of its height; a well-encoded map, 8 or 16
    bits, stays silent."""
    import warnings

    yy, xx = np.mgrid[0:64, 0:64]
    n = np.dstack([-0.5 * np.cos(xx / 10), -0.3 * np.sin(yy / 7), np.ones((64, 64))])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    for dtype in (np.uint8, np.uint16):
        top = np.iinfo(dtype).max
        v = np.round((n + 1) / 2 * top).astype(dtype)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            frames.decode(v)
        v[..., 2] = top
        with pytest.warns(UserWarning, match=r"longer than unit length .* is z stored .*"
                          r"--normal-encoding xy"):
            frames.decode(v)
        # ... only among the pixels that count (a review: an alpha-0 background warned)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            frames.decode(v, where=np.zeros((64, 64), bool))
    # shortened vectors (a resized or noisy map) are no sign of a missing z: silent
    v = np.round((0.9 * n + 1) / 2 * 255).astype(np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frames.decode(v)


def _bumps_on_a_plane(N=128):
    """Unit normals of three compact cos^2 bumps on a flat plane (exactly flat between them,
    as a texture bake's flat areas are), the height, and where the slopes are exactly 0."""
    r, c = np.mgrid[0:N, 0:N] + 0.5
    h = np.zeros((N, N))
    for y0, x0 in ((30, 35), (90, 45), (60, 100)):
        d2 = ((r - y0) ** 2 + (c - x0) ** 2) / 15**2
        h += np.where(d2 < 1, 4 * np.cos(np.pi / 2 * np.sqrt(d2)) ** 2, 0)
    gy, gx = np.gradient(h)
    return facetlift.normals_from_gradients(gx, -gy), h, (gx == 0) & (gy == 0)


@pytest.mark.parametrize("encode", [np.round, np.floor])
def test_8_bit_flat_areas_decode_to_exactly_zero(encode):
    """An audit: 8-bit encoders store the component 0 as 128 (round(127.5); some truncate to
    127), which decodes to +-0.0039: every flat area tilted, and a 1024^2 brick texture's
    height came out 27 % RMS off. A spike in the x or y histogram at 128 (127) is decoded as
    exactly 0; the height comes out within 1 %."""
    n, h, flat = _bumps_on_a_plane()
    v = np.minimum(encode((n + 1) / 2 * 255), 255).astype(np.uint8)
    assert flat.mean() > 0.5
    plain = v / 255 * 2 - 1
    assert np.abs(plain[flat][:, :2]).min() > 0.0039  # (as decoded before: tilted)
    d = frames.decode(v)
    assert (d[flat][:, :2] == 0).all()
    if encode is np.round:
        np.testing.assert_array_equal(d[v != 128], plain[v != 128])  # (other codes as before)
    else:  # a truncating encoder: every code read at the middle of its step (a second audit:
        # with 127 alone read as 0 the sloped texels kept half a code of bias, 2.7 % RMS)
        np.testing.assert_allclose(d, (v + 0.5) / 255 * 2 - 1, rtol=0, atol=1e-15)

    def rms(normals):
        z, t = -facetlift.integrate(normals).depth, h - h.mean()
        return np.sqrt(np.mean((z - z.mean() - t) ** 2) / np.mean(t**2))

    assert rms(plain) > 0.1 and rms(d) < 0.02


def test_8_bit_flat_areas_of_a_bgr_map_decode_to_zero_in_its_own_x_and_y():
    """An audit: the zero plateaus were looked for in the stored channels 0 and 1, so a BGR
    map (as cv2.imwrite writes it) read with normal_frame='z,y,x' kept the half-code tilt in
    x, its third channel (a brick texture 3.4 % -> 9.8 % RMS height error); they are now the
    channels the frame reads x and y from, and the BGR map comes out as the RGB one."""
    n, h, flat = _bumps_on_a_plane()
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", facetlift.FrameWarning)  # (8-bit decoded)
        rgb = facetlift.integrate(v).depth
        bgr = facetlift.integrate(np.ascontiguousarray(v[..., ::-1]), normal_frame="z,y,x").depth
    np.testing.assert_allclose(bgr, rgb, atol=1e-9)
    d = frames.decode(np.ascontiguousarray(v[..., ::-1]), frame="z,y,x")
    assert (d[flat][:, 1:] == 0).all()  # (stored y and x: channels 1 and 2)


def test_8_bit_maps_without_a_flat_plateau_and_16_bit_maps_decode_as_before():
    """A sphere's normals are spread continuously: no spike at 128, and the decode is
    bit for bit v / 255 * 2 - 1 (NaN outside the valid lengths); 16 bits never change."""
    r, c = np.mgrid[0:96, 0:96] + 0.5
    x, y = (c - 48) / 40, -(r - 48) / 40
    inside = x**2 + y**2 < 1
    n = np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, None))])
    n[~inside] = 0  # (the background: mid-grey fill, not a normal)
    flat, _, _ = _bumps_on_a_plane(96)
    for m, bits in ((n, 8), (n, 16), (flat, 16)):
        top = 2**bits - 1
        v = np.round((m + 1) / 2 * top).astype(np.uint8 if bits == 8 else np.uint16)
        plain = v / top * 2 - 1
        length = np.linalg.norm(plain, axis=-1)
        plain[(length < 0.5) | (length > 1.5)] = np.nan
        np.testing.assert_array_equal(frames.decode(v), plain)


def test_8_bit_zero_plateaus_are_counted_inside_where_only():
    """A review: the plateau counts of the 8-bit decode use only the pixels inside `where`
    (the mask or alpha), and no test said so. A map whose x and y spread continuously inside
    the mask (128 no more common than 127 or 129) beside a flat (128, 128, 255) background
    outside it: with the mask, 128 decodes as before inside (+0.0039); without it, the
    background's plateau makes it 0."""
    H, W = 40, 60
    r, c = np.mgrid[0:H, 0:W]
    mask = c < 30
    v = np.zeros((H, W, 3), np.uint8)
    v[..., 0] = np.where(mask, 113 + c, 128)  # (113..142 inside: 40 pixels per code)
    v[..., 1] = np.where(mask, 108 + r, 128)  # (108..147)
    x, y = v[..., 0] / 255 * 2 - 1, v[..., 1] / 255 * 2 - 1
    v[..., 2] = np.round((np.sqrt(1 - x**2 - y**2) + 1) / 2 * 255)
    plain = v / 255 * 2 - 1
    at = mask & (v[..., 0] == 128)
    assert at.sum() == 40 and np.allclose(plain[at][:, 0], 1 / 255)
    d = frames.decode(v, where=mask)
    np.testing.assert_array_equal(d[mask], plain[mask])  # (bit for bit: no plateau inside)
    every = frames.decode(v)  # (without the mask: the background's plateau counts)
    assert (every[at][:, 0] == 0).all() and (every[~mask][:, :2] == 0).all()


def test_an_srgb_encoded_map_is_named_with_the_curve_that_undoes_it():
    """An audit: an 8-bit map passed through an sRGB curve (a colour-managed export) gave 30x
    the depth error, and the warning blamed a missing z. Either way round, the curve that
    makes the vectors unit length is named, with its code; a map with z missing keeps the
    z message."""
    import warnings

    yy, xx = np.mgrid[0:64, 0:64]
    n = np.dstack([-0.5 * np.cos(xx / 10), -0.3 * np.sin(yy / 7), np.ones((64, 64))])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    v = (n + 1) / 2
    for curve, says, undo in ((frames._linear_to_srgb, "sRGB-encoded", frames._srgb_to_linear),
                              (frames._srgb_to_linear, "linearised by an sRGB decode",
                               frames._linear_to_srgb)):
        stored = np.round(curve(v) * 255).astype(np.uint8)
        with pytest.warns(UserWarning, match=rf"longer than unit length .* the map looks "
                          rf"{says}.*Non-Color") as rec:
            frames.decode(stored)
        assert "is z stored" not in str(rec[0].message)
        fixed = 2.0 * undo(stored / 255.0) - 1.0  # (the conversion the message gives)
        length = np.linalg.norm(fixed, axis=-1)
        assert np.abs(length - 1).max() < 0.03
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            facetlift.integrate(fixed)
    stored = np.round(v * 255).astype(np.uint8)
    stored[..., 2] = 255
    with pytest.warns(UserWarning, match=r"is z stored"):
        frames.decode(stored)


def test_noisy_lengths_are_told_from_a_missing_z():
    """A review: a JPEG-compressed bear (as PNG) was told that 8 % of its normals were longer
    than unit length, asked whether z was stored and pointed to --normal-encoding xy; 13.5 %
    were as much shorter: compression noise. Lengths spread both ways are now named as noise
    or lossy compression, without the flag; a blue channel fixed at 255 (x, y only stored),
    noisy too, keeps the z message."""
    yy, xx = np.mgrid[0:96, 0:96]
    n = np.dstack([-0.5 * np.cos(xx / 10), -0.3 * np.sin(yy / 7), np.ones((96, 96))])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    rng = np.random.default_rng(0)
    for dtype in (np.uint8, np.uint16):
        top = np.iinfo(dtype).max
        noisy = n * rng.uniform(0.94, 1.06, (96, 96, 1))  # (lengths off both ways, as a JPEG's)
        v = np.round((np.clip(noisy, -1, 1) + 1) / 2 * top).astype(dtype)
        with pytest.warns(facetlift.FrameWarning, match=r"lengths are noisy: \d+% are longer "
                          r"than unit length and \d+% shorter .*lossy compression") as rec:
            frames.decode(v)
        said = " ".join(str(w.message) for w in rec)
        assert "is z stored" not in said and "--normal-encoding" not in said, said
        z = np.round((np.clip(n + rng.normal(0, 0.004, n.shape), -1, 1) + 1) / 2 * top)
        z[..., 2] = top  # (a two-channel map's blue fill read as z)
        with pytest.warns(facetlift.FrameWarning, match=r"longer than unit length .* is z "
                          r"stored .*--normal-encoding xy") as rec:
            frames.decode(z.astype(dtype))
        assert "noisy" not in " ".join(str(w.message) for w in rec)


def test_the_grazing_warning_names_the_option_that_keeps_steep_walls():
    """A stamp whose near-vertical walls were dropped by the paper's rule vanished (plateau 0
    instead of 20); the smooth route's warning did not name --outlier-eps."""
    import facetlift

    n = np.dstack([np.zeros((20, 20)), np.zeros((20, 20)), np.ones((20, 20))])
    n[8, 3:17] = [0.0, 0.999, 0.045]  # (a wall seen at 87 deg)
    with pytest.warns(UserWarning, match=r"grazing: view cosine < 0.08716, outlier_eps / "
                      r"--outlier-eps sets another: a smaller one keeps more"):
        facetlift.integrate(n)


def test_half_facing_away_names_the_reversed_channel_order():
    """An audit: an OpenCV-frame map saved in BGR order and read with normal_frame='opencv'
    had half its normals facing away, and the refusal offered two frames that both ran 20
    deg off. The reversed order that faces the viewer is measured and named first."""
    r, c = np.mgrid[0:48, 0:48] + 0.5
    x, y = (c - 20) / 32, -(r - 24) / 32  # (off-centre: 59 % of x > 0)
    n = np.dstack([x, y, np.sqrt(1 - x**2 - y**2)])  # a sphere cap, facing the viewer
    stored = frames.from_facetlift(n, "opencv")[..., ::-1]  # in BGR order
    with pytest.raises(ValueError, match=r"face away .* channels in another order, e\.g\. BGR "
                       r".*--normal-frame z,-y,-x \(normal_frame='z,-y,-x'\) leaves 0% facing "
                       r"away") as e:
        facetlift.integrate(stored, normal_frame="opencv")
    assert "z,-y,-x" in str(e.value).split("; else")[0]
    s = facetlift.integrate(stored, normal_frame="z,-y,-x")
    assert s.info["mean_deviation"] < 0.5
    # nearly every normal facing away is a flipped z: no channel order is offered
    with pytest.raises(ValueError, match="face away") as e:
        facetlift.integrate(frames.from_facetlift(n, "opencv"))
    assert "channels in another order" not in str(e.value)


def test_an_integer_maps_unit_length_check_looks_inside_the_mask_only():
    """A final read: the masked-array change passed no mask to the decode's unit-length check
    for plain arrays, so a map's background fill (here decoding to length 1.3) would have
    warned again."""
    import warnings

    yy, xx = np.mgrid[0:48, 0:48]
    inside = (yy - 24) ** 2 + (xx - 24) ** 2 < 15 ** 2
    n = np.dstack([np.zeros((48, 48)), np.zeros((48, 48)), np.ones((48, 48))])
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    v[~inside] = [200, 200, 255]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        facetlift.integrate(v, inside)
    assert not [w for w in caught if "longer than unit length" in str(w.message)]


def blob(shape=(60, 80), frame_pad=8):
    """Normals of an ellipsoidal cap inside a margin (a silhouette: edge-on, pointing out of
    the mask), with a lump so that the field is not symmetric, and its mask."""
    H, W = shape
    r, c = np.indices(shape)
    u = (c + 0.5 - W / 2) / (W / 2 - frame_pad)
    v = (H / 2 - r - 0.5) / (H / 2 - frame_pad)  # (y up)
    inside = u**2 + v**2 < 1.0
    z = np.sqrt(np.clip(1.0 - u**2 - v**2, 0.0, None)) + 0.2 * np.exp(
        -((u - 0.3) ** 2 + (v + 0.2) ** 2) / 0.05)
    gx = np.gradient(z, axis=1) * (W / 2 - frame_pad)
    gy = -np.gradient(z, axis=0) * (H / 2 - frame_pad)
    n = np.dstack([-gx, -gy, np.ones(shape)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    mask = inside & np.isfinite(n).all(axis=2)
    return n, mask


def test_silhouette_names_the_wrong_axis_where_the_flips_tie():
    """Orthographically a map with x negated and one with y negated are equally integrable
    (inside-out from each other); at the object's silhouette the normals point out of it,
    which tells them apart: a DSINE map (x left) was told to try the y flip first, and the
    surface then came out inside-out (a user's check)."""
    from facetlift import describe
    from facetlift.errors import FrameWarning

    n, mask = blob()
    sil = frames.silhouette(prepare(n, mask))
    assert sil["x"] == 1.0 and sil["y"] == 1.0 and min(sil["pixels"]) >= frames.SILHOUETTE_MIN
    dsine = n * [-1, 1, 1]
    with pytest.warns(FrameWarning, match=r"wrong in x \(at the object's silhouette the normals "
                      r"point into it along x: 100 % .*try --normal-frame=-x,y,z"):
        facetlift.integrate(dsine, mask)
    guess = describe._frame_guess(dsine, mask, None, prepare(dsine, mask), frame=None,
                                  layout=None)
    assert guess["likely"].startswith("x flipped") and "-x,y,z" in guess["likely"]
    with pytest.warns(FrameWarning, match=r"wrong in y \(at the object's silhouette"):
        facetlift.integrate(n * [1, -1, 1], mask)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        facetlift.integrate(n, mask)


def test_an_inside_out_map_is_told_by_its_silhouette():
    """Both x and y negated: as integrable as the right map, so no curl tells; the normals
    point into the object all round its silhouette. Read in the frame given, the fix is named
    relative to it."""
    from facetlift.errors import FrameHint

    n, mask = blob()
    with pytest.warns(FrameHint, match=r"point into the object at its mask's edge along both "
                      r"x and y .*inside-out.*try --normal-frame=-x,-y,z.*A concave surface"):
        s = facetlift.integrate(n * [-1, -1, 1], mask)
    assert s.info["integrability"]["curl"] < frames.FLIP_MIN_CURL
    with pytest.warns(FrameHint, match=r"\(read in the frame x,-y,z\) point into the object.*"
                      r"try --normal-frame=-x,y,z"):
        facetlift.integrate(n * [-1, 1, 1], mask, normal_frame="directx")
    # a gradient field has no normal frame to name (a review found a crash there): the
    # slopes are named; a hint, as a concave surface masked alone gives it too
    H, W = mask.shape
    p = -n[..., 0] / n[..., 2]
    q = -n[..., 1] / n[..., 2]
    with pytest.warns(FrameHint, match=r"negate both p and q"):
        facetlift.integrate_gradients(-p, -q, mask)
    from facetlift import describe

    guess = describe._frame_guess(n * [-1, -1, 1], mask, None,
                                  prepare(n * [-1, -1, 1], mask), field=True)
    assert "negating both p and q" in guess["likely"] and "concave" in guess["likely"]
    # one axis: named as the slope of the layout read, as integrate's warning names it
    guess = describe._frame_guess(n * [1, -1, 1], mask, None, prepare(n * [1, -1, 1], mask),
                                  field=True)
    assert "negating the y slope (q; p with --gradient-frame rowcol)" in guess["likely"]


def test_silhouette_counts_only_the_mask_edge_inside_the_image():
    """An object cut by the image's border has no contour there; a map filling its image has
    none at all (the test stays silent); a cropped problem (an object in a larger image) sees
    its neighbours beyond the crop box as the image's."""
    n, mask = blob()
    assert frames.silhouette(prepare(n))["x"] is None  # (every pixel: no edge in the image)
    full = prepare(n, mask)
    # the same object in a larger image, cropped to its box as integrate does
    from facetlift.api import crop

    big_n = np.zeros((100, 120, 3))
    big_n[..., 2] = 1.0
    big_n[20:80, 30:110] = n
    big_m = np.zeros((100, 120), bool)
    big_m[20:80, 30:110] = mask
    sub, offset = crop(prepare(big_n, big_m))
    assert offset != (0, 0) and sub.extras["image_shape"] == (100, 120)
    assert frames.silhouette(sub) == frames.silhouette(full)
    # its left half at the image's border: those columns' edge no longer counts
    half = mask.copy()
    half[:, :40] = False
    cut = frames.silhouette(prepare(n[:, 40:], half[:, 40:]))
    assert cut["pixels"][0] < frames.silhouette(prepare(n, half))["pixels"][0]


def test_no_flip_is_suggested_where_many_normals_face_away():
    """A map in BGR channel order faces away from the camera on about half its pixels:
    prepare's warning asks about another frame or BGR order; a flip of x or y mends neither,
    and suggesting one (-x,-y,-z for an OpenCV map written by imwrite) contradicted it (a
    user's check)."""
    from facetlift.errors import FrameWarning
    from facetlift.problem import UnusableNormalsWarning

    n, mask = blob((90, 120), 10)
    K = np.array([[150.0, 0, 59.5], [0, 150.0, 44.5], [0, 0, 1]])
    bgr = (n * [1, -1, -1])[..., ::-1]  # (the OpenCV camera frame, written in BGR order)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(bgr, mask, K=K, normal_frame="opencv")
    said = [str(w.message) for w in rec]
    assert any("BGR channel order" in m for m in said), said
    assert not [m for m in said if "integrable with" in m], said
    assert [w for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert not [w for w in rec if issubclass(w.category, FrameWarning)]  # (the hint)


def test_flip_decided_only_by_a_margin_or_the_silhouette():
    """Two flips about as integrable (within SILHOUETTE_TIE) and no silhouette vote: neither
    axis is known, and the warnings name both alike (a user's DSINE map with K and depth
    jumps scored 0.43 with y and 0.52 with x flipped; y, the inside-out one, was named first
    and followed). A silhouette vote for one axis, or a clear margin, decides."""
    tie = {"curl_y_flipped": 0.43, "curl_x_flipped": 0.52}
    assert not frames.flip_decided(tie, None)
    assert not frames.flip_decided(tie, {"x": None, "y": None, "pixels": (0, 0)})
    assert frames.flip_decided(tie, {"x": 0.1, "y": 0.95, "pixels": (80, 80)})
    assert frames.flip_order(tie, {"x": 0.1, "y": 0.95, "pixels": (80, 80)}) == ("x", "y")
    assert not frames.flip_decided(tie, {"x": 0.1, "y": 0.1, "pixels": (80, 80)})
    assert frames.flip_decided({"curl_y_flipped": 0.68, "curl_x_flipped": 0.0005}, None)


def test_a_map_facing_away_is_offered_both_camera_frames():
    """z away: OpenCV's frame (y down) and Blender's camera space (y up) are both named (only
    opencv was, and a user's Blender map then went inside-out on the next hint)."""
    text = frames.facing_hint(None)
    assert "--normal-frame opencv" in text and "--normal-frame x,y,-z" in text


def test_a_texture_whose_period_is_a_multiple_of_the_curl_sample_stride_is_told(brick_texture):
    """A second audit: a y-down brick texture (512^2, bricks 64 rows high) got no frame
    warning. Its curl was sampled on every 8th row pair, the same rows of every brick, where
    the horizontal grooves are flat and the cross derivatives that tell a flip are 0 (0.94 as
    given, 0.74 flipped); over rows at seeded random places in each run of 8 it agrees with
    the whole field (1.00 and 0.04) and the warning names --normal-frame directx."""
    _, n = brick_texture()
    v = np.round((n * [1, -1, 1] + 1) / 2 * 255).astype(np.uint8)  # (DirectX: y down)
    p = prepare(frames.decode(v))
    whole = frames.flip_curls(p)  # (sampled: 2^16 of 2^18 pixels)
    full = (frames.relative_curl(p, sample=2**20),
            frames.relative_curl(p, (1.0, -1.0, 1.0), sample=2**20))
    assert full[1] < 0.1 * full[0]
    assert whole["curl"] == pytest.approx(full[0], abs=0.02)
    assert whole["curl_y_flipped"] == pytest.approx(full[1], abs=0.03)
    from facetlift.errors import FrameWarning

    with pytest.warns(FrameWarning, match=r"x or y flipped.*--normal-frame directx"):
        frames.flip_check(p)


def test_8_bit_maps_with_one_channel_inverted_zero_both_plateaus():
    """A review: a rounding encoder's map converted between OpenGL and DirectX by inverting
    green (255 - v) has x's plateau at 128 and y's at 127; read as a truncating encoder's
    (every code half a step up) it tilted every flat area by a whole code. Both plateaus are
    zero, every other code as decoded."""
    n, h, flat = _bumps_on_a_plane()
    v = np.minimum(np.round((n + 1) / 2 * 255), 255).astype(np.uint8)
    v[..., 1] = 255 - v[..., 1]  # (green inverted: y down)
    d = frames.decode(v)
    assert (d[flat][:, :2] == 0).all()
    plain = v / 255 * 2 - 1
    keep = (v[..., 0] != 128)
    np.testing.assert_array_equal(d[keep][:, 0], plain[keep][:, 0])
    keep = (v[..., 1] != 127)
    np.testing.assert_array_equal(d[keep][:, 1], plain[keep][:, 1])


def test_a_y_down_map_over_a_floor_is_told_to_flip_y(tmp_path, capsys):
    """A y-down (DirectX) map of an indoor view read as y up, with a camera: its floor faces
    away from the camera, and the warning asked about BGR order, world frames and K, never
    about y, while negating y turns every normal back toward the camera (an audit's
    estimator map, 19 % facing away). Now the warning and info name the y flip's frame."""
    from facetlift.cli import main
    from facetlift.problem import UnusableNormalsWarning

    H, W = 90, 120
    K = np.array([[100.0, 0, 59.5], [0, 100.0, 44.5], [0, 0, 1]])
    n = np.zeros((H, W, 3))
    n[..., 2] = 1.0  # a back wall facing the camera
    n[60:, :] = (0.0, 1.0, 0.0)  # the floor below the horizon (row 44.5) faces up
    stored = n * [1, -1, 1]  # (written y down)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = facetlift.integrate(stored, K=K)
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "with y negated" in said[0] and "--normal-frame directx" in said[0], said
    assert "BGR" not in said[0]
    assert s.info["input"]["facing_away_flip"][0] == "y"
    with warnings.catch_warnings(record=True) as rec:  # (read in its frame: no word)
        warnings.simplefilter("always")
        facetlift.integrate(stored, K=K, normal_frame="directx")
    assert not [w for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    # a y-up map given as directx from Python: the advice is to drop that frame, not to give
    # it (prepare ran outside the frame's context and advised the frame given, a review)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(n, K=K, normal_frame="directx")
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "with y negated" in said[0] and "--normal-frame directx" not in said[0]
    # info says the same; without a camera no flip changes which normals face away
    np.save(tmp_path / "n.npy", stored)
    np.savetxt(tmp_path / "K.txt", K)
    assert main(["info", str(tmp_path / "n.npy"), "--K", str(tmp_path / "K.txt"), "--json"]) == 0
    likely = json.loads(capsys.readouterr().out)["frame"]["likely"]
    assert likely.startswith("y flipped") and "directx" in likely, likely
    assert facetlift.problem._flip_mends_facing(
        facetlift.camera.Orthographic(), np.zeros(3, int), np.zeros(3, int),
        np.array([[0.0, 0, -1]] * 3), np.ones(3, bool), 1.0) is None


def test_decode_unsigned_names_undecoded_integer_values_as_floats():
    """An 8/16-bit map's values as floats (0..255 from a float conversion, a .mat's uint8
    variable, which read_mat makes float) given 'unsigned' were decoded into vectors far longer
    than unit, all NaN, and the run said 'no usable normal (all missing)'; without the option
    the undecoded-8-bit check names them: it is named with it too (a review)."""
    n, _ = bump()
    for scale, bits in ((255, 8), (65535, 16)):
        v = np.round((n + 1) / 2 * scale)
        v[:4] = 0.0  # (a black fill: no mask said where it is)
        with pytest.raises(ValueError, match=rf"m.npy: `normal_range` 'unsigned' says the map "
                           rf"stores \(n \+ 1\) / 2 in \[0, 1\], but its components reach "
                           rf"\d+: .*undecoded {bits}-bit.*n = v / {scale} \* 2 - 1"):
            frames.decode_unsigned(v, "`path`: m.npy")
    v = (n + 1) / 2
    v[0, 0] = 1.2  # (one stray pixel above 1: its fill rule's, not a refusal)
    assert np.isnan(frames.decode_unsigned(v, "m")[0, 0]).all()


@NEEDS_BEAR
@pytest.mark.parametrize("deg", [1.0, 3.0, 6.0])
def test_normal_noise_reads_the_angular_noise_from_the_curl(deg):
    """frames.normal_noise: about 0 for a surface's own normals, about the rotation angle's
    spread for angular noise, on a front view, a plane seen at view cosine 0.5 and through a
    pinhole (the bear's camera on its own normals), and the same seen by integrate
    (info['integrability']['noise'])."""
    from facetlift import synthetic

    n, _ = bump((96, 96))
    assert frames.normal_noise(prepare(n)) < 0.05
    rng = np.random.default_rng(5)
    noisy = synthetic.add_angular_noise(n, deg, rng)
    assert 0.85 * deg < frames.normal_noise(prepare(noisy)) < 1.1 * deg
    tilted = np.zeros((64, 64, 3))
    tilted[..., 0], tilted[..., 2] = -np.sqrt(3.0), 1.0  # (view cosine 0.5)
    tilted /= np.linalg.norm(tilted, axis=-1, keepdims=True)
    assert frames.normal_noise(prepare(tilted)) < 1e-6
    got = frames.normal_noise(prepare(synthetic.add_angular_noise(tilted, deg, rng)))
    assert 0.8 * deg < got < 1.15 * deg
    data = io.read_dataset(BEAR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = frames.normal_noise(prepare(data["normals"], data["mask"], K=data["K"]))
        bear = synthetic.add_angular_noise(data["normals"], deg, rng)
        seen = frames.normal_noise(prepare(bear, data["mask"], K=data["K"]))
        s = facetlift.integrate(noisy)
    assert own < 0.5  # (the bear's normals: 0.4 deg)
    assert 0.85 * deg < seen < 1.15 * deg
    assert s.info["integrability"]["noise"] == pytest.approx(
        frames.normal_noise(prepare(noisy)), rel=1e-9)


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (-1.0, 0.0, 1.0), (0.0, 1.0, 2.0)])
def test_normal_noise_through_a_wide_lens(normal):
    """Through a pinhole of f = 60 px on 128^2 (a 94 deg field of view) a plane's added noise
    reads as on the axis: the slopes' error grows with the normal's dot product with the
    unit-z ray, not with the view cosine (which read 1.25-1.34 deg for 2)."""
    from facetlift import synthetic

    K = np.array([[60.0, 0, 64], [0, 60.0, 64], [0, 0, 1]])
    n = np.zeros((128, 128, 3))
    n[:] = np.asarray(normal) / np.linalg.norm(normal)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = frames.normal_noise(prepare(synthetic.add_angular_noise(
            n, 2.0, np.random.default_rng(3)), K=K))
    assert 0.85 * 2.0 < got < 1.15 * 2.0


def test_normal_noise_is_nan_without_a_block_of_four_pixels():
    n, _ = bump((1, 30))
    assert np.isnan(frames.normal_noise(prepare(n)))


@pytest.mark.parametrize("fill", [(1.0, 1.0, 1.0), (-1.0, -1.0, -1.0),
                                  (127 / 255 * 2 - 1,) * 3])
def test_a_float_maps_background_fill_is_left_out(fill):
    """An audit: a normal map decoded by the user as floats (v / 65535 * 2 - 1, as BiNI's
    loader does) kept its white, black or mid-grey fill as normals, which a PNG's decoding
    drops: without a mask the DiLiGenT bear came out joined to a 45-degree plane (17.6 mm
    instead of 0.47), the grey fill was refused as facing away with the advice of a wrong
    frame. A vector repeated at the corners with a length far from 1 is now left out, with
    a warning; a unit-length background (a plane facing the camera) is kept."""
    n, _ = bump((40, 48))
    r, c = np.indices((40, 48))
    mask = (r - 19.5) ** 2 + (c - 23.5) ** 2 < 17**2
    filled = np.where(mask[..., None], n, np.asarray(fill))
    with pytest.warns(UserWarning, match=r"a background fill, no normals, was left out"):
        s = facetlift.integrate(filled)
    np.testing.assert_array_equal(np.isfinite(s.depth), mask)
    np.testing.assert_allclose(s.depth, facetlift.integrate(n, mask).depth, atol=1e-9)
    with warnings.catch_warnings():  # (a plane facing the camera around it: kept)
        warnings.simplefilter("error")
        s = facetlift.integrate(np.where(mask[..., None], n, np.array([0.0, 0.0, 1.0])))
        assert np.isfinite(s.depth).all()
        # unnormalised normals (-p, -q, 1) of a ridge, and a tent's ground scaled by 2: flat
        # parts repeated at the corners, no fill (they were dropped, or the whole map
        # refused, a review)
        p = np.where(np.arange(64) < 32, 1.2, -1.2)[None].repeat(64, 0)
        assert np.isfinite(facetlift.integrate(np.dstack([-p, 0 * p, 1 + 0 * p])).depth).all()
        tent = facetlift.synthetic.analytic("tent", 64)
        got = facetlift.integrate(2 * tent.normals, tent.mask).depth
        np.testing.assert_array_equal(np.isfinite(got), tent.mask)
        # an unnormalised pyramid whose faces are (+-1, +-1, 1): no fill either (its other
        # normals are not of unit length; three faces were dropped, a review)
        yy, xx = np.mgrid[0:64, 0:64]
        p, q = -np.sign(xx - 31.5), np.sign(yy - 31.5)
        pyramid = np.dstack([-p, -q, np.ones_like(p)]).astype(float)
        assert np.isfinite(facetlift.integrate(pyramid).depth).all()


def _ball_on_flat_fill(N=96, R=30):
    """A hemisphere's unit normals inside a disc and the flat normal (0, 0, 1) around it,
    and the disc."""
    r, c = np.mgrid[0:N, 0:N] + 0.5
    x, y = c - N / 2, N / 2 - r
    s = R * R - x * x - y * y
    m = s > 2
    n = np.stack([x / R, y / R, np.sqrt(np.clip(s, 0, None)) / R], -1)
    n[~m] = (0.0, 0.0, 1.0)
    return n, m


def test_a_flat_normal_fill_without_a_mask_is_named(tmp_path, brick_texture):
    """A review: the bear on a background of the flat-normal colour (128, 128, 255), a unit
    normal, given without a mask was integrated joined to one large plane (MADE 2.82 mm
    instead of 0.60), "unusable normals: none" and no word. Floats, an 8-bit array and a
    16-bit PNG are now warned about, counting the fill and naming --mask; with the mask, and
    where the flat surface meets the rest along gentle slopes (a tent's ground), no word."""
    n, m = _ball_on_flat_fill()
    said = (rf"`normals`: {int((~m).sum())} of the {m.size} pixels \(\d+%\), reaching the "
            r"image's corners, hold one and the same flat normal .*--mask FILE; mask= in Python")
    with pytest.warns(UserWarning, match=said):
        facetlift.integrate(n)
    codes = np.round((n + 1) / 2 * 255).astype(np.uint8)
    assert (codes[0, 0] == (128, 128, 255)).all()
    with pytest.warns(UserWarning, match=said):
        facetlift.integrate(codes)
    path = io.write_normals(tmp_path / "n.png", n, bits=16)
    with pytest.warns(UserWarning, match=r"`normals`: \d+ of the 9216 pixels.*flat normal"):
        facetlift.integrate(io.read_normals(path)[0])

    def silent(normals, mask=None):
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            facetlift.integrate(normals, mask)
        assert not [w for w in rec if "flat normal" in str(w.message)], rec

    silent(n, m)  # (given the mask: the fill is outside it)
    with warnings.catch_warnings(record=True) as rec:  # (a gradient field's zero slopes around
        warnings.simplefilter("always")  # an object: a height's ground, no fill)
        facetlift.integrate_gradients(-n[..., 0] / n[..., 2], -n[..., 1] / n[..., 2])
    assert not [w for w in rec if "flat normal" in str(w.message)], rec
    tent = facetlift.synthetic.analytic("tent", 96)  # (ground at every corner, roof at 45 deg)
    silent(tent.normals)
    silent(facetlift.synthetic.quantize(tent.normals, 8))
    bumpy, _ = bump((60, 60))  # (a bump rising gently from a plane: nothing steep beside it)
    flat = np.abs(bumpy[..., :2]).max(-1) < 1e-3
    bumpy[flat] = (0.0, 0.0, 1.0)
    silent(bumpy)
    # a texture's bricks with steep bevels on flat grooves that hold the corners: dozens of
    # raised pieces, no object on a fill (without the pieces' rule it was asked about)
    _, tiles = brick_texture(512, brick=(64, 32), bevel=(4, 6))
    silent(tiles)
    held = n.copy()  # (a fill that leaves one corner out is no background: a wall above a
    held[-30:, -30:] = (0.0, 0.6, 0.8)  # floor holds two)
    silent(held)
    for width, share in ((4, 0.16), (8, 0.31)):  # (a flat frame around a steep plane: asked
        framed = np.full_like(n, (0.0, 0.0, 1.0))  # about above 20 % of the image alone)
        framed[width:-width, width:-width] = (0.954, 0.0, 0.3)
        assert round((framed == (0.0, 0.0, 1.0)).all(-1).mean(), 2) == share
        if share <= frames.FLAT_FILL_SHARE:
            silent(framed)
        else:
            with pytest.warns(UserWarning, match=r"\(31%\), reaching the image's corners"):
                facetlift.integrate(framed)


def test_an_orthographic_map_given_a_camera_is_not_told_to_flip(tmp_path, capsys):
    """A perspective audit: a head-on (orthographic) map given a 60-degree field of view was
    told that 8 % of its normals face away and that its y axis probably runs the other way;
    following that, its deviation rose from 1.25 to 9.45 deg. Every one of its normals faces
    the viewer along the optical axis, so the warning and info now name the orthographic
    view (or a field of view too wide), not a flip."""
    from facetlift.camera import K_from_fov
    from facetlift.cli import main
    from facetlift.problem import UnusableNormalsWarning

    g = facetlift.synthetic.analytic("sphere", 200)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = facetlift.integrate(g.normals, g.mask, K=K_from_fov((200, 200), 60))
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "a map of an orthographic view given a camera" in said[0], said
    assert "negated" not in said[0] and "facing_away_flip" not in s.info["input"]
    # a y-down room with a few outlier normals: one flip mends it far more than the other,
    # so it keeps the flip's advice (it was told it was orthographic, a review)
    H, W = 90, 120
    K = np.array([[100.0, 0, 59.5], [0, 100.0, 44.5], [0, 0, 1]])
    room = np.zeros((H, W, 3))
    room[..., 2] = 1.0
    room[60:, :] = (0.0, 1.0, 0.0)
    room *= [1, -1, 1]
    rng = np.random.default_rng(0)
    odd = rng.random((H, W)) < 0.005
    room[odd] = rng.normal(size=(int(odd.sum()), 3))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(room, K=K)
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "--normal-frame directx" in said[0] and "orthographic" not in said[0]
    # a room with side walls, x and y both negated (a y-down map read with x flipped): told
    # to negate both, beside the orthographic reading that the facing cannot tell from it (it
    # was told only that it was orthographic, and integrated so came out inside-out, a review)
    walls = np.zeros((H, W, 3))
    walls[..., 2] = 1.0
    walls[:, :25], walls[:, 95:], walls[60:, 25:95] = (1.0, 0, 0), (-1.0, 0, 0), (0, 1.0, 0)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(walls * [-1, -1, 1], K=K)
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "x and y both run the other way" in said[0], said
    assert "--normal-frame=-x,-y,z" in said[0], said
    # a right orthographic vase given a 90-degree field of view: negating x mends its facing
    # too, but its silhouette says x runs as read: told of the camera, not of a flip (the
    # next review: told to flip, which turned it inside out)
    v = facetlift.synthetic.analytic("vase", 128)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(v.normals, v.mask, K=K_from_fov((128, 128), 90))
    said = [str(w.message) for w in rec if issubclass(w.category, UnusableNormalsWarning)]
    assert said and "a map of an orthographic view given a camera" in said[0], said
    assert "probably run" not in said[0] and "both run the other way" not in said[0], said
    np.save(tmp_path / "n.npy", np.where(g.mask[..., None], g.normals, np.nan))
    code = main(["info", str(tmp_path / "n.npy"), "--fov", "60", "--json"])
    out = capsys.readouterr().out
    likely = json.loads(out)["frame"]["likely"]
    assert code == 0 and likely.startswith("no camera, or a narrower one"), likely


def test_the_second_reviews_inputs_are_read_right():
    """A second review: a pure-blue fill (-1, -1, 1) of a user-decoded map went through as a
    55-degree plane; an anti-aliased corrugated 8-bit texture was told its z was not stored;
    unnormalised camera-frame normals in Python were asked whether they were a normal map."""
    N, R = 96, 30
    r, c = np.mgrid[0:N, 0:N] + 0.5
    x, y = c - 48, 48 - r
    s = R * R - x * x - y * y
    m = s > 2
    n = np.stack([x / R, y / R, np.sqrt(np.clip(s, 0, None)) / R], -1)
    v = np.round((n + 1) / 2 * 255)
    v[~m] = (0, 0, 255)
    with pytest.warns(UserWarning, match="a background fill, no normals, was left out"):
        got = facetlift.integrate(v / 255 * 2 - 1)
    np.testing.assert_array_equal(np.isfinite(got.depth), m)
    th = np.radians(25)
    cc = np.mgrid[0:1024, 0:1024][1] + 0.5
    big = np.zeros((1024, 1024, 3))
    big[..., 2] = np.cos(th)
    big[..., 0] = np.where(cc % 62 < 31, -np.sin(th), np.sin(th))
    aa = big.reshape(256, 4, 256, 4, 3).mean((1, 3))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(np.round((aa + 1) / 2 * 255).astype(np.uint8))
    assert not [w for w in rec if "z channel holds one code" in str(w.message)]
    N, R = 128, 57
    r, c = np.mgrid[0:N, 0:N] + 0.5
    x, y = c - 64, 64 - r
    s = R * R - x * x - y * y
    m = s > 2
    cv = np.stack([x / R, -y / R, -np.sqrt(np.clip(s, 0, None)) / R], -1) * 0.6
    with pytest.raises(ValueError, match="face away") as e:
        facetlift.integrate(np.where(m[..., None], cv, np.nan), m)
    assert "is it a normal map at all" not in str(e.value)


def test_rotate_takes_only_rotations_of_3_vectors():
    """A review: frames.rotate scaled the normals by 2 * I in silence and gave numpy's
    broadcast errors for a 2x2 matrix or 2-component vectors."""
    n = np.dstack([np.zeros((2, 2, 2)), np.ones((2, 2))])
    with pytest.raises(ValueError, match=r"`R` is not a rotation"):
        frames.rotate(n, 2 * np.eye(3))
    with pytest.raises(ValueError, match=r"`R` must be a 3x3 rotation matrix"):
        frames.rotate(n, np.eye(2))
    with pytest.raises(ValueError, match=r"`normals` must be \(\.\.\., 3\) vectors"):
        frames.rotate(np.zeros((2, 2, 2)), np.eye(3))
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(frames.rotate(n, turn), n @ turn.T)


def test_info_lets_the_camera_decide_where_the_curls_cannot(tmp_path, capsys):
    """A review: a right room map with --fov 60 and a little noise was told "as read, or y
    flipped: the check cannot tell", though with its camera the facing can (its y-down
    version is caught there, 22 % facing away). Where the map faces the camera as read and
    either flip would turn more than 5 % away, info says it is as read."""
    from facetlift.cli import main

    H, W = 90, 120
    K = np.array([[100.0, 0, 59.5], [0, 100.0, 44.5], [0, 0, 1]])
    walls = np.zeros((H, W, 3))
    walls[..., 2] = 1.0
    walls[:, :25], walls[:, 95:], walls[60:, 25:95] = (1.0, 0, 0), (-1.0, 0, 0), (0, 1.0, 0)
    n = facetlift.synthetic.add_angular_noise(walls, 3.0, rng=np.random.default_rng(0))
    np.save(tmp_path / "n.npy", n)
    np.savetxt(tmp_path / "K.txt", K)
    main(["info", str(tmp_path / "n.npy"), "--K", str(tmp_path / "K.txt"), "--json"])
    likely = json.loads(capsys.readouterr().out)["frame"]["likely"]
    assert likely.startswith("as read (consistent with the camera: 0.0% of the normals face "
                             "away from it as read, 42% with x negated, 19% with y negated"), likely


def test_a_field_all_but_integrable_in_another_reading_is_named_below_the_curl_floor():
    """A review: a nearly symmetric sine surface's columns-first field read as rowcol had a
    relative curl of 0.107 as read (below the 0.3 floor) and 0.00019 with p and q exchanged,
    and came out 31 % of its range wrong without a word. Below the floor, another reading
    with less than 1/20 of the curl is named; the right reading stays silent."""
    r, c = np.indices((96, 128)) + 0.5
    z = 3 * np.sin(2 * np.pi * c / 40) * np.sin(2 * np.pi * r / 50)
    dz_drow, dz_dcol = np.gradient(z)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert frames.layout_check(dz_dcol, dz_drow, "image")["suggested"] is None
    with pytest.warns(frames.LayoutWarning, match=r"exchanged"):
        out = frames.layout_check(dz_dcol, dz_drow, "rowcol")
    assert out["suggested"] == "swapped"
    assert frames.LAYOUT_LOW_CURL < out["curl"] < frames.LAYOUT_MIN_CURL
    assert out["curl_swapped"] < frames.LAYOUT_STRONG_RATIO * out["curl"]


def test_a_field_mostly_past_the_grazing_rule_is_asked_about_its_units():
    """A review: a paraboloid's slopes times 100 (up to 127) lost 99 % of their samples to
    the grazing rule and came out flat, exit 0, with the rule's words alone. Where most of a
    field is that steep the warning asks about the units; a field with a steep rim does not."""
    r, c = np.indices((48, 64)) + 0.5
    x, y = c - 32, 24 - r
    with pytest.warns(UserWarning, match=r"of the field is this steep: slopes in other units"):
        facetlift.integrate_gradients(100 * 0.02 * x, 100 * 0.02 * y)
    p, q = 0.02 * x, 0.02 * y
    p[:, :2] = 50.0  # (a steep rim: 4 % of the field)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        facetlift.integrate_gradients(p, q)
    said = " ".join(str(w.message) for w in got)
    assert "grazing" in said and "this steep" not in said


def test_the_silhouette_votes_one_pixel_inward_where_the_rim_has_no_slope():
    """np.gradient of a depth map with a NaN background leaves the rim's slopes NaN: given
    with the object's mask, the edge pixels could not vote and a field integrated inside out
    (slopes of depth, not height) went without a word (a review). The pixel one step inward
    votes for them."""
    r, c = np.indices((64, 80)) + 0.5
    rho2 = ((c - 40) ** 2 + (r - 32) ** 2) / 26.0**2
    inside = rho2 < 1
    depth = np.where(inside, 100 - 20 * np.sqrt(np.clip(1 - rho2, 0, None)), np.nan)
    dr, dc = np.gradient(depth)  # (NaN on the rim: its neighbours outside are NaN)
    assert np.isnan(dr[inside]).sum() > 50
    with pytest.warns(UserWarning, match=r"point into the object at its mask's edge"):
        facetlift.integrate_gradients(dr, dc, inside, gradient_frame="numpy")
    with warnings.catch_warnings(record=True) as got:  # (the height's slopes: silent)
        warnings.simplefilter("always")
        facetlift.integrate_gradients(-dr, -dc, inside, gradient_frame="numpy")
    assert not [w for w in got if "into the object" in str(w.message)]


def test_a_gradient_field_stacked_as_two_channels_is_pointed_to_integrate_gradients(
        tmp_path, capsys):
    """An (H, W, 2) stack of p and q was told of normal maps alone (a review)."""
    from facetlift.cli import main

    with pytest.raises(ValueError, match=r"stacked as \(H, W, 2\) is given as "
                       r"facetlift.integrate_gradients"):
        facetlift.integrate(np.zeros((20, 30, 2)))
    np.save(tmp_path / "pq.npy", np.zeros((20, 30, 2)))
    code = main(["integrate", str(tmp_path / "pq.npy"), "-o", str(tmp_path / "o")])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 1 and "--gradients P Q" in err


def test_a_hint_the_silhouette_confirms_becomes_a_claim():
    """A review's y-down render got only the hint (relative curl 0.86 as given, 0.48 with y
    flipped: between FLIP_RATIO and FLIP_HINT) though every edge pixel's normal pointed into
    the object along y: where the silhouette says the named axis points inward and the other
    outward, the hint is a claim. Not where the other axis says nothing (a room seen from
    inside has inward walls along x on a right map)."""
    from test_perspective import sphere_scene

    n, mask, K, _ = sphere_scene(min_cos=0.05)
    flipped = np.array(n) * (1, -1, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = prepare(flipped, mask, K=K)
    hint = {"curl": 0.86, "curl_y_flipped": 0.48, "curl_x_flipped": 0.9}
    f = frames.flip_assessment(problem, hint)
    assert f["says"] == {"x": "out", "y": "in"} and f["a"] == "y"
    assert f["verdict"] == "claim"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        right = prepare(np.array(n), mask, K=K)
    f = frames.flip_assessment(right, hint)  # (right: the silhouette says out, the hint stays)
    assert f["says"] == {"x": "out", "y": "out"} and f["verdict"] == "hint"
