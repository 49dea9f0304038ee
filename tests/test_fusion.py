"""Depth priors and normal confidences (docs/fusion.md): limits, identities, every error path."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import methods
from facetlift.cli import main

FUSING = [name for name, info in methods.REGISTRY.items() if info.prior]
ROUTES = [("dgp", {}), ("dgp", {"solver": "iterative", "tol": 1e-7, "max_iter": 20000}),
          ("dgp", {"discontinuities": True}), ("poisson", {}), ("m_estimator", {}),
          ("alpha_surface", {})]


def wave(shape=(24, 28)):
    """A smooth height field: normals, its depth (height = -depth), full mask."""
    H, W = shape
    r, c = np.indices(shape)
    x, y = c + 0.5, -(r + 0.5)
    z = 2.0 * np.sin(x / 7.0) * np.cos(y / 9.0)
    p = 2.0 / 7.0 * np.cos(x / 7.0) * np.cos(y / 9.0)
    q = -2.0 / 9.0 * np.sin(x / 7.0) * np.sin(y / 9.0)
    return facetlift.normals_from_gradients(p, q), -z


def sparse(depth, fraction=0.05, seed=0):
    rng = np.random.default_rng(seed)
    sel = rng.random(depth.shape) < fraction
    return np.where(sel, depth, np.nan), sel


def run(normals, mask=None, method="dgp", options=None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return facetlift.integrate(normals, mask, method=method, **(options or {}), **kw)


def test_registry_declares_prior_and_confidence():
    assert "prior" in methods.CAPABILITIES and "confidence" in methods.CAPABILITIES
    assert {"dgp", "poisson"} <= set(FUSING)
    assert not methods.REGISTRY["frankot_chellappa"].prior


@pytest.mark.parametrize("method,options", ROUTES)
def test_huge_weight_returns_the_prior_where_given(method, options):
    n, depth = wave()
    # a prior that disagrees with the normals; the discontinuity route's output mesh merges
    # facet copies closer than GAP footprints (operators.split), so there the samples agree
    # with the normals up to a constant the normals cannot see
    rng = np.random.default_rng(5)
    noise = 0.0 if options.get("discontinuities") else rng.normal(0, 0.3, depth.shape)
    prior, sel = sparse(depth + 0.3 + noise, 0.05)
    s = run(n, method=method, options=options, prior=prior, prior_weight=1e8)
    # the discontinuity route's output merges facet copies that part by less than GAP
    # footprints: there the samples are met to within that merging (a known limit)
    tol = 0.1 * np.ptp(depth) if options.get("discontinuities") else 1e-3
    assert np.abs(s.depth[sel] - prior[sel]).max() < tol
    assert s.info["prior"]["samples"] == int(sel.sum())
    assert s.info["prior"]["gauged_components"] == []


def test_discontinuities_warn_of_a_prior_weight_above_what_they_solve():
    """A fresh user's exact samples at weight 1e4-1e8 with discontinuities came out worse
    than at 100 (0 CG iterations per reweighting), although the docs promised the prior."""
    import warnings

    from facetlift.methods import dgp

    n, depth = wave()
    prior, _ = sparse(depth, 0.05)
    with pytest.warns(UserWarning, match=r"prior_weight up to 10000: above 100 the "
                      r"reweightings' solves stop"):
        facetlift.integrate(n, discontinuities=True, prior=prior, prior_weight=1e4)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        facetlift.integrate(n, discontinuities=True, prior=prior, prior_weight=dgp.PRIOR_STRONG)


@pytest.mark.parametrize("method,options", ROUTES)
def test_tiny_weight_returns_the_normals_only_result(method, options):
    n, depth = wave()
    prior, sel = sparse(depth + 5.0, 0.05)
    s0 = run(n, method=method, options=options)
    s = run(n, method=method, options=options, prior=prior, prior_weight=1e-9)
    d = s.depth - s0.depth
    assert np.nanstd(d) < 1e-4 * np.ptp(depth)
    # and the constant is the prior's, not today's mean 0
    assert np.nanmean(d) == pytest.approx(np.mean(prior[sel] - s0.depth[sel]), abs=1e-3)


def test_shifting_the_prior_shifts_the_result():
    n, depth = wave()
    prior, _ = sparse(depth, 0.1)
    a = run(n, prior=prior)
    b = run(n, prior=prior + 3.25)
    np.testing.assert_allclose(b.depth - a.depth, 3.25, atol=1e-7)


def test_exact_samples_recover_every_step_height_with_discontinuities():
    H, W = 48, 60
    r, c = np.indices((H, W))
    step = np.digitize(c, [20, 40])
    height = 0.1 * (c + 0.5) + 0.05 * (r + 0.5) + np.array([0.0, 6.0, 15.0])[step]
    n = facetlift.normals_from_gradients(np.full((H, W), 0.1), np.full((H, W), -0.05))
    n[:, [19, 20, 39, 40]] = np.nan  # the risers: no normal says how high a step is
    depth = -height
    prior, sel = sparse(depth, 0.01, seed=3)
    assert all((sel & (step == k)).any() for k in range(3))
    s = run(n, discontinuities=True, prior=prior, prior_weight=100.0)
    for k in range(3):
        inner = (step == k) & ~np.isin(c, [19, 20, 39, 40])
        assert np.nanmedian(np.abs(s.depth - depth)[inner]) < 1e-2, k
    # without the prior the steps' heights are unknowable: far off
    s0 = run(n, discontinuities=True)
    assert np.nanmedian(np.abs(s0.depth - depth - np.nanmean(s0.depth - depth))) > 1.0


def test_one_sample_per_component_moves_the_normals_only_surface_as_a_whole():
    """One depth sample in a component only fixes its constant (an offset; with a camera a
    scale): the discontinuity route keeps the shape it gives without the prior. Run with the
    sample it left out its final weights, closed every pair of pieces and ran the prior's
    reweightings (a point on orthographic cow@front: 0.507 -> 2.334 % of the depth range)."""
    from test_discontinuities import scissor_ortho, scissor_persp

    n, depth, _ = scissor_ortho()
    mask = np.ones(depth.shape, bool)
    mask[:, 60:62] = False  # (a second component, right of the gap)
    free = run(n, mask, discontinuities=True)
    prior = np.full(depth.shape, np.nan)
    prior[40, 10] = 7.5  # (one sample in the larger component, none in the other)
    s = run(n, mask, discontinuities=True, prior=prior, prior_weight=1e-3)
    assert s.info["prior_one_per_component"]
    assert s.depth[40, 10] == pytest.approx(7.5, abs=1e-9)
    big = mask & (np.arange(depth.shape[1]) < 60)
    shift = s.depth - free.depth
    np.testing.assert_allclose(shift[big], 7.5 - free.depth[40, 10], atol=1e-9)
    np.testing.assert_allclose(s.depth[mask & ~big], free.depth[mask & ~big], atol=1e-9)
    assert s.info["prior"]["gauged_components"] == [2]
    prior[20, 65] = -3.0  # (one in each: each moved to its own)
    s = run(n, mask, discontinuities=True, prior=prior)
    assert s.info["prior_one_per_component"]
    np.testing.assert_allclose((s.depth - free.depth)[mask & ~big],
                               -3.0 - free.depth[20, 65], atol=1e-9)
    prior[10, 30] = depth[10, 30]  # (two in one component: the prior's own route)
    assert not run(n, mask, discontinuities=True, prior=prior).info["prior_one_per_component"]
    # a confidence map, scaled or not, and missing normals: the same shape (the facets
    # without a normal kept their weight, a review: 0.01 everywhere made them 100x heavier);
    # a confidence above 1 is not warned about, the one sample's weight does not matter
    holed = n.copy()
    holed[20:30, 40:50] = np.nan
    free = run(holed, mask, discontinuities=True)
    one = np.full(depth.shape, np.nan)
    one[40, 10] = 7.5
    for level in (0.01, 255.0):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s = facetlift.integrate(holed, mask, discontinuities=True, prior=one,
                                    confidence=np.full(depth.shape, level))
        assert not any("`confidence` reaches" in str(w.message) for w in caught), level
        assert np.ptp((s.depth - free.depth)[big & np.isfinite(s.depth)]) < 1e-8, level
    # perspective: the sample sets the scale
    n, K, depth, _ = scissor_persp()
    free = run(n, K=K, discontinuities=True)
    prior = np.full(depth.shape, np.nan)
    prior[30, 20] = 4.0
    s = run(n, K=K, discontinuities=True, prior=prior)
    assert s.info["prior_one_per_component"] and s.depth[30, 20] == pytest.approx(4.0)
    np.testing.assert_allclose(s.depth / free.depth, 4.0 / free.depth[30, 20], rtol=1e-9)
    np.testing.assert_allclose(s.vertex_depth / free.vertex_depth, 4.0 / free.depth[30, 20],
                               rtol=1e-9)


def test_discontinuities_solve_each_reweighting_whatever_the_prior_offset():
    """A prior far from zero dominates the right-hand side; the reweightings' CG tolerance is
    relative to the normals' part, so the surface does not depend on where depth zero is (a
    tolerance relative to the whole right-hand side stopped every reweighting's CG at 0
    iterations: 1.1 depth units apart here)."""
    n, depth = wave((40, 44))
    depth = depth + 3.0 * (np.indices(depth.shape)[1] >= 22)  # a jump the normals do not show
    prior, _ = sparse(depth, 0.02, seed=1)
    near = run(n, discontinuities=True, prior=prior, prior_weight=100.0)
    far = run(n, discontinuities=True, prior=prior + 1e4, prior_weight=100.0)
    assert sum(far.info["cg_iterations"][1:-1]) > len(far.info["cg_iterations"])
    # measured 1.1e-5 apart (1.6e-6 of the depth range)
    np.testing.assert_allclose(far.depth - 1e4, near.depth, atol=1e-4 * np.ptp(depth))


def test_sparse_prior_takes_the_multigrid_trial_and_its_fallback(monkeypatch):
    """Sparse samples: the smooth route solves with a Ruge-Stueben hierarchy first; the facet
    preconditioner's route (forced, or after a failed trial) reaches the same surface."""
    from facetlift.methods.dgp import fixed_point

    n, depth = wave((40, 44))
    prior, _ = sparse(depth, 0.02, seed=2)
    s = run(n, prior=prior, prior_weight=100.0)
    assert s.info["backend"] == "pcg-amg"
    monkeypatch.setattr(fixed_point, "SPARSE_PRIOR", 0.0)  # never tried
    ref = run(n, prior=prior, prior_weight=100.0)
    assert ref.info["backend"] == "pcg-facet"
    np.testing.assert_allclose(s.depth, ref.depth, atol=1e-8 * np.ptp(depth))
    monkeypatch.setattr(fixed_point, "SPARSE_PRIOR", 0.25)
    monkeypatch.setattr(fixed_point, "AMG_TRIAL", 2)  # the trial fails: the facet route goes on
    seen = []
    on = run(n, prior=prior, prior_weight=100.0, progress=lambda it, res: seen.append(it))
    assert on.info["backend"] == "pcg-facet" and on.info["cg_iterations"] > 2
    assert seen == list(range(1, on.info["cg_iterations"] + 1))  # counted on, not restarted
    np.testing.assert_allclose(on.depth, ref.depth, atol=1e-8 * np.ptp(depth))
    # a dense prior, or a component without samples: the facet route directly
    dense = run(n, prior=depth + 0.1, prior_weight=0.01)
    assert dense.info["backend"] == "pcg-facet"


def test_perspective_prior_returns_metric_depth():
    H, W = 30, 40
    K = np.array([[500.0, 0, W / 2], [0, 500.0, H / 2], [0, 0, 1]])
    n = np.zeros((H, W, 3))
    n[..., 2] = 1.0  # a fronto-parallel plane
    prior = np.full((H, W), np.nan)
    prior[5, 7] = prior[20, 30] = 2.5
    s0 = run(n, K=K)
    assert np.nanmedian(s0.depth) == pytest.approx(1.0)
    for method in ("dgp", "poisson"):
        s = run(n, K=K, method=method, prior=prior)
        np.testing.assert_allclose(s.depth, 2.5, rtol=1e-6)
    s = run(n, K=K, prior=(np.array([5, 20]), np.array([7, 30]), np.array([2.5, 2.5])))
    np.testing.assert_allclose(s.depth, 2.5, rtol=1e-6)


def test_components_without_samples_keep_the_gauge_and_info_names_them():
    n, depth = wave((20, 30))
    mask = np.ones((20, 30), bool)
    mask[:, 14:16] = False
    prior = np.full(mask.shape, np.nan)
    prior[3, 3] = 42.0
    s = run(n, mask, prior=prior, prior_weight=1e6)
    assert s.info["prior"]["prior_components"] == [1]
    assert s.info["prior"]["gauged_components"] == [2]
    assert s.depth[3, 3] == pytest.approx(42.0, abs=1e-4)
    assert np.nanmean(s.depth[:, 16:]) == pytest.approx(0.0, abs=1e-9)
    assert s.info["prior"]["outside_mask"] == 0
    prior[5, 14] = prior[6, 15] = 7.0  # (in the gap: no normal there, dropped and counted)
    assert run(n, mask, prior=prior).info["prior"]["outside_mask"] == 2
    prior[5, 14] = prior[6, 15] = np.nan
    # said in a warning too (only info said so: a fresh user's unfixed part sat at the gauge)
    with pytest.warns(UserWarning, match=r"prior: 1 of 2 mask components \(280 of 560 "
                                         r"pixels\) hold no prior sample.*mean height of 0"):
        facetlift.prepare(n, mask, prior=prior)
    prior[3, 20] = 40.0  # (a sample in each: silent)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        facetlift.prepare(n, mask, prior=prior)


@pytest.mark.parametrize("method,options", ROUTES)
def test_confidence_zero_equals_a_missing_normal(method, options):
    n, depth = wave()
    conf = np.ones(depth.shape)
    conf[5:12, 6:15] = 0.0
    conf[15:20, 2:8] = 0.5
    missing = n.copy()
    missing[5:12, 6:15] = np.nan
    c_half = np.where(conf == 0, 1.0, conf)
    full = np.ones(depth.shape, bool)
    a = run(n, full, method=method, options=options, confidence=conf)
    b = run(missing, full, method=method, options=options, confidence=c_half)
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-7 * np.ptp(depth))
    assert a.info["input"]["zero_confidence"] == 63


def test_confidence_lowers_the_weight_of_bad_normals():
    n, depth = wave()
    bad = n.copy()
    bad[5:12, 6:15] = [0.5, 0.0, np.sqrt(0.75)]
    conf = np.ones(depth.shape)
    conf[5:12, 6:15] = 1e-3
    e = [np.abs(run(bad, confidence=c).depth - depth - np.mean(run(bad, confidence=c).depth
                                                               - depth)).mean()
         for c in (None, conf)]
    assert e[1] < 0.2 * e[0]


# ------------------------------------------------------------------------------------------
# error paths


