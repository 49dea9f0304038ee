"""The DGP fixed point on a facet mesh split along given edges (methods/dgp/split.py)."""

import numpy as np
import pytest

import facetlift
from facetlift.methods.dgp import solve_direct, targets
from facetlift.methods.dgp import split as spl


def _step(shape=(20, 24), jump=3.0, h=0.5):
    """Two tilted planes side by side with a depth jump between columns 11 and 12."""
    H, W = shape
    r, c = np.mgrid[0:H, 0:W]
    x, y = (c + 0.5) * h, -(r + 0.5) * h
    left = c < 12
    z = np.where(left, 0.2 * x + 0.1 * y, 0.2 * x + 0.1 * y + jump)
    n = facetlift.normals_from_gradients(np.full(shape, 0.2), np.full(shape, 0.1))
    right = np.zeros((H, W - 1), bool)
    right[:, 11] = True
    return n, -z, right, h


def test_no_cut_is_the_smooth_dgp_solution(wave):
    n = wave.normals((18, 21), 0.2)
    mask = np.ones((18, 21), bool)
    mask[5:9, 4:8] = False
    pr = facetlift.prepare(n, mask, pixel_size=0.2)
    bx, by, tg = targets(pr)
    z0, _ = solve_direct(pr.domain, bx, by, tg)
    mesh = spl.split(pr.domain)
    assert mesh.n_vertices == pr.domain.n_vertices and mesh.n_pieces == 1
    z1, _ = spl.solve_pieces(mesh, bx, by, tg)
    d = (z1 - z0)
    assert np.ptp(d) < 1e-10 * np.ptp(z0)


def test_a_full_cut_splits_vertices_and_pieces():
    n, depth, right, h = _step()
    pr = facetlift.prepare(n, pixel_size=h)
    mesh = spl.split(pr.domain, right, None)
    assert mesh.n_pieces == 2
    assert mesh.n_vertices == pr.domain.n_vertices + 21  # the 21 vertices on the cut doubled
    assert mesh.cut_pairs.shape == (21, 2) and mesh.n_cut_edges == 20
    # every piece is its own exact plane: the jump leaves no bending in either side
    bx, by, tg = targets(pr)
    z, zf, info = spl.solve_split(mesh, bx, by, tg)
    height = -depth[pr.domain.pixels]
    for p in range(2):
        sel = mesh.facet_piece == p
        e = zf[sel] - height[sel]
        assert np.ptp(e) < 1e-9


def test_offsets_of_separated_pieces():
    n, depth, right, h = _step()
    pr = facetlift.prepare(n, pixel_size=h)
    bx, by, tg = targets(pr)
    mesh = spl.split(pr.domain, right, None)
    z, _ = spl.solve_pieces(mesh, bx, by, tg)
    # "continue": the normals predict no jump, so the pieces are placed as one plane
    o = spl.piece_offsets(mesh, z, bx, by, tg, "continue")
    zf = (z + o[mesh.piece])[mesh.corners].mean(axis=1)
    plane = -facetlift.prepare(n, pixel_size=h).domain.facet_centres(
        solve_direct(pr.domain, bx, by, tg)[0])
    assert np.ptp(zf + plane) < 1e-9
    # "meet" does the same from the vertex copies
    o2 = spl.piece_offsets(mesh, z, bx, by, tg, "meet")
    np.testing.assert_allclose(o2 - o2[0], o - o[0], atol=1e-9)


def test_partial_cut_realises_the_jump_the_normals_imply():
    """A cut that ends inside the domain: the jump height comes from the path around it."""
    H, W = 24, 24
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    pr = facetlift.prepare(n)
    right = np.zeros((H, W - 1), bool)
    right[:12, 11] = True  # a half-length cut of a flat plane: nothing to cut, nothing bends
    mesh = spl.split(pr.domain, right, None)
    assert mesh.n_pieces == 1
    bx, by, tg = targets(pr)
    z, zf, _ = spl.solve_split(mesh, bx, by, tg)
    assert np.ptp(zf) < 1e-10


def test_bad_cut_shapes_are_named():
    pr = facetlift.prepare(np.dstack([np.zeros((4, 5, 2)), np.ones((4, 5))]))
    with pytest.raises(ValueError, match="cut edges must have shapes"):
        spl.split(pr.domain, np.zeros((4, 5), bool), None)
