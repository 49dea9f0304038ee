"""Pixel-graph methods on perspective input (log-depth slopes)."""

import numpy as np
import pytest
from test_perspective import DILIGENT, rel_error, sphere_scene

import facetlift
from facetlift.methods import REGISTRY

LOG_DEPTH = [name for name, info in REGISTRY.items() if info.perspective and name != "dgp"]


def test_registry_lists_perspective_methods():
    assert {"poisson", "alpha_surface", "m_estimator", "regularization"} <= set(LOG_DEPTH)
    assert not REGISTRY["diffusion"].perspective


@pytest.mark.parametrize("method", LOG_DEPTH)
def test_perspective_sphere_recovered(method):
    normals, mask, K, depth = sphere_scene(H=64, W=72, min_cos=0.3)
    s = facetlift.integrate(normals, mask, K=K, method=method)
    assert np.all(s.depth[mask] > 0)
    err = rel_error(s.depth, depth, mask)
    assert err.max() < 2e-4, err.max()  # measured 4e-6 (regularization: 5e-5)


def test_perspective_poisson_agrees_with_perspective_dgp():
    normals, mask, K, depth = sphere_scene(H=64, W=72, min_cos=0.3)
    a = facetlift.integrate(normals, mask, K=K, method="poisson")
    b = facetlift.integrate(normals, mask, K=K, method="dgp")
    assert rel_error(a.depth, b.depth, mask).max() < 1e-4  # measured ~8e-6


def test_diffusion_refuses_perspective():
    normals, mask, K, depth = sphere_scene(H=32, W=36, min_cos=0.3)
    with pytest.raises(ValueError, match="perspective"):
        facetlift.integrate(normals, mask, K=K, method="diffusion")


def test_backfacing_is_judged_by_the_viewing_ray_in_perspective():
    """Off-axis, a surface seen by the camera can have n_z < 0; one facing away cannot pass."""
    K = np.array([[50.0, 0, 0.0], [0, 50.0, 0.0], [0, 0, 1]])  # wide angle, centre at (0, 0)
    H, W = 6, 8
    rr, cc = np.mgrid[0:H, 0:W]
    from facetlift.perspective import rays

    r = rays(K, (rr + 60).ravel(), (cc + 60).ravel())  # pretend far off-axis via big offset
    K_off = K.copy()
    K_off[0, 2] = -60.0
    K_off[1, 2] = -60.0
    # a normal toward the camera along the ray: OpenCV m = -r, facetlift n = (m_x, -m_y, -m_z)
    m = -r / np.linalg.norm(r, axis=1, keepdims=True)
    seen = (m * np.array([1.0, -1.0, -1.0])).reshape(H, W, 3)
    tilt = seen.copy()
    tilt[..., 2] -= 0.6  # n_z < 0 but still facing the camera
    tilt /= np.linalg.norm(tilt, axis=-1, keepdims=True)
    assert (tilt[..., 2] < 0).all()
    with pytest.warns(UserWarning, match="principal point"):  # (far off-axis on purpose)
        assert facetlift.prepare(tilt, K=K_off).usable.all()  # accepted
    with pytest.raises(ValueError, match="facing away from the camera"), \
            pytest.warns(UserWarning, match="principal point"):
        facetlift.prepare(-seen, K=K_off, backfacing="error")
    with pytest.raises(ValueError, match="facing away from the camera"):
        facetlift.prepare(tilt, backfacing="error")  # orthographically the same normals do


def test_bini_skewed_camera_takes_the_exact_system():
    """BiNI's n~_z has no skew term: with a skewed K the exact cosine and slopes are used (the
    reference system would be off by 2.7e-3 of the depth on this sphere)."""
    from test_perspective import _K

    K = _K(H=64, W=72, f=300.0, skew=60.0)
    normals, mask, K, depth = sphere_scene(H=64, W=72, K=K, min_cos=0.3)
    s = facetlift.integrate(normals, mask, K=K, method="bini", discontinuities=False,
                            cg_tol=1e-10)
    assert rel_error(s.depth, depth, mask).max() < 1e-3  # measured 2.4e-4


@pytest.mark.skipif(not (DILIGENT / "depth_gt.npz").is_file(), reason="no DiLiGenT bear data")
def test_bini_reproduces_the_reference_bear_figure():
    """facetlift's BiNI follows BiNI's reference path (per-axis n~_z, cg_tol 1e-3): the bear's
    MADE is its published 0.334 mm (0.395 mm with the exact cosine and one focal length)."""
    from facetlift.io import read_dataset

    data = read_dataset(DILIGENT)
    mask = data["mask"]
    gt = np.load(DILIGENT / "depth_gt.npz")["depth_gt"].astype(float)
    s = facetlift.integrate(data["normals"], mask, K=data["K"], method="bini", max_iter=100)
    scale = np.nanmedian(gt[mask] / s.depth[mask])
    made = np.nanmean(np.abs(scale * s.depth[mask] - gt[mask]))
    assert abs(made - 0.334) < 0.002 and s.info["iterations"] == 13