@pytest.mark.parametrize("kwargs,match", [
    ({"prior": np.zeros((5, 5))}, r"`prior` must be an \(H, W\) depth map of shape \(24, 28\)"),
    ({"prior": np.full((24, 28), np.nan)}, "`prior` has no finite depth sample inside the mask"),
    # (every point left out, here two disagreeing in one pixel: said so, an audit)
    ({"prior": (np.array([3, 3]), np.array([4, 4]), np.array([1.0, 5.0]))},
     r"no finite depth sample inside the mask; its points were all left out .*disagreeing"),
    # (inf is left out as unknown: a map of nothing else has no sample)
    ({"prior": np.full((24, 28), np.inf)}, "`prior` has no finite depth sample inside the mask"),
    ({"prior": np.ones((24, 28)), "prior_weight": -1.0}, "`prior_weight` must be a finite "
     "number >= 0; got -1.0"),
    ({"prior": np.ones((24, 28)), "prior_weight": np.full((3, 3), 1.0)},
     r"`prior_weight` must be a number or have shape \(24, 28\)"),
    ({"prior": np.ones((24, 28)), "prior_weight": -np.ones((24, 28))},
     r"`prior_weight` must be finite, >= 0 and <= 1e\+10 where the prior has a sample; got -1.0"),
    ({"prior_weight": 3.0}, "`prior_weight` applies only with a `prior`"),
    ({"prior": np.ones((24, 28)), "prior_weight": 1e300}, r"<= 1e\+10 where the prior"),
    # (a points file's own weights multiply it: the message says so, not prior_weight alone)
    ({"prior": (np.array([3.0, 10.0]), np.array([4.0, 12.0]), np.array([1.0, 1.2]),
                np.array([1.0, 1e5])), "prior_weight": 1e6},
     r"`prior_weight` times the points' own weight \(here 1e\+06 x 100000\) must be finite"),
    ({"prior": np.full((24, 28), 2e200)}, r"`prior` depths must lie within \+-1e\+30"),
    ({"confidence": np.ones((2, 2))}, r"`confidence` must be a number or have shape"),
    ({"confidence": -np.ones((24, 28))},
     r"`confidence` must be finite and >= 0 inside the mask \(NaN there is a "
     r"missing normal\); got -1.0"),
    ({"prior": ([1, 2], [99, 99], [1.0, 2.0])},
     r"2 of the 2 sample\(s\) lie outside the 24 x 28 image.*no sample is inside"),
    ({"prior": ([1, 2], [3], [1.0, 2.0])}, "three arrays of one length"),
    ({"prior": np.ones((24, 28)), "method": "frankot_chellappa"},
     "method 'frankot_chellappa' does not take a `prior`"),
    ({"confidence": np.ones((24, 28)), "method": "kernel"},
     "method 'kernel' does not take a `confidence`"),
    # (BiNI's reference code has a depth term: a BiNI user was told it had none, an audit)
    ({"prior": np.ones((24, 28)), "method": "bini"},
     r"method 'bini' does not take a `prior`; facetlift's 'bini' is BiNI without the "
     r"depth-fusion term of its reference code \(lambda1.*fuse with method 'dgp'"),
])
def test_errors_name_the_argument(kwargs, match):
    n, _ = wave()
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(n, **kwargs)


def test_perspective_prior_must_be_positive():
    n, _ = wave()
    K = np.array([[100.0, 0, 14], [0, 100.0, 12], [0, 0, 1]])
    prior = np.full((24, 28), np.nan)
    prior[3, 4] = -2.0
    with pytest.raises(ValueError, match="`prior` must hold positive z-depths .* got -2.0"):
        facetlift.integrate(n, K=K, prior=prior)
    # a sparse metric map with one sample behind the camera among 50: left out, as points
    # are (it was refused as relative depth, a perspective audit); 4 of 50 are refused
    rng = np.random.default_rng(3)
    idx = rng.choice(24 * 28, 50, replace=False)
    sparse = np.full(24 * 28, np.nan)
    sparse[idx] = 5.0 + rng.random(50)
    sparse[idx[0]] = -5.0
    with pytest.warns(UserWarning, match=r"1 sample\(s\) in the mask with a non-positive"):
        facetlift.integrate(n, K=K, prior=sparse.reshape(24, 28))
    sparse[idx[:4]] = -5.0
    with pytest.raises(ValueError, match=r"`prior` must hold positive z-depths .*\(4 "
                       r"non-positive sample\(s\), 4 of them negative, of 50\); negative "
                       r"samples are left out as bad pixels while they are at most 1% of the "
                       r"nonzero ones, or at most 3 and a quarter of them, and positive ones "
                       r"remain.* if a negative value \(e.g. -1\) marks unknown depths, "
                       r"write NaN"):
        facetlift.integrate(n, K=K, prior=sparse.reshape(24, 28))
    few = np.full(24 * 28, np.nan)  # (3 of 6 negative: a zero-mean relative depth, refused)
    few[idx[:6]] = [-1.0, -0.5, -0.2, 0.3, 0.6, 1.0]
    with pytest.raises(ValueError, match=r"must hold positive z-depths"):
        facetlift.integrate(n, K=K, prior=few.reshape(24, 28))
    # a map of nothing but 0 (a user's check): the message says to write NaN
    with pytest.raises(ValueError, match=r"672 of them are 0: if 0 marks an unknown depth, "
                       "write NaN") as e:
        facetlift.integrate(n, K=K, prior=np.zeros((24, 28)))
    assert "negative samples are left out" not in str(e.value)  # (none is negative)
    # a depth sensor's map, 0 where unknown, with samples: the zeros are left out, said
    prior = np.zeros((24, 28))
    prior[3, 4] = 5.0
    with pytest.warns(UserWarning, match=r"671 sample\(s\) in the mask with a non-positive "
                      r"z-depth .* \(671 of them 0, as a depth sensor marks unknown pixels, "
                      r"or as the near end of a relative map"):
        a = facetlift.integrate(n, K=K, prior=prior).depth
    b = facetlift.integrate(n, K=K, prior=np.where(prior > 0, prior, np.nan)).depth
    np.testing.assert_array_equal(a, b)
    # (a review: the zeros' weights were checked before they were left out, and the zeros
    # outside the mask were counted as unused samples)
    mask = np.ones((24, 28), bool)
    mask[:, :4] = False
    p2 = prior.copy()
    p2[1, 1] = 6.0  # (one real sample outside the mask, beside 95 zeros there)
    with pytest.warns(UserWarning, match="non-positive z-depth"):
        s = facetlift.integrate(n, mask, K=K, prior=p2,
                                prior_weight=np.where(p2 > 0, 1.0, np.nan))
    assert s.info["input"]["prior_outside_mask"] == 1 and s.info["input"]["prior_samples"] == 1
    # orthographic, where 0 is a depth like any other: a warning when the zeros look like a
    # fill (an audit: 40,270 zeros beside 400 samples in mm, no word but the jump hint)
    prior[5:8, 6:9] = 7.0
    with pytest.warns(UserWarning, match=r"662 of its 672 samples in the mask are exactly 0 "
                      r"while the others all lie between 5 and 7: if 0 marks an unknown"):
        facetlift.integrate(n, prior=prior)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prior[10, 10] = -1.0  # (both signs among the others: a relief about 0, no warning)
        facetlift.integrate(n, prior=prior)
        facetlift.integrate(n, prior=np.zeros((24, 28)))  # (a plane at 0: no warning)
    assert not [w for w in caught if "exactly 0" in str(w.message)]


def test_a_few_bad_prior_and_confidence_pixels_do_not_refuse_the_job():
    """An audit: one inf pixel of a dense prior (even outside the mask), one negative depth
    among many with a camera, or one inf or negative confidence refused the whole job; the
    project's rule is that a few bad pixels become missing samples, counted and said."""
    n, _ = wave()
    K = np.array([[100.0, 0, 14], [0, 100.0, 12], [0, 0, 1]])
    mask = np.ones((24, 28), bool)
    mask[0, :] = False
    good = np.full((24, 28), 5.0)
    good[::3, ::3] = np.nan
    base = facetlift.integrate(n, mask, K=K, prior=good).depth
    bad = good.copy()
    bad[0, 0] = np.inf  # (outside the mask)
    bad[5, 6] = -np.inf
    # (counted inside the mask only: a ray caster's inf for "no hit" around the object was
    # warned about, an audit)
    # (the one inside is -inf, said as it is: it read "inf", a review)
    with pytest.warns(UserWarning, match=r"`prior`: 1 pixel\(s\) inside the mask hold -inf, "
                      r"the first at \(row 5, col 6\); they were left out"):
        got = facetlift.integrate(n, mask, K=K, prior=bad).depth
    outside = good.copy()
    outside[~mask] = np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(facetlift.integrate(n, mask, K=K, prior=outside).depth,
                                      base)
    ref = good.copy()
    ref[5, 6] = np.nan
    np.testing.assert_array_equal(got, facetlift.integrate(n, mask, K=K, prior=ref).depth)
    bad = good.copy()
    bad[7, 8] = -4.0  # (one negative sample among hundreds: a bad pixel)
    with pytest.warns(UserWarning, match=r"1 sample\(s\) in the mask with a non-positive "
                      r"z-depth .*the first -4.0 at \(row 7, col 8\); they were left out"):
        got = facetlift.integrate(n, mask, K=K, prior=bad).depth
    ref = good.copy()
    ref[7, 8] = np.nan
    np.testing.assert_array_equal(got, facetlift.integrate(n, mask, K=K, prior=ref).depth)
    assert np.isfinite(base).any()
    bad = good.copy()
    bad[::2] = -5.0  # (half of them negative: relative depth, refused)
    with pytest.raises(ValueError, match=r"positive z-depths .*negative.*prior_fit"):
        facetlift.integrate(n, mask, K=K, prior=bad)
    # confidence: +inf is the map's largest confidence, a negative pixel none (as NaN)
    conf = np.linspace(0.5, 2.0, 24 * 28).reshape(24, 28)
    c = conf.copy()
    c[4, 5], c[9, 9] = np.inf, -0.1
    with pytest.warns(UserWarning, match=r"`confidence`: 2 pixel\(s\) inside the mask are "
                      r"not finite and >= 0, the first inf at \(row 4, col 5\) \(1 \+inf, "
                      r"taken as the map's largest confidence 2; 1 negative"):
        got = facetlift.integrate(n, mask, confidence=c, discontinuities=False).depth
    ref = conf.copy()
    ref[4, 5], ref[9, 9] = 2.0, np.nan
    np.testing.assert_array_equal(got, facetlift.integrate(n, mask, confidence=ref).depth)
    with pytest.raises(ValueError, match=r"`confidence` must be finite and >= 0 .*more than "
                       "a few bad ones"):
        facetlift.integrate(n, mask, confidence=-conf)


def test_points_behind_the_camera_are_left_out_and_swapped_axes_are_named():
    """A user's LiDAR cloud with 10 points behind the camera was refused whole (points
    outside the image are left out); points given as (x, y, z) for (rows, cols, depths)
    landed mostly outside the mask without a word."""
    n, _ = wave()
    K = np.array([[100.0, 0, 14], [0, 100.0, 12], [0, 0, 1]])
    rows, cols = np.array([3, 10, 20, 5]), np.array([4, 12, 25, 6])
    with pytest.warns(UserWarning, match=r"2 sample\(s\) with a non-positive z-depth \(behind "
                      r"the camera\), the first -3.0 at \(row 5, col 6\); they were left out"):
        a = facetlift.integrate(n, K=K, prior=(np.r_[rows, 3], np.r_[cols, 4],
                                               [5.0, 5.0, 5.0, -3.0, -0.2])).depth
    # (left out before a pixel's points are averaged: (3, 4) keeps its 5.0; a review)
    b = facetlift.integrate(n, K=K, prior=(rows[:3], cols[:3], [5.0, 5.0, 5.0])).depth
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="positive z-depths"):  # (all of them: refused)
        facetlift.integrate(n, K=K, prior=(rows, cols, [-5.0, -5.0, -5.0, -3.0]))
    # (a sensor's 0 "unknown" kept in points made from its map: named as such, a review)
    with pytest.warns(UserWarning, match=r"2 sample\(s\) with a non-positive z-depth .* \(2 of "
                      r"them exactly 0: a depth sensor's or a map's mark for an unknown"):
        facetlift.integrate(n, K=K, prior=(rows, cols, [5.0, 0.0, 5.0, 0.0]))
    mask = np.zeros((24, 28), bool)
    mask[:, :5] = True
    with pytest.warns(UserWarning, match=r"1 of the 4 sample\(s\) lie on the mask, 4 would "
                      r"with rows and cols swapped"):
        facetlift.integrate(n, mask, prior=(np.array([1, 2, 3, 4]), np.array([10, 15, 20, 3]),
                                            np.full(4, 5.0)))
    # a cloud over the whole image beside a small object: most points off the mask either
    # way, no warning (a review)
    import warnings

    rr, cc = np.meshgrid(np.arange(0, 24, 2), np.arange(0, 28, 2), indexing="ij")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        facetlift.integrate(n, mask, prior=(rr.ravel(), cc.ravel(), np.full(rr.size, 5.0)))


def test_iterative_without_mean_subtraction_refuses_a_prior():
    n, depth = wave()
    with pytest.raises(ValueError, match="needs mean_subtraction=True"):
        facetlift.integrate(n, solver="iterative", mean_subtraction=False, prior=depth)


def test_regularization_keeps_its_prior_option():
    n, _ = wave()
    s = run(n, method="regularization", prior="laplacian")
    assert s.info["prior"] == "laplacian"
    # a depth prior's settings beside the string are named as such (they were refused as
    # "applies only with a `prior`; ... prior=None", the string given: an audit)
    for kw in ({"prior_weight": 2.0}, {"prior_fit": "affine"}, {"prior_blur": 2.0}):
        with pytest.raises(ValueError, match=rf"`{next(iter(kw))}` belong\(s\) to a depth "
                           r"prior; prior='laplacian' is regularization's smoothness option"):
            run(n, method="regularization", prior="laplacian", **kw)


# ------------------------------------------------------------------------------------------
# command line and files


def _write_inputs(tmp_path):
    n, depth = wave()
    np.save(tmp_path / "n.npy", n)
    prior, sel = sparse(depth, 0.05)
    np.save(tmp_path / "prior.npy", prior)
    return n, depth, prior, sel


def test_cli_prior_and_confidence(tmp_path, capsys):
    n, depth, prior, sel = _write_inputs(tmp_path)
    np.save(tmp_path / "conf.npy", np.ones(depth.shape))
    np.save(tmp_path / "w.npy", np.full(depth.shape, 1e6))
    code = main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "prior.npy"),
                 "--prior-weight-map", str(tmp_path / "w.npy"), "--confidence",
                 str(tmp_path / "conf.npy"), "-s", "npy", "-o", str(tmp_path / "o")])
    assert code == 0, capsys.readouterr().err
    out = np.load(tmp_path / "o" / "depth.npy")
    assert np.abs(out[sel] - prior[sel]).max() < 1e-3


def test_cli_says_when_one_sample_per_component_moved_the_surface(tmp_path, capsys):
    n, depth = wave()
    np.save(tmp_path / "n.npy", n)
    prior = np.full(depth.shape, np.nan)
    prior[5, 6] = 3.0
    np.save(tmp_path / "one.npy", prior)
    args = ["integrate", str(tmp_path / "n.npy"), "--discontinuities", "-s", "npy"]
    assert main(args + ["--prior", str(tmp_path / "one.npy"), "-o", str(tmp_path / "a")]) == 0
    assert "1 sample fixing 1 of 1 components, alone in its component: the surface moved " \
           "to it whole" in capsys.readouterr().out
    assert np.load(tmp_path / "a" / "depth.npy")[5, 6] == pytest.approx(3.0)
    prior[15, 20] = depth[15, 20] - depth[5, 6] + 3.0
    np.save(tmp_path / "two.npy", prior)
    assert main(args + ["--prior", str(tmp_path / "two.npy"), "-o", str(tmp_path / "b")]) == 0
    assert "alone in its component" not in capsys.readouterr().out
    # the pieces the cuts add: placed as without a prior, said so (the occluder: 2 more)
    from facetlift import synthetic

    g = synthetic.analytic("occluder", 48)
    np.save(tmp_path / "occ.npy", g.normals)
    one = np.full(g.mask.shape, np.nan)
    one[10, 10] = g.depth[10, 10]
    np.save(tmp_path / "occ_one.npy", one)
    assert main(["integrate", str(tmp_path / "occ.npy"), "--discontinuities", "-s", "npy",
                 "--prior", str(tmp_path / "occ_one.npy"), "-o", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    assert "cuts split the mesh into 2 more pieces (closed by the occlusion rule" in out
    assert "alone in its component" in out


@pytest.mark.parametrize("layout", ["plain", "header", "comments", "spreadsheet"])
def test_cli_prior_from_a_points_file(tmp_path, capsys, layout):
    """Sparse samples as a text file of points (SfM, LiDAR): the same surface as the same
    samples in an (H, W) map; the header orders the columns (x a column, y a row)."""
    n, depth, prior, sel = _write_inputs(tmp_path)
    r, c = np.nonzero(sel)
    z = prior[r, c]
    rows = zip(r, c, z, strict=True)
    if layout == "plain":
        text = "row col depth\n" + "".join(f"{a} {b} {float(v)!r}\n" for a, b, v in rows)
    elif layout == "header":  # another order, an extra column
        text = "z,x,intensity,y\n" + "".join(f"{float(v)!r},{b},7,{a}\n" for a, b, v in rows)
    elif layout == "comments":  # comments, tabs, fractional positions to the same pixels
        text = "# from SfM\nrow\tcol\tdepth  # pixels\n" + "".join(
            f"{a + 0.3}\t{b - 0.4}\t{float(v)!r}  # a point\n" for a, b, v in rows)
    else:  # a spreadsheet's CSV UTF-8: byte-order mark, quoted names, semicolons, CRLF
        text = "\ufeff\"u\";\"v\";\"depth\"\r\n" + "".join(
            f"{b};{a};{float(v)!r}\r\n" for a, b, v in rows)
    (tmp_path / "pts.csv").write_bytes(text.encode("utf-8"))
    for name, src in (("map", "prior.npy"), ("points", "pts.csv")):
        code = main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / src),
                     "-s", "npy", "-o", str(tmp_path / name)])
        assert code == 0, capsys.readouterr().err
    np.testing.assert_array_equal(np.load(tmp_path / "points" / "depth.npy"),
                                  np.load(tmp_path / "map" / "depth.npy"))


