"""The DiLiGenT release's own layout as a dataset folder: ``<obj>PNG/`` holding
``Normal_gt.mat``, ``mask.png`` and the photographs, the camera in ``Calib_Results.mat`` (or a
``K.txt``) in the folder or its parent; read by io.read_dataset, 'facetlift integrate' and
'facetlift batch' (named after the folders). The folders are small synthetic ones written here
with scipy.io.savemat, laid out as the release lays them out."""

from __future__ import annotations

import json

import numpy as np
import pytest

import facetlift
from facetlift import batch as fb
from facetlift import io
from facetlift.cli import main

scipy_io = pytest.importorskip("scipy.io")

H, W = 24, 30
KK = np.array([[300.0, 0.0, 15.0], [0.0, 300.0, 12.0], [0.0, 0.0, 1.0]])


def bump():
    """Normals of a bump (x right, y up, z toward the viewer), (0, 0, 0) outside the mask as
    in the release's Normal_gt.mat, and the mask."""
    r, c = np.mgrid[0:H, 0:W] + 0.5
    z = 3 * np.exp(-((c - W / 2) ** 2 + (r - H / 2) ** 2) / 40)
    n = facetlift.normals_from_gradients(z * -2 * (c - W / 2) / 40, z * 2 * (r - H / 2) / 40)
    mask = np.zeros((H, W), bool)
    mask[3:-3, 3:-3] = True
    return np.where(mask[..., None], n, 0.0), mask


def diligent(root, objects=("bearPNG", "catPNG"), *, calib=True):
    """`root` laid out as DiLiGenT's pmsData: one folder per object with Normal_gt.mat,
    mask.png, two 'photographs', light_directions.txt and a depth map beside them, and
    Calib_Results.mat (KK and a view's rotation, as the calibration toolbox saves) in `root`.
    """
    root.mkdir(parents=True, exist_ok=True)
    n, mask = bump()
    if calib:
        scipy_io.savemat(root / "Calib_Results.mat",
                         {"KK": KK, "Rc_1": np.eye(3), "fc": np.array([300.0, 300.0])})
    for obj in objects:
        f = root / obj
        f.mkdir()
        scipy_io.savemat(f / "Normal_gt.mat", {"Normal_gt": n})
        io.write_mask(f / "mask.png", mask)
        for i in (1, 2):  # (RGB 16-bit images, as the release's photographs are)
            io.write_normals(f / f"{i:03d}.png", np.dstack([np.zeros((H, W, 2)),
                                                            np.ones((H, W))]), bits=16)
        (f / "light_directions.txt").write_text("0 0 1\n0 0 1\n")
        np.save(f / "depth_gt.npy", np.full((H, W), 1500.0))
    return n, mask


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_read_dataset_takes_normal_gt_and_the_parents_calibration(tmp_path):
    n, mask = diligent(tmp_path)
    ds = io.read_dataset(tmp_path / "bearPNG")
    np.testing.assert_array_equal(ds["normals"], n)  # (the .mat's frame is facetlift's)
    np.testing.assert_array_equal(ds["mask"], mask)
    np.testing.assert_array_equal(ds["K"], KK)
    assert ds["K_file"] == tmp_path / "Calib_Results.mat"
    assert ds["prior"] is None and ds["confidence"] is None
    # the frame flag applies as to any map
    flipped = io.read_dataset(tmp_path / "bearPNG", frame="opencv")["normals"]
    np.testing.assert_array_equal(flipped, n * [1, -1, -1])
    # the files a job must not overwrite, and a batch's --resume looks at
    files = {p.name for p in io.dataset.dataset_files(tmp_path / "bearPNG")}
    assert files == {"Normal_gt.mat", "mask.png", "Calib_Results.mat"}


def test_the_folders_own_camera_comes_first_and_two_must_agree(tmp_path):
    diligent(tmp_path, ("bearPNG",))
    f = tmp_path / "bearPNG"
    own = KK.copy()
    own[0, 2] = 14.5
    np.savetxt(f / "K.txt", own)
    ds = io.read_dataset(f)
    np.testing.assert_array_equal(ds["K"], own)
    assert ds["K_file"] == f / "K.txt"
    scipy_io.savemat(f / "Calib_Results.mat", {"KK": own})  # (the same K: either will do)
    np.testing.assert_array_equal(io.read_dataset(f)["K"], own)
    scipy_io.savemat(f / "Calib_Results.mat", {"KK": KK})
    with pytest.raises(ValueError, match=r"K.txt and .*Calib_Results.mat hold different "
                                         r"intrinsics.*keep one, or give the camera with --K"):
        io.read_dataset(f)
    # a K.txt in the parent is taken as its Calib_Results.mat is
    (f / "K.txt").unlink()
    (f / "Calib_Results.mat").unlink()
    (tmp_path / "Calib_Results.mat").unlink()
    np.savetxt(tmp_path / "K.txt", own)
    np.testing.assert_array_equal(io.read_dataset(f)["K"], own)
    (tmp_path / "K.txt").unlink()  # without any: orthographic
    assert io.read_dataset(f)["K"] is None


