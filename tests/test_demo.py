"""The demo script runs end to end on a small grid and reports a small error."""

import re

import numpy as np
import pytest


@pytest.fixture(scope="module")
def demo(load_script):
    return load_script("examples/demo.py", "facetlift_demo")


def test_demo_runs_and_reports_small_error(demo, tmp_path, capsys):
    assert demo.main(["--out", str(tmp_path), "--size", "64"]) == 0
    out = capsys.readouterr().out
    for name in ("input_normals.png", "input_mask.png", "depth.npy", "mesh.ply", "preview.png"):
        assert (tmp_path / name).is_file(), name
        assert str(tmp_path / name) in out
    rms, share = re.search(r"RMS ([0-9.e-]+), max .*\(RMS ([0-9.]+)% of the range\)", out).groups()
    assert float(share) < 2.0 and 0 < float(rms) < 0.03


def test_demo_scene_gradients_match_height(demo):
    """p, q are the derivatives of the height except on the creases and the rims, a set of
    measure zero: the share of pixels where finite differences disagree halves as h halves."""
    shares = []
    for size in (96, 192):
        z, normals, mask, labels, h = demo.scene(size)
        assert set(np.unique(labels)) == {0, 1, 2}
        p, q = -normals[..., 0] / normals[..., 2], -normals[..., 1] / normals[..., 2]
        dzdx = np.gradient(z, h, axis=1)
        dzdy = -np.gradient(z, h, axis=0)  # rows run against y
        sel = mask.copy()
        sel[[0, -1], :] = sel[:, [0, -1]] = False
        bad = (np.abs(dzdx - p) > 0.05) | (np.abs(dzdy - q) > 0.05)
        shares.append(np.mean(bad[sel]))
        assert np.median(np.abs(dzdx - p)[sel]) < 1e-3
    assert shares[1] < 0.6 * shares[0]


def test_demo_rejects_tiny_size(demo):
    with pytest.raises(SystemExit):
        demo.main(["--size", "4"])
