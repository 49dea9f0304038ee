"""Surface-from-gradients by discrete geometry processing (Xie et al., CVPR 2014).

Every domain pixel is a quad facet of an (H+1) x (W+1) vertex grid (see
:mod:`facetlift.conventions`); the unknowns are the vertex heights ``z``. An iteration has two
steps.

Local shaping (Eq. 1-2)
    Each facet's four corners are projected along z onto the plane with its target normal
    through the facet's current centre ``c``: ``p_f[k] = c + p dx_k + q dy_k`` with the corner
    offsets ``(dx_k, dy_k)`` from the centre and ``(p, q) = (-n_x / n_z, -n_y / n_z)``.

Global blending with mean subtraction (Eq. 5-8)
    ``min_z sum_f || N z_f - N p_f ||^2`` with ``N = I - 11^T / 4``: ``A^T A z = A^T b`` with
    ``A = blockdiag(N) C``. ``A^T A`` never changes, so it is factorized once. Without mean
    subtraction (Eq. 4, ``mean_subtraction=False``) the target is ``z_f ~ p_f`` itself, which
    converges far more slowly (Fig. 4).

Missing samples and outliers (Sec. 4.4)
    Facets without a normal, or with a grazing normal (the ``outlier_eps`` rule of
    :func:`facetlift.prepare`), take their *current* normal each iteration: the least-squares
    plane of their corners.

Fixed point (beyond the paper)
    In the basis mean / x-slope / y-slope / twist of a facet's corner vector, ``N p_f`` of a
    known facet is ``(h p) e_x + (h q) e_y``, independent of the current shape, and that of an
    unknown facet is the x- and y-slope part of its current ``z_f``. The loop is therefore a
    preconditioned Richardson iteration whose fixed point solves the single least-squares
    problem ``min_z sum_known ||N z_f - b_f||^2 + sum_unknown (e_twist . z_f)^2``: at an unknown
    facet only the non-planar (+-+-) part is penalised. ``solver="direct"`` solves that
    problem at once; ``solver="iterative"`` runs the paper's loop. Where the unknown facets
    leave the fixed point undetermined, a tiny ``flat_weight`` on their slopes selects the
    flattest solution, which is also where the loop started from a flat mesh ends: the inside
    of a hole. A band of unknown facets across a component would leave the offset between its
    sides free, and the flattest fill made a step there (one band width times the slope), so
    both routes first continue the slopes across such a band (:func:`continue_gaps`, weight
    :data:`CONTINUE_WEIGHT`; ``info["gaps_filled"]``).

Perspective cameras (``K`` given)
    The unknown becomes the log-depth ``log Z`` on the pixel grid (vertex spacing one pixel,
    vertex ``(i, j)`` at pixel coordinates ``(row, col) = (i - 1/2, j - 1/2)``). A normal fixes
    the derivatives of ``log Z`` along columns and rows exactly
    (:func:`facetlift.perspective.log_depth_slopes`), which become the facets' target slopes;
    the same local/global machinery then runs unchanged. Depth is ``exp`` of the result, scaled
    so that each component's median facet depth is 1 (perspective depth is only defined up to
    scale). The outlier test uses the cosine between the normal and the direction toward the
    camera instead of ``n_z``, and its default threshold is only ``1/255`` (half a quantisation
    step of an 8-bit normal map, i.e. indistinguishable from edge-on): in log-depth every
    camera-facing normal has finite slopes, and the steep normals at silhouettes are what
    links the depth of an occluding surface to the one behind it (on the DiLiGenT bear,
    dropping the 32 normals with cosine below cos 85 deg raises the smooth result's error from
    0.468 to 1.06 mm).
    See docs/perspective.md.

Depth discontinuities (``discontinuities=True``)
    Every facet keeps its own corner values, glued to the shared vertices by bilateral
    weights (BiNI's one-sided depth differences, transposed to facets) that are reweighted
    until they settle, so facets separate where the depth jumps; pieces cut off on all sides
    are placed by the occlusion rule where they nearly touch (:data:`.split.TOUCH`; every
    pair with a depth prior), else left where the solve put them. See
    :mod:`facetlift.methods.dgp.discontinuous`. Only with ``solver="direct"``; it has its own
    multigrid-CG solver (``backend`` is not used).

Options
    Declared in :data:`OPTIONS` (``facetlift methods``, docs/methods.md).

Reference
    W. Xie, Y. Zhang, C. C. L. Wang, R. C.-K. Chung. Surface-from-Gradients: An Approach Based
    on Discrete Geometry Processing. CVPR 2014.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib

import numpy as np

from ..._progress import announce
from ..._warnings import warn
from ...errors import ConvergenceWarning
from ...linalg.dense import rowwise
from ...operators.stencil import E_X, E_Y
from ...options import Option
from ...problem import relief_says_relative
from .. import MethodResult
from . import discontinuous
from .common import BlurredPrior, average_deviation, empty_components, mean_angle, targets
from .discontinuous import DEFAULT_ITER, DEFAULT_K, DEFAULT_TOL, solve_discontinuous
from .fixed_point import solve_direct
from .loop import local_shaping, solve_iterative

__all__ = ["OPTIONS", "average_deviation", "local_shaping", "normal_scale", "run",
           "solve_direct", "solve_iterative", "targets"]

_ITERATIVE = {"solver": "iterative"}
_DISC = {"discontinuities": True}

OPTIONS = (
    Option("solver", "direct", "'direct' solves the loop's fixed point at once; 'iterative' "
           "runs the paper's local/global loop", kind="choice", choices=("direct", "iterative")),
    Option("discontinuities", False, "let depth jump where the normals imply it "
           "(facets with their own corners, glued by bilateral weights)", kind="bool",
           when={"solver": "direct"}),
    Option("mean_subtraction", True, "global blending with mean subtraction (Eq. 5); "
           "without it the loop converges far more slowly (Fig. 4)", kind="bool",
           when=_ITERATIVE),
    Option("max_iter", 5000, "iteration limit of the loop", kind="int", low=1, when=_ITERATIVE),
    Option("tol", 1e-3, "stop when the average angular deviation changes by less (degrees)",
           low=0.0, when=_ITERATIVE),
    Option("backend", "auto", "sparse solver of the global step (facetlift.linalg)",
           kind="choice", choices=("auto", "pcg", "pardiso", "superlu", "amg"),
           when={"discontinuities": False}),
    Option("flat_weight", 1e-9, "slope weight of facets without a normal (selects the "
           "flattest of otherwise equal solutions)", low=0.0, low_open=True, high=1.0),
    Option("progress", None, "callable(iteration, value) called after every iteration of "
           "the routes that iterate: the loop (value: deviation), the reweightings, the CG "
           "of the direct route (value: relative residual); one with a `stage` attribute "
           "also hears stage(name) as the discontinuity route's steps without iterations "
           "start (facetlift._progress)", kind="callable", none=True),
    Option("discontinuity_k", DEFAULT_K, "sharpness of the bilateral weights, in squared pixel "
           f"footprints (larger cuts more readily), for normals with up to "
           f"{discontinuous.NOISE_K:g} deg of noise; noisier ones (read from their curl) get "
           f"k * {discontinuous.NOISE_K:g} / noise, blurred maps (soft occlusion boundaries, "
           f"info['soft_edges']) k * {discontinuous.SOFT_K:g} (info['discontinuity_k'])",
           low=0.0, low_open=True, when=_DISC),
    Option("discontinuity_iter", DEFAULT_ITER, "cap on the reweightings, the growth phase's "
           "included (a safety net: the weights settle and the cuts stop growing first)",
           kind="int", low=0, when=_DISC),
    Option("discontinuity_tol", DEFAULT_TOL, "stop when no corner weight (0..4) changes "
           "by more than this (and grow cuts only by larger steps)", low=0.0, when=_DISC),
    Option("discontinuity_seed", True, "start the reweightings from cuts where the normals' "
           "curl says a jump is (one whose height changes along it: a sheet over another, a "
           "vessel's rim) and the normals around differ little (no crease), not from the "
           "smooth surface (the reweightings without a prior, or those a sparse or blurred "
           "prior starts from; not with a dense pointwise prior); measured better on the "
           "development benchmark and on held-out views (docs/results.md)", kind="bool",
           when=_DISC),
)


#: With a depth prior compared pixel by pixel on at most this share of the facets (sparse
#: samples), the reweightings start from the cuts of the normals alone (the prior-free
#: reweightings, growth phase included, without their final solve) instead of from the smooth
#: surface; 0 turns it off. From the smooth surface every sample pulls a dent into the region
#: around it, and where that region sits wrong (a jump the normals do not show, a piece the
#: occlusion rule misplaced) the bilateral weights cut the dents loose: islands of a few
#: facets at the samples' depths in a region left where it was (the fusion benchmark's
#: angle_block seen from the left: a 10-pixel strip 10 mm off, its 18 exact samples met to
#: 1e-5 on islands). From the normals' cuts the samples move whole pieces and then add the
#: cuts the normals do not show. Measured on the fusion benchmark's 51 scenes (2026-12-04,
#: seventeenth session; docs/fusion.md, "Cuts from the normals first"), mean error before ->
#: after, scenes better / worse by more than 1 %: 1 % exact samples perspective 0.861 ->
#: 0.403 mm (24 / 3; the 0.2 mm target met on 20 of 36 instead of 17), orthographic 1.437 ->
#: 1.280 % (7 / 4); 1 % noisy 0.868 -> 0.659 mm (23 / 5), 1.641 -> 1.405 % (7 / 1); 0.1 %
#: exact 1.866 -> 1.700 mm (19 / 3), 4.896 -> 4.379 % (5 / 1); 5 % exact 0.315 -> 0.245 mm
#: (27 / 3), 0.488 -> 0.450 % (8 / 4); the coarse dense prior (every facet) unchanged (1 / 0
#: of 51) at 1.9x the time, hence the share; between them (every 3rd scene, exact samples at
#: weight 100) 20 % of the pixels still gain (perspective 0.180 -> 0.152 mm, 11 / 0;
#: orthographic 2 / 0), 50 % are mixed (0.094 -> 0.100 mm, 4 / 6; orthographic 3 / 2). The
#: cost: the prior-free reweightings come first, and a sparse prior's run now takes 1.8x the
#: time of the same integration without a prior (median over 18 scenes,
#: `benchmarks/bench_prior_time.py --step 3 --repeat 3 --discontinuities`; 1.08 with exact and
#: 1.22 with noisy samples before). Cheaper first
#: passes were worse (every 2nd scene, 1 % exact and noisy samples, against this one):
#: without the growth phase 1 / 3 and 0 / 6 better / worse at 0.95-0.97x the time, stopping
#: at a weight change of 0.2 0 / 5 and 1 / 5 at 0.90x, ten reweightings 2 / 6 and 1 / 7 at
#: 0.8x; so did starting the prior's reweightings in their decay (no free ones).
PRIOR_CUTS_FIRST = 0.25

#: A blurred prior's (``prior_blur``) reweightings start from the normals' cuts too, however
#: dense it is; where its corrections then run away (:func:`blur_astray`) the blurred prior
#: is tried once more from the smooth surface before the pointwise fallback. Measured on the
#: fusion benchmark's 51 scenes with its coarse prior blurred (8 x 8 block means,
#: ``prior_blur`` 8.94 px, weight 0.003; one interleaved A/B, 2026-12-04, seventeenth session;
#: docs/fusion.md, "Cuts from the normals first"), aligned errors: perspective mean 0.675 ->
#: 0.588 mm (19 better / 6 worse by more than 1 %), orthographic 1.405 -> 1.278 % (11 / 1);
#: the fused result beats both inputs on 38 of 51 either way; median time 1.10-1.21x; no
#: scene needed the retry. The retry is for a prior that is not blurred as said (the DiLiGenT
#: bear's exact depth declared blurred by 4 px ran away from the cuts, 2.1 times the depth
#: range; from the smooth surface it is met and warned about, as before).
BLURRED_CUTS_FIRST = True


#: A piece of at most this many facets that holds a pointwise prior sample and touches one
#: other piece only (an island inside a region: the sample pulled its own few facets to its
#: depth and the prior's reweightings cut them loose, leaving the region where the normals put
#: it) is glued back after the prior's reweightings where at least half of its sample's
#: :data:`ISLAND_COMPANY` nearest samples on other pieces of its component are on such islands
#: too, or where the piece it touches holds no other sample (:data:`ISLAND_LONELY`): its
#: corners take the normals' own weights (:data:`PRIOR_CUTS_FIRST`'s first pass) and
#: the last system is solved again, so that the samples bend their region toward them. (An
#: island's own samples do not vote: three adjacent outliers on one island voted themselves
#: back into a dent, 0.05 -> 0.95 % of a sphere's range, a review.) Where the normals show no
#: jump the samples reveal (a CAD part seen head-on: flat plateaus), every sample on a raised
#: plateau made such an island and the surface matched them only at their own pixels. An island
#: among samples that sit on their region is an outlier's, which the cut keeps local, and is
#: left so (glued back, three samples raised by 30 % of a sphere's depth range pulled dents:
#: 0.08 -> 1.07 % of the range, a review). 0 turns it off. Measured on the fusion benchmark's
#: 51 scenes (one interleaved A/B, 2026-12-05, eighteenth session; docs/fusion.md, "Islands
#: around samples"), mean error before -> after, scenes better / worse by more than 1 %: exact
#: samples at weight 100, 0.1 % perspective 1.6997 -> 1.7003 mm (0 / 0), orthographic 4.379 ->
#: 3.789 % (4 / 0); 1 % 0.403 -> 0.396 mm (1 / 0), 1.280 -> 1.209 % (1 / 0); 5 % unchanged
#: (0 / 0); 1 % exact at weight 1 0.611 -> 0.608 mm (1 / 0), 1.344 -> 1.292 % (1 / 0); 1 %
#: noisy at weight 1 0.779 -> 0.776 mm (2 / 4), 1.616 -> 1.564 % (1 / 1); 1 % exact with 3 % of
#: them 5-30 % of the depth range off, weight 1, 0.491 -> 0.490 mm (1 / 0), 1.361 -> 1.290 %
#: (1 / 0); losses at most 1.7 % (noisy samples); median time 1.01-1.02x. Every island inside
#: one region glued back (no company rule) gained more on the flat scenes (1 % exact
#: orthographic 1.046 %) but lost up to 10 % on noisy samples and 13x on outliers; any island
#: (also one between two pieces) glued pieces the samples had rightly separated (cow@left, 1 %
#: exact: 1.43 -> 6.83 mm).
ISLAND_FACETS = 16

#: How many nearest samples (pixel distance) :data:`ISLAND_FACETS` asks about an island's
#: sample, of those on other pieces of its component among its nearest
#: ``ISLAND_COMPANY + ISLAND_COMPANY_REACH``; 0 glues back every island inside one region.
ISLAND_COMPANY, ISLAND_COMPANY_REACH = 4, 16

#: An island of :data:`ISLAND_FACETS` is glued back also where the one piece it touches holds
#: no sample but islands' (whatever its company): that piece was misplaced and cut loose from
#: its sample, and nothing else places it. The fusion benchmark's cow@left with 1 % exact
#: samples: the head, joined to the body by a bridge when its one sample pulled, kept the
#: normals' place 20 mm off while the sample sat on 9 facets of its own; the bridge was cut
#: later. A sample alone on such a piece now places it, an outlier too: the removal of
#: outlier samples can hardly compare a lone sample beyond a rim with others (docs/fusion.md,
#: "Outlier samples"). No effect where :data:`ISLAND_COMPANY` is 0 (every island inside one
#: region is glued back then). Measured on the fusion benchmark's 51 scenes (one interleaved
#: A/B, 2026-12-05, twenty-first session; docs/fusion.md, "An island whose piece holds no
#: other sample"): 1 % exact samples
#: perspective 0.437 -> 0.351 mm (cow@left 4.68 -> 1.59; no other scene moved by 1 %),
#: orthographic 1.2016 -> 1.2015 %; 1 % noisy samples orthographic armadillo@front 0.840 ->
#: 0.856 % (a noisy sample alone places its piece), every other scene-condition within 1 %
#: (0.1 %, 1 %, 5 % exact, 1 % noisy, 1 % with 3 % outliers; the wide-angle scenes as well);
#: the tabletop scenes better or equal in all five (0.1 % exact 2.43 -> 2.17 mm); the
#: prior-outlier benchmark's clustered outliers perspective 1.371 -> 1.378 mm
#: (cheburashka@front 0.67 -> 0.96: a one-sample island glued back, its piece moved), single
#: outliers 0.376 -> 0.349 (kept) and unchanged (removed). False: the company rule alone.
ISLAND_LONELY = True


def _sample_islands(domain, copies, sampled, footprint):
    """``(corners, count, split)``: which vertices (n,) bool to glue back around the islands
    of :data:`ISLAND_FACETS` (and :data:`ISLAND_COMPANY`) in the split of `copies` (m, 4)
    (`sampled` (m,) bool: the prior's facets), how many islands, and that split (the mesh
    and its values, as :func:`place_pieces` forms it); None where it is off."""
    if ISLAND_FACETS <= 0:
        return None
    from ...operators.split import GAP, from_copies

    split = from_copies(domain, copies, GAP * footprint)
    mesh = split[0]
    piece = mesh.facet_piece
    sizes = np.bincount(piece, minlength=mesh.n_pieces)
    held = np.bincount(piece[sampled], minlength=mesh.n_pieces) > 0  # (pieces with a sample)
    island = (sizes <= ISLAND_FACETS) & held
    verts = np.zeros(domain.n_vertices, bool)
    if not island.any():
        return verts, 0, split
    pairs = []  # (island, neighbouring piece) across every facet edge
    for q in discontinuous.neighbours(domain).values():
        ok = (q >= 0) & island[piece]
        pairs.append(np.stack([piece[ok], piece[q[ok]]], axis=1))
    pairs = np.unique(np.concatenate(pairs), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    island &= np.bincount(pairs[:, 0], minlength=mesh.n_pieces) == 1
    if ISLAND_COMPANY and island.any():
        from scipy.spatial import cKDTree

        at = np.flatnonzero(sampled)
        r, c = domain.pixels
        own, comp = piece[at], domain.facet_component[at]
        alone = island[own]
        # the nearest samples on other pieces of the same component (an island's own samples
        # agree with it: three adjacent outliers on one island voted for each other, a review)
        k = min(ISLAND_COMPANY + ISLAND_COMPANY_REACH, at.size)
        xy = np.column_stack([r[at], c[at]])
        _, near = cKDTree(xy).query(xy, k=k)
        near = near.reshape(at.size, k)
        valid = (own[near] != own[:, None]) & (comp[near] == comp[:, None])
        valid &= np.cumsum(valid, axis=1) <= ISLAND_COMPANY
        votes = valid.sum(axis=1)
        company = (votes > 0) & ((alone[near] & valid).sum(axis=1) >= 0.5 * votes)
        keep = np.zeros(mesh.n_pieces, bool)
        keep[piece[at[alone & company]]] = True
        if ISLAND_LONELY:  # (and those whose one neighbouring piece holds no sample: an
            # island's samples are its own piece's, so it holds one only where it is an island)
            other = np.zeros(mesh.n_pieces, np.int64)
            on = island[pairs[:, 0]]
            other[pairs[on, 0]] = pairs[on, 1]
            keep |= ~(held & ~island)[other]
        island &= keep
    verts[domain.corners[island[piece]].ravel()] = True
    return verts, int(island.sum()), split


_CUTS = contextvars.ContextVar("facetlift_dgp_cuts", default=None)

#: What the prior-free reweightings' cut weights are kept with (:func:`shared_cuts`): a
#: digest of the input they were found for (not the arrays: 40 bytes a pixel held through
#: the second run), and the options.
_CUT_OPTIONS = ("k", "max_iter", "tol", "flat_weight")


@contextlib.contextmanager
def shared_cuts():
    """Within it, the discontinuity route's prior-free reweightings run once per input: the
    corner weights of a prior-free run are kept, and a later run with a sparse or blurred
    prior on the same normals, mask, confidence and options (:data:`PRIOR_CUTS_FIRST`,
    :data:`BLURRED_CUTS_FIRST`) starts from them instead of repeating those reweightings
    (``info["prior_free"]["reused"]``). :func:`facetlift.integrate` with ``prior_fit`` runs
    the route on the normals alone and then with the aligned prior: the second run's first
    pass is the first run's reweightings. Kept per context (thread), dropped on exit."""
    token = _CUTS.set([])
    try:
        yield
    finally:
        _CUTS.reset(token)


