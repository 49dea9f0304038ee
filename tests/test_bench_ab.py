"""benchmarks/bench_ab.py: the A/B of two settings of the discontinuity route."""

from __future__ import annotations

import csv
import math

import pytest

SETTLE = "facetlift.methods.dgp.discontinuous.SETTLE_AFTER"


pytestmark = pytest.mark.usefixtures("own_bench_cache")  # (the scripts set it)


@pytest.fixture(scope="module")
def ab(load_script):
    return load_script("benchmarks/bench_ab.py")


def quick(tmp_path, *more):
    """Arguments for the analytic scenes of --quick (no data needed: an empty data folder)."""
    data = tmp_path / "data"
    data.mkdir(exist_ok=True)
    return ["--quick", "--data", str(data), "--cache", str(tmp_path / "cache"), "--groups",
            "ortho", "--models", "occluder,fold", "--conditions", "exact,noise3", *more]


def rows_of(path):
    return {(r["scene"], r["condition"]): r for r in csv.DictReader(path.open())}


def test_summary_counts_and_ratios(ab):
    rows = [
        {"group": "g", "scene": "s1", "condition": "exact", "a": 1.0, "b": 0.5},
        {"group": "g", "scene": "s2", "condition": "exact", "a": 1.0, "b": 0.99},  # (1 %: not)
        {"group": "g", "scene": "s3", "condition": "exact", "a": 2.0, "b": 3.0},
        {"group": "h", "scene": "s1", "condition": "noise3", "a": 4.0, "b": 1.0},
        {"group": "h", "scene": "s2", "condition": "noise3", "a": 1.0, "b": math.nan},
        {"group": "h", "scene": "s3", "condition": "noise3", "a": 2.0, "b": 2.0},
    ]
    s = ab.summarize(rows, margin=0.01)
    assert (s["runs"], s["better"], s["worse"], s["failed"], s["ties"]) == (5, 2, 1, (0, 1), 1)
    g = {(x[0], x[1]): x for x in s["groups"]}
    assert g[("g", "exact")][2] == 3
    assert g[("g", "exact")][5] == pytest.approx((0.5 + 0.99 + 3.0) / 4.0)
    assert g[("h", "noise3")][5] == pytest.approx(3.0 / 6.0)
    assert s["mean_ratio"] == pytest.approx(((4.49 / 4.0) + 0.5) / 2)
    # (by ratio: 4 -> 1 before 1 -> 0.5; the loss 2 -> 3 last)
    assert [(r["group"], r["scene"]) for r in s["movers"]][:2] == [("h", "s1"), ("g", "s1")]
    assert s["movers"][-1]["scene"] == "s3" and s["movers"][-1]["group"] == "g"
    assert ab.summarize(rows, margin=0.6)["better"] == 1  # (only 4 -> 1 is beyond 60 %)
    text = ab.report(s, 0.01)
    assert "B better than A in 2, worse in 1" in text and "failed: A in 0, B in 1" in text
    assert text.index("largest gains") < text.index("s1") < text.index("largest losses")


def test_settings_are_checked_and_restored(ab):
    from facetlift.methods.dgp import discontinuous

    options, constants = ab.split_settings(
        ["discontinuity_k=2", "facetlift.methods.dgp.discontinuous.STEEP_TAU=0.25",
         "facetlift.methods.dgp.discontinuous.GROW=False"])
    assert options == {"discontinuity_k": 2}
    before = discontinuous.STEEP_TAU
    with pytest.raises(RuntimeError):
        with ab.applied(constants):
            assert discontinuous.STEEP_TAU == 0.25 and discontinuous.GROW is False
            raise RuntimeError("a run failed")
    assert discontinuous.STEEP_TAU == before and discontinuous.GROW is True
    for bad, says in (("nokey", "KEY=VALUE"),
                      ("facetlift.methods.dgp.discontinuous.NO_SUCH=1", "has no 'NO_SUCH'"),
                      ("facetlift.no_such_module.X=1", "no module"),
                      ("facetlift.methods.dgp.discontinuous.GROW=false", "not of that kind"),
                      ("facetlift.methods.dgp.discontinuous.STEEP_TAU=0.O5", "not of that kind")):
        with pytest.raises(ValueError, match=says):
            ab.split_settings([bad])
    ab.check_options({"discontinuity_k": 2})
    with pytest.raises(ValueError, match="discontinuity_kk"):
        ab.check_options({"discontinuity_kk": 2})


