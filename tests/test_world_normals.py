"""Normals given in world space: integrate(normal_rotation=), its checks and hints, and the
command line's --world-to-camera / --camera-to-world (and a dataset folder's files)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import facetlift
from facetlift import frames, io, synthetic
from facetlift.camera import K_from_fov
from facetlift.cli import main


def random_rotation(seed: int) -> np.ndarray:
    """A proper rotation drawn uniformly (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def sphere():
    gt = synthetic.analytic("sphere", 48)
    return gt.normals, gt.mask


def to_world(cam: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Camera-frame normals (in whatever axes R maps world to) as world ones: R^T n."""
    return cam @ R  # (row vectors: (R^T n)^T = n^T R)


def messages(record) -> str:
    return "\n".join(str(w.message) for w in record)


@pytest.mark.parametrize("frame", ["opengl", "opencv"])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name, camera", [("sphere", False), ("face", True)])
def test_world_normals_rotated_integrate_as_the_camera_frame_ones(name, camera, frame, seed):
    """World normals with their world-to-camera rotation give the camera-frame result: in the
    default frame, and in OpenCV's (the camera frame's normals in OpenCV axes, then rotated by
    a rotation from world to that frame, as COLMAP's R is). (With a camera, a surface without
    normals near edge-on: the sphere's rim seen obliquely turns rounding into 1e-8.)"""
    gt = synthetic.analytic(name, 48)
    n, mask = gt.normals, gt.mask
    K = K_from_fov(mask.shape, 50.0) if camera else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = facetlift.integrate(n, mask, K=K)
        R = random_rotation(seed)
        world = to_world(frames.from_facetlift(n, frame), R)
        assert not np.allclose(world[mask], frames.from_facetlift(n, frame)[mask])
        got = facetlift.integrate(world, mask, K=K, normal_frame=frame, normal_rotation=R)
    np.testing.assert_allclose(got.depth[mask], ref.depth[mask], rtol=0, atol=1e-10)
    assert got.info["input"] == ref.info["input"]


def test_a_pose_gives_its_rotation_and_nans_stay_missing(sphere):
    """A 3x4 or 4x4 pose (with a translation) is taken for its upper-left 3x3; NaN normals
    inside the mask stay missing samples, counted as the camera-frame ones are."""
    n, mask = sphere
    n = n.copy()
    n[20:23, 20:23] = np.nan
    R = random_rotation(5)
    world = to_world(n, R)
    assert np.isnan(world[20:23, 20:23]).all()
    ref = facetlift.integrate(n, mask)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, [1.0, -2.0, 30.0]
    for matrix in (pose, pose[:3], R.tolist()):
        got = facetlift.integrate(world, mask, normal_rotation=matrix)
        np.testing.assert_allclose(got.depth[mask], ref.depth[mask], rtol=0, atol=1e-10)
        assert got.info["input"]["missing"] == ref.info["input"]["missing"] == 9


@pytest.mark.parametrize("matrix, match", [
    (np.eye(2), r"`normal_rotation` must be a 3x3 rotation matrix.*got shape \(2, 2\)"),
    (np.ones(9), r"`normal_rotation` must be a 3x3 rotation matrix.*got shape \(9,\)"),
    (np.eye(5), r"got shape \(5, 5\)"),
    ([["a", "b", "c"]] * 3, "`normal_rotation` must be a 3x3 rotation matrix .* of numbers"),
    (np.diag([1.0, np.nan, 1.0]), "`normal_rotation` has non-finite entries"),
    (np.diag([1.0, 1.0, np.inf, 1.0]), "`normal_rotation` has non-finite entries"),
    (2.0 * np.eye(3), r"`normal_rotation` is not a rotation: R R\^T differs from the "
     r"identity by up to 3 .* singular values are 2 to 2, .* scaled camera"),
    (np.array([[1.0, 0.01, 0], [0, 1, 0], [0, 0, 1]]), "is not a rotation"),
    (np.diag([1.0, -1.0, 1.0]), r"`normal_rotation` is a reflection \(determinant -1\).*"
     "normal_frame, --normal-frame"),
])
def test_bad_rotations_are_refused_naming_the_argument(sphere, matrix, match):
    n, mask = sphere
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(n, mask, normal_rotation=matrix)


def test_a_rotation_within_the_tolerance_is_taken():
    """A rotation written to 5 decimals (a text file's) is a rotation."""
    R = np.round(random_rotation(3), 5)
    assert np.allclose(frames.check_rotation(R), R)


def test_the_rotation_is_checked_before_the_normals(sphere):
    """Its error comes alone, not after the input's own (a map that faces away)."""
    n, mask = sphere
    with pytest.raises(ValueError, match="`normal_rotation`"):
        facetlift.integrate(-n, mask, normal_rotation=np.zeros((3, 3)))


def test_integrate_gradients_refuses_a_rotation():
    p = q = np.zeros((8, 8))
    with pytest.raises(ValueError, match="`normal_rotation` does not apply to a gradient "
                                         "field.*no world frame"):
        facetlift.integrate_gradients(p, q, normal_rotation=np.eye(3))


def run_integrate(normals, mask, **kw):
    """(error message or None, the warnings' text) of an integrate."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        try:
            facetlift.integrate(normals, mask, **kw)
        except ValueError as e:
            return str(e), messages(record)
    return None, messages(record)


# seeds of random_rotation whose world map (of the sphere) is refused as facing away (more
# than half) and warned about (5-50 % facing away), as found below
@pytest.mark.parametrize("seed", [3, 7])
def test_the_hint_names_the_rotation_for_world_normals_and_not_once_given(sphere, seed):
    n, mask = sphere
    R = random_rotation(seed)
    world = to_world(n, R)
    away = frames.facing_away(world[mask])
    error, said = run_integrate(world, mask)
    text = error or said
    assert (error is not None) == (away > 0.5)  # (the two paths: a refusal, a warning)
    assert "--world-to-camera FILE or --camera-to-world FILE (normal_rotation=R" in text
    error, said = run_integrate(world, mask, normal_rotation=R)
    assert error is None and "world" not in said and "rotation" not in said


def test_the_two_paths_are_both_tried(sphere):
    """The seeds above give one refusal and one warning (the test's own premise)."""
    n, mask = sphere
    shares = [frames.facing_away(to_world(n, random_rotation(s))[mask]) for s in (3, 7)]
    assert shares[0] > 0.5 and 0.05 < shares[1] < 0.5


def test_a_rotation_given_the_wrong_way_round_is_questioned(sphere):
    n, mask = sphere
    R = random_rotation(3)
    error, said = run_integrate(to_world(n, R), mask, normal_rotation=R.T)
    assert "right way round" in (error or said) and "Blender's matrix_world is camera to " \
        "world: --camera-to-world" in (error or said)


@pytest.mark.parametrize("stored", ["x,y,-z", "opencv"])
def test_no_world_hint_where_a_z_flip_explains_it(sphere, stored):
    """A camera-frame map read without its frame: told the frame, not about world space."""
    n, mask = sphere
    error, _ = run_integrate(frames.from_facetlift(n, stored), mask)
    assert error is not None and "face away" in error and "world" not in error
    error, said = run_integrate(n, mask)  # (and nothing on the right map)
    assert error is None and "world" not in said


# --------------------------------------------------------------------------------------------
# reading a rotation file: facetlift.io.read_rotation


def test_rotation_files_in_every_form(tmp_path):
    R = random_rotation(11)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R.T, [0.5, 1.0, -3.0]  # (camera to world)
    files = {
        "rows.txt": ("# world to camera\n" + "\n".join(", ".join(f"{v:.17g}" for v in row)
                                                      for row in R), False),
        "line.txt": (" ".join(f"{v:.17g}" for v in R.ravel()) + "  # row by row", False),
        "pose.txt": ("\n".join(" ".join(f"{v:.17g}" for v in row) for row in pose), True),
        "pose34.txt": ("\n".join(" ".join(f"{v:.17g}" for v in row) for row in pose[:3]),
                       True),
        "list.json": (json.dumps(R.tolist()), False),
        "blender.json": (json.dumps({"matrix_world": pose.tolist(), "name": "Camera"}), True),
        # (several matrices: the one that names a rotation, not the intrinsics)
        "colmap.json": (json.dumps({"K": np.eye(3).tolist(), "R": R.tolist(),
                                    "t": [1, 2, 3]}), False),
    }
    for name, (text, c2w) in files.items():
        (tmp_path / name).write_text(text)
        got = io.read_rotation(tmp_path / name, camera_to_world=c2w)
        np.testing.assert_allclose(got, R, atol=1e-12, err_msg=name)
    np.save(tmp_path / "r.npy", pose)
    np.testing.assert_allclose(io.read_rotation(tmp_path / "r.npy", camera_to_world=True), R,
                               atol=1e-12)


@pytest.mark.parametrize("text, c2w, match", [
    ("", False, r"`world_to_camera`: cannot read \S+ as a matrix \(the file is empty\)"),
    ("# nothing\n", False, "only comments"),
    ("1 0 0\n0 1 0", False, r"`world_to_camera` \S+bad.txt must be a 3x3 rotation .*shape "
     r"\(2, 3\)"),
    ("1 0 x\n0 1 0\n0 0 1", True, r"`camera_to_world`: cannot read \S+bad.txt as a matrix"),
    ("2 0 0\n0 2 0\n0 0 2", True, r"`camera_to_world` \S+bad.txt is not a rotation.*"
     r"singular values are 2 to 2"),
    ("-1 0 0\n0 1 0\n0 0 1", False, r"`world_to_camera` \S+bad.txt is a reflection"),
    ('{"A": [[1,0,0],[0,1,0],[0,0,1]], "B": [[1,0,0],[0,1,0],[0,0,1]]}', False,
     r'holds several, "A", "B": which one is the camera\'s rotation'),
    ('{"R": [[1,0,0],[0,1,0],[0,0,1]], "rotation": [[1,0,0],[0,1,0],[0,0,1]]}', False,
     r'holds several, "R", "rotation"'),
    ('{"focal": 35}', False, r'holds no 3x3, 3x4 or 4x4 matrix \(keys: "focal"\)'),
    ('{"matrix_world": [[1,0,0],[0,1,0],[0,0,1]]}', False, r'`world_to_camera`: \S+ holds '
     r'"matrix_world", which turns camera to world, .* give it with --camera-to-world'),
    ('{"w2c": [[1,0,0],[0,1,0],[0,0,1]]}', True, r'holds "w2c", which turns world to camera'
     r'.* give it with --world-to-camera'),
])
def test_bad_rotation_files_are_refused_naming_the_argument_and_file(tmp_path, text, c2w,
                                                                     match):
    (tmp_path / "bad.txt").write_text(text)
    with pytest.raises(ValueError, match=match):
        io.read_rotation(tmp_path / "bad.txt", camera_to_world=c2w)


# --------------------------------------------------------------------------------------------
# the command line


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def views(tmp_path, sphere):
    """A world-space map (world.npy) of the sphere, its camera-frame map (cam.npy) and the
    camera's pose (camera to world) as a 4x4 text file, as Blender gives it."""
    n, mask = sphere
    n = np.where(mask[..., None], n, np.nan)
    R = random_rotation(3)
    np.save(tmp_path / "cam.npy", n)
    np.save(tmp_path / "world.npy", to_world(n, R))
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R.T, [1.0, -2.0, 5.0]
    np.savetxt(tmp_path / "matrix_world.txt", pose, header="Blender camera.matrix_world")
    return tmp_path, R


def depth_of(folder):
    return np.load(folder / "depth.npy")


def test_cli_camera_to_world_text_and_world_to_camera_json(views, capsys):
    d, R = views
    assert run(capsys, "integrate", d / "cam.npy", "-o", d / "cam", "-s", "npy")[0] == 0
    code, out, err = run(capsys, "integrate", d / "world.npy", "--camera-to-world",
                         d / "matrix_world.txt", "-o", d / "w", "-s", "npy", "--json")
    assert code == 0, err
    np.testing.assert_allclose(depth_of(d / "w"), depth_of(d / "cam"), atol=1e-10)
    rec = json.loads(out)
    np.testing.assert_allclose(rec["normal_rotation"]["world_to_camera"], R, atol=1e-12)
    assert rec["normal_rotation"]["given_as"] == "camera_to_world"
    assert rec["normal_rotation"]["file"] == str(d / "matrix_world.txt")
    assert rec["normal_rotation"]["frame"] == "x,y,z" and rec["warnings"] == []
    # COLMAP: its world-to-camera R, to the OpenCV camera frame, in a JSON object
    cv = frames.axes_matrix("opencv").T @ R  # (world -> OpenCV camera)
    np.save(d / "colmap.npy", to_world(frames.from_facetlift(np.load(d / "cam.npy"), "opencv"),
                                       cv))
    (d / "image.json").write_text(json.dumps({"R": cv.tolist(), "t": [0.0, 1.0, 2.0],
                                              "K": np.eye(3).tolist()}))
    code, out, err = run(capsys, "integrate", d / "colmap.npy", "--normal-frame", "opencv",
                         "--world-to-camera", d / "image.json", "-o", d / "c", "-s", "npy")
    assert code == 0, err
    np.testing.assert_allclose(depth_of(d / "c"), depth_of(d / "cam"), atol=1e-10)
    assert "normals turned from world space" in out
    # without the rotation: refused, and told of it
    code, _, err = run(capsys, "integrate", d / "world.npy", "-o", d / "x", "-s", "npy")
    assert code == 1 and "--world-to-camera FILE or --camera-to-world FILE" in err


def test_cli_rotation_errors_name_the_flag_and_the_file(views, capsys):
    d, _ = views
    (d / "scaled.txt").write_text("2 0 0\n0 2 0\n0 0 2\n")
    (d / "two.json").write_text(json.dumps({"a": np.eye(3).tolist(), "b": np.eye(3).tolist()}))
    cases = [
        (["--camera-to-world", d / "matrix_world.txt", "--world-to-camera",
          d / "matrix_world.txt"], "--world-to-camera and --camera-to-world give the rotation "
         "twice"),
        (["--world-to-camera", d / "scaled.txt"], f"--world-to-camera {d / 'scaled.txt'} is "
         "not a rotation"),
        (["--camera-to-world", d / "two.json"], f'--camera-to-world: {d / "two.json"} must '
         'hold one matrix (a key such as "R", "rotation", "world_to_camera", '
         '"camera_to_world" or "matrix_world"); it holds several, "a", "b"'),
        (["--world-to-camera", d / "none.txt"], "'--world-to-camera': File"),
    ]
    for flags, said in cases:
        code, _, err = run(capsys, "integrate", d / "world.npy", *flags, "-o", d / "o")
        assert code == 1 and said in err and "Traceback" not in err, err
        assert not (d / "o").exists()  # (refused before anything is read or written)
    p = d / "p.npy"
    np.save(p, np.zeros((8, 8)))
    code, _, err = run(capsys, "integrate", "--gradients", p, p, "--world-to-camera",
                       d / "matrix_world.txt", "-o", d / "g")
    assert code == 1 and "--world-to-camera: a gradient field's slopes" in err


def test_a_dataset_folder_gives_its_rotation_and_a_flag_replaces_it(views, capsys):
    d, _ = views
    ds = d / "view"
    ds.mkdir()
    np.save(ds / "normal_map.npy", np.load(d / "world.npy"))
    (ds / "camera_to_world.txt").write_text((d / "matrix_world.txt").read_text())
    assert run(capsys, "integrate", d / "cam.npy", "-o", d / "cam", "-s", "npy")[0] == 0
    code, out, err = run(capsys, "integrate", ds, "-o", d / "o1", "-s", "npy")
    assert code == 0, err
    assert "(the folder's camera_to_world.txt)" in out
    np.testing.assert_allclose(depth_of(d / "o1"), depth_of(d / "cam"), atol=1e-10)
    code, out, _ = run(capsys, "info", ds)
    assert code == 0 and "likely as read (consistent)" in out
    assert "world space: the normals turned into the camera frame by the folder's " \
        "camera_to_world.txt (camera-to-world)" in out
    # a flag replaces the folder's file (here a broken one, then unread)
    (ds / "camera_to_world.txt").write_text("not numbers")
    code, _, err = run(capsys, "integrate", ds, "-o", d / "o2", "-s", "npy")
    assert code == 1 and "camera_to_world.txt as a matrix" in err
    code, _, err = run(capsys, "integrate", ds, "--camera-to-world", d / "matrix_world.txt",
                       "-o", d / "o2", "-s", "npy")
    assert code == 0, err
    np.testing.assert_allclose(depth_of(d / "o2"), depth_of(d / "cam"), atol=1e-10)
    # two of them: which one was meant?
    (ds / "world_to_camera.txt").write_text("1 0 0\n0 1 0\n0 0 1")
    code, _, err = run(capsys, "integrate", ds, "-o", d / "o3", "-s", "npy")
    assert code == 1 and "holds world_to_camera.txt and camera_to_world.txt" in err
    # the folder's map given by its path: the folder's rotation is named as unread
    (ds / "world_to_camera.txt").unlink()
    (ds / "camera_to_world.txt").write_text((d / "matrix_world.txt").read_text())
    code, _, err = run(capsys, "integrate", ds / "normal_map.npy", "-o", d / "o4", "-s", "npy")
    assert "camera_to_world.txt (its rotation" in err and "--camera-to-world" in err


def test_info_takes_the_flags(views, capsys):
    d, _ = views
    code, out, err = run(capsys, "info", d / "world.npy", "--camera-to-world",
                         d / "matrix_world.txt", "--json")
    rec = json.loads(out)
    assert code == 0, err
    assert rec["frame"]["likely"] == "as read (consistent)" and rec["usable"]
    assert rec["normal_rotation"]["given_as"] == "camera_to_world"
    code, out, _ = run(capsys, "info", d / "world.npy", "--json")
    rec = json.loads(out)
    assert code == 1 and "--world-to-camera FILE" in rec["frame"]["likely"]
    assert rec["normal_rotation"] is None


def test_batch_forwards_the_rotation_and_names_a_rotation_beside_plain_maps(views, capsys):
    d, R = views
    maps = d / "maps"
    maps.mkdir()
    for k in range(2):
        np.save(maps / f"v{k}.npy", np.load(d / "world.npy"))
    (maps / "camera_to_world.txt").write_text((d / "matrix_world.txt").read_text())
    assert run(capsys, "integrate", d / "cam.npy", "-o", d / "cam", "-s", "npy")[0] == 0
    code, _, err = run(capsys, "batch", maps, "-o", d / "b1", "-s", "npy", "--workers", "1")
    assert code == 1 and "holds camera_to_world.txt beside its normal maps" in err
    assert f"--camera-to-world {maps / 'camera_to_world.txt'}" in err
    code, _, err = run(capsys, "batch", maps, "-o", d / "b2", "-s", "npy", "--workers", "1",
                       "--camera-to-world", maps / "camera_to_world.txt")
    assert code == 0, err
    assert "holds camera_to_world.txt" not in err
    recs = [json.loads(line) for line in (d / "b2" / "batch.jsonl").read_text().splitlines()]
    for r in recs:
        np.testing.assert_allclose(depth_of(d / "b2" / r["name"]), depth_of(d / "cam"),
                                   atol=1e-10)
        assert r["settings"]["camera_to_world"] == str(maps / "camera_to_world.txt")
        np.testing.assert_allclose(r["normal_rotation"]["world_to_camera"], R, atol=1e-12)
    # a bad file fails the template, before any item
    (d / "bad.txt").write_text("1 2 3")
    code, _, err = run(capsys, "batch", maps, "-o", d / "b3", "--world-to-camera",
                       d / "bad.txt")
    assert code == 1 and "--world-to-camera" in err and not (d / "b3").exists()


def test_the_outputs_that_carry_normals_get_the_camera_frame_ones(views, capsys, monkeypatch):
    """-s points writes each point's normal beside its camera-frame coordinates, and the report
    measures the deviation from the normals integrated: both the turned ones, not the world
    normals as read (points in the camera frame with world normals, a deviation panel of
    the rotation's angle)."""
    import meshio

    d, _ = views
    seen = []

    def report(path, surface, normals=None, **kw):  # (no matplotlib needed: what it is given)
        seen.append(np.array(normals))
        path.write_bytes(b"")
        return path

    monkeypatch.setattr(io, "write_report", report)
    for name, flags in (("cam", []), ("w", ["--camera-to-world", d / "matrix_world.txt"])):
        src = d / ("cam.npy" if name == "cam" else "world.npy")
        code, _, err = run(capsys, "integrate", src, *flags, "-s", "points", "-s", "report",
                           "-o", d / name)
        assert code == 0, err
    clouds = [meshio.read(d / o / "points.ply") for o in ("cam", "w")]
    np.testing.assert_allclose(clouds[1].points, clouds[0].points, atol=1e-9)
    for k in ("nx", "ny", "nz"):
        np.testing.assert_allclose(clouds[1].point_data[k], clouds[0].point_data[k], atol=1e-6)
    np.testing.assert_allclose(seen[1], seen[0], atol=1e-12)


def test_a_rotation_npy_beside_maps_is_no_batch_item(views, capsys):
    """world_to_camera.npy beside a folder's maps (a .npy, as the maps are) is a rotation
    file, as K.txt is a camera file: no item, and not skipped as 'a one-channel file that
    pairs with no normal map' (a depth map or grey image), in a folder or a pattern, and no
    subfolder of maps for it alone."""
    d, R = views
    maps = d / "maps"
    maps.mkdir()
    np.save(maps / "v0.npy", np.load(d / "world.npy"))
    np.save(maps / "world_to_camera.npy", R)
    for spec in (maps, maps / "*.npy"):
        out = d / f"b{len(str(spec))}"
        code, _, err = run(capsys, "batch", spec, "-o", out, "-s", "npy", "--workers", "1",
                           "--world-to-camera", maps / "world_to_camera.npy")
        assert code == 0, err
        assert "one-channel" not in err and "world_to_camera.npy" not in err, err
        assert [json.loads(line)["name"] for line in
                (out / "batch.jsonl").read_text().splitlines()] == ["v0"]
    (maps / "cams").mkdir()  # (a subfolder holding a rotation alone holds no maps)
    (maps / "world_to_camera.npy").rename(maps / "cams" / "world_to_camera.npy")
    code, _, err = run(capsys, "batch", maps, "-o", d / "bt", "-s", "npy", "--workers", "1",
                       "--world-to-camera", maps / "cams" / "world_to_camera.npy")
    assert code == 0 and "subfolder" not in err, err


def test_a_transposed_pose_is_refused_not_taken_for_its_inverse(sphere, tmp_path):
    """A 4x4 pose stored column by column (OpenGL, glm, three.js's matrix.elements, a
    flattened column-major array) has its translation in the bottom row: read row by row its
    upper-left 3x3 is the rotation's inverse, a rotation too, which would turn the normals the
    wrong way without a word where the facing check happens to pass. A 4x4 whose bottom row
    is not 0 0 0 1 is no pose."""
    n, mask = sphere
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = random_rotation(4), [0.5, -1.0, 4.0]
    with pytest.raises(ValueError, match=r"`normal_rotation`: a 4x4 pose's bottom row is "
                                         r"0 0 0 1; got \[0\.5, -1, 4, 1\]: .*column by "
                                         r"column.*transpose"):
        facetlift.integrate(n, mask, normal_rotation=pose.T)
    odd = pose.copy()
    odd[3] = [0.0, 0.0, 1.0, 0.0]
    with pytest.raises(ValueError, match=r"bottom row is 0 0 0 1; got \[0, 0, 1, 0\]: "
                                         r"it is no pose"):
        facetlift.integrate(n, mask, normal_rotation=odd)
    (tmp_path / "three.txt").write_text(" ".join(f"{v:.17g}" for v in pose.T.ravel()))
    with pytest.raises(ValueError, match=r"`camera_to_world` \S+three.txt: a 4x4 pose's "
                                         "bottom row"):
        io.read_rotation(tmp_path / "three.txt", camera_to_world=True)
    assert np.allclose(frames.check_rotation(pose), pose[:3, :3])  # (the pose as it is)


@pytest.mark.parametrize("name", ["sphere", "vase"])
def test_a_world_map_that_a_channel_swap_seems_to_mend_is_asked_about_too(name):
    """A Blender camera looking along world X (Z up), tilted a little: its world-space Normal
    pass read as a camera-frame map faces away on about half its pixels, and the reversed
    channel order (z, y, x) happens to face the viewer, so the error offered 'BGR order'
    alone, a frame whose surface has x and y swapped, and never the rotation."""
    gt = synthetic.analytic(name, 48)
    a = np.radians(10.0)
    tilt = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    c2w = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]]) @ tilt  # (camera x, y, z in world)
    error, _ = run_integrate(gt.normals @ c2w.T, gt.mask)
    assert error is not None and "channels in another order" in error
    assert "--world-to-camera FILE or --camera-to-world FILE" in error


