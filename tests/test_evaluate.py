"""facetlift.metrics.evaluate and 'facetlift evaluate': a result scored against a ground-truth
depth map with the measures of facetlift.metrics (MADE and its scale, the RMSE after it, the
unaligned mean absolute error, the paper's normalised error for orthographic results), and the
refusals: shapes that differ, no common pixel, depths <= 0 where a scale is needed."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import cli, io, metrics
from facetlift.cli import main

BEAR = Path(__file__).parents[1] / ".." / "shared" / "data" / "normal_maps" / "diligent_bear"
K = np.array([[40.0, 0.0, 12.5], [0.0, 40.0, 9.5], [0.0, 0.0, 1.0]])


def scene(H=20, W=26):
    """A ground truth in mm (a tilted bump about 1500 mm away, NaN in one corner) and an
    estimate up to scale with a small error; the mask leaves the border out."""
    r, c = np.mgrid[0:H, 0:W]
    gt = 1500.0 + 2.0 * c + 20.0 * np.exp(-((c - W / 2) ** 2 + (r - H / 2) ** 2) / 30)
    gt[:3, :3] = np.nan
    est = gt / 1500.0 + 1e-4 * np.sin(r + 2 * c)
    mask = np.zeros((H, W), bool)
    mask[1:-1, 1:-1] = True
    return est, gt, mask


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_perspective_measures_are_the_metrics_modules(tmp_path):
    est, gt, mask = scene()
    rec = metrics.evaluate(est, gt, mask, perspective=True)
    m = mask & np.isfinite(gt)
    scale = np.median(gt[m] / est[m])
    assert rec["pixels"] == m.sum() and rec["uncovered"] == (mask & ~m).sum() == 4
    assert rec["scale"] == pytest.approx(scale, rel=1e-12)
    assert rec["made"] == pytest.approx(metrics.made(est, gt, mask)[0], rel=1e-12)
    assert rec["made"] == pytest.approx(np.mean(np.abs(scale * est[m] - gt[m])), rel=1e-12)
    assert rec["rmse_scaled"] == pytest.approx(
        np.sqrt(np.mean((scale * est[m] - gt[m]) ** 2)), rel=1e-12)
    assert rec["mae"] == pytest.approx(np.mean(np.abs(est[m] - gt[m])), rel=1e-12)
    assert rec["normalized_error"] is None and "no normalised error" in rec["notes"][0]
    # a metric result (e.g. fused with a prior): the unaligned error is the one that says so
    exact = metrics.evaluate(gt, gt, perspective=True)
    assert exact["mae"] == 0 and exact["made"] == 0 and exact["scale"] == 1
    assert exact["pixels"] == np.isfinite(gt).sum() and exact["uncovered"] == 0
    # a Surface says its own camera
    s = facetlift.integrate(facetlift.normals_from_gradients(np.zeros((20, 26)),
                                                             np.zeros((20, 26))), K=K)
    assert metrics.evaluate(s, np.full((20, 26), 1000.0))["perspective"] is True


def test_orthographic_measures_and_when_no_scale_applies():
    _, gt, mask = scene()
    est = gt - gt[mask & np.isfinite(gt)].mean()  # (an orthographic depth: mean 0)
    rec = metrics.evaluate(est, gt, mask)
    assert rec["perspective"] is False
    assert rec["normalized_error"] == pytest.approx(0, abs=1e-12)
    assert rec["mae"] == pytest.approx(1500.0 + 2.0 * 13, rel=0.05)  # (no offset applied)
    assert rec["made"] is rec["scale"] is rec["rmse_scaled"] is None
    assert "no scale: the estimate has depths <= 0" in rec["notes"][0]
    est2 = est + 0.5 * np.cos(np.arange(est.shape[1]))
    ne, _ = metrics.normalized_error(est2, gt, mask)
    assert metrics.evaluate(est2, gt, mask)["normalized_error"] == pytest.approx(ne, rel=1e-12)
    flat = np.full(gt.shape, 3.0)
    rec = metrics.evaluate(flat + 1, flat)  # (a flat truth: no normalised error, said why)
    assert rec["normalized_error"] is None and "zero depth range" in rec["notes"][0]
    assert rec["made"] == 0 and rec["scale"] == 0.75


def test_an_orthographic_result_in_other_units_is_warned_about():
    """A second audit: the DiLiGenT bear integrated orthographically in pixels spans 2.3
    times its truth in mm and scored a normalised error of 26.5 % without a word (2.3 % with
    --pixel-size 0.397). Where the depth ranges (1st to 99th percentile) differ by more than
    1.5 x the warning names the pixel size and the factor; a smaller range names depth jumps
    too; a right one is silent; positive depths are told of the camera."""
    import warnings

    _, gt, mask = scene()
    m = mask & np.isfinite(gt)
    est = gt - gt[m].mean()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = metrics.evaluate(est, gt, mask)
    assert rec["range_ratio"] == pytest.approx(1.0)
    with pytest.warns(UserWarning) as caught:
        rec = metrics.evaluate(2.3 * est, gt, mask)
    said = [str(w.message) for w in caught]
    assert len(said) == 1, said  # (not again as the offset errors' spread warning)
    assert rec["range_ratio"] == pytest.approx(2.3)
    assert ("depth range (1st to 99th percentile over the 428 pixels scored) is 2.3 times the "
            "ground truth's") in said[0]
    # (Python's words from Python: the command line's from facetlift evaluate, below)
    assert "(pixel_size: the world width" in said[0] and "about 0.435 times" in said[0]
    assert "e.g. pixel_size=0.435" in said[0] and "--" not in said[0]
    assert "depth jumps" not in said[0]
    with pytest.warns(UserWarning, match=r"is 0.5 times .*pixel_size.*flattened across "
                                          r"depth jumps .*discontinuities=True keeps"):
        metrics.evaluate(0.5 * est, gt, mask)
    with pytest.warns(UserWarning, match=r"Its depths are all > 0, as a perspective "
                                          r"result's are .*\(perspective=True, or K=K\)") as c:
        assert metrics.evaluate(gt / 1500, gt, mask)["made"] is not None
    assert "--K" not in str(c[0].message)
    assert metrics.evaluate(gt, gt, mask, perspective=True)["range_ratio"] is None
    flat = np.full(gt.shape, 3.0)
    assert metrics.evaluate(flat - 3, flat)["range_ratio"] is None  # (a flat truth: none)


def test_the_offsets_and_the_range_follow_the_results_own_pieces():
    """Two audits. (1) A connected result with a false step of 5 scored 26 % against a
    truth, and 0 % against the same truth with one column missing (a sensor's hole): each
    side of the hole took its own offset. The offset is now one per piece of the result.
    (2) Two objects integrated without a prior (each piece at mean depth 0) against a truth
    that keeps the 30 units between them: a correct result was told its depth range was
    0.056 times the truth's, with advice to integrate again at pixel size 18. The ranges are
    now compared with each piece's mean taken off; a real unit error is still named."""
    import warnings

    r, c = np.mgrid[0:64, 0:64].astype(float)
    gt = 100 + 0.1 * c + 0.05 * r
    est = gt - gt.mean()
    est[:, 32:] += 5
    hole = gt.copy()
    hole[:, 32] = np.nan
    whole = metrics.evaluate(est, gt)["normalized_error"]
    assert whole > 0.2
    assert metrics.evaluate(est, hole)["normalized_error"] == pytest.approx(whole, rel=0.01)
    aligned, m = metrics.align(est, hole)
    assert not m[:, 32].any() and np.isnan(aligned[:, 32]).all()
    # two objects, each its own piece: the offsets apart, the ranges alike
    r, c = np.mgrid[0:64, 0:128].astype(float)
    mask = np.zeros((64, 128), bool)
    mask[8:56, 8:56] = mask[8:56, 72:120] = True
    z = np.where(c < 64, 0.002 * (c - 32) ** 2, -30 + 0.003 * (r - 32) ** 2)
    p = np.where(c < 64, 0.004 * (c - 32), 0.0)
    q = np.where(c < 64, 0.0, -0.006 * (r - 32))
    s = facetlift.integrate_gradients(p, q, mask)
    truth = np.where(mask, 100 - z, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = metrics.evaluate(s, truth)
    assert rec["normalized_error"] < 1e-9 and rec["range_ratio"] == pytest.approx(1.0, 1e-3)
    with pytest.warns(UserWarning, match="is 4 times the ground truth's"):
        metrics.evaluate(facetlift.integrate_gradients(p, q, mask, pixel_size=4), truth)
    # a result whose background is stored as 0, scored with a mask: its pieces are within
    # the mask (with its 0s the two objects were one piece, 31.5 %, a review)
    zero_bg = np.where(mask, s.depth, 0.0)
    assert metrics.evaluate(zero_bg, truth, mask)["normalized_error"] < 1e-9
    assert metrics.normalized_error(zero_bg, truth, mask)[0] < 1e-9


def test_a_result_stored_as_height_is_told():
    """An audit: a result stored as height (-depth, as some tools write it) scored 20.7 %
    against 0.0076 % for the right sign, without a word. Its depths running against the
    truth's, and the negated result scoring at most half the error, give a warning that
    names the convention; a right result, and a poor one that is no height, are silent."""
    import warnings

    r, c = np.mgrid[0:40, 0:50].astype(float)
    gt = 10 * np.exp(-((r - 20) ** 2 + (c - 25) ** 2) / 80) + 0.05 * c
    est = gt - gt.mean()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        metrics.evaluate(est, gt)
        rng = np.random.default_rng(0)
        metrics.evaluate(rng.normal(size=gt.shape) * gt.std(), gt)  # (poor, no height)
    with pytest.warns(UserWarning, match=r"depths run against the ground truth's \(correlation "
                      r"-1.00\); negated it scores .* is it a height \(-depth\)\?"):
        rec = metrics.evaluate(-est, gt)
    assert rec["normalized_error"] > 0.2  # (scored as given: the warning only says it)


def test_a_background_stored_as_zero_in_both_is_named():
    """An audit: a result and a ground truth both with 0 outside the object, scored without a
    mask, came out at 47 % with advice to change the pixel size (0.0146 % with NaN
    backgrounds). Many pixels at 0 in both are named as a background; with a mask, or NaN
    backgrounds, nothing is said."""
    import warnings

    r, c = np.mgrid[0:40, 0:50].astype(float)
    inside = (r - 20) ** 2 + (c - 25) ** 2 < 15**2
    gt = np.where(inside, 10 + np.sqrt(np.clip(225 - (r - 20) ** 2 - (c - 25) ** 2, 0, None)),
                  0.0)
    est = np.where(inside, gt - 12, 0.0)
    with pytest.warns(UserWarning, match=r"hold depth 0 in both the result and the ground "
                      r"truth: a background stored as 0\?"):
        metrics.evaluate(est, gt)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        metrics.evaluate(est, gt, inside)
        metrics.evaluate(np.where(inside, est, np.nan), np.where(inside, gt, np.nan))


def test_refusals_name_what_is_wrong():
    est, gt, mask = scene()
    with pytest.raises(ValueError, match=r"`truth` must have the shape of `estimate`"):
        metrics.evaluate(est, gt[:-1])
    with pytest.raises(ValueError, match=r"no pixel where `mask`, `estimate` and `truth` are "
                                         r"all defined: `mask` has 4 pixels, `estimate` 511 "
                                         r"finite, `truth` 511 finite, 511 both"):
        sel = np.zeros_like(mask)
        sel[:2, :2] = True
        metrics.evaluate(est, gt, sel)
    with pytest.raises(ValueError, match=r"`estimate` has 184 depths <= 0 of the 428 scored: a "
                                         r"perspective result is scored after a median scale"):
        metrics.evaluate(est - est[mask & np.isfinite(gt)].mean(), gt, mask, perspective=True)
    gt0 = np.where(np.isfinite(gt), gt, 0.0)
    with pytest.raises(ValueError, match=r"`truth` has 9 depths <= 0 .*0 where undefined\? "
                                         r"store NaN there, or give a mask"):
        metrics.evaluate(np.where(np.isfinite(est), est, 1.0), gt0, perspective=True)


def test_read_depth_takes_a_ground_truths_npz_array(tmp_path):
    _, gt, _ = scene()
    np.savez(tmp_path / "gt.npz", depth_gt=gt, other=np.zeros(3))
    with pytest.raises(ValueError, match=r"`path`: .*gt.npz must hold an array named 'depth' "
                                         r"or a single array"):
        io.read_depth(tmp_path / "gt.npz")
    got = io.read_depth(tmp_path / "gt.npz", npz_names=("depth_gt", "depth"), arg="gt")
    np.testing.assert_array_equal(got, gt)


def test_cli_evaluate(tmp_path, capsys):
    est, gt, mask = scene()
    np.save(tmp_path / "depth.npy", est)
    np.savez(tmp_path / "depth_gt.npz", depth_gt=gt.astype(np.float32))
    io.write_mask(tmp_path / "mask.png", mask)
    np.savetxt(tmp_path / "K.txt", K)
    args = ("evaluate", tmp_path / "depth.npy", "--gt", tmp_path / "depth_gt.npz",
            "-m", tmp_path / "mask.png", "--K", tmp_path / "K.txt")
    code, out, err = run(capsys, *args)
    assert code == 0 and err == "", err
    rec = metrics.evaluate(est, gt.astype(np.float32), mask, perspective=True)
    assert f"428 pixels (mask: {tmp_path / 'mask.png'}; 4 mask pixels left out" in out
    assert f"perspective (--K {tmp_path / 'K.txt'})" in out
    assert f"MADE:              {rec['made']:.6g} (the ground truth's units" in out
    assert f"scale:             {rec['scale']:.6g}" in out and "normalised error:  -" in out
    code, out, err = run(capsys, *args, "--json")
    got = json.loads(out)
    assert code == 0 and got["status"] == "ok" and got["perspective"] is True
    assert got["made"] == pytest.approx(rec["made"]) and got["pixels"] == 428
    # without --K: no camera given, scored as orthographic with the paper's error, MADE
    # where the depths are all > 0, a note on them and a warning on the ranges (an audit: it
    # said "orthographic" and the docs said MADE is then "-")
    code, out, err = run(capsys, *args[:-2])
    # (no normalised error then: its ranges differ and its depths are all > 0, a perspective
    # result scored without its camera, a reproduction)
    assert code == 0 and "normalised error:  -" in out
    assert "no normalised error: the result's depths are all > 0" in out
    assert "no camera given: scored as orthographic (up to an offset per piece)" in out
    assert f"MADE:              {rec['made']:.6g}" in out
    assert "give --K to score it as one" in out
    # (the command line's flags alone: it said "perspective=True; --K on the command line",
    # a review)
    assert "facetlift: warning: the result's depth range" in err
    assert "score it with its camera (--K, or --fov as integrate took it)" in err
    assert "perspective=True" not in err
    # an orthographic result in pixels against a truth in mm: the warning names --pixel-size
    np.save(tmp_path / "pixels.npy", 2.3 * (gt - np.nanmean(gt[mask])))
    code, out, err = run(capsys, "evaluate", tmp_path / "pixels.npy", "--gt",
                         tmp_path / "depth_gt.npz", "-m", tmp_path / "mask.png", "--json")
    assert code == 0 and json.loads(out)["range_ratio"] == pytest.approx(2.3, rel=1e-4)
    assert "is 2.3 times the ground truth's" in err and "(--pixel-size: the world" in err
    assert "e.g. --pixel-size 0.435" in err and "pixel_size" not in err
    # a surface .npz keeps its camera; a --K that differs from it is refused
    s = facetlift.integrate(facetlift.normals_from_gradients(np.full((20, 26), 0.01),
                                                             np.zeros((20, 26))), K=K)
    s.save(tmp_path / "surface.npz")
    code, out, err = run(capsys, "evaluate", tmp_path / "surface.npz", "--gt",
                         tmp_path / "depth_gt.npz", "--json")
    assert code == 0 and json.loads(out)["perspective"] is True, err
    K2 = K.copy()
    K2[0, 0] = 41
    np.savetxt(tmp_path / "K2.txt", K2)
    code, _, err = run(capsys, "evaluate", tmp_path / "surface.npz", "--gt",
                       tmp_path / "depth_gt.npz", "--K", tmp_path / "K2.txt")
    assert code == 1 and "--K: " in err and "differs from the camera" in err


def test_evaluate_takes_K_in_python():
    """metrics.evaluate(depth, gt, mask, K=K) was a TypeError (it takes perspective=): K
    scores the result as a perspective depth, as facetlift evaluate --K does; a K that is
    no 3 x 3 matrix, or one beside perspective=False, or unlike a Surface's, or one given
    for an orthographic Surface, is refused."""
    est, gt, mask = scene()
    want = metrics.evaluate(est, gt, mask, perspective=True)
    got = metrics.evaluate(est, gt, mask, K=K)
    assert got["perspective"] is True and got["made"] == pytest.approx(want["made"])
    assert metrics.evaluate(est, gt, mask, K=K.tolist(), perspective=True) == got
    with pytest.raises(ValueError, match=r"`K` must be a 3x3 intrinsics matrix, its nine "
                                         r"numbers row by row, or four numbers.*shape \(3,\)"):
        metrics.evaluate(est, gt, mask, K=[1.0, 2.0, 3.0])
    # (as integrate takes K: four numbers and a Pinhole; a transposed K refused, a review)
    from facetlift.camera import Pinhole

    assert metrics.evaluate(est, gt, mask, K=[40.0, 40.0, 12.5, 9.5]) == got
    assert metrics.evaluate(est, gt, mask, K=Pinhole(K)) == got
    with pytest.raises(ValueError, match=r"looks transposed"):
        metrics.evaluate(est, gt, mask, K=K.T)
    with pytest.raises(ValueError, match=r"`K` and perspective=False contradict"):
        metrics.evaluate(est, gt, mask, K=K, perspective=False)
    s = facetlift.integrate(facetlift.normals_from_gradients(np.full((20, 26), 0.01),
                                                             np.zeros((20, 26))), K=K)
    assert metrics.evaluate(s, gt, K=K)["perspective"] is True
    K2 = K.copy()
    K2[0, 0] = 41
    with pytest.raises(ValueError, match=r"`K` differs from the camera the Surface was"):
        metrics.evaluate(s, gt, K=K2)
    # (an orthographic Surface with a K: refused, not failed later on depths <= 0, a review)
    ortho = facetlift.integrate(facetlift.normals_from_gradients(np.full((20, 26), 0.01),
                                                                 np.zeros((20, 26))))
    with pytest.raises(ValueError, match=r"`K` given for an orthographic Surface"):
        metrics.evaluate(ortho, gt, K=K)


def test_cli_evaluate_takes_an_output_folder(tmp_path, capsys, monkeypatch):
    """facetlift evaluate OUTFOLDER --gt GT was refused as 'is a directory' (a review):
    integrate's output folder is read, its surface.npz first (it keeps the camera), else its
    depth.npy; a folder holding neither is refused naming what it looks for."""
    est, gt, mask = scene()
    np.save(tmp_path / "gt.npy", gt)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    np.save(out_dir / "depth.npy", est)
    args = ("--gt", tmp_path / "gt.npy", "--json")
    code, out, err = run(capsys, "evaluate", out_dir, *args)
    assert code == 0, err
    rec = json.loads(out)
    assert rec["result"] == str(out_dir / "depth.npy") and rec["perspective"] is False
    assert rec["made"] == pytest.approx(metrics.evaluate(est, gt, K=K)["made"])
    s = facetlift.integrate(facetlift.normals_from_gradients(np.full((20, 26), 0.01),
                                                             np.zeros((20, 26))), K=K)
    s.save(out_dir / "surface.npz")
    code, out, err = run(capsys, "evaluate", out_dir, *args)
    assert code == 0 and json.loads(out)["perspective"] is True, err
    assert json.loads(out)["result"] == str(out_dir / "surface.npz")
    # a later run into the folder without -s npz: its depth.npy, not the stale surface.npz
    # (an audit), with a warning naming the stale file
    # (the later run's files are moved into place a moment later: STALE_SECONDS shortened)
    monkeypatch.setattr(cli, "STALE_SECONDS", 0.05)
    time.sleep(0.2)
    np.save(out_dir / "depth.npy", est)
    code, out, err = run(capsys, "evaluate", out_dir, *args)
    assert code == 0 and json.loads(out)["result"] == str(out_dir / "depth.npy"), err
    assert "holds surface.npz from an earlier run than its depth.npy" in err
    (tmp_path / "empty").mkdir()
    code, _, err = run(capsys, "evaluate", tmp_path / "empty", "--gt", tmp_path / "gt.npy")
    assert code == 1 and "RESULT: the folder" in err and "holds none of surface.npz, " \
        "depth.npy, depth.exr, depth.tif" in err


def test_cli_evaluate_takes_a_dataset_folder_as_ground_truth(tmp_path, capsys):
    """`--gt FOLDER` (a BiNI user's DiLiGenT folder) was refused as a directory (an audit): its
    depth_gt.* is the ground truth, its mask.png the scored pixels and its K.txt the camera
    where none is given and the result keeps none; the notes say so; --mask and --K win; a
    folder without a ground truth is refused naming the files looked for."""
    est, gt, mask = scene()
    data = tmp_path / "data"
    data.mkdir()
    np.save(data / "depth_gt.npy", gt)
    io.write_mask(data / "mask.png", mask)
    np.savetxt(data / "K.txt", K)
    np.save(tmp_path / "depth.npy", est)
    code, out, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt", data, "--json")
    assert code == 0, err
    rec = json.loads(out)
    want = metrics.evaluate(est, gt, mask, perspective=True)
    inside = (mask & np.isfinite(gt)).sum()
    assert rec["perspective"] is True and rec["pixels"] == want["pixels"] == inside
    assert rec["made"] == pytest.approx(want["made"]) and rec["gt"] == str(data / "depth_gt.npy")
    notes = " ".join(rec["notes"])
    assert "the folder's mask" in notes and "the folder's camera" in notes
    # (the text names the camera as the folder's, not as a --K the user had not typed)
    code, out, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt", data)
    assert code == 0 and "perspective (the folder's K.txt)" in out, out
    assert "--K" not in out.splitlines()[0]
    # given ones win: every finite pixel, and an orthographic score without the folder's K
    full = np.ones_like(mask)
    io.write_mask(tmp_path / "all.png", full)
    code, out, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt", data, "-m",
                         tmp_path / "all.png", "--K", data / "K.txt", "--json")
    assert code == 0 and json.loads(out)["pixels"] == np.isfinite(gt).sum(), err
    assert "the folder's mask" not in " ".join(json.loads(out)["notes"])
    # an orthographic result (mean 0) beside the folder's K: scored without it, said
    np.save(tmp_path / "ortho.npy", est - np.nanmean(est))
    code, out, err = run(capsys, "evaluate", tmp_path / "ortho.npy", "--gt", data, "--json")
    assert code == 0 and json.loads(out)["perspective"] is False, err
    assert "K.txt not used" in " ".join(json.loads(out)["notes"])
    (tmp_path / "nogt").mkdir()
    code, _, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt", tmp_path / "nogt")
    assert code == 1 and "holds none of depth_gt.npz, depth_gt.npy" in err, err


def test_cli_evaluate_refusals(tmp_path, capsys):
    est, gt, mask = scene()
    np.save(tmp_path / "depth.npy", est)
    np.save(tmp_path / "small.npy", gt[:-2])
    np.save(tmp_path / "gt.npy", gt)
    np.savetxt(tmp_path / "K.txt", K)
    code, out, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt",
                         tmp_path / "small.npy", "--json")
    assert code == 1 and "--gt: " in err and "is 18x26 (HxW) but RESULT" in err
    assert json.loads(out)["status"] == "error"
    np.save(tmp_path / "away.npy", np.where(mask, np.nan, est))
    code, _, err = run(capsys, "evaluate", tmp_path / "away.npy", "--gt", tmp_path / "gt.npy",
                       "-m", tmp_path / "gt.npy")
    assert code == 1  # (a mask of floats: read as nonzero = inside)
    io.write_mask(tmp_path / "mask.png", mask)
    code, _, err = run(capsys, "evaluate", tmp_path / "away.npy", "--gt", tmp_path / "gt.npy",
                       "-m", tmp_path / "mask.png")
    assert code == 1 and "no pixel where -m, RESULT and --gt are all defined" in err
    assert "-m has 432 pixels, RESULT 83 finite, --gt 511 finite, 83 both" in err
    np.save(tmp_path / "ortho.npy", est - 1.0)
    code, _, err = run(capsys, "evaluate", tmp_path / "ortho.npy", "--gt", tmp_path / "gt.npy",
                       "--K", tmp_path / "K.txt")
    assert code == 1 and "RESULT has" in err and "depths <= 0" in err
    assert "an orthographic result? score it without a camera" in err
    np.save(tmp_path / "zeros.npy", np.where(mask, est, 0.0))  # (a background of 0)
    code, _, err = run(capsys, "evaluate", tmp_path / "zeros.npy", "--gt", tmp_path / "gt.npy",
                       "--K", tmp_path / "K.txt")
    assert code == 1 and "0 where undefined? store NaN there" in err, err
    code, _, err = run(capsys, "evaluate", tmp_path / "depth.npy")
    assert code == 1 and "--gt" in err
    # an orthographic surface.npz with --K or --fov: refused, as metrics.evaluate refuses it
    # (it was scored as perspective without a word, an audit)
    s = facetlift.integrate(facetlift.normals_from_gradients(np.full(est.shape, 0.01),
                                                             np.zeros(est.shape)))
    s.save(tmp_path / "ortho.npz")
    for flag in (("--K", tmp_path / "K.txt"), ("--fov", 60)):
        code, _, err = run(capsys, "evaluate", tmp_path / "ortho.npz", "--gt",
                           tmp_path / "gt.npy", *flag)
        assert code == 1 and "was integrated orthographically" in err, err


