"""Discontinuity-preserving DGP: facets with their own corners, glued by bilateral weights.

The smooth DGP fixed point (:mod:`facetlift.methods.dgp.fixed_point`) minimises, over the
vertex values ``z`` (height, or log-depth for a perspective camera), ``sum_f ||P C_f z - b_f||^2``:
every facet is shaped by its own target and all facets that share a vertex share its value.
Across an occlusion boundary that sharing is wrong: the two sides are different surfaces.

Formulation
    Every facet ``f`` gets its own copy ``y_f`` (4,) of its corner values, shaped by its
    target, and each copy is glued to the shared vertex with a weight ``w_fk >= 0``::

        E(z, y) = sum_f ||P y_f - b_f||^2 + sum_f sum_k w_fk (y_f[k] - z[c(f, k)])^2.

    With every ``w = 1`` the minimiser over ``y`` reproduces the smooth DGP solution exactly
    (the facet blocks become the smooth blocks scaled by 1/2), and for integrable normals every
    copy meets its vertex whatever the weights, so a surface without jumps comes out as the
    smooth DGP surface. A corner with ``w = 0`` is cut loose: its facet keeps its own plane and
    no longer pulls on the vertex, so a jump is cut without bending either side.

Bilateral weights (after BiNI, Cao et al., ECCV 2022, transposed to facets)
    From the current facet centre values ``u_f`` (means of the own copies), every facet compares
    the one-sided differences to its two neighbours along each axis, scaled by its normal
    (``c_f`` = the cosine to the viewing ray per pixel footprint, BiNI's ``n~_z``), along x::

        omega_+x = sigmoid(k (D_-x^2 - D_+x^2)),   omega_-x = 1 - omega_+x,
        D_+-x = c_f (u_(f +- x) - u_f),

    and the same along y: the side with the larger difference is taken as discontinuous. A
    corner lies on one x-side and one y-side of its facet; its glue weight is
    ``w = 4 omega_x omega_y`` (1 where both sides agree). A missing neighbour (mask border,
    facet without a usable normal) gives no evidence: its difference counts as zero, as the
    empty rows of BiNI's one-sided differences do at the mask border. ``k``
    (``discontinuity_k``) is in squared pixel footprints, the same for orthographic and
    perspective input; for normals noisier than :data:`NOISE_K` degrees (read from their
    curl) the route uses ``k * NOISE_K / noise``, for a blurred map, whose occlusion
    boundaries turn over several pixels, ``k * SOFT_K`` (:data:`SOFT_K`, :func:`soft_edges`;
    :func:`sharpness`, ``info["discontinuity_k"]``). Its default and the evidence compared (plain
    differences, :data:`EVIDENCE`) were chosen on the discontinuity benchmark as a whole
    (``facetlift bench --experiments discontinuities``; docs/results.md, "Discontinuities").

Iteration and stopping rule
    Iteratively reweighted least squares from the smooth solution. The bilateral weights do
    not come from an energy that the iteration decreases, and on 30-80 % of the benchmark's
    scenes a few corners on ambiguous edges flip back and forth for ever (the cap was the usual
    exit). After ``n`` free reweightings (:data:`SETTLE_AFTER`; :data:`PRIOR_SETTLE_AFTER`
    with a depth prior in the system) every weight step is therefore scaled by
    ``DECAY ** (iteration - n)``: the cuts form freely first, then the weights settle. The
    loop stops when no corner weight moves by more than ``tol`` (``discontinuity_tol``,
    weights are in [0, 4]); ``discontinuity_iter`` is a cap, reported as ``converged=False``
    when hit.

    Crack growth: where a jump fades to zero along its boundary (one surface passes behind
    another, the sides of a tent) its cut advances about one pixel per reweighting, from where
    the jump is high; the settling freezes the tip short of the jump's end, and the rest of
    the jump bends whole regions. Once the weights have settled, a growth phase therefore
    lets the cuts only grow (:data:`GROW`): at the corners of every facet that has a cut
    corner or a 4-neighbour with one, a weight whose own bilateral weight is lower by more
    than ``tol`` is set to it, nothing else moves, and the system is solved again; it stops
    when no such corner is left. Weights only fall, so it ends (a corner can fall by more than
    ``tol`` at most ``4 / tol`` times); its reweightings count in ``iterations`` and against
    the cap, ``info["grown"]`` says how many there were. Not with a depth prior, which decides
    the jump heights itself (a sparse one's reweightings start from the prior-free cuts, growth
    included: :data:`facetlift.methods.dgp.PRIOR_CUTS_FIRST`).

    ``info["unsettled_corners"]`` is the fraction of corners whose own bilateral weight still
    differs from the settled one by more than :data:`CUT` (the ambiguous edges the settling
    decided). Each reweighting is one preconditioned CG solve warm-started from the previous
    vertex values.

Final weights
    After the reweightings (settled, or stopped by the cap), the last solve weighs every
    facet's normal term by its view cosine squared (:data:`FINAL_COS_POWER`, BiNI's
    weighting of the slopes; times the confidence, if any): steep facets, whose slopes are
    least reliable and whose planes fit a curved surface worst, no longer bend whole smooth
    regions. The ``energy`` trace is the reweightings' (uniform normal weights, times the
    confidence where one is given). With a sparse pointwise depth prior too (on at most a
    quarter of the facets, :func:`facetlift.methods.dgp.cuts_first`): each sample's weight is
    then scaled as its facet's normal term, which keeps their ratio (``prior_weight``'s
    units), and both halves of the prior (``PRIOR_OWN``) stay; not with a dense one compared
    pixel by pixel. With a blurred one (``prior_blur``) yes: the last solve then
    keeps the prior's half on the glued vertices and drops the half on the facets' own copies
    (``PRIOR_OWN``) with the uniform normal weights it was paired with (measured that way on
    the fusion benchmark; keeping both halves lowered the blurred mismatch but raised the
    error of a test sphere from 0.45 to 0.74). ``info["prior_blur"]["mismatch"]`` is measured
    on the surface returned.

Seeded by the curl (``discontinuity_seed``, on by default since the forty-sixth session)
    From the smooth surface a jump is seen only where the two sides' differences differ: a
    cliff between two surfaces of about the same slope (a sheet lying over another, a rim
    seen from the front) bends the smooth surface over whole regions and is never cut (the
    analytic ``fold``: 7.2 % error, as BiNI's, against 0.02 % with its jump cut). Its normals
    are not integrable along it, though: a jump whose height changes along its line leaves
    that change as curl there. With ``discontinuity_seed`` the first solve starts from corner
    weights lowered where the curl (:func:`curl_seed`: summed over 3 x 3 vertices, so that a
    crease's sampling curl cancels, scaled to an angle and compared with the larger of
    :data:`SEED_TAU` and :data:`SEED_NOISE` times the normals' noise) says so, and not where
    the normals around differ so much that the smooth start sees the jump anyway and a
    crease's mixed pixels leave curl (:data:`SEED_SPREAD`); the reweightings then keep or
    glue back those cuts as from the smooth start (``info["seeded_corners"]``). A jump of
    constant height leaves no curl and is not seeded. Measured on the development benchmark
    and four held-out sets (docs/results.md, "Seeded by the curl" and "Seeded by the curl,
    not at creases"): without that gate better on the first as a whole and mixed on the
    second (off by default then); with it better on both (on by default).

Grazing normals
    The route is run (``facetlift.integrate``) with a grazing threshold of cos 87.5 deg on
    every camera (``MethodInfo.jump_grazing``, ``facetlift.methods.JUMP_GRAZING``; the paper's
    cos 85 deg until 2026-12-05): a jump that fades out ends in nearly
    edge-on normals, whose slopes would bridge it; as missing samples they give no evidence
    and no target, and the cut can close (docs/results.md, "Discontinuities: the grazing rule").

Steep planes under noise
    Where the normals are noisy (their curl reads noise, :func:`facetlift.frames.normal_noise`)
    the evidence of a steep facet carries a noise growing with its slope, and a plane seen
    nearly edge-on was cut at random into hundreds of pieces. On facets whose normals scatter
    about their local mean no more than that noise does, the sharpness is capped so that the
    noise of their evidence stays bounded (:func:`steep_planar`, :data:`STEEP_TAU`;
    ``info["steep_planar"]`` is the share of the facets with a normal that were capped). Exact
    normals read almost no noise and are not capped.

Pieces without glue
    A region whose every boundary corner is cut loose would be free to float; a tiny floor on
    the weights (``FLOOR``) keeps it attached where its copies meet the vertices best.

The returned facet values are the means of the facets' own copies (sharp at a jump); vertex
values are the glued ``z``; the per-corner weights tell where the mesh is cut.
"""

from __future__ import annotations

import functools
import itertools
import logging
import math
import time
import weakref

import numpy as np
import scipy.sparse as sp

from ... import linalg
from ..._progress import announce
from ...conventions import CORNER_OFFSETS
from ...errors import SolverError
from ...linalg.amg import balanced, block_aggregates, hierarchy, refresh, vcycle
from ...linalg.dense import dot, norm, rowwise
from ...memory import factorization_fits
from ...operators.stencil import (
    CENTRE_BLOCK,
    E_TWIST,
    E_X,
    E_Y,
    prior_form,
    scatter_corners,
)

log = logging.getLogger(__name__)

#: Default for ``discontinuity_k`` (squared pixel footprints; see the module docstring).
DEFAULT_K = 4.0

#: Angular noise of the normals (degrees, read from their curl:
#: :func:`facetlift.frames.normal_noise`) up to which ``discontinuity_k`` applies as given;
#: noisier normals get ``k * NOISE_K / noise`` (:func:`sharpness`). The argument of the
#: bilateral sigmoid, ``k (D_-^2 - D_+^2) = k (D_- - D_+)(D_- + D_+)``, carries a noise about
#: proportional to the normals' (the cross term ``2 D e`` dominates), so a decisiveness that
#: falls as ``1 / noise`` keeps that noise's share of it fixed; below ``NOISE_K`` the spread of
#: the evidence is the surfaces' own, for which the default was chosen. 4 deg lies above every
#: condition the default ``k`` was chosen on: the normals' noise read 0.0-2.9 deg on the
#: development benchmark's exact, 8-bit, outlier and smooth3 renders and 2.5-3.4 deg at 3 deg
#: of noise (one orthographic render 4.6). Measured (thirty-second session, docs/results.md
#: "Six degrees of noise"; one A/B each against ``k`` as given, 89 development scenes): at 6
#: deg of noise (read 5.0-7.3) 44 better / 26 worse by more than 1 %, mean group ratio 0.941
#: (rooms 4.746 -> 3.671 mm, wide 1.719 -> 1.582, orthographic 7.546 -> 7.258 %; vessels 11.98
#: -> 12.12 mm), at 9 deg 64 / 17, 0.799 (perspective 2.901 -> 2.560 mm, rooms 8.79 -> 4.29,
#: tables 10.69 -> 7.57), at 3 deg 1 / 0; ``k = 2`` throughout had been 35 / 176 at exact,
#: 3-deg and blurred normals, and at 6 deg 43 / 33 (0.967). ``k`` falling as ``1 / noise^2``
#: instead (from 4 deg) was worse at 6 deg (0.979) and 9 deg (0.985: perspective +5 %, wide
#: +16 %); the held-out sets of seeds 9091 and 777001 at 6 deg: 2.373 -> 1.997 mm and 2.826
#: -> 2.553 (BiNI 1.664 and 2.657), 27 / 9 and 25 / 10 scenes better.
NOISE_K = 4.0

