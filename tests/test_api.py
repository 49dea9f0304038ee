"""facetlift.integrate / facetlift.solve: dispatch, capability checks, the Surface built."""

from __future__ import annotations

import importlib.util
import sys
import types

import numpy as np
import pytest

import facetlift
from facetlift import methods, synthetic
from facetlift.methods import MethodInfo, MethodResult
from facetlift.options import Option

EIGHT = {"dgp", "frankot_chellappa", "poisson", "alpha_surface", "m_estimator",
         "regularization", "diffusion", "kernel"}


@pytest.fixture
def fake_method(monkeypatch):
    """Register a method "fake" (module facetlift.methods._fake) with given capabilities and
    a run() that returns whatever the test puts in ``box["result"]``."""
    box = {"calls": 0}

    def run(problem, *, scale=1.0, flag=False):
        box["calls"] += 1
        box["problem"], box["options"] = problem, {"scale": scale, "flag": flag}
        return box["result"](problem) if callable(box.get("result")) else MethodResult(
            values=np.zeros(problem.domain.n_facets), info={"iterations": 0})

    module = types.ModuleType("facetlift.methods._fake")
    module.run = run
    module.OPTIONS = (Option("scale", 1.0, "a number", low=0.0),
                      Option("flag", False, "a switch", kind="bool"))
    monkeypatch.setitem(sys.modules, "facetlift.methods._fake", module)

    def register(**caps):
        info = MethodInfo(name="fake", module="_fake", summary="test double", reference="-",
                          **caps)
        monkeypatch.setitem(methods.REGISTRY, "fake", info)
        return box

    return register


def test_registry_lists_the_eight_methods():
    assert EIGHT <= set(facetlift.METHODS)
    for name, info in facetlift.METHODS.items():
        assert info.name == name and info.summary and info.reference
    dgp = methods.get("dgp")
    assert dgp.masks and dgp.missing
    opts = set(dgp.options())
    assert {"solver", "tol", "max_iter", "mean_subtraction", "discontinuities"} <= opts
    assert dgp.options()["solver"] == "direct"


def test_integrate_returns_a_surface_with_info(wave):
    n = wave.normals((10, 12), 0.2)
    s = facetlift.integrate(n, pixel_size=0.2)
    assert isinstance(s, facetlift.Surface)
    info = s.info
    assert info["method"] == "dgp" and info["solver"] == "direct"
    assert info["iterations"] == 1 and info["converged"] is True
    assert isinstance(info["deviation"], list) and all(isinstance(v, float)
                                                      for v in info["deviation"])
    sec = info["seconds"]
    assert {"prepare", "method", "total"} <= set(sec)
    assert all(v >= 0 for v in sec.values()) and sec["total"] >= sec["method"]
    assert info["outliers"] == 0 and info["missing"] == 0


def test_solve_on_a_prepared_problem_equals_integrate(wave):
    n = wave.normals((10, 12), 0.2)
    mask = np.ones((10, 12), bool)
    mask[2:4, 3:6] = False
    a = facetlift.integrate(n, mask, pixel_size=0.2, solver="iterative")
    b = facetlift.solve(facetlift.prepare(n, mask, pixel_size=0.2), "dgp", solver="iterative")
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.vertex_depth, b.vertex_depth)
    assert b.info["method"] == "dgp" and b.info["solver"] == "iterative"


def test_integrate_accepts_lists_and_does_not_modify_input(saddle):
    n = saddle.normals((5, 6), 0.3)
    n[1, 1] = np.nan
    mask = np.ones((5, 6), bool)
    n0 = n.copy()
    s = facetlift.integrate(n.tolist(), mask.tolist(), pixel_size=0.3)
    assert np.array_equal(n, n0, equal_nan=True)
    t = facetlift.integrate(n, mask, pixel_size=0.3)
    np.testing.assert_array_equal(s.depth, t.depth)


def test_library_does_not_print(wave, capsys):
    facetlift.integrate(wave.normals((8, 8), 0.25), pixel_size=0.25, solver="iterative")
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


def test_unknown_method(wave):
    with pytest.raises(ValueError, match=r"`method` must be one of \[.*'dgp'.*\]; got 'dgq'"):
        facetlift.integrate(wave.normals((4, 4)), method="dgq")


def test_unknown_method_is_checked_before_the_input():
    with pytest.raises(ValueError, match="`method` must be one of"):
        facetlift.integrate(np.ones((4, 4)), method="nope")


def test_unknown_option_lists_valid_options(wave):
    with pytest.raises(
        ValueError,
        match=r"unknown option\(s\) \['bogus', 'tolerance'\] for method 'dgp'; valid options: "
        r"\[.*'max_iter'.*'solver'.*'tol'.*\]",
    ):
        facetlift.integrate(wave.normals((4, 4)), bogus=1, tolerance=1e-3)


