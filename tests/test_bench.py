import contextlib
import csv
import io
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from facetlift import methods, synthetic
from facetlift.bench import EXPERIMENTS, Settings, Spec, method_status, run_bench
from facetlift.bench.core import Context
from facetlift.cli import main

DATA = Path(__file__).parents[1] / ".." / "shared" / "data"


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """``facetlift bench --quick`` run once for this module: (exit code, stdout, out folder)."""
    out = tmp_path_factory.mktemp("bench") / "q"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["bench", "--quick", "-o", str(out), "--no-progress"])
    assert code == 0, stderr.getvalue()
    return code, stdout.getvalue(), out


def test_quick_bench_through_main(quick):
    code, stdout, out = quick
    assert code == 0
    assert f"wrote {out / 'report.md'}" in stdout
    for name in ["table1.md", "fig4.png", "fig5.csv", "fig9.md", "report.md"]:
        assert (out / name).is_file(), name


def test_quick_bench_writes_every_table_and_figure(quick):
    out = quick[2]
    for name in ["table1", "fig4", "fig5", "figs6-8", "fig9"]:
        assert (out / f"{name}.csv").stat().st_size > 0
        assert (out / f"{name}.md").read_text().startswith("|")
    for name in ["fig4", "fig5", "fig6", "fig7", "fig8", "fig9"]:
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
    report = (out / "report.md").read_text()
    assert "Failed experiments" not in report


def test_quick_table1_and_fig4(quick):
    out = quick[2]
    t1 = _rows(out / "table1.csv")
    assert {r["resolution"] for r in t1} == {"32x32", "64x64"}
    assert all(float(r["factorization_ms"]) >= 0 for r in t1)
    table1 = (out / "table1.md").read_text()
    assert "factorization_ms" in table1 and "spectral" in table1  # timed rows, not a header
    f4 = _rows(out / "fig4.csv")
    assert {r["mean_subtraction"] for r in f4} == {"True", "False"}


def test_quick_fig9(quick):
    f9 = _rows(quick[2] / "fig9_runs.csv")
    assert {r["condition"] for r in f9} == {"noise-free", "noise 5deg"}
    assert all(r["status"] == "ok" for r in f9 if r["method"] == "dgp")
    # a noise-free analytic surface is reconstructed closely by DGP
    saddle = [r for r in f9 if r["model"] == "saddle" and r["method"] == "dgp"
              and r["condition"] == "noise-free"]
    assert float(saddle[0]["error_pct"]) < 1.0


@pytest.mark.skipif(not (DATA / "normal_maps").is_dir(), reason="no shared data folder")
def test_quick_real_normal_maps(quick):
    out = quick[2]
    assert (out / "fig10.md").is_file() and (out / "bear.md").is_file()
    assert any(r["status"] == "ok" for r in _rows(out / "fig10.csv"))


@pytest.mark.skipif(not (DATA / "meshes").is_dir(), reason="needs ../shared/data")
def test_quick_discontinuities(quick):
    """Every scene and condition has its oracle (true jumps cut) and a converged dgp-disc run;
    the oracle floor lies below the smooth DGP in every group: a broken oracle (no cuts, wrong
    edges) would not."""
    out = quick[2]
    runs = _rows(out / "discontinuities_runs.csv")
    keys = {(r["group"], r["scene"], r["condition"]) for r in runs}
    assert len(keys) >= 4 and {k[0] for k in keys} == {"perspective", "ortho"}
    by = {(r["group"], r["scene"], r["condition"], r["method"]): r for r in runs}
    for key in keys:
        assert by[key + ("oracle",)]["status"] == "ok"
        assert by[key + ("dgp-disc",)]["converged"] == "True"
    for group in ("perspective", "ortho"):
        err = {m: np.mean([float(by[k + (m,)]["error"]) for k in keys if k[0] == group])
               for m in ("dgp", "oracle")}
        assert err["oracle"] < err["dgp"], group
        # every piece at its true place: no worse than the occlusion rule's guess
        placed = np.mean([float(by[k + ("oracle-placed",)]["error"]) for k in keys
                          if k[0] == group])
        assert placed <= err["oracle"] * (1 + 1e-9), group
    real = _rows(out / "discontinuities_real.csv")
    assert {r["data"] for r in real} >= {"diligent_bear"}
    assert all(r["status"] == "ok" for r in real if r["method"].startswith("dgp"))