#: Soft occlusion boundaries: a blurred normal map (a network's estimate, a map resampled or
#: filtered) turns over a jump across several pixels, where a sharp map steps in one. The
#: bilateral weights need a sharper sigmoid to cut such a ramp: ``discontinuity_k`` times
#: ``SOFT_K`` where fewer than :data:`SOFT_SHARE` of the map's strong changes (an angle above
#: :data:`SOFT_ANGLE` between 4-neighbours, at least :data:`SOFT_MIN` of them) are one-pixel
#: steps (:data:`SOFT_PEAK` times both changes beside them; :func:`soft_edges`,
#: ``info["soft_edges"]``), and the noise read from the curl is below :data:`NOISE_K`.
#: Measured on the development benchmark's renders (thirty-seventh session, docs/results.md
#: "Discontinuities: soft occlusion boundaries told from the map"): the share is 0.0175-1.0
#: on every exact, 8-bit, noisy, smooth3, outlier and photometric-stereo render with enough
#: strong changes, 0.000-0.019 blurred by 1.5 px (75 of 77 below 0.01) and 0.000 by 3 px; the
#: DiLiGenT bear 0.048, BiNI's human map 0.080, its tent 1.0. With the factor 2 (``k`` 8, the
#: twentieth session's sweep) on the blurred renders: 107 better / 18 worse by more than 1 % of
#: 178, mean group ratio 0.939 (perspective blur1.5 3.050 -> 2.847 mm, BiNI 3.150); a held-out
#: set drawn before the change (seed 682732) blur1.5 2.548 -> 2.242 mm (BiNI 2.522), blur3
#: 3.189 -> 2.904.
#: Factors 1.5 and 3 against 2 on the same renders: mean group ratios 1.018 and 1.004 (3: large
#: single failures, goblet@e50 10.15 -> 17.61 mm).
#: A sharp map of a smooth, strongly curved surface can read as blurred (the analytic "face":
#: 0.0; a review measured 16 % more error there with the factor, on a small error).
SOFT_K = 2.0
#: See :data:`SOFT_K`.
SOFT_SHARE = 0.01
#: See :data:`SOFT_K` (degrees).
SOFT_ANGLE = 10.0
#: See :data:`SOFT_K`.
SOFT_PEAK = 2.0
#: See :data:`SOFT_K`.
SOFT_MIN = 100

#: A plane seen nearly edge-on through noisy normals falls apart into hundreds of pieces: on
#: a facet of slope ``t`` (footprints per pixel) the bilateral argument's two squared
#: differences, both about ``(c t)^2``, carry a noise of about ``2 sqrt(2) k t sigma``
#: (``sigma`` the normals' angular noise in radians), far beyond the sigmoid's width where
#: ``t`` is large, and the reweightings cut at random (docs/results.md, "Stronger blur,
#: smooth errors and a fresh held-out set": a tray seen at view cosine 0.1-0.2 with 3 deg of
#: noise, 4.87 mm against BiNI's 0.90). Where the normals scatter about their own mean over a
#: (2 :data:`PLANAR_RADIUS` + 1)^2 window by a mean angle of at most :data:`PLANAR` times the
#: noise read from the curl (a plane, or a surface whose normals turn evenly: the window's mean
#: follows an even turn), each facet's sharpness is capped at ``k STEEP_TAU / (t sigma)``
#: (:func:`steep_planar`), so that its evidence's noise stays about ``2 sqrt(2) STEEP_TAU k``:
#: a plane's noisy cuts no longer form. A band toward a silhouette, whose normals turn ever
#: faster, mostly keeps the full sharpness (the back of a cow seen from behind: capped without
#: this test, it bridged the jump to the head, 1.35 -> 10.0 mm); the test tells them apart
#: only partly (a cylinder's band on 24 x 20 pixels: about a quarter of the share of a
#: plane's facets capped, tests/test_discontinuities.py). Measured (thirty-third session,
#: docs/results.md "Steep planes under noise"): the development benchmark's 89 scenes at exact,
#: 3 and 6 deg of noise (267 runs) 42 better / 32 worse by more than 1 %, mean group ratio
#: 1.002 (exact normals unchanged); at 8-bit, blurred and smooth3 normals (267 runs) 2 / 1;
#: held-out sets with 3 deg of noise (seed 1206) 2.557 -> 2.304 mm (BiNI 2.421), with 6 deg
#: (seeds 9091, 777001, 4711) 1.997 / 2.553 / 3.264 -> 1.287 / 2.438 / 3.145 (BiNI 1.664 /
#: 2.657 / 3.004), and a set drawn after the choice (seed 2468) 3.157 -> 2.982 mm at 3 deg and
#: 3.733 -> 3.226 at 6 deg (BiNI 3.288 and 3.437), 28 scene-conditions better, 13 worse. The
#: cap without the planarity test lost (3 deg: 28 / 48, perspective 2.33 -> 2.64 mm), and on
#: five probe scenes so did 0.25 and 0.5, a cap kept to the interior of steep regions, and one
#: kept to facets steeper than 3 or 4 footprints per pixel.
STEEP_TAU = 0.1
#: See :data:`STEEP_TAU`: the largest ratio of a facet's local normal spread to the noise read
#: from the curl at which it counts as planar (the held-out trays' steep facets: median 0.75
#: with 3 deg of noise; the cow's back seen from behind: 1.1).
PLANAR = 0.9
#: See :data:`STEEP_TAU`: half the window's width (pixels) of the planarity test.
PLANAR_RADIUS = 2

#: Default cap on the reweightings, the growth phase's included (a safety net: the
#: weight-change rule and the end of the growth phase normally come first).
DEFAULT_ITER = 200

#: Ruge-Stueben interpolation of the reweightings' multigrid hierarchies. "direct" builds
#: faster than "classical" with nearly the same CG iterations on the glued systems: 6-9 % less
#: time on the four timing objects (interleaved runs), no error on the 72 perspective benchmark
#: runs changed by 1 % (docs/benchmarks.md).
INTERPOLATION = "direct"

#: Default largest corner-weight change below which the reweighting has converged (weights are
#: in [0, 4]). Chosen on the benchmark's perspective scenes (exact and 3-deg noise, 72 runs):
#: against 0.01, 0.05 changed one error by more than 1 % (fandisk@oblique with noise, +6.7 %;
#: means +0.04 % / +0.2 %), with 26 reweightings (median) instead of 35-36; 0.2 changed 15 of
#: 72 (12 for the worse) with 18 (all before the growth phase, which takes steps above it).
DEFAULT_TOL = 0.05

#: Smallest glue weight: keeps pieces whose boundary is cut everywhere attached.
FLOOR = 1e-6

#: Corner weights below this count as cut (the fraction reported in ``info``).
CUT = 0.5

#: What the bilateral weights compare: "difference" (one-sided differences, BiNI's choice) or
#: "residual" (differences minus the normals' trapezoid prediction). Chosen on the benchmark:
#: "residual" was better on the DiLiGenT bear alone but lost to BiNI on 46 to 57 of 72
#: half-resolution perspective scene-conditions, where "difference" won on 46 (k = 4); a
#: third variant, differences minus the facet's own slope (exact on curved jump-free
#: surfaces), was worse than "difference" on 33 of 48 (docs/results.md).
EVIDENCE = "difference"

#: Free reweightings before the weight steps decay (lets the cuts form first), without a
#: depth prior in the system (the prior-free route, and the prior-free first pass of a sparse
#: or blurred prior's run). 20 since the thirty-first session: on the development benchmark's
#: 89 scenes at exact, 3-deg-noise and blur1.5 normals (267 runs, one A/B against 10) 133
#: errors better and 22 worse by more than 1 %, 17 of 18 group-condition means lower
#: (perspective exact 2.429 -> 2.316 mm, noise 2.349 -> 2.328, blur 3.186 -> 3.050; room blur
#: 5.682 -> 5.216; tabletop exact 7.251 -> 7.062; orthographic noise 6.819 -> 6.877 %, the one
#: higher), 8-bit 39 / 7; 1.05-1.2x the time (the four timing objects 0.94-1.27x, docs/
#: benchmarks.md); a fresh held-out set (seed 8086, exact, 8-bit, noise and blur, 144 runs)
#: 75 / 18, every mean lower, and a second one (seed 9091) ahead of BiNI in all five
#: conditions (docs/results.md, "Slower settling");
#: the DiLiGenT bear 0.079 -> 0.117 mm (issue 9's 0.10 missed; 15, 25 and 30: 0.115-0.118),
#: BiNI's tent 2.47 -> 1.15 deg, the human map 2.61 -> 2.51 deg. 30 (against 20, 191 runs: 48
#: better / 18 worse, mean group ratio 0.993, blur 1-2 % lower) took more time and was worse
#: with noise (wide +2.5 %). Faster settling had lost before (6 and 5:
#: docs/benchmarks.md), and 30 had lost on 24 perspective scenes before the grazing rule and
#: the crack growth (DiLiGenT bear 0.382 -> 0.317 mm then, means 3.344 -> 3.393 mm).
SETTLE_AFTER = 20

#: The same with a depth prior in the system (a dense prior's reweightings, a sparse or
#: blurred prior's second pass): 10, as it was measured on the fusion benchmark; 20 was not
#: measured there.
PRIOR_SETTLE_AFTER = 10

#: Factor by which every later weight step shrinks per reweighting (0.85: the steps fall
#: below 1 % of their size about 28 reweightings later).
DECAY = 0.85

#: Crack growth after the settling (module docstring). Measured on the benchmark's 59 cached
#: renders at exact and 3-deg-noise normals (one interleaved A/B, 120 runs): better by more
#: than 1 % on 20 runs, worse on 5 (perspective exact 2.505 -> 2.482 mm, 8 / 0; 3-deg noise
#: 2.447 -> 2.450 mm, 5 / 5; wide 1.725 -> 1.722 and 1.703 -> 1.693 mm; orthographic 5.422
#: -> 5.415 % and 5.630 -> 5.632 %); a median of 4 growth reweightings (0 on 23 runs, at
#: most 45, featuretype@left), median time ratio 1.01-1.10. BiNI's tent (a jump fading to
#: zero along the tent's sides, 128^2): mean deviation from the input normals 6.57 -> 2.61
#: deg in 48 growth reweightings (BiNI 2.34); the human map 2.84 -> 2.76 deg; the DiLiGenT
#: bear unchanged (one growth reweighting). Not with a depth prior (it decides the jump
#: heights): on every 2nd cached render with 1 % exact or noisy samples and the coarse prior
#: (72 runs) no error moved by more than 1 %, and the time rose (median ratios 1.06, 1.12 and
#: 1.91 with the coarse prior).
GROW = True

#: Power of the view cosine that weighs each facet's normal term in the final solve, once the
#: cuts are settled (0: uniform, the paper's DGP energy). The residual of BiNI's equations is
#: the slope residual times the normal's z component, so BiNI weighs a slope by ``cos^2``; a
#: normal's angular error grows its slope's error by ``1 / cos^2``, and a steep facet's plane
#: fits a curved surface worst. Uniformly weighted, those steep rim facets bend whole smooth
#: regions: an analytic sphere (r 60 mm at 1.5 m, DiLiGenT camera) came out at 0.016 mm MADE
#: (BiNI 0.008, with a four-fold pattern over the whole disc), 0.011 mm with ``cos^2``.
#: Only the final solve: weighting the reweightings too moved the cuts (perspective mean
#: 2.482 -> 2.606 mm, 19 wins / 13 losses against BiNI instead of 22 / 10). Measured on the
#: benchmark's 59 cached renders at exact and 3-deg-noise normals (one interleaved A/B, 120
#: runs), against uniform: wins / losses against BiNI perspective 22 / 10 -> 26 / 6 (exact),
#: 20 / 13 -> 26 / 7 (noise), wide 4 / 7 -> 7 / 4 and 5 / 6 -> 9 / 3, orthographic 7 / 3 -> 8 /
#: 2; means perspective 2.482 -> 2.488 and 2.450 -> 2.462 mm, wide 1.722 -> 1.719 and 1.693 ->
#: 1.610 mm, orthographic 5.415 -> 5.286 and 5.632 -> 5.250 %; on the 12 nearly jump-free
#: perspective scenes (BiNI below 0.3 mm) 0.098 -> 0.067 mm exact (BiNI 0.100; 11 wins / 1
#: loss) and 0.124 -> 0.087 mm with noise (BiNI 0.125; 8 / 2). Power 1: means 2.470 / 2.361
#: mm but 24 / 9 and 22 / 10 wins, nearly jump-free 0.082 mm. Median time +8 %. With a
#: blurred prior (``prior_blur``) too, and with a sparse pointwise one (the prior's
#: reweightings start from the normals' cuts, :func:`facetlift.methods.dgp.cuts_first`;
#: each sample's weight in the final solve scaled as its facet's normal term, so that
#: ``prior_weight`` keeps its units); not with a dense pointwise one (docs/fusion.md, "One
#: sample per component, and final weights with sparse samples").
FINAL_COS_POWER = 2