def test_cli_evaluate_a_16bit_png_ground_truth(tmp_path, capsys):
    """A ground truth in 16-bit PNG counts (a sensor's, a dataset's millimetres) with
    --gt-scale scores as the same depth given as floats; without the scale it is refused with
    the flag named; 0 counts are undefined; --gt-scale multiplies a float ground truth too."""
    import imagecodecs

    est, gt, mask = scene()
    np.save(tmp_path / "depth.npy", est)
    io.write_mask(tmp_path / "mask.png", mask)
    np.savetxt(tmp_path / "K.txt", K)
    counts = np.where(np.isfinite(gt), np.round(gt * 1000), 0).astype(np.uint16)
    (tmp_path / "gt.png").write_bytes(imagecodecs.png_encode(counts))
    np.save(tmp_path / "gt_mm.npy", np.where(counts > 0, counts, np.nan).astype(float))
    base = ("evaluate", tmp_path / "depth.npy", "-m", tmp_path / "mask.png", "--K",
            tmp_path / "K.txt", "--json")
    code, out, err = run(capsys, *base, "--gt", tmp_path / "gt.png", "--gt-scale", "0.001")
    assert code == 0, err
    got = json.loads(out)
    want = metrics.evaluate(est, np.where(counts > 0, counts * 0.001, np.nan), mask,
                            perspective=True)
    assert got["made"] == pytest.approx(want["made"]) and got["pixels"] == want["pixels"]
    code, out, err = run(capsys, *base, "--gt", tmp_path / "gt_mm.npy", "--gt-scale", "0.001")
    assert code == 0 and json.loads(out)["made"] == pytest.approx(want["made"]), err
    # the same counts in an integer TIFF: 0 is undefined there too (the help said so, the
    # code scored them as depth 0, a review)
    import tifffile

    tifffile.imwrite(tmp_path / "gt.tif", counts)
    code, out, err = run(capsys, *base, "--gt", tmp_path / "gt.tif", "--gt-scale", "0.001")
    assert code == 0 and json.loads(out)["made"] == pytest.approx(want["made"]), err
    assert json.loads(out)["pixels"] == want["pixels"]
    code, _, err = run(capsys, *base, "--gt", tmp_path / "gt.png")
    assert code == 1 and "--gt: " in err and "with --gt-scale" in err
    assert "in Python" not in err
    code, _, err = run(capsys, *base, "--gt", tmp_path / "gt.png", "--gt-scale", "-1")
    assert code == 1 and "--gt-scale must be a positive number" in err