def test_the_same_settings_tie_and_a_change_shows_on_its_side(ab, tmp_path, capsys):
    """B set to A's default sharpness ties on every run; a constant set on B moves the jump
    scene, set on A the same amount the other way, and is restored after each run."""
    from facetlift.methods.dgp import discontinuous

    same = tmp_path / "same.csv"
    args = quick(tmp_path, "--csv")
    k = f"discontinuity_k={discontinuous.DEFAULT_K}"
    assert ab.main(args + [str(same), "--b", k]) == 0
    rows = rows_of(same)
    assert len(rows) == 4 and {s for s, _ in rows} == {"occluder", "fold"}
    assert all(float(r["a"]) == float(r["b"]) and math.isfinite(float(r["a"]))
               for r in rows.values())
    assert "B better than A in 0, worse in 0" in capsys.readouterr().out
    before = discontinuous.SETTLE_AFTER
    on_b, on_a = tmp_path / "b.csv", tmp_path / "a.csv"
    assert ab.main(args + [str(on_b), "--b", f"{SETTLE}=0"]) == 0
    assert ab.main(args + [str(on_a), "--a", f"{SETTLE}=0"]) == 0
    assert discontinuous.SETTLE_AFTER == before
    b, a = rows_of(on_b), rows_of(on_a)
    jump = b[("occluder", "exact")]
    assert abs(float(jump["b"]) - float(jump["a"])) > 0.01 * float(jump["a"])
    for key in b:  # (the same two surfaces, the sides swapped)
        assert float(b[key]["a"]) == float(a[key]["b"])
        assert float(b[key]["b"]) == float(a[key]["a"])
        assert float(b[key]["a"]) == float(rows[key]["a"])  # (the defaults, as before)


def test_a_side_that_fails_is_counted_and_said(ab, tmp_path, capsys, monkeypatch):
    import facetlift.bench.core as core

    real = core.run_method

    def failing(spec, *a, **k):
        if spec.label == "B":
            return core.Run("B", "failed", message="planted")
        return real(spec, *a, **k)

    monkeypatch.setattr(core, "run_method", failing)
    out = tmp_path / "f.csv"
    assert ab.main(quick(tmp_path, "--csv", str(out))) == 1  # (no run with both sides)
    captured = capsys.readouterr()
    assert "failed: A in 0, B in 4" in captured.out
    assert "side B:" in captured.err and "planted" in captured.err
    rows = rows_of(out)
    assert all(r["b_status"] == "failed: planted" and math.isnan(float(r["b"]))
               for r in rows.values())


@pytest.mark.parametrize("more, says", [
    (["--conditions", "noise99"], "--conditions: unknown noise99"),
    (["--conditions", ","], "--conditions: none given"),
    (["--b", "facetlift.methods.dgp.discontinuous.NO_SUCH=1"], "has no 'NO_SUCH'"),
    (["--b", "discontinuity_kk=2"], "--b: unknown option"),
    (["--margin", "-0.5"], "--margin must be at least 0"),
    (["--csv", "/nonexistent-folder/x.csv"], "--csv:"),
])
def test_errors_name_the_argument(ab, tmp_path, capsys, more, says):
    args = quick(tmp_path)
    if more[0] == "--conditions":
        args = args[:args.index("--conditions")] + args[args.index("--conditions") + 2:]
    with pytest.raises(SystemExit):
        ab.main(args + more)
    assert says in capsys.readouterr().err


def test_a_missing_data_folder_is_an_error(ab, tmp_path, capsys):
    with pytest.raises(SystemExit):
        ab.main(["--data", str(tmp_path / "nowhere")])
    assert "--data: no folder" in capsys.readouterr().err
