"""Outlier samples of a sparse depth prior, found before the solve from the normals.

A sample of a depth prior (a LiDAR return, an SfM point) that lies far off the surface pulls
its piece with it: the prior term is quadratic, and with ``discontinuities`` the route may cut
a blob loose around the sample and move it there (docs/fusion.md, "Outlier samples"). The
surface returned cannot tell such a sample, since a strong prior weight makes the surface meet
it; the normals can. Between two samples ``i`` and ``j`` the normals predict the difference
of the camera's unknown (height, or log-depth with a pinhole camera) by integrating their
slopes along the straight line from one to the other; the samples' own difference should
agree with it, up to the normals' and the samples' noise, unless a depth jump lies between
them. Every sample is compared so with its :data:`K_NEAR` nearest samples (and with those
that have it among theirs).

A comparison is left out (neither agreeing nor disagreeing) where the line leaves the mask or
crosses a facet without a usable normal or one steeper than :data:`STEEP` (view cosine): a jump
that the normals show at all shows as such a rim. A sample is an **outlier** when it can be
compared with at least three of its neighbours and with :data:`KNOWN` of them, and agrees with
none: a correct sample on a piece of its own beyond a jump agrees with none of its neighbours
either, but where the normals show the jump as a rim, most of its lines cross the rim and are
not made. Two samples agree when their difference and the normals' differ by at most the
larger of :data:`FAR` times the median over all comparisons and :data:`FLOOR` (a relative
depth with a pinhole camera; without one a share of the larger of the object's width and
the samples' depth range, taken per mask component between the 5th and 95th percentiles so
that the outliers sought and other objects at other depths do not widen it).

Dense priors (samples on more than :data:`DENSE` of the facets: a depth sensor's map, a
monocular network's) are checked pixel by pixel: each sample against its eight neighbouring
samples, across rims too (a sensor's flying pixels lie on the silhouette's grazing rim), and
left out where fewer than half of at least :data:`DENSE_KNOWN` comparisons agree
(docs/fusion.md, "Dense priors: a sensor's flying pixels"). Blurred priors (``prior_blur``)
are not checked: their samples differ from the surface by design.
"""

from __future__ import annotations

import numpy as np

#: Nearest samples each sample is compared with.
K_NEAR = 8
#: A line across a facet whose normal's view cosine is below this is not compared (a rim).
STEEP = 0.3
#: Share of a sample's comparisons that must be made before it can be called an outlier.
KNOWN = 0.75
#: Agreement tolerance: FAR times the median disagreement over all comparisons, and at least
#: FLOOR (relative depth with a camera; a share of the depth range or object width without).
FAR, FLOOR = 10.0, 0.02
#: Priors with samples on more than this share of the facets are dense (a depth map): each
#: sample is compared with its eight neighbouring samples instead of its :data:`K_NEAR`
#: nearest (:func:`_dense`), and is an outlier where at least :data:`DENSE_KNOWN` comparisons
#: are made and, with a pinhole camera, fewer than half of them agree, orthographically none.
#: A sensor's flying pixels (a perspective map) lie in runs along the silhouettes, so a
#: flying pixel often agrees with one flying neighbour: on a review's Kinect-like map of the
#: bear "none agree" found 364 of 760 (1.29 mm at weight 0.01), "at most one" 615 (0.33 mm),
#: "fewer than half" 673 (0.18 mm), and the 2 % relative floor keeps a pinhole view's true
#: steps (exact maps of the bear and of renders lost none). Orthographically a height step of
#: a few units at a jagged self-occlusion exceeds the floor, and the majority left out
#: correct samples there (exact 256^2 renders, discontinuities: the bunny 0.265 -> 0.385,
#: 141 removed; "none agree": 0.266, 5 removed).
DENSE, DENSE_KNOWN = 0.25, 3
#: Lines longer than this many pixels are not compared.
MAX_LENGTH = 128
#: Points along the lines per pixel of their length.
STEPS_PER_PIXEL = 2
#: Line points handled at once (memory: about 50 bytes each).
CHUNK = 1_000_000


