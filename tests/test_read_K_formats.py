"""read_K on the files calibration tools write: OpenCV FileStorage YAML / XML, ROS
camera_info and CameraInfo dumps, COLMAP's cameras.txt, nerfstudio's transforms.json; each
written as the tool writes it."""

import json
import warnings

import numpy as np
import pytest

from facetlift import io
from facetlift.cli import main

#: The camera of these files, in facetlift's convention (pixel centres at integers).
K = np.array([[500.0, 0, 320.5], [0, 510, 240.25], [0, 0, 1]])

OPENCV_YAML = """%YAML:1.0
---
calibration_time: "Thu 01 Jan 2026 12:00:00 PM UTC"
image_width: 640
image_height: 480
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 5.0000000000000000e+02, 0., 3.2050000000000000e+02, 0.,
       5.1000000000000000e+02, 2.4025000000000000e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 1.0000000000000001e-01, -2.0000000000000001e-01, 0., 0.,
       0. ]
avg_reprojection_error: 2.5000000000000000e-01
"""

STEREO_YAML = """%YAML:1.0
---
M1: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 500., 0., 320.5, 0., 510., 240.25, 0., 0., 1. ]
D1: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
M2: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 502., 0., 318., 0., 511., 241., 0., 0., 1. ]
D2: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
R: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]
"""

OPENCV_XML = """<?xml version="1.0"?>
<opencv_storage>
<calibration_time>"Thu 01 Jan 2026 12:00:00 PM UTC"</calibration_time>
<image_width>640</image_width>
<image_height>480</image_height>
<camera_matrix type_id="opencv-matrix">
  <rows>3</rows>
  <cols>3</cols>
  <dt>d</dt>
  <data>
    5.0000000000000000e+02 0. 3.2050000000000000e+02 0.
    5.1000000000000000e+02 2.4025000000000000e+02 0. 0. 1.</data></camera_matrix>
<distortion_coefficients type_id="opencv-matrix">
  <rows>5</rows>
  <cols>1</cols>
  <dt>d</dt>
  <data>
    0. 0. 0. 0. 0.</data></distortion_coefficients>
</opencv_storage>
"""

# (camera_calibration's ost.yaml; P from a rectification, differing from the camera matrix)
ROS_CAMERA_INFO = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.5, 0.0, 510.0, 240.25, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.2, 0.001, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [480.0, 0.0, 318.0, 0.0, 0.0, 490.0, 238.0, 0.0, 0.0, 0.0, 1.0, 0.0]
"""

# (ros2 topic echo --once /camera/camera_info > info.yaml)
ROS2_DUMP = "\n".join([
    "header:", "  stamp:", "    sec: 1767225600", "    nanosec: 0",
    "  frame_id: camera_optical_frame", "height: 480", "width: 640",
    "distortion_model: plumb_bob", "d:", *["- 0.0"] * 5,
    "k:", *[f"- {float(v)!r}" for v in K.ravel()],
    "r:", *[f"- {float(v)!r}" for v in np.eye(3).ravel()],
    "p:", *[f"- {float(v)!r}" for v in np.hstack([K, np.zeros((3, 1))]).ravel()],
    "binning_x: 0", "binning_y: 0", "roi:", "  x_offset: 0", "  y_offset: 0", "  height: 0",
    "  width: 0", "  do_rectify: false", "---", ""])

# (rostopic echo -n 1 /camera/camera_info, ROS 1: upper-case flow lists)
ROS1_DUMP = """header:
  seq: 12
  stamp:
    secs: 1767225600
    nsecs:         0
  frame_id: "camera_rgb_optical_frame"
height: 480
width: 640
distortion_model: "plumb_bob"
D: [0.0, 0.0, 0.0, 0.0, 0.0]
K: [500.0, 0.0, 320.5, 0.0, 510.0, 240.25, 0.0, 0.0, 1.0]
R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
P: [500.0, 0.0, 320.5, 0.0, 0.0, 510.0, 240.25, 0.0, 0.0, 0.0, 1.0, 0.0]
binning_x: 0
binning_y: 0
roi:
  x_offset: 0
  y_offset: 0
  height: 0
  width: 0
  do_rectify: False
