"""Pixel-graph methods on perspective input (log-depth slopes)."""

import numpy as np
import pytest

import facetlift
from facetlift.methods import REGISTRY

from test_perspective import rel_error, sphere_scene

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