#: Facets per block of the energy trace's sums (a diagnostic, ``info["energy"]``): its
#: temporaries (about 1 MB) stay in the cache, where whole (m, 4) ones were page-faulted in
#: anew every reweighting (2048^2 full square, a library call, profiled: 2.47 -> 0.46 s over
#: 10 reweightings; a fresh 4M-facet call in a microbenchmark 1.13 -> 0.15 s, warm 0.11 ->
#: 0.09 s).
ENERGY_BLOCK = 1 << 14

#: Multigrid policy of the reweightings' solves. The hierarchy of the previous reweighting is
#: reused as it is while no corner weight moves by more than :data:`REUSE_STEP`; when one
#: does, its coarse operators are recomputed for the new system (a Galerkin refresh, about a
#: fifth of a build: the bear 8 builds -> 1), and also after a solve that took more than
#: :data:`REFRESH_ITS` CG iterations (small steps add up: a hierarchy several reweightings old
#: took 12-30 iterations where a refreshed one takes 1-5); a new hierarchy is built after a
#: CG solve that took more than :data:`REUSE_ITS` iterations, and from then on the block
#: coarse space of :data:`COARSE_BLOCK` is added (below).
REUSE_ITS = 20
REUSE_STEP = 0.5

#: Refresh after a solve slower than this (above). On the benchmark's 64 renders at exact,
#: 8-bit and 3-deg-noise normals (192 runs, one interleaved A/B against no such refresh):
#: 3 errors moved by more than 1 % (one 11 % better, two 1.4 % worse; every group mean within
#: 0.1 %), 192 / 192 converged, CG iterations fewer, median time ratio 0.98 (the sum 155.6 ->
#: 151.0 s); the timing object armadillo@front (49k pixels) 2.7 -> 1.7-1.8 s: without it three
#: builds and the block coarse space, with it one build and no block space (docs/benchmarks.md:
#: 2.71 -> 1.84 s beside BiNI). Before the polish's trial a Galerkin refresh alone did not
#: make the trial finish on any of the four timing objects; a reinterpolating one is taken
#: there (:data:`POLISH_REFRESH`).
REFRESH_ITS = 8

#: A refresh after a slow solve (:data:`REFRESH_ITS`) also recomputes the interpolation from the new
#: matrix (direct interpolation on each level's old coarse points and pattern,
#: :func:`facetlift.linalg.amg.refresh`): new cuts make the old interpolation average across them,
#: and a Galerkin refresh alone left 8-10 CG iterations per reweighting on maps with long jumps,
#: where a new hierarchy takes about 3 but costs a Ruge-Stueben splitting each time. Measured
#: (2026-12-03, fifth session; interleaved A/B, 2-core VM): the analytic ``occluder`` at 512^2
#: 13.2-15.0 -> 9.0-9.5 s (CG iterations 325 -> 165, error 11.9636 -> 11.9644 %), at 1024^2 70.9 ->
#: 63.7 s (417 -> 218 iterations over 42 -> 60 reweightings, the path moved; 12.200 -> 12.194 %;
#: 61-66 s in later runs); the timing objects: bear, bunny and max_planck on the same paths,
#: armadillo on another (35 -> 41 reweightings, CG 185 -> 169, 1.04-1.27x the time in paired runs
#: with POLISH_REFRESH, docs/benchmarks.md); the benchmark's 64 renders at exact and 3-deg-noise
#: normals (128 runs): median time 1.00x, CG iterations -3 %, 12 errors better and 10 worse by more
#: than 1 % (group means within 0.2 %), 128 / 128 converged; with a sparse prior (18 scenes, 1 %
#: exact or noisy samples) no change (CG iterations within 3 %). Recomputing it at every refresh was
#: faster still on the occluder (8.4 s) but slower on the objects (bunny 2.39 -> 2.67 s).
REINTERPOLATE = True

#: Before the final polish's trial (:data:`POLISH_TRIAL`) the hierarchy is refreshed for the
#: final system (unless it is of that system already), its interpolation recomputed where
#: :data:`REINTERPOLATE` says so: the final weights
#: (:data:`FINAL_COS_POWER`) change every facet's normal term, and on the reweightings' old
#: hierarchy the trial had failed on every object and large map, leaving a factorization
#: (or a new hierarchy above :data:`DIRECT_POLISH`). Measured (2026-12-03, fifth session,
#: interleaved A/B): the analytic ``occluder`` at 1024^2 71.0 -> 57.8 s (the trial finishes
#: in 20 iterations instead of a factorization of 1 M unknowns, the same error to 5 digits),
#: at 512^2 10.7 -> 9.1 s (7 iterations); the four timing objects 0.99x (their trial still
#: fails: factorized); the benchmark's renders at exact and 3-deg-noise normals (64 runs)
#: every error the same to 2.3e-6 relative, median time 1.00-1.01x.
POLISH_REFRESH = True

#: Side (vertices) of the square blocks whose piecewise constants are solved exactly in every
#: preconditioning step once CG has been slow (:func:`facetlift.linalg.amg.balanced`). The
#: Ruge-Stueben hierarchy resolves the smooth error of these glued systems slowly: whole
#: regions' offsets behind rim facets without a normal (CG 821 -> 389 iterations on the
#: benchmark's spot@front, 375 -> 239 on max_planck@left), and at the reweightings' loose
#: tolerance that error steered the weights (max_planck@oblique with noise: 0.54 mm with the
#: refreshed hierarchy alone, 0.28 with the blocks, 0.29 with every solve to 1e-5). The
#: block space is formed with the hierarchy's finest matrix and kept while the hierarchy is
#: (it was formed anew for every reweighting's system): on the benchmark's 64 renders at exact,
#: 8-bit and 3-deg-noise normals (192 runs, one interleaved A/B) no error moved by 1 %, CG
#: iterations 24,716 -> 24,727, median time ratio 0.99; bunny@front 2.12 -> 2.02 s and
#: max_planck@front 2.53 -> 2.40 s (17 of 31 formations saved), the others never use it.
COARSE_BLOCK = 8

#: Relative CG residual of the reweightings' solves (the weights move on anyway); the final
#: weights are solved once more to ``cg_rtol``. Against 1e-6 throughout, on 72 runs of the
#: benchmark's first 10 scenes: errors within -6.5 / +1.9 % (mean ratio 0.999), median time
#: -27 %, orthographic renders 3-5x faster.
LOOSE_RTOL = 1e-4

#: CG iterations the final polish (to ``cg_rtol``) may take on the reweightings' hierarchy
#: before it is continued by a factorization or on a new hierarchy of the final system; where
#: the average rate of these says that as many again finish it, CG goes on there (at most
#: twice as many; the 2048^2 disk: 10 + 3 iterations, where a new hierarchy cost 3 s).
POLISH_TRIAL = 10

#: Most vertices for which the final polish skips the trial above and factorizes at once
#: where the reweightings needed the block coarse space (:data:`COARSE_BLOCK`: a solve took
#: more than :data:`REUSE_ITS` iterations) and the factorization is affordable. On the
#: benchmark's 59 renders and 4 analytic scenes at exact, 8-bit and 3-deg-noise normals (189
#: runs, 2026-12-04) the trial failed on every one of the 49 runs that had turned the block
#: space on (and finished on 48 of the other 140), and on all 31 such runs of its renders at
#: 1024 x 1224 (up to 260k pixels; it finished on 8 of the other 17): its refresh and ten
#: CG iterations were lost there (max_planck@front 2.43-2.49 -> 2.28-2.29 s, bunny@front
#: about 0.03 s of 2.2 s). Where the trial fails, the factorization is the one that followed
#: it: the same surface (where it would have finished, the factorized one, within the
#: tolerance of it). Larger systems keep the trial, where a factorization costs seconds.
DIRECT_FIRST = 300_000

#: Most vertices for which a system CG does not solve in time, above all the final polish when
#: the trial above does not converge, is factorized (:func:`_factorized`) instead of solved by
#: CG on a new hierarchy, where the factorization fits in memory (:func:`_affordable`). The
#: final systems, with their cuts and rim weights, are the hardest of the loop (a handful of
#: near-null modes: the offsets and tilts of regions that cuts nearly separate): on the 41-64k
#: pixel timing objects CG on a new Ruge-Stueben hierarchy took 99-122 iterations from 5e-3
#: (0.4-0.8 s with the build) against a 0.26-0.40 s factorization; on a 1024 x 1224 render of
#: the bunny (258k vertices) 699 iterations (12 s; the block coarse space or classical
#: interpolation changed that by 10 %) against SuperLU's 2.5 s; on a 2048 x 2448 one (1.03 M
#: vertices) 1,956 iterations (170 s) against 21 s, with 1.5 GB more at the peak (minimum-
#: degree order; nested dissection on the grid, :mod:`facetlift.linalg.ordering`, made such
#: factorizations 2.5-3.5x faster since). On the DiLiGenT bear upsampled 6x (1.43 M pixels;
#: the limit was 1 M then) the whole job took 226 s with CG on a new hierarchy (152
#: iterations, converged) and 182 s factorized, the peak 2.1 -> 3.7 GB. Where it is not
#: factorized and CG on a new hierarchy stops at its iteration cap, the better of its iterate
#: and its start is kept (``info["unsolved"]``, and a warning); before, a solve CG could not
#: finish above 250k vertices raised an error (docs/benchmarks.md).
DIRECT_POLISH = 2_000_000

#: Least share of the centred right-hand side in the CG tolerance's reference with a prior
#: (:func:`_rhs_scale`). Measured on 7 scenes of the fusion benchmark (1 % samples, exact at
#: weight 100 and noisy at weight 1) against the normals' part alone (floored at 1e-6 of the
#: whole): errors within -4.3 / +2.1 % (exact), -1.5 / +0.3 % (noisy), with 0.16-0.28x the CG
#: iterations on exact samples (flat views: featuretype@front 1,900 -> 303, plateau 1,108 ->
#: 132, steps 1,083 -> 145; cow@oblique 385 -> 88). The centred right-hand side alone was
#: faster still but worse by 3-17 % on 9 of 12 other scenes with exact samples.
RHS_SHARE = 0.1

#: Smallest tolerance factor of :func:`_rhs_scale` (a residual of 1e-6 * 1e-6 of the whole
#: right-hand side is still well above rounding).
RHS_SCALE_FLOOR = 1e-6

#: Forcing term of the reweightings' solves: each stops once its residual is below this
#: fraction of the residual it started from (the previous vertex values in the new system),
#: if that comes before ``max(cg_rtol, LOOSE_RTOL)`` (None: that tolerance alone). The weights move
#: on after every solve, so an early one need not be tight; the warm starts carry the rest
#: into the later ones and the polish. On the benchmark's 48 pinhole scenes (exact and 3-deg
#: noise, 96 runs, one interleaved run): CG iterations 24,096 -> 16,270, median time ratio
#: 0.78-0.80, mean MADE 2.470 -> 2.476 mm (perspective) and 1.789 -> 1.714 mm (wide), 15 runs
#: better and 20 worse by more than 1 % (the reweighting path moves; largest +13 %, -28 %);
#: 0.3 was as fast but worse (perspective mean 2.624 mm, 26 worse). Orthographic renders (11
#: scenes): exact 5.420 -> 5.422 %, 3-deg noise 5.297 -> 5.630 % (4 worse, 1 better), 0.8x the
#: time. Not used with a depth prior: on the fusion benchmark's priors (every 2nd render, 24
#: scenes) it saved 12-28 % of the time but the mean error with 1 % noisy samples rose 5.6 %
#: (perspective) and 10 % (orthographic), with exact samples -0.5 % / +11 %.
FORCING = 0.1