def test_options_are_forwarded(fake_method, wave):
    box = fake_method(missing=True)
    facetlift.integrate(wave.normals((4, 5)), method="fake", scale=2.5)
    assert box["options"] == {"scale": 2.5, "flag": False}
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['solver'\] for method 'fake'; "
                       r"valid options: \['flag', 'scale'\]"):
        facetlift.integrate(wave.normals((4, 5)), method="fake", solver="direct")


def _missing_input(wave):
    n = wave.normals((6, 6), 0.2)
    n[2, 3] = np.nan
    return n, np.ones((6, 6), bool)


def test_method_without_missing_support_refuses_missing_samples(fake_method, wave):
    box = fake_method(missing=False)
    n, mask = _missing_input(wave)
    with pytest.raises(ValueError, match=r"method 'fake' cannot take missing samples \(1 pixels"):
        facetlift.integrate(n, mask, method="fake")
    known = np.ones((6, 6), bool)
    known[0, 0] = False
    with pytest.raises(ValueError, match=r"cannot take missing samples \(1 pixels"):
        facetlift.integrate(wave.normals((6, 6), 0.2), known=known, method="fake")
    assert box["calls"] == 0  # refused before running
    facetlift.integrate(wave.normals((6, 6), 0.2), method="fake")  # complete input is fine
    assert box["calls"] == 1


@pytest.mark.parametrize("name", sorted(n for n, i in methods.REGISTRY.items() if not i.missing))
def test_registered_methods_without_missing_support_refuse(wave, name):
    if importlib.util.find_spec(f"facetlift.methods.{methods.REGISTRY[name].module}") is None:
        pytest.skip(f"method module {name!r} not written yet")
    n, mask = _missing_input(wave)
    with pytest.raises(ValueError, match=f"method '{name}' cannot take missing samples"):
        facetlift.integrate(n, mask, method=name)


def test_method_without_perspective_refuses_K(fake_method, wave):
    box = fake_method(missing=True, perspective=False)
    K = [[100.0, 0.0, 2.0], [0.0, 100.0, 2.0], [0.0, 0.0, 1.0]]
    with pytest.raises(ValueError, match=r"method 'fake' does not support perspective input"):
        facetlift.integrate(wave.normals((5, 5)), method="fake", K=K)
    assert box["calls"] == 0


def test_surface_from_facet_depths_only(fake_method):
    """A method returning facet depths: vertex depths are the mean of the adjacent facets,
    and each component's mean facet depth is zero (orthographic)."""
    mask = np.zeros((6, 9), bool)
    mask[1:5, 1:4] = True
    mask[1:5, 6:8] = True
    box = fake_method()
    rng = np.random.default_rng(0)
    raw = {}

    def result(problem):
        raw["d"] = rng.normal(size=problem.domain.n_facets) + 10 * problem.domain.facet_component
        return MethodResult(values=-raw["d"])  # heights

    box["result"] = result
    s = facetlift.integrate(np.dstack([np.zeros((6, 9, 2)), np.ones((6, 9))]), mask,
                            method="fake")
    # the method saw the mask's bounding box (api.crop); same facets, same order
    assert box["problem"].domain.n_facets == int(mask.sum())
    d = facetlift.prepare(np.dstack([np.zeros((6, 9, 2)), np.ones((6, 9))]), mask).domain
    for k in range(d.n_components):
        part = d.facet_component == k
        np.testing.assert_allclose(s.depth[d.pixels][part],
                                   raw["d"][part] - raw["d"][part].mean(), atol=1e-12)
        assert abs(s.depth[d.labels == k + 1].mean()) < 1e-12
    f = s.depth
    # vertex (i, j) touches pixels (i-1..i, j-1..j): (2, 2) four domain pixels, (1, 1) only
    # pixel (1, 1), (1, 2) pixels (1, 1) and (1, 2)
    np.testing.assert_allclose(s.vertex_depth[2, 2], f[1:3, 1:3].mean(), atol=1e-12)
    np.testing.assert_allclose(s.vertex_depth[1, 1], f[1, 1], atol=1e-12)
    np.testing.assert_allclose(s.vertex_depth[1, 2], f[1, 1:3].mean(), atol=1e-12)


def test_surface_from_vertex_depths_only(fake_method):
    mask = np.ones((4, 5), bool)
    box = fake_method()
    rng = np.random.default_rng(1)
    raw = {}

    def result(problem):
        raw["v"] = rng.normal(size=problem.domain.n_vertices) + 3.0
        return MethodResult(vertex_values=-raw["v"])  # heights

    box["result"] = result
    s = facetlift.integrate(np.dstack([np.zeros((4, 5, 2)), np.ones((4, 5))]), mask,
                            method="fake")
    v = raw["v"].reshape(5, 6)
    centres = (v[:-1, :-1] + v[:-1, 1:] + v[1:, 1:] + v[1:, :-1]) / 4
    shift = centres.mean()
    np.testing.assert_allclose(s.depth, centres - shift, atol=1e-12)
    np.testing.assert_allclose(s.vertex_depth, v - shift, atol=1e-12)


