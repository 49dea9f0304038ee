"""The DGP fixed point on a facet mesh split along given edges (methods/dgp/split.py)."""

from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift.methods.dgp import solve_direct, targets
from facetlift.methods.dgp import split as spl

BEAR = Path(__file__).parents[1] / ".." / "shared" / "data" / "normal_maps" / "diligent_bear"


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


def _plane_copies(domain, gx=0.3, gy=-0.2, jump_cols=None, jump=5.0):
    """Every facet's corner values of the plane z = gx col + gy row (corner (r, c) at grid
    position (r, c)), plus `jump` on the columns >= `jump_cols`."""
    r, c = domain.pixels
    dr = np.array([0, 0, 1, 1])
    dc = np.array([0, 1, 1, 0])
    z = gx * (c[:, None] + dc) + gy * (r[:, None] + dr)
    if jump_cols is not None:
        z = z + np.where(c >= jump_cols, jump, 0.0)[:, None]
    return z


def test_a_small_piece_is_hung_on_its_closest_neighbour_along_one_edge():
    """A facet cut loose on every side (a steep rim facet or a mixed pixel on a jump: they
    floated as loose quads in the mesh) is hung on the edge where it meets a larger piece best,
    rigidly; a jump beside it stays cut, and the two large pieces stay apart."""
    from facetlift.operators.split import from_copies

    pr = facetlift.prepare(np.dstack([np.zeros((12, 14, 2)), np.ones((12, 14))]))
    d = pr.domain
    copies = _plane_copies(d, jump_cols=7)
    r, c = d.pixels
    f = np.flatnonzero((r == 5) & (c == 6))[0]  # left of the jump, next to it
    copies[f] += np.array([1.2, 0.7, 0.9, 1.6])  # off its neighbours by 0.7-1.6 (gap 0.5)
    mesh, _ = from_copies(d, copies, 0.5)
    assert mesh.n_pieces == 3 and np.bincount(mesh.facet_piece).min() == 1
    hung = spl.absorb_small_pieces(mesh, copies, 4, 0.5)
    after, _ = from_copies(d, hung, 0.5)
    assert after.n_pieces == 2  # the island joined, the jump kept
    assert after.facet_piece[f] == after.facet_piece[np.flatnonzero((r == 5) & (c == 5))[0]]
    assert after.facet_piece[f] != after.facet_piece[np.flatnonzero((r == 5) & (c == 7))[0]]
    others = np.arange(d.n_facets) != f
    np.testing.assert_array_equal(hung[others], copies[others])  # nobody else moved
    # its best edge (the top one: largest corner gap 1.2, against 1.6 left and below, 4.1 and
    # more across the jump) takes the neighbour's copies; the facet moved rigidly by the mean
    # difference there (-0.95)
    up = np.flatnonzero((r == 4) & (c == 6))[0]
    np.testing.assert_allclose(hung[f, [0, 1]], copies[up, [3, 2]])
    np.testing.assert_allclose(hung[f, [2, 3]], copies[f, [2, 3]] - 0.95)
    # a piece with a prior sample stays where it is; nothing small: nothing to do
    anchored = np.zeros(d.n_facets, bool)
    anchored[f] = True
    assert spl.absorb_small_pieces(mesh, copies, 4, 0.5, anchored) is None
    assert spl.absorb_small_pieces(after, hung, 4, 0.5) is None
    assert spl.absorb_small_pieces(mesh, copies, 0, 0.5) is None