@pytest.mark.skipif(not (DATA / "meshes").is_dir(), reason="needs ../shared/data")
def test_quick_heldout(quick):
    """The held-out experiment runs the development benchmark's columns and oracle on its own
    scenes (one random view per mesh in --quick), into its own files."""
    out = quick[2]
    runs = _rows(out / "heldout_runs.csv")
    keys = {(r["scene"], r["condition"]) for r in runs}
    assert len(keys) >= 2 and {r["group"] for r in runs} == {"heldout"}
    assert all(k[0].endswith("@h0") for k in keys)
    by = {(r["scene"], r["condition"], r["method"]): r for r in runs}
    for key in keys:
        assert by[key + ("oracle",)]["status"] == "ok"
        assert by[key + ("dgp-disc",)]["converged"] == "True"
    assert "held-out views" in (out / "report.md").read_text()


def test_heldout_views_are_drawn_from_the_seed(tmp_path):
    """Each mesh's held-out views come from the seed and its name: the same again for the same
    seed, the first n - 1 of n views those of n - 1, other views for another seed or mesh;
    unit directions from a camera inside the elevation band, fill inside its band."""
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings

    views = D.heldout_views("bunny", 5, 7)
    assert views == D.heldout_views("bunny", 5, 7)
    assert views[:4] == D.heldout_views("bunny", 4, 7)
    assert views != D.heldout_views("bunny", 5, 8) and views != D.heldout_views("cow", 5, 7)
    lo, hi = np.sin(np.radians(D.HELDOUT_ELEVATION))
    for d, fill in views:
        assert np.linalg.norm(d) == pytest.approx(1.0)
        assert lo <= -d[1] <= hi  # (the rays travel down from a camera above)
        assert D.HELDOUT_FILL[0] <= fill <= D.HELDOUT_FILL[1]
    data = tmp_path / "data"
    (data / "meshes").mkdir(parents=True)
    for name in ("one", "two"):
        (data / "meshes" / f"{name}.ply").write_text("")  # (listed, never loaded here)
    ctx = Context(out=tmp_path, settings=Settings(heldout_views=2), data=data)
    assert [(g, n) for g, n, _ in D.heldout_scenes(ctx)] == [
        ("heldout", "one@h0"), ("heldout", "one@h1"), ("heldout", "two@h0"),
        ("heldout", "two@h1")]
    ctx = Context(out=tmp_path, settings=Settings(heldout_views=2), data=data, models=["two"])
    assert [n for _, n, _ in D.heldout_scenes(ctx)] == ["two@h0", "two@h1"]


@pytest.mark.parametrize("name", ["steps", "plateau", "occluder"])
def test_placed_oracle_removes_the_pieces_offsets(name):
    """The analytic jump scenes' pieces touch nowhere, so the occlusion rule (smallest jump
    zero) misplaces them by whole steps; the placed oracle moves each piece to its true place
    and leaves only the shape error inside the pieces."""
    from facetlift.bench import discontinuities as D

    gt = synthetic.analytic(name, 64)
    err, dev, seconds, placed = D.oracle(gt, gt.normals)
    assert err > 5.0 and placed < 0.05 and dev < 0.1 and seconds > 0