def test_the_bear_integrated_and_evaluated(tmp_path, capsys):
    """The shared DiLiGenT bear, integrated smoothly with its camera, scores BiNI's MADE in
    mm (0.468 here; BiNI's own, with jumps, 0.334)."""
    if not BEAR.is_dir():
        pytest.skip(f"{BEAR} not present")
    data = io.read_dataset(BEAR)
    s = facetlift.integrate(data["normals"], data["mask"], K=data["K"])
    s.save(tmp_path / "depth.npy")
    code, out, err = run(capsys, "evaluate", tmp_path / "depth.npy", "--gt",
                         BEAR / "depth_gt.npz", "-m", BEAR / "mask.png", "--K", BEAR / "K.txt",
                         "--json")
    assert code == 0, err
    rec = json.loads(out)
    assert rec["pixels"] == data["mask"].sum() and rec["uncovered"] == 0
    assert 0.3 < rec["made"] < 0.6 and 1400 < rec["scale"] < 1600
    assert rec["rmse_scaled"] > rec["made"]


def test_evaluate_takes_the_field_of_view_integrate_took(tmp_path, capsys):
    """A photo's user integrates with --fov and has no K file: evaluate took only --K, and
    scored the perspective result as orthographic (an audit). --fov is the camera now, refused
    beside --K and where a surface .npz keeps another camera."""
    from facetlift.camera import K_from_fov

    r, c = np.indices((40, 60))
    gt = 2.0 + 0.01 * r + 0.005 * c
    np.save(tmp_path / "gt.npy", gt)
    np.save(tmp_path / "depth.npy", gt / np.median(gt))
    args = ("evaluate", tmp_path / "depth.npy", "--gt", tmp_path / "gt.npy")
    code, out, err = run(capsys, *args, "--fov", "60", "--json")
    got = json.loads(out)
    assert code == 0 and got["perspective"] is True, err
    assert got["made"] == pytest.approx(0, abs=1e-9)
    code, out, _ = run(capsys, *args, "--fov", "60")
    assert code == 0 and "perspective (--fov 60 deg)" in out
    np.savetxt(tmp_path / "K.txt", K_from_fov((40, 60), 60))
    code, _, err = run(capsys, *args, "--fov", "60", "--K", tmp_path / "K.txt")
    assert code == 1 and "contradict" in err
    s = facetlift.Surface.from_depth(gt, np.ones(gt.shape, bool), K=K_from_fov((40, 60), 50))
    s.save(tmp_path / "s.npz")
    code, _, err = run(capsys, "evaluate", tmp_path / "s.npz", "--gt", tmp_path / "gt.npy",
                       "--fov", "60")
    assert code == 1 and "differs from the camera" in err


