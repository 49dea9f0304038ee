"""benchmarks/bench_cut_errors.py: the route's cuts against the true jumps."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from facetlift import synthetic

pytestmark = pytest.mark.usefixtures("own_bench_cache")  # (the scripts set it)


@pytest.fixture(scope="module")
def ce(load_script):
    return load_script("benchmarks/bench_cut_errors.py")


def test_near_counts_a_cut_beside_the_jump(ce):
    """A true jump between columns 2 and 3; cuts on it, one column beside it and two columns
    off: within one pixel the first two are near, within none only the first."""
    shape = (6, 7)
    true_right = np.zeros((6, 6), bool)
    true_right[:, 2] = True
    own_right = np.zeros((6, 6), bool)
    own_right[:, [2, 3, 5]] = True
    down = np.zeros((5, 7), bool)
    pixels = ce.touched(true_right, down, shape)
    assert pixels[:, [2, 3]].all() and pixels.sum() == 12
    r1, d1 = ce.near(own_right, down, pixels, 1)
    r0, _ = ce.near(own_right, down, pixels, 0)
    assert np.flatnonzero(r1[0]).tolist() == [2, 3] and r1.sum() == 12 and not d1.any()
    assert np.flatnonzero(r0[0]).tolist() == [2] and r0.sum() == 6
    assert ce.count((r1, d1)) == 12


def test_decompose_on_an_analytic_scene(ce):
    """The orthographic `occluder` at 64^2: the route's error as integrate gives it, the
    oracle's as the benchmark's, the true cuts with the route's sides at the oracle (the sides
    of one occluding plate are clear), the route's cuts through the rule near its own error,
    and precision / recall as shares."""
    import facetlift
    from facetlift.bench import discontinuities as D

    gt = synthetic.analytic("occluder", 64)
    s = facetlift.integrate(gt.normals, gt.mask, discontinuities=True)
    row = ce.decompose(gt, gt.normals, s)
    assert row["route"] == pytest.approx(D.error_of(gt, s.depth), rel=1e-12)
    assert row["oracle"] == pytest.approx(D.oracle(gt, gt.normals)[0], rel=1e-12)
    assert row["true"] == pytest.approx(row["oracle"], rel=1e-6)
    assert row["own"] == pytest.approx(row["route"], rel=0.1)  # (11.13 against 11.86 %)
    assert 0.5 < row["precision"] <= 1.0 and 0.5 < row["recall"] <= 1.0
    assert row["jumps"] == sum(int(e.sum()) for e in synthetic.jump_edges(gt)) > 0
    assert row["cuts"] == sum(int(e.sum()) for e in s.cuts) > 0


def test_script_writes_rows_and_a_table(ce, tmp_path, capsys):
    """The command line on the benchmark's `occluder` (no data needed): one CSV row of
    numbers, the group table, and logging back on afterwards (it was left off for the rest of
    the process, which failed a CLI test run after it, a review)."""
    import logging

    data = tmp_path / "data"
    data.mkdir()
    out = tmp_path / "rows.csv"
    assert ce.main(["--data", str(data), "--cache", str(tmp_path / "cache"), "--groups",
                    "ortho", "--models", "occluder", "--conditions", "exact", "--csv",
                    str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [(r["scene"], r["condition"]) for r in rows] == [("occluder", "exact")]
    assert all(np.isfinite(float(v)) for k, v in rows[0].items()
               if k not in ("group", "scene", "condition"))
    assert "| ortho | exact | 1 |" in capsys.readouterr().out
    assert not logging.getLogger("facetlift").manager.disable
    with pytest.raises(SystemExit):
        ce.main(["--data", str(data), "--conditions", ","])
    assert "--conditions: none given" in capsys.readouterr().err


def test_oracle_refuses_sides_of_another_shape():
    from facetlift.bench import discontinuities as D

    gt = synthetic.analytic("occluder", 32)
    with pytest.raises(ValueError, match="`sides` must be a depth map of the scene's shape"):
        D.oracle(gt, gt.normals, sides=np.pad(gt.depth, ((5, 0), (5, 0))))
    with pytest.raises(ValueError, match="`sides` has no finite depth"):
        D.oracle(gt, gt.normals, sides=np.full(gt.depth.shape, np.nan))