#: Forcing term of the reweightings' solves with a depth prior no stronger than the normals
#: (its largest sample weight at most the largest weight of a usable normal: ``prior_weight``
#: <= 1 without a confidence map) and compared pixel by pixel; None for a stronger or a blurred
#: prior (:data:`FORCING` is not used with any prior). Measured on 2026-12-03 against tight
#: solves (one interleaved A/B on the fusion benchmark's scenes, perspective and
#: orthographic): 1 % noisy samples at weight 1, 35 scenes: median time 0.77x, CG iterations
#: 9,365 -> 5,457, errors better by more than 1 % on 9 and worse on 5 (mean ratio 0.992,
#: largest 1.039); the coarse dense prior at weight 0.01, 26 scenes: 0.78x, no error moved by
#: 0.1 %. Not used where it was worse: 1 % exact samples at weight 100 (0.89x the time, but 12
#: errors worse and 5 better, mean +1.5 %, largest +12 %), the blurred coarse prior (0.74x,
#: 11 worse and 5 better, mean +1.7 %, largest +14 %); 0.1 instead of 0.03 was worse on noisy
#: samples (7 worse and 3 better of 18).
PRIOR_FORCING = 0.03


#: Share of a depth prior's weight on the facets' own copies ``y``; the rest is on the glued
#: vertices ``z`` (docs/fusion.md). On ``z`` a sample moves the piece it lies on; on ``y``
#: alone every sample that disagrees with the normals tears its facet loose (rings of cuts
#: around the samples); on ``y`` too a huge weight makes the output meet the prior.
PRIOR_OWN = 0.5

#: (x side, y side) of facet corners 0..3 (top-left, top-right, bottom-right, bottom-left):
#: +1 for the +x (right) / +y (up) side.
CORNER_SIDES = ((-1, 1), (1, 1), (1, -1), (-1, -1))

# sums and means over a facet's four corners as products: numpy's reductions over an axis of
# length 4 are five times slower
_ONES = np.ones(4)
_QUARTER = np.full(4, 0.25)


#: The (a, b) entries, a <= b, that hold a symmetric 4 x 4 block: the rows of the upper layout.
UPPER = tuple((a, b) for a in range(4) for b in range(a, 4))

#: Offsets (dr, dc) of the vertex grid's stencil planes that :class:`FacetBlocks` forms: the
#: vertex itself and the neighbours after it in row-major order (a coupling is symmetric: one
#: at a backward offset is read from the neighbour's plane of the opposite offset).
FORWARD = ((0, 0), (0, 1), (1, -1), (1, 0), (1, 1))


class FacetBlocks:
    """Assemble symmetric per-facet 4x4 blocks (each its own values) into the fixed 9-point
    CSR pattern of the vertex grid.

    The blocks are taken in the *upper* layout, (10, m): row ``i`` holds entry
    ``UPPER[i] = (a, b)``, a <= b, of every facet's block. The assembly works on the grid: each
    row is laid on the facet grid and added, as a shifted slice, to one stencil plane of the
    vertex grid, (5, H + 1, W + 1), plane ``i`` holding every vertex's coupling to its
    neighbour at the offset ``FORWARD[i]`` (each coupling once: the matrix is symmetric). The
    CSR data are gathered from the planes in row order: vertex indices run row-major, so a
    row's columns are its neighbours in offset order, and the coupling to a neighbour at a
    backward offset is read at that neighbour. Contiguous slice additions instead of a scatter
    over 10 m indices: 1024^2 0.26 -> 0.09 s per assembly, and no (10, m) index arrays to
    keep; five planes instead of nine: 2048^2 0.18 -> 0.13 s (random blocks, same data to the
    last bit).

    Parameters
    ----------
    domain : Domain
    pin : float
        Diagonal weight added at one vertex per connected component (fixes the constant).
    skip : (n_components,) bool, optional
        Components that get no pin.
    """

    def __init__(self, domain, pin: float = 1.0, skip=None):
        self.domain = domain
        H, W = domain.shape
        present = _shared_neighbours(domain)  # (n, 9)
        counts = present.sum(axis=1)
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.nnz = int(self.indptr[-1])
        idx_dtype = np.int32 if self.nnz < 2**31 and domain.n_vertices < 2**31 else np.int64
        self.indptr = self.indptr.astype(idx_dtype)
        vflat = np.flatnonzero(domain.vertex_mask)
        # column of each present neighbour: the vertex index at the offset, in plane order
        vindex = np.full((H + 3) * (W + 3), -1, idx_dtype)  # padded by one all round
        vr, vc = np.divmod(vflat, W + 1)
        at = (vr + 1) * (W + 3) + vc + 1  # (each vertex's place in the padded grid)
        vindex[at] = np.arange(vflat.size)
        # (filled in place, in the index type: no (n, 9) int64 stack, 300 MB at 2048^2)
        cols = np.empty(present.shape, idx_dtype)
        for k, (dr, dc) in enumerate(_OFFSETS):
            np.take(vindex, at + (dr * (W + 3) + dc), out=cols[:, k])
        self.indices = cols[present]
        # where each nonzero lies in the stencil planes (5, (H + 1) (W + 1)), in CSR order: a
        # coupling to a neighbour at a forward offset is in that offset's plane at the vertex
        # itself, one at a backward offset in the opposite offset's plane at the neighbour
        plane = (H + 1) * (W + 1)
        pos_dtype = np.int32 if len(FORWARD) * plane < 2**31 else np.int64
        base = []
        for dr, dc in _OFFSETS:
            ahead = (dr, dc) in FORWARD
            base.append(FORWARD.index((dr, dc) if ahead else (-dr, -dc)) * plane
                        + (0 if ahead else dr * (W + 1) + dc))
        base = np.asarray(base, dtype=pos_dtype)
        self.position = (np.broadcast_to(base, present.shape)[present]
                         + np.repeat(vflat.astype(pos_dtype), counts))
        pr, pc = domain.pixels
        self.fflat = None if domain.n_facets == H * W else (pr * W + pc)
        first = domain.first_vertices if skip is None else domain.first_vertices[~skip]
        # (a sparse addition: a dense (nnz,) array of pins would be 72 bytes per pixel)
        self.pinned = first
        self.pin_at = self.indptr[first] + present[first, :4].sum(axis=1)
        self.pin = float(pin)

    def assemble(self, Q, upper: bool = False) -> sp.csr_matrix:
        """(n, n) CSR of ``sum_f C_f^T Q_f C_f`` plus the pins. `Q`: symmetric blocks, (m, 4,
        4) or (m, 16), or with `upper` the upper layout: (10, m), or any iterable of its ten
        rows in order (each is used before the next is taken, so an iterator may reuse one
        buffer: :meth:`GlueInverse.eliminated_rows`)."""
        if not upper:
            Q = np.reshape(Q, (-1, 16)).T[[4 * a + b for a, b in UPPER]]
        H, W = self.domain.shape
        grid = None if self.fflat is None else np.zeros(H * W)
        planes = np.zeros((len(FORWARD), H + 1, W + 1))
        for (a, b), row in zip(UPPER, Q, strict=True):
            if grid is None:
                facet = row.reshape(H, W)
            else:  # (the other cells stay zero)
                grid[self.fflat] = row
                facet = grid.reshape(H, W)
            (ra, ca), (rb, cb) = CORNER_OFFSETS[a], CORNER_OFFSETS[b]
            if (rb - ra, cb - ca) not in FORWARD:  # (the entry of b's row at a)
                (ra, ca), (rb, cb) = (rb, cb), (ra, ca)
            planes[FORWARD.index((rb - ra, cb - ca)), ra:ra + H, ca:ca + W] += facet
        data = planes.reshape(-1)[self.position]
        del planes
        data[self.pin_at] += self.pin
        n = self.domain.n_vertices
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(n, n))


#: A vertex's 3 x 3 neighbourhood, ``(dr, dc)`` in the column order of
#: :func:`_shared_neighbours` (column ``3 (dr + 1) + (dc + 1)``).
_OFFSETS = tuple(itertools.product((-1, 0, 1), repeat=2))


def _shared_neighbours(domain) -> np.ndarray:
    """(n, 9) bool: whether every vertex shares a facet with its neighbour at offset
    ``(dr, dc)``, column ``3 (dr + 1) + (dc + 1)`` (itself in column 4)."""
    H, W = domain.shape
    mp = np.pad(domain.mask, 1)  # facet (r, c) at mp[r + 1, c + 1]
    vm = domain.vertex_mask
    present = []
    for dr, dc in _OFFSETS:
        rows = (-1, 0) if dr == 0 else ((-1,) if dr < 0 else (0,))  # facet rows vr + k
        cols = (-1, 0) if dc == 0 else ((-1,) if dc < 0 else (0,))
        shared = np.zeros((H + 1, W + 1), bool)
        for kr in rows:
            for kc in cols:
                shared |= mp[1 + kr:H + 2 + kr, 1 + kc:W + 2 + kc]
        present.append(shared[vm])
    return np.stack(present, axis=1)


def _rhs_scale(rhs, normals_part, centred):
    """CG tolerance factor with a depth prior: the reference over ``|rhs|``.

    A prior's samples enter the right-hand side with their absolute depths (log-depths for a
    perspective camera) times their weight, and can outweigh the rest by orders of magnitude; a
    residual relative to the whole right-hand side then stops CG before it moves the surface
    (0 iterations per reweighting at prior weight 100, docs/fusion.md). The reference is the
    normals' part instead, but at least :data:`RHS_SHARE` of the right-hand side of the same
    system with the prior's mean depth subtracted (`centred`: the samples' variation, all the
    information where the normals carry little, e.g. a flat view of steps), and at least
    :data:`RHS_SCALE_FLOOR` of the whole (rounding).
    """
    whole = norm(rhs)
    if whole == 0.0:
        return 1.0
    ref = max(norm(normals_part), RHS_SHARE * norm(centred))
    return min(1.0, max(ref / whole, RHS_SCALE_FLOOR))


def _facet_system(bx, by, flat_weight, fusion=None, target=None):
    """``A = P^T P`` (4, 4) of a facet without a target, and ``a_f = P^T b_f`` (m, 4).

    A facet with a target has ``A = I - 11^T / 4`` (slopes and twist, see
    :class:`GlueInverse`). With `fusion` ``(c, lam, t)`` (normal weights, prior weights and
    targets, each (m,); docs/fusion.md) every facet's normal term is scaled by ``c_f`` and
    ``lam_f (mean y_f - t_f)^2`` is added: ``A_other`` is then (k, 4, 4), one per facet
    without a `target` (m,) bool, in facet order.
    """
    slope = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
    A_other = flat_weight * slope + np.outer(E_TWIST, E_TWIST)
    a = bx[:, None] * E_X + by[:, None] * E_Y
    if fusion is not None:
        if target is None:
            raise ValueError("_facet_system: `target` is required with `fusion`")
        c, lam, t = fusion
        other = np.flatnonzero(~target)
        A_other = c[other, None, None] * A_other + lam[other, None, None] / 16.0
        a = c[:, None] * a + (0.25 * lam * t)[:, None]
    return A_other, a