def test_a_few_ground_truth_pixels_setting_the_range_are_warned_about():
    """An audit: one hole stored as 0 in a float ground truth set the normalised error's
    depth range and took the bear's error from 2.30 % to 0.07 % without a word."""
    import warnings

    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 48)
    s = facetlift.integrate(gt.normals, gt.mask)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        metrics.evaluate(s.depth, gt.depth, gt.mask)
    bad = gt.depth.copy()
    r, c = np.argwhere(gt.mask)[100]
    bad[r, c] = 1e3
    with pytest.warns(UserWarning, match=rf"a few pixels set it .*\(row {r}, col {c}\)"):
        metrics.evaluate(s.depth, bad, gt.mask)


def test_a_flat_result_is_scored_with_a_warning_not_a_crash(tmp_path):
    """A result of constant depth (normals all facing the camera) raised ZeroDivisionError in
    evaluate, and integrate of a dataset folder with a depth_gt exited 3 for it (a review)."""
    est, gt, mask = scene()
    flat = np.where(np.isfinite(est), 0.0, np.nan)
    with pytest.warns(UserWarning, match=r"the result is flat"):
        rec = metrics.evaluate(flat, gt - 1500.0, mask)
    assert rec["range_ratio"] == 0 and rec["normalized_error"] > 0.1
    ds = tmp_path / "ds"
    ds.mkdir()
    normals = np.zeros((20, 26, 3))
    normals[..., 2] = 1.0
    np.save(ds / "normal_map.npy", normals)
    np.save(ds / "depth_gt.npy", np.where(np.isfinite(gt), gt - 1500.0, np.nan))
    code = main(["integrate", str(ds), "-o", str(tmp_path / "out"), "--save", "npy"])
    assert code == 0 and (tmp_path / "out" / "depth.npy").is_file()