def test_read_dataset_rotation_as_its_docstring_says_to_pass_it(views):
    """read_dataset's normals come converted from `frame`, its rotation does not: the
    docstring's rotation_in_facetlift(ds["rotation"], frame) gives the camera-frame result
    with an OpenCV-frame folder (COLMAP's R), and the rotation as it is does not."""
    d, R = views
    ds_dir = d / "colmap"
    ds_dir.mkdir()
    cv = frames.axes_matrix("opencv").T @ R  # (world -> OpenCV camera)
    np.save(ds_dir / "normal_map.npy",
            to_world(frames.from_facetlift(np.load(d / "cam.npy"), "opencv"), cv))
    np.savetxt(ds_dir / "world_to_camera.txt", cv)
    ref = facetlift.integrate(np.load(d / "cam.npy"))
    ds = io.read_dataset(ds_dir, frame="opencv")
    np.testing.assert_allclose(ds["rotation"], cv, atol=1e-12)
    got = facetlift.integrate(ds["normals"], ds["mask"], normal_rotation=frames.
                              rotation_in_facetlift(ds["rotation"], "opencv"))
    np.testing.assert_allclose(got.depth[ref.mask], ref.depth[ref.mask], atol=1e-10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            wrong = facetlift.integrate(ds["normals"], ds["mask"],
                                        normal_rotation=ds["rotation"]).depth[ref.mask]
        except ValueError:
            wrong = None
    assert wrong is None or not np.allclose(wrong, ref.depth[ref.mask], atol=1e-3)