class GlueInverse:
    """``M_f = (A_f + diag(w_f))^{-1}`` for every facet, kept in closed form.

    For a facet with a target ``A_f = I - 11^T / 4``, so ``A_f + W_f`` is a diagonal minus a
    rank-one matrix and Sherman-Morrison gives ``M_f = diag(d_f) + c_f d_f d_f^T`` with
    ``d_f = 1 / (1 + w_f)``: applying it and forming the eliminated blocks costs a few
    elementwise operations per facet, no (m, 4, 4) arrays but the blocks themselves. The few
    facets without a target are inverted directly. With `fusion` (:func:`_facet_system`)
    ``A_f = c_f I - (c_f / 4 - lam_f / 16) 11^T``: still a diagonal minus a rank-one matrix.
    """

    def __init__(self, target, w, A_other, fusion=None):
        scale, alpha = (1.0, 0.25) if fusion is None else (
            fusion[0][:, None], 0.25 * fusion[0] - fusion[1] / 16.0)
        self.w = w
        self.d = np.add(w, scale)  # (m, 4): 1 / (scale + w), in one array
        np.reciprocal(self.d, out=self.d)
        self.c = np.broadcast_to(alpha / (1.0 - alpha * rowwise(self.d, _ONES)), (len(w),))
        self.other = np.flatnonzero(~target)
        self.M_other = None
        if self.other.size:
            self.M_other = np.linalg.inv(A_other + w[self.other][:, :, None] * np.eye(4))

    def apply(self, v, plus=None, out=None):
        """``M_f v_f`` for every facet, plus `plus` (m, 4) where given: (m, 4), in `out` where
        given (which may be `v` itself: then formed in place; `plus` must not share memory
        with `out`)."""
        d = self.d  # (M v = d * (v + c (d . v)): one new (m, 4) array, no temporaries)
        s = np.einsum("fa,fa->f", d, v)
        s *= self.c
        other = None
        if self.other.size:  # (before `out` overwrites `v`)
            other = np.einsum("fab,fb->fa", self.M_other, v[self.other])
        out = np.add(v, s[:, None], out=out)
        out *= d
        if other is not None:
            out[self.other] = other
        if plus is not None:
            out += plus
        return out

    def eliminated(self):
        """``Q_f = W_f - W_f M_f W_f``: the facet blocks once the copies are eliminated, in the
        upper layout (10, m) of :class:`FacetBlocks`."""
        return np.stack([row.copy() for row in self.eliminated_rows()])

    def eliminated_rows(self):
        """The rows of :meth:`eliminated` one by one, in one reused buffer (each is valid until
        the next is taken): the assembly consumes them so, and the (10, m) array is never
        held (320 MB at 2048^2). Rows of m numbers are ten times faster to form than m blocks
        of 4 x 4."""
        w, m = self.w, len(self.w)
        gt = np.multiply(w.T, self.d.T, out=np.empty((4, m)))
        negc = -self.c
        other = None
        if self.other.size:
            idx = np.arange(4)
            wo = w[self.other]
            other = -(wo[:, :, None] * self.M_other * wo[:, None, :])
            other[:, idx, idx] += wo
        row = np.empty(m)
        diag = np.empty(m)
        for a, b in UPPER:  # (formed row by row: no (4, m) temporary but g)
            np.multiply(gt[a], gt[b], out=row)
            row *= negc
            if a == b:  # (+ w_a (1 - g_a))
                np.subtract(1.0, gt[a], out=diag)
                diag *= w[:, a]
                row += diag
            if other is not None:
                row[self.other] = other[:, a, b]
            yield row


#: The first solve's glue weights from the normals' curl (:func:`curl_seed`): a corner at a
#: vertex where the curl, summed over :data:`SEED_WINDOW` x :data:`SEED_WINDOW` vertices and
#: scaled to an angle, is ``C`` starts at ``1 / (1 + (C / tau)^2)``, ``tau`` the larger of
#: :data:`SEED_TAU` (radians) and :data:`SEED_NOISE` times the normals' noise
#: (:func:`facetlift.frames.normal_noise`), with ``discontinuity_seed``. See the module
#: docstring, "Seeded by the curl"; the values were the first tried (a 3 x 3 window against
#: none, on ten scenes), measured on the development benchmark (docs/results.md).
SEED_TAU = 0.01
SEED_NOISE = 3.0
SEED_WINDOW = 3
#: A vertex is seeded only where that curl is also more than this many times the largest
#: angle (radians) between the normals of two facets around a vertex of its window (with
#: `normals` given to :func:`curl_seed`, NaN where a facet has none of its own; 0: not used).
#: The seed is for jumps between surfaces of about one slope, which the smooth start cannot
#: see; where the normals differ across the line the bilateral weights see it anyway, and a
#: crease's mixed pixels (their averaged normals are no mean of the two slopes) leave curl
#: that does not cancel in the window: the walls and floor of the benchmark's rooms were
#: seeded along every crease. On the development renders' exact normals, of the vertices whose
#: curl exceeds the threshold, those more than two pixels from a true jump fell from
#: 1,000-2,900 per table or room to 0-48 with 0.2, those near one to about half; the analytic
#: `fold` kept all 577. Chosen on the development benchmark and three held-out sets, a fourth
#: drawn after (docs/results.md, "Seeded by the curl, not at creases"): with 0.2 the seed made
#: 106 development runs better and 76 worse than the smooth start (ungated 104 / 78, the rooms
#: +26 %); 0.3 against 0.2: 72 / 89; 0.15 against 0.2: 82 / 56 with the mean level (vessels
#: +5 %).
SEED_SPREAD = 0.2
#: A vertex is seeded only where its own curl is at least this share of the largest in its
#: window (0: not used, the default). The window's sum spreads a jump line's curl over the
#: vertices beside it, whose seeded corners can cut a facet off the wrong side: on BiNI's tent
#: the flat column beside each side's jump hangs on the slope as a comb (a review), which 0.3,
#: 0.5 and 0.8 all mend (mean deviation 0.304 -> 0.125 deg). Not taken (docs/results.md,
#: "Seeds at the curl's peak"): on the development benchmark 0.5 made 103 runs better and 67
#: worse, but the DiLiGenT-like perspective group with exact and 8-bit normals worse with each
#: value (+0.5 to +9 %), and both held-out sets tried worse with exact normals (+5.2 %,
#: +3.4 %); kept for A/B runs (benchmarks/bench_ab.py).
SEED_PEAK = 0.0


def curl_seed(domain, bx, by, target, cosines, footprint: float, noise: float,
              normals=None):
    """(m, 4) starting corner weights from the curl of the target slopes, or None where no
    corner is seeded below 1 (see :data:`SEED_TAU`).

    Around every interior vertex the four facets' slopes `bx`, `by` (of the unknown per pixel,
    y up; `target` False: none) per pixel `footprint` give a curl, scaled to an angle by
    :func:`facetlift.frames.curl_to_angle` of the facets' view `cosines` (as it was measured;
    :func:`facetlift.frames.normal_noise` has since taken a pinhole's slope cosine, which reads
    a wide lens' off-axis curl larger, a review); the signed curl is summed over a window of
    :data:`SEED_WINDOW` vertices a side and divided by the window's width, so that a jump
    line's curl (its height's change along it) adds up and a crease's (the sampling's, of
    either sign along it) cancels. `noise` is in radians. With `normals` (m, 3), the facets'
    own unit normals (NaN where a facet has none of its own: missing, or of confidence 0), a
    vertex is seeded only where its curl also exceeds :data:`SEED_SPREAD` times their largest
    angle around it (:func:`_spread`).
    """
    import scipy.ndimage as ndi

    from ...frames import curl_to_angle

    H, W = domain.shape
    r, c = domain.pixels
    img = np.full((3, H + 2, W + 2), np.nan)
    img[0, r + 1, c + 1] = np.where(target, bx, np.nan) / footprint
    img[1, r + 1, c + 1] = np.where(target, by, np.nan) / footprint
    img[2, r + 1, c + 1] = np.where(target, cosines, np.nan) ** 2
    tl, tr, bl, br = img[:, :-1, :-1], img[:, :-1, 1:], img[:, 1:, :-1], img[:, 1:, 1:]
    curl = 0.5 * ((tl[0] + tr[0] - bl[0] - br[0]) - (tr[1] + br[1] - tl[1] - bl[1]))
    curl *= curl_to_angle(0.25 * (tl[2] + tr[2] + bl[2] + br[2]))  # (radians)
    np.nan_to_num(curl, copy=False, nan=0.0)  # (a vertex without four targets: no curl)
    raw = curl
    if SEED_WINDOW > 1:
        curl = ndi.uniform_filter(curl, size=SEED_WINDOW, mode="constant") * SEED_WINDOW
        if SEED_PEAK > 0:
            peak = ndi.maximum_filter(np.abs(raw), size=SEED_WINDOW, mode="constant")
            curl = np.where(np.abs(raw) >= SEED_PEAK * peak, curl, 0.0)
    tau = max(SEED_TAU, SEED_NOISE * (noise if np.isfinite(noise) else 0.0))
    g = 1.0 / (1.0 + np.square(curl / tau))
    if normals is not None and SEED_SPREAD > 0:
        g[np.abs(curl) <= SEED_SPREAD * _spread(domain, normals, target)] = 1.0
    if g.min() >= 1.0:
        return None
    return np.stack([g[r + dr, c + dc] for dr, dc in CORNER_OFFSETS], axis=1)


def _spread(domain, normals, target):
    """(H + 1, W + 1) the largest angle (radians) between the normals of two facets around a
    vertex, its largest over a window of :data:`SEED_WINDOW` vertices a side."""
    import scipy.ndimage as ndi

    H, W = domain.shape
    r, c = domain.pixels
    img = np.full((H + 2, W + 2, 3), np.nan)
    img[r + 1, c + 1] = np.where(target[:, None], normals, np.nan)
    quad = (img[:-1, :-1], img[:-1, 1:], img[1:, :-1], img[1:, 1:])
    low = np.ones((H + 1, W + 1))  # (the smallest cosine: the largest angle, one arccos)
    for i, j in itertools.combinations(range(4), 2):
        # (NaN where a facet has no normal: fmin ignores it)
        np.fmin(low, np.einsum("ijk,ijk->ij", quad[i], quad[j]), out=low)
    out = np.arccos(np.clip(low, -1.0, 1.0, out=low), out=low)
    return ndi.maximum_filter(out, size=SEED_WINDOW, mode="constant")


def neighbours(domain) -> dict[str, np.ndarray]:
    """Facet index of each facet's neighbour on the +x, -x, +y (up) and -y side; -1 if none."""
    H, W = domain.shape
    idx = np.full((H + 2, W + 2), -1, np.int64)
    r, c = domain.pixels
    idx[r + 1, c + 1] = np.arange(domain.n_facets)
    return {"+x": idx[r + 1, c + 2], "-x": idx[r + 1, c], "+y": idx[r, c + 1],
            "-y": idx[r + 2, c + 1]}


def _sigmoid(x, k=1.0):
    """``sigmoid(k x)``, formed in `x` (as ``(1 + tanh(k x / 2)) / 2``)."""
    x *= 0.5 * k
    np.tanh(x, out=x)
    x += 1.0
    x *= 0.5
    return x


def evidence(nb, scale) -> list[tuple[str, float, np.ndarray, np.ndarray]]:
    """``(side, sign, neighbour, weight)`` per side for :func:`bilateral_weights`: the
    neighbour's facet index (0 where there is none) and the facet's normal scale where the
    pair gives evidence (0 where the neighbour is missing or has no normal). Depends on the
    domain and the normals only: computed once per solve."""
    out = []
    for key, q in nb.items():
        qq = np.maximum(q, 0).astype(np.int32 if q.size < 2**31 else np.int64)
        has = (q >= 0) & (scale[qq] > 0)  # a neighbour without a normal gives no evidence
        out.append((key, 1.0 if key[0] == "+" else -1.0, qq, np.where(has, scale, 0.0)))
    return out