def test_a_mask_with_a_gap_does_not_split_the_result():
    """A false step across a connected result, where the mask leaves two columns out: scored
    0 as the pieces were cut at the mask (11 % with the same columns NaN in the truth, a
    review). A background stored as a number outside the mask still separates objects."""
    r, c = np.mgrid[0:24, 0:30].astype(float)
    gt = 0.1 * c + 0.05 * np.sin(r / 3)
    est = gt + np.where(c >= 15, 0.5, 0.0)  # (a false step at column 15)
    mask = np.ones(gt.shape, bool)
    mask[:, 14:16] = False
    hole = gt.copy()
    hole[:, 14:16] = np.nan
    want = metrics.normalized_error(est, hole)[0]
    assert want > 0.05
    assert metrics.normalized_error(est, gt, mask)[0] == pytest.approx(want, rel=1e-12)
    assert metrics.evaluate(est, gt, mask)["normalized_error"] == pytest.approx(want, rel=1e-12)
    # two objects, each with its own offset, on a background stored as 0: two pieces
    two = np.zeros_like(gt)
    two[:, :12] = gt[:, :12]
    two[:, 18:] = gt[:, 18:] + 3.0
    sel = np.zeros(gt.shape, bool)
    sel[:, :12] = sel[:, 18:] = True
    assert metrics.normalized_error(two, gt, sel)[0] < 1e-12


