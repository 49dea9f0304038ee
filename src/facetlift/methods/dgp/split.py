"""The DGP fixed point on a facet mesh split along given edges (vertices duplicated per side).

Given the set of *cut* edges between 4-neighbouring pixels, the facet mesh is split
(:mod:`facetlift.operators.split`); on that split mesh the smooth DGP fixed point
(:mod:`facetlift.methods.dgp.fixed_point`) is solved exactly: every piece is the smooth DGP
surface of its own facets, with nothing of the jump left in it, and without any cut the
result is the smooth DGP solution itself.

Offsets of separated pieces
    A piece that the cuts separate completely from the rest of its mask component has a free
    constant: normals say nothing about how far a surface lies behind the one occluding it.
    :func:`piece_offsets` fixes those constants rigidly (without bending any piece): by least
    squares over the cut edges, so that on average the surface continues across the cut as
    the normals of the two facets predict (``rule="continue"``), or the vertex copies meet
    (``rule="meet"``); :func:`occlusion_offsets` sets a low quantile of every boundary's
    jumps (5 %; the median where both signs are common) to zero (``rule="occlusion"``; the
    discontinuity route, without a depth prior, only
    where it is at most :data:`TOUCH` footprints, from the places its own solve gave the
    pieces).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ... import linalg
from ...operators.split import SplitMesh, split
from ...operators.stencil import E_X, E_Y
from .fixed_point import SLOPE_BLOCK, TWIST_BLOCK

__all__ = ["SplitMesh", "absorb_small_pieces", "assemble", "line_pieces", "occlusion_offsets",
           "piece_offsets", "solve_pieces", "solve_split", "split"]


def assemble(mesh: SplitMesh, bx, by, target, *, weights=None, flat_weight=1e-9):
    """``K`` (n, n) CSR and right-hand side of the DGP fixed point on the split mesh.

    Per facet: ``w (slope + twist)`` with a target, ``w (flat_weight slope + twist)`` without;
    right-hand side ``C_f^T w (bx e_x + by e_y)`` (see :mod:`facetlift.methods.dgp`).
    """
    m = mesh.corners.shape[0]
    w = np.ones(m) if weights is None else np.asarray(weights, float)
    blocks = np.where(
        target[:, None, None], SLOPE_BLOCK + TWIST_BLOCK, flat_weight * SLOPE_BLOCK + TWIST_BLOCK
    ) * w[:, None, None]
    c = mesh.corners
    rows = np.repeat(c, 4, axis=1).ravel()
    cols = np.tile(c, (1, 4)).ravel()
    K = sp.csr_matrix((blocks.reshape(m, 16).ravel(), (rows, cols)),
                      shape=(mesh.n_vertices, mesh.n_vertices))
    local = (w * bx)[:, None] * E_X + (w * by)[:, None] * E_Y
    rhs = np.bincount(c.ravel(), local.ravel(), minlength=mesh.n_vertices)
    return K, rhs


def solve_pieces(mesh: SplitMesh, bx, by, target, *, weights=None, flat_weight=1e-9,
                 backend="auto"):
    """Split-vertex values (n,) of the DGP fixed point on `mesh`, every piece with an arbitrary
    constant (its first split vertex pinned), and the solver's info."""
    K, rhs = assemble(mesh, bx, by, target, weights=weights, flat_weight=flat_weight)
    first = np.full(mesh.n_pieces, -1, dtype=np.int64)
    order = np.arange(mesh.n_vertices)[::-1]
    first[mesh.piece[order]] = order
    pin = np.zeros(mesh.n_vertices)
    pin[first] = 1.0
    K = (K + sp.diags(pin)).tocsr()
    vr, vc = mesh.domain.vertices  # (the copies of a vertex share its grid position)
    z, info = linalg.solve(K, rhs, backend, grid=(vr[mesh.vertex], vc[mesh.vertex]))
    return z, info


