"""Outlier samples of a sparse depth prior: found from the normals before the solve, left out,
counted and warned about (facetlift.prior_outliers, docs/fusion.md "Outlier samples")."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import synthetic
from facetlift.cli import main

BEAR = Path(__file__).resolve().parents[2] / "shared" / "data" / "normal_maps" / "diligent_bear"


def _sphere_samples(n=80, seed=0):
    gt = synthetic.analytic("sphere", 64)
    rng = np.random.default_rng(seed)
    rr, cc = np.nonzero(gt.mask)
    k = rng.choice(rr.size, n, replace=False)
    return gt, rr[k], cc[k], gt.depth[rr[k], cc[k]].copy()


def test_isolated_outliers_are_left_out_counted_and_named():
    gt, r, c, z = _sphere_samples()
    span = np.nanmax(gt.depth) - np.nanmin(gt.depth)
    z[:3] += 0.3 * span
    kw = dict(pixel_size=gt.pixel_size, prior_weight=100.0)
    with pytest.warns(UserWarning, match=r"prior: 3 of the 80 samples disagree with every "
                      r"neighbouring sample .* left out as outliers"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), **kw)
    out = s.info["prior"]["outliers"]
    assert out["removed"] == 3 and out["checked"] == 80
    assert tuple(out["first"]) in set(zip(r[:3], c[:3], strict=True))
    # every one named, in the image's rows and columns (a user cleans the SfM model with them)
    assert sorted(map(tuple, out["pixels"])) == sorted(zip(r[:3].tolist(), c[:3].tolist(),
                                                           strict=True))
    assert out["unconfirmed"] == len(out["unconfirmed_pixels"])
    assert s.info["prior"]["samples"] == 77
    # the same as giving the other 77 samples alone
    alone = facetlift.integrate(gt.normals, gt.mask, prior=(r[3:], c[3:], z[3:]), **kw)
    np.testing.assert_allclose(s.depth, alone.depth, equal_nan=True)
    # kept, they pull the surface with them (weight 100: the surface meets them)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kept = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), prior_outliers="keep",
                                   **kw)
    err = np.nanmean(np.abs(s.depth - gt.depth)[gt.mask])
    err_kept = np.nanmean(np.abs(kept.depth - gt.depth)[gt.mask])
    assert err < 0.01 * span < err_kept
    assert kept.info["prior"]["outliers"] is None and kept.info["prior"]["samples"] == 80


@pytest.mark.parametrize("name", ["sphere", "steps", "plateau", "occluder", "fold"])
def test_exact_and_noisy_samples_are_all_kept(name):
    """Samples across depth jumps that the normals do not show (steps, plateau) agree with
    their own side's neighbours and are kept, as are noisy ones."""
    gt = synthetic.analytic(name, 96)
    rng = np.random.default_rng(1)
    rr, cc = np.nonzero(gt.mask)
    k = rng.choice(rr.size, rr.size // 50, replace=False)
    z = gt.depth[rr[k], cc[k]]
    span = np.nanmax(gt.depth) - np.nanmin(gt.depth)
    for noise in (0.0, 0.01):
        zz = z + rng.normal(0.0, noise * span, z.size)
        problem = facetlift.prepare(gt.normals, gt.mask, pixel_size=gt.pixel_size,
                                    prior=(rr[k], cc[k], zz))
        assert problem.extras["prior_outliers"]["removed"] == 0, (name, noise)
        assert problem.counts["prior_samples"] == k.size


@pytest.mark.skipif(not BEAR.is_dir(), reason="../shared/data not beside the checkout")
def test_the_bear_with_outliers_and_the_discontinuity_route():
    """3 % of 1 % samples of the DiLiGenT bear moved 30-80 mm: removed before the solve,
    with no exact sample among them; the discontinuity route no longer cuts blobs loose
    around them."""
    d = facetlift.io.read_dataset(BEAR)
    n, m, K = d["normals"], d["mask"], d["K"]
    gt = np.load(BEAR / "depth_gt.npz")["depth_gt"]
    rng = np.random.default_rng(0)
    rr, cc = np.nonzero(m)
    pick = rng.choice(rr.size, int(0.01 * rr.size), replace=False)
    r, c = rr[pick], cc[pick]
    z = gt[r, c].copy()
    bad = rng.random(z.size) < 0.03
    z[bad] += rng.choice([-1, 1], bad.sum()) * rng.uniform(30, 80, bad.sum())
    planted = set(zip(r[bad], c[bad], strict=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = facetlift.prepare(n, m, K=K, prior=(r, c, z))
        removed = problem.prior_weight == 0
        rows, cols = problem.domain.pixels
        sampled = np.isfinite(problem.prior)
        found = set(zip(rows[removed & sampled], cols[removed & sampled], strict=True))
        assert found <= planted and len(found) >= 0.6 * len(planted)
        errs = {}
        for how in ("remove", "keep"):
            s = facetlift.integrate(n, m, K=K, prior=(r, c, z), discontinuities=True,
                                    prior_outliers=how)
            errs[how] = float(np.mean(np.abs(s.depth - gt)[m]))
    assert errs["remove"] < 0.5 * errs["keep"], errs
    assert errs["remove"] < 0.1, errs  # mm, against 0.16 kept (measured)


def test_a_dense_priors_lone_wrong_pixels_are_left_out_by_their_neighbours():
    """A dense map's sample is compared with its eight neighbouring samples and left out where
    most of them disagree (a sensor's flying pixels), where a sparse prior's must agree with
    none: a correct sample beside a wrong one stays."""
    gt = synthetic.analytic("sphere", 48)
    dense = np.where(gt.mask, gt.depth, np.nan)
    span = np.nanmax(gt.depth) - np.nanmin(gt.depth)
    dense[20, 20] += 5.0 * span
    dense[30, 21] -= 3.0 * span
    dense[30, 22] -= 2.0 * span  # (beside another wrong one: most of its neighbours still right)
    with pytest.warns(UserWarning, match=r"prior: 3 of the \d+ samples disagree with every "
                      r"neighbouring sample \(pixel\) .* flying pixels"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=dense, prior_weight=0.01)
    out = s.info["prior"]["outliers"]
    assert out["removed"] == 3 and out["dense"] and not out["majority"]
    assert sorted(map(tuple, out["pixels"])) == [(20, 20), (30, 21), (30, 22)]
    err = np.nanmean(np.abs(s.depth - gt.depth)[gt.mask])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kept = facetlift.integrate(gt.normals, gt.mask, prior=dense, prior_weight=0.01,
                                   prior_outliers="keep")
    clean = facetlift.integrate(gt.normals, gt.mask, prior=np.where(gt.mask, gt.depth, np.nan),
                                prior_weight=0.01)
    err_clean = np.nanmean(np.abs(clean.depth - gt.depth)[gt.mask])
    assert err < 1.05 * err_clean < 0.5 * np.nanmean(np.abs(kept.depth - gt.depth)[gt.mask])
    # a right map, with noise, loses none
    noisy = np.where(gt.mask, gt.depth, np.nan)
    noisy += np.random.default_rng(0).normal(0, 0.002 * span, noisy.shape)
    problem = facetlift.prepare(gt.normals, gt.mask, prior=noisy, prior_weight=0.01)
    assert problem.extras["prior_outliers"]["removed"] == 0


def test_a_pinhole_dense_priors_runs_of_flying_pixels_are_left_out_by_the_majority():
    """With a camera a sample is an outlier where fewer than half of its comparisons agree: a
    sensor's flying pixels lie in runs along the silhouette, side by side (a review's bear:
    364 of 760 found by "none agree", 673 by the majority); the 2 % relative floor keeps true
    steps."""
    from test_perspective import sphere_scene

    n, mask, K, gt = sphere_scene(min_cos=0.2)
    depth = np.where(mask, gt, np.nan)
    # a run of four flying pixels along one row inside the silhouette, 10-40 % farther
    rr, cc = np.nonzero(mask)
    r0 = int(np.median(rr))
    c0 = int(cc[rr == r0].min()) + 1
    run = [(r0, c0 + k) for k in range(4)]
    for k, (r, c) in enumerate(run):
        depth[r, c] *= 1.1 + 0.02 * k  # (neighbours within 2 %: they agree with each other)
    with pytest.warns(UserWarning, match=r"disagree with most of their neighbouring samples"):
        s = facetlift.integrate(n, mask, K=K, prior=depth, prior_weight=0.01)
    out = s.info["prior"]["outliers"]
    assert out["majority"] and set(map(tuple, out["pixels"])) >= set(run)
    assert out["removed"] <= len(run) + 2
    problem = facetlift.prepare(n, mask, K=K, prior=np.where(mask, gt, np.nan))
    assert problem.extras["prior_outliers"]["removed"] == 0  # (exact: none)


@pytest.mark.parametrize("name", ["steps", "occluder"])
def test_a_dense_prior_across_depth_jumps_keeps_the_jumps_edges(name):
    """Exact depth across jumps the normals do not show: a sample on a jump's straight edge
    has most of its neighbours on its own side and stays; only corners may go."""
    gt = synthetic.analytic(name, 96)
    dense = np.where(gt.mask, gt.depth, np.nan)
    problem = facetlift.prepare(gt.normals, gt.mask, pixel_size=gt.pixel_size, prior=dense)
    out = problem.extras["prior_outliers"]
    assert out["removed"] <= 0.002 * out["checked"], out["removed"]


def test_blurred_and_few_samples_priors_are_not_checked():
    gt = synthetic.analytic("sphere", 48)
    _, r, c, z = _sphere_samples(40)
    problem = facetlift.prepare(gt.normals, gt.mask, prior=(r * 0.75, c * 0.75, z),
                                prior_blur=2.0, prior_weight=0.001)
    assert "blurred" in problem.extras["prior_outliers"]["skipped"]
    problem = facetlift.prepare(gt.normals, gt.mask, prior=(r[:4] * 0.75, c[:4] * 0.75, z[:4]))
    assert problem.extras["prior_outliers"] == {"removed": 0,
                                                "skipped": "4 samples (fewer than 5)"}


def test_a_far_sample_or_object_does_not_widen_the_orthographic_tolerance():
    # (the floor once took the samples' whole depth range: one sample 100 ranges off, or a
    # second object far behind, raised it 20-fold and hid the other outliers, a review)
    gt, r, c, z = _sphere_samples()
    span = np.nanmax(gt.depth) - np.nanmin(gt.depth)
    z[:3] += 0.3 * span
    z[3] += 100 * span
    with pytest.warns(UserWarning, match="4 of the 80 samples .* left out as outliers"):
        problem = facetlift.prepare(gt.normals, gt.mask, prior=(r, c, z),
                                    pixel_size=gt.pixel_size)
    assert problem.extras["prior_outliers"]["removed"] == 4
    # two spheres side by side, the right one far behind; the outliers on the left one
    normals = np.concatenate([gt.normals, gt.normals], axis=1)
    mask = np.concatenate([gt.mask, gt.mask], axis=1)
    r2 = np.r_[r[4:], r[4:]]
    c2 = np.r_[c[4:], c[4:] + gt.mask.shape[1]]
    z2 = np.r_[z[4:], z[4:] + 1000 * span]
    z2[:3] += 0.3 * span
    with pytest.warns(UserWarning, match="3 of the 152 samples .* left out as outliers"):
        problem = facetlift.prepare(normals, mask, prior=(r2, c2, z2), pixel_size=gt.pixel_size)
    assert problem.extras["prior_outliers"]["removed"] == 3


def test_a_diagonal_rim_one_pixel_wide_stops_a_line():
    # (a 45-degree line visits every other diagonal only; the pixels beside its steps are
    # looked at too, a review)
    from facetlift.prior_outliers import _line_integrals

    n = 20
    index = np.arange(n * n).reshape(n, n)
    gx = np.zeros(n * n)
    rows, cols = np.divmod(np.arange(n * n), n)
    for wall in (19, 20):  # (odd and even diagonals)
        gy = np.where(rows + cols == wall, np.nan, 0.0)
        pts = np.array([[5.0, 5.0], [14.0, 14.0], [5.0, 6.0], [14.0, 13.0]])
        got = _line_integrals(pts, np.array([0, 2]), np.array([1, 3]), index,
                              np.where(np.isnan(gy), np.nan, gx), gy)
        assert np.isnan(got).all(), wall
    # and with no wall the lines are made
    got = _line_integrals(pts, np.array([0, 2]), np.array([1, 3]), index, gx, np.zeros(n * n))
    assert np.all(got == 0.0)


def test_a_method_without_a_prior_refuses_it_before_any_outlier_warning():
    gt, r, c, z = _sphere_samples()
    z[:3] += 0.3 * (np.nanmax(gt.depth) - np.nanmin(gt.depth))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="does not take a `prior`"):
            facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), method="bini",
                                pixel_size=gt.pixel_size)
    # None is the default
    s = facetlift.integrate(gt.normals, gt.mask, prior=(r[3:], c[3:], z[3:]),
                            prior_outliers=None, pixel_size=gt.pixel_size)
    assert s.info["prior"]["outliers"]["removed"] == 0


