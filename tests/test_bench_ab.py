"""benchmarks/bench_ab.py: the A/B of two settings of the discontinuity route."""

from __future__ import annotations

import csv
import importlib.util
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def ab():
    spec = importlib.util.spec_from_file_location("bench_ab", ROOT / "benchmarks" / "bench_ab.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_summary_counts_and_ratios(ab):
    rows = [
        {"group": "g", "scene": "s1", "condition": "exact", "a": 1.0, "b": 0.5},
        {"group": "g", "scene": "s2", "condition": "exact", "a": 1.0, "b": 1.005},  # (within 1 %)
        {"group": "g", "scene": "s3", "condition": "exact", "a": 2.0, "b": 3.0},
        {"group": "h", "scene": "s1", "condition": "noise3", "a": 4.0, "b": 2.0},
        {"group": "h", "scene": "s2", "condition": "noise3", "a": 1.0, "b": math.nan},
    ]
    s = ab.summarize(rows, margin=0.01)
    assert (s["runs"], s["better"], s["worse"], s["left_out"]) == (4, 2, 1, 1)
    g = {(x[0], x[1]): x for x in s["groups"]}
    assert g[("g", "exact")][2] == 3
    assert g[("g", "exact")][5] == pytest.approx((0.5 + 1.005 + 3.0) / 4.0)
    assert g[("h", "noise3")][5] == pytest.approx(0.5)
    assert s["mean_ratio"] == pytest.approx(((4.505 / 4.0) + 0.5) / 2)
    assert [r["scene"] for r in s["movers"]][:2] == ["s1", "s1"]  # (the largest gains first)
    assert s["movers"][-1]["scene"] == "s3"
    text = ab.report(s, 0.01)
    assert "B better than A in 2, worse in 1" in text and "1 left out" in text


def test_settings_are_checked_and_restored(ab):
    from facetlift.methods.dgp import discontinuous

    options, constants = ab.split_settings(
        ["discontinuity_k=2", "facetlift.methods.dgp.discontinuous.STEEP_TAU=0.25", "x=abc"])
    assert options == {"discontinuity_k": 2, "x": "abc"}
    before = discontinuous.STEEP_TAU
    with pytest.raises(RuntimeError):
        with ab.applied(constants):
            assert discontinuous.STEEP_TAU == 0.25
            raise RuntimeError("a run failed")
    assert discontinuous.STEEP_TAU == before
    for bad, says in (("nokey", "KEY=VALUE"),
                      ("facetlift.methods.dgp.discontinuous.NO_SUCH=1", "has no 'NO_SUCH'"),
                      ("facetlift.no_such_module.X=1", "no module")):
        with pytest.raises(ValueError, match=says):
            ab.split_settings([bad])


def test_the_same_settings_on_both_sides_tie_and_a_change_shows(ab, tmp_path, capsys):
    """The analytic scenes of --quick: B set to A's default sharpness ties on every run, and
    another sharpness moves the jump scene."""
    from facetlift.methods.dgp.discontinuous import DEFAULT_K

    out = tmp_path / "same.csv"
    args = ["--quick", "--groups", "ortho", "--models", "occluder,fold", "--conditions",
            "exact,noise3", "--csv"]
    assert ab.main(args + [str(out), "--b", f"discontinuity_k={DEFAULT_K}"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 4 and {r["scene"] for r in rows} == {"occluder", "fold"}
    assert all(float(r["a"]) == float(r["b"]) and math.isfinite(float(r["a"])) for r in rows)
    assert "B better than A in 0, worse in 0" in capsys.readouterr().out
    moved = tmp_path / "moved.csv"
    assert ab.main(args + [str(moved), "--b", "discontinuity_k=1"]) == 0
    rows = {(r["scene"], r["condition"]): r for r in csv.DictReader(moved.open())}
    jump = rows[("occluder", "exact")]
    assert abs(float(jump["b"]) - float(jump["a"])) > 0.01 * float(jump["a"])


def test_errors_name_the_argument(ab, capsys):
    with pytest.raises(SystemExit):
        ab.main(["--conditions", "noise99"])
    assert "--conditions: unknown noise99" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        ab.main(["--b", "facetlift.methods.dgp.discontinuous.NO_SUCH=1"])
    assert "has no 'NO_SUCH'" in capsys.readouterr().err
