"""Preconditioners for facet systems on any mask: the spectral box plus an exact local solve
where facets are weak.

A facet system is ``K = sum_f C_f^T Q_f C_f`` on the vertices of a
:class:`~facetlift.domain.Domain` (:func:`facetlift.operators.stencil.facet_form`). Where every
facet carries the full mean-subtracted block ``N = I - 11^T/4`` (slopes and twist), the exact
solver of that operator on the domain's bounding box (:class:`~.spectral.BoxPreconditioner`)
makes CG converge in 20-30 iterations at any size and for any mask shape. Facets without a
target (missing samples, grazing rims) carry only their twist (plus a tiny slope weight): a
vertex all of whose facets are such *weak* facets is nearly free, and clusters of them (a
one- or two-pixel band of grazing normals along a silhouette, a hole in the data) leave
near-null modes that the box does not see: CG then needs hundreds of iterations (812 on a
torus at 2048^2) and, worse, stops at a small residual with the modes unresolved (the
solution was off by 1e-3 of its range at 512^2).

:class:`FacetPreconditioner` deals with them by a two-level (additive-Schwarz-like)
construction. The set ``E`` of vertices touched by weak facets only, together with the
vertices of large weak clusters (:func:`weak_vertices`), is small (a band along the rim, the
interior of gaps: 0.9 % of the vertices on the torus, 1 % with 30 % random missing samples);
its block ``K_EE`` is factorized once (SuperLU; it is banded or tiny), and one application
is the symmetric multiplicative sweep

    x = E-solve(r);  x += box(r - K x);  x += E-solve(r - K x)

which is SPD (it is the symmetric Gauss-Seidel iteration of the two-block splitting). Only
the rows of ``K`` at ``E`` and its neighbours are used for the two corrections, so the cost
over the box is small. The box transform runs in float32 (twice as fast; the preconditioner
only needs a few digits) and CG uses the flexible (Polak-Ribiere) update, so the float32
rounding does not slow it down.

Measured on this 2-core machine (docs/benchmarks.md): torus 1024^2 186 -> 33 iterations and
the solution equal to a direct factorization to 1e-9 of its range where the box alone was
off by 8e-4; 30 % random missing samples 52-81 -> 49-56 iterations; full rectangles with every
normal known one iteration (the box is then exact).

Reuse (a solver that changes facet weights, e.g. the discontinuity reweighting)
    Build once per domain, then per reweighting only refresh::

        pre = FacetPreconditioner(domain, K0, strong0)            # box, or multigrid if thin
        pre.use_multigrid(weights=w0)     # optional: multigrid on sum_f w_f N (w_f in (0, 1])
        for each reweighting:
            K = ...                                               # same 9-point pattern
            pre.refresh(K, strong, weights=w)   # local block redone; multigrid re-Galerkin
            x, info = facet.solve(K, b, pre, rtol=..., x0=x)      # or cg(..., flexible=True)

    ``strong`` marks the facets whose block is (close to) the full ``N``; the others are
    weak and their vertices go to the exact local solve. The box part depends on the domain
    only and is never rebuilt. The multigrid part (:meth:`use_multigrid`) is a hierarchy of
    ``sum_f w_f C_f^T N C_f``: with facets cut apart (a ring of facets with weight 1e-3 in a
    512^2 disk) CG needed 64 iterations with the box, 70 with a unit-weight hierarchy, 51
    with that hierarchy refreshed to the cut weights (:meth:`refresh` with ``weights``:
    0.2 s, the coarsening and interpolation kept, the coarse operators recomputed) and 13
    with a hierarchy built for the cut weights (0.9 s: ``use_multigrid(weights=w)`` again).
    So: rebuild when the weak set has changed much (the first reweightings), refresh
    afterwards.
"""

from __future__ import annotations

import threading

import numpy as np
import scipy.sparse as sp

from .cg import CGInfo, cg
from .dense import norm
from .spectral import BoxPreconditioner

#: Weak facets in 8-connected clusters of at least this many facets (a band along a rim, a
#: hole in the data) hand all their vertices to the local solve; smaller clusters only the
#: vertices they alone touch. Measured on a torus at 2048^2: 39 CG iterations with the
#: exclusive vertices only, 27 with the clusters' vertices. Lower thresholds resolve rarer
#: near-free modes too (1024 small disks with 30 % missing samples at 512^2: one disk whose
#: bottom row hangs on a row of 8 missing samples is 3.7e-3 of the range off a factorization
#: at 256, 2.4e-7 at 8), but with 30 % random missing samples clusters of 8 are everywhere:
#: 2.5x the memory and 3x the time at 1024^2. 256 keeps random gaps cheap.
CLUSTER = 256

