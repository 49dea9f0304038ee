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
#: nearest, and is an outlier where at least :data:`DENSE_KNOWN` comparisons are made and
#: fewer than half of them agree (a sensor's flying pixels, stray returns).
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
    dense = n > DENSE * d.n_facets
    a, b, predicted = _predicted(problem, s, neighbours=dense)
    e = np.abs((u[s[b]] - u[s[a]]) - predicted)
    made = np.isfinite(e)
    if made.sum() < 3:
        return None, {"skipped": f"{int(made.sum())} comparisons made (fewer than 3)",
                      "checked": int(n)}
    if problem.camera.perspective:
        floor = FLOOR
    else:
        floor = FLOOR * max(_spread(u[s], d.facet_component[s]), _width(problem))
    threshold = max(FAR * float(np.median(e[made])), floor)
    agree = made & (e <= threshold)

    def tally(sel):
        return np.bincount(a[sel], minlength=n) + np.bincount(b[sel], minlength=n)

    total, compared, agreeing = tally(slice(None)), tally(made), tally(agree)
    if dense:
        # (a map's neighbours: most of a sample's comparisons across a jump or a flying
        # point beside it still disagree, so the majority decides, not "agrees with none")
        bad = (compared >= DENSE_KNOWN) & (2 * agreeing < compared)
    else:
        bad = (compared >= 3) & (compared >= KNOWN * total) & (agreeing == 0)
    # (and those that agree with none of the few comparisons made: kept, but counted)
    doubtful = (compared >= 1) & (agreeing == 0) & ~bad
    out = np.zeros(d.n_facets, dtype=bool)
    out[s[bad]] = True
    return out, {"checked": int(n), "dense": bool(dense), "comparisons": int(made.sum()),
                 "threshold": threshold,
                 "unconfirmed": int(doubtful.sum()),
                 "unconfirmed_pixels": image_pixels(d, s[doubtful])}


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


def _predicted(problem, s: np.ndarray, neighbours: bool = False
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b, predicted)``: pairs of the samples at facets `s` (indices into `s`, each with
    its :data:`K_NEAR` nearest, or with `neighbours` its eight neighbouring pixels that hold
    samples; every pair once) and the change of the unknown from a to b that the normals
    predict along the line (NaN where not compared: rims, no normal, outside the mask, too
    long)."""
    d = problem.domain
    r, c = d.pixels
    gx, gy = problem.grid_slopes
    # (also where there is no usable normal: cosine 0; a map's neighbours are compared across
    # a rim too: a sensor's flying pixels lie on the silhouette's grazing rim, and a step of
    # one pixel there predicts far less than they are off)
    rim = problem.view_cosines <= 0 if neighbours else problem.view_cosines < STEEP
    gx = np.where(rim, np.nan, gx)
    gy = np.where(rim, np.nan, gy)
    if neighbours:  # (the midpoint rule over the two facets: a step of one pixel)
        a, b = _adjacent(d.shape, r[s], c[s])
        fa, fb = s[a], s[b]
        dr, dc = r[fb] - r[fa], c[fb] - c[fa]
        # (x along columns, y up: a step down the rows is a step of -1 in y)
        return a, b, 0.5 * ((gx[fa] + gx[fb]) * dc - (gy[fa] + gy[fb]) * dr)
    index = np.full(d.shape, -1, dtype=np.int64)
    index[r, c] = np.arange(r.size)
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


def _adjacent(shape, r: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of the samples at pixels (`r`, `c`) that are 8-neighbours, each once."""
    at = np.full(shape, -1, dtype=np.int64)
    at[r, c] = np.arange(r.size)
    a, b = [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        rr, cc = r + dr, c + dc
        ok = (rr < shape[0]) & (cc >= 0) & (cc < shape[1])
        j = np.full(r.size, -1, dtype=np.int64)
        j[ok] = at[rr[ok], cc[ok]]
        a.append(np.flatnonzero(j >= 0))
        b.append(j[j >= 0])
    return np.concatenate(a), np.concatenate(b)


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