def bilateral_weights(u, nb, scale, k, slopes=None):
    """Corner glue weights (m, 4) from facet values `u` (m,) (see the module docstring).

    `nb` is :func:`neighbours` (or :func:`evidence` of it and `scale`, computed once); `scale`
    (m,) the normal scale ``c_f`` (0 where a facet has no target: no evidence). With `slopes`
    ``(bx, by)`` the compared quantities are the differences minus what the two facets'
    normals predict (trapezoid rule), otherwise the plain differences (BiNI's choice). A
    missing neighbour counts as a zero difference.
    """
    sides = nb if isinstance(nb, list) else evidence(nb, scale)
    sq = {}
    for key, sign, qq, hs in sides:
        d = u[qq] - u
        if slopes is not None:
            g = slopes[0] if key[1] == "x" else slopes[1]
            d = sign * d - 0.5 * (g + g[qq])
        d *= hs
        sq[key] = np.square(d, out=d)
    # the + side's weight and the - side's, per axis (formed in the squares' own arrays)
    omega = {}
    for a in ("x", "y"):
        plus = _sigmoid(np.subtract(sq["-" + a], sq["+" + a], out=sq["-" + a]), k)
        omega[a] = {1: plus, -1: np.subtract(1.0, plus, out=sq["+" + a])}
    out = np.empty((len(u), 4))
    for i, (sx, sy) in enumerate(CORNER_SIDES):
        np.multiply(omega["x"][sx], omega["y"][sy], out=out[:, i])
    out *= 4.0
    return np.maximum(out, FLOOR, out=out)


def sharpness(k: float, noise: float, steps: float = float("nan")) -> float:
    """The bilateral sigmoid's sharpness for ``discontinuity_k`` `k`, the normals' angular
    noise `noise` in degrees (:data:`NOISE_K`) and their share of one-pixel steps `steps`
    (:func:`soft_edges`): ``k * NOISE_K / noise`` above ``NOISE_K``; at most that, ``k *
    SOFT_K`` where the share is below :data:`SOFT_SHARE` (a blurred map); else (or where
    either is unknown, NaN) `k`."""
    if np.isfinite(noise) and noise > NOISE_K:
        return float(k) * NOISE_K / float(noise)
    if np.isfinite(steps) and steps < SOFT_SHARE:
        return float(k) * SOFT_K
    return float(k)


def soft_edges(domain, normals, given) -> float:
    """The share of one-pixel steps among the strong changes of the normal map (NaN where
    fewer than :data:`SOFT_MIN` strong changes are seen); below :data:`SOFT_SHARE` the map
    counts as blurred (:data:`SOFT_K`).

    A strong change is an angle above :data:`SOFT_ANGLE` between two 4-neighbours' normals
    (`normals` (m, 3), NaN where missing; `given` (m,) bool, the facets whose own normal is
    used); it is a one-pixel step where it exceeds both changes beside it along the same line
    by :data:`SOFT_PEAK` times (both neighbours given). A spike (one normal unlike the two
    beside it, an outlier: a neighbouring change of at least half its size that turns back,
    so that the normals two pixels apart differ less than the larger change) is neither step
    nor
    ramp and not counted. Chords ``|n_a - n_b|`` stand for the angles (monotonic)."""
    good = given & np.isfinite(normals).all(axis=1)
    img = np.stack([domain.to_image(np.where(good, normals[:, i], np.nan)) for i in range(3)],
                   axis=-1)
    strong_sq = (2.0 * math.sin(math.radians(SOFT_ANGLE) / 2.0)) ** 2
    peak_sq = SOFT_PEAK ** 2
    strong = steps = 0
    for a in (img, img.transpose(1, 0, 2)):
        d = a[:, 1:] - a[:, :-1]
        d = np.einsum("ijk,ijk->ij", d, d)  # (squared chords; NaN beside a missing normal)
        e = a[:, 2:] - a[:, :-2]
        e = np.einsum("ijk,ijk->ij", e, e)  # (across two pixels)
        mid, left, right = d[:, 1:-1], d[:, :-2], d[:, 2:]
        with np.errstate(invalid="ignore"):
            big = (mid > strong_sq) & np.isfinite(left) & np.isfinite(right)
            spike = (((peak_sq * left >= mid) & (e[:, :-1] < np.fmax(left, mid)))
                     | ((peak_sq * right >= mid) & (e[:, 1:] < np.fmax(right, mid))))
            big &= ~spike
            strong += int(big.sum())
            steps += int((big & (mid >= peak_sq * np.fmax(left, right))).sum())
    return steps / strong if strong >= SOFT_MIN else float("nan")


def steep_planar(domain, normals, target, bx, by, footprint: float, noise: float, given=None):
    """(m,) factors in (0, 1] of the bilateral sharpness per facet (:data:`STEEP_TAU`), or None
    where none is below 1: ``min(1, STEEP_TAU / (t sigma))`` on the facets whose normals
    scatter about their local mean no more than the noise does (:data:`PLANAR`), 1 elsewhere.
    `normals` (m, 3) are the input's (NaN where missing), `bx`, `by` the facets' slopes of the
    unknown, `footprint` the camera's footprint, `noise` the normals' noise in degrees
    (:func:`facetlift.frames.normal_noise`); `given`
    (m,) bool, the facets whose own normal is used (default `target`: a normal of confidence 0
    is none, and a filled facet's neighbours speak for it)."""
    if not (np.isfinite(noise) and noise > 0 and STEEP_TAU > 0):
        return None
    sigma = math.radians(noise)
    t = np.hypot(bx, by) / footprint
    cap = STEEP_TAU / np.maximum(t * sigma, 1e-300)
    steep = target & (cap < 1.0)
    if not steep.any():
        return None
    from scipy import ndimage

    r, c = domain.pixels
    good = (target if given is None else given) & np.isfinite(normals).all(axis=1)
    size = 2 * PLANAR_RADIUS + 1
    img = np.stack([domain.to_image(np.where(good, normals[:, i], 0.0), fill=0.0)
                    for i in range(3)])
    have = domain.to_image(good.astype(float), fill=0.0)
    mean = np.stack([ndimage.uniform_filter(img[i], size) for i in range(3)])
    mean /= np.maximum(np.sqrt(np.sum(mean * mean, axis=0)), 1e-12)
    angle = np.arccos(np.clip(np.sum(img * mean, axis=0), -1.0, 1.0)) * have
    count = ndimage.uniform_filter(have, size)
    spread = ndimage.uniform_filter(angle, size) / np.maximum(count, 1e-12)
    # (a filled facet by its neighbours' normals; a window without a given normal is none)
    planar = (spread[r, c] < PLANAR * sigma) & (count[r, c] > 0)
    out = np.where(steep & planar, cap, 1.0)
    return out if (out < 1.0).any() else None


def changes_big(step) -> bool:
    """Whether a weight step may change the system's near-null modes (see :data:`REUSE_STEP`)."""
    return bool(np.abs(step).max() > REUSE_STEP)


def solve_discontinuous(
    domain, bx, by, target, *, normal_scale, k: float = DEFAULT_K,
    max_iter: int = DEFAULT_ITER, tol: float = DEFAULT_TOL, flat_weight: float = 1e-9,
    cg_rtol: float = 1e-6, callback=None, prior=None, weights=None, x0=None,
    final_weights=None, blur=None, w0=None, polish_last=True, seed=None, k_scale=None,
):
    """Minimise the glued facet energy with bilateral weights (see the module docstring).

    Parameters
    ----------
    domain : Domain
    bx, by : (m,) float
        Target slopes of the unknown per facet (zero where `target` is False), as for
        :func:`facetlift.methods.dgp.solve_direct`.
    target : (m,) bool
    normal_scale : (m,) float
        ``c_f``: view cosine of each facet's normal per pixel footprint (0 without a target).
    k : float
        Sharpness of the bilateral sigmoid, in squared pixel footprints.
    max_iter : int
        Most reweightings after the smooth solution (0 returns the smooth solution).
    tol : float
        Stop when no corner weight changes by more than this between reweightings; the
        growth phase then lowers only weights whose own bilateral weight is lower by more.
    flat_weight : float
        Slope weight of facets without a target (see dgp).
    cg_rtol : float
        Relative residual of the final solve (and of the one solve when ``max_iter`` is 0);
        the first solve and the reweightings' solve to ``max(cg_rtol, LOOSE_RTOL)`` with the
        forcing term (:data:`FORCING`; :data:`PRIOR_FORCING` with a prior).
    callback : callable(iteration, largest corner-weight change), optional
    prior : (w, t, fixed), optional
        Depth prior on the facet centres of the glued vertices ``z``: weights and targets
        (m,) and the components it fixes (not pinned); it decides the offsets of pieces the
        cuts separate (docs/fusion.md).
    weights : (m,) float, optional
        Weight of every facet's normal term (the normals' confidence).
    x0 : (n,) float, optional
        Start of the first solve (default zeros).
    final_weights : (m,) float, optional
        Weight of every facet's normal term in the final solve, after the reweightings (also
        when the cap stopped them; instead of `weights`: the route passes the view cosine
        squared, :data:`FINAL_COS_POWER`, times the confidence, without a prior or with a
        sparse or blurred one, :func:`facetlift.methods.dgp.cuts_first`); not with
        ``max_iter = 0`` unless `w0` is given (then its one solve). A pointwise prior's
        weights are scaled in that solve as its facets' normal terms (``final_weights /
        weights``).
    blur : BlurredPrior, optional
        The `prior` seen through a blur (``prior_blur``,
        :class:`~facetlift.methods.dgp.common.BlurredPrior`): its target is corrected after
        every reweighting's solve (from the facets' own centre values), and the reweightings
        go on, even with settled weights, until it stops; the last system is then formed with
        the last target.
    w0 : (m, 4) float, optional
        Corner glue weights to start from (default all 1: the smooth solution); with
        ``max_iter = 0`` the system of these weights is solved once to `cg_rtol`: with
        `final_weights` (weights a pass before settled) the final weights' system, else
        with `weights`.
    polish_last : bool
        Solve the last system to `cg_rtol` after the reweightings (default). False where only
        the weights are wanted (:data:`facetlift.methods.dgp.PRIOR_CUTS_FIRST`): `z` and `y`
        are then the last loose solve's.
    seed : (m, 4) float, optional
        Corner weights of the first solve where neither `w0` nor a `prior` is given and
        `max_iter` is not 0 (:func:`curl_seed`; default all 1).
    k_scale : (m,) float, optional
        Factor of `k` per facet (:func:`steep_planar`; default 1 everywhere).

    Returns
    -------
    z : (n,) float
        Vertex values.
    y : (m, 4) float
        Every facet's own corner values (its centre value is their mean).
    w : (m, 4) float
        Final corner glue weights.
    info : dict
        ``iterations`` (reweightings, the growth phase's included), ``grown`` (the growth
        phase's), ``converged``, ``energy`` (per reweighting), ``weight_change`` (largest
        corner-weight step per reweighting), ``cg_iterations`` (list), ``multigrid_builds``
        and ``multigrid_refreshes`` (new and Galerkin-refreshed hierarchies),
        ``block_coarse_space`` (whether the block coarse space of :data:`COARSE_BLOCK` was
        turned on by the reweightings), ``cut_corners`` (fraction of corners with weight
        below :data:`CUT`), ``final_weights`` (whether the final solve used them),
        ``polish`` (how the last system was solved to `cg_rtol`: "trial" on the loop's
        hierarchy, "direct" (after a trial that did not finish, or at once:
        :data:`DIRECT_FIRST`) or "multigrid", :data:`DIRECT_POLISH`; None without a polish),
        ``unsolved`` (the relative residuals of the solves whose unfinished CG iterate was kept,
        too large to factorize), ``unsettled_corners``, ``seconds``.
    """
    # (BLAS was limited to one thread here while pyamg's own V-cycle took its vector norms
    # through it: 13 of 20 s on the bear on a busy machine. CG's products are einsum's and
    # the V-cycle is ours since; the process-wide limit stuck at one thread for a library's
    # threaded callers, and without it the timing objects take the same time: bear 0.77 /
    # 0.77 s, bunny 2.34 / 2.41 s, medians of 3 interleaved, 2026-12-03)
    if w0 is None and prior is None and seed is not None and max_iter > 0:
        w0, seeded = seed, True
    else:
        seeded = False
    per_facet = k if k_scale is None else k * np.asarray(k_scale, dtype=float)
    out = _solve(domain, bx, by, target, normal_scale, per_facet, max_iter, tol, flat_weight,
                 cg_rtol, callback, prior, weights, x0, final_weights, blur, w0, polish_last,
                 seeded)
    out[3]["discontinuity_k"] = float(k)  # (the scalar; `per_facet` is what the weights use)
    out[3]["steep_planar"] = (0.0 if k_scale is None or not target.any()  # (of the facets
                              else float(np.mean(np.asarray(k_scale)[target] < 1.0)))  # with one)
    return out