---
"""

COLMAP_HEADER = ("# Camera list with one line of data per camera:\n"
                 "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n")


def colmap(*lines):
    return COLMAP_HEADER + f"# Number of cameras: {len(lines)}\n" + "".join(
        ln + "\n" for ln in lines)


def read(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = io.read_K(tmp_path / name)
    return got, [str(w.message) for w in caught]


@pytest.mark.parametrize("name, text", [
    ("calib.yml", OPENCV_YAML),
    ("calib.yaml", OPENCV_YAML.replace("%YAML:1.0", "%YAML 1.0")),
    ("calib.txt", OPENCV_YAML),  # (found by its %YAML line, whatever its name)
    ("calib.xml", OPENCV_XML),
    ("info.yaml", ROS2_DUMP),
    ("info.txt", ROS2_DUMP),  # (an echo redirected to a .txt: found by its k: line)
    ("info1.yaml", ROS1_DUMP),
    # (an echo of several messages: the first; a later one's other K is not read)
    ("info2.yaml", ROS1_DUMP + ROS1_DUMP.replace("320.5", "300.5")),
])
def test_calibration_files_give_their_camera_matrix(tmp_path, name, text):
    got, said = read(tmp_path, name, text)
    np.testing.assert_array_equal(got, K)
    # (P equal to K in the dumps, zero distortion: nothing to say; OPENCV_YAML's distortion
    # is warned about)
    distorted = text.startswith("%YAML")
    assert len(said) == distorted
    assert not distorted or "lens distortion (k1 0.1, k2 -0.2)" in said[0]


DISTORTED = [  # (file name, text, the coefficients named): k1 -0.25, p1 0.001 in each
    ("dist.yml", OPENCV_YAML.replace("1.0000000000000001e-01, -2.0000000000000001e-01, 0., 0.",
                                     "-0.25, 0., 1.0e-03, 0."), "k1 -0.25, p1 0.001"),
    ("dist_coeffs.yml", OPENCV_YAML.replace("distortion_coefficients", "dist_coeffs").replace(
        "1.0000000000000001e-01, -2.0000000000000001e-01, 0., 0.", "-0.25, 0., 1.0e-03, 0."),
     "k1 -0.25, p1 0.001"),
    ("D.yml", OPENCV_YAML.replace("distortion_coefficients", "D").replace(
        "1.0000000000000001e-01, -2.0000000000000001e-01, 0., 0.", "-0.25, 0., 1.0e-03, 0."),
     "k1 -0.25, p1 0.001"),
    ("dist.xml", OPENCV_XML.replace("0. 0. 0. 0. 0.</data>", "-0.25 0. 1.0e-03 0. 0.</data>"),
     "k1 -0.25, p1 0.001"),
    ("ost.yaml", ROS_CAMERA_INFO.replace("[0.1, -0.2, 0.001, 0.0, 0.0]",
                                         "[-0.25, 0.0, 0.001, 0.0, 0.0]"), "k1 -0.25, p1 0.001"),
    ("ros2.yaml", ROS2_DUMP.replace("d:\n- 0.0\n- 0.0\n- 0.0", "d:\n- -0.25\n- 0.0\n- 0.001"),
     "k1 -0.25, p1 0.001"),
    ("ros1.yaml", ROS1_DUMP.replace("D: [0.0, 0.0, 0.0,", "D: [-0.25, 0.0, 0.001,"),
     "k1 -0.25, p1 0.001"),
    ("fisheye.yaml", ROS1_DUMP.replace('"plumb_bob"', '"equidistant"').replace(
        "D: [0.0, 0.0, 0.0, 0.0, 0.0]", "D: [-0.25, 0.0, 0.001, 0.0]"), "k1 -0.25, k3 0.001"),
]


@pytest.mark.parametrize("name, text, named", DISTORTED)
def test_opencv_and_ros_distortion_is_warned_about(tmp_path, name, text, named):
    """Distortion other than zero in an OpenCV FileStorage file (distortion_coefficients,
    dist_coeffs, D) or a ROS camera_info / CameraInfo dump (distortion_coefficients, d, D)
    was read without a word, where COLMAP's and nerfstudio's was warned about (a fresh
    user's review): the same warning, naming the file and the coefficients, and how to
    undistort the image first."""
    got, said = read(tmp_path, name, text)
    np.testing.assert_array_equal(got, K)
    said = [w for w in said if "lens distortion" in w]
    assert len(said) == 1, said
    assert said[0].startswith(f"`K`: {tmp_path / name} has lens distortion ({named}), which K "
                              "leaves out: the normal map must be of an undistorted image")
    assert ("cv2.fisheye.undistortImage" if "fisheye" in name else "cv2.undistort(") in said[0]


def test_a_stereo_calibration_s_own_distortion_is_the_one_read(tmp_path):
    """One camera of a stereo calibration (M1 with D1 and D2 beside it): D1 is its own."""
    import re

    left = re.sub(r"M2:.*?(?=D2:)", "", STEREO_YAML, flags=re.S)  # (M1, D1, D2, R)
    got, said = read(tmp_path, "left.yml", left.replace("data: [ 0., 0., 0., 0., 0. ]",
                                                        "data: [ 0.5, 0., 0., 0., 0. ]", 1))
    np.testing.assert_array_equal(got, K)
    assert len(said) == 1 and "lens distortion (k1 0.5)" in said[0]
    got, said = read(tmp_path, "right.yml", left.replace("data: [ 0., 0., 0., 0., 0. ]\nR",
                                                         "data: [ 0.5, 0., 0., 0., 0. ]\nR"))
    assert said == []


def test_opencv_yaml_reads_the_matrix_not_the_distortion_or_another_3x3(tmp_path):
    """The data list spans two lines; the 1x5 distortion beside it is no candidate; a
    rotation R beside the camera_matrix is not taken for it."""
    text = OPENCV_YAML + ("R: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                          "   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\n")
    got, _ = read(tmp_path, "calib.yml", text)
    np.testing.assert_array_equal(got, K)
    # (an unnamed single 3x3 is taken too; rows / cols other than 3x3 are not)
    got, _ = read(tmp_path, "mtx.yml", OPENCV_YAML.replace("camera_matrix", "mtx"))
    np.testing.assert_array_equal(got, K)
    with pytest.raises(ValueError, match=r"^`K`: .*bad\.yml holds no 3x3 matrix"):
        read(tmp_path, "bad.yml", OPENCV_YAML.replace("rows: 3", "rows: 4"))


def test_a_stereo_calibration_names_its_two_cameras(tmp_path):
    with pytest.raises(ValueError, match=r"^`K`: .*stereo\.yml holds several 3x3 matrices, "
                       r"M1, M2 \(a stereo calibration.*\): which is the image's camera\? "
                       r"Copy that one out"):
        read(tmp_path, "stereo.yml", STEREO_YAML)
    # (one camera's M1 alone is the usual key)
    got, _ = read(tmp_path, "left.yml", STEREO_YAML.split("M2:")[0])
    np.testing.assert_array_equal(got, K)


def test_ros_camera_info_with_another_projection_warns_of_rectified_images(tmp_path):
    got, said = read(tmp_path, "ost.yaml", ROS_CAMERA_INFO)
    np.testing.assert_array_equal(got, K)  # (camera_matrix: the raw image's)
    # (and its distortion, the other warning)
    assert len(said) == 2 and "ost.yaml" in said[0] and "rectified image" in said[0]
    assert "projection_matrix's left 3x3" in said[0] and "480 490 318 238" in said[0]
    assert "lens distortion (k1 0.1, k2 -0.2, p1 0.001)" in said[1]
    # (a P equal to the camera matrix within 1e-6 relative: silent)
    same = ROS_CAMERA_INFO.replace(
        "480.0, 0.0, 318.0, 0.0, 0.0, 490.0, 238.0",
        "500.0001, 0.0, 320.5, 0.0, 0.0, 510.0, 240.25").replace(
        "[0.1, -0.2, 0.001, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0, 0.0]")
    got, said = read(tmp_path, "same.yaml", same)
    assert said == []


def test_colmap_pinhole_shifts_the_principal_point_by_half_a_pixel(tmp_path):
    """COLMAP's upper-left pixel centre is (0.5, 0.5), facetlift's (0, 0)."""
    got, said = read(tmp_path, "cameras.txt", colmap("1 PINHOLE 640 480 500 510 321 240.75"))
    np.testing.assert_array_equal(got, K)
    assert said == []
    got, _ = read(tmp_path, "simple.txt", colmap("3 SIMPLE_PINHOLE 640 480 500 321 240.75"))
    np.testing.assert_array_equal(got, [[500, 0, 320.5], [0, 500, 240.25], [0, 0, 1]])
    # (the same camera twice, e.g. one per image: taken)
    got, _ = read(tmp_path, "twice.txt", colmap("1 PINHOLE 640 480 500 510 321 240.75",
                                                "2 PINHOLE 640 480 500 510 321 240.75"))
    np.testing.assert_array_equal(got, K)


def test_colmap_distortion_is_warned_about_and_zero_distortion_is_not(tmp_path):
    got, said = read(tmp_path, "cameras.txt",
                     colmap("1 SIMPLE_RADIAL 640 480 500 321 240.75 -0.0123"))
    np.testing.assert_array_equal(got, [[500, 0, 320.5], [0, 500, 240.25], [0, 0, 1]])
    assert len(said) == 1 and "lens distortion (k -0.0123)" in said[0]
    assert "image_undistorter" in said[0]
    got, said = read(tmp_path, "zero.txt",
                     colmap("1 OPENCV 640 480 500 510 321 240.75 0 0 0 0"))
    np.testing.assert_array_equal(got, K)
    assert said == []


def test_colmap_different_cameras_are_listed(tmp_path):
    with pytest.raises(ValueError, match=r"^`K`: .*cameras\.txt holds 2 different cameras, "
                       r"camera 1 \(PINHOLE, 640x480\), camera 2 \(SIMPLE_RADIAL, 1920x1080\): "
                       r"give the image's camera.*save its line as a cameras\.txt of its own"):
        read(tmp_path, "cameras.txt", colmap("1 PINHOLE 640 480 500 510 321 240.75",
                                             "2 SIMPLE_RADIAL 1920 1080 1500 960 540 0.01"))


def test_colmap_fisheye_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"^`K`: .*camera 1 is COLMAP's OPENCV_FISHEYE, a "
                       r"fish-eye.*needs a pinhole image.*image_undistorter.*PINHOLE"):
        read(tmp_path, "cameras.txt",
             colmap("1 OPENCV_FISHEYE 640 480 300 300 320 240 0.01 0.001 0 0"))
    with pytest.raises(ValueError, match=r"PINHOLE\) must have 4 parameters \(fx, fy, cx, cy"):
        read(tmp_path, "short.txt", colmap("1 PINHOLE 640 480 500 510 321"))


def colmap_bin(*cams):
    """A cameras.bin as COLMAP writes it: uint64 count, then per camera int32 id and model
    id, uint64 width and height, float64 parameters (little-endian)."""
    import struct

    out = struct.pack("<Q", len(cams))
    for cid, model_id, w, h, params in cams:
        out += struct.pack("<iiQQ", cid, model_id, w, h) + struct.pack(f"<{len(params)}d",
                                                                          *params)
    return out


def test_colmap_cameras_bin_reads_as_its_text_export(tmp_path):
    """COLMAP's mapper writes the binary model by default: the same camera as cameras.txt
    gives it, principal point shifted by half a pixel; its errors name the file."""
    (tmp_path / "cameras.bin").write_bytes(colmap_bin((1, 1, 640, 480, (500, 510, 321,
                                                                         240.75))))
    np.testing.assert_array_equal(io.read_K(tmp_path / "cameras.bin"), K)
    (tmp_path / "two.bin").write_bytes(colmap_bin((1, 1, 640, 480, (500, 510, 321, 240.75)),
                                                  (2, 2, 1920, 1080, (1500, 960, 540, 0.01))))
    with pytest.raises(ValueError, match=r"^`K`: .*two\.bin holds 2 different cameras, "
                       r"camera 1 \(PINHOLE, 640x480\), camera 2 \(SIMPLE_RADIAL, 1920x1080\)"):
        io.read_K(tmp_path / "two.bin")
    (tmp_path / "fish.bin").write_bytes(colmap_bin((1, 5, 640, 480, (300,) * 8)))
    with pytest.raises(ValueError, match=r"camera 1 is COLMAP's OPENCV_FISHEYE"):
        io.read_K(tmp_path / "fish.bin")
    whole = colmap_bin((1, 1, 640, 480, (500, 510, 321, 240.75)))
    for name, data, why in (("cut.bin", whole[:-8], r"parameters run past its end"),
                            ("long.bin", whole + b"\0" * 8, r"8 bytes after its 1 cameras"),
                            ("tiny.bin", b"\1\2", r"2 bytes"),
                            ("model.bin", colmap_bin((1, 42, 640, 480, ())), r"model id 42")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=rf"^`K`: \S+{name} is not a COLMAP cameras\.bin "
                           rf"\(.*{why}.*model_converter"):
            io.read_K(tmp_path / name)


def test_transforms_json_fl_x_alone_and_its_half_pixel(tmp_path):
    """nerfstudio copies COLMAP's cx, cy into transforms.json and casts rays through
    pixel + 0.5: its principal point is COLMAP's, shifted as COLMAP's."""
    data = {"camera_model": "OPENCV", "fl_x": 500.0, "cx": 321.0, "cy": 240.75, "w": 640,
            "h": 480, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
            "frames": [{"file_path": "images/frame_00001.png",
                        "transform_matrix": np.eye(4).tolist()}]}
    got, said = read(tmp_path, "transforms.json", json.dumps(data, indent=4))
    np.testing.assert_array_equal(got, [[500, 0, 320.5], [0, 500, 240.25], [0, 0, 1]])
    assert said == []
    got, said = read(tmp_path, "t2.json", json.dumps({**data, "fl_y": 510.0, "k1": 0.02}))
    np.testing.assert_array_equal(got, K)
    assert len(said) == 1 and "lens distortion (k1 0.02)" in said[0]
    blender = {"camera_angle_x": 0.6911112070083618, "frames": data["frames"]}
    with pytest.raises(ValueError, match=r"^`K`: .*camera_angle_x \(0\.69111\d* radians = "
                       r"39\.5978 degrees\).*give --fov with that angle in degrees .*in "
                       r"Python K=facetlift\.camera\.K_from_fov\(normals\.shape\[:2\], "
                       r"degrees\)"):
        read(tmp_path, "transforms_train.json", json.dumps(blender))


def test_transforms_json_with_its_camera_per_frame(tmp_path):
    """nerfstudio's datasets of several cameras give fl_x, cx, ... per frame: one camera for
    every frame is read (shifted as at the top); different ones are named, not guessed."""
    cam = {"fl_x": 500, "fl_y": 510, "cx": 321, "cy": 240.75, "w": 640, "h": 480}
    frames = [{"file_path": f"images/{i}.png", "transform_matrix": np.eye(4).tolist(), **cam}
              for i in range(3)]
    (tmp_path / "same.json").write_text(json.dumps({"camera_model": "OPENCV",
                                                    "frames": frames}))
    np.testing.assert_array_equal(io.read_K(tmp_path / "same.json"), K)
    frames[1] = {**frames[1], "fl_x": 600}
    (tmp_path / "two.json").write_text(json.dumps({"frames": frames}))
    with pytest.raises(ValueError, match=r"^`K`: \S+two\.json gives its frames 2 different "
                       r"cameras .*3 frames.*minus 0\.5"):
        io.read_K(tmp_path / "two.json")


def test_integrate_with_colmap_cameras_txt_matches_the_fx_fy_cx_cy_file(tmp_path, capsys):
    """The command line: --K cameras.txt gives the depth of the equivalent text file (COLMAP's
    cx, cy minus 0.5), not that of COLMAP's numbers taken as given; a reader's warning is
    shown as the others are."""
    from test_cli import write_input

    npath, mpath, _ = write_input(tmp_path)
    (tmp_path / "cameras.txt").write_text(colmap("1 PINHOLE 26 20 40 42 13.5 10.5"))
    (tmp_path / "K.txt").write_text("fx fy cx cy\n40 42 13 10\n")
    (tmp_path / "asis.txt").write_text("fx fy cx cy\n40 42 13.5 10.5\n")
    depth = {}
    for name in ("cameras.txt", "K.txt", "asis.txt"):
        code = main(["integrate", str(npath), "--mask", str(mpath), "--K", str(tmp_path / name),
                     "-s", "npy", "-o", str(tmp_path / name.split(".")[0])])
        _, err = capsys.readouterr()
        assert code == 0, err
        depth[name] = np.load(tmp_path / name.split(".")[0] / "depth.npy")
    np.testing.assert_array_equal(depth["cameras.txt"], depth["K.txt"])
    assert not np.allclose(depth["cameras.txt"], depth["asis.txt"], equal_nan=True)
    (tmp_path / "radial.txt").write_text(colmap("1 SIMPLE_RADIAL 26 20 40 13.5 10.5 0.05"))
    code = main(["integrate", str(npath), "--mask", str(mpath), "--K",
                 str(tmp_path / "radial.txt"), "-s", "npy", "-o", str(tmp_path / "r")])
    _, err = capsys.readouterr()
    assert code == 0 and "facetlift: warning: --K: " in err and "lens distortion (k 0.05)" in err


@pytest.mark.parametrize("name", ["K.yml", "K.yaml"])
def test_plain_rows_in_a_yaml_named_file_are_still_read_as_text(tmp_path, name):
    """A .yml / .yaml name alone does not make a file YAML: three rows of numbers (no key)
    parsed before the calibration readers and must still."""
    got, said = read(tmp_path, name, "500 0 320.5\n0 510 240.25\n0 0 1\n")
    np.testing.assert_array_equal(got, K)
    got, _ = read(tmp_path, "four" + name[1:], "fx fy cx cy\n500 510 320.5 240.25\n")
    np.testing.assert_array_equal(got, K)


def test_instant_ngp_fisheye_flag_is_refused(tmp_path):
    """instant-ngp's colmap2nerf.py marks a fish-eye camera by "is_fisheye": true beside
    fl_x (no camera_model): refused as nerfstudio's fish-eye camera_model is."""
    data = {"camera_angle_x": 1.1, "fl_x": 500.0, "fl_y": 510.0, "k1": 0.0, "k2": 0.0,
            "p1": 0.0, "p2": 0.0, "is_fisheye": False, "cx": 321.0, "cy": 240.75, "w": 640.0,
            "h": 480.0, "aabb_scale": 32, "frames": []}
    got, said = read(tmp_path, "transforms.json", json.dumps(data))
    np.testing.assert_array_equal(got, K)
    with pytest.raises(ValueError, match=r"^`K`: .*fish\.json: is_fisheye is true: a normal "
                       r"map needs a pinhole image"):
        read(tmp_path, "fish.json", json.dumps({**data, "is_fisheye": True}))


def test_calibration_files_state_their_image_size_and_read_K_returns_K_alone(tmp_path):
    """read_K_stated gives the image size (H, W) a calibration file states beside K (what a
    normal map of another size is checked against); read_K still returns the matrix alone."""
    from facetlift.io.dataset import read_K_stated

    cases = {"calib.yml": OPENCV_YAML, "calib.xml": OPENCV_XML, "ost.yaml": ROS_CAMERA_INFO,
             "info.yaml": ROS2_DUMP, "info1.yaml": ROS1_DUMP,
             "cameras.txt": colmap("1 PINHOLE 640 480 500 510 321 240.75"),
             "transforms.json": json.dumps({"fl_x": 500, "fl_y": 510, "cx": 321, "cy": 240.75,
                                            "w": 640, "h": 480})}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            K_, size = read_K_stated(tmp_path / name)
            plain = io.read_K(tmp_path / name)
        np.testing.assert_array_equal(K_, K)
        assert size == (480, 640), name
        assert isinstance(plain, np.ndarray) and plain.shape == (3, 3)
    (tmp_path / "cameras.bin").write_bytes(colmap_bin((1, 1, 640, 480, (500, 510, 321,
                                                                         240.75))))
    assert read_K_stated(tmp_path / "cameras.bin")[1] == (480, 640)
    # (none stated: a text K, a ROS dump's 0 x 0, COLMAP's same camera at two sizes)
    (tmp_path / "K.txt").write_text("500 510 320.5 240.25\n")
    (tmp_path / "zero.yaml").write_text(ROS2_DUMP.replace("height: 480", "height: 0"))
    (tmp_path / "two.txt").write_text(colmap("1 PINHOLE 640 480 500 510 321 240.75",
                                             "2 PINHOLE 1280 960 500 510 321 240.75"))
    for name in ("K.txt", "zero.yaml", "two.txt"):
        assert read_K_stated(tmp_path / name)[1] is None, name


def test_resize_ratio_names_simple_fractions_on_both_axes():
    from fractions import Fraction

    from facetlift.camera import resize_ratio

    assert resize_ratio((1024, 1224), (512, 612)) == Fraction(1, 2)
    assert resize_ratio((1025, 1225), (512, 612)) == Fraction(1, 2)  # (a resize rounds)
    assert resize_ratio((1080, 1920), (720, 1280)) == Fraction(2, 3)
    assert resize_ratio((512, 612), (1024, 1224)) == 2
    # (another ratio on each axis, a crop, the same size: none)
    for stated, shape in (((480, 640), (480, 600)), ((1080, 1920), (540, 540)),
                          ((480, 640), (480, 640)), ((480, 640), (640, 480))):
        assert resize_ratio(stated, shape) is None


def test_a_calibration_of_another_image_size_is_refused(tmp_path, capsys):
    """A fresh user's review: a ROS camera_info of a 1224 x 1024 camera used on a 612 x 512
    normal map was caught only by chance. Where the K file states an image size other than
    the map's, --K is refused naming both sizes; where the map is that image resized by a
    simple fraction, the message says so and gives K scaled for it. integrate, info,
    evaluate and a dataset folder's camera file alike."""
    from test_cli import write_input

    npath, mpath, _ = write_input(tmp_path)  # (20 x 26)
    ros = ROS_CAMERA_INFO.replace("[0.1, -0.2, 0.001, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0, 0.0]")
    ros = ros.split("projection_matrix")[0]
    (tmp_path / "big.yaml").write_text(ros.replace("image_width: 640", "image_width: 52")
                                       .replace("image_height: 480", "image_height: 40")
                                       .replace("500.0, 0.0, 320.5, 0.0, 510.0, 240.25",
                                                "80.0, 0.0, 25.5, 0.0, 84.0, 19.5"))
    (tmp_path / "crop.yaml").write_text(ros.replace("image_width: 640", "image_width: 30")
                                        .replace("image_height: 480", "image_height: 20"))
    (tmp_path / "same.yaml").write_text(ros.replace("image_width: 640", "image_width: 26")
                                        .replace("image_height: 480", "image_height: 20")
                                        .replace("500.0, 0.0, 320.5, 0.0, 510.0, 240.25",
                                                 "40.0, 0.0, 12.5, 0.0, 42.0, 9.5"))
    base = ["integrate", str(npath), "--mask", str(mpath), "-s", "npy"]
    assert main([*base, "--K", str(tmp_path / "big.yaml"), "-o", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err
    assert (f"--K: {tmp_path / 'big.yaml'} is the calibration of a 52 x 40 image (W x H) but "
            "the normal map is 26 x 20: it looks like that image downsampled 2x") in err
    # (fx, fy halved; cx, cy as pixel centres: (25.5 + 0.5) / 2 - 0.5, (19.5 + 0.5) / 2 - 0.5)
    assert "for a resize (cv2.resize, PIL) fx fy cx cy = 40 42 12.5 9.5 " in err
    assert "K[:2] / 2 instead (facetlift.Pinhole(K).subsampled(2))" in err
    assert not (tmp_path / "a").exists()
    assert main([*base, "--K", str(tmp_path / "crop.yaml"), "-o", str(tmp_path / "b")]) == 1
    err = capsys.readouterr().err
    assert "30 x 20 image (W x H) but the normal map is 26 x 20: K is for another image" in err
    assert "a K already adjusted for it has no image size to compare" in err  # (a crop)
    # the image turned on its side (a review: told only 'another image')
    (tmp_path / "side.yaml").write_text(ros.replace("image_width: 640", "image_width: 20")
                                        .replace("image_height: 480", "image_height: 26"))
    assert main([*base, "--K", str(tmp_path / "side.yaml"), "-o", str(tmp_path / "e")]) == 1
    assert "the image is turned on its side (portrait against landscape)" in \
        capsys.readouterr().err
    assert main([*base, "--K", str(tmp_path / "same.yaml"), "-o", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    assert main(["info", str(npath), "--K", str(tmp_path / "big.yaml")]) == 1
    assert "downsampled 2x" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "c" / "depth.npy"), "--gt",
                 str(tmp_path / "c" / "depth.npy"), "--K", str(tmp_path / "big.yaml")]) == 1
    err = capsys.readouterr().err
    assert "downsampled 2x" in err and "but the result is 26 x 20" in err  # (not a normal map)
    # a dataset folder's K.txt that is a camera_info (found by its camera_matrix line)
    folder = tmp_path / "ds"
    folder.mkdir()
    write_input(folder, name="normal_map.png")
    (folder / "K.txt").write_text((tmp_path / "big.yaml").read_text())
    assert main(["integrate", str(folder), "-s", "npy", "-o", str(tmp_path / "d")]) == 1
    assert (f"NORMALS: {folder / 'K.txt'} is the calibration of a 52 x 40 image"
            in capsys.readouterr().err)


def bouguet_mat(path, nx, ny, fc=(40.0, 42.0), cc=(12.5, 9.5), kc=(0.0,) * 5):
    """A Calib_Results.mat as the Camera Calibration Toolbox saves it: KK with fc, cc,
    alpha_c, kc (5 x 1; left out where None) beside it, the calibrated image's size nx
    (width) and ny (height) as 1x1 matrices (left out where None), and a view's rotation
    (another 3x3)."""
    from scipy import io as sio

    KK = np.array([[fc[0], 0.0, cc[0]], [0.0, fc[1], cc[1]], [0.0, 0.0, 1.0]])
    data = {"KK": KK, "fc": np.array([[fc[0]], [fc[1]]]), "cc": np.array([[cc[0]], [cc[1]]]),
            "alpha_c": 0.0, "Rc_1": np.eye(3)}
    data.update({k: v for k, v in (("nx", nx), ("ny", ny)) if v is not None})
    if kc is not None:
        data["kc"] = np.reshape(np.asarray(kc, float), (-1, 1))
    sio.savemat(path, data)
    return KK


def test_a_calibration_toolbox_mat_states_its_image_size(tmp_path, capsys):
    """A Bouguet Calib_Results.mat states its image's size (nx, ny), which was not read: a
    calibration of another image size passed, as no other calibration file does. Now read
    (read_K_stated), and checked as the other files' sizes are: --K, info, evaluate, a
    dataset folder's Calib_Results.mat; without nx, ny (or not two whole numbers) no size, as
    before."""
    from test_cli import write_input

    from facetlift.io.dataset import read_K_stated

    npath, mpath, _ = write_input(tmp_path)  # (20 x 26)
    same = bouguet_mat(tmp_path / "same.mat", 26, 20)
    bouguet_mat(tmp_path / "big.mat", 52, 40, fc=(80.0, 84.0), cc=(25.5, 19.5))
    bouguet_mat(tmp_path / "none.mat", None, None)
    bouguet_mat(tmp_path / "odd.mat", 26.5, 20)
    bouguet_mat(tmp_path / "two.mat", np.array([26, 26]), 20)
    K_, size = read_K_stated(tmp_path / "same.mat")
    np.testing.assert_array_equal(K_, same)
    assert size == (20, 26) and read_K_stated(tmp_path / "big.mat")[1] == (40, 52)
    for name in ("none.mat", "odd.mat", "two.mat"):
        assert read_K_stated(tmp_path / name)[1] is None, name
    base = ["integrate", str(npath), "--mask", str(mpath), "-s", "npy"]
    assert main([*base, "--K", str(tmp_path / "big.mat"), "-o", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err
    assert (f"--K: {tmp_path / 'big.mat'} is the calibration of a 52 x 40 image (W x H) but "
            "the normal map is 26 x 20: it looks like that image downsampled 2x") in err
    assert "fx fy cx cy = 40 42 12.5 9.5 " in err and not (tmp_path / "a").exists()
    for name in ("same.mat", "none.mat"):
        assert main([*base, "--K", str(tmp_path / name), "-o", str(tmp_path / name[:-4])]) == 0
    capsys.readouterr()
    assert main(["info", str(npath), "--K", str(tmp_path / "big.mat")]) == 1
    assert "downsampled 2x" in capsys.readouterr().err
    depth = str(tmp_path / "same" / "depth.npy")
    assert main(["evaluate", depth, "--gt", depth, "--K", str(tmp_path / "big.mat")]) == 1
    assert "but the result is 26 x 20" in capsys.readouterr().err
    # a dataset folder's Calib_Results.mat
    folder = tmp_path / "ds"
    folder.mkdir()
    write_input(folder, name="normal_map.png")
    (tmp_path / "big.mat").rename(folder / "Calib_Results.mat")
    assert main(["integrate", str(folder), "-s", "npy", "-o", str(tmp_path / "d")]) == 1
    assert (f"{folder / 'Calib_Results.mat'} is the calibration of a 52 x 40 image"
            in capsys.readouterr().err)


def test_a_calibration_toolbox_mats_lens_distortion_is_warned_about(tmp_path, capsys):
    """A Bouguet Calib_Results.mat's kc (its lens distortion, k1 k2 p1 p2 k3) was read
    without a word, where OpenCV's, ROS's, COLMAP's and nerfstudio's distortion is warned
    about: KK is a pinhole's, and facetlift models none. Now one warning names the file, the
    coefficients beyond 1e-6 and the whole kc, and says to undistort the images first; a kc
    of zeros (or below 1e-6), or none, is no word. --K and a dataset folder alike."""
    from test_cli import write_input

    npath, mpath, _ = write_input(tmp_path)  # (20 x 26)
    for name, kc in (("zero.mat", (0.0,) * 5), ("tiny.mat", (1e-7, -1e-7, 0, 0, 5e-7)),
                     ("none.mat", None)):
        bouguet_mat(tmp_path / name, 26, 20, kc=kc)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            io.read_K(tmp_path / name)
    KK = bouguet_mat(tmp_path / "dist.mat", 26, 20, kc=(-0.21, 0.13, 0.0, 2e-7, 0.0))
    with pytest.warns(UserWarning) as rec:
        got = io.read_K(tmp_path / "dist.mat")
    np.testing.assert_array_equal(got, KK)
    said = [str(w.message) for w in rec]
    assert len(said) == 1, said
    assert said[0].startswith(f"`K`: {tmp_path / 'dist.mat'} has lens distortion (k1 -0.21, "
                              "k2 0.13), which K leaves out: the normal map must be of an "
                              "undistorted image; its kc = [-0.21, 0.13, 0, 2e-07, 0] ")
    assert "ideal pinhole" in said[0] and "undistort the images first" in said[0]
    base = ["integrate", str(npath), "--mask", str(mpath), "-s", "npy"]
    assert main([*base, "--K", str(tmp_path / "dist.mat"), "-o", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert err.count("lens distortion") == 1 and "kc = [-0.21, 0.13, 0, 2e-07, 0]" in err
    assert main([*base, "--K", str(tmp_path / "zero.mat"), "-o", str(tmp_path / "b")]) == 0
    assert "lens distortion" not in capsys.readouterr().err
    folder = tmp_path / "ds"
    folder.mkdir()
    write_input(folder, name="normal_map.png")
    (tmp_path / "dist.mat").rename(folder / "Calib_Results.mat")
    with pytest.warns(UserWarning, match=r"Calib_Results.mat has lens distortion \(k1 -0.21"):
        ds = io.read_dataset(folder)
    np.testing.assert_array_equal(ds["K"], KK)


def test_a_2x2_matrix_is_refused_as_such_and_four_numbers_in_a_column_are_fx_fy_cx_cy(tmp_path):
    """Four numbers in two rows were read as fx fy cx cy, and the error showed a 3x3 matrix
    the user never wrote (a fresh user's check)."""
    p = tmp_path / "K.txt"
    np.savetxt(p, 3000 * np.eye(2))
    with pytest.raises(ValueError, match=r"holds a 2x2 matrix; expected a 3x3 matrix"):
        io.read_K(p)
    p.write_text("3000\n3100\n300\n250\n")
    np.testing.assert_array_equal(io.read_K(p), [[3000, 0, 300], [0, 3100, 250], [0, 0, 1]])


def test_json_K_under_a_key_or_nested_in_an_object(tmp_path):
    """A review: a JSON K file was read only as a list or as an object with fx, fy, cx, cy at
    its top. The matrix under K, intrinsics, camera_matrix or intrinsic_matrix (3x3, or nine
    numbers row by row), and fx ... cy or such a matrix in one object inside it are read
    too; two of them, or none, are named."""
    rows = K.tolist()
    for i, data in enumerate([
            {"K": rows}, {"intrinsics": K.ravel().tolist()}, {"Camera_Matrix": rows},
            {"intrinsic_matrix": rows, "width": 640}, {"camera": {"fx": 500, "fy": 510,
                                                                 "cx": 320.5, "cy": 240.25}},
            {"cam0": {"K": rows}, "baseline": 0.1}]):
        got, said = read(tmp_path, f"k{i}.json", json.dumps(data))
        np.testing.assert_array_equal(got, K)
        assert said == [], (data, said)
    for data, match in [
            ({"K": rows, "intrinsics": rows}, r"holding both K and intrinsics: which is K"),
            ({"left": {"K": rows}, "right": {"K": rows}},
             r"several cameras \(left, right\): which is the image's"),
            ({"focal": 500}, r"a JSON object needs fx, fy, cx, cy; .* missing \(or the matrix "
                             r"under K, intrinsics, camera_matrix, intrinsic_matrix")]:
        (tmp_path / "bad.json").write_text(json.dumps(data))
        with pytest.raises(ValueError, match=match):
            io.read_K(tmp_path / "bad.json")


def test_a_4x4_intrinsics_file_gives_its_top_left_3x3(tmp_path):
    """A review: ScanNet's intrinsic_color.txt (K in the top-left of a 4x4, last row and
    column 0 0 0 1) was refused as 16 numbers. Taken where the rest is the identity's; a 4x4
    that is not (a pose) is refused, naming its last row and column."""
    K4 = np.eye(4)
    K4[:3, :3] = K
    np.savetxt(tmp_path / "intrinsic_color.txt", K4, fmt="%f")
    np.testing.assert_array_equal(io.read_K(tmp_path / "intrinsic_color.txt"), K)
    np.save(tmp_path / "K4.npy", K4)
    np.testing.assert_array_equal(io.read_K(tmp_path / "K4.npy"), K)
    pose = K4.copy()
    pose[:3, 3] = [0.1, 0.2, 1.5]
    np.savetxt(tmp_path / "pose.txt", pose)
    with pytest.raises(ValueError, match=r"pose\.txt holds a 4x4 matrix whose last row and "
                       r"column are not 0 0 0 1 .*column \[0\.1, 0\.2, 1\.5\]"):
        io.read_K(tmp_path / "pose.txt")


def _other_camera_file(path, name):
    """Write a camera file named `name` (:data:`OTHER_CAMERA_FILES`) as its tool writes it,
    fx 500 in each."""
    K4 = np.eye(4)
    K4[:3, :3] = K
    writers = {
        "cameras.txt": lambda p: p.write_text(colmap("1 PINHOLE 640 480 500 510 321 240.75")),
        "cameras.bin": lambda p: p.write_bytes(colmap_bin((1, 1, 640, 480,
                                                           (500, 510, 321, 240.75)))),
        "calib.yml": lambda p: p.write_text(OPENCV_YAML),
        "calib.yaml": lambda p: p.write_text(OPENCV_YAML),
        "calib.xml": lambda p: p.write_text(OPENCV_XML),
        "camera_info.yaml": lambda p: p.write_text(ROS_CAMERA_INFO),
        "camera_info.yml": lambda p: p.write_text(ROS_CAMERA_INFO),
        "transforms.json": lambda p: p.write_text(json.dumps(
            {"fl_x": 500, "fl_y": 510, "cx": 321, "cy": 240.75, "w": 640, "h": 480})),
        "K.json": lambda p: p.write_text(json.dumps({"K": K.tolist()})),
        "K.npy": lambda p: np.save(p, K),
        "K.yml": lambda p: p.write_text("500 0 320.5\n0 510 240.25\n0 0 1\n"),
        "K.yaml": lambda p: p.write_text(OPENCV_YAML),
        "K.xml": lambda p: p.write_text(OPENCV_XML),
        "intrinsics.txt": lambda p: p.write_text("500 510 320.5 240.25\n"),
        "intrinsics.json": lambda p: p.write_text(json.dumps(
            {"fx": 500, "fy": 510, "cx": 320.5, "cy": 240.25})),
        "intrinsics.npy": lambda p: np.save(p, K.ravel()),
        "intrinsic_color.txt": lambda p: np.savetxt(p, K4),
    }
    writers[name](path / name)


def test_every_camera_file_named_as_unread_is_one_that_K_reads(tmp_path):
    """The warning on other tools' camera files beside a map (OTHER_CAMERA_FILES) tells the
    user to give one with --K: each name it looks for is one read_K reads."""
    from facetlift.io.dataset import OTHER_CAMERA_FILES

    for name in OTHER_CAMERA_FILES:
        _other_camera_file(tmp_path, name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the files' distortion)
            got = io.read_K(tmp_path / name)
        assert got[0, 0] == 500 and got[1, 1] == 510, name


def test_a_camera_file_that_is_not_read_by_itself_is_named(tmp_path, capsys):
    """A review: a dataset folder (or a map file) with COLMAP's cameras.txt, OpenCV's
    calib.yml, a transforms.json, K.npy ... beside it ran orthographically without a word:
    only a folder's K.txt and Calib_Results.mat are read by themselves. Such files are named
    with --K (not read: which camera, and whether it is this image's, is the user's to say)
    by integrate and info (its camera line too), and by a batch once per folder, whose
    K.npy is no map; none where a camera is given or --orthographic says so."""
    from test_cli import write_input

    npath, mpath, _ = write_input(tmp_path)  # (20 x 26)
    ds = tmp_path / "ds"
    ds.mkdir()
    np.save(ds / "normal_map.npy", np.load(npath) if npath.suffix == ".npy" else
            io.read_normals(npath)[0])
    _other_camera_file(ds, "cameras.txt")
    code = main(["integrate", str(ds), "-s", "npy", "-o", str(tmp_path / "o1")])
    _, err = capsys.readouterr()
    assert code == 0 and (f"warning: the dataset folder {ds} holds cameras.txt: a camera "
                          "file that is not read by itself") in err, err
    assert f"integrated orthographically; give --K {ds / 'cameras.txt'}" in err
    code = main(["info", str(ds)])
    out, err = capsys.readouterr()
    assert code == 0 and (f"camera: orthographic (cameras.txt beside it not read: --K "
                          f"{ds / 'cameras.txt'} to use it)") in out, out
    for flags in (["--orthographic"], ["--K", "26 26 12.5 9.5"]):
        code = main(["integrate", str(ds), *flags, "-s", "npy", "-o", str(tmp_path / "o2")])
        _, err = capsys.readouterr()
        assert code == 0 and "cameras.txt" not in err, (flags, err)
    # beside a map file
    _other_camera_file(tmp_path, "K.npy")
    _other_camera_file(tmp_path, "calib.yml")
    code = main(["integrate", str(npath), "--mask", str(mpath), "-s", "npy", "-o",
                 str(tmp_path / "o3")])
    _, err = capsys.readouterr()
    assert code == 0 and (f"{npath.name} has calib.yml and K.npy beside it: camera files that "
                          "are not read by themselves") in err, err
    # a batch: once for the folder, and K.npy is no map
    maps = tmp_path / "maps"
    maps.mkdir()
    for name in ("a.npy", "b.npy"):
        np.save(maps / name, np.load(ds / "normal_map.npy"))
    _other_camera_file(maps, "K.npy")
    code = main(["batch", str(maps), "-s", "npy", "-o", str(tmp_path / "bo")])
    out, err = capsys.readouterr()
    assert code == 0 and err.count("K.npy") == 2 and "2 of 2 succeeded" in out, (out, err)
    assert f"batch: {maps} holds K.npy beside its normal maps, a camera file that" in err


def test_K_that_is_neither_a_file_nor_numbers_says_what_K_takes(tmp_path, capsys):
    """A review: --K 420 and --K "fx=420 ..." were told "File '420' does not exist" alone."""
    from test_cli import write_input

    npath, _, _ = write_input(tmp_path)
    for typed in ("420", "fx=420 fy=420 cx=12 cy=9"):
        code, err = main(["integrate", str(npath), "--K", typed]), capsys.readouterr()[1]
        assert code != 0 and f"File {typed!r} does not exist, and it is no K typed inline: " \
            "--K takes a K file" in err, err
        assert "or four numbers fx fy cx cy" in err and "--fov DEG" in err


def test_json_K_as_open3d_and_opencv_filestorage_write_it(tmp_path):
    """The diff review: Open3D's camera JSON stores ``intrinsic_matrix`` column-major and was
    refused as transposed (with MATLAB's advice); OpenCV FileStorage's JSON holds the matrix
    as {"type_id": "opencv-matrix", "data": [...]}; {"K": {"fx": ...}} nests the four; K and
    fx ... cy that differ are refused, as two matrices are."""
    import json

    from facetlift.io import read_K

    want = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
    cases = {
        "open3d": {"width": 640, "height": 480,
                   "intrinsic_matrix": [500, 0, 0, 0, 500, 0, 320, 240, 1]},
        "filestorage": {"camera_matrix": {"type_id": "opencv-matrix", "rows": 3, "cols": 3,
                                          "dt": "d", "data": [500, 0, 320, 0, 500, 240, 0, 0,
                                                              1]}},
        "nested": {"K": {"fx": 500, "fy": 500, "cx": 320, "cy": 240}},
        "agreeing": {"K": want, "fx": 500, "fy": 500, "cx": 320, "cy": 240},
    }
    for name, obj in cases.items():
        f = tmp_path / f"{name}.json"
        f.write_text(json.dumps(obj))
        assert read_K(f).tolist() == want, name
    f = tmp_path / "differ.json"
    f.write_text(json.dumps({"K": want, "fx": 510, "fy": 500, "cx": 320, "cy": 240}))
    with pytest.raises(ValueError, match="both K and fx, fy, cx, cy, which differ"):
        read_K(f)
