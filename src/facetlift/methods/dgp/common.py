"""Pieces every DGP route shares: targets from a problem, deviations, empty components."""

from __future__ import annotations

import numpy as np

from ..._warnings import warn
from ...linalg.dense import rowwise
from ...operators.stencil import E_X, E_Y, grid_slopes


def targets(problem):
    """Per-facet target slopes (bx, by) of the unknown and the facets that have a target.

    ``(bx, by)`` are the problem's grid slopes (:attr:`facetlift.problem.Problem.grid_slopes`:
    the change of the camera's unknown across one facet along x and y), zero where a facet has
    no usable normal; ``target`` is :attr:`~facetlift.problem.Problem.usable`.
    """
    gx, gy = problem.grid_slopes
    target = problem.usable
    return np.where(target, gx, 0.0), np.where(target, gy, 0.0), target


def empty_components(domain, target, fixed=None, offset=(0, 0)):
    """Indices of the components without any target normal, nor a place fixed by a prior
    where `fixed` (n_components,) bool is given (warned about: they come out flat). The
    warning names one by its size and first pixel, in the image's rows and columns: `offset`
    is the (row, col) of `domain` in the image (a problem cropped to its mask's box,
    :func:`facetlift.api.crop`)."""
    have = np.bincount(domain.facet_component[target], minlength=domain.n_components) > 0
    if fixed is not None:
        have |= np.asarray(fixed, bool)
    empty = np.flatnonzero(~have)
    if empty.size:
        # (named by a pixel and its size: "component 1" of an internal numbering told a
        # photometric-stereo user with a fully shadowed part nothing to look for, an audit)
        first = int(domain.first_facets[empty[0]])
        r = int(domain.pixels[0][first]) + int(offset[0])
        c = int(domain.pixels[1][first]) + int(offset[1])
        size = int(domain.component_sizes[empty[0]])
        warn(
            f"{empty.size} connected component(s) have no usable normal (e.g. the one of "
            f"{size} pixel(s) whose first pixel is at row {r}, col {c}); they are "
            "reconstructed flat"
        )
    return empty


def flatten(domain, z, empty):
    """Components without a target normal are flat (their tilt is only weakly determined)."""
    if empty.size:
        z[np.isin(domain.vertex_component, empty)] = 0.0
    return z


def facet_slopes(domain, z):
    """Current (e_x . z_f, e_y . z_f) of every facet: h times its least-squares slopes."""
    zf = z[domain.corners]
    return rowwise(zf, E_X), rowwise(zf, E_Y)


def average_deviation(domain, z, bx, by, target, h=1.0) -> float:
    """Mean angle (degrees) between current facet normals and target normals.

    `bx`, `by` and the current facet slopes are changes of the unknown across a facet of
    width `h` (the camera footprint), so the normals are ``(-gx, -gy, h)`` and
    ``(-bx, -by, h)``.
    """
    if not target.any():
        return 0.0
    # on the vertex image (grid slicing), not through the (m, 4) corner gather
    gx, gy = grid_slopes(domain.to_vertex_image(z, fill=0.0))
    return mean_angle(gx[domain.mask], gy[domain.mask], bx, by, target, h)


def mean_angle(gx, gy, bx, by, target, h) -> float:
    """Mean angle (degrees) between normals (-gx, -gy, h) and (-bx, -by, h) where `target`."""
    if not target.any():
        return 0.0
    gx, gy, bx, by = (np.ravel(a) for a in (gx, gy, bx, by))
    idx = np.flatnonzero(target)
    total = 0.0
    h2 = h * h
    for a in range(0, idx.size, _CHUNK):  # in chunks: no full-size temporaries
        k = idx[a : a + _CHUNK]
        gxk, gyk, bxk, byk = gx[k], gy[k], bx[k], by[k]
        # atan2(|a x b|, a . b), accurate near zero unlike arccos
        cross = np.sqrt(h2 * ((byk - gyk) ** 2 + (gxk - bxk) ** 2) + (gxk * byk - gyk * bxk) ** 2)
        total += float(np.arctan2(cross, gxk * bxk + gyk * byk + h2).sum())
    return float(np.degrees(total / idx.size))


#: Facets per chunk of :func:`mean_angle`.
_CHUNK = 1 << 20