@pytest.mark.parametrize("text,match", [
    ("1 2 3\n4 5 6\n", r"the first line must be a header naming the columns.*'1 2 3'"),
    ("a,b,c\n1,2,3\n", "the first line must be a header"),
    ("row col depth\n", "holds no sample"),
    ("", "holds no sample"),
    ("row col depth\n1 2 x\n", "a line that is not 3 numbers"),
    ("row col depth\n1 2\n", "lines of 2 numbers under a header of 3 columns"),
    ("row col\n1 2\n", "the first line must be a header"),
    ("row col depth\n1 900 5\n",
     r"1 of the 1 sample\(s\) lie outside the 24 x 28 image, the first at \(row 1, col 900\)"),
])
def test_cli_prior_points_file_errors(tmp_path, capsys, text, match):
    _write_inputs(tmp_path)
    (tmp_path / "pts.txt").write_text(text)
    code = main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "pts.txt"),
                 "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1 and re.search(match, err) and "Traceback" not in err, err


@pytest.mark.parametrize("z", ["1.49,1.49,1.49", "1.49,1.51,1.47"])
def test_cli_prior_of_unprojected_points_asks_about_K(tmp_path, capsys, z):
    """A CSV of three camera-frame points in metres under an x,y,z header (0.012,-0.03,1.49)
    rounds onto pixel (0, 0): it was told "no finite depth sample inside the mask (1 outside
    it)" alone (a review); the message asks whether they were projected with K, as the error
    of points all outside the image does, whether the pixel's depths agree (outside the mask)
    or not (left out as a conflict)."""
    _write_inputs(tmp_path)
    mask = np.ones((24, 28), bool)
    mask[0, 0] = False
    np.save(tmp_path / "m.npy", mask)
    depths = z.split(",")
    xy = [("0.012", "-0.03"), ("0.02", "0.01"), ("-0.015", "0.02")]
    (tmp_path / "pts.csv").write_text("x,y,z\n" + "".join(
        f"{x},{y},{d}\n" for (x, y), d in zip(xy, depths, strict=True)))
    argv = ["integrate", str(tmp_path / "n.npy"), "--mask", str(tmp_path / "m.npy"), "-o",
            str(tmp_path / "o"), "--prior"]
    code = main(argv + [str(tmp_path / "pts.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "no finite depth sample inside the mask" in err, err
    assert ("its 3 points all fall into one pixel (row 0, col 0): 3-D points not projected "
            "with K (x, y in metres or mm") in err
    # most of them outside the image: asked alike; points spread over the image are not
    (tmp_path / "far.csv").write_text("row,col,depth\n0,0,1.5\n-40,3,1.5\n5,900,1.5\n")
    code = main(argv + [str(tmp_path / "far.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "2 of its 3 points lie outside the 24 x 28 image: 3-D points not " \
        "projected with K" in err, err
    (tmp_path / "spread.csv").write_text("row,col,depth\n0,0,1.5\n0,1,1.5\n1,0,1.5\n")
    mask[:2, :2] = False
    np.save(tmp_path / "m.npy", mask)
    code = main(argv + [str(tmp_path / "spread.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "(3 outside it)" in err and "projected with K" not in err, err


def test_info_checks_a_prior_and_a_confidence_given_as_flags(tmp_path, capsys):
    """info read only a dataset folder's prior (a user's check: no way to preflight one's
    own points file); now --prior / --confidence are read and checked as integrate would."""
    import json

    n, depth, prior, sel = _write_inputs(tmp_path)
    conf = np.ones(depth.shape)
    conf[0, 0] = 0.0  # (outside the mask below: not in the range, a user's check)
    np.save(tmp_path / "conf.npy", conf)
    (tmp_path / "pts.csv").write_text("row,col,depth\n3,4,5\n1,900,5\n")
    mask = np.ones(depth.shape, bool)
    mask[0, :] = False
    facetlift.io.write_mask(tmp_path / "m.png", mask)
    code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "pts.csv"),
                 "--confidence", str(tmp_path / "conf.npy"), "--mask", str(tmp_path / "m.png")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert ("depth prior (" in out
            and "pts.csv): 1 known pixels, 1 in the mask, 5 to 5 there" in out)
    assert ("normal confidence (" in out
            and "conf.npy): 672 known pixels, 644 in the mask, 1 to 1 there" in out)
    assert out.count("1 of the 2 sample(s) lie outside the 24 x 28 image") == 1
    np.save(tmp_path / "bad.npy", np.where(sel, -1.0, np.nan))
    code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "bad.npy"),
                 "--K", str(_K_file(tmp_path)), "--json"])
    rec = json.loads(capsys.readouterr().out)
    assert code == 1 and "positive z-depths" in rec["problem"]
    # every point outside the image: a report whose problem says so (not an error line)
    (tmp_path / "out.csv").write_text("row,col,depth\n999,0,5\n")
    code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "out.csv"),
                 "--json"])
    rec = json.loads(capsys.readouterr().out)
    assert code == 1 and "no sample is inside" in rec["problem"] and rec["shape"] == [24, 28]
    # without a prior, --prior-blur's own value errors come first (a review)
    for value, match in (("-1", "--prior-blur must be a finite number of pixels >= 0"),
                         ("0.2", "--prior-blur below half a pixel is no blur"),
                         ("4", "--prior-blur 4 applies only with a prior")):
        code = main(["integrate", str(tmp_path / "n.npy"), "--prior-blur", value, "-o",
                     str(tmp_path / "o")])
        assert code == 1 and match in capsys.readouterr().err


def _K_file(tmp_path):
    path = tmp_path / "K.txt"
    path.write_text("30 0 14\n0 30 12\n0 0 1\n")
    return path


def test_points_outside_the_image_are_left_out_with_a_warning(tmp_path, capsys):
    """One stray point of a point cloud refused the whole job (a user's check)."""
    _write_inputs(tmp_path)
    (tmp_path / "pts.txt").write_text("row col depth\n3 4 5\n1 900 5\n-2 1 5\n")
    code = main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "pts.txt"),
                 "-s", "npy", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert re.search(r"warning: --prior \(rows, cols, depths\): 2 of the 3 sample\(s\) lie "
                     r"outside the 24 x 28 image, the first at \(row 1, col 900\); they were "
                     r"left out", err), err
    # most of them outside: a camera-frame cloud read as pixels? (a user's mm under x,y,z)
    assert "most of them: 3-D points" in err and "Project them with K first" in err
    n = np.load(tmp_path / "n.npy")
    with pytest.warns(UserWarning, match="1 of the 2 sample") as rec:
        a = facetlift.integrate(n, prior=([3, 30], [4, 4], [5.0, 5.0])).depth
    assert not any("3-D points" in str(w.message) for w in rec)
    np.testing.assert_array_equal(a, facetlift.integrate(n, prior=([3], [4], [5.0])).depth)


def test_weight_maps_read_alike_from_png_and_tiff_and_scale_with_the_weight(tmp_path):
    """An 8-bit TIFF mask of 255s was read as 255 where the same PNG gave 1; a PNG weight map
    could not exceed 1 and was refused beside --prior-weight; an RGB map used its red
    channel only."""
    import imagecodecs
    import tifffile

    from facetlift import io
    from facetlift.jobs import Job, read

    m = np.zeros((6, 7), np.uint8)
    m[1:4, 2:6] = 255
    (tmp_path / "c.png").write_bytes(imagecodecs.png_encode(m))
    tifffile.imwrite(tmp_path / "c.tif", m)
    tifffile.imwrite(tmp_path / "f.tif", m.astype(np.float32))
    png, tif = (io.read_weights(tmp_path / f, arg="confidence") for f in ("c.png", "c.tif"))
    np.testing.assert_array_equal(png, tif)
    assert png.max() == 1.0
    assert io.read_weights(tmp_path / "f.tif", arg="confidence").max() == 255.0  # (as stored)
    grey = np.repeat(m[..., None], 3, axis=2)
    (tmp_path / "g.png").write_bytes(imagecodecs.png_encode(grey))
    np.testing.assert_array_equal(io.read_weights(tmp_path / "g.png", arg="confidence"), png)
    ga = np.dstack([m, np.full_like(m, 255)])  # grey + alpha (was read before: still is)
    (tmp_path / "ga.png").write_bytes(imagecodecs.png_encode(ga))
    np.testing.assert_array_equal(io.read_weights(tmp_path / "ga.png", arg="confidence"), png)
    tifffile.imwrite(tmp_path / "01.tif", (m > 0).astype(np.uint8))  # 0/1 as uint8: 1/255
    with pytest.warns(UserWarning, match=r"`confidence`: .* only 0 and 1 .* store 255"):
        io.read_weights(tmp_path / "01.tif", arg="confidence")
    grey[0, 0, 1] = 7
    (tmp_path / "rgb.png").write_bytes(imagecodecs.png_encode(grey))
    with pytest.raises(ValueError, match="`confidence`: .* colour channels that differ"):
        io.read_weights(tmp_path / "rgb.png", arg="confidence")
    n = np.dstack([np.zeros((6, 7, 2)), np.ones((6, 7))])
    np.save(tmp_path / "n.npy", n)
    np.save(tmp_path / "p.npy", np.full((6, 7), 2.0))
    job = Job(normals=str(tmp_path / "n.npy"), prior=str(tmp_path / "p.npy"),
              prior_weight=100.0, prior_weight_map=str(tmp_path / "c.png"))
    w = read(job).prior_weight
    assert w.max() == 100.0 and w.min() == 0.0


def test_cli_16bit_png_prior_needs_a_scale(tmp_path, capsys):
    import imagecodecs

    n, depth, _, sel = _write_inputs(tmp_path)
    counts = np.where(sel, np.rint((depth + 10.0) * 1000), 0).astype(np.uint16)
    (tmp_path / "p.png").write_bytes(imagecodecs.png_encode(counts))
    argv = ["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "p.png"), "-s",
            "npy", "--prior-weight", "1e6"]
    assert main(argv + ["-o", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err
    assert "--prior-scale" in err and "Traceback" not in err
    assert main(argv + ["--prior-scale", "0.001", "-o", str(tmp_path / "b")]) == 0
    out = np.load(tmp_path / "b" / "depth.npy")
    assert np.abs(out[sel] - (depth[sel] + 10.0)).max() < 1e-3


def test_info_reads_a_dataset_with_a_16bit_png_prior_given_its_scale(tmp_path, capsys):
    """info refused such a folder and named --prior-scale, which it did not take; then it
    refused it with --prior-scale's message. It describes the folder, the prior it holds,
    and (without the scale) integrate's refusal as a warning naming both ways out."""
    import imagecodecs

    n, depth, _, sel = _write_inputs(tmp_path)
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    counts = np.where(sel, np.rint((depth + 10.0) * 1000), 0).astype(np.uint16)
    (folder / "prior_depth.png").write_bytes(imagecodecs.png_encode(counts))
    assert main(["info", str(folder)]) == 1  # (described, and integrate would refuse it)
    out = capsys.readouterr().out
    assert f"{n.shape[0]}x{n.shape[1]} pixels" in out and "depth prior" not in out
    assert "warning: integrate would refuse this folder" in out
    assert "--prior-scale" in out and "--no-prior" in out
    assert main(["info", str(folder), "--prior-scale", "0.001"]) == 0
    out = capsys.readouterr().out
    assert f"depth prior (dataset file): {int(sel.sum())} known pixels" in out
    assert "refuse" not in out
    # integrate names both ways out too
    assert main(["integrate", str(folder), "-o", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "--prior-scale" in err and "--no-prior" in err
    # a confidence map of the wrong size: left out, the prior still described, the refusal
    # in the JSON for scripts that use info as a check
    import json

    np.save(folder / "confidence.npy", np.ones((3, 3)))
    assert main(["info", str(folder), "--prior-scale", "0.001", "--json"]) == 1
    rec = json.loads(capsys.readouterr().out)
    assert rec["prior"]["known_pixels"] == int(sel.sum()) and "confidence" not in rec
    assert "--no-confidence" in rec["refused"] and "3x3" in rec["refused"]
    # the source of a folder's prior is the folder's file, of --prior the file given (a
    # review: the retry loop's flag was printed, "depth prior (True)")
    assert main(["info", str(folder), "--prior-scale", "0.001"]) == 1
    assert "depth prior (dataset file)" in capsys.readouterr().out
    (tmp_path / "pts.csv").write_text("row,col,depth\n3,4,5\n")
    assert main(["info", str(folder), "--prior", str(tmp_path / "pts.csv")]) == 1
    assert "depth prior (" in (out := capsys.readouterr().out) and "pts.csv): 1 known" in out


def test_dataset_folder_picks_up_a_points_prior(tmp_path, capsys):
    """A folder's prior_depth.csv is read like --prior's points file, as a map: info
    describes it, integrate uses it (a review: it was ignored in silence)."""
    n, depth, prior, sel = _write_inputs(tmp_path)
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    r, c = np.nonzero(sel)
    (folder / "prior_depth.csv").write_text("row,col,depth\n" + "".join(
        f"{a},{b},{float(prior[a, b])!r}\n" for a, b in zip(r, c, strict=True)))
    data = facetlift.io.read_dataset(folder)
    np.testing.assert_array_equal(np.isfinite(data["prior"]), sel)
    import json

    assert main(["info", str(folder), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["prior"]["known_pixels"] == int(sel.sum())
    assert main(["integrate", str(folder), "-s", "npy", "--prior-weight", "1e6",
                 "-o", str(tmp_path / "o")]) == 0, capsys.readouterr().err
    out = np.load(tmp_path / "o" / "depth.npy")
    assert np.abs(out[sel] - prior[sel]).max() < 1e-3
    (folder / "prior_depth.csv").write_text("row,col,depth\n999,0,1.0\n")
    assert main(["integrate", str(folder), "-o", str(tmp_path / "p")]) == 1
    err = capsys.readouterr().err
    assert "outside the 24 x 28 image" in err and "--no-prior" in err


def test_dataset_folder_picks_up_prior_and_confidence(tmp_path, capsys):
    n, depth, prior, sel = _write_inputs(tmp_path)
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    np.save(folder / "prior_depth.npy", prior)
    conf = np.ones(depth.shape)
    conf[2:5, 2:5] = 0
    np.save(folder / "confidence.npy", conf)
    code = main(["integrate", str(folder), "-s", "npy", "--prior-weight", "1e6", "--json",
                 "-o", str(tmp_path / "o")])
    assert code == 0, capsys.readouterr().err
    import json

    rec = json.loads(capsys.readouterr().out)
    assert rec["info"]["prior"]["samples"] == int(sel.sum())
    assert rec["info"]["input"]["zero_confidence"] == 9
    out = np.load(tmp_path / "o" / "depth.npy")
    assert np.abs(out[sel] - prior[sel]).max() < 1e-3
    assert rec["info"]["prior"]["gauge"] is None  # (every component fixed: no gauge applied)
    assert rec["prior_file"] == "the folder's prior_depth.npy"
    assert rec["confidence_file"] == "the folder's confidence.npy"
    # the text summary says that a prior and a confidence map were used, and which files
    # (read without asking: a stray confidence.npy changed results unsaid, an audit)
    code = main(["integrate", str(folder), "-s", "npy", "--prior-weight", "1e6",
                 "-o", str(tmp_path / "t")])
    out = capsys.readouterr().out
    assert code == 0 and (f"depth prior (the folder's prior_depth.npy): {int(sel.sum())} "
                          "samples fixing 1 of 1") in out
    assert "confidence map (the folder's confidence.npy, 9 at 0)" in out
    code = main(["integrate", str(folder / "normal_map.npy"), "-s", "npy", "--confidence",
                 str(folder / "confidence.npy"), "--json", "-o", str(tmp_path / "g")])
    rec = json.loads(capsys.readouterr().out)
    assert code == 0 and rec["confidence_file"] == str(folder / "confidence.npy")
    assert rec["prior_file"] is None
    # --no-prior / --no-confidence leave the folder's files unused (there was no way to)
    code = main(["integrate", str(folder), "-s", "npy", "--no-prior", "--no-confidence",
                 "--json", "-o", str(tmp_path / "n")])
    assert code == 0, capsys.readouterr().err
    rec = json.loads(capsys.readouterr().out)
    assert "prior" not in rec["info"] and "zero_confidence" not in rec["info"]["input"]
    code = main(["integrate", str(folder), "-s", "npy", "--no-confidence", "--json", "-o",
                 str(tmp_path / "c")])
    rec = json.loads(capsys.readouterr().out)
    assert code == 0 and "prior" in rec["info"] and "zero_confidence" not in rec["info"]["input"]
    for flags in (["--no-prior", "--prior", str(folder / "prior_depth.npy")],
                  ["--no-confidence", "--confidence", str(folder / "confidence.npy")]):
        assert main(["integrate", str(folder), "-o", str(tmp_path / "x"), *flags]) == 1
        assert "contradict" in capsys.readouterr().err
    data = facetlift.io.read_dataset(folder, with_prior=False, with_confidence=False)
    assert data["prior"] is None and data["confidence"] is None
    # a method that takes neither names the folder's file and the flag that leaves it out (a
    # batch user's --method bini was refused a confidence it had not asked for)
    assert main(["integrate", str(folder), "--no-prior", "--method", "bini", "-o",
                 str(tmp_path / "b")]) == 1
    err = " ".join(capsys.readouterr().err.split())
    assert ("does not take a" in err and "the dataset folder's confidence.* file, which this "
            "method does not take: --no-confidence leaves it out" in err)
    assert main(["integrate", str(folder), "--no-confidence", "--method", "bini", "-o",
                 str(tmp_path / "b")]) == 1
    assert "prior_depth.* file, which this method does not take: --no-prior leaves it" in (
        " ".join(capsys.readouterr().err.split()))
    # both at once, where the method takes neither (a review: one refusal after the other)
    assert main(["integrate", str(folder), "--method", "bini", "-o", str(tmp_path / "b")]) == 1
    assert ("prior_depth.* and confidence.* files, which this method does not take: "
            "--no-prior --no-confidence leave them out, dataset_prior=False, "
            "dataset_confidence=False in Python") in " ".join(capsys.readouterr().err.split())


@pytest.mark.parametrize("extra,match", [
    (["--prior", "bad.npy"], "--prior: size 3x3"),
    (["--prior", "prior.npy", "--prior-weight", "-2"], "--prior-weight must be a finite number"),
    (["--confidence", "bad.npy"], "--confidence: size 3x3"),
    (["--prior-weight", "5"], "--prior-weight applies only with a prior"),
    (["--prior", "nan.npy"], "no finite depth sample"),
    (["--prior", "prior.npy", "--method", "frankot_chellappa"], "does not take a --prior"),
])
def test_cli_errors_exit_1_without_traceback(tmp_path, capsys, extra, match):
    _write_inputs(tmp_path)
    np.save(tmp_path / "bad.npy", np.ones((3, 3)))
    np.save(tmp_path / "nan.npy", np.full((24, 28), np.nan))
    extra = [str(tmp_path / a) if a.endswith(".npy") else a for a in extra]
    code = main(["integrate", str(tmp_path / "n.npy"), *extra, "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1
    assert match in err and "Traceback" not in err


def test_discontinuities_with_a_prior_fill_a_hole_of_missing_normals_like_the_smooth_dgp():
    """Facets without a normal leave near-null modes (the flattest fill of a hole); a prior's
    samples excite them, and multigrid-CG alone left a hole of missing normals in a perspective
    render hundreds of mm off (fusion benchmark, 'corrupt missing'); the discontinuity route
    now starts from the smooth fixed point, which resolves them."""
    from test_perspective import sphere_scene

    n, mask, K, depth = sphere_scene(H=120, W=140)
    rr, cc = np.indices(mask.shape)
    hole = mask & ((rr - 60) ** 2 + (cc - 75) ** 2 < 15**2)
    n = np.where(hole[..., None], np.nan, n)
    rng = np.random.default_rng(3)
    idx = rng.choice(np.flatnonzero(mask & ~hole), 60, replace=False)
    prior = np.full(mask.shape, np.nan)
    prior.flat[idx] = depth.flat[idx]
    err = {}
    for disc in (False, True):
        s = facetlift.integrate(n, mask, K=K, prior=prior, prior_weight=100.0,
                                discontinuities=disc)
        err[disc] = np.abs(s.depth - depth)[hole].mean()
    assert err[True] < 2 * err[False] + 1e-3 * np.nanmedian(depth)


def test_bench_prior_alone_with_collinear_samples():
    """The benchmark's 'prior only' column: samples on one line (a thin scene, 0.1 %) cannot be
    triangulated; the nearest sample fills the mask (the full run stopped there once)."""
    from facetlift.bench.fusion import interpolate

    mask = np.zeros((20, 30), bool)
    mask[5:15, 3:27] = True
    prior = np.full(mask.shape, np.nan)
    prior[[6, 9, 12, 14], 10] = [1.0, 2.0, 3.0, 4.0]  # one column: collinear
    alone = interpolate(prior, mask)
    assert np.isfinite(alone[mask]).all() and np.isnan(alone[~mask]).all()
    assert alone[6, 20] == 1.0 and alone[14, 3] == 4.0
    prior[8, 20] = 5.0  # spans the plane: linear inside the hull
    assert interpolate(prior, mask)[9, 12] not in (1.0, 2.0, 3.0, 4.0, 5.0)


def test_an_error_raised_by_progress_is_not_swallowed_by_the_multigrid_trial():
    n, depth = wave((40, 44))
    prior, _ = sparse(depth, 0.02, seed=2)

    class Stop(RuntimeError):
        pass

    def progress(it, res):
        if it == 3:
            raise Stop

    with pytest.raises(Stop):
        run(n, prior=prior, prior_weight=100.0, progress=progress)


def test_confidence_outside_the_mask_is_ignored_and_nan_inside_is_a_missing_normal():
    H, W = 24, 28
    r, c = np.indices((H, W))
    n = facetlift.normals_from_gradients(0.1 * np.cos(c / 4), 0.1 * np.sin(r / 5))
    mask = np.zeros((H, W), bool)
    mask[2:-2, 3:-3] = True
    conf = np.ones((H, W))
    conf[0, 0], conf[1, 5] = np.nan, -3.0  # outside the mask: never looked at
    conf[5, 6] = np.nan  # inside: a missing normal
    s = facetlift.integrate(n, mask, confidence=conf)
    missing = n.copy()
    missing[5, 6] = np.nan
    ref = facetlift.integrate(missing, mask)
    assert s.info["input"]["zero_confidence"] == 1
    np.testing.assert_allclose(s.depth[mask], ref.depth[mask], atol=1e-9)


def test_confidence_without_a_prior_is_scale_free():
    r, c = np.indices((20, 24))
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 4), 0.1 * np.sin(r / 5))
    ref = facetlift.integrate(n)
    for scale in (1e-12, 1e12):
        s = facetlift.integrate(n, confidence=np.full((20, 24), scale))
        np.testing.assert_allclose(s.depth, ref.depth, atol=1e-9)


@pytest.mark.parametrize("discontinuities", [False, True])
def test_confidence_scale_free_with_missing_normals(discontinuities):
    """A fresh user's check: the facets without a usable normal were given the weight 1 before
    the map was scaled to a largest of 1, so a 0/1 map times 0.01 weighed them 100 times the
    normals and moved the depth by 8.5 % of its range."""
    r, c = np.indices((24, 28))
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 4), 0.1 * np.sin(r / 5))
    rng = np.random.default_rng(3)
    n[rng.random((24, 28)) < 0.15] = np.nan
    conf = np.where(rng.random((24, 28)) < 0.2, 0.0, 0.5 + rng.random((24, 28)))
    ref = facetlift.integrate(n, np.ones((24, 28), bool), confidence=conf,
                              discontinuities=discontinuities)
    for scale in (0.01, 100.0):
        s = facetlift.integrate(n, np.ones((24, 28), bool), confidence=scale * conf,
                                discontinuities=discontinuities)
        np.testing.assert_allclose(s.depth, ref.depth, atol=1e-8 * np.ptp(ref.depth))


def test_a_noisy_dense_prior_that_tears_the_discontinuity_route_is_warned_about():
    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 64)
    rng = np.random.default_rng(0)
    noisy = np.where(gt.mask, gt.depth + rng.normal(0, 3 * gt.pixel_size, gt.depth.shape),
                     np.nan)
    with pytest.warns(UserWarning, match=r"of the facet corners were cut.* tear the surface"):
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=noisy,
                            discontinuities=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # a low weight: no such warning
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=noisy,
                            prior_weight=0.01, discontinuities=True)


def test_a_prior_that_tears_the_surface_into_many_pieces_is_warned_about():
    """A fresh user's noisy dense prior cut 26 % of the corners (below TORN) into 3,497 mesh
    pieces without a word: many pieces warn too (TORN_PIECES)."""
    from facetlift import synthetic
    from facetlift.methods import dgp

    gt = synthetic.analytic("sphere", 96)
    rng = np.random.default_rng(0)
    rng.normal(size=gt.depth.shape)  # (the draw measured: sigma 2 first, then 4)
    noisy = np.where(gt.mask, gt.depth + rng.normal(0, 4 * gt.pixel_size, gt.depth.shape),
                     np.nan)
    with pytest.warns(UserWarning, match=r"corners were cut, \d+ pieces .* tear the surface"):
        s = facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=noisy,
                                prior_weight=0.1, discontinuities=True)
    assert s.info["cut_corners"] < dgp.TORN
    assert s.info["mesh_pieces"] > dgp.TORN_PIECES * gt.mask.sum()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # a lower weight: a few pieces, no warning
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=noisy,
                            prior_weight=0.03, discontinuities=True)
    # already at the weight the warning recommends: it says so instead of recommending it (a
    # user at 0.01 was told to lower it to 0.01)
    noisier = np.where(gt.mask, gt.depth + rng.normal(0, 40 * gt.pixel_size, gt.depth.shape),
                       np.nan)
    with pytest.warns(UserWarning, match=r"A prior_weight below its 0\.01 .*may be noisier"):
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=noisier,
                            prior_weight=0.01, discontinuities=True)