@pytest.mark.parametrize("name", ["steps", "occluder"])
def test_oracle_takes_the_occluding_sides_from_the_truth(name, monkeypatch):
    """The split solve leaves each piece an arbitrary constant; the occlusion rule reads each
    pair's occluding side from the gaps it starts from, so the oracle starts it from the
    true placement: any other constants per piece give the same oracle (from the solve's own,
    the sides were a coin flip and the oracle no floor)."""
    from facetlift.bench import discontinuities as D
    from facetlift.methods.dgp import split as dgp_split

    gt = synthetic.analytic(name, 64)
    base = D.oracle(gt, gt.normals)
    solve = dgp_split.solve_pieces

    def shifted(mesh, *a, **kw):  # every piece moved by a large constant of either sign
        z, info = solve(mesh, *a, **kw)
        rng = np.random.default_rng(mesh.n_pieces)
        return z + rng.choice([-50.0, 50.0], mesh.n_pieces)[mesh.piece], info

    monkeypatch.setattr(dgp_split, "solve_pieces", shifted)
    other = D.oracle(gt, gt.normals)
    assert other[0] == pytest.approx(base[0], rel=1e-9, abs=1e-12)
    assert other[3] == pytest.approx(base[3], rel=1e-9, abs=1e-12)
    assert other[1] == pytest.approx(base[1], rel=1e-5, abs=1e-6)  # (angles: rounding)


def test_placed_oracle_ignores_missing_ground_truth(monkeypatch):
    """Ground truth missing on 60 % of the pixels (the jumps cut as before): each piece is
    still moved by the median of its known differences, not held by the missing ones."""
    from dataclasses import replace

    from facetlift.bench import discontinuities as D

    gt = synthetic.analytic("steps", 64)
    edges = synthetic.jump_edges(gt)
    monkeypatch.setattr(synthetic, "jump_edges", lambda g, **kw: edges)
    holes = np.random.default_rng(0).random(gt.depth.shape) < 0.6
    err, _, _, placed = D.oracle(replace(gt, depth=np.where(holes, np.nan, gt.depth)),
                                 gt.normals)
    assert err > 5.0 and placed < 0.05


def test_missing_and_failing_methods_are_recorded(tmp_path, monkeypatch):
    def run(problem):
        raise RuntimeError("boom")

    mod = types.ModuleType("facetlift.methods._bench_test_boom")
    mod.run = run
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    monkeypatch.setitem(methods.REGISTRY, "ghost", methods.MethodInfo(
        name="ghost", module="_no_such_module", summary="", reference=""))
    monkeypatch.setitem(methods.REGISTRY, "boom", methods.MethodInfo(
        name="boom", module="_bench_test_boom", summary="", reference=""))
    out = run_bench(tmp_path, quick=True, methods=["dgp", "ghost", "boom"],
                    experiments=["maps"], progress=False)
    rows = _rows(out / "figs6-8.csv")
    status = {(r["model"], r["method"]): r["status"] for r in rows}
    assert status[("saddle", "ghost")] == "unavailable"
    assert status[("saddle", "boom")] == "failed"
    assert status[("saddle", "dgp")] == "ok"
    assert "boom" in next(r["message"] for r in rows if r["method"] == "boom")
    report = (out / "report.md").read_text()
    assert "| ghost | no |" in report


def test_measure_records_a_failing_metric_and_skips_it_for_a_failed_run(tmp_path):
    gt = synthetic.analytic("saddle", 16)
    ctx = Context(tmp_path, Settings.quick(), status=method_status(["poisson"]))

    def flat(surface):
        raise ValueError("flat truth")

    r, value = ctx.measure(Spec("poisson", "poisson"), gt.normals, gt.mask, flat)
    assert value is None and r.status == "failed" and r.message == "metric: flat truth"
    r, value = ctx.measure(Spec("poisson", "poisson"), gt.normals, gt.mask, lambda s: s.shape)
    assert r.status == "ok" and value == (16, 16)
    r, value = ctx.measure(Spec("dgp", "dgp"), gt.normals, gt.mask, flat)  # not in `status`
    assert value is None and r.status == "unavailable"