def _cut_key(domain, bx, by, target, kw) -> tuple:
    """A digest of the input and the options that decide the prior-free cut weights."""
    h = hashlib.blake2b(digest_size=20)
    for a in (domain.mask, bx, by, target, kw["normal_scale"], kw.get("weights"),
              kw.get("seed"), kw.get("k_scale")):  # (discontinuity_seed's start, the
        # steep planar facets' sharpness: other cuts)
        a = np.array([np.nan]) if a is None else np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.view(np.uint8).ravel() if a.size else b"")
    return h.hexdigest(), tuple(kw[key] for key in _CUT_OPTIONS)


#: The counts of multigrid hierarchies and factorizations in a pass's ``info``.
_BUILDS = ("multigrid_builds", "multigrid_refreshes", "factorizations")


def _add_pass(info, other, counts, lists, before=False):
    """`info` of a :func:`solve_discontinuous` with another pass's `other` counted in: the
    keys `counts` summed, the lists `lists` joined (`other`'s first where `before`), the
    seconds summed."""
    for key in counts:
        info[key] += other[key]
    for key in lists:
        info[key] = (list(other[key]) + list(info[key]) if before
                     else list(info[key]) + list(other[key]))
    info["seconds"] = {key: other["seconds"][key] + value
                       for key, value in info["seconds"].items()}