def _of(ref, K) -> bool:
    """Whether the weak reference `ref` (or None) is to the matrix `K`."""
    return ref is not None and ref() is K


def _affordable(n: int) -> bool:
    """Whether a system of `n` unknowns is factorized when CG on it is slow: up to
    :data:`DIRECT_POLISH`, and where the factorization fits in half the free memory and in
    what the job's plan leaves of its limit (:func:`facetlift.memory.factorization_fits`: it
    is not in the plan, whose route is CG's)."""
    return n <= DIRECT_POLISH and factorization_fits(n)


def _factorized(K, rhs, amg, grid):
    """``K^{-1} rhs`` by a factorization (:func:`facetlift.linalg.factorizer`), whatever the
    size: exact where CG on these systems is slow (:data:`DIRECT_POLISH`). The multigrid
    hierarchy is dropped first (the caller drops its own references to it). `grid`: the
    vertices' grid positions (SuperLU's nested-dissection ordering)."""
    amg["ml"] = amg["pre"] = amg["for"] = amg["bal"] = None
    amg["factorized"] += 1
    return linalg.solve(K, rhs, linalg.factorizer(), grid=grid)[0]


def _cut_inside(domain, w: np.ndarray) -> float:
    """The share of corner weights `w` (m, 4) below :data:`CUT` among the facets whose eight
    neighbours are all in `domain`; NaN where there is no such facet."""
    from scipy import ndimage

    full = ndimage.binary_erosion(domain.mask, np.ones((3, 3), bool), border_value=0)
    r, c = domain.pixels
    inside = full[r, c]
    return float((w[inside] < CUT).mean()) if inside.any() else float("nan")


def _on_vertices(domain, lam, target):
    """The prior's share on the glued vertices (``1 - PRIOR_OWN`` of the (m,) weights `lam`
    toward `target`): each facet block's diagonal addition and the right-hand side."""
    share = (1.0 - PRIOR_OWN) * lam
    return share * CENTRE_BLOCK[0, 0], prior_form(domain, share, target, matrix=False)


def _as_final(lam, final_weights, weights):
    """A pointwise prior's (m,) weights `lam` in the final solve: each scaled as its facet's
    normal term, from `weights` to `final_weights` (1 where a facet's normal weight is 0),
    which keeps their ratio, ``prior_weight``'s units."""
    return lam * np.divide(final_weights, weights, out=np.ones(len(lam)), where=weights > 0)


