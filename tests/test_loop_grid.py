"""The grid-sliced loop step equals the literal local shaping (Eq. 1-2) plus scatter."""

import numpy as np

from facetlift.domain import Domain
from facetlift.methods.dgp.common import facet_slopes
from facetlift.methods.dgp.loop import local_shaping
from facetlift.operators.stencil import grid_scatter, grid_slopes, scatter_corners


def _setup(seed=0):
    rng = np.random.default_rng(seed)
    mask = rng.random((9, 11)) < 0.8
    mask[3:6, 4:7] = False
    d = Domain.from_mask(mask)
    z = rng.standard_normal(d.n_vertices)
    target = rng.random(d.n_facets) < 0.6
    bx = np.where(target, rng.standard_normal(d.n_facets), 0.0)
    by = np.where(target, rng.standard_normal(d.n_facets), 0.0)
    return d, z, bx, by, target


def test_grid_slopes_match_facet_slopes():
    d, z, *_ = _setup()
    gx, gy = grid_slopes(d.to_vertex_image(z, fill=0.0))
    fx, fy = facet_slopes(d, z)
    r, c = d.pixels
    np.testing.assert_allclose(gx[r, c], fx, atol=1e-14)
    np.testing.assert_allclose(gy[r, c], fy, atol=1e-14)


def test_grid_scatter_matches_local_shaping_and_scatter():
    d, z, bx, by, target = _setup(1)
    projected, centre = local_shaping(d, z, bx, by, target)
    fx, fy = facet_slopes(d, z)
    gx = d.to_image(np.where(target, bx, fx), fill=0.0)
    gy = d.to_image(np.where(target, by, fy), fill=0.0)
    vm = d.vertex_mask
    # with mean subtraction (N p_f) and without (p_f itself)
    np.testing.assert_allclose(
        grid_scatter(gx, gy)[vm], scatter_corners(d, projected - centre[:, None]), atol=1e-13
    )
    np.testing.assert_allclose(
        grid_scatter(gx, gy, d.to_image(centre, fill=0.0))[vm],
        scatter_corners(d, projected),
        atol=1e-13,
    )