def test_a_bini_folder_stays_orthographic_under_a_parent_camera(tmp_path):
    """BiNI's rule: a folder without K.txt is orthographic; a camera file above it (a
    collection's) must not make it perspective without a word. A folder that holds both a
    normal_map.* and Normal_gt.mat is in the DiLiGenT layout: its normal_map is read (an
    estimate saved beside the ground truth), with the parent's camera."""
    n, mask = bump()
    f = tmp_path / "tent"
    f.mkdir()
    io.write_normals(f / "normal_map.png", n, bits=16)
    io.write_mask(f / "mask.png", mask)
    np.savetxt(tmp_path / "K.txt", KK)
    assert io.read_dataset(f)["K"] is None
    scipy_io.savemat(f / "Normal_gt.mat", {"Normal_gt": -n})
    ds = io.read_dataset(f)
    np.testing.assert_allclose(ds["normals"][mask], n[mask], atol=1e-4)  # (the PNG's)
    np.testing.assert_array_equal(ds["K"], KK)


def test_a_photometric_stereo_folder_with_an_estimate_takes_the_parents_camera(tmp_path):
    """An audit: a release object folder holding the user's estimated normal_map.png (as the
    'photometric stereo folder' error tells) beside light_directions.txt, without
    Normal_gt.mat, ran orthographic: its parent's Calib_Results.mat was looked for only beside
    a Normal_gt.mat."""
    n, mask = bump()
    diligent(tmp_path / "pmsData", objects=("objPNG",))
    f = tmp_path / "pmsData" / "objPNG"
    (f / "Normal_gt.mat").unlink()
    io.write_normals(f / "normal_map.png", n, bits=16)
    np.testing.assert_array_equal(io.read_dataset(f)["K"], KK)


def test_dataset_file_names_are_matched_whatever_their_case(tmp_path):
    """An audit: K.TXT, mask.PNG and Normal_Map.png (a Windows user's names) were skipped in
    silence: the job ran orthographic and without its mask (1578 mm MADE on the bear instead
    of 0.47). Two names that differ only in case are refused."""
    n, mask = bump()
    f = tmp_path / "obj"
    f.mkdir()
    io.write_normals(f / "Normal_Map.PNG", np.where(mask[..., None], n, [0, 0, 1]), bits=16)
    io.write_mask(f / "MASK.png", mask)
    np.savetxt(f / "K.TXT", KK)
    from facetlift.io.dataset import is_dataset

    assert is_dataset(f)
    ds = io.read_dataset(f)
    np.testing.assert_array_equal(ds["mask"], mask)
    np.testing.assert_array_equal(ds["K"], KK)
    np.savetxt(f / "k.txt", KK)
    with pytest.raises(ValueError, match=r"K.TXT and k.txt, names that differ only in case"):
        io.read_dataset(f)


def test_normal_gt_variables(tmp_path):
    n, mask = bump()
    f = tmp_path / "objPNG"
    f.mkdir()
    scipy_io.savemat(f / "Normal_gt.mat", {"N": n, "mask": mask.astype(np.uint8)})
    np.testing.assert_array_equal(io.read_dataset(f)["normals"], n)  # (its only HxWx3 one)
    scipy_io.savemat(f / "Normal_gt.mat", {"p": np.zeros((H, W)), "q": np.zeros((H, W))})
    with pytest.raises(ValueError, match=r"must hold the normals as Normal_gt.*got variables "
                                         r"p \(24x30\), q \(24x30\).*--mat-keys"):
        io.read_dataset(f)