def test_a_hang_that_would_bridge_a_jump_is_undone():
    """A facet on a jump whose rigid shift puts its far edge within the gap of the other side
    (review): hung, it joined the two sides into one piece, a face across the jump. It is left
    loose instead; an anchored one-facet piece is no place to hang on either."""
    from facetlift.operators.split import from_copies

    pr = facetlift.prepare(np.dstack([np.zeros((12, 14, 2)), np.ones((12, 14))]))
    d = pr.domain
    r, c = d.pixels
    copies = np.where((c >= 7)[:, None], 1.0, 0.0) * np.ones((1, 4))  # flat, a jump of 1
    f = np.flatnonzero((r == 5) & (c == 6))[0]
    copies[f] = [0.6, 1.6, 1.6, 0.6]
    mesh, _ = from_copies(d, copies, 0.5)
    assert sorted(np.bincount(mesh.facet_piece)) == [1, 83, 84]
    out = spl.absorb_small_pieces(mesh, copies, 4, 0.5)
    if out is not None:
        after, _ = from_copies(d, out, 0.5)
        assert after.n_pieces >= 2  # the two sides stay apart
        left, right = (np.flatnonzero((r == 5) & (c == cc))[0] for cc in (5, 7))
        assert after.facet_piece[left] != after.facet_piece[right]
    # a harmless island elsewhere is still hung: only the bridging hang is undone (final
    # read: every hang in the merged piece was undone with it)
    g = np.flatnonzero((r == 2) & (c == 2))[0]
    copies = np.where((c >= 7)[:, None], 1.0, 0.0) * np.ones((1, 4))
    copies[f] = [0.6, 1.6, 1.6, 0.6]
    copies[g] += 0.8
    mesh, _ = from_copies(d, copies, 0.5)
    out = spl.absorb_small_pieces(mesh, copies, 4, 0.5)
    after, _ = from_copies(d, out, 0.5)
    np.testing.assert_allclose(out[g], 0.0)  # (hung: the flat left side's values)
    np.testing.assert_array_equal(out[f], copies[f])  # (left loose)
    assert after.n_pieces == 3
    # a one-facet piece with a prior sample beside a one-facet piece: neither is hung on it
    copies = np.zeros((d.n_facets, 4))
    a, b = (np.flatnonzero((r == 5) & (c == cc))[0] for cc in (6, 7))
    copies[a] += 3.0
    copies[b] += 6.0
    mesh, _ = from_copies(d, copies, 0.5)
    anchored = np.zeros(d.n_facets, bool)
    anchored[a] = True
    out = spl.absorb_small_pieces(mesh, copies, 4, 0.5, anchored)
    np.testing.assert_array_equal(out[a], copies[a])  # (not moved: it has a sample)
    after, _ = from_copies(d, out, 0.5)
    assert after.facet_piece[b] != after.facet_piece[a]  # (b hung on the large piece)
    assert after.n_pieces == 2


def test_a_chain_of_two_hangs_across_a_jump_undoes_only_those_two():
    """Two facets on either side of a jump, each hung on its own side, that meet each other
    within the gap join the two sides; undoing every hang in the piece they made (as before)
    left hundreds of harmless hangs undone on a 384^2 armadillo render (316 single quads in
    its mesh, 7 now). Only the two are undone; an island elsewhere stays hung."""
    from facetlift.operators.split import from_copies

    pr = facetlift.prepare(np.dstack([np.zeros((12, 14, 2)), np.ones((12, 14))]))
    d = pr.domain
    r, c = d.pixels
    copies = np.where((c >= 7)[:, None], 1.0, 0.0) * np.ones((1, 4))  # flat, a jump of 1
    a, b, g = (np.flatnonzero((r == rr) & (c == cc))[0] for rr, cc in ((5, 6), (5, 7), (2, 2)))
    copies[a] = [0.6, 1.2, 1.2, 0.6]  # hung on the left: right edge at 0.6
    copies[b] = [0.2, 0.45, 0.45, 0.2]  # hung on the right: left edge at 0.75
    copies[g] += 0.8
    mesh, _ = from_copies(d, copies, 0.5)
    assert sorted(np.bincount(mesh.facet_piece)) == [1, 1, 1, 82, 83]
    out = spl.absorb_small_pieces(mesh, copies, 4, 0.5)
    after, _ = from_copies(d, out, 0.5)
    left, right = (np.flatnonzero((r == 5) & (c == cc))[0] for cc in (5, 8))
    assert after.facet_piece[left] != after.facet_piece[right]  # the sides stay apart
    np.testing.assert_array_equal(out[[a, b]], copies[[a, b]])  # the chain undone
    np.testing.assert_allclose(out[g], 0.0)  # the island hung on the left side
    assert after.n_pieces == 4
    # the same through an anchored piece between them (a review: every hang was undone)
    q = np.flatnonzero((r == 4) & (c == 7))[0]
    copies = np.where((c >= 7)[:, None], 1.0, 0.0) * np.ones((1, 4))
    copies[a] = [0.6, 1.2, 1.2, 0.6]
    copies[b] = [0.6, 0.5, 0.3, 0.6]  # anchored: not moved, joined to both hung pieces
    copies[q] = [1.6, 1.6, 1.1, 1.1]
    copies[g] += 0.8
    mesh, _ = from_copies(d, copies, 0.5)
    anchored = np.zeros(d.n_facets, bool)
    anchored[b] = True
    out = spl.absorb_small_pieces(mesh, copies, 4, 0.5, anchored)
    after, _ = from_copies(d, out, 0.5)
    assert after.facet_piece[left] != after.facet_piece[right]
    np.testing.assert_array_equal(out[[a, b, q]], copies[[a, b, q]])
    np.testing.assert_allclose(out[g], 0.0)