def test_a_weak_prior_takes_the_forcing_term_and_a_strong_one_does_not(monkeypatch):
    """The reweightings' CG stops early (PRIOR_FORCING) with a pointwise prior no stronger
    than the normals, not with a stronger or a blurred one; the weak prior's surface stays the
    tightly solved one's. (The prior's own reweightings: the prior-free first pass that gives
    them their starting cuts, PRIOR_CUTS_FIRST and BLURRED_CUTS_FIRST, takes the prior-free
    route's FORCING.)"""
    from facetlift.methods import dgp
    from facetlift.methods.dgp import discontinuous as D

    monkeypatch.setattr(dgp, "PRIOR_CUTS_FIRST", 0.0)
    monkeypatch.setattr(dgp, "BLURRED_CUTS_FIRST", False)

    n, depth = wave((40, 44))
    depth = depth + 3.0 * (np.indices(depth.shape)[1] >= 22)
    rng = np.random.default_rng(2)
    prior, sel = sparse(depth, 0.05, seed=3)
    prior = prior + 0.02 * rng.normal(size=prior.shape)
    seen = []
    real_cg = D.linalg.cg

    def cg(*args, **kwargs):
        seen.append(kwargs.get("reduction"))
        return real_cg(*args, **kwargs)

    def reductions(**kw):
        seen.clear()
        out = run(n, discontinuities=True, prior=prior, **kw)
        return out, set(seen)

    monkeypatch.setattr(D.linalg, "cg", cg)
    weak, used = reductions(prior_weight=1.0)
    assert D.PRIOR_FORCING in used
    assert reductions(prior_weight=2.0)[1] == {None}
    assert reductions(prior_weight=1.0, prior_blur=2.0)[1] == {None}
    # the normals' weights are the usable ones': a missing normal (weight 1 in the system, no
    # target) does not make a prior 100x the others' weak
    conf = np.full(depth.shape, 0.01)
    holed = n.copy()
    holed[5, 5] = np.nan
    seen.clear()
    run(holed, discontinuities=True, prior=prior, prior_weight=1.0, confidence=conf)
    assert set(seen) == {None}
    monkeypatch.setattr(D, "PRIOR_FORCING", None)
    tight, used = reductions(prior_weight=1.0)
    assert used == {None}
    # measured 6e-4 apart at 0.03 (0.125 with a forcing term of 0.3)
    np.testing.assert_allclose(weak.depth, tight.depth, atol=0.01)


def test_a_prior_that_fights_the_normals_is_warned_about():
    """A network's disparity given as depth (near is large) pulled a user's surface inside out
    (mean deviation 82-124 deg, exit 0, no word): a prior whose result deviates from the
    normals by more than PRIOR_FIGHT degrees gets a warning; the right prior stays silent."""
    import warnings

    from facetlift import api, synthetic

    gt = synthetic.analytic("sphere", 48)
    with pytest.warns(UserWarning, match=r"deviates from its input normals by \d+ deg on "
                                         r"average: the depth prior fights them. If the scene "
                                         r"has depth jumps, .*discontinuities=True.*disparity"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=-gt.depth, prior_weight=1.0)
    assert s.info["mean_deviation"] > api.PRIOR_FIGHT == 45.0
    # orthographic: the warning names K (a user forgot --K with a metric prior)
    with pytest.warns(UserWarning, match=r"Without K the depth is orthographic.*--K"):
        facetlift.integrate(gt.normals, gt.mask, prior=-gt.depth, prior_weight=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        facetlift.integrate(gt.normals, gt.mask, prior=gt.depth, prior_weight=1.0)


def test_samples_far_from_the_surface_are_counted_and_warned_about():
    """A LiDAR user's occluded and flying points (154 of 2,900, up to 0.69 m off) went without
    a word; exact samples give no such warning."""
    from scipy import ndimage

    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 64)
    rng = np.random.default_rng(0)
    rr, cc = np.nonzero(gt.mask)
    k = rng.choice(rr.size, 80, replace=False)
    r, c = rr[k], cc[k]
    z = gt.depth[r, c].copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        s = facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size,
                                prior=(r, c, z), prior_weight=0.01)
    assert s.info["prior"]["far_samples"] == 0
    span = np.nanmax(gt.depth) - np.nanmin(gt.depth)
    z[:3] += 0.3 * span  # three outliers (kept: the removal is tests/test_prior_outliers.py)
    with pytest.warns(UserWarning, match=r"prior: 3 of the 80 samples lie far from the surface"):
        s = facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size,
                                prior=(r, c, z), prior_weight=0.01, prior_outliers="keep")
    assert s.info["prior"]["far_samples"] == 3
    assert tuple(s.info["prior"]["farthest_sample"]) in set(zip(r[:3], c[:3], strict=True))
    # a dense map with a band of far samples: the warning names the silhouette band and the
    # prior's blur too (it spoke only of sensors' points and SfM to a monocular user, an
    # audit); the sparse samples above are not told of it
    dense = gt.depth.copy()
    dense[gt.mask & ~ndimage.binary_erosion(gt.mask)] += 2.0 * span
    with pytest.warns(UserWarning, match=r"lie far from the surface.*a band along the "
                                         r"silhouettes.*--prior-blur"):
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=dense,
                            prior_weight=0.01, prior_outliers="keep")
    with pytest.warns(UserWarning) as rec:
        facetlift.integrate(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=(r, c, z),
                            prior_weight=0.01, prior_outliers="keep")
    assert not any("silhouettes" in str(w.message) for w in rec)