#: Clusters larger than this many facets give only their exclusive vertices (one giant gap
#: would make the local block a 2-D factorization of its own).
MAX_LOCAL = 250_000

#: CG iterations with the box before :func:`solve` judges its rate, and the most it lets the
#: box take (predicted from that rate) before switching to multigrid. A multigrid iteration
#: costs 3-4 box iterations and takes 20-90 of them where the box takes 50-120 (many small
#: components with 30 % missing normals at 512^2: box 100 iterations, 2.0 s; multigrid 89,
#: 6.6 s), so only a box that would need hundreds is replaced.
PROBE, BOX_BUDGET = 30, 250

#: The most box iterations in any case (the probe's rate can be too hopeful when the box's
#: convergence slows down later): then :func:`solve` switches to multigrid all the same.
BOX_LIMIT = 150

#: A vertex joins the local solve when its prior mass exceeds this multiple of the median
#: normal-term diagonal (:func:`heavy_vertices`), unless more than HEAVY_SHARE of the
#: vertices would (a dense prior). HEAVY_DIAGONAL: a facet prior's diagonal per unit of its
#: lumped mass (``w 11^T / 16`` against the row sum ``w / 4``).
HEAVY, HEAVY_SHARE, HEAVY_DIAGONAL = 1.0, 0.2, 0.25

#: Boxes of at least this many vertices run their transform in float32 (the transform's cost is
#: the box's, not the mask's: a mask in a small part of a large box, e.g. the human map's
#: silhouette in a 512^2 square, 56k pixels, pays for the whole box). Measured on 2026-12-03
#: (sixth session) on the mask suite at 512^2, float32 against float64 below 65,536 mask
#: vertices: human 0.48 -> 0.32 s (45 CG iterations both; depth within 8e-14 of its range),
#: with 30 % missing normals 0.82 -> 0.57 s (93 both, 6e-9), bear 0.15 -> 0.12 s with missing
#: normals (63 both), 0.08 s either way with every normal known.
FLOAT32_FROM = 65_536


def box_vertices(domain) -> int:
    """Vertices of the domain's bounding box (the box transform's size, before its padding to
    a fast transform length)."""
    vm = domain.vertex_mask
    rows = np.flatnonzero(vm.any(axis=1))
    cols = np.flatnonzero(vm.any(axis=0))
    if rows.size == 0:
        return 0
    return int((rows[-1] - rows[0] + 1) * (cols[-1] - cols[0] + 1))


def _touched(domain, facets: np.ndarray) -> np.ndarray:
    """(H+1, W+1) bool: vertices that are a corner of at least one of the `facets` (m,)."""
    H, W = domain.shape
    f = np.zeros((H, W), dtype=bool)
    f[domain.pixels] = facets
    out = np.zeros((H + 1, W + 1), dtype=bool)
    out[:-1, :-1] |= f
    out[:-1, 1:] |= f
    out[1:, 1:] |= f
    out[1:, :-1] |= f
    return out


#: A domain is thin when fewer than this share of its facets survive :data:`THIN_DEPTH`
#: 8-connected erosions (a spiral 4 pixels wide: none; disks of radius 6: 25 %; real objects:
#: over 80 %).
THIN_SHARE, THIN_DEPTH = 0.1, 3


def thin(domain) -> bool:
    """Whether `domain` is thin (:data:`THIN_SHARE`): the box's fictitious material would
    glue its parts together, so multigrid is the better global part from the start.

    Measured with the domain's small enclosed holes filled
    (:func:`facetlift.problem.enclosed_holes`, up to
    :data:`~facetlift.problem.HOLE_PIXELS` pixels): a map whose normals are NaN at scattered
    pixels, integrated without a mask, is riddled with such holes and read as thin, so it was
    factorized as a 2-D system (2048^2 with 30 % of them NaN: 73.2 s and 7.2 GB, where CG with
    the box takes 18.4-19.9 s; 1024^2 11.8 s against 3.8-4.4; depth within 6e-11 of its
    range). The
    box glues across a hole of a few pixels no more than the domain around it does."""
    import scipy.ndimage as ndi

    from ..problem import enclosed_holes

    mask = domain.mask | enclosed_holes(domain.mask)
    core = ndi.binary_erosion(mask, structure=np.ones((3, 3), dtype=bool),
                              iterations=THIN_DEPTH)
    return int(core.sum()) < THIN_SHARE * domain.n_facets