def test_a_failing_experiment_is_reported_and_the_others_run(tmp_path, monkeypatch):
    from facetlift.bench import runner

    def broken(ctx):
        raise RuntimeError("broken on purpose")

    monkeypatch.setitem(runner.EXPERIMENT_FUNCTIONS, "fig4", broken)
    out = run_bench(tmp_path, quick=True, experiments=["fig4", "table1"], progress=False)
    report = (out / "report.md").read_text()
    assert "## Failed experiments" in report
    assert "| fig4 | RuntimeError: broken on purpose |" in report
    assert (out / "table1.csv").is_file() and not (out / "fig4.csv").exists()


def test_bench_input_errors(tmp_path):
    with pytest.raises(ValueError, match="`methods`: unknown"):
        run_bench(tmp_path, methods=["nope"], progress=False)
    with pytest.raises(ValueError, match="`experiments`: unknown"):
        run_bench(tmp_path, experiments=["fig99"], progress=False)
    with pytest.raises(ValueError, match="`conditions`: unknown.*'noise9'.*smooth3"):
        run_bench(tmp_path, experiments=["discontinuities"], conditions=["noise9"],
                  progress=False)
    with pytest.raises(ValueError, match="`conditions`: none given"):
        run_bench(tmp_path, experiments=["discontinuities"], conditions=",", progress=False)
    with pytest.raises(ValueError, match="`heldout_seed` applies to the heldout"):
        run_bench(tmp_path, experiments=["fig4"], heldout_seed=3, progress=False)
    with pytest.raises(ValueError, match="`heldout_seed` must be >= 0"):
        run_bench(tmp_path, experiments=["heldout"], heldout_seed=-1, progress=False)
    with pytest.raises(ValueError, match="`conditions` applies to the discontinuities and "
                                         "heldout"):
        run_bench(tmp_path, experiments=["fig4"], conditions=["smooth3"], progress=False)


def test_every_discontinuity_condition_perturbs_as_named():
    from facetlift.bench.discontinuities import CONDITIONS, condition
    from facetlift.synthetic import analytic

    gt = analytic("vase", 48)
    m = gt.mask
    for name in CONDITIONS:
        n = condition(gt, name, "vase")
        assert n.shape == gt.normals.shape, name
        if name.startswith("ps"):  # a photometric stereo's fit: NaN where too few lights
            ok = np.isfinite(n[..., 0]) & m
            assert ok.sum() > 0.97 * m.sum() and np.isnan(n[~m]).all(), name
            ang = np.degrees(np.arccos(np.clip(np.sum(n[ok] * gt.normals[ok], axis=-1), -1, 1)))
            assert 0 < np.median(ang) < (2.0 if name == "ps" else 10.0), name
            np.testing.assert_array_equal(n, condition(gt, name, "vase"))
            continue
        assert np.isfinite(n[m]).all(), name
        ang = np.degrees(np.arccos(np.clip(np.sum(n[m] * gt.normals[m], axis=-1), -1, 1)))
        if name == "exact":
            np.testing.assert_array_equal(n, gt.normals)
        elif name in ("noise3", "smooth3"):  # RMS 3 degrees
            assert np.sqrt(np.mean(ang**2)) == pytest.approx(3.0, rel=0.1), name
        elif name == "noise6":
            assert np.sqrt(np.mean(ang**2)) == pytest.approx(6.0, rel=0.1), name
        elif name == "outliers":  # 2 % moved, by up to 45 degrees
            assert (ang > 1e-3).mean() == pytest.approx(0.02, abs=0.002)
            assert ang.max() <= 45.0 + 1e-6
        elif name.startswith(("blur", "resample")):  # the curved vase's normals averaged:
            # turned a little
            assert 0 < np.median(ang) < 5.0 and np.isnan(n[~m]).all(), name
        else:  # quantised (8 bits turn the vase's steep normals by degrees)
            assert 0 < ang.max() < 10.0, name
        np.testing.assert_array_equal(n, condition(gt, name, "vase"))  # seeded by the name