def find_outliers(problem) -> tuple[np.ndarray | None, dict]:
    """``(outlier, details)``: (m,) bool, True at the facets whose prior sample is an outlier
    (module docstring), and ``checked`` (the samples with a positive weight), ``comparisons``
    (made), ``threshold`` (the tolerance, in the camera's unknown: log-depth or height) and
    ``unconfirmed`` / ``unconfirmed_pixels`` (image [row, col]): samples that agree with none
    of their comparisons made, too few to call them outliers. Where the prior is not checked,
    ``(None, {"skipped": why})``: no prior, a blurred or a dense one, fewer than 5 samples,
    or fewer than 3 comparisons made."""
    w = problem.prior_weight
    if w is None:
        return None, {"skipped": "no prior"}
    if problem.prior_blur > 0:
        return None, {"skipped": "a blurred prior (prior_blur)"}
    d = problem.domain
    u = problem.prior
    s = _samples(problem)
    n = s.size
    if n < 5:
        return None, {"skipped": f"{n} samples (fewer than 5)"}
    if problem.camera.perspective:
        floor = FLOOR
    else:
        # (over every k-th sample of a dense map: the percentiles need no more, and a sort
        # of 4 M took 0.6 s)
        k = max(1, s.size // DENSE_MEDIAN)
        floor = FLOOR * max(_spread(u[s[::k]], d.facet_component[s[::k]]), _width(problem))
    if n > DENSE * d.n_facets:
        got = _dense(problem, s, floor)
        if got is not None:
            return got
    a, b, predicted = _predicted(problem, s)
    e = np.abs((u[s[b]] - u[s[a]]) - predicted)
    made = np.isfinite(e)
    if made.sum() < 3:
        return None, {"skipped": f"{int(made.sum())} comparisons made (fewer than 3)",
                      "checked": int(n)}
    threshold = max(FAR * float(np.median(e[made])), floor)
    agree = made & (e <= threshold)

    def tally(sel):
        return np.bincount(a[sel], minlength=n) + np.bincount(b[sel], minlength=n)

    total, compared, agreeing = tally(slice(None)), tally(made), tally(agree)
    bad = (compared >= 3) & (compared >= KNOWN * total) & (agreeing == 0)
    return _result(d, s, bad, compared, agreeing, int(made.sum()), threshold, dense=False)


def _result(d, s, bad, compared, agreeing, comparisons: int, threshold: float, dense: bool,
            **more):
    """:func:`find_outliers`' answer from the samples' tallies (`more`: other details)."""
    # (and those that agree with none of the few comparisons made: kept, but counted)
    doubtful = (compared >= 1) & (agreeing == 0) & ~bad
    out = np.zeros(d.n_facets, dtype=bool)
    out[s[bad]] = True
    return out, {"checked": int(s.size), "dense": dense, "comparisons": comparisons,
                 "threshold": threshold,
                 "unconfirmed": int(doubtful.sum()),
                 "unconfirmed_pixels": image_pixels(d, s[doubtful]), **more}


#: Comparisons of the median disagreement of a dense prior (:func:`_dense`): a random subset
#: of this many where there are more.
DENSE_MEDIAN = 1_000_000


def _dense(problem, s: np.ndarray, floor: float):
    """The dense rule (:data:`DENSE`) on the image grid: each sample against its eight
    neighbouring samples, the normals' change between the two pixels by the midpoint rule
    over their slopes, across rims too (a sensor's flying pixels lie on the silhouette's
    grazing rim, and a step of one pixel there predicts far less than they are off; only
    facets without a usable normal are not compared). An outlier where at least
    :data:`DENSE_KNOWN` comparisons are made and (:data:`DENSE`) fewer than half agree with a
    pinhole camera, none orthographically. None where fewer than half of the samples have
    :data:`DENSE_KNOWN` neighbours to be compared with (a prior in scan lines, or scattered:
    the sparse rule decides)."""
    d = problem.domain
    H, W = d.shape
    r, c = d.pixels
    u = np.full((H, W), np.nan)
    u[r[s], c[s]] = problem.prior[s]
    gx_f, gy_f = problem.grid_slopes
    unusable = ~(problem.view_cosines > 0)
    gx = np.full((H, W), np.nan)
    gy = np.full((H, W), np.nan)
    gx[r, c] = np.where(unusable, np.nan, gx_f)
    gy[r, c] = np.where(unusable, np.nan, gy_f)
    steps = []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        A = (slice(0, H - dr), slice(max(0, -dc), W - max(0, dc)))
        B = (slice(dr, H), slice(max(0, dc), W - max(0, -dc)))
        # (x along columns, y up: a step down the rows is a step of -1 in y)
        with np.errstate(invalid="ignore"):
            e = np.abs(u[B] - u[A] - 0.5 * ((gx[A] + gx[B]) * dc - (gy[A] + gy[B]) * dr))
        steps.append((A, B, e))
    del gx, gy
    compared = np.zeros((H, W), np.int8)
    values = []
    for A, B, e in steps:
        made = np.isfinite(e)
        compared[A] += made
        compared[B] += made
        values.append(e[made])
    known = compared[r[s], c[s]]
    if not np.count_nonzero(known >= DENSE_KNOWN) * 2 >= s.size:
        return None
    values = np.concatenate(values)
    if values.size > DENSE_MEDIAN:
        # (drawn with replacement: a permutation of 16 M values took half a second)
        values = values[np.random.default_rng(0).integers(0, values.size, DENSE_MEDIAN)]
    threshold = max(FAR * float(np.median(values)), floor)
    del values
    agreeing = np.zeros((H, W), np.int8)
    for A, B, e in steps:
        with np.errstate(invalid="ignore"):
            ok = e <= threshold  # (NaN: not made, never agreeing)
        agreeing[A] += ok
        agreeing[B] += ok
    comparisons = int(compared.sum()) // 2
    known = known.astype(np.int64)
    agree = agreeing[r[s], c[s]].astype(np.int64)
    if problem.camera.perspective:  # (fewer than half agree: DENSE's note)
        bad = (known >= DENSE_KNOWN) & (2 * agree < known)
    else:
        bad = (known >= DENSE_KNOWN) & (agree == 0)
    return _result(d, s, bad, known, agree, comparisons, threshold, dense=True,
                   majority=bool(problem.camera.perspective))


#: Samples (a random subset of a denser prior) whose differences are compared with the
#: normals' for :func:`trend`.
TREND_SAMPLES = 1000
#: ... over the pairs whose predicted change exceeds this (relative depth; orthographic: a
#: share of the object's width) and whose prior changes by half of it (orthographic: of the
#: samples' own range).
TREND_FLOOR = 0.002
#: ... and only with at least this many such pairs (with 15-21, a noisy prior on a flat render
#: agreed on none).
TREND_PAIRS = 30


def trend(problem) -> dict | None:
    """How the prior's changes between neighbouring samples follow the normals' signs.

    Over up to :data:`TREND_SAMPLES` samples (a fixed random subset of a denser prior), the
    pairs of neighbours (lines as for the outliers) between which the normals predict a change
    of the camera's unknown of at least :data:`TREND_FLOOR` (relative depth; orthographic, of
    the object's width) are decided where the prior's own change is at least half that (of its
    own 5-95 % range without a camera: the sign test does not depend on the prior's units):
    ``{"agreement": share of the decided pairs whose change has the predicted sign, "pairs":
    decided, "undecided": the others}``; near 1 for a prior that matches the normals, near 0
    for one that runs against them (a disparity or inverse depth, a height given as depth),
    about 0.5 for noise. None with fewer than 5 samples, fewer than 10 comparisons made, or
    fewer than :data:`TREND_PAIRS` decided pairs."""
    w = problem.prior_weight
    if w is None:
        return None
    d = problem.domain
    u = problem.prior
    s = _samples(problem)
    if s.size > TREND_SAMPLES:
        s = np.sort(np.random.default_rng(0).choice(s, TREND_SAMPLES, replace=False))
    if s.size < 5:
        return None
    a, b, predicted = _predicted(problem, s)
    given = u[s[b]] - u[s[a]]
    made = np.isfinite(predicted) & np.isfinite(given)
    if made.sum() < 10:
        return None
    x, y = predicted[made], given[made]
    # (signs where the normals predict a change: robust to the few pairs across a jump, which
    # dominated a correlation; the prior's floor in its own units, a review: a prior in
    # smaller units than pixel_size had every pair agree)
    if problem.camera.perspective:
        floor_x = floor_y = TREND_FLOOR
    else:
        floor_x = TREND_FLOOR * _width(problem)
        floor_y = TREND_FLOOR * _spread(u[s], d.facet_component[s])
    big = np.abs(x) >= floor_x
    x, y = x[big], y[big]
    sized = (np.abs(y) >= 0.5 * floor_y) & (y != 0)
    same = sized & (np.sign(y) == np.sign(x))
    decided = int(sized.sum())
    if decided < TREND_PAIRS:
        return None
    return {"agreement": float(same.sum() / decided), "pairs": decided,
            "undecided": int(x.size - decided)}


#: The most pixels listed in ``info`` (``pixels``, ``unconfirmed_pixels``: about 13 bytes
#: each in --json; the counts stay whole).
LISTED = 100_000


def image_pixels(domain, facets: np.ndarray) -> list[list[int]]:
    """[[row, col], ...] of `facets` in the image (the first :data:`LISTED`)."""
    r, c = domain.pixels
    f = facets[:LISTED]
    return [[int(a), int(b)] for a, b in zip(r[f], c[f], strict=True)]


def _samples(problem) -> np.ndarray:
    """The facets holding a prior sample with a positive weight."""
    return np.flatnonzero((problem.prior_weight > 0) & np.isfinite(problem.prior))


def _width(problem) -> float:
    """The object's width (its larger side over the mask, in pixel_size units)."""
    r, c = problem.domain.pixels
    return float(max(np.ptp(r), np.ptp(c)) + 1) * problem.camera.pixel_size


def _spread(values: np.ndarray, component: np.ndarray) -> float:
    """The largest range between the 5th and 95th percentiles (nearest rank) of `values`
    within a mask component (the outliers sought and objects at other depths do not widen
    it); vectorized over the components (a mask may hold thousands)."""
    order = np.lexsort((values, component))
    v, comp = values[order], component[order]
    start = np.flatnonzero(np.r_[True, comp[1:] != comp[:-1]])
    count = np.diff(np.r_[start, comp.size])
    lo = v[start + np.floor(0.05 * (count - 1)).astype(np.int64)]
    hi = v[start + np.ceil(0.95 * (count - 1)).astype(np.int64)]
    return float(np.max(hi - lo)) if v.size else 0.0


def _predicted(problem, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b, predicted)``: pairs of the samples at facets `s` (indices into `s`, each with
    its :data:`K_NEAR` nearest, every pair once) and the change of the unknown from a to b
    that the normals predict along the line (NaN where not compared: rims, no normal,
    outside the mask, too long)."""
    d = problem.domain
    r, c = d.pixels
    index = np.full(d.shape, -1, dtype=np.int64)
    index[r, c] = np.arange(r.size)
    gx, gy = problem.grid_slopes
    rim = problem.view_cosines < STEEP  # (also where there is no usable normal: cosine 0)
    gx = np.where(rim, np.nan, gx)
    gy = np.where(rim, np.nan, gy)
    pts = np.column_stack([r[s], c[s]]).astype(float)
    a, b = _pairs(pts, min(K_NEAR, s.size - 1))
    return a, b, _line_integrals(pts, a, b, index, gx, gy)


def _pairs(pts: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Each sample with its `k` nearest, every unordered pair once."""
    from scipy.spatial import cKDTree

    _, near = cKDTree(pts).query(pts, k + 1)
    near = near[:, 1:]
    a = np.repeat(np.arange(len(pts)), k)
    pair = np.unique(np.sort(np.column_stack([a, near.ravel()]), axis=1), axis=0)
    return pair[:, 0], pair[:, 1]


def _line_integrals(pts, a, b, index, gx, gy) -> np.ndarray:
    """The change of the unknown from sample `a` to sample `b` along the straight line by the
    midpoint rule over the nearest facets' slopes; NaN where the line leaves the domain,
    crosses a facet without a slope or is longer than :data:`MAX_LENGTH`."""
    H, W = index.shape
    dr = pts[b, 0] - pts[a, 0]
    dc = pts[b, 1] - pts[a, 1]
    length = np.maximum(np.abs(dr), np.abs(dc))
    steps = np.maximum(np.ceil(STEPS_PER_PIXEL * length), 1).astype(np.int64)
    out = np.full(a.size, np.nan)
    todo = np.flatnonzero(length <= MAX_LENGTH)
    if not todo.size:
        return out
    todo = todo[np.argsort(steps[todo], kind="stable")]  # (similar lengths share a chunk)
    lo = 0
    while lo < todo.size:
        # (the most lines whose padded points fit CHUNK: k lines cost k times the last one's)
        cost = np.arange(1, todo.size - lo + 1) * steps[todo[lo:]]
        hi = lo + max(1, int(np.searchsorted(cost, CHUNK, side="right")))
        q = todo[lo:hi]
        lo = hi
        longest = int(steps[q[-1]])
        st = steps[q][:, None]
        t = (np.arange(longest) + 0.5)[None, :] / st
        on = t < 1.0
        rr = np.clip(np.rint(pts[a[q], 0][:, None] + t * dr[q][:, None]), 0, H - 1)
        cc = np.clip(np.rint(pts[a[q], 1][:, None] + t * dc[q][:, None]), 0, W - 1)
        ri, ci = rr.astype(np.int64), cc.astype(np.int64)
        f = index[ri, ci]
        fs = np.maximum(f, 0)
        # (x along columns, y up: a step down the rows is a step of -1 in y)
        g = (gx[fs] * dc[q][:, None] - gy[fs] * dr[q][:, None]) / st
        g = np.where(on, g, 0.0)
        ok = ((f >= 0) | ~on).all(axis=1) & np.isfinite(g).all(axis=1)
        # a diagonal step between two points passes a corner: a one-pixel diagonal rim there
        # is crossed unseen unless both pixels beside the step are looked at (blocked when
        # both are: a 45-degree line visits only every other diagonal)
        diag = on[:, 1:] & (ri[:, 1:] != ri[:, :-1]) & (ci[:, 1:] != ci[:, :-1])
        if diag.any():
            def usable(a, b):
                k = index[a, b]
                return (k >= 0) & np.isfinite(gx[np.maximum(k, 0)])
            side = usable(ri[:, :-1], ci[:, 1:]) | usable(ri[:, 1:], ci[:, :-1])
            ok &= ~(diag & ~side).any(axis=1)
        out[q] = np.where(ok, g.sum(axis=1), np.nan)
    return out