def test_perspective_values_are_log_depth_with_median_one(fake_method):
    box = fake_method(perspective=True)
    logd = np.log([1.0, 2.0, 4.0, 8.0, 16.0] * 3 + [1.0])
    box["result"] = lambda problem: MethodResult(values=logd + 7.0)
    K = [[100.0, 0.0, 2.0], [0.0, 100.0, 2.0], [0.0, 0.0, 1.0]]
    s = facetlift.integrate(np.dstack([np.zeros((4, 4, 2)), np.ones((4, 4))]), K=K,
                            method="fake")
    np.testing.assert_allclose(s.depth.ravel(), np.exp(logd) / 4.0)  # median 4 -> 1
    assert np.isclose(np.median(s.depth), 1.0)
    assert s.K is not None and np.allclose(s.K, K)


def test_non_finite_method_values_are_a_solver_error(fake_method):
    box = fake_method()
    box["result"] = lambda problem: MethodResult(values=np.full(problem.domain.n_facets, np.nan))
    with pytest.raises(facetlift.SolverError, match="non-finite depth at 16 of 16 pixels"):
        facetlift.integrate(np.dstack([np.zeros((4, 4, 2)), np.ones((4, 4))]), method="fake")


def test_methods_see_the_mask_bounding_box_and_results_land_in_place():
    """Integration runs on the mask's bounding box; the Surface is full-size and equal to
    integrating the cropped input, for orthographic and perspective (shifted K) input."""
    H, W = 40, 50
    rr, cc = np.mgrid[0:H, 0:W]
    mask = (rr - 22) ** 2 + (cc - 30) ** 2 < 100
    p = 0.01 * (cc - 30.0)
    q = -0.02 * (rr - 22.0)
    normals = facetlift.normals_from_gradients(p, q)
    full = facetlift.integrate(normals, mask)
    r0, c0 = 13, 21
    sub = facetlift.integrate(normals[r0:32, c0:40], mask[r0:32, c0:40])
    assert full.depth.shape == (H, W) and np.isnan(full.depth[~mask]).all()
    np.testing.assert_allclose(full.depth[r0:32, c0:40], sub.depth, atol=1e-10)
    np.testing.assert_allclose(full.vertex_depth[r0:33, c0:41], sub.vertex_depth, atol=1e-10)
    K = np.array([[80.0, 0, 24.5], [0, 80.0, 19.5], [0, 0, 1]])
    Ks = K.copy()
    Ks[0, 2] -= c0
    Ks[1, 2] -= r0
    a = facetlift.integrate(normals, mask, K=K)
    b = facetlift.integrate(normals[r0:32, c0:40], mask[r0:32, c0:40], K=Ks)
    np.testing.assert_allclose(a.depth[r0:32, c0:40], b.depth, rtol=1e-10)
    np.testing.assert_array_equal(a.K, K)
    np.testing.assert_allclose(a.points(), b.points(), rtol=1e-10)


def test_corner_copies_give_a_mesh_split_at_the_jumps(fake_method, tmp_path):
    """A method that returns per-facet corner values (a discontinuity-preserving route): the
    Surface is cut where neighbouring facets' copies part, its mesh is split there (vertices
    duplicated, no face across the jump) and depth is the mean of each facet's mesh corners."""
    H, W = 6, 8
    box = fake_method()
    step = 5.0

    def result(problem):
        r, c = problem.domain.pixels
        # heights at the four corners of every facet: plane 0.1 x, plus `step` for columns >= 4
        x = np.stack([c, c + 1, c + 1, c], axis=1).astype(float)
        y = np.stack([r, r, r + 1, r + 1], axis=1) * 0.0
        copies = 0.1 * x + y + np.where(c >= 4, step, 0.0)[:, None]
        return MethodResult(values=copies.mean(axis=1), extras={"corner_values": copies})

    box["result"] = result
    mask = np.ones((H, W), bool)
    s = facetlift.integrate(np.dstack([np.zeros((H, W, 2)), np.ones((H, W))]), mask,
                            method="fake")
    right, down = s.cuts
    assert right[:, 3].all() and right.sum() == H and not down.any()
    assert np.allclose(s.discontinuities[:, 3:5], step) and np.all(s.discontinuities[:, :3] == 0)
    assert np.all(s.discontinuities[:, 5:] == 0)
    verts, quads = s.to_mesh()
    assert len(verts) == (H + 1) * (W + 1) + (H + 1)  # the column of vertices on the cut, twice
    z = verts[:, 2]  # height = -depth
    assert np.ptp(z[quads], axis=1).max() < 0.2 + 1e-9  # no face spans the jump
    np.testing.assert_allclose((-z[quads]).mean(axis=1), s.depth[mask], atol=1e-12)
    s.save(tmp_path / "m.ply")
    s.save(tmp_path / "s.npz")
    with np.load(tmp_path / "s.npz") as f:
        assert f["cuts_right"].sum() == H and "discontinuities" in f
    out = s.save(tmp_path / "d.png")
    assert out.read_bytes()[:4] == b"\x89PNG"
    from facetlift import io

    io.write_discontinuities(tmp_path / "j.png", s)
    plain = facetlift.integrate(np.dstack([np.zeros((H, W, 2)), np.ones((H, W))]))
    with pytest.raises(ValueError, match="no discontinuity map: integrate with"):
        io.write_discontinuities(tmp_path / "k.png", plain)
    # bini with discontinuities=True was told to integrate with discontinuities=True (an
    # audit): the method is named, and the one that makes a map
    bini = facetlift.integrate(np.dstack([np.zeros((H, W, 2)), np.ones((H, W))]),
                               method="bini", discontinuities=True)
    with pytest.raises(ValueError, match=r"method 'bini' does not make one \(it comes only "
                       r"from \['dgp'\]"):
        io.write_discontinuities(tmp_path / "b.png", bini)