def test_a_perspective_result_of_several_pieces_gets_a_note():
    """Two pieces, each exact up to its own scale: MADE's one median scale scores the scales
    between them (1.86 for two exact spheres, without a word, a review); a note gives MADE
    with a scale per piece."""
    est, gt, mask = scene()
    two = est.copy()
    two[:, 13] = np.nan  # (two pieces)
    two[:, 14:] *= 1.3  # (the right one at another scale)
    rec = metrics.evaluate(two, gt, mask, perspective=True)
    note = [n for n in rec["notes"] if "separate pieces" in n]
    assert len(note) == 1 and "2 separate pieces" in note[0]
    each = float(note[0].rsplit(" ", 1)[1])
    assert each < 0.1 * rec["made"]
    assert not [n for n in metrics.evaluate(est, gt, mask, perspective=True)["notes"]
                if "separate pieces" in n]


def test_a_negative_camera_z_truth_is_told_to_negate():
    """A ground truth stored as OpenGL's or Blender's camera z (negative in front) was asked
    whether 0 meant undefined (a review)."""
    est, gt, mask = scene()
    with pytest.raises(ValueError, match=r"all are < 0.*negate it"):
        metrics.evaluate(est, -gt, mask, perspective=True)


def test_an_orthographic_surface_with_positive_depths_is_not_told_to_give_K(tmp_path, capsys):
    """An orthographic result fused with a positive prior, saved as surface.npz (its camera
    stored as orthographic): evaluate noted "give --K", then refused the --K (a review)."""
    r, c = np.mgrid[0:20, 0:26].astype(float)
    depth = 100.0 + 0.1 * c + 0.05 * r
    normals = facetlift.normals_from_gradients(np.full((20, 26), -0.1), np.full((20, 26), 0.05))
    s = facetlift.integrate(normals, prior=depth, prior_weight=10.0)
    assert (s.depth > 0).all()
    s.save(tmp_path / "surface.npz")
    np.save(tmp_path / "gt.npy", depth)
    code, out, err = run(capsys, "evaluate", tmp_path / "surface.npz", "--gt", tmp_path / "gt.npy")
    assert code == 0 and "--K" not in out