def piece_offsets(mesh: SplitMesh, z: np.ndarray, bx, by, target, rule: str = "continue",
                  scale: float | None = None, robust_iter: int = 30):
    """Constants (n_pieces,) that place the separated pieces of `mesh` relative to each other.

    Pieces are moved rigidly to fit the cut edges: ``rule="continue"`` asks the difference
    of the two facet centres across a cut edge to equal what their normals predict
    (trapezoid rule on their grid slopes, as if the surface went on); ``"meet"`` asks the two
    copies of each cut vertex to coincide. With `scale` (in the unknown's units) the fit is
    robust (Cauchy weights, iteratively reweighted): the part of a boundary where the two
    pieces really continue decides, the part with a true jump is ignored. Pieces in different
    mask components, or joined to nothing, keep their constant (0).
    """
    k = max(mesh.n_pieces, 1)
    if mesh.n_pieces <= 1:
        return np.zeros(k)
    if rule == "meet":
        a, b = mesh.cut_pairs[:, 0], mesh.cut_pairs[:, 1]
        pa, pb = mesh.piece[a], mesh.piece[b]
        gap = z[b] - z[a]  # want (z_b + o_B) - (z_a + o_A) = 0
    else:
        pa, pb, gap = _continuation(mesh, z, bx, by, target)
    keep = pa != pb
    pa, pb, gap = pa[keep], pb[keep], gap[keep]
    if pa.size == 0:
        return np.zeros(k)
    import scipy.sparse.linalg as spla
    from scipy.sparse.csgraph import connected_components

    rows = np.arange(pa.size)
    D = sp.csr_matrix(
        (np.concatenate([-np.ones(pa.size), np.ones(pa.size)]),
         (np.concatenate([rows, rows]), np.concatenate([pa, pb]))), shape=(pa.size, k))
    _, grp = connected_components(D.T @ D, directed=False)
    first = np.full(grp.max() + 1, -1)
    first[grp[::-1]] = np.arange(k)[::-1]
    pin = sp.diags(np.bincount(first, minlength=k).astype(float))
    w = np.ones(pa.size)
    o = np.zeros(k)
    for _ in range(robust_iter if scale else 1):
        L = (D.T @ sp.diags(w) @ D + pin).tocsc()
        o_new = np.asarray(spla.spsolve(L, D.T @ (-w * gap)))
        done = np.abs(o_new - o).max() < 1e-3 * (scale or 1.0)
        o = o_new
        if scale is None or done:
            break
        r = gap + D @ o
        w = 1.0 / (1.0 + (r / scale) ** 2)
    return o


#: A boundary whose jumps take each sign on more than this share of its edges has no single
#: occluding side; its two pieces are then placed by the median jump instead.
MIXED = 0.2

#: The prior-free route's occlusion rule (:func:`facetlift.methods.dgp.place_pieces`) moves a
#: pair of pieces only where the jump it would set to zero is at most this many pixel
#: footprints (its `touch`): two pieces whose smallest boundary jump, as the cutting solve left
#: it, is that small nearly touch, and the rule closes the gap (the DiLiGenT bear's head on
#: its body: 1-3 footprints). Farther apart nothing in the normals says where they touch, and
#: such a pair keeps the relative place the solve gave it (the tiny glue ``FLOOR`` of its cut
#: corners), much as BiNI's soft weights place pieces. Chosen on 2026-12-06 (thirtieth
#: session; docs/results.md, "The occlusion rule only where pieces nearly touch") over 8,
#: 16, 32, 64 and no rule at all (0) on the development benchmark (267 runs) and six held-out
#: sets (648): 16 made 76 / 35 development and 188 / 69 held-out runs better / worse by more
#: than 1 % against the rule everywhere (held-out means -1.2 to -3.5 %); no rule was better
#: still by about 1 % on the held-out means (8 did about as well as no rule on the development
#: benchmark; not run held out), but no rule leaves the bear, the one real object with ground
#: truth, at 0.311 mm and 8 at 0.117 (issue 9's limit 0.10; 16: 0.079, every pair: 0.020).
#: 32 keeps the bear at 0.021 mm but gained about half as much (development 46 / 22, held-out
#: 116 / 40, means -0.7 to -2.5 %). The bear's 0.079: its head and body are closed (their
#: 62-edge boundary asks 0.9 footprints), but single-facet neck pieces, which link them too
#: and ask 18-40, now keep their places in the reconciliation (0.37 footprints more).
#: (Measured with the reweightings' SETTLE_AFTER at 10; with 20, since the thirty-first
#: session, the bear is at 0.117 mm with 16.)
TOUCH = 16.0

