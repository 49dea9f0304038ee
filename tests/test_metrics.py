import numpy as np
import pytest

from facetlift import Surface, integrate, normals_from_gradients
from facetlift.metrics import (
    align,
    angular_error,
    facet_normals,
    made,
    mae,
    normalized_error,
    rmse,
)
from facetlift.synthetic import analytic


def _two_components():
    gt = analytic("face", 32)
    mask = gt.mask.copy()
    mask[:, 15:17] = False  # two components
    depth = np.where(mask, gt.depth, np.nan)
    return depth, mask


def test_constant_per_component_is_zero_error():
    depth, mask = _two_components()
    est = depth.copy()
    est[:, :15] += 3.0
    est[:, 17:] -= 7.5
    mean, err = normalized_error(est, depth, mask)
    assert mean < 1e-14 and np.nanmax(err) < 1e-14
    assert np.isnan(err[~mask]).all()
    assert rmse(est, depth, mask) < 1e-12 and mae(est, depth, mask) < 1e-12
    aligned, m = align(est, depth, mask)
    np.testing.assert_allclose(aligned[m], depth[m], atol=1e-12)


def test_known_error_values():
    gt = analytic("saddle", 20)
    rng = np.random.default_rng(5)
    sign = rng.choice([-1.0, 1.0], size=gt.shape)
    sign -= sign.mean()  # zero mean: alignment leaves it untouched
    est = gt.depth + sign
    mean, err = normalized_error(est, gt.depth)
    assert mean == pytest.approx(np.abs(sign).mean() / gt.depth_range, rel=1e-12)
    assert rmse(est, gt.depth) == pytest.approx(np.sqrt(np.mean(sign**2)), rel=1e-12)
    assert mae(est, gt.depth) == pytest.approx(np.abs(sign).mean(), rel=1e-12)


def test_made_is_scale_invariant():
    rng = np.random.default_rng(11)
    gt = 1500 + rng.uniform(-30, 30, (16, 18))
    val, err = made(gt / 3.7, gt)
    assert val < 1e-10 and np.nanmax(err) < 1e-10
    est = gt / 3.7
    est[0, 0] *= 1.01  # one pixel off: MADE = its error / number of pixels
    mask = np.ones(gt.shape, bool)
    val, err = made(est, gt, mask)
    assert val == pytest.approx(0.01 * gt[0, 0] / gt.size, rel=1e-6)


def test_metric_errors():
    a = np.zeros((4, 4))
    with pytest.raises(ValueError, match="`estimate` must be an"):
        normalized_error(np.zeros(4), a)
    with pytest.raises(ValueError, match="`truth` must have the shape"):
        rmse(a, np.zeros((3, 4)))
    with pytest.raises(ValueError, match="`mask` must have shape"):
        mae(a, a, np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="zero depth range"):
        normalized_error(a, a)
    with pytest.raises(ValueError, match="no pixel"):
        normalized_error(a, np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="no finite scale"):
        made(np.full((4, 4), 1e-310), np.full((4, 4), 1e300))  # (an overflowing scale)
    # an orthographic depth (mean 0) gave a number without meaning (a fresh-user check)
    with pytest.raises(ValueError, match="`estimate` has depths <= 0 .* rmse or mae"):
        made(a, np.ones((4, 4)))
    with pytest.raises(ValueError, match="`truth` has depths <= 0"):
        made(np.ones((4, 4)), np.ones((4, 4)) - 2.0)
    with pytest.raises(ValueError, match="`vertex_depth`"):
        facet_normals(np.zeros(5))


def test_facet_normals_of_orthographic_plane():
    a, b, h = 0.3, -1.2, 0.5
    i, j = np.mgrid[0:9, 0:11]
    height = a * (j * h) + b * (-i * h)  # vertex (i, j) at x = j h, y = -i h
    n = facet_normals(-height, pixel_size=h)
    expect = normals_from_gradients(np.full((8, 10), a), np.full((8, 10), b))
    np.testing.assert_allclose(n, expect, atol=1e-12)
    surf = Surface(depth=np.zeros((8, 10)), vertex_depth=-height, mask=np.ones((8, 10), bool),
                   pixel_size=h)
    mean, mx, err = angular_error(surf, expect)
    assert mx < 1e-6 and err.shape == (8, 10)
    # a 10-degree tilt of the reference shows as 10 degrees
    tilted = normals_from_gradients(np.full((8, 10), np.tan(np.radians(10))), np.zeros((8, 10)))
    flat = Surface(depth=np.zeros((8, 10)), vertex_depth=np.zeros((9, 11)),
                   mask=np.ones((8, 10), bool))
    assert angular_error(flat, tilted)[0] == pytest.approx(10.0, abs=1e-9)


