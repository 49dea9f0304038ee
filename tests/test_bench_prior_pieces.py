"""benchmarks/bench_prior_pieces.py: depth points in the pieces the route's cuts separate."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from facetlift import synthetic

pytestmark = pytest.mark.usefixtures("own_bench_cache")  # (the scripts set it)


@pytest.fixture(scope="module")
def pp(load_script):
    return load_script("benchmarks/bench_prior_pieces.py")


def test_points_take_the_middle_pixel_of_each_large_piece(pp):
    """Piece 0 has 6 pixels, piece 1 has 3, piece 2 has 1 (its depth NaN): with a least size
    of 3 a point each in pieces 0 and 1, at the middle of its pixels in row-major order."""
    pieces = np.array([[0, 0, 0, -1],
                       [0, 0, 1, 2],
                       [0, 1, 1, -1]])
    depth = np.arange(12, dtype=float).reshape(3, 4)
    depth[1, 3] = np.nan
    prior = pp.points(depth, pieces, 3)
    # piece 0: (0,0) (0,1) (0,2) (1,0) (1,1) (2,0) -> the 4th, (1,0); piece 1: (1,2) (2,1)
    # (2,2) -> the 2nd, (2,1)
    assert np.argwhere(np.isfinite(prior)).tolist() == [[1, 0], [2, 1]]
    assert prior[1, 0] == 4.0 and prior[2, 1] == 9.0
    assert np.isfinite(pp.points(depth, pieces, 1)).sum() == 2  # (piece 2's depth is NaN)
    assert not np.isfinite(pp.points(depth, pieces, 7)).any()


def test_one_point_is_the_normals_only_error_on_one_component(pp):
    """The analytic `occluder` (one component): a single point keeps the normals-only surface
    (dgp.lone_samples), so its aligned error is the normals-only one; the points per piece
    are one per piece of the route's result of the least size."""
    import facetlift

    gt = synthetic.analytic("occluder", 64)
    row = pp.run_scene(gt, gt.normals, min_piece=20)
    assert row["one"] == pytest.approx(row["normals only"], rel=1e-9)
    assert row["one points"] == 1
    pieces = facetlift.integrate(gt.normals, gt.mask, discontinuities=True).pieces()
    sizes = np.bincount(pieces[pieces >= 0])
    assert row["per piece points"] == int((sizes >= 20).sum()) >= 1
    assert np.isfinite(row["per piece"]) and row["per piece s"] > 0


def test_script_writes_rows_and_a_table(pp, tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    out = tmp_path / "rows.csv"
    assert pp.main(["--data", str(data), "--cache", str(tmp_path / "cache"), "--groups",
                    "ortho", "--models", "occluder", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [(r["scene"], r["condition"]) for r in rows] == [("occluder", "exact")]
    assert all(np.isfinite(float(v)) for k, v in rows[0].items()
               if k not in ("group", "scene", "condition"))
    assert "| ortho | exact | 1 |" in capsys.readouterr().out
    for bad, said in ((["--min-piece", "0"], "--min-piece must be 1 or more"),
                      (["--weight", "-1"], "--weight must be a positive number")):
        with pytest.raises(SystemExit):
            pp.main(["--data", str(data), *bad])
        assert said in capsys.readouterr().err