@pytest.mark.skipif(not (BEAR / "depth_gt.npz").is_file(), reason="no DiLiGenT bear data")
@pytest.mark.filterwarnings("ignore:.*cannot be used")
def test_the_bear_mesh_has_no_loose_quads():
    """The DiLiGenT bear with jumps: 43 single facets (steep rim facets on the neck and paw)
    floated loose in the mesh; the mesh is now one piece, with the same MADE."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from facetlift import io, metrics

    root = BEAR
    data = io.read_dataset(root)
    s = facetlift.integrate(data["normals"], data["mask"], K=data["K"], discontinuities=True)
    assert s.info["hung_facets"] > 0 and s.info["mesh_pieces"] == 1
    # every cut edge is one the mesh splits: a jump beside it (an edge whose ends stayed
    # joined around it was marked, with 0 jump on both sides: down[223, 352]; fresh-user check)
    right, down = s.cuts
    near = np.zeros(s.shape, bool)
    near[:, :-1] |= right
    near[:, 1:] |= right
    near[:-1] |= down
    near[1:] |= down
    assert near.any() and not (near & (s.discontinuities == 0)).any()
    # the mesh the placement made while hanging the small pieces is the surface's: the same as
    # splitting the returned copies anew
    import facetlift.methods.dgp as dgp

    real = dgp.place_pieces
    dgp.place_pieces = lambda *a, **k: (lambda p: (p[0], {**p[1], "_mesh": None}))(real(*a, **k))
    try:
        anew = facetlift.integrate(data["normals"], data["mask"], K=data["K"],
                                   discontinuities=True)
    finally:
        dgp.place_pieces = real
    for a, b in zip((*s.split, *s.cuts), (*anew.split, *anew.cuts), strict=True):
        np.testing.assert_array_equal(a, b)
    assert "_mesh" not in s.info and "split_mesh" not in s.info
    V, F = s.to_mesh()
    g = sp.csr_matrix((np.ones(F.size), (np.repeat(F[:, 0], 4), F.ravel())),
                      shape=(len(V), len(V)))
    _, lab = connected_components(g, directed=False)
    sizes = np.bincount(lab[F[:, 0]])
    assert sizes[sizes > 0].min() > 4, sorted(sizes[sizes > 0])[:10]
    with np.load(f"{root}/depth_gt.npz") as z:
        gt = z["depth_gt"]
    # (0.117 mm since SETTLE_AFTER 20, 0.079 before, 0.0463 before split.TOUCH; the issue's
    # target for the bear is 0.10, missed; BiNI's 0.334)
    assert metrics.made(s.depth, gt, data["mask"])[0] < 0.13
    # with its own depth as a blurred prior every facet holds a sample: hung all the same
    # (547 pieces before, MADE 0.853 mm; now 99, 0.727); a pointwise one keeps them
    rows, cols = slice(150, 300), slice(200, 420)  # (the neck and paw: 5 s instead of 10)
    mask = data["mask"][rows, cols]
    K = data["K"].copy()
    K[0, 2] -= cols.start
    K[1, 2] -= rows.start
    prior = np.where(mask, gt[rows, cols], np.nan)
    import facetlift.methods.dgp as dgp

    def run():
        return facetlift.integrate(data["normals"][rows, cols], mask, K=K, prior=prior,
                                   prior_blur=4, prior_weight=0.003, discontinuities=True)

    hung = run()
    real = dgp.place_pieces
    dgp.place_pieces = lambda *a, hang_anchored=False, **k: real(*a, **k)
    try:
        kept = run()
    finally:
        dgp.place_pieces = real
    assert hung.info["hung_facets"] > kept.info["hung_facets"]
    assert hung.info["mesh_pieces"] < 0.5 * kept.info["mesh_pieces"], (
        hung.info["mesh_pieces"], kept.info["mesh_pieces"])