def test_facet_normals_of_perspective_plane():
    K = np.array([[500.0, 0, 15.3], [0, 480.0, 11.8], [0, 0, 1]])
    nc = np.array([0.2, -0.3, -1.0])  # OpenCV frame, facing the camera (z forward)
    nc /= np.linalg.norm(nc)
    d = -100.0  # plane nc . X = d, in front of the camera
    i, j = np.mgrid[0:25, 0:31].astype(float)
    # vertex (i, j) lies at pixel position (row i - 0.5, col j - 0.5)
    ray = np.stack([(j - 0.5 - K[0, 2]) / K[0, 0], (i - 0.5 - K[1, 2]) / K[1, 1],
                    np.ones_like(i)], axis=-1)
    Z = d / (ray @ nc)
    assert (Z > 0).all()
    n = facet_normals(Z, K=K)
    expect = np.array([nc[0], -nc[1], -nc[2]])  # to x right, y up, z toward the viewer
    np.testing.assert_allclose(n, np.broadcast_to(expect, n.shape), atol=1e-9)
    surf = Surface(depth=np.ones((24, 30)), vertex_depth=Z, mask=np.ones((24, 30), bool), K=K)
    assert angular_error(surf, np.broadcast_to(expect, (24, 30, 3)))[1] < 1e-6


def test_angular_error_of_exact_reconstruction():
    gt = analytic("plane", 24)
    s = integrate(gt.normals, gt.mask)
    mean, mx, _ = angular_error(s, gt.normals)
    assert mx < 1e-6
    with pytest.raises(ValueError, match="`normals` must have shape"):
        angular_error(s, gt.normals[:-1])


def test_angular_error_of_a_surface_split_at_jumps_uses_each_facets_own_corners():
    """On a surface cut at its jumps the facets next to a cut keep their own plane; measured
    on the glued vertex grid instead they spanned the jump (the report showed 2.1 deg where
    the result's own deviation was 0.05 deg)."""
    g = analytic("occluder", 64)
    s = integrate(g.normals, g.mask, discontinuities=True)
    assert s.split is not None
    mean = angular_error(s, g.normals)[0]
    assert mean == pytest.approx(s.info["mean_deviation"], rel=1e-6)
    assert mean < 0.5 * angular_error(integrate(g.normals, g.mask), g.normals)[0]


def test_metrics_take_a_surface_and_name_a_missing_scale():
    """An audit: made(surface, ...) raised a bare TypeError, angular_error(depth, ...) an
    AttributeError, and rmse / mae / normalized_error of a perspective result (median depth
    1) against depth in mm returned 10.5 mm without a word."""
    import warnings

    gt = analytic("sphere", 48)
    s = integrate(gt.normals, gt.mask)
    assert rmse(s, gt.depth) == rmse(s.depth, gt.depth)
    persp = integrate(gt.normals, gt.mask, K=[[60.0, 0, 24], [0, 60.0, 24], [0, 0, 1]])
    assert made(persp, 3.0 * persp.depth)[0] == made(persp.depth, 3.0 * persp.depth)[0] == 0.0
    with pytest.raises(ValueError, match="`surface` must be a facetlift.Surface"):
        angular_error(s.depth, gt.normals)
    for f in (rmse, mae, normalized_error):
        with pytest.warns(UserWarning, match=r"depth spread is .* times the truth's: these "
                          r"errors align by an offset only"):
            f(s.depth, 1000.0 * gt.depth)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            f(s.depth, gt.depth)


def test_no_scale_warning_where_no_scale_explains_the_error():
    """A review: a near-flat truth (a frontal plane with 1e-4 scan noise) beside a result's
    own noise has spreads 187x apart, but no scale error: no warning."""
    import warnings

    rng = np.random.default_rng(0)
    truth = 1e-4 * rng.standard_normal((32, 32))
    est = 2e-2 * rng.standard_normal((32, 32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rmse(est, truth)
        mae(est, truth)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("discontinuities", [False, True])
def test_surface_normals_by_blocks_of_rows_equal_the_whole_frame(monkeypatch, discontinuities):
    """A review: the whole frame's normals at once took 2.7 GB of temporaries at 4096^2 for
    a preview; they are formed by blocks of rows, and any block size gives the same normals
    and shading (the split mesh's facets included)."""
    from facetlift import metrics
    from facetlift.io.preview import shade

    g = analytic("occluder", 40)
    s = integrate(g.normals, g.mask, discontinuities=discontinuities)
    assert (s.split is not None) == discontinuities
    whole, lit = metrics.surface_normals(s), shade(s)
    for rows in (1, 3, 7):
        monkeypatch.setattr(metrics, "NORMAL_ROWS", rows)
        np.testing.assert_array_equal(metrics.surface_normals(s), whole)
        np.testing.assert_array_equal(shade(s), lit)
    assert np.isfinite(whole[s.mask]).all()


def test_angular_error_of_a_depth_array_names_surface_from_depth():
    """Another tool's depth map given to angular_error was told to use facet_normals, whose
    corner depths it is not (a review); Surface.from_depth makes a Surface of it."""
    import facetlift
    from facetlift import metrics

    r, c = np.indices((24, 30)) + 0.5
    z = 0.05 * (c - 15) ** 2 / 10 + 0.02 * r
    n = facetlift.normals_from_gradients(*np.gradient(-z)[::-1] * np.array([[[1.0]], [[-1.0]]]))
    with pytest.raises(ValueError, match=r"Surface.from_depth\(depth, mask, K=K\) makes one"):
        metrics.angular_error(z, n)
    mean, _, _ = metrics.angular_error(facetlift.Surface.from_depth(z), n)
    assert mean < 1.0