def cuts_first(prior, blur, max_iter) -> bool:
    """Whether the discontinuity route's reweightings with the prior terms `prior` (None: no
    prior) start from the normals' own cuts: a pointwise prior on at most
    :data:`PRIOR_CUTS_FIRST` of the facets, or a blurred one (`blur`) while
    :data:`BLURRED_CUTS_FIRST`; only with reweightings (`max_iter` > 0)."""
    return prior is not None and max_iter > 0 and (
        (blur is None and 0 < np.mean(prior[0] > 0) <= PRIOR_CUTS_FIRST)
        or (blur is not None and BLURRED_CUTS_FIRST))


def _discontinuous(domain, bx, by, target, *, prior, blur, x0, final_weights,
                   footprint=None, deviation=None, **kw):
    """:func:`solve_discontinuous`, from the normals' own cuts where a depth prior is compared
    pixel by pixel on few facets (:data:`PRIOR_CUTS_FIRST`) or seen through a blur
    (:data:`BLURRED_CUTS_FIRST`). That first pass is the prior-free
    route's reweightings (its confidence scaled to a largest of 1, as ``prepare`` scales it
    without a prior); the two passes share ``max_iter``, and ``info`` counts both
    (``info["prior_free"]``: the first pass's own). With a pointwise prior and the pixel
    `footprint` (of the unknown), the islands of :data:`ISLAND_FACETS` are then glued back and
    the last system solved again (``info["islands_reglued"]``). With `deviation` (a callable
    of facet copies: their mean angle to the input normals) the first pass's surface is
    measured (``info["prior_free"]["deviation"]``; where its weights were reused, that of the
    prior-free run they came from, which measures it when given `deviation`). Returns ``z, y,
    w, info`` as :func:`solve_discontinuous` and the split of `y` where the islands' search
    formed it (else None) for :func:`place_pieces`."""
    if not cuts_first(prior, blur, kw["max_iter"]):
        out = solve_discontinuous(domain, bx, by, target, prior=prior, blur=blur, x0=x0,
                                  final_weights=final_weights, **kw)
        kept = _CUTS.get()
        if prior is None and kept is not None and x0 is None:  # (shared_cuts)
            info = out[3]
            kept.append((_cut_key(domain, bx, by, target, kw), (out[2], {
                **{key: info[key] for key in ("iterations", "grown", "converged", "energy",
                                              "weight_change", "block_coarse_space",
                                              "cg_iterations", "unsolved", "seeded_corners")},
                # (its surface's, for a reusing run's blur_bent: without it the ratio to the
                # normals' own cuts was off there, a review)
                "deviation": None if deviation is None else deviation(out[1])})))
        return (*out, None)
    first_kw = dict(kw)
    weights = kw.get("weights")
    if weights is not None and target.any():
        first_kw["weights"] = np.where(target, weights / weights[target].max(), weights)
    kept = _CUTS.get()  # (shared_cuts)
    reused = None if not kept else dict(kept).get(_cut_key(domain, bx, by, target, first_kw))
    if reused is not None:
        # (the same reweightings a prior-free run did on this input: their weights and their
        # counts, CG's and its unfinished solves' included (the prior-free run's warnings are
        # not repeated, facetlift.api), but no time or multigrid build counted again)
        w, counts = reused
        first = {**counts, "multigrid_builds": 0, "multigrid_refreshes": 0, "factorizations": 0,
                 "seconds": {"setup": 0.0, "solve": 0.0}}
    else:
        _, y_free, w, first = solve_discontinuous(domain, bx, by, target, polish_last=False,
                                                  **first_kw)
        if deviation is not None:  # (of its last loose solve: no polish in this pass)
            first["deviation"] = deviation(y_free)
        del y_free
    w_first = w
    kw["max_iter"] -= first["iterations"]  # (0 left: one solve with these cuts)
    z, y, w, info = solve_discontinuous(domain, bx, by, target, prior=prior, x0=x0, w0=w,
                                        final_weights=final_weights, blur=blur, **kw)
    islands = None
    if blur is None and footprint is not None:  # (ISLAND_FACETS)
        islands = _sample_islands(domain, y, prior[0] > 0, footprint)
    if islands is not None and islands[0].any():
        w = np.where(islands[0][domain.corners], w_first, w)  # (their corners glued back)
        announce(kw.get("callback"), "islands glued back")
        # (with the final weights, as the solve it repeats: solve_discontinuous with w0)
        z, y, w, again = solve_discontinuous(domain, bx, by, target, prior=prior, x0=z, w0=w,
                                             final_weights=final_weights, blur=blur,
                                             **{**kw, "max_iter": 0, "callback": None})
        # (the last system solved again to the same tolerance, by CG on a new hierarchy, then
        # with the final weights as the polish solves them)
        info["polish"] = again["polish"] or (
            "direct" if again["factorizations"] else "multigrid")
        info["cut_corners"] = again["cut_corners"]  # (of the weights returned)
        info["cut_corners_inside"] = again["cut_corners_inside"]
        _add_pass(info, again, _BUILDS, ("cg_iterations", "unsolved"))
    split = None
    if islands is not None:
        info["islands_reglued"] = islands[1]
        split = None if islands[1] else islands[2]  # (of `y` as returned: nothing glued)
    info["prior_free"] = {key: first.get(key) for key in ("iterations", "grown", "converged",
                                                          "seconds", "seeded_corners")}
    info["prior_free"]["deviation"] = first.get("deviation")
    info["prior_free"]["reused"] = reused is not None
    _add_pass(info, first, ("iterations", "grown") + _BUILDS,
              ("energy", "weight_change", "cg_iterations", "unsolved"), before=True)
    info["converged"] = bool(info["converged"] and first["converged"])
    info["block_coarse_space"] = bool(info["block_coarse_space"] or first["block_coarse_space"])
    return z, y, w, info, split