def test_cli_bench_refuses_an_unknown_condition(tmp_path):
    from click.testing import CliRunner

    from facetlift.cli import cli

    r = CliRunner().invoke(cli, ["bench", "-o", str(tmp_path), "--experiments",
                                 "discontinuities", "--conditions", "noise9"])
    assert r.exit_code == 2 and "noise9" in r.output and "smooth3" in r.output
    with pytest.raises(ValueError, match="`extra_meshes`"):
        run_bench(tmp_path, extra_meshes=[tmp_path / "none.ply"], progress=False)
    assert "fig9" in EXPERIMENTS


def test_importing_the_bench_loads_neither_click_nor_matplotlib():
    code = ("import sys, facetlift.bench; "
            "print(sorted({'click', 'matplotlib'} & set(sys.modules)))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "[]"


def test_quick_fusion_bench(quick):
    """The fusion experiment ran in the quick bench: its tables, and confidence 0 on the
    corrupted normals gives exactly the error of those normals missing."""
    out = quick[2]
    assert "| group | method | condition |" in (out / "fusion.md").read_text()
    rows = [r for r in _rows(out / "fusion_runs.csv") if r["status"] == "ok"]
    assert {r["condition"] for r in rows} >= {"normals only", "sparse 1%", "noisy 1%", "coarse",
                                             "corrupt conf0", "corrupt missing"}
    by = {(r["scene"], r["method"], r["condition"]): float(r["error"]) for r in rows
          if r["condition"].startswith("corrupt ")}
    for (scene, method, cond), err in by.items():
        if cond == "corrupt conf0":
            assert err == pytest.approx(by[(scene, method, "corrupt missing")], rel=1e-6)


def test_fusion_bench_reports_aligned_errors(quick):
    """Fused, prior-only and normals-only errors after the same alignment (docs/fusion.md):
    'beats both' is judged on these."""
    rows = [r for r in _rows(quick[2] / "fusion_runs.csv")
            if r["status"] == "ok" and r["condition"] == "coarse"]
    assert rows
    for r in rows:
        assert r["aligned_error"] and r["prior_aligned"] and r["normals_error"]


def test_coarse_prior_is_exact_for_a_plane_to_the_mask_edge():
    """The first-order normalised convolution: no centroid bias where blocks are cut by the
    mask (the blurred block means were 2.3 depth units off on this disk)."""
    from facetlift.bench.fusion import coarse_prior

    r, c = np.indices((96, 100))
    mask = (r - 45.3) ** 2 + (c - 52.1) ** 2 < 40**2
    depth = 0.3 * c + 0.1 * r
    gt = synthetic.GroundTruth(depth, np.zeros((96, 100, 3)), mask, 1.0, "plane", None)
    p = coarse_prior(gt)
    assert np.isnan(p[~mask]).all()
    assert np.abs(p - depth)[mask].max() < 1e-2


def test_tabletop_scenes_take_every_mesh_in_turn(tmp_path):
    """The tabletop group's scenes: two meshes each in turn, every third scene three, every
    mesh once before any comes again; scene names are unique (the index is in them)."""
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings

    m = list("abcdefghijkl")
    picks = [D.tabletop_meshes(m, i) for i in range(8)]
    assert [len(p) for p in picks] == [2, 2, 3, 2, 2, 3, 2, 2]
    first = [x for p in picks[:5] for x in p]
    assert len(set(first)) == len(first) == 11
    assert set(first + picks[5]) == set(m)
    assert D.tabletop_meshes(["a", "b"], 2) == ["a", "b"]  # (never a mesh twice in a scene)
    data = tmp_path / "data"
    (data / "meshes").mkdir(parents=True)
    for name in ("one", "two", "three"):
        (data / "meshes" / f"{name}.ply").write_text("")  # (listed, never loaded here)
    ctx = Context(out=tmp_path, settings=Settings(disc_tabletop=3), data=data)
    names = [n for g, n, _ in D.scenes(ctx) if g == "tabletop"]
    assert names == ["one+three@table0", "two+one@table1", "three+two+one@table2"]
    ctx = Context(out=tmp_path, settings=Settings(disc_tabletop=0), data=data)
    assert not [g for g, _, _ in D.scenes(ctx) if g == "tabletop"]


def test_room_scenes_take_every_mesh_in_turn(tmp_path):
    """The room group's scenes: two and three meshes in turn, every mesh once before any comes
    again; named by their meshes and index; none with disc_rooms=0."""
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings

    m = list("abcdefghijkl")
    picks = [D.room_meshes(m, i) for i in range(6)]
    assert [len(p) for p in picks] == [2, 3, 2, 3, 2, 3]
    first = [x for p in picks[:5] for x in p]
    assert first == m
    assert D.room_meshes(["a", "b"], 1) == ["a", "b"]
    data = tmp_path / "data"
    (data / "meshes").mkdir(parents=True)
    for name in ("one", "two", "three"):
        (data / "meshes" / f"{name}.ply").write_text("")  # (listed, never loaded here)
    ctx = Context(out=tmp_path, settings=Settings(disc_rooms=2, disc_tabletop=0), data=data)
    names = [n for g, n, _ in D.scenes(ctx) if g == "room"]
    assert names == ["one+three@room0", "two+one+three@room1"]
    ctx = Context(out=tmp_path, settings=Settings(disc_rooms=0), data=data)
    assert not [g for g, _, _ in D.scenes(ctx) if g == "room"]


def test_a_tabletop_scene_renders(tmp_path, monkeypatch):
    """The tabletop group's loader renders its scene with the benchmark's pinhole camera (two
    small meshes, a small image) and caches it."""
    import trimesh

    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings

    monkeypatch.delenv("FACETLIFT_BENCH_CACHE", raising=False)  # (the cache under out/)
    data = tmp_path / "data"
    (data / "meshes").mkdir(parents=True)
    trimesh.creation.icosphere(subdivisions=3).export(data / "meshes" / "ball.ply")
    trimesh.creation.box((1.0, 1.4, 0.8)).export(data / "meshes" / "box.ply")
    settings = Settings(disc_tabletop=1, disc_resolution=(48, 56), disc_samples=1,
                        disc_views=(), disc_wide_views=(), disc_ortho_views=(), disc_analytic=(),
                        disc_vessels=(), disc_rooms=0)
    ctx = Context(out=tmp_path / "out", settings=settings, data=data)
    [(group, name, load)] = D.scenes(ctx)
    gt = load()
    assert (group, name, gt.name) == ("tabletop", "ball+box@table0", "ball+box@table0")
    assert gt.K is not None and gt.K[0, 0] == pytest.approx(D._pinhole((48, 56))[0, 0])
    assert gt.mask.sum() > 300 and np.isfinite(gt.depth[gt.mask]).all()
    assert list((tmp_path / "out" / "cache").glob("table2_0_ball+box@table0_*.npz"))


def test_a_vessel_scene_renders_with_the_jump_at_its_rim(tmp_path, monkeypatch):
    """The vessel group's loader renders an open cup seen from 40 degrees above with the
    benchmark's pinhole camera (no mesh of the data folder needed) and caches it: the front of
    the rim hides part of the inside, a depth jump."""
    from facetlift import synthetic
    from facetlift.bench import discontinuities as D
    from facetlift.bench.core import Context, Settings

    monkeypatch.delenv("FACETLIFT_BENCH_CACHE", raising=False)  # (the cache under out/)
    settings = Settings(disc_tabletop=0, disc_resolution=(96, 112), disc_samples=1,
                        disc_views=(), disc_wide_views=(), disc_ortho_views=(), disc_analytic=(),
                        disc_vessels=("cup",), disc_vessel_elevations=(40.0,))
    ctx = Context(out=tmp_path / "out", settings=settings, data=tmp_path / "no-data")
    [(group, name, load)] = D.scenes(ctx)
    gt = load()
    assert (group, name, gt.name) == ("vessel", "cup@e40", "cup@e40")
    assert gt.K is not None and gt.mask.sum() > 1000
    right, down = synthetic.jump_edges(gt)
    assert down.sum() > 10  # the rim's front, across the rows
    assert list((tmp_path / "out" / "cache").glob(f"vessel{D.VESSEL_VERSION}_cup_e40_*.npz"))


def test_without_matplotlib_the_tables_stay_and_the_figures_are_listed(tmp_path, monkeypatch):
    """Without the plot extra an experiment lost its report section to the ImportError of
    its figure, with a traceback, while its CSV was written (an audit)."""
    import importlib.util

    from facetlift.bench import plots

    real = importlib.util.find_spec
    monkeypatch.setattr(plots.importlib.util, "find_spec",
                        lambda name, *a: None if name == "matplotlib" else real(name, *a))
    out = run_bench(tmp_path, quick=True, experiments=["fig4"], progress=False)
    report = (out / "report.md").read_text()
    assert "## Fig. 4" in report and "Failed experiments" not in report
    assert "## Figures not drawn" in report and "fig4.png" in report
    assert (out / "fig4.csv").is_file() and not (out / "fig4.png").exists()


def test_scenes_that_cannot_be_made_are_listed(tmp_path):
    """A scene that fails to load (the render extra missing) was only logged, and the means
    went over the others without a word (an audit)."""
    from facetlift.bench import discontinuities as disc
    from facetlift.bench.core import Context, Settings
    from facetlift.bench.runner import _report

    def missing():
        raise ImportError("facetlift.synthetic.render_perspective needs trimesh")

    ctx = Context(tmp_path, Settings.quick())
    assert list(disc.usable(ctx, [("perspective", "spot@front", missing)], "x")) == []
    assert ctx.unavailable == {"spot@front (perspective)": "facetlift.synthetic."
                                                           "render_perspective needs trimesh"}
    assert "## Scenes not rendered" in _report(ctx, "quick", [], 1.0)


def test_an_interrupted_run_still_writes_its_report(tmp_path, monkeypatch):
    """Ctrl-C left the finished experiments' files without a report.md (an audit)."""
    from facetlift.bench import runner

    def stop(ctx):
        raise KeyboardInterrupt

    monkeypatch.setitem(runner.EXPERIMENT_FUNCTIONS, "fig4", stop)
    with pytest.raises(KeyboardInterrupt):
        run_bench(tmp_path, quick=True, experiments=["table1", "fig4"], progress=False)
    report = (tmp_path / "report.md").read_text()
    assert "| fig4 | interrupted" in report and (tmp_path / "table1.csv").is_file()


def test_unknown_models_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"`models`: unknown \['nope'\]"):
        run_bench(tmp_path, quick=True, experiments=["fig9"], models=["nope"], progress=False)