def test_submodules_are_attributes_of_a_plain_import():
    """``import facetlift`` then ``facetlift.io.read_mask`` (as the docs write it) works, and
    importing facetlift still loads none of them."""
    import subprocess

    code = ("import sys, facetlift; assert 'facetlift.io' not in sys.modules; "
            "facetlift.io.read_mask; facetlift.synthetic.analytic; facetlift.metrics.made; "
            "print('ok')")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.stdout.strip() == "ok", res.stderr
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        facetlift.nothing  # noqa: B018


@pytest.mark.parametrize("method", ["frankot_chellappa", "kernel", "poisson"])
def test_every_method_reports_iterations_and_converged(method):
    n = np.dstack([np.zeros((8, 9, 2)), np.ones((8, 9))])
    info = facetlift.integrate(n, method=method).info
    assert info["iterations"] >= 1 and info["converged"] is True


def test_warning_kinds_can_be_turned_into_errors_one_by_one():
    """A library could not make "wrong frame" or "not converged" an error without matching
    the message: every warning was a plain UserWarning but the unusable-normals one."""
    import warnings

    from facetlift import synthetic

    g = synthetic.analytic("sphere", 48)
    flipped = g.normals * np.array([1.0, -1.0, 1.0])  # (y down: the frame is wrong)
    for kind in (facetlift.FrameWarning, facetlift.ConvergenceWarning,
                 facetlift.UnusableNormalsWarning, facetlift.LayoutWarning):
        assert issubclass(kind, UserWarning)
    assert issubclass(facetlift.LayoutWarning, facetlift.FrameWarning)
    with warnings.catch_warnings():
        warnings.simplefilter("error", facetlift.FrameWarning)
        facetlift.integrate(g.normals, g.mask)  # (the right frame: no warning)
        with pytest.raises(facetlift.FrameWarning, match="y flipped"):
            facetlift.integrate(flipped, g.mask)
        with pytest.raises(facetlift.FrameWarning, match="decoded"):
            facetlift.integrate(np.round((g.normals + 1) / 2 * 255).astype(np.uint8), g.mask)
    with warnings.catch_warnings():
        warnings.simplefilter("error", facetlift.ConvergenceWarning)
        with pytest.raises(facetlift.ConvergenceWarning, match="bini"):
            facetlift.integrate(g.normals, g.mask, method="bini", max_iter=1)


def test_a_string_prior_for_a_method_without_the_option_names_prior():
    """It said "unknown option(s) ['prior'] for method 'dgp'", while dgp takes a depth prior."""
    from facetlift import synthetic

    g = synthetic.analytic("sphere", 16)
    with pytest.raises(ValueError, match=r"`prior` must be a depth map .* 'dgp' has none"):
        facetlift.integrate(g.normals, g.mask, prior="abc")


def test_a_pinhole_camera_object_is_taken_as_k():
    from facetlift import synthetic

    g = synthetic.analytic("sphere", 16)
    K = np.array([[20.0, 0, 8], [0, 20.0, 8], [0, 0, 1]])
    a = facetlift.integrate(g.normals, g.mask, K=facetlift.Pinhole(K))
    b = facetlift.integrate(g.normals, g.mask, K=K)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)