def test_a_zero_background_never_joins_objects_whatever_the_mask_leaves_out():
    """A review: with a mask that left out more of the objects than of the background, the
    background's zeros (43 % of the pixels outside it) joined two objects into one piece:
    27 % error and a unit warning for a result exact up to each object's offset."""
    r, c = np.mgrid[0:30, 0:40].astype(float)
    gt = 0.1 * c + 0.05 * np.sin(r / 3)
    est = np.zeros_like(gt)
    est[:, :15] = gt[:, :15]
    est[:, 22:] = gt[:, 22:] + 3.0
    roi = np.zeros(gt.shape, bool)
    roi[5:25, 2:10] = roi[5:25, 28:36] = True  # (most of each object left out)
    assert metrics.evaluate(est, gt, roi)["normalized_error"] < 1e-12


def test_scoring_masks_count_negative_values_as_outside_and_pieces_are_scored_ones():
    """metrics.evaluate counted a logit mask's negatives inside (twice the pixels), and the
    pieces note counted a piece the mask left out (a review)."""
    est, gt, mask = scene()
    logit = np.where(mask, 3.0, -3.0)
    with pytest.warns(UserWarning, match=r"negative values"):
        rec = metrics.evaluate(est, gt, logit, perspective=True)
    assert rec["pixels"] == metrics.evaluate(est, gt, mask, perspective=True)["pixels"]
    two = est.copy()
    two[:, 13] = np.nan
    two[:, 14:] *= 1.3
    left = mask.copy()
    left[:, 13:] = False  # (only the left piece scored)
    notes = metrics.evaluate(two, gt, left, perspective=True)["notes"]
    assert not [n for n in notes if "separate pieces" in n]
    from facetlift.camera import Orthographic

    with pytest.raises(ValueError, match=r"`K` is an orthographic camera"):
        metrics.evaluate(est, gt, mask, K=Orthographic(1.0))