def test_the_render_cache_is_keyed_by_the_meshes_contents(tmp_path, monkeypatch):
    """A render cached under its mesh's stem came back for another mesh of that name or an
    edited one; a truncated cache file dropped its scene from every later run (an audit)."""
    import numpy as np

    from facetlift import synthetic
    from facetlift.bench import discontinuities as disc
    from facetlift.bench.core import Context, Settings

    monkeypatch.setenv("FACETLIFT_BENCH_CACHE", str(tmp_path / "cache"))
    ctx = Context(tmp_path, Settings.quick())
    mesh = tmp_path / "m.ply"
    mesh.write_text("one")
    made = []

    def make():
        made.append(1)
        return synthetic.analytic("sphere", 8)

    disc._cached(ctx, "k", make, (mesh,))
    disc._cached(ctx, "k", make, (mesh,))
    assert len(made) == 1  # (the second from the cache)
    mesh.write_text("another mesh")
    disc._cached(ctx, "k", make, (mesh,))
    assert len(made) == 2  # (other contents: rendered anew)
    cached = tmp_path / "cache" / "k.npz"
    cached.write_bytes(cached.read_bytes()[:100])
    gt = disc._cached(ctx, "k", make, (mesh,))
    assert len(made) == 3 and np.isfinite(gt.depth[gt.mask]).all()
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == ["k.npz"]