def test_points_crowded_into_a_few_pixels_are_warned_about():
    """A LiDAR user's camera-frame x, y, z in metres under an x,y,z header were read as
    columns and rows: 2,900 points averaged into 6 pixels, without a word."""
    from facetlift.problem import prior_image

    rng = np.random.default_rng(1)
    xyz = rng.uniform(-1.5, 1.5, (100, 3)) + [0, 0, 3]
    with pytest.warns(UserWarning, match=r"the \d+ samples fall into only \d+ pixel"):
        prior_image((xyz[:, 1], xyz[:, 0], xyz[:, 2]), (40, 50), positive=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        prior_image((rng.uniform(0, 39, 100), rng.uniform(0, 49, 100), np.full(100, 3.0)),
                    (40, 50), positive=True)


def test_far_samples_on_a_fronto_parallel_wall_and_dense_points_are_not_warned_about():
    """A review's false alarms: exact samples on an orthographic wall of constant depth (no
    depth range: the floor was 0) with smoothly noisy normals; a depth map at 4x the
    resolution given as points (16 per pixel, every pixel covered)."""
    from facetlift import synthetic
    from facetlift.problem import prior_image

    n = np.zeros((120, 120, 3))
    n[..., 2] = 1.0
    rng = np.random.default_rng(0)
    n = synthetic.add_smooth_noise(n, 3.0, rng, length=20.0)
    rr, cc = np.meshgrid(np.arange(5, 120, 10), np.arange(5, 120, 10), indexing="ij")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        s = facetlift.integrate(n, prior=(rr.ravel(), cc.ravel(), np.full(rr.size, 7.0)))
        fine = np.indices((160, 160)) / 4.0 - 0.375
        prior_image((fine[0].ravel(), fine[1].ravel(), np.full(fine[0].size, 2.0)), (40, 40))
    assert s.info["prior"]["far_samples"] == 0


def test_the_pieces_warning_names_image_pixels_and_leaves_unsampled_components_alone(
        monkeypatch):
    """A review: the largest unsampled piece was named in the cropped problem's rows and
    columns, and a mask component without a sample (the gauge's, warned about on its own)
    was reported as a piece the cuts separate."""
    from facetlift.methods import dgp

    real = dgp.place_pieces

    def one_loose(*a, **k):  # (the crop's row 3, col 4 as the largest unsampled piece)
        placed, info = real(*a, **k)
        return placed, {**info, "unanchored_pieces": 1, "unanchored_facets": 150,
                        "unanchored_largest": [150, 3, 4]}

    monkeypatch.setattr(dgp, "place_pieces", one_loose)
    n = np.zeros((50, 60, 3))
    n[..., 2] = 1.0
    mask = np.zeros((50, 60), bool)
    mask[20:45, 25:55] = True  # (cropped by 20 rows and 25 columns)
    pts = (np.full(4, 30), np.arange(30, 50, 5), np.full(4, 3.0))
    with pytest.warns(UserWarning, match=r"largest 150, e\.g\. at \(row 23, col 29\)"):
        s = facetlift.integrate(n, mask, prior=pts, discontinuities=True)
    assert s.info["unanchored_largest"] == [150, 23, 29]
    monkeypatch.setattr(dgp, "place_pieces", real)
    # a second component without a sample: the gauge warning only
    two = np.zeros((60, 90), bool)
    two[5:55, 5:40] = two[5:55, 50:85] = True
    flat = np.zeros((60, 90, 3))
    flat[..., 2] = 1.0
    pts = (np.full(5, 30), np.arange(10, 35, 5), np.full(5, 3.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = facetlift.integrate(flat, two, prior=pts, discontinuities=True)
    text = " ".join(str(w.message) for w in caught)
    assert "mask components" in text and "that the cuts separate" not in text
    assert s.info["unanchored_pieces"] == 0


def test_a_grey_exr_confidence_stored_as_rgb_is_read_as_its_grey_level(tmp_path):
    """A photometric-stereo user's grey EXR (R = G = B) was refused ('must hold one
    channel'), where a grey RGB PNG is read; channels that differ are still refused."""
    from facetlift.io.images import _write_exr

    w = np.linspace(0.0, 2.0, 12 * 10).reshape(12, 10).astype(np.float32)
    _write_exr(tmp_path / "c.exr", {"R": w, "G": w, "B": w})
    np.testing.assert_array_equal(facetlift.io.read_weights(tmp_path / "c.exr",
                                                            arg="confidence"), w)
    _write_exr(tmp_path / "d.exr", {"R": w, "G": w, "B": w + 1})
    with pytest.raises(ValueError, match="`confidence`: .* R, G, B that differ"):
        facetlift.io.read_weights(tmp_path / "d.exr", arg="confidence")


def test_points_files_with_a_column_named_twice_or_nan_depths_say_so(tmp_path):
    """A LiDAR user's headers 'u,v,depth,x,y,z' and 'u,v,z,r' (r: reflectivity) were told
    that the header was missing; lines with a NaN depth were dropped without a count."""
    from facetlift.problem import prior_image

    (tmp_path / "a.csv").write_text("u,v,depth,x,y,z\n1,2,3,0.1,0.2,3\n")
    with pytest.raises(ValueError, match=r"names a column twice \('v' and 'y' both name the "
                       r"row; 'u' and 'x' both name the col; 'depth' and 'z' both name the "
                       r"depth\)"):
        facetlift.io.read_prior(tmp_path / "a.csv")
    (tmp_path / "b.csv").write_text("u,v,z,r\n1,2,3,0.5\n")
    with pytest.raises(ValueError, match=r"'v' and 'r' both name the row.*'reflectivity'"):
        facetlift.io.read_prior(tmp_path / "b.csv")
    (tmp_path / "c.csv").write_text("u,v,z,reflectivity\n1,2,3,0.5\n4,5,nan,0.1\n")
    pts = facetlift.io.read_prior(tmp_path / "c.csv")
    with pytest.warns(UserWarning, match=r"1 sample\(s\) with a non-finite depth, the first at "
                      r"\(row 5, col 4\)"):
        img = prior_image(pts, (10, 10))
    assert np.isfinite(img).sum() == 1 and img[2, 1] == 3.0


@pytest.mark.parametrize("discontinuities", [False, True])
def test_points_with_their_own_weights(discontinuities):
    """SfM points come with a confidence (reprojection error, track length): a fourth array
    of per-point weights gives what the same samples give with those weights as a
    prior_weight map; a point of weight 0 is no sample; points in one pixel are averaged
    by weight."""
    from facetlift.problem import prior_samples

    n, depth = wave()
    prior, sel = sparse(depth, 0.05)
    r, c = np.nonzero(sel)
    w = np.random.default_rng(1).uniform(0.2, 5.0, r.size)
    wmap = np.ones(depth.shape)
    wmap[r, c] = w
    kw = dict(discontinuities=discontinuities)
    a = run(n, prior=(r, c, prior[r, c], w), prior_weight=3.0, **kw)
    b = run(n, prior=prior, prior_weight=3.0 * wmap, **kw)
    np.testing.assert_allclose(a.depth, b.depth, rtol=0, atol=1e-9)
    plain = run(n, prior=(r, c, prior[r, c]), prior_weight=3.0, **kw)
    assert np.abs(a.depth - plain.depth).max() > 1e-6  # (the weights did something)
    # a far-off point of weight 0 is no sample (in a sampled pixel: kept, it would make the
    # pixel's points disagree, which leaves the pixel out)
    far = (np.r_[r, r[0]], np.r_[c, c[0]], np.r_[prior[r, c], 50.0], np.r_[w, 0.0])
    np.testing.assert_allclose(run(n, prior=far, prior_weight=3.0, **kw).depth, a.depth,
                               rtol=0, atol=1e-9)
    img, wimg = prior_samples(tuple(map(np.array, ([2, 2, 4], [3, 3, 1], [100.0, 101.5, 2.0],
                                                   [1.0, 2.0, 0.5]))), (8, 8), positive=True)
    assert img[2, 3] == 101.0 and wimg[2, 3] == pytest.approx(5 / 3)  # (sum w^2 / sum w)
    assert img[4, 1] == 2.0 and wimg[4, 1] == 0.5
    assert np.isfinite(img).sum() == 2 and prior_samples(prior, depth.shape)[1] is None


@pytest.mark.parametrize("weights, match", [
    ([1.0, -1.0], r"`prior\[3\]` \(the points' weights\) must be finite and >= 0; got -1.0 "
                  r"for the point at \(row 3, col 4\)"),
    ([1.0, np.nan], r"`prior\[3\]`.* got nan"),
    ([0.0, 0.0], r"every point's weight is 0"),
    ([1.0], r"needs four arrays of one length; got lengths 2, 2, 2, 1"),
])
def test_points_weights_errors(weights, match):
    n, _ = wave()
    with pytest.raises(ValueError, match=match):
        run(n, prior=([1, 3], [2, 4], [1.0, 1.0], weights))


def test_prior_and_confidence_from_matlab_files(tmp_path, capsys):
    """Quéau's toolbox keeps a prior z0 and its weights lambda in .mat files: --prior and
    --confidence read them (a variable of a known name, or the only (H, W) one), as a dataset
    folder's prior_depth.mat does; anything else lists the variables."""
    from scipy import io as sio

    n, depth, prior, sel = _write_inputs(tmp_path)
    conf = np.ones(depth.shape)
    conf[2:5, 2:5] = 0.0
    np.save(tmp_path / "conf.npy", conf)
    sio.savemat(tmp_path / "z0.mat", {"z0": prior, "lambda": np.full(depth.shape, 7.0)})
    sio.savemat(tmp_path / "c.mat", {"anything": conf, "scalar": 3.0})
    np.testing.assert_array_equal(facetlift.io.read_prior(tmp_path / "z0.mat"), prior)
    # lambda is the prior's weight (Quéau's), no confidence of the normals (a review)
    np.testing.assert_array_equal(
        facetlift.io.read_weights(tmp_path / "z0.mat", arg="prior_weight_map"),
        np.full(depth.shape, 7.0))
    with pytest.raises(ValueError, match=r"one named confidence, weights, weight, w; got "
                       r"variables lambda \(24x28\), z0 \(24x28\)"):
        facetlift.io.read_weights(tmp_path / "z0.mat", arg="confidence")
    for name, extra in (("npy", ["--prior", str(tmp_path / "prior.npy"), "--confidence",
                                 str(tmp_path / "conf.npy")]),
                        ("mat", ["--prior", str(tmp_path / "z0.mat"), "--confidence",
                                 str(tmp_path / "c.mat")])):
        code = main(["integrate", str(tmp_path / "n.npy"), *extra, "-s", "npy",
                     "-o", str(tmp_path / name)])
        assert code == 0, capsys.readouterr().err
    np.testing.assert_array_equal(np.load(tmp_path / "mat" / "depth.npy"),
                                  np.load(tmp_path / "npy" / "depth.npy"))
    sio.savemat(tmp_path / "two.mat", {"a": conf, "b": conf})
    code = main(["integrate", str(tmp_path / "n.npy"), "--confidence", str(tmp_path / "two.mat"),
                 "-o", str(tmp_path / "bad")])
    err = capsys.readouterr().err
    assert code == 1 and "must hold one (H, W) numeric weight map, or one named " \
        "confidence" in err and "got variables a (24x28), b (24x28)" in err, err


def test_a_few_points_as_a_list_of_rows_are_refused_not_read_as_columns():
    """Three (row, col, depth) points in a list were read as the columns (rows, cols,
    depths): the depths became pixel positions (a median depth of 273 instead of 1500 and
    no word, a user's check); four of them were refused, and with a weights column they
    would now be read as columns too."""
    n, _ = wave()
    for pts in ([(5, 6, 1.5), (6, 7, 1.5), (7, 6, 1.5)],
                [[5, 6, 1.5], [6, 7, 1.5], [7, 6, 1.5], [8, 8, 1.5]],  # (json.load, tolist())
                [(5, 6, 1.5), (6, 7, 1.5), (7, 6, 1.5), (8, 8, 1.5)]):
        with pytest.raises(ValueError, match=r"could be columns \(rows, cols, depths\[, "
                           r"weights\]\) or points.*tuple\(np.asarray\(points, float\).T\)"):
            run(n, prior=pts)
        s = run(n, prior=tuple(np.asarray(pts, float).T))
        assert s.info["prior"]["samples"] == len(pts)
    with pytest.raises(ValueError, match=r"got shape \(5, 3\); a list of \(row, col, depth\) "
                       "points"):
        run(n, prior=[(5, 6, 1.5)] * 5)
    r3 = np.array([[5, 6, 7, 8, 9], [6, 7, 6, 8, 9], [1.5] * 5])  # (rows, cols, depths) rows
    with pytest.raises(ValueError, match=r"got shape \(3, 5\); the rows \(rows, cols, depths"
                       r"\[, weights\]\) of one array\? Give them as a tuple, tuple\(arr\)"):
        run(n, prior=r3)
    assert run(n, prior=tuple(r3)).info["prior"]["samples"] == 5
    # a map of three or four rows given as a nested list is a map (a review)
    small = np.ones((4, 5, 3)) * [0.0, 0.0, 1.0]
    for rows in (3, 4):
        s = run(small[:rows], prior=np.full((rows, 5), 2.0).tolist())
        assert s.info["prior"]["samples"] == rows * 5


def test_prior_weight_map_errors_name_the_flag(tmp_path, capsys):
    n, depth, prior, sel = _write_inputs(tmp_path)
    np.save(tmp_path / "wneg.npy", np.full(depth.shape, -1.0))
    for extra in ([], ["--prior-weight", "5"]):  # (its product was blamed on --prior-weight)
        code = main(["integrate", str(tmp_path / "n.npy"), "--prior",
                     str(tmp_path / "prior.npy"), "--prior-weight-map", str(tmp_path / "wneg.npy"),
                     *extra, "-o", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 1 and ("--prior-weight-map must be finite, >= 0" if not extra else
                              "--prior-weight-map (times --prior-weight) must be finite, >= 0"
                              ) in err, err
    # a sentinel where the prior has no sample is no error (as integrate's prior_weight)
    wmap = np.full(depth.shape, -1.0)
    wmap[sel] = 2.0
    np.save(tmp_path / "wsentinel.npy", wmap)
    assert main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "prior.npy"),
                 "--prior-weight-map", str(tmp_path / "wsentinel.npy"), "-s", "npy",
                 "-o", str(tmp_path / "ok")]) == 0, capsys.readouterr().err


def test_points_files_with_a_weight_column(tmp_path, capsys):
    """A weight (or confidence) column of a points file weighs its points, given with --prior
    or as a dataset folder's prior_depth.csv; info reads it; a bad weight names its line."""
    n, depth, prior, sel = _write_inputs(tmp_path)
    r, c = np.nonzero(sel)
    w = np.linspace(0.5, 4.0, r.size)
    wmap = np.ones(depth.shape)
    wmap[r, c] = w
    np.save(tmp_path / "wmap.npy", wmap)
    (tmp_path / "pts.csv").write_text("u,v,depth,confidence\n" + "".join(
        f"{b},{a},{float(prior[a, b])!r},{float(x)!r}\n" for a, b, x in zip(r, c, w, strict=True)))
    pts = facetlift.io.read_prior(tmp_path / "pts.csv")
    assert len(pts) == 4 and np.array_equal(pts[3], w)
    for name, extra in (("map", ["--prior", str(tmp_path / "prior.npy"), "--prior-weight-map",
                                 str(tmp_path / "wmap.npy")]),
                        ("points", ["--prior", str(tmp_path / "pts.csv")])):
        code = main(["integrate", str(tmp_path / "n.npy"), *extra, "--prior-weight", "2",
                     "-s", "npy", "-o", str(tmp_path / name)])
        assert code == 0, capsys.readouterr().err
    expected = np.load(tmp_path / "map" / "depth.npy")
    np.testing.assert_allclose(np.load(tmp_path / "points" / "depth.npy"), expected, atol=1e-9)
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    (folder / "prior_depth.csv").write_text((tmp_path / "pts.csv").read_text())
    assert len(facetlift.io.read_dataset(folder)["prior"]) == 4
    assert main(["integrate", str(folder), "--prior-weight", "2", "-s", "npy",
                 "-o", str(tmp_path / "ds_out")]) == 0, capsys.readouterr().err
    np.testing.assert_allclose(np.load(tmp_path / "ds_out" / "depth.npy"), expected, atol=1e-9)
    assert main(["info", str(folder)]) == 0 and "depth prior" in capsys.readouterr().out
    (folder / "prior_depth.csv").write_text("row,col,depth,weight\n999,0,1.0,1\n")
    assert main(["integrate", str(folder), "-o", str(tmp_path / "far")]) == 1
    err = capsys.readouterr().err  # (the folder's hint, as for a file without weights)
    assert "outside the 24 x 28 image" in err and "--no-prior" in err, err
    (tmp_path / "zero.csv").write_text("row col depth weights\n1 2 3 0\n2 3 4 0\n")
    with pytest.raises(ValueError, match=r"zero.csv: the weight column is 0 on every line"):
        facetlift.io.read_prior(tmp_path / "zero.csv")
    (tmp_path / "bad.csv").write_text("row col depth weight\n1 2 3 1\n2 3 4 -2\n")
    code = main(["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "bad.csv"),
                 "-o", str(tmp_path / "bad")])
    err = capsys.readouterr().err
    assert code == 1 and "weight column must hold finite numbers >= 0; got -2.0 on data " \
        "line 2" in err, err


def test_a_pixel_whose_points_disagree_is_left_out():
    """A LiDAR cloud seen past an object's edge puts points of the wall behind into the
    object's pixels, and an SfM point duplicated across views may be mismatched in one: the
    mean was a depth neither surface has; keeping the nearest kept a mismatch in front and
    dropped the good points behind it (a user's check)."""
    from facetlift.problem import CONFLICT, prior_image

    rows = np.array([2.0, 2.2, 1.9, 5.0, 5.1, 7.0])
    cols = np.array([3.0, 2.9, 3.1, 7.0, 7.0, 1.0])
    depths = np.array([2.0, 2.0 * (1 + CONFLICT / 2), 3.0, 4.0, 4.0, 1.0])
    with pytest.warns(UserWarning, match=r"1 pixel\(s\) hold points whose depths differ by "
                      r"more than 2% of the depth \(the first at row 2, col 3; 3 points\): they "
                      r"were left out"):
        img = prior_image((rows, cols, depths), (8, 10), positive=True)
    assert np.isnan(img[2, 3]) and img[5, 7] == 4.0 and img[7, 1] == 1.0
    assert np.isfinite(img).sum() == 2
    # a mismatch in front of two good points: the pixel goes, not the good points alone
    with pytest.warns(UserWarning, match=r"1 pixel\(s\) hold points"):
        img = prior_image((rows[:3], cols[:3], [2.0, 2.0, 1.5]), (8, 10), positive=True)
    assert np.isfinite(img).sum() == 0
    # without a camera: a share of the samples' depth range
    with pytest.warns(UserWarning, match=r"by more than 2% of the depth range"):
        img = prior_image((rows, cols, depths), (8, 10))
    assert np.isnan(img[2, 3])
    # points of one surface in a pixel are averaged without a word
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        img = prior_image((rows[:2], cols[:2], depths[:2]), (8, 10), positive=True)
    assert img[2, 3] == pytest.approx(2.0 * (1 + CONFLICT / 4))


@pytest.mark.skipif(not (Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"
                         / "armadillo.ply").is_file(),
                    reason="../shared/data not beside the checkout")
def test_exact_sparse_samples_on_a_render_with_rim_slivers_do_not_warn_of_tearing():
    """A fresh SfM user's exact 1 % samples on the armadillo render were told the prior tore
    the surface (1,564 pieces, counted before the slivers of at most SMALL_PIECE facets hang
    on their neighbours; 1,140 without a prior): the mesh's pieces count now."""
    from facetlift import synthetic
    from facetlift.bench.discontinuities import load_mesh

    mesh = load_mesh(Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"
                     / "armadillo.ply")
    gt = synthetic.render_perspective(mesh, resolution=(256, 306))
    rng = np.random.default_rng(0)
    rr, cc = np.nonzero(gt.mask)
    pick = rng.choice(rr.size, int(0.01 * rr.size), replace=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = facetlift.integrate(gt.normals, gt.mask, K=gt.K, prior_weight=100.0,
                                prior=(rr[pick], cc[pick], gt.depth[rr[pick], cc[pick]]),
                                discontinuities=True)
    assert s.info["pieces"] > 0.05 * gt.mask.sum()  # (the slivers before the hanging)
    assert not [w for w in caught if "tear" in str(w.message)]


def test_pixel_conflicts_do_not_hide_crowded_points_walls_or_points_behind_the_camera():
    """A review: a camera-frame cloud read as pixels put thousands of points of spread depths
    into 9 pixels, every one conflicted, and the crowded warning said '0 pixel(s)'; points all
    behind the camera conflicted away before the sign error; a wall's exact samples (depth
    range 0) conflicted over a rounding difference."""
    from facetlift.problem import prior_image

    xyz = np.random.default_rng(1).uniform(0, 2, (2900, 3)) + [0, 0, 2.5]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        img = prior_image((xyz[:, 1], xyz[:, 0], xyz[:, 2]), (40, 50), positive=True)
    said = " ".join(str(w.message) for w in caught)
    assert re.search(r"fall into only [1-9]\d* pixel", said) and "hold points" not in said
    assert np.isfinite(img).sum() == 9
    K = np.array([[100.0, 0, 14], [0, 100.0, 12], [0, 0, 1]])
    n, _ = wave()
    with pytest.raises(ValueError, match="positive z-depths"):
        facetlift.integrate(n, K=K, prior=([2, 2.2], [3, 3], [-2.0, -2.5]))
    rows, cols = np.divmod(np.arange(20), 5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        img = prior_image((np.r_[rows, 1], np.r_[cols, 1], np.r_[np.full(20, 3.0), 3.0 + 1e-12]),
                          (8, 10))
    assert np.isfinite(img).sum() == 20


def test_the_time_estimate_allows_for_a_prior():
    """A LiDAR user's run at weight 100 took 8.1 s against 1.2-4.9 s estimated: the slowest
    time is PRIOR_SLOWER times the one without a prior."""
    from facetlift.describe import PRIOR_SLOWER, SECONDS_PER_PIXEL, estimate

    n, _ = wave()
    rows, cols = np.divmod(np.arange(0, 24 * 28, 7), 28)
    for kw in ({}, {"discontinuities": True}):
        plain = estimate(facetlift.prepare(n), **kw)
        fused = estimate(facetlift.prepare(n, prior=(rows, cols, np.full(rows.size, 5.0))),
                         **kw)
        fast, slow = SECONDS_PER_PIXEL[fused["route"]]
        assert fused["seconds"] == pytest.approx([fast * 672, PRIOR_SLOWER * slow * 672])
        fast, slow = SECONDS_PER_PIXEL[plain["route"]]
        assert plain["seconds"] == pytest.approx([fast * 672, slow * 672])


def test_a_prior_out_of_the_normals_scale_is_named_by_the_tearing_warning():
    """Exact samples with a pixel_size 32 times too small: no outlier can be told (the
    tolerance grows with the disagreement), and the cuts tear the sphere apart; the warning
    now names the scale as a cause."""
    from facetlift import synthetic

    gt = synthetic.analytic("sphere", 64)
    rng = np.random.default_rng(0)
    rr, cc = np.nonzero(gt.mask)
    k = rng.choice(rr.size, 80, replace=False)
    with pytest.warns(UserWarning, match=r"tear the surface apart.* not in the normals' scale "
                      r"\(pixel_size, K"):
        facetlift.integrate(gt.normals, gt.mask, prior=(rr[k], cc[k], gt.depth[rr[k], cc[k]]),
                            pixel_size=gt.pixel_size / 32, discontinuities=True)


def test_an_orthographic_prior_in_other_units_than_the_normals_is_named():
    """An audit: the DiLiGenT bear's exact samples in mm without its K (or pixel size) came
    out 30x worse with only the depth-jump hint. The prior's relief against the normals' (at
    `pixel_size`) is measured on pairs of nearby samples and a factor of 2 or more named."""
    n, depth = wave((60, 70))
    prior = sparse(3.0 * depth)[0]  # (the depth at pixel_size 3)
    with pytest.warns(UserWarning, match=r"prior: its relief is 3\.\d* times what the normals "
                      r"give at pixel_size 1 .* pixel_size of about 3\.\d"):
        s = facetlift.integrate(n, prior=prior)
    assert s.info["prior"]["relief_ratio"] == pytest.approx(3.0, rel=0.05)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = facetlift.integrate(n, prior=prior, pixel_size=3.0)
        facetlift.integrate(n, prior=sparse(depth)[0])
    assert not [w for w in caught if "relief" in str(w.message)]
    assert s.info["prior"]["relief_ratio"] == pytest.approx(1.0, rel=0.05)
    # with K the relief is of log-depth: the prior's units do not change it (a dense prior's
    # too, since 2026-12-05; a relative depth's offset does: tests/test_prior_fit.py)
    K = np.array([[100.0, 0, 35], [0, 100.0, 30], [0, 0, 1]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = facetlift.integrate(n, prior=sparse(3.0 * depth + 100.0)[0], K=K)
        b = facetlift.integrate(n, prior=1000.0 * sparse(3.0 * depth + 100.0)[0], K=K)
    assert a.info["prior"]["relief_ratio"] is not None
    assert a.info["prior"]["relief_ratio"] == pytest.approx(b.info["prior"]["relief_ratio"])


def test_prior_fit_from_threads_leaves_the_warning_state_as_it_was():
    """An audit: integrate(..., prior_fit=...) from a two-thread pool left an 'always' filter
    and the display of later warnings pointing at a finished thread's record (the capture
    swaps module-wide state); the capturing blocks now take turns."""
    from concurrent.futures import ThreadPoolExecutor

    n, depth = wave((40, 48))
    prior = np.where(np.isfinite(depth), 2.0 * depth + 5.0, np.nan)
    serial = facetlift.integrate(n, prior=prior, prior_fit="affine").depth
    show, filters = warnings._showwarnmsg_impl, list(warnings.filters)
    with ThreadPoolExecutor(2) as ex:
        depths = list(ex.map(lambda _: facetlift.integrate(n, prior=prior,
                                                           prior_fit="affine").depth, range(12)))
    assert warnings._showwarnmsg_impl is show and warnings.filters == filters
    for d in depths:
        np.testing.assert_array_equal(d, serial)
    with pytest.warns(UserWarning, match="still heard"):
        warnings.warn("still heard", UserWarning, stacklevel=1)


def test_threads_record_their_own_warnings_at_the_same_time():
    """A review: a lock around whole recording blocks ran a threaded cluster's items one at a
    time (and could deadlock); each thread now records its own warnings while the others
    run, and the state is put back when the last one leaves."""
    import threading

    from facetlift._warnings import recording

    show, filters = warnings._showwarnmsg_impl, list(warnings.filters)
    both_inside = threading.Barrier(2, timeout=10)  # (taking turns would time out here)
    got = {}

    def work(name):
        with recording() as caught:
            both_inside.wait()
            warnings.warn(f"from {name}", UserWarning, stacklevel=1)
            both_inside.wait()
        got[name] = [str(w.message) for w in caught]

    threads = [threading.Thread(target=work, args=(k,)) for k in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == {"a": ["from a"], "b": ["from b"]}
    assert warnings._showwarnmsg_impl is show and warnings.filters == filters


def test_warnings_of_calls_in_a_loop_are_shown_once_with_prior_fit_among_them():
    """A notebook audit: once a prior_fit call was in a loop, every warning came again on
    every turn (each recording block emptied the modules' registries of warnings shown once,
    and prior_fit's own were re-emitted without one). Under the default filters each is
    shown once now, as without prior_fit."""
    from facetlift import synthetic

    g = synthetic.analytic("sphere", 48)
    n8 = ((np.nan_to_num(g.normals) + 1) * 127.5).astype(np.uint8)
    prior = np.where(g.mask, 2 * g.depth + 1, np.nan)
    prior[24, 24] = np.inf
    with warnings.catch_warnings(record=True) as got:
        warnings.resetwarnings()
        warnings.simplefilter("default")
        for _ in range(3):
            facetlift.integrate(n8, g.mask)
            facetlift.integrate(g.normals, g.mask, prior=prior, prior_fit="affine")
    said = [str(w.message) for w in got]
    assert len([m for m in said if "is uint8: decoded" in m]) == 1, said
    assert len([m for m in said if "hold inf" in m]) == 1, said


def test_a_recording_thread_leaves_the_filters_other_threads_set_meanwhile():
    """An audit: the capture saved the filters when the first thread began to record and
    put that list back when the last one left, so a main thread's temporary
    simplefilter("error", ...) inside catch_warnings, entered before a prior_fit run in a
    worker and left while it ran, stayed for good (the next 8-bit map raised FrameWarning),
    and a simplefilter("ignore", ...) set while it ran was lost. The capture now takes out
    its own "always" entry only."""
    import threading

    from facetlift._warnings import recording

    filters = list(warnings.filters)

    def recording_worker():
        """A thread inside a recording block; the returned call lets it leave."""
        inside, resume = threading.Event(), threading.Event()

        def work():
            with recording():
                inside.set()
                resume.wait(10)

        t = threading.Thread(target=work)
        t.start()
        inside.wait(10)
        return lambda: (resume.set(), t.join())

    with warnings.catch_warnings():  # (entered before, left while the worker records)
        warnings.simplefilter("error", facetlift.FrameWarning)
        finish = recording_worker()
    finish()
    assert warnings.filters == filters
    try:
        finish = recording_worker()
        warnings.simplefilter("ignore", facetlift.FrameWarning)  # (set while it records)
        finish()
        assert warnings.filters[1:] == filters
        assert warnings.filters[0][:3] == ("ignore", None, facetlift.FrameWarning)
    finally:
        warnings.filters[:] = filters
        warnings._filters_mutated()
    finish = recording_worker()
    with warnings.catch_warnings():  # (entered while the worker records, left after it)
        finish()
    assert warnings.filters == filters
    with pytest.warns(UserWarning, match="still heard"):
        warnings.warn("still heard", UserWarning, stacklevel=1)
    # (the display that catch_warnings left is the capture's: a later capture keeps the one
    # saved before it, so that another thread's warning is still shown, not passed round to
    # itself until the recursion limit, a review)
    shown, show = [], warnings.showwarning
    warnings.showwarning = lambda message, *rest, **kw: shown.append(str(message))
    try:
        finish = recording_worker()
        with warnings.catch_warnings():
            finish()
        finish = recording_worker()
        warnings.warn("heard while one records", UserWarning, stacklevel=1)
        finish()
        warnings.warn("heard after", UserWarning, stacklevel=1)
    finally:
        warnings.showwarning = show
    assert shown == ["heard while one records", "heard after"], shown
    # a capture left in a list that another thread's nested catch_warnings keeps current:
    # the next capture's snapshot of the user's filters leaves that stale entry out, so the
    # user's error filter still raises in another thread while it records (a review)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        finish = recording_worker()
        with warnings.catch_warnings():
            with warnings.catch_warnings():
                finish()
            finish = recording_worker()
            with pytest.raises(RuntimeWarning, match="still an error"):
                warnings.warn("still an error", RuntimeWarning, stacklevel=1)
            finish()


def test_samples_move_the_pieces_of_the_normals_cuts_instead_of_tearing_islands(monkeypatch):
    """With a sparse pointwise prior the reweightings start from the normals' own cuts
    (PRIOR_CUTS_FIRST): exact samples then move whole pieces. From the smooth surface each
    sample pulled a dent that the bilateral weights cut loose, an island at the right depth
    in a region left where it was (the analytic occluder, 2 % exact samples, four draws:
    0.26-0.31 % of the depth range against 0.04-0.18 %; the fusion benchmark's 256^2 one,
    1 %: 0.35 % against 0.03 %)."""
    from facetlift import synthetic
    from facetlift.methods import dgp

    gt = synthetic.analytic("occluder", 64)
    kw = {"pixel_size": gt.pixel_size, "discontinuities": True}

    def error(first, prior):
        monkeypatch.setattr(dgp, "PRIOR_CUTS_FIRST", 0.25 if first else 0.0)
        s = run(gt.normals, gt.mask, prior=prior, prior_weight=100.0, **kw)
        return np.nanmean(np.abs(s.depth - gt.depth)) / gt.depth_range, s.info

    priors = [sparse(np.where(gt.mask, gt.depth, np.nan), 0.02, seed=i)[0] for i in range(4)]
    islands = [error(False, p) for p in priors]
    moved = [error(True, p) for p in priors]
    assert all("prior_free" not in info for _, info in islands)
    assert sum(e for e, _ in moved) < 0.5 * sum(e for e, _ in islands)
    assert max(e for e, _ in moved) < 2.5e-3
    # the first pass is the prior-free route's reweightings, the cap shared by both passes
    alone = run(gt.normals, gt.mask, **kw).info
    info = moved[0][1]
    assert info["prior_free"]["iterations"] == alone["iterations"]
    assert info["prior_free"]["grown"] == alone["grown"]
    assert len(info["weight_change"]) == info["iterations"] > alone["iterations"]
    capped = run(gt.normals, gt.mask, prior=priors[0], prior_weight=100.0,
                 discontinuity_iter=alone["iterations"] + 1, **kw).info
    assert capped["iterations"] == alone["iterations"] + 1 and not capped["converged"]
    # a dense prior (more than a quarter of the facets) starts from the smooth surface: there
    # the first pass changed nothing measurable and cost its time
    dense = run(gt.normals, gt.mask, prior=np.where(gt.mask, gt.depth, np.nan),
                prior_weight=0.01, **kw)
    assert "prior_free" not in dense.info


def test_islands_around_samples_are_glued_back_where_the_normals_show_no_jump(monkeypatch):
    """A jump the normals do not show (flat normals over a raised square: a CAD part seen
    head-on) and exact samples on both levels: samples pulled their own few facets to their
    depth and the prior's reweightings cut them loose, islands inside a region left where the
    normals put it. ISLAND_FACETS glues such islands back where their nearest samples are
    islands too (the samples then move their region); off, the surface met those samples at
    their own pixels only."""
    from facetlift.methods import dgp

    n = np.zeros((96, 96, 3))
    n[..., 2] = 1.0
    mask = np.ones((96, 96), bool)
    depth = np.full((96, 96), 20.0)
    depth[24:72, 24:72] = 40.0
    prior = np.full(depth.shape, np.nan)
    pick = np.random.default_rng(2).choice(depth.size, 90, replace=False)
    prior.flat[pick] = depth.flat[pick]

    def error(facets):
        monkeypatch.setattr(dgp, "ISLAND_FACETS", facets)
        s = run(n, mask, prior=prior, prior_weight=100.0, discontinuities=True)
        return np.abs(s.depth - depth).mean(), s.info

    kept, off = error(0)
    glued, info = error(16)
    assert info["islands_reglued"] >= 3 and "islands_reglued" not in off
    assert glued < 0.7 * kept
    # (one more solve: the system with the islands glued, with the final weights)
    assert len(info["cg_iterations"]) == len(off["cg_iterations"]) + 1
    assert info["final_weights"] and off["final_weights"]
    assert info["polish"] == "multigrid"
    # samples that agree with the normals make no island
    flat = run(n, mask, prior=np.where(np.isfinite(prior), 20.0, np.nan), prior_weight=100.0,
               discontinuities=True)
    assert flat.info["islands_reglued"] == 0
    assert np.allclose(flat.depth, 20.0, atol=1e-6)


@pytest.mark.parametrize("company", [4, 0])
def test_an_island_whose_piece_holds_no_other_sample_is_glued_back(monkeypatch, company):
    """A piece the normals misplaced whose one sample the prior's reweightings cut loose on an
    island of its own (the fusion benchmark's cow@left, 1 % exact samples: the head's only
    sample, 4.7 mm MADE): the island's nearest samples lie on other, well-placed pieces, so
    the company rule alone left it, and the piece kept no sample to place it. The island is
    glued back where its piece holds no sample but islands'; not where the piece has one of
    its own (that sample places it, and the island's is then the odd one)."""
    from facetlift.domain import Domain
    from facetlift.methods import dgp

    monkeypatch.setattr(dgp, "ISLAND_COMPANY", company)
    dom = Domain.from_mask(np.ones((40, 40), bool))
    level = np.zeros((40, 40))
    level[10:30, 10:30] = 10.0  # a piece cut from the rest all round
    level[18:20, 18:20] = -5.0  # an island of 4 facets inside it
    r, c = dom.pixels
    copies = np.repeat(level[r, c][:, None], 4, axis=1)
    grid = np.zeros((40, 40), bool)
    grid[::5, ::5] = True
    grid[10:30, 10:30] = False  # samples around the piece, none on it ...
    grid[18, 18] = True  # ... but the island's

    def islands(sampled, lonely=True):
        monkeypatch.setattr(dgp, "ISLAND_LONELY", lonely)
        verts, count, _ = dgp._sample_islands(dom, copies, sampled[r, c], 1.0)
        return verts.reshape(41, 41), count

    verts, count = islands(grid)
    assert count == 1 and verts.sum() == 9 and verts[18:21, 18:21].all()
    if company:  # (without the company rule every island inside one piece is glued back)
        assert islands(grid, lonely=False)[1] == 0
    held = grid.copy()
    held[25, 25] = True  # the piece's own sample
    assert islands(held)[1] == (0 if company else 1)


@pytest.mark.parametrize("cluster", [False, True])
def test_an_outlier_samples_island_is_left_cut(monkeypatch, cluster):
    """An outlier sample that the removal let through is cut loose on an island of its own,
    which keeps its error local; its nearest samples on other pieces are no islands, so
    ISLAND_FACETS leaves it. Glued back it pulled a dent (a review's sphere, 1 % samples,
    three raised by 30 % of the depth range, weight 1: 0.08 -> 1.07 % of the range); three
    adjacent outliers (which the removal does not find: they agree) share one island and
    voted for each other until the vote left the island's own samples out (0.05 -> 0.95 %)."""
    from facetlift import synthetic
    from facetlift.methods import dgp

    gt = synthetic.analytic("sphere", 96)
    idx = np.flatnonzero(gt.mask)
    pick = np.random.default_rng(0).choice(idx, int(0.01 * idx.size), replace=False)
    prior = np.full(gt.depth.shape, np.nan)
    prior.flat[pick] = gt.depth.flat[pick]
    if cluster:
        bad = np.ravel_multi_index(([40, 40, 41], [52, 53, 52]), prior.shape)
        prior.flat[bad] = gt.depth.flat[bad] + 0.3 * gt.depth_range
    else:
        prior.flat[pick[:3]] += 0.3 * gt.depth_range
    kw = {"prior": prior, "prior_weight": 1.0, "discontinuities": True}
    s = run(gt.normals, gt.mask, **kw)
    monkeypatch.setattr(dgp, "ISLAND_COMPANY", 0)  # (every island inside one region)
    every = run(gt.normals, gt.mask, **kw)
    monkeypatch.setattr(dgp, "ISLAND_FACETS", 0)
    off = run(gt.normals, gt.mask, **kw)
    assert s.info["islands_reglued"] == 0 and every.info["islands_reglued"] >= 1
    assert np.array_equal(s.depth, off.depth, equal_nan=True)
    err = [np.nanmean(np.abs(x.depth - gt.depth)) for x in (s, every)]
    assert err[0] < 0.2 * err[1]


def test_the_first_pass_is_the_prior_free_route_also_with_a_confidence_map():
    """The prior-free route takes a confidence map's ratios only (prepare scales it to a
    largest of 1 without a prior, not with one): the first pass scales it alike, so a uniform
    confidence of 0.01 gives it the cuts of none."""
    from facetlift import synthetic

    gt = synthetic.analytic("occluder", 64)
    n = gt.normals.copy()
    n[20:30, 10:18] = np.nan  # (facets without a normal keep a weight of 1 whatever the scale)
    kw = {"pixel_size": gt.pixel_size, "discontinuities": True}
    prior, _ = sparse(np.where(gt.mask, gt.depth, np.nan), 0.02, seed=0)
    plain = run(n, gt.mask, prior=prior, **kw).info["prior_free"]
    low = run(n, gt.mask, prior=prior, confidence=np.full(n.shape[:2], 0.01),
              **kw).info["prior_free"]
    alone = run(n, gt.mask, **kw).info
    assert low["iterations"] == plain["iterations"] == alone["iterations"]
    assert low["grown"] == plain["grown"] == alone["grown"]


@pytest.mark.parametrize("prior", [False, True])
def test_confidence_zero_on_a_grazing_normal_equals_a_missing_one(prior):
    """A normal of confidence 0 is missing also where it is grazing: the discontinuity route
    fills an isolated missing facet from its neighbours (fill_gaps) but leaves a grazing one
    as a silhouette's gap, and confidence 0 on a grazing normal was left as such a gap where
    the same pixel without a normal was filled (two facets of a fusion benchmark scene: the
    surfaces differed)."""
    n, depth = wave()
    tilt = np.array([np.sin(np.radians(88.0)), 0.0, np.cos(np.radians(88.0))])
    n[9, 11] = tilt  # (grazing: view cosine below the route's cos 87.5 deg)
    assert tilt[2] < facetlift.METHODS["dgp"].jump_grazing
    conf = np.ones(depth.shape)
    conf[9, 11] = 0.0
    missing = n.copy()
    missing[9, 11] = np.nan
    kw = {"discontinuities": True}
    if prior:
        kw["prior"] = sparse(depth, 0.05, seed=1)[0]
    full = np.ones(depth.shape, bool)
    a = run(n, full, confidence=conf, **kw)
    b = run(missing, full, **kw)
    assert a.info["gaps_filled"] == b.info["gaps_filled"] == 1
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-9 * np.ptp(depth))


def _shared_bear():
    """(the DiLiGenT bear's dataset, its ground-truth depth) from ../shared, or a skip."""
    from pathlib import Path

    from facetlift import io

    bear = Path(__file__).resolve().parents[2] / "shared" / "data" / "normal_maps" / \
        "diligent_bear"
    if not bear.is_dir():
        pytest.skip("shared DiLiGenT bear not available")
    with np.load(bear / "depth_gt.npz") as z:
        return io.read_dataset(bear), np.asarray(z["depth_gt"], float)


def test_a_blurred_prior_that_tears_the_surface_is_warned_about(monkeypatch):
    """An audit's 4x coarse sensor (block means of the DiLiGenT bear's depth with 3 mm of
    noise, 5 % dropouts, whole millimetres, upsampled bilinearly) given with prior_blur tore
    the discontinuity route into 827 pieces (37 % of the corners cut, 2.56 mm) without a word:
    the torn warning covers blurred priors too, and names the low pointwise weight that did
    better. Since the twenty-eighth session that surface, 17.9 deg from its own normals on
    average, is caught as bent (methods.dgp.BENT) and the prior compared pixel by pixel:
    MADE 0.20 mm, 73 mesh pieces (checked below; the torn warning with BENT off)."""
    from scipy.ndimage import map_coordinates

    import facetlift.methods.dgp as dgp

    ds, gt = _shared_bear()
    f, (H, W) = 4, gt.shape
    blocks = gt.reshape(H // f, f, W // f, f)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (blocks off the object)
        coarse = np.nanmean(blocks, axis=(1, 3))
    coarse[np.isfinite(blocks).mean(axis=(1, 3)) < 0.75] = np.nan  # (edge blocks: no return)
    rng = np.random.default_rng(0)
    coarse = np.round(coarse + rng.normal(0, 3.0, coarse.shape))
    coarse[rng.random(coarse.shape) < 0.05] = np.nan
    rows, cols = np.mgrid[:H, :W].astype(float)
    at = [(rows - (f - 1) / 2) / f, (cols - (f - 1) / 2) / f]
    known = map_coordinates(np.isfinite(coarse).astype(float), at, order=1, mode="constant")
    sensor = np.where(known > 0.999, map_coordinates(np.nan_to_num(coarse), at, order=1,
                                                     mode="nearest"), np.nan)
    kw = dict(K=ds["K"], prior=sensor, prior_blur=2.0, discontinuities=True)
    with pytest.warns(UserWarning, match=r"prior_blur: the surface departed from its own "
                                         r"normals by 1[5-9]\.\d deg"):
        s = facetlift.integrate(ds["normals"], ds["mask"], **kw)
    assert s.info["prior_blur"]["fallback"] and s.info["prior_blur"]["bent"] > dgp.BENT
    assert s.info["mesh_pieces"] < 100
    m = s.mask & np.isfinite(gt)
    assert facetlift.metrics.made(s.depth, gt, m)[0] < 0.5  # (0.20 mm; torn: 2.57)
    monkeypatch.setattr(dgp, "BENT", np.inf)
    with pytest.warns(UserWarning, match=r"blurred depth prior .* corners were cut, [\d,]+ "
                                         r"pieces: .*tore the surface apart.*0\.001"):
        s = facetlift.integrate(ds["normals"], ds["mask"], **kw)
    assert s.info["mesh_pieces"] > 100


def test_a_resized_point_grid_declared_blurred_is_warned_about():
    """A user's check: the DiLiGenT bear's depth at every 8th pixel, resized bilinearly to the
    map (no blur: each sample kept at its place) and given with prior_blur 8.9 (the 1.1 f rule
    of block means) came out 14.9 deg from its own normals, under the fallback's BENT, and
    2.7 mm off, without a word. It is kept but warned about (BENT_WARN), naming the samples as
    the better input; given as samples, the same depths give about 0.01 mm."""
    from scipy.ndimage import distance_transform_edt, zoom

    import facetlift.methods.dgp as dgp

    ds, gt = _shared_bear()
    m = ds["mask"]
    near = distance_transform_edt(~m, return_distances=False, return_indices=True)
    filled = np.where(m, gt, np.nan)[tuple(near)]
    resized = zoom(filled[::8, ::8], (512 / 64, 612 / 77), order=1)[:512, :612]
    with pytest.warns(UserWarning, match=r"prior_blur: the surface lies 1[2-5]\.\d deg from "
                                         r"its own normals .*A map resized from point samples"):
        s = facetlift.integrate(ds["normals"], m, K=ds["K"], prior=resized, prior_blur=8.9,
                                discontinuities=True)
    assert not s.info["prior_blur"].get("fallback")
    assert dgp.BENT_WARN < s.info["mean_deviation"] < dgp.BENT
    sel = s.mask & np.isfinite(gt)
    assert np.mean(np.abs(s.depth[sel] - gt[sel])) > 1.0  # (2.73 mm: kept as it was)
    samples = np.full(gt.shape, np.nan)
    samples[::8, ::8] = np.where(m, gt, np.nan)[::8, ::8]
    s = facetlift.integrate(ds["normals"], m, K=ds["K"], prior=samples,
                            discontinuities=True)
    assert np.mean(np.abs(s.depth[sel] - gt[sel])) < 0.05  # (0.011 mm)


def test_info_counts_a_sensor_maps_zeros_as_unknown_with_a_camera(tmp_path, capsys):
    """A review: info reported a perspective prior's zeros (a depth sensor's unknown, which
    integrate leaves out) as known pixels with the range 0 to 5; an orthographic prior's
    zeros are depths and stay counted."""
    import json

    n, _ = wave()
    np.save(tmp_path / "n.npy", n)
    p = np.zeros((24, 28))
    p[::4, ::4] = 5.0
    np.save(tmp_path / "p.npy", p)
    for extra, known, low in ((["--K", str(_K_file(tmp_path))], 42, 5.0), ([], 672, 0.0)):
        code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "p.npy"),
                     "--json", *extra])
        rec = json.loads(capsys.readouterr().out)
        assert code == 0 and rec["prior"]["known_pixels"] == known
        assert rec["prior"]["known_in_mask"] == known and rec["prior"]["range"][0] == low
    # fitted (--prior-fit) for a camera: the zeros are left out of the fit too (they pulled
    # the scale 1e4 off, a review), and info counts the same pixels
    code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "p.npy"),
                 "--json", "--K", str(_K_file(tmp_path)), "--prior-fit", "scale"])
    rec = json.loads(capsys.readouterr().out)
    assert code == 0 and rec["prior"]["known_pixels"] == 42
    K = np.loadtxt(_K_file(tmp_path))
    d = facetlift.integrate(n, K=K).depth
    q = np.where(p > 0, 3.0 * d, 0.0)
    with pytest.warns(UserWarning, match=r"`prior`: 630 pixel\(s\) in the mask hold exactly 0, "
                      r"the first at \(row 0, col 1\): left out of the fit"):
        s = facetlift.integrate(n, K=K, prior=q, prior_fit="scale")
    assert s.info["prior"]["fit"]["scale"] == pytest.approx(1 / 3)
    # a normalised map's 0 is no sensor's mark only: said so (a review)
    with pytest.warns(UserWarning, match=r"hold exactly 0.*or the end of a map normalised"):
        facetlift.integrate(n, K=K, prior=np.where(p > 0, 1.0 / (3.0 * d), 0.0),
                            prior_fit="disparity")
    assert s.info["input"]["prior_samples"] == 42
    # zeros only outside the mask (a map's background): no word (an audit)
    inner = np.zeros((24, 28), bool)
    inner[::4, :] = True
    inner[:, ::4] = True
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = facetlift.integrate(n, inner, K=K, prior=np.where(inner, 3.0 * d, 0.0),
                                prior_fit="scale")
        # (and without a mask: the domain is the valid normals, a review)
        blk = np.zeros((24, 28), bool)
        blk[4:20, 4:24] = True
        facetlift.integrate(np.where(blk[..., None], n, np.nan), K=K,
                            prior=np.where(blk, 3.0 * d, 0.0), prior_fit="scale")
    assert s.info["prior"]["fit"]["scale"] == pytest.approx(1 / 3, rel=1e-2)
    # a prior integrate refuses (a negated relative depth) keeps its values in the report
    np.save(tmp_path / "neg.npy", np.where(p > 0, -p, np.nan))
    code = main(["info", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "neg.npy"),
                 "--json", "--K", str(_K_file(tmp_path))])
    rec = json.loads(capsys.readouterr().out)
    assert code == 1 and "positive z-depths" in rec["problem"]
    assert rec["prior"]["known_pixels"] == 42 and rec["prior"]["range"] == [-5.0, -5.0]