def run(
    problem, *, solver, discontinuities, mean_subtraction, max_iter, tol, backend, flat_weight,
    progress, discontinuity_k, discontinuity_iter, discontinuity_tol, discontinuity_seed,
) -> MethodResult:
    """Integrate `problem` with the DGP method (options checked by facetlift.solve)."""
    bx, by, target = targets(problem)
    s = problem.camera.footprint()
    domain = problem.domain
    terms = prior = fusion_terms(problem)  # (the pointwise prior, as given)
    weights = problem.confidence  # None: every normal term weighs 1
    blur = astray = retried = bent = retried_bent = None

    def blurred():
        """A new BlurredPrior of the prior's terms, and the prior it weighs."""
        b = BlurredPrior(domain, terms[0], terms[1], problem.prior_blur)
        return b, (b.weight,) + terms[1:]

    if prior is not None and problem.prior_blur > 0:  # docs/fusion.md, "Blurred priors"
        if solver != "direct":
            raise ValueError("`prior_blur` needs solver='direct' for method 'dgp' (the paper's "
                             f"loop has no blurred prior term); got solver={solver!r}")
        if discontinuities and discontinuity_iter == 0:
            raise ValueError("`prior_blur` needs discontinuity_iter >= 1 with "
                             "discontinuities=True (the blurred prior's target is corrected "
                             "between reweightings); got discontinuity_iter=0")
        blur, prior = blurred()
    lone = None  # (a pointwise prior of one sample per component: lone_samples)
    if discontinuities and prior is not None and blur is None:
        lone = lone_samples(domain, prior)
        if lone is not None:  # the route without it (its confidence scaled as prepare
            prior = None  # scales it without a prior), each sampled component moved after
            if weights is not None and target.any():  # (not the facets without a normal,
                # which prepare gives 1 after its scaling, as _discontinuous's first pass)
                weights = np.where(target, weights / weights[target].max(), weights)
    if discontinuities:
        if discontinuity_tol >= 4.0 and discontinuity_iter > 0:  # (a review: said nowhere)
            warn(f"`discontinuity_tol` {discontinuity_tol:g}: the corner weights lie in 0..4, "
                 "so no step exceeds it and the reweightings stop at the first that may "
                 "(the first, or with a blurred prior the first its target settles at; "
                 f"reported converged); the default is {DEFAULT_TOL:g}")
        empty_components(domain, target, offset=problem.extras.get("offset", (0, 0)))
        given = target  # (the input's own normals: the deviation is measured on them)
        scale = normal_scale(problem)
        cosines = problem.view_cosines
        filled = None
        if GAP_WEIGHT > 0:
            # (a Problem built without prepare has no such mask: nothing is filled, not the
            # back-facing facets that ~known would add, a review)
            gaps = problem.extras.get("no_normal")
            if gaps is not None:
                bx, by, target, scale, cosines, weights, filled = fill_gaps(
                    domain, bx, by, target, scale, cosines, weights, gaps)
                if prior is None:  # (as for the smooth routes, _continued)
                    bx, by, target, scale, cosines, weights, filled = _bands_continued(
                        domain, bx, by, target, scale, cosines, weights, gaps, filled)
        def start(prior):
            if prior is None or target.all():
                return None
            # facets without a normal leave near-null modes (the flattest fill of a hole) that
            # the prior's samples excite and multigrid-CG does not resolve (a hole of missing
            # normals came out hundreds of mm off): start from the smooth fixed point, whose
            # solver resolves them exactly
            return solve_direct(domain, bx, by, target, backend, flat_weight, weights, h=s,
                                prior=prior, rtol=START_RTOL if blur is None else None)[0]

        z0 = start(prior)
        final = None
        power = discontinuous.FINAL_COS_POWER  # (docs/perspective.md, "Final weights")
        # (with a pointwise prior only where it starts from the normals' cuts, a sparse one:
        # FINAL_COS_POWER; a dense one's weight is in units of a normal term of weight 1)
        if (prior is None or blur is not None
                or cuts_first(prior, None, discontinuity_iter)) and power:
            final = np.where(target, cosines, 1.0) ** power
            final = final if weights is None else final * weights
        from ...frames import normal_noise

        noise = normal_noise(problem)  # (degrees, from the curl: discontinuous.NOISE_K)
        # (a blurred map's soft occlusion boundaries: discontinuous.SOFT_K)
        steps = discontinuous.soft_edges(domain, problem.normals, given)
        k_used = discontinuous.sharpness(discontinuity_k, noise, steps)
        seed = None
        if discontinuity_seed and discontinuity_iter > 0:  # (the prior-free reweightings
            # from the normals' curl; with no reweighting every corner glued: docs/cli.md,
            # `converged`, says what that run is)
            # (the spread of the input's own normals: not a confidence-0 normal's direction,
            # which is missing whatever it is; a review)
            seed = discontinuous.curl_seed(domain, bx, by, target, cosines, s,
                                           float(np.radians(noise)),
                                           np.where(given[:, None], problem.normals, np.nan))
        # (a plane seen nearly edge-on through noisy normals: its facets' sharpness capped)
        k_scale = discontinuous.steep_planar(domain, problem.normals, target, bx, by, s, noise,
                                             given=given)
        from ..._progress import rising

        # (one count over the passes, each of which counts from 1: a review)
        common = dict(normal_scale=scale, k=k_used, max_iter=discontinuity_iter,
                      tol=discontinuity_tol, flat_weight=flat_weight, callback=rising(progress),
                      weights=weights, seed=seed, k_scale=k_scale)

        def deviation(c):
            """Mean angle (deg) of the facets' copies `c` to the input's own normals."""
            return mean_angle(rowwise(c, E_X), rowwise(c, E_Y), bx, by, given, s)

        z, y, w, info, split = _discontinuous(domain, bx, by, target, prior=prior, x0=z0,
                                              final_weights=final, blur=blur, footprint=s,
                                              # (a prior-free run's too: kept for a run
                                              # that reuses its cuts, shared_cuts)
                                              deviation=deviation if blur is not None
                                              or prior is None else None,
                                              **common)
        free = info.get("prior_free", {}).get("deviation")  # (the normals' own cuts' surface)
        announce(progress, "placing pieces")
        if lone is None:
            copies, pinfo = place_pieces(domain, y, bx, by, target, s, split=split,
                                         anchored=None if prior is None else prior[0] > 0,
                                         hang_anchored=blur is not None)
        else:  # (placed as without the prior, the pieces no sample holds counted for the
            # warning below; then each sampled component moved to its sample)
            copies, pinfo = place_pieces(domain, y, bx, by, target, s, split=split,
                                         anchored=terms[0] > 0, by_prior=False)
            copies = meet_samples(domain, copies, terms, lone)

        angle = None  # (the last surface's mean deviation, trouble's)

        def trouble():
            """Whether the blurred prior ran away (:func:`blur_astray`) or bent the surface
            away from its normals (:func:`blur_bent`); sets `astray` and `bent`."""
            nonlocal astray, bent, angle
            astray = blur_astray(blur, copies.mean(axis=1))
            angle = None if astray is not None else deviation(copies)
            bent = blur_bent(angle, free)  # (None with no angle)
            return astray is not None or bent is not None

        if blur is not None and trouble() and "prior_free" in info:
            # (they ran away from the normals' cuts: the blurred prior once more from the
            # smooth surface, BLURRED_CUTS_FIRST)
            blur, prior = blurred()
            z, y, w, info = solve_discontinuous(domain, bx, by, target, prior=prior, x0=z0,
                                                final_weights=final, blur=blur, **common)
            retried = astray  # (the departure from the normals' cuts)
            retried_bent = bent
            copies, pinfo = place_pieces(domain, y, bx, by, target, s, anchored=prior[0] > 0,
                                         hang_anchored=True)
            trouble()
        if astray is not None or bent is not None:  # (the blurred prior ran away or bent
            # the surface away from its normals: the prior compared pixel by pixel instead)
            prior = terms
            z, y, w, info, split = _discontinuous(domain, bx, by, target, prior=prior,
                                                  x0=start(prior), final_weights=None,
                                                  blur=None, footprint=s, **common)
            copies, pinfo = place_pieces(domain, y, bx, by, target, s, anchored=prior[0] > 0,
                                         split=split)
            blur.returned = blur.rms(copies.mean(axis=1))  # (of the surface returned)
            if bent is not None and not np.isfinite(bent):
                why = ("the surface's depths overflowed (no deviation from its normals could "
                       "be measured): the blurred prior's corrections ran away (sigma "
                       f"{problem.prior_blur:g} px; a prior near 0 or of another kind, e.g. a "
                       "relative depth not fitted, prior_fit=, can do so, docs/fusion.md)")
            elif bent is not None:
                free_text = "" if free is None else f" (the normals' own cuts: {free:.2g} deg)"
                why = (f"the surface departed from its own normals by {bent:.3g} deg on "
                       f"average{free_text}, more than a surface of these normals can: the "
                       "blurred prior's corrections bent it (sigma "
                       f"{problem.prior_blur:g} px; a prior that is not blurred as said, e.g. "
                       "block means upsampled without a further blur, can do so, "
                       "docs/fusion.md)")
            else:
                why = (f"the surface departed from the blurred prior by up to {astray:.3g} "
                       "times the depth range of the prior (or of the first solve, the larger; "
                       "99.9th percentile), far beyond what a blur can hide: the blurred "
                       f"prior's corrections tore it apart (sigma {problem.prior_blur:g} px; "
                       "block means upsampled without a further blur are known to do so, "
                       "docs/fusion.md)")
            warn(f"prior_blur: {why}. The prior was compared pixel by pixel instead "
                 "(info['prior_blur']['fallback']); a smaller prior_weight (--prior-weight) or "
                 "integrating without discontinuities may do better", ConvergenceWarning)
        elif blur is not None and blur_bent(angle, free, BENT_WARN) is not None:
            # (kept, but said: a map resized from point samples and declared blurred came out
            # 14.9 deg from its normals, under BENT, 2.7 mm off on the bear, a user's check)
            own = "" if free is None else f" (the normals' own cuts: {free:.2g} deg)"
            warn(f"prior_blur: the surface lies {angle:.3g} deg from its own normals on "
                 f"average{own}: the blurred prior's "
                 f"corrections bent it (sigma {problem.prior_blur:g} px). Is the prior blurred "
                 "as said? A map resized from point samples of a coarse grid is not: give "
                 "those samples instead (NaN between them, docs/fusion.md, 'A depth map of "
                 "lower resolution'); or try a smaller prior_blur (--prior-blur) or none",
                 ConvergenceWarning)
        pointwise = prior is not None and (blur is None or astray is not None
                                           or bent is not None)
        # (the share of one-pixel steps among the map's strong changes; NaN: too few seen)
        info["soft_edges"] = steps
        # (not with a prior aligned by prior_fit, inside shared_cuts: its alignment a few %
        # off tears a sharp prior at the jumps while it agrees on the flats, and the warning
        # names the fit, a review)
        # (measured only where the warning would fire: six image-sized arrays, a review)
        fitted = _CUTS.get() is not None

        def agrees():
            return (pointwise and not fitted
                    and prior_mismatch(domain, prior, bx, by, target, s) <= PRIOR_AGREES)
        _discontinuity_warnings(info, prior if pointwise else None, domain,
                                pinfo["mesh_pieces"],
                                blurred=prior if prior is not None and not pointwise else None,
                                noise=noise, agrees=agrees,
                                relative=problem.perspective and not fitted
                                and relief_says_relative(problem.extras.get("prior_relief")))
        if (pointwise or lone is not None) and pinfo.get("unanchored_pieces"):
            size, row, col = pinfo["unanchored_largest"]
            r0, c0 = problem.extras.get("offset", (0, 0))  # (the image's rows and columns)
            row, col = row + r0, col + c0
            pinfo["unanchored_largest"] = [size, row, col]
            warn(f"discontinuities with a depth prior: {pinfo['unanchored_pieces']} piece(s) "
                 f"that the cuts separate hold no prior sample ({pinfo['unanchored_facets']:,} "
                 f"pixels; the largest {size:,}, e.g. at (row {row}, col {col})): their depth "
                 "is placed against their neighbours by the occlusion rule, not measured, and "
                 "may be far off (info['unanchored_pieces'], --json); give samples there")
        split_mesh = pinfo.pop("_mesh", None)
        info.update(pinfo)
        info["solver"] = "discontinuous"
        # (of the facets as returned, each on its own corner copies: the glued vertices' mean
        # angle, 1.8 deg where the result's was 0.68, described a surface not returned)
        info["deviation"] = [deviation(copies)]
        info["gaps_filled"] = 0 if filled is None else int(filled.sum())
        if terms is not None and problem.prior_blur == 0:
            info["prior_one_per_component"] = lone is not None
        extras = {"corner_values": copies}
        if split_mesh is not None:  # (make_surface splits the copies itself otherwise)
            extras["split_mesh"] = split_mesh
        result = MethodResult(values=copies.mean(axis=1), info=info, extras=extras)
    elif solver == "direct":  # both loops share this fixed point
        bx, by, target, weights, filled = _continued(problem, bx, by, target, weights)
        z, info = solve_direct(domain, bx, by, target, backend, flat_weight, weights, h=s,
                               prior=prior, progress=progress, blur=blur,
                               offset=problem.extras.get("offset", (0, 0)))
        info["gaps_filled"] = int(filled.sum())
        result = MethodResult(vertex_values=z, info=info)
    else:
        bx, by, target, weights, filled = _continued(problem, bx, by, target, weights)
        z, info = solve_iterative(
            domain, bx, by, target, s, mean_subtraction, max_iter, tol, backend, progress,
            weights=weights, prior=prior, offset=problem.extras.get("offset", (0, 0)),
        )
        info["gaps_filled"] = int(filled.sum())
        result = MethodResult(vertex_values=z, info=info)
    if blur is not None:
        info["prior_blur"] = blur.info()
        info["prior_blur"]["fallback"] = astray is not None or bent is not None
        info["prior_blur"]["astray"] = astray  # (the departure ratio that called for it)
        # (the mean deviation from the normals, deg, that called for it: blur_bent)
        info["prior_blur"]["bent"] = bent
        # (the same from the normals' cuts, where it called for the retry from the smooth
        # surface: BLURRED_CUTS_FIRST)
        info["prior_blur"]["retried"] = retried
        info["prior_blur"]["retried_bent"] = retried_bent
        if not info["prior_blur"]["fallback"]:
            info["converged"] = bool(info.get("converged", True)) and blur.converged
            _blur_check(info["prior_blur"], blur.prior[blur.samples])
    # (of the input's own usable normals: the discontinuity route's filled target would leave
    # out the filled facets of confidence 0, a review)
    info["outliers"] = int((problem.known & ~problem.usable).sum())
    info["missing"] = int((~problem.known).sum())
    return result