def _solve(domain, bx, by, target, normal_scale, k, max_iter, tol, flat_weight, cg_rtol,
           callback, prior=None, weights=None, x0=None, final_weights=None, blur=None, w0=None,
           polish_last=True, seeded=False):
    t0 = time.perf_counter()
    m = domain.n_facets
    # (no reweighting on weights a pass before settled, w0: its one solve is the final
    # weights' own, not a solve of the plain system and then that one: the islands' repeated
    # solve did both)
    final_first = (max_iter == 0 and polish_last and final_weights is not None
                   and w0 is not None and blur is None)
    if final_first:
        final_weights = np.asarray(final_weights, dtype=float)
        if prior is not None:  # (its samples' weights scaled as in the final solve below)
            c = np.ones(m) if weights is None else np.asarray(weights, float)
            prior = (_as_final(prior[0], final_weights, c), *prior[1:])
        weights = final_weights
    fusion = None
    if weights is not None or prior is not None:  # docs/fusion.md
        c = np.ones(m) if weights is None else np.asarray(weights, float)
        lam, t_prior = (np.zeros(m), np.zeros(m)) if prior is None else prior[:2]
        fusion = (c, PRIOR_OWN * lam, t_prior)
    A_other, a = _facet_system(bx, by, flat_weight, fusion, target)
    blocks = FacetBlocks(domain, skip=None if prior is None else prior[2])
    pz = rP = None
    if prior is not None:
        # on the shared (glued) vertices, not on the facets' own copies: a sample then moves
        # the piece it lies on instead of tearing its own facet loose (a ring of cuts around
        # every sample), and decides the offsets the cuts leave free. Its matrix (prior_form's,
        # w / 16 on every entry of a facet's block) is added to the eliminated blocks as they
        # are assembled: no second matrix and no sparse sum per reweighting (the noisy
        # fusion scenes: 1-2 ms of 30-40 a reweighting)
        pz, rP = _on_vertices(domain, prior[0], prior[1])
    corners = domain.corners
    # (4, 3): corner vector -> (x-slope, y-slope, twist)
    slope_twist = np.stack([E_X, E_Y, E_TWIST], axis=1)
    all_target = bool(target.all())

    a_normals = centre = None
    if prior is not None:  # (for the CG tolerance: _rhs_scale)
        a_normals = _facet_system(bx, by, flat_weight, fusion[:2] + (np.zeros(m),), target)[1]
        centre = float(np.sum(prior[0] * prior[1]) / np.sum(prior[0]))

    def retarget(t_new):
        """A blurred prior's corrected target: the prior's terms (not its matrix) anew."""
        nonlocal prior, fusion, A_other, a, rP
        prior = (prior[0], t_new, prior[2])
        fusion = (fusion[0], fusion[1], t_new)
        A_other, a = _facet_system(bx, by, flat_weight, fusion, target)
        rP = _on_vertices(domain, prior[0], t_new)[1]

    def state(w):
        M = GlueInverse(target, w, A_other, fusion)
        Ma = M.apply(a)
        rows = M.eliminated_rows()
        if pz is not None:  # (each row is the generator's buffer: added to in place)
            rows = (np.add(row, pz, out=row) for row in rows)
        K = blocks.assemble(rows, upper=True)
        rhs = scatter_corners(domain, w * Ma)
        scale = None
        if pz is not None:
            rhs = rhs + rP
            shift = K @ np.full(rhs.size, centre)  # the prior's mean depth everywhere ...
            shift[blocks.pinned] -= blocks.pin * centre  # ... (the pins hold no prior)
            scale = _rhs_scale(rhs, scatter_corners(domain, w * M.apply(a_normals)),
                               rhs - shift)
        return M, Ma, K, rhs, scale

    def copies(M, Ma, w, zc):
        """Every facet's own corner values, for the vertex values at its corners `zc`."""
        # (in place in the one new array: a second (m, 4) one was page-faulted in anew every
        # reweighting, 128 MB at 2048^2)
        wz = w * zc
        return M.apply(wz, plus=Ma, out=wz)

    def energy(y, w, zc):
        # (the energy trace is a diagnostic: summed over blocks of ENERGY_BLOCK facets, whose
        # temporaries stay in the cache and are not page-faulted in anew every reweighting)
        total = 0.0
        for s0 in range(0, m, ENERGY_BLOCK):
            s1 = min(s0 + ENERGY_BLOCK, m)
            yb = y[s0:s1]
            st = rowwise(yb, slope_twist)  # (b, 3): x-slope, y-slope and twist residuals
            st[:, 0] -= bx[s0:s1]
            st[:, 1] -= by[s0:s1]
            if not all_target:
                st[~target[s0:s1], :2] = 0.0
            gap = np.subtract(yb, zc[s0:s1])
            gap *= gap
            total += dot(w[s0:s1].reshape(-1), gap.reshape(-1))
            st *= st
            if fusion is None:  # (no prior either)
                total += float(st.sum())
                continue
            total += dot(fusion[0][s0:s1], st.sum(axis=1))
            if prior is not None:
                t = prior[1][s0:s1]
                total += float(np.sum(fusion[1][s0:s1] * (rowwise(yb, _QUARTER) - t) ** 2 + (
                    (1.0 - PRIOR_OWN) * prior[0][s0:s1] * (rowwise(zc[s0:s1], _QUARTER) - t) ** 2)))
        return total

    slopes = (bx, by) if EVIDENCE == "residual" else None
    w = np.ones((m, 4)) if w0 is None else np.array(w0, dtype=float)
    M, Ma, K, rhs, scale = state(w)
    t1 = time.perf_counter()

    @functools.cache
    def blocks_Z():
        vr, vc = np.nonzero(domain.vertex_mask)
        return block_aggregates(vr, vc, COARSE_BLOCK, domain.vertex_component)

    # ("for": the system the hierarchy was built for, "at": the one it was last refreshed or
    # built for; weak references, compared by identity: a held reference kept a third
    # system's matrix alive while the next one was formed, 0.3 GB at 2048^2)
    amg = {"ml": None, "pre": None, "for": None, "at": None, "builds": 0, "refreshes": 0,
           "last_its": 0, "slow": False, "unsolved": [], "bal": None, "factorized": 0}

    def solve(K, rhs, z0, rebuild=True, rtol=cg_rtol, fresh=False, scale=None, trial=False,
              reduction=None):
        # the weights change the system's near-null modes (cut corners): a hierarchy of the
        # current system keeps CG at ~5-15 iterations where one of the smooth system needs
        # hundreds. A new one is built when the last solve was slow; when the weights moved
        # much, or the last solve needed more than REFRESH_ITS iterations on it, the old one's
        # coarse operators are recomputed for the new system (Galerkin refresh, a fraction of
        # a build); once the weights settle, it serves as it is
        if amg["ml"] is None or amg["last_its"] > REUSE_ITS or (fresh and not _of(amg["for"], K)):
            # (the old one freed before the new one is built: the block space's closure too)
            amg["ml"] = amg["pre"] = amg["bal"] = None
            amg["ml"] = hierarchy(K, symmetric_gs=True, interpolation=INTERPOLATION)
            amg["pre"] = vcycle(amg["ml"])
            amg["builds"] += 1
            amg["for"] = amg["at"] = weakref.ref(K)
        elif rebuild or (amg["last_its"] > REFRESH_ITS and not trial) or (
                # (the final system, unless the hierarchy is of it already: a prior compared
                # pixel by pixel keeps the last reweighting's system)
                trial and POLISH_REFRESH and not _of(amg["at"], K)):
            amg["bal"] = None  # (formed anew below)
            refresh(amg["ml"], K, reinterpolate=REINTERPOLATE and (
                trial or amg["last_its"] > REFRESH_ITS))
            amg["refreshes"] += 1
            amg["for"] = None  # refreshed, not built, for K
            amg["at"] = weakref.ref(K)
        pre = amg["pre"]
        if amg["slow"]:  # regions' offsets converge slowly: add the block coarse space
            # formed with the hierarchy's own finest matrix, and kept until the hierarchy is
            # refreshed or rebuilt (which drop it): between those the V-cycle smooths with
            # that matrix too, and the balanced form is SPD for any (COARSE_BLOCK)
            if amg["bal"] is None:
                amg["bal"] = balanced(amg["ml"].levels[0].A, pre, blocks_Z())
            pre = amg["bal"]
        plain = rtol
        if scale is not None:  # a prior: the tolerance is relative to the normals' part
            rtol = rtol * scale
        z, info = linalg.cg(K, rhs, pre, x0=z0, rtol=rtol, reduction=reduction,
                            maxiter=POLISH_TRIAL if trial else 500)
        if trial:
            its = info.iterations
            r = info.residuals
            if not info.converged and its and 0.0 < rtol < r[-1] < r[0] < math.inf:
                # at the average rate of its iterations, would as many again finish it? Then
                # go on here, with twice as many allowed (the rate is optimistic: the first
                # iteration gains most, and the restart loses the Krylov space; the 2048^2
                # disk needed 3 more, a new hierarchy costs seconds there); else a
                # factorization or a new hierarchy goes on
                more = math.log(rtol / r[-1]) / math.log(r[-1] / r[0]) * its
                if more <= POLISH_TRIAL:
                    z, info = linalg.cg(K, rhs, pre, x0=z, rtol=rtol, reduction=reduction,
                                        maxiter=2 * POLISH_TRIAL)
                    its += info.iterations
            return z, its, info.converged
        amg["last_its"] = info.iterations
        # (the first, cold-started solve counts too: an object with a rim of facets without a
        # normal shows it there, e.g. 89 iterations on the benchmark's spot@front)
        amg["slow"] = amg["slow"] or info.iterations > REUSE_ITS
        if not info.converged and not (scale is not None and np.isfinite(z).all()
                                       and info.relative_residual <= plain):
            # an ill-conditioned system: factorized where that is affordable, else the better
            # of CG's iterate and its start is kept (its residual in info["unsolved"]). (With
            # a prior that disagrees with the normals CG may stall above the scaled
            # tolerance; a residual below the unscaled one, the criterion before the scaling,
            # is kept as it is)
            if _affordable(K.shape[0]):
                pre = None  # (its closure holds the hierarchy: freed before the factorization)
                z = _factorized(K, rhs, amg, domain.vertices)
            else:
                z = _kept(K, rhs, z, z0, info.residuals[0])
        return z, info.iterations

    def _kept(K, rhs, z, z0, start):
        """Of CG's unfinished iterate `z` and its start `z0` (relative residual `start`), the
        finite one with the smaller true residual, recorded in ``amg["unsolved"]``."""
        bn = norm(rhs) or 1.0
        r = norm(rhs - K @ z) / bn if np.isfinite(z).all() else np.inf
        if not r <= start and np.isfinite(z0).all() and np.isfinite(start):
            z, r = z0, start
        if not np.isfinite(r):
            raise SolverError(
                f"discontinuities: multigrid-preconditioned CG failed on {K.shape[0]:,} "
                f"unknowns (a non-finite iterate), which are too many to factorize here "
                f"(more than {DIRECT_POLISH:,}, or more than the memory the job may use "
                "allows: max_memory / --max-memory, or half the free memory)")
        amg["unsolved"].append(r)
        return z

    # the first (smooth) solution only starts the reweightings: as loose as theirs
    announce(callback, "smooth start" if w0 is None else
             "start from the normals' curl" if seeded else "start from the normals' cuts")
    # (the glue inverse, the copies' constant part and the pairs' evidence are formed after
    # this solve, whose first multigrid build is the run's largest transient, about four
    # times the matrix: 2048^2 peaks there)
    M = Ma = None
    z, its = solve(K, rhs, np.zeros(domain.n_vertices) if x0 is None else x0, scale=scale,
                   rtol=max(cg_rtol, LOOSE_RTOL) if max_iter > 0 else cg_rtol)
    cg_its = [its]
    nb = evidence(neighbours(domain), normal_scale)
    M = GlueInverse(target, w, A_other, fusion)
    Ma = M.apply(a)
    zc = z[corners]
    y = copies(M, Ma, w, zc)
    energies = [energy(y, w, zc)]
    del zc
    changes = []
    converged = max_iter == 0
    it = 0
    # (the forcing term; with a prior only a weak pointwise one's, PRIOR_FORCING)
    forcing = FORCING if prior is None else (
        PRIOR_FORCING if blur is None
        and prior[0].max() <= fusion[0][target].max(initial=0.0) else None)
    forced = forcing is not None

    def reweighted(w, big, z):
        """The system of weights `w` (after a step that `big` says was large,
        :func:`changes_big`), its loose solve from `z`, the copies and the energy trace's
        entry."""
        M, Ma, K, rhs, scale = state(w)
        z, its = solve(K, rhs, z, rebuild=big, scale=scale,
                       rtol=max(cg_rtol, LOOSE_RTOL), reduction=forcing)
        cg_its.append(its)
        zc = z[corners]
        y = copies(M, Ma, w, zc)
        energies.append(energy(y, w, zc))
        return M, Ma, K, rhs, scale, z, y

    # (free reweightings before the steps decay: SETTLE_AFTER, PRIOR_SETTLE_AFTER)
    settle = SETTLE_AFTER if prior is None else PRIOR_SETTLE_AFTER
    moving = blur is not None and max_iter > 0 and blur.update(y.mean(axis=1), settled=False)
    if moving:
        retarget(blur.target)
    if max_iter > 0:
        announce(callback, "reweighting")
    for it in range(1, max_iter + 1):
        step = bilateral_weights(rowwise(y, _QUARTER), nb, normal_scale, k, slopes) - w
        if it > settle:
            step *= DECAY ** (it - settle)
        w = w + step
        changes.append(float(np.abs(step).max()))
        big = changes_big(step)
        # (freed before the next state is formed: the solve's own hierarchy holds its matrix)
        M = Ma = K = rhs = y = step = None
        M, Ma, K, rhs, scale, z, y = reweighted(w, big, z)
        log.info("reweighting %d: largest corner-weight change %.3g (tol %.3g), %d CG "
                 "iterations", it, changes[-1], tol, cg_its[-1])
        if callback is not None:
            callback(it, changes[-1])
        if moving:  # a blurred prior: its target corrected for this solve's surface
            moving = blur.update(y.mean(axis=1), settled=changes[-1] <= tol)
            if moving:
                retarget(blur.target)
        if changes[-1] <= tol and not moving:
            converged = True
            break
    grown = 0
    unsettled = None  # (the settled weights' diagnostic, for the current y; below)
    if GROW and converged and max_iter > 0 and prior is None:
        # crack growth (module docstring): weights only fall, at corners on or next to a cut
        pr, pc = domain.pixels
        grid = np.zeros((domain.shape[0] + 2, domain.shape[1] + 2), bool)
        step = None
        while True:
            cut = (w < CUT).any(axis=1)  # facets with a cut corner
            if not cut.any():
                break
            grid[pr + 1, pc + 1] = cut  # ... and their 4-neighbours
            near = (cut | grid[pr, pc + 1] | grid[pr + 2, pc + 1] | grid[pr + 1, pc]
                    | grid[pr + 1, pc + 2])
            # (formed in place: one (m, 4) array, 134 MB at 2048^2)
            step = bilateral_weights(rowwise(y, _QUARTER), nb, normal_scale, k, slopes)
            step -= w
            unsettled = float((np.abs(step) > CUT).mean())  # (own weight - w, for this y)
            step[(step >= -tol) | ~near[:, None]] = 0.0
            if not step.any():
                break
            if it >= max_iter:  # (the cap counts the growth too)
                converged = False
                break
            if not grown:
                announce(callback, "crack growth")
            it += 1
            grown += 1
            w = w + step
            changes.append(float(-step.min()))
            big = changes_big(step)
            M = Ma = K = rhs = y = step = unsettled = None
            M, Ma, K, rhs, scale, z, y = reweighted(w, big, z)
            log.info("reweighting %d (crack growth): largest weight fall %.3g, %d CG "
                     "iterations", it, changes[-1], cg_its[-1])
            if callback is not None:
                callback(it, changes[-1])
        del grid, step
    # (the settled weights' own diagnostics, before the final solve changes the energy; the
    # growth phase's last check has them when it ended on a look at this y)
    if unsettled is None:
        own = bilateral_weights(rowwise(y, _QUARTER), nb, normal_scale, k, slopes)
        unsettled = float((np.abs(own - w) > CUT).mean())
        del own  # (freed before the final solve)
    slow = amg["slow"]
    # (on weights that reweightings settled: these or a pass before, w0; the second pass of
    # a sparse prior whose first used up max_iter, and the islands' repeated solve, whose
    # one solve is the final system's: final_first)
    # (not a blurred prior's pass without reweightings: its target was never corrected, a
    # review: plateau with discontinuity_iter 1, 2.36 -> 3.13 with the final weights)
    final = (polish_last and final_weights is not None
             and (it > 0 or (w0 is not None and blur is None)) and not final_first)
    if moving and not final:  # (the cap stopped the reweightings: the last target's system)
        M = Ma = K = rhs = None
        M, Ma, K, rhs, scale = state(w)
    if final:  # the final solve's own normal weights (FINAL_COS_POWER), on the settled cuts
        final_weights = np.asarray(final_weights, dtype=float)
        if prior is not None and blur is None:  # a pointwise prior: each sample's weight
            # scaled as its facet's normal term, which keeps their ratio, prior_weight's units
            # (left as given, the samples of 1 % noise at weight 1 were fitted closer: mean
            # MADE 0.576 -> 0.582 mm on the 36 perspective fusion scenes, 22 worse by 1 %;
            # scaled, here and in the islands' repeated solve, 0.564, 2 worse)
            lam = _as_final(prior[0], final_weights, fusion[0])
            fusion = (final_weights, PRIOR_OWN * lam, prior[1])
            pz, rP = _on_vertices(domain, lam, prior[1])
        else:  # (a blurred prior's final solve: on the glued vertices only, as measured)
            fusion = (final_weights, np.zeros(m), np.zeros(m))
        A_other, a = _facet_system(bx, by, flat_weight, fusion, target)
        M = Ma = K = rhs = None
        M, Ma, K, rhs, scale = state(w)
    polish = None  # (how the final system was solved to cg_rtol: info["polish"])
    if (it > 0 or final) and polish_last:  # (a final solve follows: the polish, or the
        # final weights')
        announce(callback, "final solve")
    if polish_last and (it > 0 or final) and (LOOSE_RTOL > cg_rtol or forced or final):  # loose
        # on the hierarchy at hand when it does so quickly (large smooth maps: 2-3 CG
        # iterations, where a new hierarchy costs seconds), else by a factorization where
        # affordable (DIRECT_POLISH; at once where the loop was slow: DIRECT_FIRST), else by
        # CG on a new hierarchy of the final system
        affordable = _affordable(K.shape[0])  # (reads the free memory: once)
        its, done = 0, False
        direct = affordable and amg["slow"] and K.shape[0] <= DIRECT_FIRST
        if (amg["ml"] is not None or not affordable) and not direct:
            # (no hierarchy where the last solve factorized)
            z, its, done = solve(K, rhs, z, rebuild=False, scale=scale, trial=True)
            polish = "trial"
        if not done and affordable:
            z = _factorized(K, rhs, amg, domain.vertices)
            polish = "direct"
        elif not done:
            z, more = solve(K, rhs, z, fresh=True, scale=scale)
            its += more
            polish = "multigrid"
        cg_its.append(its)
        y = copies(M, Ma, w, z[corners])
    if blur is not None:  # (the mismatch of the surface returned)
        blur.returned = blur.rms(y.mean(axis=1))
    t2 = time.perf_counter()
    info = {
        "iterations": it,
        "grown": grown,
        "converged": converged,
        "energy": energies,
        "weight_change": changes,
        "cg_iterations": cg_its,
        "cut_corners": float((w < CUT).mean()),
        # (the same among facets whose eight neighbours are all in the domain: at the mask's
        # edge a missing neighbour reads as a zero difference, so a slope's edge facets have
        # their inner corners below CUT with nothing to separate: a plane strip 3 pixels wide
        # at 60 degrees read 33 % cut, 1 mesh piece, and was warned about, a review)
        "cut_corners_inside": _cut_inside(domain, w),
        # (the corners the curl started cut, curl_seed)
        "seeded_corners": float((w0 < CUT).mean()) if seeded else 0.0,
        "multigrid_builds": amg["builds"],
        "multigrid_refreshes": amg["refreshes"],
        "block_coarse_space": slow,
        "unsettled_corners": unsettled,
        "final_weights": bool(final or final_first),
        "polish": polish,
        "factorizations": amg["factorized"],  # (systems solved by a factorization)
        # relative residuals of the solves whose unfinished CG iterate was kept (too large to
        # factorize: DIRECT_POLISH, or short of memory)
        "unsolved": amg["unsolved"],
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return z, y, w, info