#: Weight factor in :func:`occlusion_offsets`'s reconciliation of the pairs that involve a
#: *line* piece (:func:`line_pieces`: no interior facet, more than `small` facets). Such a
#: piece is a row of mixed pixels along a jump (their normals averaged over both surfaces),
#: cut from both sides; each of its two boundaries asks for its smallest jump to be zero,
#: which is a guess on at least one side, and relayed through it the two guesses outweighed
#: the pair of pieces it lies between (an open bowl seen from 20 degrees: the rim's one pixel
#: of mixed normals, 25 facets long, relayed a jump of 45 mm where the bowl's front and inside
#: touch at the rim's ends). Scaled down, such a pair still places its pieces where nothing
#: else links them (a uniform factor changes nothing there). Measured on the benchmark's 83
#: scenes at exact, 8-bit and 3-deg-noise normals against 1 (docs/results.md): vessel group
#: 13.55 -> 12.56 mm with exact normals, 25 of 249 scene-conditions better by more than 1 %,
#: 7 worse; 0.1 kept part of the relay (vessel group 12.68 mm, 4 scenes worse than 1e-3),
#: 1e-6 did as 1e-3 (every group mean within 0.01 %; exact normals, the 83 scenes; the bear
#: 0.0204 mm at all three).
#: Pieces of at most `small` facets (the route passes its SMALL_PIECE, the pieces it
#: hangs on a neighbour afterwards) keep their full weight: the DiLiGenT bear's head is placed
#: through such pieces on its neck (with every line piece scaled down its MADE went 0.020 ->
#: 0.157 mm).
LINE_RELAY = 1e-3


def line_pieces(mesh: SplitMesh, small: int) -> np.ndarray:
    """(n_pieces,) bool: the pieces of more than `small` facets of which no facet has all
    four neighbours in the piece (at most two facets wide: a line along a jump). Purely
    geometric: a genuinely thin surface (a handle or stem one or two pixels wide, a band
    between a fold and a jump) counts too, which is harmless where its pairs are the only link
    (:data:`LINE_RELAY`)."""
    d = mesh.domain
    H, W = d.shape
    k = max(mesh.n_pieces, 1)
    # (the piece of every pixel, padded: int32, 268 MB at 8192^2 where int64 took 537)
    fp = mesh.facet_piece.astype(np.int32 if k < 2**31 else np.int64)
    at = np.full((H + 2, W + 2), -1, fp.dtype)
    r, c = d.pixels
    at[r + 1, c + 1] = fp
    inner = ((at[r + 1, c + 2] == fp) & (at[r + 1, c] == fp) & (at[r, c + 1] == fp)
             & (at[r + 2, c + 1] == fp))
    return ((np.bincount(fp[inner], minlength=k) == 0)
            & (np.bincount(fp, minlength=k) > small))


#: For each side of a facet: (its neighbour's key in
#: :func:`facetlift.methods.dgp.discontinuous.neighbours`, the facet's two corners on it, the
#: neighbour's two facing them); corners 0..3 top-left, top-right, bottom-right, bottom-left.
_EDGES = (("+x", (1, 2), (0, 3)), ("-x", (0, 3), (1, 2)), ("-y", (3, 2), (0, 1)),
          ("+y", (0, 1), (3, 2)))