class BlurredPrior:
    """A prior seen through a blur (``prior_blur``, docs/fusion.md, "Blurred priors").

    The routes take a prior as a pointwise term ``w_f (u_f - t_f)^2`` on the facet centres.
    For a blurred prior ``p`` the target ``t`` starts at ``p`` and is corrected after each
    solve by the mismatch of the result ``u`` seen through the same blur ``B``
    (:class:`facetlift.operators.blur.PlaneBlur`): ``t += OMEGA (p - B u)`` at the samples, a
    relaxed fixed-point iteration whose fixed point is a surface whose blur meets the prior
    while the normals shape everything finer than the blur. At the scales the blur removes
    the mismatch cannot move and the target stays the prior's (the normals rule there, the
    weight being small against a pixel's normal term at those scales).

    Stopping: when the weighted RMS mismatch at the samples falls by less than :data:`TOL`
    of itself in one update (it levels off at what the blur model cannot explain), or grows,
    or after :data:`MAX_UPDATES` updates of a settled surface (a safety net; ``converged`` is
    False then; the discontinuity route's updates while its weights still move do not count).

    The blur sees only the components the prior fixes (those with a sample). A surface whose
    mismatch grew is not kept by the direct route (the previous one is returned). The direct
    route's steps are mixed (Anderson, :data:`ANDERSON`; ``accelerate``): on every second
    scene of the fusion benchmark that lowered the geometric-mean ratio to the better input
    from 0.763 to 0.668 (better on 24 of 26), at 1.2x the time.
    """

    #: Relaxation of the target's correction. The blurred result responds to a change of the
    #: target by a factor in (0, 1] (largest at the lowest frequencies), so plain Richardson
    #: steps (1.0) converge slowly at the scales near the blur; 1.5 halves the updates on the
    #: development scenes and stays below the bound 2 of a symmetric response.
    OMEGA = 1.5
    TOL = 0.05
    MAX_UPDATES = 30

    #: The prior's weight falls toward the mask's edge with this power of the share of the
    #: blur's mass on the mask (:attr:`PlaneBlur.support`: 1 inside, 1/16 of the weight at a
    #: straight edge): there the blurred value is an extrapolation, and on the development
    #: renders the blur model's mismatch with the coarse prior is 5-10x larger within one
    #: sigma of the silhouette than inside (curved rims). Chosen on every second scene of the
    #: fusion benchmark (26 scenes, dgp and dgp-disc, weights 0.01 and 0.003): power 0 / 2 / 4
    #: gave dgp-disc at 0.003 16 / 20 / 20 scenes better than both inputs, geometric-mean
    #: ratio to the better input 0.70 (2) / 0.66 (4); dgp 23 / 23 / 21, 0.70 / 0.73.
    TAPER = 4

    #: Depth of the Anderson mixing of the direct route's target updates (its fixed-point map
    #: does not change between updates; the discontinuity route's does while its weights
    #: move, and it takes the plain relaxed steps).
    ANDERSON = 3

    #: Relative residual of the direct route's solves with a blurred prior (the fixed point
    #: is only reached to :data:`TOL` of the mismatch; the route's 1e-11 would be wasted: on
    #: the armadillo render 206 CG iterations over 12 solves at 1e-8, 125 at 1e-6, the
    #: mismatch the same to 4 digits).
    RTOL = 1e-6

    def __init__(self, domain, weight, prior, sigma):
        from ...operators.blur import PlaneBlur

        self.domain = domain
        weight = np.asarray(weight, float)
        comp = domain.facet_component
        n = domain.n_components
        # the blur sees the components the prior fixes, nothing else: a component without a
        # sample has an arbitrary level (its gauge) that must not leak into its neighbours'
        fixed = (np.bincount(comp[weight > 0], minlength=n) > 0)[comp]
        seen = np.zeros(domain.shape, bool)
        seen[domain.pixels] = fixed
        self.blur = PlaneBlur(seen, sigma)
        # the prior's weights, tapered toward the mask's edge (TAPER), the share of the blur's
        # mass relative to its largest in each component (a part narrower than the blur keeps
        # its weight where it is widest)
        support = self.blur.support[domain.pixels]
        peak = np.zeros(n)
        np.maximum.at(peak, comp, support)
        share = np.divide(support, peak[comp], out=np.zeros_like(support), where=fixed)
        self.weight = weight * share**self.TAPER
        self._root = np.sqrt(self.weight)  # (the mixing's row weights)
        self.samples = self.weight > 0
        self.prior = np.where(self.samples, prior, 0.0)
        self.target = self.prior.copy()
        self.sigma = float(sigma)
        self.residuals: list[float] = []
        # (the mismatch of the surface returned where the updates did not see it: the
        # discontinuity route's last solve comes after them)
        self.returned: float | None = None
        self.converged = False
        self.grew = False  # (stopped because the mismatch grew: the caller may keep the last)
        self.done = False
        self.updates = 0
        self._capped = 0  # (updates counted toward MAX_UPDATES)
        self.capped = False  # (stopped by MAX_UPDATES)
        self.accelerate = False  # (Anderson mixing and reverts: the direct route's)
        self._mixed = False  # (whether the last step was a mixed one)
        self._previous = self.target
        self._last_step = None  # (target, relaxed mismatch) of the last update, for mixing
        self._dx: list = []
        self._df: list = []
        self._settled = False  # (whether the last mismatch was of a settled surface)
        self.first_span = None  # (the first solve's depth range at the samples: a scale)

    def mismatch(self, centres):
        """``p - B u`` (m,) at the samples (0 elsewhere) for facet-centre values `centres`."""
        d = self.domain
        seen = self.blur(d.to_image(centres, fill=0.0))[d.pixels]
        return np.where(self.samples, self.prior - np.nan_to_num(seen), 0.0)

    def rms(self, centres) -> float:
        """The weighted RMS of :meth:`mismatch` (in the unknown's units)."""
        return self._rms(self.mismatch(centres))

    def _rms(self, r) -> float:
        w = self.weight
        return float(np.sqrt(np.sum(w * r * r) / max(float(np.sum(w)), 1e-300)))

    def update(self, centres, settled: bool = True) -> bool:
        """Correct the target for the result's facet-centre values `centres` (m,); returns
        whether it changed (False once stopped: converged, levelled off or at the cap).

        While not `settled` (the discontinuity route's weights still move the surface) the
        target is corrected without the stopping test and without counting toward the cap.
        With :attr:`accelerate` (the direct route) the steps are mixed; a mixed step that made
        the mismatch grow is followed by a plain one from the history's start, and a plain
        one that did stops the updates with :attr:`grew` set and the target put back: the
        caller then returns the surface before it (the update is not counted)."""
        if self.first_span is None:  # (the first solve's surface, before any correction)
            seen = centres[self.samples]
            self.first_span = float(np.ptp(seen)) if seen.size else 0.0
        if self.done:
            return False
        r = self.mismatch(centres)
        rms = self._rms(r)
        last = self.residuals[-1] if self.residuals and self._settled else np.inf
        self.residuals.append(rms)
        self._settled = settled
        mixed, self._mixed = self._mixed, False
        if settled and rms > last and mixed:  # (a mixed step overshot: start the mixing anew)
            self._last_step = None
            self._dx.clear()
            self._df.clear()
        elif settled and (rms == 0.0 or rms > (1.0 - self.TOL) * last):
            self.done = self.converged = True
            if rms > last and self.accelerate:
                self.grew = True
                self.target = self._previous
                self.updates -= 1
            return False
        if settled and self._capped >= self.MAX_UPDATES:
            self.done = self.capped = True
            return False
        f = self.OMEGA * r
        step = f
        if self.accelerate and self.ANDERSON > 0:  # Anderson mixing: the step the last ones
            if self._last_step is not None:  # predict
                t0, f0 = self._last_step
                self._dx.append(self.target - t0)
                self._df.append(f - f0)
                del self._dx[:-self.ANDERSON], self._df[:-self.ANDERSON]
                F = np.stack([d * self._root for d in self._df], axis=1)
                gamma = np.linalg.lstsq(F, f * self._root, rcond=None)[0]
                step = f - sum(g * (dx + df) for g, dx, df in
                               zip(gamma, self._dx, self._df, strict=True))
                self._mixed = True
            self._last_step = (self.target, f)
        self._previous = self.target
        self.target = self.target + step
        self.updates += 1
        self._capped += settled
        return True

    def info(self) -> dict:
        """``info["prior_blur"]``: sigma, target updates, the mismatch (weighted RMS at the
        samples, in the camera's unknown: height, or log-depth for a perspective camera) of
        the surface returned, of the first solve's (``mismatch_first``) and of the last
        surface the updates saw (``mismatch_last``: the discontinuity route's final solve,
        with its own weights, comes after it), whether the updates levelled off
        (``converged``), and whether :data:`MAX_UPDATES` (``cap``) stopped them (``capped``;
        with discontinuities the reweighting budget can stop them before either)."""
        first = self.residuals[0] if self.residuals else None
        last = self.residuals[-1] if self.residuals else None
        if self.grew and len(self.residuals) > 1:
            last = self.residuals[-2]
        return {"sigma": self.sigma, "updates": self.updates,
                "mismatch": self.returned if self.returned is not None else last,
                "mismatch_first": first, "mismatch_last": last,
                "converged": self.converged, "capped": self.capped,
                "cap": self.MAX_UPDATES}