def test_a_folder_without_a_normal_map_names_maps_not_depths_nor_photographs(tmp_path):
    """An audit: the message listed depth_gt.npy among 'other maps' and offered `facetlift
    batch FOLDER`, which would have run the depth maps (and the photographs) as normal
    maps."""
    diligent(tmp_path, ("bearPNG",))
    f = tmp_path / "bearPNG"
    (f / "Normal_gt.mat").unlink()
    with pytest.raises(ValueError, match=r"has no normal_map file .*Normal_gt.mat.*photometric "
                                         r"stereo folder.*photographs") as e:
        io.read_dataset(f)
    assert "batch" not in str(e.value)
    (f / "light_directions.txt").unlink()
    np.save(f / "est.npy", bump()[0])
    with pytest.raises(ValueError, match=r"other files that may be normal maps \(001.png, "
                                         r"002.png, est.npy\): integrate one by its path") as e:
        io.read_dataset(f)
    # a batch of the folder is not offered where it would run a depth map as a normal map
    # (an RGB rendering of it: a batch skips only one-channel files, depth_gt.npy among them)
    io.write_normals(f / "depth_vis.png", bump()[0])
    with pytest.raises(ValueError) as e:
        io.read_dataset(f)
    assert "or all of them with `facetlift batch" not in str(e.value)
    assert str(e.value).endswith(f"`facetlift batch {f}` would run depth_vis.png as normal "
                                 "maps too: give it the maps by name")
    (f / "depth_vis.png").unlink()  # (only maps: the batch is offered, a user's check)
    with pytest.raises(ValueError, match=r"\(001.png, 002.png, est.npy\).*or all of them "
                                         r"with `facetlift batch"):
        io.read_dataset(f)


def test_integrate_a_diligent_folder(tmp_path, capsys):
    n, mask = diligent(tmp_path)
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "integrate", tmp_path / "bearPNG", "-o", out, "--json")
    assert code == 0, err
    rec = json.loads(stdout)
    assert rec["perspective"] and rec["camera"] == "the folder's ../Calib_Results.mat"
    assert rec["mask_source"] == "dataset mask" and rec["warnings"] == []
    expected = facetlift.integrate(n, mask, K=KK)
    np.testing.assert_allclose(np.load(out / "depth.npy")[mask], expected.depth[mask],
                               rtol=1e-9)
    code, stdout, err = run(capsys, "integrate", tmp_path / "bearPNG", "-o", out)
    assert code == 0 and "perspective (the folder's ../Calib_Results.mat)" in stdout, err
    # info says where K came from, as integrate does (a second audit: it gave K alone)
    code, stdout, err = run(capsys, "info", tmp_path / "bearPNG")
    assert code == 0, err
    assert "(format mat)" in stdout
    assert ("camera: perspective (the folder's ../Calib_Results.mat), K = [[300.0"
            in stdout)
    code, stdout, err = run(capsys, "info", tmp_path / "bearPNG", "--json")
    assert code == 0 and json.loads(stdout)["camera"] == "the folder's ../Calib_Results.mat"
    code, stdout, err = run(capsys, "info", tmp_path / "bearPNG", "--K",
                            tmp_path / "Calib_Results.mat", "--json")
    assert code == 0 and json.loads(stdout)["camera"] == "K", err
    code, stdout, err = run(capsys, "info", tmp_path / "bearPNG", "--fov", "40")
    assert code == 0 and "camera: perspective (fov 40 deg), K = " in stdout, err


def test_a_corrupt_normal_gt_is_worded_alike_on_stderr_and_in_the_log(tmp_path, capsys):
    """A second audit: a batch item whose Normal_gt.mat is corrupt was "NORMALS: ..." on
    stderr and "`folder`: ..." in batch.jsonl; the command line's log words its errors and
    warnings as its stderr does (the library's batch keeps the Python names)."""
    diligent(tmp_path / "pmsData", ("bearPNG",))
    bad = tmp_path / "pmsData" / "bearPNG" / "Normal_gt.mat"
    bad.write_bytes(bad.read_bytes()[:200])
    code, _, err = run(capsys, "batch", tmp_path / "pmsData", "-o", tmp_path / "out")
    assert code == 1
    said = err.split("facetlift: error: bearPNG (error): ", 1)[1].splitlines()[0]
    rec = json.loads((tmp_path / "out" / "batch.jsonl").read_text().splitlines()[0])
    assert rec["error"] == said and said.startswith("NORMALS: ") and "Normal_gt.mat" in said
    recs = fb.batch([tmp_path / "pmsData"], tmp_path / "lib")
    assert recs[0]["error"].startswith("`folder`: ")