@pytest.mark.skipif(not (DATA / "meshes").is_dir(), reason="needs ../shared/data")
def test_scene_and_table_names_are_models_too(tmp_path):
    """`cow@left` and `spot+stanford_bunny@table4`, the docs' examples, were refused by the
    first check of the names (a review)."""
    from facetlift.bench.core import Context, Settings
    from facetlift.bench.runner import _check_models

    for names in (["cow@left"], ["spot+stanford_bunny@table4"], ["cow", "sphere", "cup"],
                  ["tent"]):
        _check_models(Context(tmp_path, Settings(), DATA, models=tuple(names)))
    # (names that no experiment of the run lists: a table of other meshes, quick mode's
    # missing tables, a review)
    with pytest.raises(ValueError, match=r"unknown \['cow\+spot@table0'\]"):
        _check_models(Context(tmp_path, Settings(), DATA, models=("cow+spot@table0",)))
    with pytest.raises(ValueError, match=r"unknown \['spot\+stanford_bunny@table4'\]"):
        _check_models(Context(tmp_path, Settings.quick(), DATA,
                              models=("spot+stanford_bunny@table4",)))


def test_sigterm_still_writes_the_report(tmp_path, monkeypatch):
    """SIGTERM killed a run without its report (Ctrl-C wrote one; a review)."""
    import os
    import signal

    from facetlift.bench import runner
    from facetlift.io.atomic import Terminated

    def term(ctx):
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setitem(runner.EXPERIMENT_FUNCTIONS, "fig4", term)
    with pytest.raises(Terminated):
        run_bench(tmp_path, quick=True, experiments=["table1", "fig4"], progress=False)
    assert "| fig4 | interrupted" in (tmp_path / "report.md").read_text()