def test_progress_true_shows_the_command_lines_bar(capsys):
    """A sixth fresh-user check: progress=True was refused (a callable or None); it is the
    command line's bar, on stderr, closed after the solve."""
    import threading

    from facetlift import synthetic

    gt = synthetic.analytic("occluder", 48)
    s = facetlift.integrate(gt.normals, gt.mask, discontinuities=True, progress=True)
    err = capsys.readouterr().err
    start = "start from the normals' curl" if s.info["seeded_corners"] else "smooth start"
    assert s.info["iterations"] > 0 and "reweighting" in err and start in err
    assert not [t for t in threading.enumerate() if t.name == "facetlift-progress"]
    with pytest.raises(ValueError, match=r"`progress` must be True \(a progress bar on stderr\), "
                       r"False, a callable or None; got .yes."):
        facetlift.integrate(gt.normals, gt.mask, progress="yes")


def test_small_api_messages_a_user_met(tmp_path):
    """A missing file is a FileNotFoundError (and the ValueError every bad input raises);
    integrate_gradients names p and q, not the normals it made; a misspelt option gets the
    names it may have meant."""
    from facetlift import io
    from facetlift.errors import InputFileNotFound

    with pytest.raises(FileNotFoundError, match=r"`path`: file .*nope.png does not exist"):
        io.read_normals(tmp_path / "nope.png")
    with pytest.raises(ValueError, match="does not exist"):
        io.read_normals(tmp_path / "nope.png")
    assert issubclass(InputFileNotFound, ValueError)
    with pytest.raises(ValueError, match=r"^`p` and `q` have no pixel where both are finite"):
        facetlift.integrate_gradients(np.full((10, 10), np.nan), np.zeros((10, 10)))
    n = np.zeros((10, 10, 3))
    n[..., 2] = 1.0
    # best first: the one option taking True before those the ratio ranks higher (a review:
    # 'discontinuities' came last)
    with pytest.raises(ValueError, match=r"did you mean 'discontinuities' or 'discontinuity_k' "
                       r"or 'discontinuity_tol' for 'discontinuity'\?"):
        facetlift.integrate(n, discontinuity=True)
    with pytest.raises(ValueError, match=r"did you mean 'discontinuity_k' or "
                       r"'discontinuity_tol' or 'discontinuities' for 'discontinuity'\?"):
        facetlift.integrate(n, discontinuity=2.0)
    with pytest.raises(ValueError, match=r"`method` must be one of .*; got 'DGP'; did you mean "
                       r"'dgp'\?"):
        facetlift.integrate(n, method="DGP")
    with pytest.raises(ValueError, match=r"did you mean 'max_iter' for 'maxiter'\?"):
        facetlift.integrate(n, maxiter=3)


def test_a_misspelt_keyword_of_integrate_is_suggested():
    """integrate's own keywords are offered for a misspelt one (normal_frmae was told the
    method's options alone, a user's check); the list is integrate's signature."""
    import inspect

    from facetlift import api

    own = set(inspect.signature(api.integrate).parameters) - {"normals", "options"}
    assert set(api._INTEGRATE_KEYWORDS) == own
    n = np.zeros((10, 10, 3))
    n[..., 2] = 1.0
    with pytest.raises(ValueError, match=r"did you mean 'normal_frame' for 'normal_frmae'\?"):
        facetlift.integrate(n, normal_frmae="opencv")


def test_fov_is_pointed_to_k_from_fov():
    """An audit: integrate(n, fov=60), the command line's --fov in Python, was told "unknown
    option(s) ['fov']" and the method's options alone; the message gives the K to pass (no
    fov keyword: K is the one camera argument), and a misspelling beside it is still
    suggested."""
    n = np.zeros((10, 12, 3))
    n[..., 2] = 1.0
    for method in ("dgp", "bini"):
        with pytest.raises(ValueError, match=r"unknown option\(s\) \['fov'\].*integrate takes "
                           r"no field of view: give the camera it makes as "
                           r"K=facetlift\.camera\.K_from_fov\(normals\.shape\[:2\], 60\)"):
            facetlift.integrate(n, method=method, fov=60)
    with pytest.raises(ValueError, match=r"did you mean 'max_iter' for 'maxiter'\?; integrate "
                       r"takes no field of view: .*K_from_fov\(normals\.shape\[:2\], 72\.5\)"):
        facetlift.integrate(n, fov=72.5, maxiter=3)
    K = facetlift.camera.K_from_fov(n.shape[:2], 60)  # (what the message says works)
    facetlift.integrate(n, K=K)


def test_progress_is_accepted_by_every_method():
    """progress= is a general argument (the README's, the command line's --progress): a
    method without iterations has nothing to report, and frankot_chellappa refused it (a
    user's check); an option the method lacks is not suggested as itself."""
    n = np.zeros((12, 14, 3))
    n[..., 2] = 1.0
    seen = []
    for method in facetlift.METHODS:
        facetlift.integrate(n, method=method, progress=lambda *a: seen.append(a))
        facetlift.integrate(n, method=method, progress=True)
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['solver'\] for method "
                       r"'poisson'; valid options: \['backend', 'progress'\]$"):
        facetlift.integrate(n, method="poisson", solver="iterative")


