"""A blurred depth prior (``prior_blur``): the blur operator, the fusion through it, errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import ndimage

import facetlift
from facetlift import methods
from facetlift.cli import main
from facetlift.operators.blur import PlaneBlur


def run(normals, mask=None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return facetlift.integrate(normals, mask, **kw)


def two_bumps(shape=(96, 128)):
    """Two separate discs, each a smooth bump at its own depth (an offset the normals cannot
    tell): normals, depth (NaN outside), mask."""
    H, W = shape
    r, c = np.indices(shape) + 0.5
    height = np.zeros(shape)
    p = np.zeros(shape)
    q = np.zeros(shape)
    mask = np.zeros(shape, bool)
    for (r0, c0, rad, base) in ((48.0, 34.0, 30.0, 3.0), (48.0, 96.0, 26.0, -5.0)):
        d2 = (r - r0) ** 2 + (c - c0) ** 2
        disc = d2 < rad**2
        g = 4.0 * np.exp(-d2 / (2 * (0.5 * rad) ** 2))
        x, y = c - c0, -(r - r0)
        height = np.where(disc, base + g + 0.05 * x, height)
        p = np.where(disc, -g * x / (0.5 * rad) ** 2 + 0.05, p)
        q = np.where(disc, -g * y / (0.5 * rad) ** 2, q)
        mask |= disc
    n = facetlift.normals_from_gradients(p, q)
    return n, np.where(mask, -height, np.nan), mask


def coarse(depth, mask, block=4):
    """The fusion benchmark's coarse prior (block means, a Gaussian of one block, bilinear
    upsampling; :func:`facetlift.bench.fusion.coarse_prior`) with blocks of `block` pixels,
    and its blur as one Gaussian's standard deviation (:data:`~facetlift.bench.fusion.
    BLUR_SIGMA` for blocks of 8)."""
    from types import SimpleNamespace

    from facetlift.bench.fusion import coarse_prior

    gt = SimpleNamespace(mask=mask, depth=np.where(mask, depth, np.nan))
    return coarse_prior(gt, block), block * float(np.sqrt(1 / 12 + 1 + 1 / 6))


def mae(a, b, mask):
    return float(np.mean(np.abs(a - b)[mask]))


# ------------------------------------------------------------------------------------------
# the blur


def test_plane_blur_keeps_constants_and_planes_on_any_mask():
    rng = np.random.default_rng(0)
    mask = ndimage.binary_opening(rng.random((40, 50)) < 0.8)
    mask[10:14, :] = True
    B = PlaneBlur(mask, 3.0)
    r, c = np.indices(mask.shape)
    assert np.allclose(B(np.full(mask.shape, 2.5))[mask], 2.5, atol=1e-9)
    plane = 0.3 * c - 0.2 * r + 1.0
    # a plane is its own first-order fit (the ridge on the slopes bends it by well under
    # a thousandth of a pixel's change at the ragged edges)
    assert np.abs(B(plane) - plane)[mask].max() < 0.02
    assert np.all(np.isnan(B(plane)[~mask]))
    # a weighted mean would sit at the centroid of a ragged neighbourhood: much further off
    g = ndimage.gaussian_filter
    mean = g(np.where(mask, plane, 0.0), 3.0, mode="constant") / g(mask * 1.0, 3.0,
                                                                      mode="constant")
    assert np.abs(mean - plane)[mask].max() > 10 * np.abs(B(plane) - plane)[mask].max()


def test_plane_blur_is_linear_and_smooths():
    rng = np.random.default_rng(1)
    mask = np.ones((32, 32), bool)
    B = PlaneBlur(mask, 2.0)
    a, b = rng.normal(size=(2, 32, 32))
    assert np.allclose(B(2 * a - b), 2 * B(a) - B(b))
    assert B(a).std() < 0.3 * a.std()
    with pytest.raises(ValueError, match="sigma"):
        PlaneBlur(mask, 0.0)


# ------------------------------------------------------------------------------------------
# the fusion


@pytest.mark.parametrize("options", [{}, {"discontinuities": True}],
                         ids=["dgp", "dgp-disc"])
def test_blurred_prior_beats_both_inputs_and_the_pointwise_fusion(options):
    n, depth, mask = two_bumps()
    prior, sigma = coarse(depth, mask)
    plain = run(n, mask, **options)
    pointwise = run(n, mask, prior=prior, prior_weight=0.01, **options)
    s = run(n, mask, prior=prior, prior_weight=0.01, prior_blur=sigma, **options)
    e_prior = mae(prior, depth, mask)
    e_plain = mae(plain.depth, depth, mask)  # (the offsets between the discs are unknown)
    e_point = mae(pointwise.depth, depth, mask)
    e = mae(s.depth, depth, mask)
    assert e < 0.5 * e_prior and e < 0.1 * e_plain and e < 0.5 * e_point, (e, e_prior,
                                                                             e_plain, e_point)
    info = s.info["prior_blur"]
    assert info["sigma"] == sigma and info["updates"] >= 2 and info["converged"]
    assert info["mismatch"][1] < 0.5 * info["mismatch"][0]
    assert s.info["converged"]


def test_zero_blur_is_the_pointwise_prior():
    n, depth, mask = two_bumps((48, 64))
    prior, _ = coarse(depth, mask)
    a = run(n, mask, prior=prior, prior_weight=0.01)
    b = run(n, mask, prior=prior, prior_weight=0.01, prior_blur=0)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)
    assert "prior_blur" not in b.info


def test_blurred_prior_is_metric_in_perspective():
    n, depth, mask = two_bumps()
    H, W = mask.shape
    K = np.array([[300.0, 0, W / 2], [0, 300.0, H / 2], [0, 0, 1]])
    # the bumps' normals as seen by a far camera: close to orthographic, metric depth ~ 100
    z = 100.0 + depth
    prior, sigma = coarse(z, mask)
    s = run(n, mask, K=K, prior=prior, prior_weight=0.01, prior_blur=sigma)
    assert abs(np.nanmedian(s.depth[mask]) - np.nanmedian(z[mask])) < 1.0


@pytest.mark.parametrize("kwargs, match", [
    ({"prior_blur": -1.0}, "`prior_blur` must be a finite number of pixels >= 0"),
    ({"prior_blur": float("nan")}, "`prior_blur` must be a finite number"),
    ({"prior_blur": "wide"}, "`prior_blur` must be a number of pixels"),
    ({"prior_blur": 2.0, "prior": None}, "`prior_blur` applies only with a `prior`"),
    ({"prior_blur": 2.0, "method": "poisson"}, "does not take a `prior_blur`"),
    ({"prior_blur": 2.0, "solver": "iterative"}, "`prior_blur` needs solver='direct'"),
])
def test_errors_name_the_argument(kwargs, match):
    n, depth, mask = two_bumps((48, 64))
    kw = {"prior": coarse(depth, mask)[0], **kwargs}
    with pytest.raises(ValueError, match=match):
        run(n, mask, **kw)


def test_registry_declares_prior_blur():
    assert "prior_blur" in methods.CAPABILITIES
    assert [k for k, v in methods.REGISTRY.items() if v.prior_blur] == ["dgp"]


def test_cli_prior_blur(tmp_path, capsys):
    n, depth, mask = two_bumps()
    np.save(tmp_path / "n.npy", np.where(mask[..., None], n, np.nan))
    prior, sigma = coarse(depth, mask)
    np.save(tmp_path / "prior.npy", prior)
    args = ["integrate", str(tmp_path / "n.npy"), "--prior", str(tmp_path / "prior.npy"),
            "--prior-weight", "0.01", "-s", "npy"]
    assert main(args + ["--prior-blur", f"{sigma}", "-o", str(tmp_path / "b")]) == 0, \
        capsys.readouterr().err
    assert main(args + ["-o", str(tmp_path / "p")]) == 0, capsys.readouterr().err
    blurred = np.load(tmp_path / "b" / "depth.npy")
    pointwise = np.load(tmp_path / "p" / "depth.npy")
    assert mae(blurred, depth, mask) < 0.5 * mae(pointwise, depth, mask)
    capsys.readouterr()
    assert main(args + ["--prior-blur", "-3", "-o", str(tmp_path / "e")]) == 1
    err = capsys.readouterr().err
    assert "`prior_blur` must be a finite number of pixels >= 0" in err
    assert "Traceback" not in err