def test_normal_gt_given_by_its_path_names_the_folders_files(tmp_path, capsys):
    diligent(tmp_path, ("bearPNG",))
    code, _, err = run(capsys, "integrate", tmp_path / "bearPNG" / "Normal_gt.mat", "-o",
                       tmp_path / "o")
    assert code == 0, err
    assert ("../Calib_Results.mat (its camera: the map is integrated orthographically) and "
            "mask.png (its mask) this run does not read" in err)
    assert f"facetlift integrate {tmp_path / 'bearPNG'}" in err and err.count("warning") == 1
    # the documented line, with the files given: no word
    code, _, err = run(capsys, "integrate", tmp_path / "bearPNG" / "Normal_gt.mat",
                       "--mat-keys", "Normal_gt", "--mask", tmp_path / "bearPNG" / "mask.png",
                       "--K", tmp_path / "Calib_Results.mat", "-o", tmp_path / "o2")
    assert code == 0 and "warning" not in err, err


def test_batch_names_items_after_the_folders(tmp_path, capsys):
    """An audit: 'facetlift batch bearPNG catPNG' ran each folder's files as maps, named
    Normal_gt, Normal_gt-2, 001, 001-2 ..., and the root's Calib_Results.mat as a map that
    failed."""
    diligent(tmp_path / "pmsData")
    root = tmp_path / "pmsData"
    assert [it.name for it in fb.items([root])] == ["bearPNG", "catPNG"]
    assert [it.name for it in fb.items([root / "bearPNG", root / "catPNG"])] == [
        "bearPNG", "catPNG"]
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "batch", root, "-o", out)
    assert code == 0 and "2 of 2 succeeded" in stdout, err
    assert "warning" not in err, err
    assert sorted(p.name for p in out.iterdir()) == ["batch.jsonl", "bearPNG", "catPNG"]
    recs = [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]
    assert all(r["camera"] == "the folder's ../Calib_Results.mat" for r in recs)
    # --resume runs an item again when the parent's calibration changed
    before = fb.fingerprint(fb.items([root / "bearPNG"])[0])
    assert "Calib_Results.mat" in [name for name, *_ in before]
    scipy_io.savemat(root / "Calib_Results.mat", {"KK": KK * [[1.01], [1.01], [1]]})
    assert fb.fingerprint(fb.items([root / "bearPNG"])[0]) != before


def test_the_recipes_diligent_folder_lines_run_as_written(tmp_path, capsys, monkeypatch):
    """docs/recipes.md gives the release's folders to integrate and batch as they are."""
    import shlex
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "recipes.md").read_text()
    lines = [ln.split("#")[0] for ln in text.splitlines()
             if ln.startswith(("facetlift integrate DiLiGenT/", "facetlift batch DiLiGenT/"))]
    assert len(lines) == 2
    diligent(tmp_path / "DiLiGenT" / "pmsData")
    monkeypatch.chdir(tmp_path)
    for line in lines:
        code, _, err = run(capsys, *shlex.split(line)[1:])
        assert code == 0 and "warning" not in err, err
    assert (tmp_path / "bear_out" / "depth.npy").is_file()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "batch.jsonl", "bearPNG", "catPNG"]


def test_the_release_folder_itself_points_to_its_objects_and_an_empty_K_is_named(tmp_path):
    """An audit: `integrate pmsData` said only 'no normal_map file'; an empty K.txt was read
    as JSON ('Expecting value')."""
    diligent(tmp_path / "pmsData")
    with pytest.raises(ValueError, match=r"it holds dataset folders \(bearPNG, catPNG\).*"
                                         r"facetlift batch"):
        io.read_dataset(tmp_path / "pmsData")
    (tmp_path / "K.txt").write_text("")
    with pytest.raises(ValueError, match=r"the file is empty"):
        io.read_K(tmp_path / "K.txt")


def test_a_folder_with_a_jpeg_normal_map_says_so(tmp_path):
    """A dataset folder holding normal_map.jpg was told it has no normal_map file, without a
    word of the JPEG (a review)."""
    f = tmp_path / "obj"
    f.mkdir()
    (f / "normal_map.jpg").write_bytes(b"\xff\xd8\xff\xe0 not read")
    with pytest.raises(ValueError, match=r"has no normal_map file .*normal_map\.jpg is a JPEG, "
                                         r"which is not read.*convert it to normal_map\.png"):
        io.read_dataset(f)