#: Relative residual of the smooth solve with a pointwise depth prior that starts the
#: discontinuity route's reweightings (None: the fixed point's own, 1e-11; a blurred prior's
#: start keeps it). The reweightings solve to 1e-4 themselves (``LOOSE_RTOL``). Measured on
#: every third scene of the fusion benchmark (22, 1 % exact samples at weight 100 and 1 % noisy
#: ones at weight 1; one interleaved A/B, 2026-12-04): median time 0.977x (exact) and 0.972x
#: (noisy); errors within 1 % on 41 of 44 runs (spot@front exact +6.5 %, cheburashka@left noisy
#: +2.5 %, fandisk@oblique noisy +1.8 %; fandisk@oblique and mountain@oblique exact -2 %).
START_RTOL = 1e-4


#: The discontinuity route gives a facet without a normal (missing, non-finite, zero-length
#: or of confidence 0), at least two of whose four edge neighbours have a usable one, their
#: mean slope as its target with this weight (times their mean normal weight). Without it
#: such a facet transmits no offset: where a cut leaves a bridge a facet or two wide (the
#: DiLiGenT bear's head on its body), one missing normal in the bridge set the head free
#: (200 or 400 random missing normals: MADE 0.27 mm instead of 0.025 on 3 of 5 seeds each).
#: Larger gaps keep the flattest fill inside. Measured in docs/perspective.md
#: (benchmarks/bench_missing_jumps.py).
GAP_WEIGHT = 0.1


def _continued(problem, bx, by, target, weights):
    """The smooth routes' targets with the gaps continued (:func:`continue_gaps`) where
    :data:`GAP_WEIGHT` is on and the problem marks its facets without a normal."""
    gaps = problem.extras.get("no_normal")
    if not GAP_WEIGHT > 0 or gaps is None or problem.has_prior:
        # (a prior's samples place the sides of a band themselves, and one that hides a jump
        # was bridged against them: two planes 5 apart came back 0.16 off, a review)
        return bx, by, target, weights, np.zeros(problem.domain.n_facets, bool)
    return continue_gaps(problem.domain, bx, by, target, weights, gaps)


def continue_gaps(domain, bx, by, target, weights, gaps):
    """The smooth routes' fill of facets without a normal: `bx, by, target, weights` with
    every facet of `gaps` (m,) bool that has no target and lies in a band of such facets
    between two groups of facets with one (:func:`_loose`) given the harmonic continuation of
    the slopes around it (:func:`continued`) as its target, of weight
    :data:`CONTINUE_WEIGHT` times the continued normal weight; and those facets (m,) bool.

    Without it such a facet holds only the tiny ``flat_weight`` on its slopes: a band of
    missing normals across a region made a flat step in the surface, one band width times the
    slope high (a plane with one row of NaN normals came back with a step of 0.2 where its
    rows rise by 0.2, an audit). The slopes continued across the band make such a plane
    exact. Not the grazing or back-facing facets, which lie on silhouettes
    (:func:`fill_gaps`), and not a region of facets without a normal that touches none with
    one (it stays flat, with its warning).
    """
    (bx, by), w, fill = _weakly_continued(domain, target, gaps, weights, (bx, by))
    return bx, by, target | fill, w, fill


def _weakly_continued(domain, target, gaps, weights, columns):
    """``(columns, weights, fill)``: the per-facet `columns` and the normal `weights` (None:
    1) continued across the bands of :func:`continued`, the filled facets' weights times
    :data:`CONTINUE_WEIGHT`; all as given where nothing is filled."""
    w = np.ones(domain.n_facets) if weights is None else np.asarray(weights, dtype=float)
    values, fill = continued(domain, np.column_stack([*columns, w]), target, gaps)
    if not fill.any():
        return tuple(columns), weights, fill
    *columns, w = values.T
    return tuple(columns), np.where(fill, CONTINUE_WEIGHT * np.maximum(w, 0.0), w), fill


def _bands_continued(domain, bx, by, target, scale, cosines, weights, gaps, filled):
    """The discontinuity route's targets after :func:`fill_gaps` with the bands of facets
    without a normal that join two groups continued across as :func:`continue_gaps` does for
    the smooth routes (the slopes, the normal scale and the view cosine alike; weight
    :data:`CONTINUE_WEIGHT` times the continued normal weight), and `filled` with them.
    Measured with a row and a column of missing normals across each object, on every third
    scene of the development benchmark (docs/perspective.md, "Bands of missing normals"):
    bands 3 pixels wide, perspective 2.930 -> 2.572 mm (10 better, 1 worse by more than 1 %;
    with every normal 2.153), orthographic 5.675 -> 5.223 % (3 / 0); 6 pixels wide, 30 scenes
    of every group, 21 better and 7 worse (perspective 3.245 -> 2.528 mm, rooms 11.14 ->
    3.92, wide 2.075 -> 2.508: a band along a jump is continued across it). A band one facet
    wide is :func:`fill_gaps`' as before."""
    (bx, by, scale, cosines), w, more = _weakly_continued(domain, target, gaps, weights,
                                                            (bx, by, scale, cosines))
    return bx, by, target | more, scale, cosines, w, filled | more


def continued(domain, values, target, gaps):
    """``(values, fill)``: `values` (m, k) with the rows of the facets to fill replaced by
    the harmonic continuation of the rows around them (each filled row the mean of its edge
    neighbours', those with a `target` fixed), and those facets (m,) bool: the facets of
    `gaps` without a target in regions of such facets that join two large groups of facets
    with one (:func:`_loose`). A copy only where something is filled."""
    values = np.asarray(values, dtype=float)
    unknown = gaps & ~target
    none = np.zeros(domain.n_facets, bool)
    if not unknown.any():
        return values, none
    groups = _groups(domain, target)
    if groups is None:  # (no two large groups in one component: nothing to join; the
        # graph below took 2.4 s for a 2048^2 map with 30 % of its normals missing at random)
        return values, none
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    from scipy.sparse.csgraph import connected_components

    sides = list(discontinuous.neighbours(domain).values())  # (-1: none)
    idx = np.flatnonzero(unknown)
    pos = np.full(domain.n_facets, -1, np.int64)
    pos[idx] = np.arange(idx.size)
    rows, cols = [], []
    deg = np.zeros(idx.size)
    known_sum = np.zeros((idx.size, values.shape[1]))
    beside = np.zeros(idx.size, bool)  # (a gap with an edge neighbour that has a target)
    for q in sides:
        qq = q[idx]
        inside = qq >= 0
        link = inside & (pos[np.maximum(qq, 0)] >= 0)  # (a gap beside a gap)
        fixed = inside & target[np.maximum(qq, 0)]  # (a gap beside a facet with a target)
        beside |= fixed
        deg += link | fixed
        known_sum[fixed] += values[qq[fixed]]
        rows.append(np.flatnonzero(link))
        cols.append(pos[qq[link]])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    A = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(idx.size, idx.size))
    # (the regions of gaps that touch a facet with a target; the others stay unfilled)
    _, label = connected_components(A, directed=False)
    k = label.max() + 1
    touches = np.zeros(k, bool)
    touches[label[beside]] = True
    keep = touches[label] & _loose(domain, idx, label, k, groups)[label]
    if not keep.any():
        return values, none
    sub = np.flatnonzero(keep)
    L = (sp.diags(deg) - A)[sub][:, sub].tocsc()
    rhs = known_sum[sub]
    if sub.size <= CONTINUE_DIRECT:
        x = np.asarray(spla.splu(L).solve(rhs)).reshape(sub.size, -1)
    else:  # (a large region: multigrid, as the solvers' own)
        import pyamg

        ml = pyamg.smoothed_aggregation_solver(L.tocsr(), symmetry="symmetric")
        x = np.column_stack([ml.solve(rhs[:, j], tol=1e-8, maxiter=200)
                             for j in range(rhs.shape[1])])
    fill = np.zeros(domain.n_facets, bool)
    fill[idx[sub]] = True
    values = values.copy()
    values[fill] = x
    return values, fill


#: Weight of :func:`continue_gaps`' continued slopes (times the continued normal weight).
CONTINUE_WEIGHT = 1e-3

#: Fewest facets of a group of facets with a normal (8-connected) that :func:`continue_gaps`
#: joins to another across facets without one.
CONTINUE_GROUP = 64

#: Smallest share of its mask component a group of :func:`continue_gaps` must hold (with
#: :data:`CONTINUE_GROUP` facets): with 60 % of the normals missing at random, clusters of
#: 64 known facets are common and were continued as if bands parted them (the analytic
#: saddle, exact with the flattest fill, 6e-8 -> 1e-3 RMS; the face +7 %, a review); the
#: parts a band cuts off an object are larger.
CONTINUE_SHARE = 0.05

#: Largest number of facets of :func:`continue_gaps`' system solved by factorization; larger
#: ones by smoothed-aggregation multigrid (pyamg).
CONTINUE_DIRECT = 200_000


def _groups(domain, target) -> np.ndarray | None:
    """(H, W) labels of the groups of at least :data:`CONTINUE_GROUP` 8-connected facets
    with a target (0 elsewhere), or None where no mask component holds two of them."""
    from scipy import ndimage

    groups, n = ndimage.label(domain.to_image(target, fill=False), np.ones((3, 3), bool))
    if n < 2:
        return None
    size = np.bincount(groups.ravel(), minlength=n + 1)
    # (the mask component of each group: two large ones in one component may be joined by
    # gaps; large: CONTINUE_GROUP facets and CONTINUE_SHARE of their component)
    r, c = domain.pixels
    where = np.zeros(n + 1, np.int64)
    where[groups[r, c]] = domain.facet_component
    share = CONTINUE_SHARE * np.bincount(domain.facet_component)[where]
    big = (size >= CONTINUE_GROUP) & (size >= share)
    big[0] = False
    if big.sum() < 2:
        return None
    comp = where[big]
    if np.unique(comp).size == comp.size:
        return None
    groups[~big[groups]] = 0
    return groups