def test_a_prior_of_weight_zero_everywhere_is_warned_about():
    """An audit: prior_weight 0 (or an all-zero weight map) dropped the prior in silence,
    leaving the camera's gauge where the user expected metric depth."""
    n = np.dstack([np.zeros((12, 14)), np.zeros((12, 14)), np.ones((12, 14))])
    p = np.full((12, 14), 5.0)
    with pytest.warns(UserWarning, match=r"`prior_weight` is 0 at every sample"):
        facetlift.integrate(n, prior=p, prior_weight=np.zeros((12, 14)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = facetlift.integrate(n, prior=p, prior_weight=1e-3)
    np.testing.assert_allclose(s.depth, 5.0, atol=1e-6)


def test_an_exact_dense_prior_is_not_blamed_for_the_normals_cuts():
    """An audit: an exact dense prior on a scene whose normals cut it into many pieces was
    told it tore the surface apart (and to lower its weight or blur it, which made the result
    3-5x worse). The warning now needs the prior to disagree with the normals from pixel to
    pixel (methods.dgp.prior_mismatch): exact, the DiLiGenT-like steps read about 0; with
    noise of 2 footprints about 1.9."""
    from facetlift import synthetic
    from facetlift.methods import dgp

    gt = synthetic.analytic("steps", 64)
    bx, by, target = dgp.targets(facetlift.prepare(gt.normals, gt.mask))
    problem = facetlift.prepare(gt.normals, gt.mask, prior=gt.depth)
    s = problem.camera.footprint()
    exact = dgp.prior_mismatch(problem.domain, dgp.fusion_terms(problem), bx, by, target, s)
    noisy = facetlift.prepare(gt.normals, gt.mask, prior=gt.depth + np.random.default_rng(0)
                              .normal(0, 2 * s, gt.depth.shape))
    rough = dgp.prior_mismatch(noisy.domain, dgp.fusion_terms(noisy), bx, by, target, s)
    assert exact < 0.05 * dgp.PRIOR_AGREES and 1.5 < rough < 2.5, (exact, rough)
    info = {"cut_corners": 0.9, "unsolved": []}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgp._discontinuity_warnings(info, dgp.fusion_terms(problem), problem.domain, 500,
                                    agrees=True)
    with pytest.warns(UserWarning, match=r"its samples tear the surface apart"):
        dgp._discontinuity_warnings(info, dgp.fusion_terms(problem), problem.domain, 500)


def test_the_torn_warning_is_gated_by_the_priors_agreement_in_a_run(monkeypatch):
    """The gate wired into the route (a review): with every cut counting as torn, an exact
    dense prior gets no warning, the same prior with 2 footprints of noise does."""
    from facetlift import synthetic
    from facetlift.methods import dgp

    monkeypatch.setattr(dgp, "TORN", -1.0)
    gt = synthetic.analytic("steps", 64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        facetlift.integrate(gt.normals, gt.mask, prior=gt.depth, prior_weight=0.01,
                            discontinuities=True)
    s = gt.depth.shape
    noisy = gt.depth + np.random.default_rng(1).normal(0, 2 * gt.pixel_size, s)
    with pytest.warns(UserWarning, match=r"its samples tear the surface apart"):
        facetlift.integrate(gt.normals, gt.mask, prior=noisy, prior_weight=0.01,
                            discontinuities=True)


def test_a_fusion_audits_mistakes_are_named():
    """A fusion audit: a 0..255 confidence beside a prior weighed the prior 255x less (12x
    the error) with no word; a dense prior flipped or shifted against the normals (15 and
    4.6 mm) had no word; a prior turned on its side was told to be resized (12 mm after);
    a per-point prior_weight array and an 8-bit PNG prior got messages with no way on."""
    from facetlift import io

    bear = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "normal_maps" \
        / "diligent_bear"
    if not bear.is_dir():
        pytest.skip("the shared data is not here")
    ds = io.read_dataset(bear)
    n, m, K = ds["normals"], ds["mask"], ds["K"]
    with np.load(bear / "depth_gt.npz") as z:
        gt = np.where(m, z["depth_gt"].astype(float), np.nan)
    noisy = gt + np.random.default_rng(0).normal(0, 1, gt.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (registered: silent)
        # (but for the bear's one lone normal 85 deg or more from the ray, said since
        # 2026-12-08: problem.STEEP_ISOLATED)
        warnings.simplefilter("ignore", facetlift.problem.UnusableNormalsWarning)
        facetlift.integrate(n, m, K=K, prior=noisy, prior_weight=0.01)
    for off in (noisy[::-1], np.roll(noisy, 30, 0)):
        with pytest.warns(UserWarning, match=r"its relief hardly follows the normals'.*blurred "
                          r".*or of another view, or not registered"):
            facetlift.integrate(n, m, K=K, prior=off, prior_weight=0.01)
    with pytest.warns(UserWarning, match=r"`confidence` reaches 255 .* 0\.\.255\?"):
        facetlift.integrate(n, m, K=K, prior=noisy, prior_weight=0.01,
                            confidence=np.full(m.shape, 255.0))
    with pytest.raises(ValueError, match=r"turned on its side: a depth frame in the other "
                       r"orientation\? .*np\.rot90"):
        facetlift.integrate(n, m, K=K, prior=np.rot90(gt))
    r, c = np.nonzero(m)
    with pytest.raises(ValueError, match=r"goes in the prior as a fourth array, prior=\(rows, "
                       "cols, depths, weights\\)"):
        facetlift.integrate(n, m, K=K, prior=(r[:50], c[:50], gt[r[:50], c[:50]]),
                            prior_weight=np.ones(50))


def test_an_8_bit_png_prior_is_told_how_to_go_on(tmp_path):
    """A fusion audit: Depth Anything's demo writes its relative output as an 8-bit PNG,
    refused as 'must be a single-channel 16-bit PNG' with no way forward."""
    import imagecodecs

    from facetlift import io

    (tmp_path / "mono8.png").write_bytes(imagecodecs.png_encode(
        np.arange(64, dtype=np.uint8).reshape(8, 8)))
    with pytest.raises(ValueError, match=r"got dtype uint8, shape \(8, 8\): an 8-bit map holds "
                       r"too few levels .*as \.npy"):
        io.read_prior(tmp_path / "mono8.png", 1.0)


def test_the_second_reviews_priors_are_read_right():
    """A second review: a square prior 3x coarser was told it was turned on its side; a
    sparse map of 8 samples with one behind the camera was refused (its points are not)."""
    from facetlift.perspective import normals_from_depth

    n = np.zeros((121, 120, 3))
    n[..., 2] = 1
    with pytest.raises(ValueError) as e:
        facetlift.integrate(n, prior=np.ones((40, 40)))
    assert "turned on its side" not in str(e.value) and "3x coarser" in str(e.value)
    K = np.array([[100.0, 0, 48], [0, 100, 48], [0, 0, 1]])
    r, c = np.mgrid[0:96, 0:96]
    d = 10 + 0.01 * (c - 48)
    nn = normals_from_depth(d, K)
    idx = np.random.default_rng(0).choice(96 * 96, 8, replace=False)
    p = np.full((96, 96), np.nan)
    p.flat[idx] = d.flat[idx]
    p.flat[idx[0]] = -3
    with pytest.warns(UserWarning, match=r"1 sample\(s\) in the mask with a non-positive"):
        facetlift.integrate(nn, K=K, prior=p)


def test_the_discontinuity_routes_progress_count_rises_over_its_passes():
    """A review: with a sparse prior the route runs the prior-free reweightings, then those
    with the prior, each counting from 1: a progress callable heard 1, 2, 1, 2, 3, ... and the
    command line's bar ran backwards. The count now rises over both passes, to the total the
    info reports, and a stage callable still hears the stages."""
    from facetlift import synthetic

    g = synthetic.analytic("steps", 64)
    rng = np.random.default_rng(0)
    prior = np.where(rng.random(g.mask.shape) < 0.02, g.depth, np.nan)
    seen, stages = [], []

    def progress(it, change):
        seen.append(it)

    progress.stage = stages.append
    s = facetlift.integrate(g.normals, g.mask, prior=prior, discontinuities=True,
                            progress=progress)
    assert s.info["prior_free"]["iterations"] >= 1  # (two passes ran)
    assert seen == sorted(set(seen)) and seen[-1] == s.info["iterations"], seen
    assert "reweighting" in stages


def test_a_dense_prior_in_other_units_without_K_is_told_its_pixel_size():
    """An audit of the docs' claims: the DiLiGenT bear's depth in mm given as a dense prior
    without K (ratio 0.402) was told only that its relief hardly follows the normals', with a
    blur as the cure (17.6 deg after it). A ratio between 0 and 0.5 now names other units
    first, with the pixel_size that fits; a prior at the right scale says nothing."""
    from facetlift import synthetic

    g = synthetic.analytic("pyramid", 160)
    with pytest.warns(UserWarning, match=r"relief hardly follows the normals' \(a ratio of "
                      r"0\.4 .*in other units than the depth's .*needs a pixel_size of about "
                      r"0\.4 \(--pixel-size\).*blurred"):
        facetlift.integrate(g.normals, g.mask, prior=np.where(g.mask, 0.4 * g.depth, np.nan))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(g.normals, g.mask, prior=np.where(g.mask, g.depth, np.nan))
    assert not any("relief" in str(w.message) for w in rec)


def test_exact_samples_far_from_a_smooth_surface_are_sent_to_discontinuities():
    """An audit of warnings on clean inputs: exact sparse samples on the analytic occluder,
    integrated smoothly, were called outliers to remove (removing them raised the error
    3.29 -> 7.57 %, where discontinuities=True gives 0.06 %). On the smooth route the
    warning now leads with the jumps the surface bends over and names discontinuities=True;
    with it the samples are met and nothing is said."""
    from facetlift import synthetic

    g = synthetic.analytic("occluder", 128)
    rng = np.random.default_rng(0)
    prior = np.where(g.mask & (rng.random(g.mask.shape) < 0.04), g.depth, np.nan)
    with pytest.warns(UserWarning, match=r"samples lie far from the surface returned .*: the "
                      r"smooth surface bends over depth jumps and leaves correct samples far "
                      r"from it: integrate with discontinuities=True \(--discontinuities\) "
                      r"first\. Else outliers"):
        facetlift.integrate(g.normals, g.mask, prior=prior, prior_outliers="keep")
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = facetlift.integrate(g.normals, g.mask, prior=prior, prior_outliers="keep",
                                discontinuities=True)
    assert not any("lie far from the surface" in str(w.message) for w in rec)
    err = np.nanmean(np.abs(s.depth - g.depth)[g.mask]) / np.ptp(g.depth[g.mask])
    assert err < 0.01


def test_the_progress_count_rises_over_prior_fits_two_runs():
    """A review: with prior_fit the normals-only run and the fused one each counted from 1
    (the bar ran backwards); the count rises over both, and the stages are heard."""
    from facetlift import synthetic

    g = synthetic.analytic("steps", 64)
    prior = np.where(g.mask, 0.5 * g.depth + 3.0, np.nan)
    seen, stages = [], []

    def progress(it, change):
        seen.append(it)

    progress.stage = stages.append
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        facetlift.integrate(g.normals, g.mask, prior=prior, prior_fit="affine",
                            discontinuities=True, progress=progress, prior_weight=0.01)
    assert seen == sorted(set(seen)) and len(seen) > 2, seen
    assert "fitting the prior" in stages and "integrating with the prior" in stages