def test_a_perspective_height_or_disparity_is_told_and_not_sent_to_give_K(tmp_path, capsys):
    """A review: a height (positive, larger = nearer) scored with K printed MADE 561.7 on the
    bear and a disparity 17.7, without a word; scored without K, the height was told to give
    --K as a perspective result's positive depths are. Depths running against the truth's
    are named; a right result is silent."""
    import warnings

    est, gt, mask = scene()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = metrics.evaluate(est, gt, mask, perspective=True)
    assert rec["correlation"] > 0.99 and rec["coverage"] == 1.0
    for bad in (np.nanmax(gt) + 10.0 - gt, 1.0 / gt):  # (a height, a disparity)
        with pytest.warns(UserWarning, match=r"run against the ground truth's \(correlation "
                          r"-\d\.\d\d\): a height \(larger = nearer\), a disparity"):
            rec = metrics.evaluate(bad, gt, mask, perspective=True)
        assert rec["made"] is not None and rec["correlation"] < -0.9
    height = np.nanmax(gt) + 10.0 - gt
    np.save(tmp_path / "gt.npy", gt)
    # (scored without a camera, a positive height or a disparity is named too, with no
    # normalised error, and not sent to give --K nor a pixel size: a review)
    for bad, name in ((height, "h.npy"), (1.0 / gt, "d.npy")):
        np.save(tmp_path / name, bad)
        code, out, err = run(capsys, "evaluate", tmp_path / name, "--gt", tmp_path / "gt.npy")
        err = " ".join(err.split())
        assert code == 0 and "run against the ground truth's" in err and "a disparity" in err
        assert "give --K" not in out + err and "--pixel-size" not in err
        assert out.split("normalised error:")[1].split()[0] == "-"


def test_a_result_that_leaves_much_of_the_mask_undefined_is_warned_about():
    """A review: 9 of the bear's 40,670 pixels scored MADE 0, and a result stored upside
    down lost a third of the mask, with only a count in the text. Below 95 % of the mask's
    pixels with a defined truth a warning says that the rest is not scored; ``coverage``
    gives the share. Holes in the truth are not the result's and do not count."""
    import warnings

    est, gt, mask = scene()
    few = est.copy()
    few[mask] = np.nan
    few[5, 5:8] = est[5, 5:8]
    with pytest.warns(UserWarning, match=r"undefined \(NaN\) at \d+ of the \d+ mask pixels"):
        rec = metrics.evaluate(few, gt, mask, perspective=True)
    assert rec["pixels"] == 3 and rec["coverage"] < 0.01
    holes = gt.copy()
    holes[5:15, 5:15] = np.nan  # (the truth's holes: 100 of 432, not the result's)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = metrics.evaluate(est, holes, mask, perspective=True)
    assert rec["coverage"] == 1.0 and rec["uncovered"] > 90
    assert metrics.evaluate(est, gt, perspective=True)["coverage"] is None  # (no mask)


def test_an_orthographic_result_in_more_pieces_than_the_truth_gets_a_note():
    """A review: a tilted result scored 7.54 % whole and 1.84 % cut into 16 pieces by lines
    of undefined pixels, each piece aligned by its own offset, without a word. A note gives
    the error with one offset per piece of the truth; a whole result gets none."""
    r, c = np.mgrid[0:64, 0:64].astype(float)
    gt = 10 * np.exp(-((r - 32) ** 2 + (c - 32) ** 2) / 200)
    est = gt + 0.05 * c  # (tilted)
    cut = est.copy()
    cut[::16, :] = cut[:, ::16] = np.nan
    whole = metrics.evaluate(est, gt)
    assert not [n for n in whole["notes"] if "separate pieces" in n]
    rec = metrics.evaluate(cut, gt)
    note = [n for n in rec["notes"] if "separate pieces" in n]
    assert len(note) == 1 and "16 separate pieces" in note[0]
    joined = float(note[0].split("it is ")[1].split(" %")[0]) / 100
    assert rec["normalized_error"] < 0.5 * joined
    assert joined == pytest.approx(whole["normalized_error"], rel=0.05)


def test_evaluate_reads_mat_results_and_ground_truths(tmp_path, capsys):
    """DiLiGenT's ground truth and MATLAB toolboxes' results are .mat files: they were refused
    as RESULT and --gt (a review). A transposed result is named so."""
    from scipy.io import savemat

    est, gt, mask = scene()
    savemat(tmp_path / "gt.mat", {"depth_gt": gt, "other": np.zeros((1, 3))})
    savemat(tmp_path / "z.mat", {"z": est})
    np.save(tmp_path / "mask.npy", mask)
    code, out, _ = run(capsys, "evaluate", tmp_path / "z.mat", "--gt", tmp_path / "gt.mat",
                       "-m", tmp_path / "mask.npy", "--K", "40,40,12.5,9.5", "--json")
    rec = json.loads(out)
    assert code == 0 and rec["made"] == pytest.approx(
        metrics.evaluate(est, gt, mask, perspective=True)["made"])
    np.save(tmp_path / "t.npy", est.T)
    code, _, err = run(capsys, "evaluate", tmp_path / "t.npy", "--gt", tmp_path / "gt.mat")
    assert code == 1 and "transposed" in err


def test_a_grey_rgb_exr_result_is_read_and_a_colour_one_refused(tmp_path, capsys):
    """A depth saved as a grey R, G, B EXR was refused ("must hold channel Z or one
    channel", a review): equal channels are one map; unequal ones are still refused."""
    import OpenEXR

    est, gt, _ = scene()
    est = np.where(np.isfinite(gt), est, np.nan).astype(np.float32)
    np.save(tmp_path / "gt.npy", gt)
    for name, chans in (("grey", (est, est, est)), ("colour", (est, 2 * est, est))):
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, dict(zip("RGB", chans, strict=True))) as f:
            f.write(str(tmp_path / f"{name}.exr"))
    assert np.array_equal(io.read_depth(tmp_path / "grey.exr"), est, equal_nan=True)
    code, _, err = run(capsys, "evaluate", tmp_path / "colour.exr", "--gt", tmp_path / "gt.npy")
    assert code == 1 and "must hold channel Z or one channel" in err