def test_a_camera_a_method_cannot_take_is_refused_before_the_input_is_checked():
    """--method kernel with --K printed the input's warnings (grazing normals) and then the
    refusal (a user's check): the refusal comes first, alone."""
    import warnings

    n = np.zeros((12, 14, 3))
    n[..., 2] = 1.0
    n[3, 4] = [0.0, 0.0, -1.0]  # (back-facing: a warning if the input were checked)
    K = np.array([[20.0, 0, 6.5], [0, 20.0, 5.5], [0, 0, 1]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"method 'kernel' does not support perspective"):
            facetlift.integrate(n, method="kernel", K=K)


def test_inputs_an_audit_of_the_api_refused_or_misread():
    """An audit of the Python API: normals scaled by 1e-3 (half of them negative) were
    refused as [0, 1]-encoded; np.True_ was refused by every bool option (numpy 2 names its
    type "bool"); big-endian uint16 was refused as "not uint16"; Surface.from_depth took a
    masked array's hidden values and a NaN mask; prepare(camera=...) dropped K= in silence and
    took a string; progress=False was refused."""
    from facetlift import synthetic
    from facetlift.camera import Orthographic
    from facetlift.surface import Surface

    gt = synthetic.analytic("sphere", 32)
    ref = facetlift.integrate(gt.normals, gt.mask).depth
    for scale in (1e-3, 1e-8):
        np.testing.assert_allclose(facetlift.integrate(gt.normals * scale, gt.mask).depth, ref,
                                   atol=1e-9)
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded"):  # (still refused)
        facetlift.integrate((gt.normals + 1) / 2, gt.mask)
    small = np.zeros((32, 32), bool)  # (an encoded object on a white background, 6 % of the
    small[13:21, 13:21] = True  # image: it passed with the first version of the rule, a review)
    with pytest.raises(ValueError, match=r"looks \[0, 1\]-encoded"):
        facetlift.integrate(np.where(small[..., None], (gt.normals + 1) / 2, 1.0))
    s = facetlift.integrate(gt.normals, gt.mask, discontinuities=True,
                            discontinuity_seed=np.True_)
    assert s.info["method"] == "dgp"
    facetlift.integrate(gt.normals, gt.mask, solver="iterative", mean_subtraction=np.False_)
    u = np.round((np.where(gt.mask[..., None], gt.normals, [0, 0, 1]) + 1) / 2 * 65535)
    with pytest.warns(UserWarning, match=r"decoded as v / 65535"):
        a = facetlift.integrate(u.astype(np.uint16), gt.mask).depth
    with pytest.warns(UserWarning, match=r"decoded as v / 65535"):
        b = facetlift.integrate(u.astype(">u2"), gt.mask).depth
    np.testing.assert_array_equal(a, b)
    depth = np.fromfunction(lambda r, c: 5 + 0.01 * r + 0.02 * c, (20, 20))
    hidden = np.ma.masked_array(depth.copy(), mask=np.zeros((20, 20), bool))
    hidden.mask[5, 5] = True
    hidden.data[5, 5] = 1e6
    surf = Surface.from_depth(hidden)
    assert not surf.mask[5, 5] and np.nanmax(surf.vertex_depth) < 6
    with pytest.raises(ValueError, match=r"`mask` contains NaN"):
        Surface.from_depth(depth, np.full((20, 20), np.nan))
    with pytest.raises(ValueError, match=r"`depth` must be a real numeric array"):
        Surface.from_depth("abc")
    with pytest.raises(ValueError, match=r"give `camera`, or `K` / `pixel_size`, not both"):
        facetlift.prepare(gt.normals, gt.mask, camera=Orthographic(1.0), K=np.eye(3))
    with pytest.raises(ValueError, match=r"`camera` must be a facetlift.camera.Camera"):
        facetlift.prepare(gt.normals, gt.mask, camera="pinhole")
    facetlift.integrate(gt.normals, gt.mask, progress=False)
    facetlift.integrate(gt.normals, gt.mask, progress=np.False_)
    with pytest.raises(ValueError, match=r"`progress` must be True .*; got 'garbage'"):
        facetlift.integrate(gt.normals, gt.mask, method="frankot_chellappa", progress="garbage")
    problem = facetlift.prepare(gt.normals, gt.mask)
    facetlift.solve(problem, "frankot_chellappa", progress=lambda i, v: None)


def test_another_threads_filters_hold_while_one_records():
    """While one thread recorded its warnings (prior_fit, jobs, batch items), every other
    thread's warnings were shown unfiltered: a simplefilter('error', FrameWarning) did not
    raise (an audit)."""
    import threading
    import warnings

    face = synthetic.analytic("face", 48)
    sph = synthetic.analytic("sphere", 48)
    prior = np.where(np.random.default_rng(0).random((48, 48)) < 0.05, sph.depth * 2 + 1,
                     np.nan)
    inside, release = threading.Event(), threading.Event()

    def hold(i, v):
        inside.set()
        release.wait(30)

    t = threading.Thread(target=facetlift.integrate, args=(sph.normals, sph.mask),
                         kwargs=dict(prior=prior, prior_fit="affine", progress=hold))
    with warnings.catch_warnings():
        warnings.simplefilter("error", facetlift.FrameWarning)
        t.start()
        try:
            assert inside.wait(30)
            with pytest.raises(facetlift.FrameWarning):
                facetlift.integrate(face.normals * [1, -1, 1], face.mask)
        finally:
            release.set()
            t.join()


def test_prior_fit_passes_on_warnings_that_are_not_its_own():
    """A progress callback's warning in prior_fit's first run was dropped with the input's
    warnings that the second run repeats (an audit)."""
    import warnings

    sph = synthetic.analytic("sphere", 48)
    prior = np.where(np.random.default_rng(0).random((48, 48)) < 0.05, sph.depth * 2 + 1,
                     np.nan)
    said = []

    def callback(i, v):
        if not said:
            said.append(i)
            warnings.warn("the callback's own warning", stacklevel=2)

    with pytest.warns(UserWarning, match="the callback's own warning"):
        facetlift.integrate(sph.normals, sph.mask, prior=prior, prior_fit="affine",
                            progress=callback)


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs os.fork")
def test_a_child_forked_beside_a_limited_call_gets_the_process_limits_back():
    """A fork while another thread was inside a BLAS-limited or recording call left the child
    on one BLAS thread and with its warning filters at 'always' for its life (an audit)."""
    import os
    import threading
    import warnings

    from threadpoolctl import threadpool_info

    from facetlift import _threads, _warnings

    before = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
    inside, release = threading.Event(), threading.Event()

    def hold():
        with _threads.blas_limit(1), _warnings.recording():
            inside.set()
            release.wait(30)

    t = threading.Thread(target=hold)
    t.start()
    try:
        assert inside.wait(30)
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # (the child: report and leave at once)
            try:
                blas = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
                ok = (blas == before and _threads._STATE["depth"] == 0
                      and _warnings._SHARED["depth"] == 0
                      and warnings.showwarning is not _warnings._dispatch)
                os.write(w, b"1" if ok else repr((blas, before)).encode())
            finally:
                os._exit(0)
        os.close(w)
        said = os.read(r, 200)
        os.waitpid(pid, 0)
    finally:
        release.set()
        t.join()
    assert said == b"1", said


class _AnotherThreadRecords:
    """A block during which another thread is inside facetlift's warning capture
    (``_warnings.recording``), as a prior_fit call or a batch item in a thread is."""

    def __enter__(self):
        import threading

        from facetlift import _warnings

        self.inside, self.release = threading.Event(), threading.Event()

        def hold():
            with _warnings.recording():
                self.inside.set()
                self.release.wait(30)

        self.thread = threading.Thread(target=hold)
        self.thread.start()
        assert self.inside.wait(30)
        return self

    def __exit__(self, *exc):
        self.release.set()
        self.thread.join()
        return False


def test_module_filters_hold_in_other_threads_while_one_records():
    """A filter's module= is matched against the module's name (numpy._core..., the test
    module), not the file's base name, while another thread records (a review)."""
    import warnings

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", module="numpy")
        warnings.filterwarnings("error", message="raised here", module=__name__)
        with _AnotherThreadRecords():
            np.mean(np.array([]))  # (numpy's RuntimeWarning: ignored)
            with pytest.raises(UserWarning, match="raised here"):
                warnings.warn("raised here", stacklevel=1)
    assert not [w for w in seen if issubclass(w.category, RuntimeWarning)]


def test_plain_string_filters_of_python_itself_hold_while_one_records():
    """Python's own default filter for __main__'s DeprecationWarnings holds its module as a
    plain string: matching it as a regex raised an AttributeError inside any deprecation
    warning of another thread while a facetlift job recorded (a review)."""
    import warnings

    with warnings.catch_warnings(record=True) as seen:
        warnings.resetwarnings()
        warnings.filters.insert(0, ("always", None, DeprecationWarning, __name__, 0))
        with _AnotherThreadRecords():
            warnings.warn("an old API", DeprecationWarning, stacklevel=1)
    assert [str(w.message) for w in seen] == ["an old API"]


def test_a_notebook_sees_batch_parameters_and_a_missing_q_is_named():
    """A notebook audit: inspect.signature(facetlift.batch) gave (*args, **kwargs) and
    `facetlift.batch?` the module's text; integrate_gradients(pq, None) said "`q` must be a
    real numeric array; got dtype object"."""
    import inspect

    import numpy as np

    import facetlift
    from facetlift.batch import batch as batch_function

    assert inspect.signature(facetlift.batch) == inspect.signature(batch_function)
    assert facetlift.batch.__call__.__doc__ == batch_function.__doc__
    with pytest.raises(ValueError, match=r"`q` is required.*give p\[\.\.\., 0\] and "
                       r"p\[\.\.\., 1\]"):
        facetlift.integrate_gradients(np.zeros((8, 9, 2)), None)


def _undecoded_sphere():
    g = synthetic.analytic("sphere", 48)
    u8 = np.round((np.nan_to_num(g.normals) + 1) / 2 * 255).astype(np.uint8)
    return g, u8


@pytest.mark.parametrize("dtype", [int, np.int16, np.int32])
def test_an_undecoded_map_held_as_signed_integers_is_refused(dtype):
    """img.astype(int) before arithmetic: the raw 0..255 went through as normals without a
    word (an audit: 2.0 degrees of mean deviation for a surface 11.5 RMS off on a range of
    19.7). Refused now, as the same values in floats are."""
    g, u8 = _undecoded_sphere()
    with pytest.raises(ValueError, match=r"looks like an undecoded 8-bit normal map"):
        facetlift.integrate(u8.astype(dtype), g.mask)
    # (a map stored as n * 127 in int8 is no encoding of [0, 255]: it integrates)
    s = facetlift.integrate(np.round(np.nan_to_num(g.normals) * 127).astype(np.int8), g.mask)
    ref = facetlift.integrate(g.normals, g.mask)
    assert np.nanmax(np.abs(s.depth - ref.depth)) < 0.05 * np.nanmax(np.abs(ref.depth))


def test_prepare_checks_the_normals_as_integrate_does():
    """facetlift.prepare + solve skipped integrate's checks of the input: a uint8 map was read
    as raw 0..255, undecoded floats went through (an audit)."""
    g, u8 = _undecoded_sphere()
    with pytest.warns(facetlift.FrameWarning, match=r"uint8: decoded as v / 255"):
        p = facetlift.prepare(u8, g.mask)
    want = facetlift.integrate(g.normals, g.mask)
    got = facetlift.solve(p)
    assert np.nanmax(np.abs(got.depth - want.depth)) < 0.05 * np.nanmax(np.abs(want.depth))
    with pytest.raises(ValueError, match=r"looks like an undecoded 8-bit normal map"):
        facetlift.prepare(u8.astype(float), mask=g.mask)
    assert facetlift.prepare.__doc__.startswith("Check user inputs")


def test_negative_mask_values_count_as_outside(tmp_path):
    """A logit mask (-5 outside, 5 inside) made every pixel inside as nonzero, the
    background's NaN normals filled in as surface without a word (an audit)."""
    from facetlift import io

    g = synthetic.analytic("sphere", 48)
    with pytest.warns(UserWarning, match=r"`mask` holds \d+ negative values.*count as outside"):
        s = facetlift.integrate(g.normals, np.where(g.mask, 5.0, -5.0))
    np.testing.assert_array_equal(s.mask, g.mask)
    np.save(tmp_path / "logit.npy", np.where(g.mask, 2.0, -2.0))
    with pytest.warns(UserWarning, match=r"negative values"):
        np.testing.assert_array_equal(io.read_mask(tmp_path / "logit.npy"), g.mask)


def test_camera_objects_given_to_integrate_are_taken_or_named():
    """K=Orthographic(2) said "must be a real numeric array; got dtype object", camera= was
    told of dgp's options alone, and a Pinhole's repr could not make one (an audit)."""
    from facetlift.camera import Orthographic, Pinhole

    n = facetlift.normals_from_gradients(np.full((8, 9), 0.1), np.zeros((8, 9)))
    with pytest.raises(ValueError, match=r"`K` is an orthographic camera.*pixel_size=2"):
        facetlift.integrate(n, K=Orthographic(2.0))
    with pytest.raises(ValueError, match=r"integrate takes the camera as K="):
        facetlift.integrate(n, camera=Orthographic(2.0))
    K = [[60.123456789, 0.5, 15.25], [0.0, 61.0, 12.0], [0.0, 0.0, 1.0]]
    cam = eval(repr(Pinhole(K)), {"Pinhole": Pinhole})
    np.testing.assert_array_equal(cam.K, K)


def test_a_progress_callable_of_the_wrong_arity_is_refused_before_the_solve():
    """progress=lambda i: ... failed as a TypeError once the solve had begun (an audit)."""
    n = facetlift.normals_from_gradients(np.full((8, 9), 0.1), np.zeros((8, 9)))
    with pytest.raises(ValueError, match=r"progress\(iteration, value\).*cannot take two"):
        facetlift.integrate(n, solver="iterative", progress=lambda i: None)
    seen = []
    facetlift.integrate(n, solver="iterative", max_iter=2, progress=lambda *a: seen.append(a))
    assert seen and all(len(a) == 2 for a in seen)