def _loose(domain, idx, label, k: int, groups) -> np.ndarray:
    """(k,) bool: which regions `label` of the facets `idx` without a target join groups of
    facets with one that nothing else joins (a band across the domain: facets that share a
    vertex fix each other's offset, so the groups are those of 8-connected pixels with a
    target): there the normals leave the groups' relative offset free. Not a hole inside one
    group, whose inside keeps the flattest fill: continuing the slopes into holes was no
    better on the analytic surfaces (the 128^2 face, RMS inside a hole at rows 50-59, columns
    70-79: 0.17 -> 0.42; 24 x 24 there 2.2 -> 1.8; 30 % random missing normals +4 % on the
    sphere). Only large groups count (:func:`_groups`, whose labels `groups` are): a few
    known normals amid missing ones (30 % missing at random leaves such islands) sit as well
    in the flattest fill (the sphere's error +6 % with them continued)."""
    H, W = domain.shape
    r, c = domain.pixels[0][idx], domain.pixels[1][idx]
    lo = np.full(k, np.iinfo(np.int64).max)
    hi = np.zeros(k, np.int64)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            rr, cc = r + dr, c + dc
            ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            g = np.zeros(idx.size, np.int64)
            g[ok] = groups[rr[ok], cc[ok]]
            seen = g > 0
            np.minimum.at(lo, label[seen], g[seen])
            np.maximum.at(hi, label[seen], g[seen])
    return hi > lo


def fill_gaps(domain, bx, by, target, scale, cosines, weights, gaps):
    """`bx, by, target, scale, cosines, weights` with the facets that :data:`GAP_WEIGHT`
    fills given their edge neighbours' means (weights: times GAP_WEIGHT), and those facets
    (m,) bool. Only facets of `gaps` (m,) bool are filled: those without a normal (a normal
    of confidence 0 is none, whatever its direction), not the grazing or back-facing ones,
    which lie on the silhouettes, where the neighbours' slopes would glue an occluding rim to
    what it occludes (filling those too took the bear from 0.025 to 0.38 mm)."""
    sides = list(discontinuous.neighbours(domain).values())  # (-1: none)
    nb = [np.maximum(q, 0) for q in sides]
    have = [(q >= 0) & target[qq] for q, qq in zip(sides, nb, strict=True)]
    count = np.sum(have, axis=0)
    fill = gaps & ~target & (count >= 2)
    if not fill.any():
        return bx, by, target, scale, cosines, weights, fill
    c = count[fill].astype(float)

    def mean(v):
        out = np.array(v, dtype=float)
        out[fill] = sum(np.where(h[fill], v[qq[fill]], 0.0)
                        for h, qq in zip(have, nb, strict=True)) / c
        return out

    w = np.ones(domain.n_facets) if weights is None else np.asarray(weights, dtype=float)
    w = mean(w)
    w[fill] *= GAP_WEIGHT
    return (mean(bx), mean(by), target | fill, mean(scale), mean(cosines), w, fill)


#: Median disagreement, in pixel footprints, between a pointwise prior's step from pixel to
#: 4-neighbouring pixel and the step the two normals there predict
#: (:func:`prior_mismatch`) at or below which the prior is taken to agree with the normals:
#: then the cuts are the normals' jumps, not its tearing, and the torn-surface warning
#: (:data:`TORN`, :data:`TORN_PIECES`) is not given. An audit's exact dense prior on a render
#: with 80 pieces of its own (19 % of the corners cut with or without it) was told to lower
#: its weight or blur it, which took its 0.00044 mm to 0.0015 and 0.0024. Gaussian noise of
#: sigma footprints reads 0.95 sigma (the DiLiGenT bear's own depth as the prior: 0.005 exact,
#: 0.24 / 0.48 / 0.95 / 2.86 at 0.25 / 0.5 / 1 / 3 footprints); a sensor's 1-3 footprints
#: stay far above this. A median of local steps cannot see a prior that is smooth and wrong
#: as a whole, or one with a false jump along a line (the median of a steps scene's pairs
#: reads 0.0 with a false 5-unit jump, 0.035 scaled by 1.2, a review): such a prior tearing
#: the surface gets no warning.
PRIOR_AGREES = 0.1


def prior_mismatch(domain, prior, bx, by, target, footprint: float) -> float:
    """The median over 4-neighbouring facets that both hold a prior sample and a normal of
    ``|(t_b - t_a) - (predicted step)|`` in pixel footprints (the prior's targets `t` in the
    camera's unknown, the predicted step the trapezoid of the two normals' grid slopes, as
    :func:`facetlift.methods.dgp.split._continuation` predicts one); NaN with fewer than 20
    such pairs."""
    if prior is None or not footprint > 0:
        return float("nan")
    H, W = domain.shape
    r, c = domain.pixels
    t = np.full((H, W), np.nan)
    have = (prior[0] > 0) & target
    t[r[have], c[have]] = prior[1][have]
    gx = np.zeros((H, W))
    gy = np.zeros((H, W))
    gx[r, c], gy[r, c] = bx, by
    right = (t[:, 1:] - t[:, :-1]) - 0.5 * (gx[:, 1:] + gx[:, :-1])
    down = (t[1:, :] - t[:-1, :]) + 0.5 * (gy[1:, :] + gy[:-1, :])
    e = np.abs(np.concatenate([right[np.isfinite(right)], down[np.isfinite(down)]]))
    return float(np.median(e)) / footprint if e.size >= 20 else float("nan")


def _discontinuity_warnings(info: dict, prior, domain, pieces: int = 0,
                            blurred=None, noise: float = float("nan"),
                            agrees=False, relative=False) -> None:
    """The discontinuity route's warnings on the solve returned: a pointwise `prior` that tore
    the surface apart (:data:`TORN`, :data:`TORN_PIECES`; None: no such prior), or a
    `blurred` one (``prior_blur``, the prior's terms as `prior`'s) that did, a run without a
    prior that cut too much (:data:`CUT_MANY`; the normals' noise, `noise` in degrees as the
    route read it, named), and solves left unfinished. `relative`: a perspective prior not
    aligned by ``prior_fit``, so the torn warnings name a relative depth too."""
    # (a review: a monocular network's 0..1 depth given with K tore the bunny into 8,167
    # pieces, 407 mm off, and was told of noise and weights only)
    fit = (" Or it is a relative depth, known only up to scale and shift (a monocular "
           "network's, e.g. 0..1, or a disparity): fit it with prior_fit='affine' or "
           "'disparity' (--prior-fit)." if relative else "")
    if prior is not None and prior[0].max() > PRIOR_STRONG:
        warn(f"discontinuities with prior_weight up to {prior[0].max():g}: above "
             f"{PRIOR_STRONG:g} the reweightings' solves stop before the normals' part is "
             "solved (their tolerance is relative to a right-hand side the samples dominate), "
             "and the surface away from the samples gets worse, not better; "
             f"{PRIOR_STRONG:g} already meets exact samples closely (docs/fusion.md, 'Units')")
    many = max(TORN_PIECES * domain.n_facets, 50)
    # (`agrees`, a bool or a callable giving one: the pointwise prior steps as the normals
    # do, :data:`PRIOR_AGREES`: the cuts are the normals' own)
    if prior is not None and (info["cut_corners"] > TORN or pieces > many) and not (
            agrees() if callable(agrees) else agrees):
        samples = int((prior[0] > 0).sum())
        typical = float(np.median(prior[0][prior[0] > 0])) if samples else 0.0
        # (what such a prior is: 1,000 LiDAR points were told of a dense map, a review)
        kind = ("a sensor's or a network's dense map" if samples > 0.25 * domain.n_facets
                else "points with noise of several pixel footprints, a LiDAR's or SfM's: "
                "0.01 did best for 3 mm on a rendered armadillo, docs/fusion.md")
        # (a user at 0.01 was told to lower it to 0.01)
        lower = ("A lower prior_weight (--prior-weight; 0.01 did best for a dense prior with "
                 "noise of 1-3 pixel footprints, 0.001 for a 4x coarse sensor about 7 "
                 "footprints noisy, docs/fusion.md)" if typical > TORN_BEST * 1.01
                 else f"A prior_weight below its {typical:g} (--prior-weight; {TORN_BEST:g} did "
                 "best for a dense prior with noise of 1-3 pixel footprints, 0.001 for a 4x "
                 "coarse sensor about 7 footprints noisy, docs/fusion.md: this one may be "
                 "noisier, or not aligned with the normals)")
        # (a neural-estimator user's blurred 8-bit normals against an exact disparity prior:
        # 3,540 pieces, the best result of all (0.35 mm), and the warning blamed a noisy
        # prior, whose advice did not help, an audit: either side may be the noisy one)
        warn(f"discontinuities with a depth prior: {info['cut_corners']:.0%} of the facet "
             f"corners were cut, {pieces:,} pieces ({samples:,} prior samples): where the "
             "prior and the normals disagree from pixel to pixel, its samples tear the "
             f"surface apart. If the prior is the noisier ({kind}): {lower}, prior_blur, "
             "or integrating without discontinuities may do "
             "better. If the normals are (blurred or 8-bit, against a sharp prior), the depth "
             "follows the prior and may be right though the mesh is in pieces: judge it by "
             "the depth. Or the prior is not in the normals' scale (pixel_size, K, the "
             "prior's units: a pixel_size 32 times too small tore a sphere's exact samples "
             f"apart so).{fit}")
    if blurred is not None and (info["cut_corners"] > TORN or pieces > many):
        # (an audit's 4x coarse sensor with 3 mm of noise, prior_blur 2: 37 % of the corners
        # cut, 827 pieces, 2.56 mm on the DiLiGenT bear against 0.16 at prior_weight 0.001
        # pixel by pixel, and no word: the blurred prior's mismatch had fallen)
        warn(f"discontinuities with a blurred depth prior (prior_blur): "
             f"{info['cut_corners']:.0%} of the facet corners were cut, {pieces:,} pieces: "
             "the blurred prior's corrections tore the surface apart, as a prior noisier than "
             "a blur (a sensor's noise, a map upsampled in blocks) does. A pointwise prior at a "
             "low prior_weight (0.001 did best for a 4x coarse sensor with noise of about 7 "
             "pixel footprints, docs/fusion.md 'A depth sensor'), the coarse map's pixels as "
             "points at their footprints' centres, or integrating without discontinuities may "
             f"do better.{fit}")
    # (counted away from the mask's edge, info["cut_corners_inside"]: a slope's edge facets
    # read as cut with nothing to separate, and a 3-pixel strip of a plane was warned
    # about, a review)
    inside = info.get("cut_corners_inside", info["cut_corners"])
    if prior is None and blurred is None and inside > CUT_MANY:
        steep = "on surfaces seen steeply (a floor or a table top from a low camera)"
        if np.isfinite(noise) and noise < NOISE_LOW:  # (the usual cause ruled out: a review)
            cause = (f"these normals' noise, read from their curl, is low (about {noise:.1f} "
                     f"deg), so it is less likely noisy normals {steep} read as jumps than "
                     "many real ones, or a camera or frame that does not fit the normals")
        else:
            read = ("" if not np.isfinite(noise) else
                    f" (these normals' noise, read from their curl: about {noise:.1f} deg)")
            cause = f"noisy normals{read} {steep} read as jumps"
        warn(f"discontinuities: {inside:.0%} of the facet corners were cut away from the "
             f"mask's edge ({pieces:,} mesh pieces), more than surfaces with real jumps give "
             "(at most 21 % of all corners on the development benchmark's renders and the "
             f"real maps, 18 % away from the edge on every third of them): {cause}. "
             + ("" if discontinuous.sharpness(1.0, noise) == 1.0 else
                f"For this noise the sharpness was already lowered to "
                f"{info['discontinuity_k']:.2g} (discontinuity_k times "
                f"{discontinuous.NOISE_K:g} / noise, info['discontinuity_k']). ")
             # (a review: a blurred map's doubled sharpness went unsaid, and the advice's k=2
             # was then the old default's 4)
             + ("" if discontinuous.sharpness(1.0, noise, info.get("soft_edges", np.nan))
                <= 1.0 else
                f"This map read as blurred (info['soft_edges'] "
                f"{info.get('soft_edges', np.nan):.3g}), so the sharpness was raised to "
                f"{info['discontinuity_k']:.2g} (discontinuity_k times "
                f"{discontinuous.SOFT_K:g}); the values below are multiplied by it too. ")
             + "A smaller discontinuity_k cuts far less (--option discontinuity_k=2, or 1), or "
             "integrate without discontinuities (docs/results.md, 'A flat surface seen "
             "steeply, with noise, falls apart')")
    if info["unsolved"]:
        why = (f"more than {discontinuous.DIRECT_POLISH:,} vertices"
               if domain.n_vertices > discontinuous.DIRECT_POLISH else
               "a factorization would not fit in the memory the job may use: the limit "
               "of max_memory (--max-memory), or half the free memory")
        warn(f"discontinuities: {len(info['unsolved'])} linear solve(s) of "
             f"{domain.n_vertices:,} vertices did not converge in CG (relative residual "
             f"up to {max(info['unsolved']):.1e}) and were not factorized ({why}): the "
             "surface is usable but less exact (info['unsolved'])", ConvergenceWarning)