def weak_vertices(domain, strong: np.ndarray, *, every: bool = False, big=None) -> np.ndarray:
    """(n,) bool: the vertices of the local solve.

    Vertices all of whose facets are weak (``strong`` False), and every vertex of a weak
    facet in an 8-connected cluster of :data:`CLUSTER` to :data:`MAX_LOCAL` weak facets
    (separate clusters: the local block stays block-diagonal, its factorization linear in
    size); with `every`, every vertex of a weak facet (for thin domains, whose blocks
    factorize with little fill).

    Parameters
    ----------
    domain : Domain
    strong : (m,) bool
        Facets carrying the full slope-and-twist block (e.g. facets with a target normal).
    big : (m,) bool, optional
        :func:`clustered` of the weak facets, where the caller has it.
    """
    vm = domain.vertex_mask
    weak = ~np.asarray(strong, dtype=bool)
    if every:
        return _touched(domain, weak)[vm]
    out = ~_touched(domain, ~weak)[vm]
    if big is None:
        big = clustered(domain, weak)
    if big.any():
        out |= _touched(domain, big)[vm]
    return out


def clustered(domain, weak: np.ndarray) -> np.ndarray:
    """(m,) bool: the `weak` facets in 8-connected clusters of :data:`CLUSTER` to
    :data:`MAX_LOCAL` weak facets (whose every vertex :func:`weak_vertices` takes)."""
    import scipy.ndimage as ndi

    weak = np.asarray(weak, dtype=bool)
    if weak.sum() < CLUSTER:
        return np.zeros_like(weak)
    img = domain.to_image(weak, fill=False).astype(bool)
    labels, _ = ndi.label(img, structure=np.ones((3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel())
    big = (sizes >= CLUSTER) & (sizes <= MAX_LOCAL)
    big[0] = False
    return big[labels[domain.pixels]]


def heavy_vertices(K, mass: np.ndarray) -> np.ndarray:
    """(n,) bool: the vertices where a depth prior's lumped `mass` (n,) outweighs the normal
    term of `K`'s diagonal, for the local solve; none when they are more than
    :data:`HEAVY_SHARE` of the vertices (a dense prior, whose mass the box then carries in
    its shift).

    A strongly weighted isolated sample (weight 100: exact points) is a stiff local spring the
    box does not see: CG took 160-174 iterations with 1 % such samples on the 512 x 612 and
    256^2 armadillo renders instead of 35 without a prior; solving its four corners exactly
    in the local block brings that back to the prior-free count.
    """
    mass = np.asarray(mass, dtype=float)
    d = np.asarray(K.diagonal()).ravel() - mass * HEAVY_DIAGONAL
    free = mass == 0
    base = float(np.median(d[free])) if free.any() else float(np.median(d))
    heavy = mass > HEAVY * base
    if heavy.sum() > HEAVY_SHARE * heavy.size:
        return np.zeros_like(heavy)
    return heavy


def _local_factor(KEE, domain, E: np.ndarray):
    """The local block's factorization: SuperLU in its minimum-degree order, or, where the
    block holds more than :data:`LOCAL_WHOLE` of the unknowns, in nested-dissection order on
    the grid positions of its vertices `E` (:func:`facetlift.linalg.direct.superlu`). Half
    the normals missing at random make the weak facets percolate, and the block a 2-D grid
    system of its own that the minimum-degree order filled badly (a 512^2 disk: 0.85 s to
    factorize against 0.40 s); many small clusters, the usual block, fill less in that order
    (a 1024^2 square with 15 % of it in small holes: 2.98 M entries against 3.83 M in
    nested dissection, 8.5 against 12.7 ms a local solve, a review)."""
    import scipy.sparse.linalg as spla

    from .direct import superlu

    if E.size > LOCAL_WHOLE * domain.n_vertices:
        vr, vc = domain.vertices
        return superlu(KEE, (vr[E], vc[E]))
    return spla.splu(KEE, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                     options={"SymmetricMode": True})


class FacetPreconditioner:
    """``z = M(r)`` for a facet system `K` (n, n) on `domain`: the bounding-box spectral
    solve, with an exact solve on the vertices that touch weak facets only.

    Parameters
    ----------
    domain : Domain
    K : (n, n) sparse matrix
        The facet system (symmetric positive semi-definite; singular in the constants).
    strong : (m,) bool
        Facets with the full slope-and-twist block (see :func:`weak_vertices`). All True:
        the box alone.
    coarse : {"auto", "box", "amg"}
        The global part: the bounding-box spectral solve or a multigrid V-cycle
        (:meth:`use_multigrid`). "auto": multigrid for thin domains (:func:`thin`), else
        the box (which :func:`solve` may still switch to multigrid by measurement).
    dtype : numpy dtype, optional
        Precision of the box transform. Default: float32 for a box of :data:`FLOAT32_FROM`
        vertices or more (twice as fast, and enough for a preconditioner), float64 below
        (where speed does not matter, so small problems iterate exactly as with the float64
        box).
    prior : (mass, fixed), optional
        A depth prior in `K` (docs/fusion.md): its lumped diagonal ``mass`` (n,) and the
        components it fixes, ``fixed`` (n_components,) bool. The box and the mean-free
        multigrid do not see a component's constant, which the prior makes a mode of `K`:
        one application is then wrapped in a symmetric coarse correction on those constants
        (``x = Pc r; x += M (r - K x); x += Pc (r - K x)`` with ``Pc = P (P^T K P)^{-1} P^T``,
        P the components' indicators), and the multigrid operator carries ``mass`` instead of
        the pins of the fixed components.

    Attributes
    ----------
    exact : bool
        The box solve is the exact pseudo-inverse (full rectangle, every facet strong, the
        plain ``N`` block): one application solves the system.
    n_weak : int
        Size of the local block.
    """

    def __init__(
        self, domain, K, strong: np.ndarray, *, coarse: str = "auto", dtype=None, workers=None,
        prior=None,
    ):
        if dtype is None:
            dtype = np.float32 if box_vertices(domain) >= FLOAT32_FROM else np.float64
        self.domain = domain
        self._prior = prior
        self._P = None
        if prior is not None:
            fixed = np.asarray(prior[1], dtype=bool)
            comp = domain.vertex_component
            sel = np.flatnonzero(fixed[comp])
            new = np.cumsum(fixed) - 1
            self._P = sp.csr_matrix((np.ones(sel.size), (sel, new[comp[sel]])),
                                    shape=(domain.n_vertices, int(fixed.sum())))
        # the prior's mean lumped mass per facet corner as the box's shift: the smooth modes
        # a prior stiffens (dense or many samples) then see it
        # (heavy samples, in the local block, left out: a homogenised shift from 0.1 % samples
        # of weight 100 took CG from 57 to 103 iterations on the armadillo render)
        self._heavy = None
        shift = 0.0
        if prior is not None:
            self._heavy = heavy_vertices(K, prior[0])
            shift = float(np.sum(prior[0][~self._heavy])) / (4.0 * domain.n_facets)
        self.box = BoxPreconditioner(domain, workers=workers, dtype=dtype, shift=shift)
        #: (K, Factor) once :func:`solve` factorized K instead of iterating (kept for more
        #: solves with the same K), else None; whether it may (False: the caller asked for
        #: CG itself, ``backend="pcg"``); and whether a factorization of this K failed
        self.direct = None
        self.may_factorize = True
        self.direct_failed = False
        self._lock = threading.Lock()
        self.coarse = "box"
        self._global = self.box
        self._thin = thin(domain)
        self.refresh(K, strong)
        if coarse == "amg" or (coarse == "auto" and self._thin):
            self.use_multigrid()

    def use_multigrid(self, weights=None) -> FacetPreconditioner:
        """Replace the box by one V-cycle of a Ruge-Stueben hierarchy of the facet operator
        ``sum_f w_f C_f^T N C_f`` of the domain (`weights` ``w`` (m,), default 1), pinned at
        one vertex per component. It is an M-matrix, so classical AMG suits it; with unit
        weights it does not depend on the system's facet weights and is built once per
        domain. For thin domains (a spiral 4 pixels wide: 1183 box iterations, 46 after the
        switch at 512^2), where the box's fictitious material glues neighbouring arms
        together; and, with weights, for systems whose facets are cut apart (a depth
        discontinuity), where a unit operator glues what the system separates."""
        from .amg import hierarchy, vcycle

        ml = hierarchy(self._operator(weights), symmetric_gs=True)
        self._ml = ml
        self._global = vcycle(ml)
        self.coarse = "amg"
        self.exact = False
        return self

    def _operator(self, weights):
        from ..operators.stencil import N_MEAN_FREE, facet_form, pin_components

        w = 1.0 if weights is None else np.asarray(weights, dtype=float)
        # pinned: a singular hierarchy breaks down on domains of many small components
        # (their coarse blocks are singular up to rounding)
        A = facet_form(self.domain, [(w, N_MEAN_FREE)])
        if self._prior is None:
            return pin_components(self.domain, A)
        mass, fixed = self._prior
        return pin_components(self.domain, A + sp.diags(mass, format="csr"), skip=fixed)

    def _regalerkin(self, weights) -> None:
        """New facet weights for the multigrid part: the same coarsening and interpolation,
        the coarse operators recomputed (``A_{l+1} = R A_l P``, no new setup)."""
        from .amg import refresh

        refresh(self._ml, self._operator(weights))

    def refresh(self, K, strong: np.ndarray, weights=None) -> FacetPreconditioner:
        """Use a new matrix (same domain) and weak set. The global part is kept: the box
        (it depends on the domain only), or the multigrid hierarchy, whose coarse operators
        are recomputed for new facet `weights` when given (:meth:`use_multigrid`; the
        coarsening and interpolation stay). The local factorization is redone (at its first
        use). Returns self."""
        if weights is not None and self.coarse == "amg":
            self._regalerkin(weights)
        self.K = K
        self.direct = None
        self.direct_failed = False
        # on a thin domain (a strip a few pixels wide) the weak vertices' block factorizes
        # with little fill however many there are: take them all (thin spiral with 30 %
        # missing normals at 2048^2: 643 CG iterations, 88 s with the clusters only)
        weak = ~np.asarray(strong, dtype=bool)
        big = None if self._thin else clustered(self.domain, weak)
        local = weak_vertices(self.domain, strong, every=self._thin, big=big)
        #: share of the facets that are weak outside the local solve's clusters (scattered
        #: missing normals: CG needs about twice the iterations, :func:`_factorize_first`)
        self.scattered = 0.0 if big is None else float(np.mean(weak & ~big))
        if self._heavy is not None:
            local |= self._heavy
        E = np.flatnonzero(local)
        self.exact = self.coarse == "box" and self.box.exact and E.size == 0 and self._P is None
        if self._P is not None:
            kc = np.asarray((self._P.T @ (K @ self._P)).diagonal()).ravel()
            self._kc_inv = 1.0 / np.maximum(kc, 1e-300)
        self.n_weak = int(E.size)
        self._E = E
        self._lu = self._KEE = None
        if E.size:
            K = sp.csr_matrix(K)
            rows = K[E]
            # the rows of K at E, and (K symmetric) its columns of E restricted to the rows
            # where they are non-zero: the two local corrections cost O(|E|), not O(n)
            self._rows_E = rows
            self._near = np.unique(rows.indices)
            self._cols_E = sp.csr_matrix(rows[:, self._near].T)
            KEE = rows[:, E].tocsc()
            # a tiny diagonal shift keeps a weak cluster that is free in the constant (a whole
            # component without targets) factorizable; CG works in the range of K anyway
            shift = 1e-12 * max(float(np.abs(KEE.diagonal()).max()), 1e-300)
            # (factorized at its first use: a solve that factorizes the whole system first,
            # :func:`_factorize_first`, never needs it)
            self._KEE = KEE + sp.diags(np.full(E.size, shift), format="csc")
        return self

    @property
    def _local(self):
        """The local block's factorization (:func:`_local_factor`), made at the first use
        (once, also where two threads apply one preconditioner)."""
        with self._lock:
            if self._lu is None:
                self._lu = _local_factor(self._KEE, self.domain, self._E)
                self._KEE = None
        return self._lu

    def _coarse(self, r: np.ndarray) -> np.ndarray:
        return self._P @ (self._kc_inv * (self._P.T @ r))

    def __call__(self, r: np.ndarray) -> np.ndarray:
        if self._P is None:
            return self._apply(r)
        # components do not couple, so P^T K P is diagonal; symmetric multiplicative sweep
        x = self._coarse(r)
        x += self._apply(r - self.K @ x)
        x += self._coarse(r - self.K @ x)
        return x

    def _apply(self, r: np.ndarray) -> np.ndarray:
        if not self._E.size:
            return self._global(r)
        E, lu = self._E, self._local
        xE = lu.solve(r[E])
        r1 = r.copy()
        r1[self._near] -= self._cols_E @ xE
        x = self._global(r1)
        x[E] += xE
        x[E] += lu.solve(r[E] - self._rows_E @ x)
        return x


def solve(
    K, b: np.ndarray, pre: FacetPreconditioner, *, rtol: float, x0=None, maxiter: int = 2000,
    progress=None,
) -> tuple[np.ndarray, CGInfo]:
    """Flexible CG on the facet system `K` with `pre`, choosing its global part by measurement.

    The box runs first; if after :data:`PROBE` iterations the residual rate of their second
    half predicts more than :data:`BOX_BUDGET` iterations in all, or if it has not converged
    after :data:`BOX_LIMIT`, `pre` switches to multigrid
    (:meth:`FacetPreconditioner.use_multigrid`, kept for later solves) and CG restarts from
    the current iterate. The returned info counts the iterations of both phases, and so does
    `progress` (callable(iteration, relative residual), called after every iteration). After
    the probe a factorization is taken instead where :func:`_factorize_instead` predicts it
    faster (kept on `pre` for later solves with the same `K`; its true residual is appended to
    the info's residuals, and a failed one leaves CG to go on).
    """
    # factorized by an earlier solve with this K, or to be factorized before any iteration
    # (_factorize_first); a start already within rtol needs neither
    cached = pre.direct is not None and pre.direct[0] is K
    if cached or _factorize_first(K, pre):
        bn = norm(b) or 1.0
        start = 1.0 if x0 is None else norm(b - K @ x0) / bn
        if start <= rtol:
            return x0, CGInfo(converged=True, residuals=[start])
        done = _direct(K, b, pre, CGInfo(residuals=[start]), rtol)
        if done is not None and done[1].converged:
            return done
        if done is not None and done[1].residuals[-1] < start:  # (CG goes on from the better)
            x0 = done[0]
    if pre.coarse != "box" or pre.exact:
        return cg(K, b, pre, x0=x0, rtol=rtol, maxiter=maxiter, flexible=True, progress=progress)
    x, info = cg(K, b, pre, x0=x0, rtol=rtol, maxiter=min(PROBE, maxiter), flexible=True,
                 progress=progress)
    if info.converged or info.breakdown or info.iterations >= maxiter:
        return x, info
    # the rate of the probe's second half (the first drops fast on the high frequencies)
    res = info.residuals
    half = len(res) // 2
    rate = (res[-1] / res[half]) ** (1.0 / (len(res) - 1 - half))
    left = np.log(rtol / res[-1]) / np.log(rate) if 0 < rate < 1 else np.inf
    predicted = info.iterations + max(left, 0.0)
    fresh = pre.direct is None or pre.direct[0] is not K  # (else its factor was just tried)
    if fresh and _factorize_instead(K, pre, max(left, 0.0)):
        done = _direct(K, b, pre, info, rtol)
        if done is not None and done[1].converged:
            return done
        if done is not None:  # (not to rtol: CG goes on from the better of the two)
            if info.residuals.pop() < info.residuals[-1]:
                x = done[0]
    if predicted <= BOX_BUDGET:  # keep the box, but not beyond BOX_LIMIT iterations
        x, more = cg(K, b, pre, x0=x, rtol=rtol, maxiter=min(BOX_LIMIT, maxiter) - PROBE,
                     flexible=True, progress=_after(progress, info.iterations))
        info.iterations += more.iterations
        info.residuals += more.residuals[1:]
        info.converged, info.breakdown = more.converged, more.breakdown
        if info.converged or info.breakdown or info.iterations >= maxiter:
            return x, info
    pre.use_multigrid()
    # restart from the current iterate (residuals stay relative to |b|)
    x, more = cg(K, b, pre, x0=x, rtol=rtol, maxiter=maxiter - info.iterations, flexible=True,
                 progress=_after(progress, info.iterations))
    info.iterations += more.iterations
    info.residuals += more.residuals[1:]
    info.converged, info.breakdown = more.converged, more.breakdown
    return x, info


#: The cost model of :func:`_factorize_instead`, in seconds on the AMD EPYC VM of
#: docs/benchmarks.md (only their ratio matters: both sides are memory-bound sparse work, and
#: the decision must not depend on the machine's load, or two runs of one job could take
#: different routes). The factorization (SuperLU in nested-dissection order): per unknown and
#: per unit of :func:`facetlift.linalg.ordering.factorization_work`, fitted on pinned facet
#: systems with 30 % missing normals on the mask-shape suite's rect, disk, torus, many
#: components, bear, human and thin masks at 512^2 and 1024^2 (29k-1.05M unknowns: measured
#: 0.16-14.5 s, the model within -30 / +20 % of each, low on the torus-like shapes).
FACTOR_PER_UNKNOWN, FACTOR_PER_WORK = 3.5e-6, 4.5e-9

#: ... and one iteration of CG with the box: per unknown and per vertex cell of the box (its
#: spectral solve), fitted on the same systems' probes (2.6-66 ms, the model within -30 / +15
#: % of each).
ITERATION_PER_UNKNOWN, ITERATION_PER_CELL = 25e-9, 30e-9

#: The factorization is taken only where its modelled time is below this share of CG's
#: modelled remaining time (the models' errors are +-30 %): the human mask with 30 % missing
#: normals at 1024^2 sits at 0.82 and measured 2.42-3.37 s factorized against 2.80-2.90 s
#: with CG (interleaved runs), a tie the margin leaves to CG; many small components at 0.57
#: gain 0.63x.
SWITCH_MARGIN = 0.7


#: The most unknowns :func:`_factorize_instead` factorizes in one component of the mask
#: where its time model decides (components do not fill each other in, so many small ones
#: factorize in time and memory linear in their number: :func:`_blocks`, :func:`_by_blocks`),
#: and in the whole system where no time model decides (below, and
#: :func:`_factorize_first`'s large local block). 2M (8 x LARGE) before: 16,384 small disks of
#: a 2048^2 map with 30 % missing normals (2.5M unknowns, 182 CG iterations, 25.6 s)
#: factorize in 10.3 s; larger fat masks stay with CG by the model (a full 2048^2 square
#: would take minutes).
FACTOR_CAP = 8_000_000

#: ... and where CG is predicted never to finish (the time model cannot bound the choice;
#: the whole system's unknowns).
FACTOR_CAP_UNBOUNDED = 2_000_000


def _blocks(domain) -> np.ndarray:
    """Unknowns (vertices) of each connected component of `domain`: the independent blocks of
    its facet system."""
    return np.bincount(domain.vertex_component)


def _factorize_instead(K, pre, remaining: float) -> bool:
    """Whether factorizing `K` (SuperLU in nested-dissection order) is predicted to take less
    time than the `remaining` CG iterations (a model, :data:`FACTOR_PER_UNKNOWN` ...
    :data:`ITERATION_PER_CELL`, not a clock: the same job takes the same route where the
    memory allows), and fits in memory (:func:`facetlift.memory.factorization_fits`, which
    reads the free memory). Not where the caller asked for CG itself
    (``pre.may_factorize`` False), not with PARDISO's own ordering, whose time this model
    does not describe, nor above :data:`FACTOR_CAP` unknowns in a component."""
    from ..memory import factorization_fits
    from . import factorizer

    n = K.shape[0]
    # (remaining may be inf, CG not predicted to converge at all: then factorize if it fits)
    if not remaining > 0 or not pre.may_factorize or pre.direct_failed:
        return False
    # (CG predicted never to finish, remaining inf, passes any time test: then only up to the
    # old 2M cap, where no fat mask factorizes for minutes)
    blocks = _blocks(pre.domain)
    # (the time model bounds a component's size; without it, the whole system's)
    size = blocks.max() if np.isfinite(remaining) else n
    cap = FACTOR_CAP if np.isfinite(remaining) else FACTOR_CAP_UNBOUNDED
    if factorizer() != "superlu" or size > cap or not factorization_fits(n, blocks):
        return False
    H, W = pre.domain.shape
    iteration = ITERATION_PER_UNKNOWN * n + ITERATION_PER_CELL * (H + 1) * (W + 1)
    return _cheaper(n, pre.domain, SWITCH_MARGIN * remaining * iteration)


#: :func:`_factorize_first`: the whole system is factorized before any CG iteration where the
#: local block holds more than this share of the unknowns (more than about 40 % of the normals
#: missing at random: the weak facets percolate into one cluster, and the local block is a 2-D
#: system nearly as large as the whole, solved twice per iteration: a 512^2 disk with 50 %
#: missing took 5.0 s, factorized 0.65 s; docs/benchmarks.md) ...
LOCAL_WHOLE = 0.25

#: ... or where at least this share of the facets are weak outside the local clusters
#: (scattered missing normals: 52-93 CG iterations at 30 % on the mask suite's shapes, 24-45
#: with every normal) and the modelled factorization costs less than :data:`FIRST_ITERATIONS`
#: box iterations (:data:`ITERATION_PER_UNKNOWN`, and :data:`ITERATION_PER_CELL` per cell of
#: the domain's bounding box, half that for a float32 box, :data:`FLOAT32_FROM`). Measured with
#: 30 % missing on the mask suite (2026-12-04, best of 2 against CG): factorized first 0.32-0.83x
#: the time where the model's ratio was 31-78 iterations (bear, human and many components at
#: 256^2-1024^2, the torus at 256^2), 1.19-1.8x where it was 127-204 (the torus at 512^2 and
#: 1024^2, the bear mask at 1024^2, the disk at 512^2; the human mask at 2048^2, 115: 8.7 s
#: against CG's 4.8 s), a tie at 93 (the disk at 256^2); with 10 % missing (scattered share
#: 0.1) the gains were mixed (0.71-1.42x), so those stay with CG.
SCATTERED, FIRST_ITERATIONS = 0.2, 85.0


def _factorize_first(K, pre) -> bool:
    """Whether :func:`solve` factorizes `K` before the probe (:data:`LOCAL_WHOLE`,
    :data:`SCATTERED`): a model, as :func:`_factorize_instead`, with the same conditions
    (the caller allows it, SuperLU, :data:`FACTOR_CAP`, the memory)."""
    from ..memory import factorization_fits
    from . import factorizer

    if not pre.may_factorize or pre.direct_failed or pre.coarse != "box" or pre.exact:
        return False
    n = K.shape[0]
    large_local = pre.n_weak > LOCAL_WHOLE * n
    if not large_local and pre.scattered < SCATTERED:
        return False
    blocks = _blocks(pre.domain)
    # (a large local block factorizes the whole without the time model: up to the cap in all)
    size = n if large_local else blocks.max()
    if (factorizer() != "superlu" or size > FACTOR_CAP
            or not factorization_fits(n, blocks)):
        return False
    if large_local:
        return True
    box = box_vertices(pre.domain)
    iteration = ITERATION_PER_UNKNOWN * n + ITERATION_PER_CELL * box * (
        0.5 if box >= FLOAT32_FROM else 1.0)
    return _cheaper(n, pre.domain, FIRST_ITERATIONS * iteration)


def _cheaper(n: int, domain, budget: float) -> bool:
    """Whether the modelled factorization of `n` unknowns on `domain` (:data:`FACTOR_PER_UNKNOWN`,
    :data:`FACTOR_PER_WORK`) takes less than `budget` seconds. Its part per unknown alone is
    checked first: where that is over budget the separators' work (a quarter of a second on
    a 2048^2 square) is not computed, and the answer is the same."""
    from .ordering import factorization_work

    base = FACTOR_PER_UNKNOWN * n
    if not base < budget:
        return False
    return base + FACTOR_PER_WORK * factorization_work(*domain.vertices) < budget


def _direct(K, b, pre, info: CGInfo, rtol: float):
    """``K x = b`` by a factorization of `K` pinned at one vertex per component (a prior's
    fixed components are not pinned; :func:`facetlift.operators.stencil.pin_components`),
    kept on `pre` for the next solve with the same `K`; the factorized solution's true
    relative residual is appended to `info` (the iterations so far: the factorization is not
    one) and decides ``converged``. None where the factorization failed (singular, out of
    memory): `pre` then keeps to CG."""
    from ..operators.stencil import pin_components
    from .direct import SolverError

    try:
        if pre.direct is None or pre.direct[0] is not K:
            fixed = None if pre._prior is None else np.asarray(pre._prior[1], dtype=bool)
            pinned = pin_components(pre.domain, K, skip=fixed)
            pre.direct = (K, _by_blocks(pinned, pre.domain))
            del pinned
        x = pre.direct[1].solve(b)
    except (SolverError, MemoryError):  # (CG goes on from where it was: the caller)
        pre.direct = None
        pre.direct_failed = True  # (not again for this matrix: refresh() clears it)
        return None
    bn = norm(b) or 1.0
    info.residuals.append(norm(b - K @ x) / bn)
    info.converged = info.residuals[-1] <= rtol
    return x, info


#: Unknowns per factorization where a system of several components is factorized
#: (:func:`_by_blocks`): whole components are grouped up to this size and each group is
#: factorized alone, so that only one group's transient copies and SuperLU's work space are
#: held at a time.
BLOCK_UNKNOWNS = 1_000_000


def _by_blocks(K, domain):
    """A :class:`facetlift.linalg.direct.Factor` of the pinned facet system `K` of `domain`:
    one SuperLU factorization (nested-dissection order on the grid) of each group of whole
    components of about :data:`BLOCK_UNKNOWNS` unknowns (components do not couple: the same
    solution as one factorization of the whole, to rounding), or of the whole where it is one
    group."""
    from .direct import Factor, superlu

    sizes = _blocks(domain)
    n = K.shape[0]
    if n <= BLOCK_UNKNOWNS or sizes.size == 1:
        return superlu(K, domain.vertices)
    order = np.argsort(domain.vertex_component, kind="stable")
    ends = np.cumsum(sizes)
    # cut after the component where the running total first passes each multiple
    cuts = np.unique(np.searchsorted(ends, np.arange(1, n // BLOCK_UNKNOWNS + 1)
                                     * BLOCK_UNKNOWNS, side="left"))
    bounds = np.unique(np.r_[0, ends[cuts], n])
    rows, cols = domain.vertices
    K = sp.csr_matrix(K)
    parts = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        idx = np.sort(order[a:b])
        parts.append((idx, superlu(K[idx][:, idx], (rows[idx], cols[idx]))))

    def _solve(rhs):
        x = np.empty_like(rhs)
        for idx, f in parts:
            x[idx] = f.solve(np.ascontiguousarray(rhs[idx]))
        return x

    return Factor(_solve, "superlu")


def _after(progress, done: int):
    """`progress` counting on from `done` iterations (a restarted CG), or None."""
    if progress is None:
        return None
    return lambda it, value: progress(done + it, value)