def test_bad_values_are_refused_by_name(tmp_path, capsys):
    gt, r, c, z = _sphere_samples()
    with pytest.raises(ValueError, match=r"`prior_outliers` must be one of remove, keep; got "
                       r"'drop'"):
        facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), prior_outliers="drop")
    with pytest.raises(ValueError, match=r"`prior_outliers` 'keep' applies only with a prior"):
        facetlift.integrate(gt.normals, gt.mask, prior_outliers="keep")
    np.save(tmp_path / "n.npy", gt.normals)
    code = main(["integrate", str(tmp_path / "n.npy"), "--prior-outliers", "keep", "-o",
                 str(tmp_path / "o")])
    assert code == 1 and "--prior-outliers 'keep' applies only with a prior" in (
        capsys.readouterr().err)


def test_the_command_line_removes_and_keeps(tmp_path, capsys):
    gt, r, c, z = _sphere_samples()
    z[:2] += 0.3 * (np.nanmax(gt.depth) - np.nanmin(gt.depth))
    np.save(tmp_path / "n.npy", np.where(gt.mask[..., None], gt.normals, np.nan))
    prior = np.full(gt.mask.shape, np.nan)
    prior[r, c] = z
    np.save(tmp_path / "p.npy", prior)
    base = ["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "p.npy"),
            "--prior-weight", "100", "--pixel-size", str(gt.pixel_size), "--json"]
    code = main([*base, "-o", str(tmp_path / "a")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "2 of the 80 samples disagree" in captured.err
    info = json.loads(captured.out)["info"]
    assert info["prior"]["outliers"]["removed"] == 2
    code = main([*base, "--prior-outliers", "keep", "-o", str(tmp_path / "b")])
    captured = capsys.readouterr()
    assert code == 0 and "disagree" not in captured.err
    assert json.loads(captured.out)["info"]["prior"]["outliers"] is None
    # the text summary counts them
    code = main([*base[:-1], "-o", str(tmp_path / "c")])
    captured = capsys.readouterr()
    assert code == 0 and "2 prior outliers left out" in captured.out + captured.err


def test_a_majority_disagreeing_is_not_removed_but_warned(monkeypatch):
    # (the tolerance follows the median disagreement, so real data hardly gets here; the
    # branch is reached by making the finder call most samples outliers)
    from facetlift import prior_outliers

    gt, r, c, z = _sphere_samples()
    real = prior_outliers.find_outliers

    def most(problem):
        bad, details = real(problem)
        return np.isfinite(problem.prior) & (problem.prior_weight > 0), details

    monkeypatch.setattr(prior_outliers, "find_outliers", most)
    with pytest.warns(UserWarning, match=r"80 of the 80 samples disagree .* too many to be "
                      r"outliers: all are used"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), pixel_size=gt.pixel_size)
    out = s.info["prior"]["outliers"]
    assert out["removed"] == 0 and out["disagreeing"] == 80
    assert s.info["prior"]["samples"] == 80


def test_samples_compared_too_little_to_be_removed_are_named_beside_the_outliers(monkeypatch):
    # (a user's mismatched SfM points that agreed with none of the 5 of 8 comparisons made were
    # kept without a word; the finder's count is reported, and said only beside outliers)
    from facetlift import prior_outliers

    gt, r, c, z = _sphere_samples()
    z[:3] += 0.3 * (np.nanmax(gt.depth) - np.nanmin(gt.depth))
    real = prior_outliers.find_outliers

    def doubting(problem):
        bad, details = real(problem)
        return bad, {**details, "unconfirmed": 2, "unconfirmed_pixels": [[1, 2], [3, 4]]}

    monkeypatch.setattr(prior_outliers, "find_outliers", doubting)
    with pytest.warns(UserWarning, match=r"3 of the 80 samples .* stray returns, or a correct "
                      r"sample beside a depth jump that the normals do not show .*; 2 more "
                      r"disagree with the few they could be compared with and were kept"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), pixel_size=gt.pixel_size)
    assert s.info["prior"]["outliers"]["unconfirmed_pixels"] == [[1, 2], [3, 4]]