#: The discontinuity route's surface has run away from a blurred prior when the 99.9th
#: percentile of its pointwise departure from the prior (at the samples) exceeds this multiple
#: of the larger of the prior's whole depth range and the first solve's (before any
#: correction of the target; relief that the blur flattens has its range there): a blur hides
#: detail within the range, not beyond it.
#: Measured on the fusion benchmark's coarse priors (every second scene, 26 scenes at weights
#: 0.003 and 0.01, sigma 8.94 px): 0.013-1.10 (median 0.5), and none of the 102 runs of all 51
#: scenes at those weights fell back; a fresh-user check's blocky priors
#: (8 x 8 block means, sigma 4 px, a sphere and a box before a wall): 2.6 with bilinear
#: upsampling (487-2,762 pieces, error 8.8 % against 2.3 % pixel by pixel) and 44 with
#: nearest (12,144 pieces, depths from 1e-14 to 5e12). A review's ripple that the blur
#: flattens (its amplitude above the prior's range) stays below with the first solve's range.
ASTRAY = 2.0


def blur_astray(blur, centres) -> float | None:
    """The departure ratio of :data:`ASTRAY` where the surface's facet centres `centres` ran
    away from the blurred prior `blur` (:class:`BlurredPrior`), else None. A flat prior (range
    at rounding level) or a departure at rounding level is never astray."""
    p = blur.prior[blur.samples]
    if p.size == 0:
        return None
    dev = np.abs(np.nan_to_num(centres[blur.samples], nan=np.inf) - p)
    q = float(np.quantile(dev, 0.999))
    span = max(float(p.max() - p.min()), blur.first_span or 0.0)
    floor = 1e-9 * (1.0 + float(np.abs(p).max()))
    if not span > floor or not q > floor:
        return None
    ratio = q / span
    return ratio if ratio > ASTRAY else None


#: Mean angle (degrees) between a blurred prior's surface (``prior_blur``, with
#: discontinuities) and its input normals above which, where it is also more than
#: :data:`BENT_RATIO` times the angle of the normals' own cuts' surface, the prior is taken to
#: have bent the surface away from its normals (:func:`blur_bent`): it is then handled as one
#: that ran away (:data:`ASTRAY`): tried once more from the smooth surface, then compared
#: pixel by pixel, with a warning. Measured (twenty-eighth session, docs/fusion.md, "A blurred
#: prior that bends the surface"; the fusion benchmark's 51 perspective and orthographic
#: scenes, weight 0.003, a `/tmp` script): with its coarse prior blurred as said the surfaces
#: came out 0-10.2 deg from their normals, none caught (the largest, `featuretype@front` and
#: `mountain@front` at 8.6-10.2 deg, still below the smooth route's errors); with 8 x 8 block
#: means repeated and declared blurred by 4 px, 47 of the 51 fall back, most because they ran
#: away (ASTRAY), four because they came out 18-50 deg from their normals (the other four stay
#: within 0.5 deg): `tray_bottom@oblique` 48.6 deg (aligned error 1.69 mm; 0.047 once
#: caught), `max_planck@front` 33.6 (2.45; 0.083), `cheburashka@front` 18.4 (1.12; 0.063) and
#: its orthographic view 18.1 (5.46 %; 0.29). Not caught: the DiLiGenT bear with 4 x 4
#: block means declared blurred by 2 px, 5.6 deg (MADE 0.37 mm; 0.020 without the prior, 0.041
#: on the smooth route with it).
BENT = 15.0
BENT_RATIO = 3.0

#: Mean deviation (degrees) above which, under :data:`BENT` and with the same ratio to the
#: normals' own cuts, such a surface is kept but warned about. On the fusion benchmark's 51
#: scenes with their coarse prior declared blurred as it is (re-measured 2026-12-07, `/tmp`
#: script) the surfaces came out 0.1-10.2 deg from their normals (`featuretype@front`
#: orthographic 10.2, `mountain@front` 9.7 and 8.7, `featuretype@front` 8.9, 47 times its
#: own cuts' 0.19); a user's map resized bilinearly from the DiLiGenT bear's depth at every
#: 8th pixel and declared blurred by 8.9 px came out at 14.9 deg (0.23 on its own cuts) and
#: 2.73 mm off, where its samples given as such gave 0.011 mm (docs/fusion.md).
BENT_WARN = 12.0


def blur_bent(angle: float | None, free: float | None, limit: float | None = None
              ) -> float | None:
    """`angle` (the surface's mean deviation from its normals, degrees) where it exceeds
    `limit` (default :data:`BENT`) and :data:`BENT_RATIO` times `free` (the normals' own
    cuts' surface's; None: not measured), else None (also for an `angle` of None)."""
    limit = BENT if limit is None else limit
    if angle is not None and not np.isfinite(angle):  # (depths overflowed: no angle to
        return float("inf")  # measure; a review's relative prior with a blended silhouette
        # band, declared blurred, returned depths of 1e-156 to 1e9 with no word)
    if angle is not None and angle > limit and (free is None or angle > BENT_RATIO * free):
        return angle
    return None


def _blur_check(pb: dict, prior) -> None:
    """Warn when the surface returned meets a blurred prior, seen through the blur, worse than
    the first solve did: the corrections made it worse, so the prior is not blurred as
    `prior_blur` says (an exact depth map given as blurred is met by a deconvolution that
    bends the surface: the DiLiGenT bear with its own depth at sigma 4 and weight 0.003, 0.85
    mm with jumps against 0.026 without the prior). On the fusion benchmark's coarse priors
    the returned mismatch is 0.06-0.26 of the first (24 runs); a mismatch at rounding level
    (a flat view) is left alone."""
    first, last = pb.get("mismatch_first"), pb.get("mismatch")
    if first is None or last is None or not last > first:
        return
    floor = 1e-9 * (1.0 + float(np.max(np.abs(prior), initial=0.0)))
    if last > floor:
        seen = pb.get("mismatch_last")
        # (the discontinuity route's last solve, with its own normal weights, comes after the
        # updates: where they had lowered the mismatch, that solve raised it, not the sigma)
        why = (f"the prior may not be blurred by sigma {pb['sigma']:g} px" if seen is None
               or seen >= first else
               f"the updates had lowered it to {seen:.3g}, and the discontinuity route's last "
               "solve (its own normal weights) raised it again, or the prior may not be "
               f"blurred by sigma {pb['sigma']:g} px")
        warn(f"prior_blur: the surface returned meets the blurred prior worse (weighted RMS "
             f"mismatch {last:.3g}) than the first solve did ({first:.3g}): {why}; compare "
             "with another `prior_blur` (--prior-blur: about 1.1 times the factor a coarse "
             "map was enlarged by, more for a network's soft output; smaller for a sharper "
             "map; a too small one was worse on the DiLiGenT bear, an audit) or none (a "
             "pointwise prior), and without discontinuities (docs/fusion.md, 'Blurred "
             "priors')")


def fusion_terms(problem):
    """``(weight, target, fixed)`` of the problem's depth prior on the facet centres (values of
    the camera's unknown) and the components it fixes; None without a prior."""
    if not problem.has_prior:
        return None
    w, t = problem.prior_terms()
    return w, t, problem.prior_components


def lone_samples(domain, prior):
    """The facets of the pointwise prior's samples (:func:`fusion_terms`' `prior`) where no
    connected component of the domain holds more than one, else None.

    One sample in a component says nothing about its shape or its cuts: it fixes that
    component's constant (its offset; with a perspective camera its scale), which the normals
    leave free. The discontinuity route then runs without the prior and moves each sampled
    component to its sample (:func:`meet_samples`), which is where the prior's energy has its
    minimum at any weight. Run with the sample, the route left out its final weights, closed
    every pair of pieces and ran the prior's reweightings: one depth point on orthographic
    ``cow@front`` made 0.507 % of the depth range 2.334 %, and perspective
    ``max_planck@front`` 0.023 mm 0.186 mm (docs/fusion.md, "One sample per component, and
    final weights with sparse samples")."""
    from ...problem import one_sample_per_component

    facets = np.flatnonzero(prior[0] > 0)
    return facets if facets.size and one_sample_per_component(domain, prior[0]) else None


def meet_samples(domain, copies, prior, facets):
    """The facets' corner copies (m, 4) with every component that holds one of the samples
    `facets` (:func:`lone_samples`) moved as a whole (the camera's unknown offset) so that
    the sample's facet centre meets its target in `prior` (:func:`fusion_terms`)."""
    comp = domain.facet_component
    shift = np.zeros(domain.n_components)
    shift[comp[facets]] = prior[1][facets] - copies[facets].mean(axis=1)
    return copies + shift[comp][:, None]


def normal_scale(problem):
    """(m,) ``c_f``: each usable normal's cosine to the viewing ray per pixel footprint (the
    factor BiNI calls ``n~_z``), 0 where a facet has no usable normal."""
    return problem.view_cosines / problem.camera.footprint()


