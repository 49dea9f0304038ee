"""The CLI treats the discontinuity reweighting's fixed budget as a note, not a failure."""

import functools
import importlib

import numpy as np
from test_cli import run, write_input

import facetlift
from facetlift.cli import main


def test_discontinuity_budget_is_a_note_not_exit_2(tmp_path, capsys, monkeypatch):
    dgp = importlib.import_module("facetlift.methods.dgp")
    real = dgp.run

    @functools.wraps(real)  # keeps the option signature that integrate() checks
    def budget_used(problem, **kw):
        result = real(problem, **kw)
        assert result.info["solver"] == "discontinuous"
        result.info["converged"] = False  # as when the weights have not settled yet
        return result

    monkeypatch.setattr(dgp, "run", budget_used)
    npath, mpath, _ = write_input(tmp_path)
    out = tmp_path / "o"
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", out,
                            "--discontinuities", "--option", "discontinuity_iter=1")
    assert code == 0, err
    assert (out / "depth.npy").is_file() and "not converged" in stdout
    assert "discontinuity_iter" in err


def test_iterative_non_convergence_still_exits_2(tmp_path, capsys):
    npath, mpath, _ = write_input(tmp_path)
    code, _, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "o",
                       "--solver", "iterative", "--max-iter", "1", "--tol", "0",
                       "--no-progress")
    assert code == 2 and "did not converge" in err


def test_a_smooth_result_bent_across_jumps_gets_the_hint(tmp_path, capsys):
    """A user ran the default (smooth) route on a map with depth jumps and never learned of
    --discontinuities (the DiLiGenT bear: 0.468 mm against 0.025): where more than 0.2 % of
    the facets deviate from their normals by more than 10 deg the command line says so;
    not on a jump-free surface, nor with --discontinuities or an explicit
    --option discontinuities=false."""
    from facetlift import synthetic

    for name in ("occluder", "sphere", "vase"):
        gt = synthetic.analytic(name, 64)
        np.save(tmp_path / f"{name}.npy", gt.normals)
    flipped = synthetic.analytic("vase", 64).normals * [1.0, -1.0, 1.0]
    np.save(tmp_path / "flipped.npy", flipped)
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    import demo

    _, n, mask, _, h = demo.scene(128)
    np.save(tmp_path / "demo.npy", np.where(mask[..., None], n, np.nan))
    runs = {
        ("occluder", ()): True, ("sphere", ()): False, ("vase", ()): False,
        ("occluder", ("--discontinuities",)): False,
        ("occluder", ("--option", "discontinuities=false")): False,
        # bini keeps jumps by default: the flag would change nothing (a review)
        ("occluder", ("--method", "bini")): False,
        # a map read in the wrong frame deviates for that reason, which its warning names
        ("flipped", ()): False,
        # creases deviate too, but an integrable field has no jump to keep (the demo's roofs)
        ("demo", ()): False,
    }
    for (name, extra), hinted in runs.items():
        assert main(["integrate", str(tmp_path / f"{name}.npy"), *extra, "-s", "npy",
                     "-o", str(tmp_path / f"o_{name}_{len(extra)}")]) == 0
        err = capsys.readouterr().err
        assert ("hint: " in err and "--discontinuities keeps them" in err) == hinted, (name, err)
        if name == "flipped":  # (the frame's warning, not the hint, explains it)
            assert "far more integrable with y flipped" in err
    s = facetlift.integrate(synthetic.analytic("occluder", 64).normals)
    assert s.info["deviation_over_10"] > 0.002


BEAR = "../shared/data/normal_maps/diligent_bear"