@pytest.mark.skipif(not BEAR.is_dir(), reason="../shared/data not beside the checkout")
def test_a_prior_that_runs_against_the_normals_is_named():
    """A user's disparity given as the prior at a low weight deviated 26 deg without a word
    (below the fight warning's 45): the prior's changes between neighbouring samples are
    compared in sign with the normals'."""
    gt, r, c, z = _sphere_samples()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        s = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, z), pixel_size=gt.pixel_size)
    assert s.info["prior"]["trend"]["agreement"] > 0.9
    with pytest.warns(UserWarning, match=r"its depth changes run against the normals'.* a "
                      r"height rather than a depth"):
        s = facetlift.integrate(gt.normals, gt.mask, prior=(r, c, -z), pixel_size=gt.pixel_size)
    assert s.info["prior"]["trend"]["agreement"] < 0.1
    # whatever the prior's units (a review: 1 / depth in small units agreed everywhere)
    for prior in (1.0 / (z - z.min() + 100.0), -z / 1000.0, -z * 1000.0):
        with pytest.warns(UserWarning, match=r"run against the normals'"):
            facetlift.prepare(gt.normals, gt.mask, prior=(r, c, prior), pixel_size=gt.pixel_size)
    # the DiLiGenT bear with its depth given as disparity, densely, at a low weight
    d = facetlift.io.read_dataset(BEAR)
    depth = np.load(BEAR / "depth_gt.npz")["depth_gt"]
    with pytest.warns(UserWarning, match=r"disparity or inverse depth"):
        facetlift.prepare(d["normals"], d["mask"], K=d["K"], prior=1e6 / depth,
                          prior_weight=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        # (the bear's one lone normal 85 deg or more from the ray: problem.STEEP_ISOLATED)
        warnings.simplefilter("ignore", facetlift.problem.UnusableNormalsWarning)
        p = facetlift.prepare(d["normals"], d["mask"], K=d["K"], prior=depth, prior_weight=0.01)
    assert p.extras["prior_trend"]["agreement"] > 0.9