def test_an_unreadable_normal_map_folder_is_named_in_the_report(tmp_path):
    """It was only a row of fig10.csv (an audit)."""
    (tmp_path / "empty").mkdir()
    run_bench(tmp_path / "o", quick=True, experiments=["fig10"], progress=False,
              extra_normal_maps=[tmp_path / "empty"], data_dir=tmp_path)
    assert "Not read: empty (" in (tmp_path / "o" / "report.md").read_text()


def test_experiments_named_twice_run_once(tmp_path):
    out = run_bench(tmp_path, quick=True, experiments=["table1", "table1"], progress=False)
    assert (out / "report.md").read_text().count("## Table 1") == 1


def test_oracle_with_given_cuts_and_sides():
    """`cuts` and `sides` default to the truth's: given them, the same oracle; without any
    cut the occluder's plate bends into the floor (even each piece at its true place is far
    off, and the surface leaves its normals); started from a placement with the plate behind
    the floor, the rule takes the other occluding side (11.1 -> 15.5 %)."""
    from facetlift.bench import discontinuities as D

    gt = synthetic.analytic("occluder", 64)
    base = D.oracle(gt, gt.normals)
    given = D.oracle(gt, gt.normals, cuts=synthetic.jump_edges(gt), sides=gt.depth)
    assert given[0] == pytest.approx(base[0], rel=1e-12, abs=1e-12)
    assert given[3] == pytest.approx(base[3], rel=1e-12, abs=1e-12)
    right, down = synthetic.jump_edges(gt)
    uncut = D.oracle(gt, gt.normals, cuts=(np.zeros_like(right), np.zeros_like(down)))
    assert uncut[3] > 100.0 * base[3] and uncut[1] > 10.0 * base[1]  # (bent: 2.7 deg)
    flipped = D.oracle(gt, gt.normals, sides=-gt.depth)
    assert flipped[0] > 1.2 * base[0] and flipped[3] == pytest.approx(base[3], rel=1e-9)