def absorb_small_pieces(mesh: SplitMesh, copies, size: int, gap: float, anchored=None, *,
                        with_mesh: bool = False):
    """The facets' corner copies (m, 4) with every piece of at most `size` facets hung on its
    best edge to a larger piece; None where there is nothing to hang. With `with_mesh`, the
    pair ``(copies, their split)`` (the split is made here anyway: a caller's next pass takes
    it instead of splitting again).

    A piece this small is no separated surface but a few facets that fit neither side of a
    jump: steep rim facets (whose planes part from their neighbours' by more than the split's
    gap on a curved surface) and mixed pixels along the jump line. Left alone they float as
    loose quads in the mesh. The edge is the one, of all the piece's edges to a facet of a
    piece of more than `size` facets, whose two corner copies differ least from the
    neighbour's; the piece is moved rigidly by the mean difference there and the two copies on
    the edge take the neighbour's values: joined along that edge, its other edges cut where
    they part by more than `gap` (the split's, :func:`facetlift.operators.split.from_copies`).
    A hang that would join two larger pieces (an edge that lands within `gap` of the far side
    of a jump: a face stretched across it) is undone. Pieces holding a facet of `anchored`
    (m,) bool (prior samples) are not moved, and pieces next to no larger piece stay as
    they are.
    """
    from ...operators.split import from_copies
    from .discontinuous import neighbours

    d = mesh.domain
    k = mesh.n_pieces
    fp = mesh.facet_piece
    large = np.bincount(fp, minlength=k) > size
    movable = ~large
    if anchored is not None:
        movable &= ~(np.bincount(fp[np.asarray(anchored, bool)], minlength=k) > 0)
    if not movable.any() or not large.any():
        return None
    nb = neighbours(d)
    f = np.flatnonzero(movable[fp])  # the small pieces' facets
    best_gap = np.full(k, np.inf)
    best = np.zeros((k, 3), dtype=np.int64)  # facet, neighbour, side
    for side, (key, own, theirs) in enumerate(_EDGES):
        g = nb[key][f]
        ok = g >= 0
        ok[ok] = large[fp[g[ok]]]
        ff, gg = f[ok], g[ok]
        diff = np.maximum(np.abs(copies[ff, own[0]] - copies[gg, theirs[0]]),
                          np.abs(copies[ff, own[1]] - copies[gg, theirs[1]]))
        order = np.argsort(diff, kind="stable")  # the smallest per piece: its first
        first = order[np.unique(fp[ff[order]], return_index=True)[1]]
        better = diff[first] < best_gap[fp[ff[first]]]
        first = first[better]
        best_gap[fp[ff[first]]] = diff[first]
        best[fp[ff[first]]] = np.stack([ff[first], gg[first], np.full(first.size, side)], 1)
    hung = np.flatnonzero(np.isfinite(best_gap))
    if hung.size == 0:
        return None
    out = np.array(copies, dtype=float, copy=True)
    shift = np.zeros(k)
    edges = []
    for side, (_, own, theirs) in enumerate(_EDGES):
        p = hung[best[hung, 2] == side]
        ff, gg = best[p, 0], best[p, 1]
        want = copies[np.ix_(gg, theirs)]
        shift[p] = (want - copies[np.ix_(ff, own)]).mean(axis=1)
        edges.append((ff, own, want))
    moved = np.isin(fp, hung)
    out[moved] += shift[fp[moved]][:, None]
    for ff, own, want in edges:
        out[np.ix_(ff, own)] = want
    # undo the hangs that join two larger pieces. Every piece has an owner: a larger piece
    # itself, a hung one the piece it was hung on (none for the others). An uncut edge between
    # pieces of two different owners joins them: the hung pieces on such an edge are undone,
    # until none is left. (Undoing every hang in a piece that a bridge had made instead, as
    # before, undid 331 of 524 hangs on a 384^2 armadillo render for a few bridges: 316
    # single quads floated in its mesh.) A piece without an owner (anchored, or undone) joined
    # to pieces of two owners bridges them: the hung pieces joined to it are undone. A longer
    # bridge through such pieces is found as a piece of the new split holding facets of two
    # larger pieces: every hang in it is then undone
    owner = np.full(k, -1, dtype=np.int64)
    owner[large] = np.flatnonzero(large)
    owner[hung] = fp[best[hung, 1]]
    r, c = d.pixels
    lf = np.flatnonzero(large[fp])
    while True:
        after, _ = from_copies(d, out, gap)
        rp = np.pad(after.right, 1, constant_values=True)  # rp[r + 1, c + 1] = right[r, c]
        dp = np.pad(after.down, 1, constant_values=True)
        undo = np.zeros(k, bool)
        via = []  # (piece without an owner, owner of a piece joined to it, that piece)
        for key, cut in (("+x", rp[r + 1, c + 1]), ("-y", dp[r + 1, c + 1])):
            g = nb[key]
            sel = np.flatnonzero((g >= 0) & ~cut)
            pa, pb = fp[sel], fp[g[sel]]
            oa, ob = owner[pa], owner[pb]
            clash = (oa >= 0) & (ob >= 0) & (oa != ob)
            undo[pa[clash]] = True
            undo[pb[clash]] = True
            for x, o, y in ((pa, ob, pb), (pb, oa, pa)):
                one = (owner[x] < 0) & (o >= 0) & (x != y)
                via.append(np.stack([x[one], o[one], y[one]]))
        # a piece without an owner (an anchored one, or one undone) joined to pieces of two
        # owners: the hung pieces joined to it are undone (a review: the fallback below undid
        # every hang in the merged piece for such a bridge)
        via = np.concatenate(via, axis=1)
        # (only once no clash is left: a clash's undoing may already have broken the bridge,
        # a review's fuzzing found hangs undone for nothing otherwise)
        if via.shape[1] and not (undo & ~large).any():
            pairs = np.unique(via[0] * k + via[1])
            bad = np.bincount(pairs // k, minlength=k) > 1
            undo[via[2][bad[via[0]]]] = True
        undo &= ~large
        if not undo.any():
            # (new pieces holding facets of more than one larger piece)
            both = np.unique(after.facet_piece[lf].astype(np.int64) * k + fp[lf])
            bridged = np.bincount(both // k, minlength=after.n_pieces) > 1
            undo = np.zeros(k, bool)
            undo[fp[moved & bridged[after.facet_piece]]] = True
            if not undo.any():
                break
        back = np.isin(fp, np.flatnonzero(undo))
        out[back] = copies[back]
        moved &= ~back
        owner[undo] = -1
    if not moved.any():
        return None
    return (out, after) if with_mesh else out


def occlusion_offsets(mesh: SplitMesh, z, bx, by, target, quantile: float = 0.05,
                      scale: float = 0.0, fixed=None, small: int | None = None,
                      touch: float | None = None):
    """Constants (n_pieces,) placing separated pieces by the occlusion rule.

    Across the boundary between two pieces one surface lies in front of the other: the jump
    has one sign along it, and where the boundary ends inside the object (a fold) it fades to
    zero. So each pair of neighbouring pieces is placed with the smallest jump zero: the
    `quantile` of the boundary gaps (the continuation residual of :func:`_continuation`), on the
    side of the jump's majority sign, is set to 0 (where both signs are common among the jumps
    larger than `scale`, see :data:`MIXED`, the median instead). Pairs are then reconciled by
    least squares weighted by their boundary length (one constant per group of connected
    pieces stays free). Pieces where `fixed` (n_pieces,) bool is True keep offset 0 (their
    place is known, e.g. from a depth prior); a group with a fixed piece has no free constant.
    With `small` (the route's :data:`facetlift.methods.dgp.SMALL_PIECE`), the pairs of a line
    piece of more than `small` facets (:func:`line_pieces`) weigh :data:`LINE_RELAY` times
    their length (None: every pair its length). With `touch` (in units of `scale`; the
    route's :data:`TOUCH`), a pair whose jump to set to zero exceeds `touch` x `scale` keeps
    its relative place in `z` instead (it still links its pieces in the reconciliation); None:
    every pair is closed, as from a start whose offsets mean nothing (:func:`solve_split`).
    A pair with both signs (:data:`MIXED`) is compared by its median jump.
    """
    if touch is not None and not scale > 0:
        raise ValueError(f"occlusion_offsets: `touch` needs a footprint `scale` > 0; got "
                         f"scale={scale!r}")
    k = max(mesh.n_pieces, 1)
    if mesh.n_pieces <= 1 or (fixed is not None and fixed.all()):
        return np.zeros(k)
    pa, pb, gap = _continuation(mesh, z, bx, by, target)
    keep = pa != pb
    pa, pb, gap = pa[keep], pb[keep], gap[keep]
    if pa.size == 0:
        return np.zeros(k)
    lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
    g = np.where(pa == lo, gap, -gap)  # gap from piece lo to piece hi
    key = lo.astype(np.int64) * k + hi
    order = np.argsort(key, kind="stable")
    key, g = key[order], g[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ends = np.r_[starts[1:], key.size]
    rows_lo, rows_hi, want, weight = [], [], [], []
    for s0, s1 in zip(starts, ends, strict=True):
        gg = g[s0:s1]
        big = gg[np.abs(gg) > scale]
        share = (big > 0).mean() if big.size else 0.5
        if MIXED < share < 1.0 - MIXED:
            q = np.median(gg)  # both pieces in front somewhere: no occlusion order to use
        else:
            q = np.quantile(gg, quantile) if share >= 0.5 else np.quantile(gg, 1.0 - quantile)
        if touch is not None and abs(q) > touch * scale:
            q = 0.0  # (too far apart to say they touch: the start's relative place stays)
        rows_lo.append(key[s0] // k)
        rows_hi.append(key[s0] % k)
        want.append(q)  # (u_hi + o_hi) - (u_lo + o_lo) - t: make this q -> 0: o_hi - o_lo = -q
        weight.append(s1 - s0)
    lo = np.asarray(rows_lo)
    hi = np.asarray(rows_hi)
    want = -np.asarray(want)
    w = np.asarray(weight, float)
    if small is not None:  # (pairs with a line piece: a relay only where nothing else links)
        line = line_pieces(mesh, small)
        w = np.where(line[lo] | line[hi], LINE_RELAY * w, w)
    import scipy.sparse.linalg as spla
    from scipy.sparse.csgraph import connected_components

    rows = np.arange(lo.size)
    D = sp.csr_matrix((np.r_[-np.ones(lo.size), np.ones(lo.size)], (np.r_[rows, rows],
                       np.r_[lo, hi])), shape=(lo.size, k))
    L = D.T @ sp.diags(w) @ D
    _, grp = connected_components(L, directed=False)
    if fixed is not None and fixed.any():
        # fixed pieces are removed from the unknowns (offset 0); groups without one get a pin
        free = ~np.asarray(fixed, bool)
        has_fixed = np.bincount(grp[~free], minlength=grp.max() + 1) > 0
        pin = np.zeros(k)
        cand = free & ~has_fixed[grp]
        first = np.full(grp.max() + 1, -1)
        first[grp[::-1][cand[::-1]]] = np.arange(k)[::-1][cand[::-1]]
        pin[first[first >= 0]] = 1.0
        b = D.T @ (w * want)
        o = np.zeros(k)
        idx = np.flatnonzero(free)
        if idx.size:
            Lf = (L + sp.diags(pin)).tocsc()[idx][:, idx]
            o[idx] = np.atleast_1d(spla.spsolve(Lf.tocsc(), b[idx]))
        return o
    first = np.full(grp.max() + 1, -1)
    first[grp[::-1]] = np.arange(k)[::-1]
    L = (L + sp.diags(np.bincount(first, minlength=k).astype(float))).tocsc()
    return np.asarray(spla.spsolve(L, D.T @ (w * want)))


def _continuation(mesh: SplitMesh, z, bx, by, target):
    """For every cut edge with a target on both sides: (piece a, piece b, gap) where gap is the
    facet-centre difference across the edge minus the difference the normals predict."""
    d = mesh.domain
    H, W = d.shape
    idx = np.full((H, W), -1, dtype=np.int64)
    idx[d.pixels] = np.arange(d.n_facets)
    centre = z[mesh.corners].mean(axis=1)
    out = []
    for cut, (da, db), along in ((mesh.right, (0, 1), "x"), (mesh.down, (1, 0), "y")):
        r, c = np.nonzero(cut)
        fa, fb = idx[r, c], idx[r + da, c + db]
        ok = (fa >= 0) & (fb >= 0)
        fa, fb = fa[ok], fb[ok]
        ok = target[fa] & target[fb]
        fa, fb = fa[ok], fb[ok]
        pred = 0.5 * (bx[fa] + bx[fb]) if along == "x" else -0.5 * (by[fa] + by[fb])
        out.append((mesh.facet_piece[fa], mesh.facet_piece[fb],
                    centre[fb] - centre[fa] - pred))
    pa, pb, gap = (np.concatenate(v) for v in zip(*out, strict=True))
    return pa, pb, gap


def solve_split(mesh: SplitMesh, bx, by, target, *, weights=None, flat_weight=1e-9,
                rule="continue", scale=None, backend="auto", reference=None, small=None):
    """Split-vertex values of the DGP fixed point on `mesh` with the pieces placed by
    :func:`piece_offsets`, or (``reference`` (m,) facet values, e.g. the smooth solution) each
    piece moved to the reference's mean over the piece; returns ``(z, facet values, info)``.
    `small`: :func:`occlusion_offsets`'s (with ``rule="occlusion"``)."""
    z, sinfo = solve_pieces(mesh, bx, by, target, weights=weights, flat_weight=flat_weight,
                            backend=backend)
    if reference is not None:
        zf = z[mesh.corners].mean(axis=1)
        k = mesh.n_pieces
        o = np.bincount(mesh.facet_piece, reference - zf, k) / np.bincount(mesh.facet_piece,
                                                                            minlength=k)
        if rule == "median":
            from scipy import ndimage

            o = np.atleast_1d(ndimage.median(reference - zf, mesh.facet_piece + 1,
                                             np.arange(1, k + 1)))
    elif rule == "occlusion":
        o = occlusion_offsets(mesh, z, bx, by, target, scale=scale or 0.0, small=small)
    else:
        o = piece_offsets(mesh, z, bx, by, target, rule, scale)
    z = z + o[mesh.piece]
    info = {"pieces": mesh.n_pieces, "cut_edges": mesh.n_cut_edges, "backend": sinfo.backend}
    return z, z[mesh.corners].mean(axis=1), info