def test_a_wrong_camera_gets_a_pointer_to_its_warning_not_the_jump_hint(tmp_path, capsys):
    """A fresh user's review: the DiLiGenT bear with its K in mm (K / 100: fx 37.7) or its
    principal point 10x off deviated on 92 % and 59 % of the facets, and beside the K warning
    the hint said --discontinuities keeps them (with K / 100, flip the frame first). Where
    the run warned of its camera (a CameraWarning) the hint points at that warning; with the
    right K the bear's real jumps are still named (0.5 %), also where the K comes from a
    calibration file with lens distortion (warned about, but nearly every real calibration
    has some: a review found the hint gone for them)."""
    import json
    from pathlib import Path

    import pytest

    if not Path(BEAR).is_dir():
        pytest.skip("../shared/data not available")
    K = np.loadtxt(Path(BEAR) / "K.txt")
    mm = K.copy()
    mm[:2] /= 100
    off = K.copy()
    off[:2, 2] *= 10
    files = {}
    for name, k in (("right", K), ("mm", mm), ("off", off)):
        files[name] = tmp_path / f"{name}.txt"
        np.savetxt(files[name], k)
    files["distorted"] = tmp_path / "distorted.yml"
    files["distorted"].write_text(
        "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        f"   data: [ {', '.join(f'{v:.17g}' for v in K.ravel())} ]\n"
        "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
        "   data: [ -0.01, 0., 0., 0., 0. ]\n")
    base = ["integrate", f"{BEAR}/normal_map.png", "-m", f"{BEAR}/mask.png", "-s", "npy"]
    for name, path in files.items():
        code, out, err = run(capsys, *base, "--K", path, "-o", tmp_path / name, "--json")
        rec = json.loads(out)
        assert code == 0 and len(rec["hints"]) == 1, err
        hint = rec["hints"][0]
        assert rec["camera_warned"] == (name not in ("right", "distorted"))
        assert f"hint: {hint}" in err
        if name == "distorted":
            assert "lens distortion" in err
        if name in ("right", "distorted"):
            assert "0.5% of the facets deviate" in hint and "--discontinuities keeps" in hint
            continue
        assert "--discontinuities" not in hint and "frame" not in hint, hint
        assert "a camera that is not the image's bends a whole surface so; mend the camera " \
               "the warning names first" in hint
        assert "facetlift: warning: --K: " in err
    # the library's warnings say which kind they are
    import warnings

    from facetlift import io

    ds = io.read_dataset(BEAR)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        facetlift.integrate(ds["normals"], ds["mask"], K=mm)
    assert {w.category for w in caught if "`K`" in str(w.message)} == {facetlift.CameraWarning}


def test_a_deviation_wider_than_jumps_make_names_the_input_not_the_jumps(capsys):
    """Bent-across jumps deviate on at most 63 % of the facets on the discontinuity
    benchmark: beyond JUMP_HINT_WIDE (75 %) the hint names the frame, camera and encoding
    instead; up to it, and on a batch item alike, the jumps as before; a camera warning
    turns even a small share into the pointer."""
    from types import SimpleNamespace

    from facetlift.cli import _jump_hint
    from facetlift.hints import JUMP_HINT_WIDE, job_hints

    job = SimpleNamespace(method="dgp", options={}, normal_frame=None, gradients=None)
    info = {"method": "dgp", "input": {"usable": 1000},
            "integrability": {"curl": 0.5, "curl_y_flipped": 0.9, "curl_x_flipped": 0.9}}
    wide = _jump_hint(job, {**info, "deviation_over_10": 0.9})
    assert JUMP_HINT_WIDE == 0.75
    assert "90.0% of the facets deviate" in wide and "--discontinuities" not in wide
    assert "the input is off as a whole: check its frame" in wide and "its camera" in wide
    assert "depth prior" not in wide
    withprior = _jump_hint(job, {**info, "deviation_over_10": 0.9, "prior": {"samples": 900}})
    assert "and the dense depth prior: its depths in the units of the pixel size" in withprior
    assert "or --prior-fit for one known up to scale" in withprior
    fitted = _jump_hint(job, {**info, "deviation_over_10": 0.9,
                              "prior": {"samples": 900, "fit": {"scale": 2.0}}})
    assert "dense depth prior" in fitted and "--prior-fit" not in fitted
    sparse = _jump_hint(job, {**info, "deviation_over_10": 0.9, "prior": {"samples": 3}})
    assert "depth prior" not in sparse
    jumps = _jump_hint(job, {**info, "deviation_over_10": 0.63})
    assert "--discontinuities keeps them" in jumps
    assert job_hints(job, {**info, "deviation_over_10": 0.63}) == [jumps]
    pointer = job_hints(job, {**info, "deviation_over_10": 0.01}, camera_warned=True)
    assert len(pointer) == 1 and "mend the camera the warning names first" in pointer[0]
    # many normals facing away (a BGR map): its warning asks about the frame, no jump hint
    # beside it (an audit)
    away = {**info, "deviation_over_10": 0.41, "input": {"usable": 1000, "facing_away": 0.49}}
    assert _jump_hint(job, away) is None
    assert _jump_hint(job, {**away, "input": {"usable": 1000, "facing_away": 0.01}})
    capsys.readouterr()