#: Pieces of at most this many facets are hung on their best edge to a larger piece once the
#: pieces are placed (:func:`facetlift.methods.dgp.split.absorb_small_pieces`; in at most
#: SMALL_PASSES passes): no loose quads in the mesh. Measured on the benchmark's 192 runs
#: against none: 9 errors better by 1.1-1.9 %, none worse by 1 % (docs/perspective.md).
SMALL_PIECE = 4
SMALL_PASSES = 3

#: With a pointwise prior, pieces the cuts separate that hold no sample and at least this
#: many facets and this share of them are warned about: the occlusion rule placed them, the
#: prior did not (a LiDAR user's sphere without a point on it, about 1 % of the image, came
#: out 498 mm off, silently). On the fusion benchmark's renders with 1 % and 5 % exact
#: samples such pieces are mostly rim slivers of 50-90 facets (0.2-0.6 % of the mask),
#: which 100 and 0.5 % leave out; mountain@front's 516-facet piece at 1 % is named.
UNANCHORED_MIN, UNANCHORED_SHARE = 100, 0.005

#: Share of cut facet corners above which a pointwise depth prior is said to tear the
#: discontinuity route's surface apart (a warning). On 12 perspective renders with a dense
#: prior of 1 or 3 pixel footprints of noise (mean over the scenes): 0.07-0.08 at weights
#: 0.001-0.1 with 1 footprint, 0.42 at weight 1 (2,920 mesh pieces, median); with 3
#: footprints 0.21 at 0.1 and 0.67 at 1 (17,861 pieces, the error twice the smooth route's).
#: Without a prior the benchmark's 64 renders (exact and 3-deg noise) and the three real
#: maps cut 0.0-0.21 (median 0.07; measured 2026-12-03).
TORN = 0.4

#: Largest pointwise prior weight the discontinuity route solves well (a warning above it).
#: A fresh user's table scene (480 x 612, fx 600, 1,500 exact samples on its left half):
#: mean error on the right half, without samples, 0.38 mm at weight 100, 8.29 at 1e4, 27.9
#: at 1e8 (0 CG iterations in every reweighting); with samples everywhere 0.61, 0.78 and
#: 2.32 mm. Measuring the tolerance against the samples' variation at unit weight solved
#: 1e4 (0.40 mm) but took 2,903 CG iterations (16 s) and 974 at weight 100 (113 before).
PRIOR_STRONG = 100.0

#: ... or where the cuts leave more mesh pieces (once the pieces of at most SMALL_PIECE
#: facets hang on their neighbours) than this share of the facets (and more than 50): a fresh
#: user's dense prior with 6 mm of noise (about 4 footprints) at weight 0.1 cut 26 % of the
#: corners into 3,497 pieces (12 % of the facets, no warning). Without a prior the benchmark's
#: 60 mesh renders at exact and 8-bit normals give at most 42 mesh pieces (0.2 %; 2026-12-03,
#: eighth session); every third render with 1 % exact samples at weight 100 or 1 % noisy ones
#: at 1 at most 0.62 / 0.70 %, a dense prior with 2 footprints of noise at 0.1 more than 1 % on
#: 12 of 22 (2026-12-04). The pieces before the hanging fired on clean sparse priors (a user's
#: armadillo: 1,564 pieces, 3 %; 1,140 without a prior).
TORN_PIECES = 0.01

#: Share of the facet corners cut above which the route, without a depth prior, warns that its
#: cuts may be noise: noisy normals on steeply seen surfaces read as jumps (the squares of the
#: one-sided differences the weights compare carry noise of about 2 s dtheta for a slope of s
#: footprints per pixel and an angular noise dtheta). Without a prior the benchmark's 64
#: renders at exact and 3-deg-noise normals and the three real maps cut 0.0-0.21 (2026-12-03),
#: the development benchmark's 89 scenes at exact, 8-bit and 3-deg noise (267 runs) at most
#: 0.215 (the orthographic armadillo with noise; 2026-12-05), the real maps 0.03-0.08,
#: the 36 held-out scenes of seed 2027 at exact and 3-deg noise at most 0.215 but for one: a
#: tray seen at view cosines 0.1-0.2 with 3-deg noise cut 0.363 into 602 pieces, 3.08 mm
#: against BiNI's 0.75 (discontinuity_k 2: 0.155, 0.53 mm; 1: 0.054, 0.56 mm; the smooth DGP
#: 1.26 mm); a plane at view cosine 0.15 with 3-deg noise cuts 0.46-0.47 (twenty-seventh
#: session). A warning only: nothing is changed.
CUT_MANY = 0.3
#: Below this noise (degrees, :func:`facetlift.frames.normal_noise`) the warning of
#: :data:`CUT_MANY` does not blame noisy normals (exact renders read 0.0-0.85 deg, 8-bit ones
#: about 0.1 more, 3 deg of angular noise 2.3-3.0).
NOISE_LOW = 1.0

#: The weight that did best for a dense noisy prior with discontinuities (docs/fusion.md),
#: which the tearing warning recommends.
TORN_BEST = 0.01


def place_pieces(domain, copies, bx, by, target, footprint, anchored=None,
                 hang_anchored=False, split=None, by_prior=True):
    """The facets' corner copies (m, 4) with the pieces the jumps separate placed by the
    occlusion rule (:func:`facetlift.methods.dgp.split.occlusion_offsets`): the mesh is split
    where neighbouring copies part by more than :data:`facetlift.operators.split.GAP`
    footprints, and each separated piece moved rigidly so that the smallest jump on its boundary
    is zero where that jump is at most :data:`facetlift.methods.dgp.split.TOUCH` footprints
    (without `anchored`; farther apart the pair keeps the solve's relative place). Pieces
    holding a facet of `anchored` (m,) bool (prior samples) stay where the
    solve put them: the prior decided their offset; the others are placed relative to them.
    Then the pieces of at most :data:`SMALL_PIECE` facets are hung on their larger
    neighbours: those holding a facet of `anchored` only with `hang_anchored` (a blurred
    prior, whose samples are no pointwise values: a huge pointwise weight must return the
    prior where given). Returns the copies and ``{"pieces", "mesh_pieces", "moved_pieces",
    "hung_facets", "_mesh"}`` (with `anchored` also ``"unanchored_pieces"``,
    ``"unanchored_facets"`` and, where there are such pieces, ``"unanchored_largest"``;
    ``"_mesh"``, the split of the copies returned where the hanging made one, else None, is
    for :func:`run`, which takes it out). `split`: :func:`facetlift.operators.split.from_copies`
    of `copies` where the caller formed it already (the islands' search), else formed here.
    Without `by_prior` the pieces are placed as without `anchored`, which only counts the
    pieces no sample holds (the samples of :func:`lone_samples`, which move whole components
    afterwards)."""
    from ...operators.split import GAP, from_copies
    from .split import TOUCH, absorb_small_pieces, occlusion_offsets

    mesh, values = split if split is not None else from_copies(domain, copies,
                                                               GAP * footprint)
    fixed = held_pieces = None
    if anchored is not None:
        held_pieces = np.bincount(mesh.facet_piece[anchored], minlength=mesh.n_pieces) > 0
        fixed = held_pieces if by_prior else None
    hold = anchored if by_prior else None  # (the samples that keep their small pieces)
    # (a gap of more than TOUCH footprints is left as the solve has it; with a prior every
    # pair is closed: TOUCH there made 31 of 136 sparse-prior runs better and 58 worse,
    # vessels +22 %, docs/results.md "The occlusion rule only where pieces nearly touch")
    offsets = occlusion_offsets(mesh, values, bx, by, target, scale=footprint, fixed=fixed,
                                small=SMALL_PIECE, touch=TOUCH if fixed is None else None)
    moved = int((np.abs(offsets) > GAP * footprint).sum())
    loose = {}
    if held_pieces is not None:  # (large pieces no sample holds: placed by the rule, not
        sizes = np.bincount(mesh.facet_piece, minlength=mesh.n_pieces)  # measured)
        big = ~held_pieces & (sizes >= max(UNANCHORED_MIN, UNANCHORED_SHARE * domain.n_facets))
        # (only in components that hold a sample: a component without one keeps the camera's
        # gauge, warned about on its own, and no cut separates it, a review)
        comp = domain.facet_component
        held = np.bincount(comp[anchored], minlength=domain.n_components) > 0
        lead = np.full(mesh.n_pieces, -1)
        lead[mesh.facet_piece[::-1]] = np.arange(domain.n_facets)[::-1]  # (a facet of each)
        big &= held[comp[lead]]
        first = np.flatnonzero(big)
        loose = {"unanchored_pieces": int(big.sum()), "unanchored_facets": int(sizes[big].sum())}
        if first.size:  # (a pixel of the largest, for the warning)
            k = first[np.argmax(sizes[first])]
            f = int(lead[k])
            r, c = domain.pixels
            loose["unanchored_largest"] = [int(sizes[k]), int(r[f]), int(c[f])]
    placed = (values + offsets[mesh.piece])[mesh.corners]
    # then the small pieces hung on their larger neighbours (after the placement: hung before,
    # one can bridge two pieces the placement moves apart, e.g. the DiLiGenT bear's arm)
    before = placed
    # (the placement only joins pieces: without a small piece before it, none after; the split
    # of a 2048^2 map costs 1.6 s)
    passes = SMALL_PASSES if np.bincount(mesh.facet_piece).min() <= SMALL_PIECE else 0
    after = None
    for _ in range(passes):  # (a piece hung on a small one may make it large enough)
        if after is None:
            after, _ = from_copies(domain, placed, GAP * footprint)
        # (a blurred prior's samples hold every facet, and nothing was hung: the bear with its
        # own depth blurred by 4 px, 547 pieces, MADE 0.853 mm; hung 99 pieces, 0.727; on 9
        # coarse blurred priors better or within 0.5 %)
        hung = absorb_small_pieces(after, placed, SMALL_PIECE, GAP * footprint,
                                   None if hang_anchored else hold, with_mesh=True)
        if hung is None:
            break
        placed, after = hung
    # (the pieces left once the small ones hang on their neighbours: the mesh's)
    left = mesh.n_pieces if after is None else after.n_pieces
    # (the split of the copies returned, where the hanging made one, under "_mesh": the
    # surface's mesh, not split again (1.6 s at 2048^2); :func:`run` takes it out of the info)
    return placed, {"pieces": mesh.n_pieces, "mesh_pieces": left, "moved_pieces": moved,
                    "hung_facets": int(np.any(placed != before, axis=1).sum()), **loose,
                    "_mesh": after}
