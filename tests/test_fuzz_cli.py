"""Directed bad input through the command line (issue 12's campaign, re-done): malformed files,
masks, K files and paths, and every invalid value of every declared option of every method.

Each case must exit 0, 1 or 2 (never 3: that is a bug), print at most one error line and no
traceback, leave no staging or temporary file behind, and, on exit 0, write finite depth on
the mask. The default run takes every 6th case; ``make test-slow`` runs the others (all of
them: ``pytest -m "slow or not slow" tests/test_fuzz_cli.py``).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import tifffile
from scipy import io as sio

import facetlift
from facetlift import io
from facetlift.cli import main
from facetlift.methods import REGISTRY

BAD_VALUES = ['"a"', "null", "[1]", '{"a": 1}', "NaN", "-Infinity", "1e400", "-1", "1.5",
              "true", '""', "0"]


def _good(folder):
    r, c = np.indices((14, 16)) + 0.5
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 3), 0.1 * np.sin(r / 3))
    return io.write_normals(folder / "good.png", n)


def _files(folder):
    """name -> (argv tail) of malformed inputs, built in `folder`."""
    good = _good(folder)
    cases = {}

    def put(name, data: bytes):
        (folder / name).write_bytes(data)
        return folder / name

    for ext in (".png", ".tif", ".exr", ".npy", ".mat"):
        cases[f"empty{ext}"] = [put(f"empty{ext}", b"")]
        cases[f"text{ext}"] = [put(f"text{ext}", b"this is not an image\n" * 4)]
        cases[f"truncated{ext}"] = [put(f"truncated{ext}", good.read_bytes()[:60])]
    np.save(folder / "two.npy", np.zeros((4, 4, 2)))
    np.save(folder / "obj.npy", np.array(["a", "b"]))
    np.save(folder / "int64.npy", np.ones((5, 5, 3), np.int64))
    np.save(folder / "one_pixel.npy", np.array([[[0.0, 0.0, 1.0]]]))
    np.save(folder / "huge.npy", np.full((6, 6, 3), 1e308))
    np.save(folder / "zeros.npy", np.zeros((6, 6, 3)))
    np.save(folder / "nan.npy", np.full((6, 6, 3), np.nan))
    np.save(folder / "away.npy", np.dstack([np.zeros((9, 9)), np.zeros((9, 9)), -np.ones((9, 9))]))
    tifffile.imwrite(folder / "i32.tif", np.zeros((4, 4, 3), np.int32), photometric="rgb")
    sio.savemat(folder / "nokeys.mat", {"a": np.zeros((3, 3))})
    sio.savemat(folder / "strs.mat", {"p": "text", "q": "text"})
    for name in ("two.npy", "obj.npy", "int64.npy", "one_pixel.npy", "huge.npy", "zeros.npy",
                 "nan.npy", "away.npy", "i32.tif", "nokeys.mat", "strs.mat"):
        cases[name] = [folder / name]
    (folder / "nodata").mkdir()
    cases["folder without normal_map"] = [folder / "nodata"]
    cases["missing file"] = [folder / "missing.png"]
    # masks
    io.write_mask(folder / "small_mask.png", np.ones((3, 3)))
    io.write_mask(folder / "zero_mask.png", np.zeros((14, 16)))
    lone = np.zeros((14, 16))
    lone[5, 5] = 1
    io.write_mask(folder / "lone_mask.png", lone)
    np.save(folder / "nan_mask.npy", np.full((14, 16), np.nan))
    for name in ("small_mask.png", "zero_mask.png", "lone_mask.png", "nan_mask.npy",
                 "text.png"):
        cases[f"mask {name}"] = [good, "--mask", folder / name]
    cases["mask is a folder"] = [good, "--mask", folder / "nodata"]
    # K files
    for name, text in {"K_text": "a b c\n", "K_2x2": "1 0\n0 1\n",
                       "K_nan": "nan 0 1\n0 1 1\n0 0 1\n", "K_neg": "-5 0 1\n0 5 1\n0 0 1\n",
                       "K_transposed": "100 0 0\n0 100 0\n8 7 1\n", "K_empty": ""}.items():
        (folder / f"{name}.txt").write_text(text)
        cases[name] = [good, "--K", folder / f"{name}.txt"]
    # paths and flags
    (folder / "a_file").write_text("x")
    cases["out is a file"] = [good, "-o", folder / "a_file"]
    cases["out under a file"] = [good, "-o", folder / "a_file" / "sub"]
    cases["bad frame"] = [good, "--normal-frame", "x,x,z"]
    cases["bad gradient frame"] = ["--gradients", good, good, "--gradient-frame", "yx"]
    cases["gradients are a PNG"] = ["--gradients", good, good]
    cases["pixel size 0"] = [good, "--pixel-size", "0"]
    cases["pixel size nan"] = [good, "--pixel-size", "nan"]
    cases["pixel size 1e308"] = [good, "--pixel-size", "1e308"]
    cases["outlier eps 2"] = [good, "--outlier-eps", "2"]
    cases["max iter -1"] = [good, "--solver", "iterative", "--max-iter", "-1"]
    cases["unknown method"] = [good, "--method", "magic"]
    cases["save twice"] = [good, "-s", "npy", "-s", "npy"]
    return cases


def _cases(folder):
    cases = {f"file: {k}": v for k, v in _files(folder).items()}
    good = folder / "good.png"
    for method, info in REGISTRY.items():
        for opt in info.specs():
            if opt.name == "progress":
                continue
            for value in BAD_VALUES:
                cases[f"{method} {opt.name}={value}"] = [good, "--method", method, "--option",
                                                         f"{opt.name}={value}"]
    return cases


def _case_names():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        return sorted(_cases(Path(d)))


ALL = _case_names()
QUICK = ALL[::6]


def check(tmp_path, capsys, name):
    argv = _cases(tmp_path)[name]
    out = tmp_path / "o"
    if "-o" not in argv:
        argv = argv + ["-o", out]
    before = {p for p in tmp_path.rglob("*")}
    code = main(["integrate", *[str(a) for a in argv], "--json"])
    stdout, err = capsys.readouterr()
    assert code in (0, 1, 2), (code, err)
    assert "Traceback" not in err
    errors = [ln for ln in err.splitlines() if ln.startswith("facetlift: error:")]
    assert len(errors) == (0 if code == 0 else 1), err
    leftovers = [p for p in tmp_path.rglob("*") if p not in before and (
        p.name.startswith(".") or "staging" in p.name)]
    assert not leftovers, leftovers
    if code == 0:
        rec = json.loads(stdout)
        depth = np.load(rec["outputs"]["npy"])
        assert np.isfinite(depth[~np.isnan(depth)]).all() and np.isfinite(depth).any()
    return code


@pytest.mark.parametrize("name", QUICK)
def test_directed_bad_input(tmp_path, capsys, name):
    check(tmp_path, capsys, name)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(ALL) - set(QUICK)))
def test_directed_bad_input_all(tmp_path, capsys, name):
    check(tmp_path, capsys, name)


def test_the_campaign_is_large_and_mostly_refused(tmp_path, capsys):
    assert len(ALL) >= 300
    codes = [check(tmp_path / str(i), capsys, n) for i, n in enumerate(QUICK[:12])
             if (tmp_path / str(i)).mkdir() is None]
    assert 1 in codes and all(re.fullmatch("[012]", str(c)) for c in codes)
