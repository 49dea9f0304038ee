"""Discontinuity-preserving DGP (``discontinuities=True``), orthographic and perspective."""

from __future__ import annotations

import numpy as np
import pytest
from test_perspective import rel_error, sphere_scene

import facetlift
from facetlift.methods import dgp
from facetlift.methods.dgp import discontinuous as disc
from facetlift.operators.stencil import E_TWIST, E_X, E_Y, facet_form
from facetlift.perspective import rays
from facetlift.problem import prepare


def scissor_ortho(H=64, W=72, slopes=((0.1, 1.0), (-0.15, -0.8))):
    """Two planes, left and right of the vertex column W//2, meeting at one point of it.

    The depth jump across the seam grows linearly (1.8 height units per pixel) away from the
    hinge: a jump that the normals determine (a jump of constant size along a line, e.g. two
    parallel planes, is invisible in any normal map and cannot be recovered by any method).
    """
    r, c = np.mgrid[0:H, 0:W]
    x, y = c + 0.5, -(r + 0.5)
    left = c < W // 2
    p = np.where(left, slopes[0][0], slopes[1][0])
    q = np.where(left, slopes[0][1], slopes[1][1])
    height = p * (x - W // 2) + q * (y + H / 2 + 3.5)
    n = np.stack([-p, -q, np.ones_like(p)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True), -height, left


def scissor_persp(H=64, W=72, f=150.0):
    """The perspective analogue: two 3D planes through one point seen on the seam."""
    K = np.array([[f, 0, W / 2 - 3.2], [0, f, H / 2 + 2.1], [0, 0, 1]])
    rr, cc = np.mgrid[0:H, 0:W]
    r = rays(K, rr.ravel(), cc.ravel()).reshape(H, W, 3)
    X0 = 5.0 * rays(K, [H / 2 + 3.5], [W // 2 - 0.5])[0]
    left = cc < W // 2
    n = np.empty((H, W, 3))
    depth = np.empty((H, W))
    for side, m in ((left, [0.1, 0.9, -1.0]), (~left, [-0.15, -0.8, -1.0])):
        m = np.asarray(m) / np.linalg.norm(m)
        depth[side] = (m @ X0) / (r[side] @ m)
        n[side] = m * np.array([1.0, -1.0, -1.0])
    return n, K, depth, left


def ortho_errors(depth, gt, left):
    """(mean error after one constant, worst per-side error after one constant per side)."""
    e = depth - gt
    bend = max(np.abs(e[s] - np.median(e[s])).mean() for s in (left, ~left))
    return np.abs(e - np.median(e)).mean(), bend


def test_ortho_step_is_kept_sharp():
    n, gt, left = scissor_ortho()
    smooth = facetlift.integrate(n)
    sharp = facetlift.integrate(n, discontinuities=True)
    g0, b0 = ortho_errors(smooth.depth, gt, left)
    g1, b1 = ortho_errors(sharp.depth, gt, left)
    # smooth DGP bends both planes toward each other (b0 ~ 7.8 units); the robust glue lets
    # them separate along the seam (b1 ~ 0.26, the rest is the zone near the hinge where the
    # jump is below the threshold)
    assert b1 < 0.1 * b0
    assert g1 < 0.6 * g0
    assert sharp.info["detached"] > 0
    assert sharp.info["solver"] == "discontinuous"


def test_perspective_step_is_kept_sharp():
    n, K, gt, left = scissor_persp()
    smooth = facetlift.integrate(n, K=K)
    sharp = facetlift.integrate(n, K=K, discontinuities=True)
    bends = []
    for s in (smooth, sharp):
        bends.append(max(rel_error(s.depth * side, gt * side, side).mean()
                         for side in (left, ~left)))
    assert bends[1] < 0.1 * bends[0]
    assert rel_error(sharp.depth, gt, np.ones_like(left)).mean() < \
        0.6 * rel_error(smooth.depth, gt, np.ones_like(left)).mean()


@pytest.mark.parametrize("quantise", [False, True])
def test_smooth_sphere_not_harmed_perspective(quantise):
    n, mask, K, gt = sphere_scene(min_cos=0.2)
    if quantise:
        n = np.round((np.nan_to_num(n) + 1) / 2 * 255) / 255 * 2 - 1
    a = facetlift.integrate(n, mask, K=K)
    b = facetlift.integrate(n, mask, K=K, discontinuities=True)
    assert np.abs(b.depth[mask] / a.depth[mask] - 1).max() < 1e-4
    assert rel_error(b.depth, gt, mask).mean() < 1.1 * rel_error(a.depth, gt, mask).mean()
    assert b.info["detached"] == 0


def test_smooth_hemisphere_not_harmed_orthographic():
    H = W = 80
    r, c = np.mgrid[0:H, 0:W]
    x, y = (c + 0.5 - W / 2) / 30, (-(r + 0.5) + H / 2) / 30
    mask = x**2 + y**2 < 0.95**2
    z = np.sqrt(np.clip(1 - x**2 - y**2, 0, None))
    n = np.stack([x, y, z], -1)
    n = np.round((n + 1) / 2 * 255) / 255 * 2 - 1  # 8-bit
    n[~mask] = np.nan
    a = facetlift.integrate(n, mask, pixel_size=1 / 30)
    b = facetlift.integrate(n, mask, pixel_size=1 / 30, discontinuities=True)
    assert np.abs(b.depth - a.depth)[mask].max() < 2e-3  # height units; radius 1


def test_no_reweighting_is_the_smooth_solution():
    """With uniform glue the eliminated facet copies give exactly the smooth DGP system."""
    n, _, _ = scissor_ortho(H=20, W=24)
    pr = prepare(n)
    bx, by, tg = dgp.targets(pr)
    z0, _ = dgp.solve_direct(pr.domain, bx, by, tg)
    z1, zf, info = disc.solve_discontinuous(pr.domain, bx, by, tg, scale=1.0, max_iter=0)
    shift = z0[0] - z1[0]
    np.testing.assert_allclose(z1 + shift, z0, atol=1e-7)
    np.testing.assert_allclose(zf + shift, pr.domain.facet_centres(z0), atol=1e-7)
    assert info["iterations"] == 0


def test_facet_blocks_match_facet_form():
    rng = np.random.default_rng(7)
    mask = rng.random((15, 17)) < 0.7
    mask[5:8, :] = True
    from facetlift.domain import Domain

    d = Domain.from_mask(mask)
    w = rng.random(d.n_facets)
    blocks = disc.FacetBlocks(d, pin=0.0)
    Q = np.outer(E_X, E_X) + 2 * np.outer(E_Y, E_Y) + 0.5 * np.outer(E_TWIST, E_TWIST)
    Kb = blocks.assemble(w[:, None, None] * Q)
    Kf = facet_form(d, [(w, Q)])
    np.testing.assert_allclose(Kb.toarray(), Kf.toarray(), atol=1e-12)


def test_glue_weight():
    r = np.array([0.0, 0.05, 0.2, 1.0, -1.0, 10.0])
    w = disc.glue_weight(r, 1.0)
    assert w[0] == 1.0 and w[1] == 1.0  # inside the core
    np.testing.assert_allclose(w[2:], 1 / (1 + r[2:] ** 2))
    np.testing.assert_allclose(disc.glue_weight(r * 3, 3.0), w)  # only r / ks matters


def test_missing_samples_and_components():
    n, gt, left = scissor_ortho(H=30, W=36)
    known = np.ones(left.shape, bool)
    known[10:13, 5:9] = False
    mask = np.ones(left.shape, bool)
    mask[:, 8] = False  # a second component on the left
    s = facetlift.integrate(n, mask, known=known, discontinuities=True)
    assert np.isfinite(s.depth[mask]).all()
    assert s.info["missing"] == int((mask & ~known).sum())


@pytest.mark.parametrize(
    "options, match",
    [
        (dict(discontinuity_k=0.0), "discontinuity_k"),
        (dict(discontinuity_k=np.nan), "discontinuity_k"),
        (dict(discontinuity_iter=-1), "discontinuity_iter"),
        (dict(discontinuity_iter=2.5), "discontinuity_iter"),
        (dict(solver="iterative"), "solver"),
    ],
)
def test_bad_options(options, match):
    n, _, _ = scissor_ortho(H=8, W=8)
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(n, discontinuities=True, **options)


def test_vertex_curl():
    """Zero for an integrable field; the change of the jump per pixel along a seam."""
    from facetlift.domain import Domain

    H, W = 12, 14
    d = Domain.from_mask(np.ones((H, W), bool))
    r, c = d.pixels
    tg = np.ones(d.n_facets, bool)
    # gradient of the quadratic 0.3 x^2 - 0.2 x y + 0.1 y^2 at the pixel centres
    x, y = c + 0.5, -(r + 0.5)
    curl = disc.vertex_curl(d, 0.6 * x - 0.2 * y, -0.2 * x + 0.2 * y, tg)
    np.testing.assert_allclose(curl, 0, atol=1e-12)
    n, _, left = scissor_ortho(H=H, W=W, slopes=((0.0, 1.0), (0.0, -0.8)))
    pr = prepare(n)
    bx, by, tg = dgp.targets(pr)
    curl = pr.domain.to_vertex_image(disc.vertex_curl(pr.domain, bx, by, tg))
    np.testing.assert_allclose(np.abs(curl[1:-1, W // 2]), 1.8, rtol=1e-12)
    curl[1:-1, W // 2] = 0
    np.testing.assert_allclose(curl, 0, atol=1e-12)


def test_stalled_start_falls_back_to_the_direct_solver(monkeypatch):
    n, gt, left = scissor_ortho(H=30, W=36)
    ref = facetlift.integrate(n, discontinuities=True)
    monkeypatch.setattr(disc, "START_CG", 1)
    s = facetlift.integrate(n, discontinuities=True)
    assert s.info["cg_iterations"][0] == 1
    np.testing.assert_allclose(s.depth, ref.depth, atol=1e-5)
