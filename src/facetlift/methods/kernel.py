"""Gaussian-kernel surface-from-gradients (Ng, Wu & Tang, PAMI 2010), computed in tiles.

Model and energy
    The height is a function in the reproducing-kernel Hilbert space of the Gaussian kernel
    ``k(x, x') = exp(-|x - x'|^2 / (2 sigma^2))`` (x in pixel units). Given gradient samples
    ``g_i = grad z(x_i)`` at the known pixel centres, the method minimises

        ``sum_i |grad f(x_i) - g_i|^2 + reg * ||f||_k^2``

    whose minimiser (representer theorem) is a sum of kernel derivatives centred on the
    samples, ``f(x) = sum_j a_j d k(x, x_j) / dx'_col + b_j d k(x, x_j) / dx'_row``, with the
    coefficients from the closed-form system ``(G + reg I) [a; b] = g``; ``G`` is the
    (2n, 2n) Gram matrix of the gradient functionals, i.e. the negated Hessian blocks
    ``-k_cc, -k_cr, -k_rr`` of the kernel at the sample differences. No discrete integrability
    is enforced: the surface is continuous by construction and is evaluated at every domain
    pixel centre, known or missing. With ``reg -> 0`` it is the Hermite (gradient-only) RBF
    interpolant. Gradients are used in pixel units (``h p`` and ``-h q`` along columns and
    rows, y being up), so `sigma` is in pixels and the result is in world units.

The approximation (this implementation, not the paper's)
    The exact solve is a dense (2n, 2n) system: 256 x 256 pixels would need a 131072-square
    dense matrix (and a matrix-free conjugate-gradient solve converges too slowly: the Gram
    matrix is as ill-conditioned as a grad-div operator, and more so in its curl part). As
    the Gaussian decays fast, the fit near a pixel depends mostly on samples within a few
    sigma. The bounding box of the mask is therefore cut into square cores of ``tile``
    pixels; each core, grown by an overlap ``o = ceil(sigma)`` (the blending zone) and by a
    further ``margin`` pixels (data only, to keep the fit's one-sided boundary error out of
    the blending zone), is fitted exactly with a dense Cholesky solve of its own samples.
    The free constant of every connected piece of every tile's blending region is then
    chosen by least squares so that overlapping fits agree (one constant per tile *piece*,
    so that several mask components, or a component entering a tile twice, each get their
    own), and the fits are blended with a partition of unity (products of 1-D smoothstep
    ramps over the overlaps, normalised). Tiles with the same sample pattern (all interior
    tiles of a dense rectangle) share one factorisation. The result is the exact kernel fit
    up to (i) the truncation of the data at ``o + margin`` pixels and (ii) the blend of two
    slightly different fits in the overlaps, which adds ``grad w (f_s - f_t)`` to the
    gradient. On the smooth analytic surfaces of the tests, tiled (``tile=8``) and
    single-window (exact) fits differ by ~1e-5 of the depth range in the interior (9e-6
    measured at 40 x 40), about the exact fit's own error there, and at the mask boundary
    by up to the size of the fit's one-sided boundary error (4e-4 of the range).

Options
    sigma : float, default 2.0 (pixels)
        Kernel width. The paper ties it to the sample spacing; we could not verify a default
        value in it, so ours follows from two limits. With ``c = sigma / spacing`` the
        Gaussian's approximation error on smooth surfaces saturates near ``exp(-2 pi^2 c^2)``
        (negligible from c = 1.5 on), and its Gram matrix loses frequencies near Nyquist
        like ``exp(-sigma^2 pi^2 / 2)``: below ``reg`` they are smoothed away, so a larger
        sigma blurs the finest detail and costs ``O(sigma^4)`` more time. With sigma = 1 the
        one-sided fit at a mask boundary is poor (errors ~0.4 h |grad z| on a saddle, against
        ~0.01 h |grad z| at sigma = 2), and 30 % missing samples leave gaps it cannot bridge.
        Sparse input needs sigma of the order of the gap between samples.
    reg : float, default 1e-6
        Ridge ``reg`` (in units of the Gram diagonal ``1/sigma^2``): 0 interpolates the
        gradients (and may fail to factor when sigma is large); values up to ~1e-3 damp
        noise a little; larger ones shrink the whole surface towards flat, because the
        Gaussian RKHS norm penalises the height itself (with 5 degree normal noise on a
        128 x 128 surface, max error 8.1e-3 of the range at 1e-6, 6.8e-3 at 1e-3, 6.4e-2
        at 0.1).
    tile : int, default 16
        Core size in pixels (raised to ``2 o`` if smaller). Cost per pixel grows like
        ``(tile + 2 o + 2 margin)^6 / tile^2`` where sample patterns differ.
    margin : int or None, default None -> ``ceil(2 sigma)``
        Extra data border of each fit, in pixels.

Limits
    Orthographic only. A missing region much wider than sigma is filled by a surface that
    flattens towards the region's middle (a Gaussian fit decays to a constant away from its
    data); use a larger `sigma` for sparse input. Like every smooth kernel fit it rounds
    sharp creases over about sigma pixels, and its error is largest at the mask boundary,
    where a fit has data on one side only. Time at the defaults, on a 2-core AMD EPYC VM
    shared with other jobs (load ~3.5): 3.2 s for a dense 256 x 256 saddle (4 distinct
    factorisations) and 4.7 s for a 256 x 256 annulus with 30 % of the samples missing
    (204 tiles, each with its own factorisation). Memory: a few (2n, 2n) dense matrices,
    n <= (tile + 2 o + 2 margin)^2, i.e. up to 20 MB each at the defaults.

Reference
    H.-S. Ng, T.-P. Wu, C.-K. Tang. Surface-from-gradients without discrete integrability
    enforcement: a Gaussian kernel approach. IEEE TPAMI 32(11), 2010.
"""

from __future__ import annotations

import logging
import math
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.linalg as sla
import scipy.ndimage as ndi
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla

from .. import linalg
from .._threads import cores, single_blas_thread
from .._warnings import warn
from ..options import Option
from . import MethodResult

log = logging.getLogger(__name__)

_EIGHT = np.ones((3, 3), dtype=bool)

OPTIONS = (
    # below about 3/4 of a pixel the kernels' derivatives no longer span the grid's slopes:
    # an exact 64^2 paraboloid came out 0.63 / 0.28 / 0.12 / 0.038 / 0.020 of its range off
    # at sigma 0.5 / 0.65 / 0.7 / 0.75 / 1 (mean deviation 33 / 14 / 5.5 / 2.0 / 0.7 deg), with
    # no failure to report (an audit, 2026-12-07)
    Option("sigma", 2.0, "kernel width in pixels (the fit fails below 0.75)", low=0.75),
    Option("reg", 1e-6, "ridge regularisation, relative to the Gram diagonal", low=0.0),
    Option("tile", 16, "core size of the local fits in pixels", kind="int", low=4),
    Option("margin", None, "data border of each local fit in pixels (default ceil(2 sigma))",
           kind="int", low=0, none=True),
    Option("progress", None, "callable(groups done, share of the tiles fitted) called after "
           "every group of tiles with one sample pattern (a dense interior is one group)",
           kind="callable", none=True),
)


#: Separate components share one box when their own boxes' areas add up to more than this
#: many times the union box's (see :mod:`facetlift.methods.frankot_chellappa`).
SHARED_BOX_FACTOR = 4.0


def run(problem, *, sigma, reg, tile, margin, progress) -> MethodResult:
    """Integrate `problem` with the Gaussian-kernel method (see the module docstring).

    Parameters
    ----------
    problem : Problem
        Orthographic problem; missing samples allowed (at least one known sample).
    sigma : float
        Kernel width in pixels, > 0.
    reg : float
        Ridge regularisation, >= 0, relative to the Gram diagonal.
    tile : int
        Core size of the local fits in pixels, >= 4.
    margin : int or None
        Data border of each local fit in pixels (>= 0); None means ``ceil(2 sigma)``.
    progress : callable(groups done, share of the tiles fitted) or None

    Returns
    -------
    MethodResult
        ``values`` (m,): heights at facet centres; ``info`` with the number of tiles,
        distinct factorisations and the seconds spent fitting and blending.

    Raises
    ------
    facetlift.linalg.SolverError
        If a local Gram matrix cannot be factored (raise `reg`).
    """
    if margin is None:
        margin = math.ceil(2 * sigma)

    d = problem.domain
    rows, cols = d.pixels
    gx, gy = problem.grid_slopes
    # each connected component on its own box: a fit window reaching into another component
    # took its samples (a flat part 3 pixels from a pyramid came back 0.086 high), unless the
    # boxes overlap so much that their areas add up to far more than the union box's
    groups = d.component_facets(shared=SHARED_BOX_FACTOR)
    values = np.zeros(d.n_facets)
    info: dict = {}
    done = {"groups": 0, "facets": 0, "box": 0}

    def step(k, share):  # (progress over every box: the groups so far, the facets' share)
        progress(done["groups"] + k,
                 (done["facets"] + share * done["box"]) / max(d.n_facets, 1))

    boxes = []  # (facets, their rows, columns and usable, (r0, c0), known, inside, plan)
    for f in groups:
        r, c = rows[f], cols[f]
        r0, c0 = r.min(), c.min()
        shape = (int(r.max() - r0 + 1), int(c.max() - c0 + 1))
        inside = np.zeros(shape, dtype=bool)
        inside[r - r0, c - c0] = True
        known = np.zeros(shape, dtype=bool)
        ok = problem.usable[f]
        known[r[ok] - r0, c[ok] - c0] = True
        boxes.append((f, (r, c, ok), (r0, c0), known, inside,
                      plan_tiles(known, inside, sigma=sigma, tile=tile, margin=margin)))
    # (the whole run's factorizations, said once before any starts: KERNEL_WARN_SECONDS; per
    # box, a mask of several pieces each under the limit went unsaid, a review)
    _time_check([size for *_, plan in boxes for size in plan[2]], sigma, tile, margin)
    for f, (r, c, ok), (r0, c0), known, inside, plan in boxes:
        done["box"] = f.size
        gc = np.zeros(inside.shape)
        gr = np.zeros(inside.shape)
        gc[r - r0, c - c0] = np.where(ok, gx[f], 0.0)  # dz / d col
        gr[r - r0, c - c0] = np.where(ok, -gy[f], 0.0)  # dz / d row (y is up)
        z, part = fit_tiles(gc, gr, known, inside, sigma=sigma, reg=reg, tile=tile,
                            margin=margin, progress=step if progress is not None else None,
                            plan=plan)
        values[f] = z[r - r0, c - c0]
        for key in ("tiles", "factorizations"):
            info[key] = info.get(key, 0) + part[key]
        for key, sec in part["seconds"].items():
            info.setdefault("seconds", {})[key] = info.get("seconds", {}).get(key, 0.0) + sec
        done["groups"] += part["factorizations"]
        done["facets"] += f.size
    # (the tile the fits used: fit_tiles widens one below two blend widths)
    info.update(boxes=len(groups), sigma=sigma, reg=reg, tile=max(tile, 2 * math.ceil(sigma)),
                margin=margin)
    return MethodResult(values=values, info=info)


def plan_tiles(known, inside, *, sigma, tile, margin):
    """The tiles of a box (:func:`fit_tiles`) and their grouping by sample pattern:
    ``(specs, groups, sizes)``, each tile's (core, blend region, fit window) slices, the
    groups' tile indices keyed by pattern, and each group's unknowns (twice its samples)."""
    H, W = inside.shape
    o = math.ceil(sigma)
    tile = max(tile, 2 * o)  # at most two blend regions overlap along an axis
    specs = []  # (core, blend region, fit window) per tile that touches the domain
    for lo_r in range(0, H, tile):
        for lo_c in range(0, W, tile):
            hi_r, hi_c = min(lo_r + tile, H), min(lo_c + tile, W)
            er = slice(max(lo_r - o, 0), min(hi_r + o, H))  # blend region
            ec = slice(max(lo_c - o, 0), min(hi_c + o, W))
            if not inside[er, ec].any():
                continue
            fr = slice(max(er.start - margin, 0), min(er.stop + margin, H))  # fit window
            fc = slice(max(ec.start - margin, 0), min(ec.stop + margin, W))
            specs.append(((lo_r, hi_r, lo_c, hi_c), (er, ec), (fr, fc)))
    # One factorisation per distinct sample pattern, used for all tiles with that pattern
    groups: dict = {}
    for i, (_, _, (fr, fc)) in enumerate(specs):
        kn = known[fr, fc]
        if kn.any():
            groups.setdefault((kn.shape, kn.tobytes()), []).append(i)
    sizes = [2 * int(np.count_nonzero(known[specs[m[0]][2]])) for m in groups.values()]
    return specs, groups, sizes


def _time_check(sizes, sigma, tile, margin) -> None:
    """Warn where the fits' factorizations (`sizes`: each one's unknowns; (2 n)^3 / 3 flops
    each) are estimated at more than :data:`KERNEL_WARN_SECONDS` (:data:`KERNEL_FLOPS`): a
    review's sigma=12 at 512^2 ran for many minutes without a word, within memory."""
    seconds = sum(float(n) ** 3 / 3.0 for n in sizes) / KERNEL_FLOPS
    if seconds > KERNEL_WARN_SECONDS:
        warn(f"kernel: {len(sizes):,} local fits of up to {max(sizes):,} unknowns (sigma "
             f"{sigma:g}, tile {max(tile, 2 * math.ceil(sigma))}, margin {margin}) take "
             f"about {seconds / 60:.0f} min or more (their factorizations alone, at the 2-core "
             "VM's rate); each fit's work grows as the sixth power of its window (tile + 2 "
             "ceil(sigma) + 2 margin): a smaller sigma, tile or margin, or the method dgp, is "
             "far faster")


def fit_tiles(gc, gr, known, inside, *, sigma, reg, tile, margin, progress=None, plan=None):
    """Tiled Gaussian-kernel fit on a box (see the module docstring).

    Parameters
    ----------
    gc, gr : (H, W) float
        Height derivatives along columns and rows (pixel units) at the known pixels.
    known, inside : (H, W) bool
        Pixels with a sample, and pixels where the height is wanted.
    progress : callable(groups done, share of the tiles fitted), optional
        Called in the calling thread as each group of tiles is fitted.
    plan : tuple, optional
        :func:`plan_tiles` of this box, where the caller has it.

    Returns
    -------
    z : (H, W) float
        Height at the `inside` pixels (0 elsewhere), any constant per connected piece.
    info : dict
    """
    t0 = time.perf_counter()
    H, W = inside.shape
    o = math.ceil(sigma)
    # (groups run on a thread pool with single-threaded BLAS: for many small Cholesky
    # factorisations a multi-threaded BLAS is slower, several times so on a loaded machine.
    # Results do not depend on scheduling: every tile is computed the same way and assembled
    # in order; only `workers` factors live at a time)
    specs, groups, _ = (plan_tiles(known, inside, sigma=sigma, tile=tile, margin=margin)
                        if plan is None else plan)
    fits = [np.zeros(inside[er, ec].shape) for _, (er, ec), _ in specs]

    def fit_group(members):
        _, _, (fr, fc) = specs[members[0]]
        kn = known[fr, fc]
        fac = _factor(kn, sigma, reg)
        # one triangular solve for the coefficients of all the group's tiles (BLAS-3), and
        # one evaluation matrix per distinct (blend pattern, offset): interior tiles share it
        rhs = np.empty((2 * int(kn.sum()), len(members)))
        for col, i in enumerate(members):
            _, _, (fr, fc) = specs[i]
            rhs[:, col] = np.concatenate([gc[fr, fc][kn], gr[fr, fc][kn]])
        coef = sla.cho_solve(fac, rhs, check_finite=False)
        layouts: dict = {}
        for col, i in enumerate(members):
            _, (er, ec), (fr, fc) = specs[i]
            ev = inside[er, ec]
            offset = (er.start - fr.start, ec.start - fc.start)
            layouts.setdefault((ev.shape, ev.tobytes(), offset), []).append(col)
        for (_, _, offset), cols in layouts.items():
            _, (er, ec), _ = specs[members[cols[0]]]
            ev = inside[er, ec]
            values = _evaluation(kn, ev, offset, sigma) @ coef[:, cols]
            for j, col in enumerate(cols):
                fits[members[col]][ev] = values[:, j]
        return len(members)

    workers = max(1, min(len(groups), cores(), 8))
    with single_blas_thread(), ThreadPoolExecutor(workers) as pool:
        done, total = 0, max(sum(len(m) for m in groups.values()), 1)
        for k, count in enumerate(pool.map(fit_group, groups.values()), 1):
            done += count
            if progress is not None:
                progress(k, done / total)
    pieces = []  # per tile: (slices of its blend region, piece node ids, f, weights)
    n_nodes = 0
    for ((lo_r, hi_r, lo_c, hi_c), (er, ec), _), f in zip(specs, fits, strict=True):
        ev = inside[er, ec]
        labels, n = ndi.label(ev, structure=_EIGHT)
        w = np.outer(_ramp(er, lo_r, hi_r, o, H), _ramp(ec, lo_c, hi_c, o, W))
        pieces.append((er, ec, labels + (n_nodes - 1), f, w * ev))
        n_nodes += n
    t1 = time.perf_counter()
    z = _blend(pieces, n_nodes, (H, W))
    info = {
        "tiles": len(pieces),
        "factorizations": len(groups),
        "seconds": {"fit": t1 - t0, "blend": time.perf_counter() - t1},
    }
    return z, info


#: Flops per second of the kernel fits' factorizations, measured on the 2-core VM (the
#: analytic vase at 512^2, sigma 2 / 3 / 4: (2n)^3 / 3 summed over the distinct fits, 4.6e10 /
#: 1.8e11 / 5.8e11, in 2.7 / 7.6 / 21.7 s: 17-27 GFlop/s with the rest of the run), taken at
#: the fast end so that the estimate is a lower bound.
KERNEL_FLOPS = 3.0e10

#: A kernel fit estimated (:data:`KERNEL_FLOPS`) to take longer than this is warned about
#: before it starts (a review: sigma=12 at 512^2, about 1.9e14 flops, ran past a minute with no
#: word, within memory).
KERNEL_WARN_SECONDS = 120.0


def _factor(known, sigma, reg):
    """Cholesky factor of the (2n, 2n) Gram matrix (cols then rows) of a window's samples."""
    kr, kc = np.nonzero(known)
    n = kr.size
    dr = (kr[:, None] - kr[None, :]).astype(float)
    dc = (kc[:, None] - kc[None, :]).astype(float)
    s2 = sigma**2
    # (built in place, in LAPACK's order: the Gram matrix and three (n, n) tables are the
    # peak, 56 n^2 bytes, which memory._kernel_tiles plans; each product's temporaries and
    # cho_factor's copy of a C-ordered matrix took it to about 80, an audit)
    k = dr * dr
    k += dc * dc
    k /= -2 * s2
    np.exp(k, out=k)
    k /= s2
    G = np.empty((2 * n, 2 * n), order="F")  # (LAPACK's order: factorized in place)
    for block, a, b in ((G[:n, :n], dc, dc), (G[n:, n:], dr, dr)):  # k (1 - d d / s2)
        np.multiply(a, b, out=block)
        block /= s2
        np.subtract(1.0, block, out=block)
        block *= k
    cross = G[:n, n:]  # -k (dr dc / s2)
    np.multiply(dr, dc, out=cross)
    cross /= s2
    cross *= k
    np.negative(cross, out=cross)
    G[n:, :n] = cross
    del dr, dc, k
    G[np.diag_indices_from(G)] += reg / s2
    try:
        return sla.cho_factor(G, lower=True, overwrite_a=True, check_finite=False)
    except np.linalg.LinAlgError as e:
        raise linalg.SolverError(
            f"kernel Gram matrix of {n} samples is not positive definite at "
            f"sigma={sigma}, reg={reg}: increase `reg` ({e})"
        ) from None


def _evaluation(known, ev, offset, sigma):
    """(|ev|, 2n) matrix taking a window's coefficients (cols then rows) to the height at its
    `ev` blend pixels: ``f(x) = sum_j a_j dk(x, x_j)/dx'_c + b_j dk(x, x_j)/dx'_r``, with
    ``dk/dx' = (d / sigma^2) k``."""
    kr, kc = np.nonzero(known)
    er, ec = np.nonzero(ev)
    dr = (er + offset[0])[:, None] - kr[None, :]
    dc = (ec + offset[1])[:, None] - kc[None, :]
    k = np.exp(-(dr * dr + dc * dc) / (2 * sigma**2)) / sigma**2
    return np.concatenate([k * dc, k * dr], axis=1)


def _ramp(sl, lo, hi, o, n):
    """1-D partition-of-unity weight of a core [lo, hi) over the blend slice `sl`."""
    x = np.arange(sl.start, sl.stop) + 0.5
    if o == 0:
        return np.ones(x.size)
    up = np.ones(x.size) if lo == 0 else _smoothstep((x - (lo - o)) / (2 * o))
    down = np.ones(x.size) if hi == n else _smoothstep(((hi + o) - x) / (2 * o))
    return up * down


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _blend(pieces, n_nodes, shape):
    """Choose one constant per tile piece by least squares on the overlaps, then blend."""
    H, W = shape
    layers = pieces
    wsum = np.zeros(shape)
    for er, ec, _, _, w in layers:
        wsum[er, ec] += w
    # Stack, for every pixel, the (node, f, w) of each tile covering it (at most 4 with
    # o <= tile / 2), then accumulate the weighted graph Laplacian of pairwise differences.
    rows, cols, vals, rhs = [], [], [], np.zeros(n_nodes)
    stack_node = np.full((4,) + shape, -1, dtype=np.int64)
    stack_f = np.zeros((4,) + shape)
    stack_w = np.zeros((4,) + shape)
    level = np.zeros(shape, dtype=np.int64)
    for er, ec, node, f, w in layers:
        sel = w > 0
        lv = level[er, ec]
        rr, cc = np.nonzero(sel)
        if lv[sel].max(initial=0) >= 4:  # pragma: no cover - guarded by o <= tile / 2
            raise RuntimeError("more than four tiles overlap a pixel")
        stack_node[lv[sel], rr + er.start, cc + ec.start] = node[sel]
        stack_f[lv[sel], rr + er.start, cc + ec.start] = f[sel]
        stack_w[lv[sel], rr + er.start, cc + ec.start] = w[sel]
        level[er, ec] += sel
    for a in range(4):
        for b in range(a + 1, 4):
            both = (stack_node[a] >= 0) & (stack_node[b] >= 0)
            if not both.any():
                continue
            na, nb = stack_node[a][both], stack_node[b][both]
            ww = stack_w[a][both] * stack_w[b][both] / wsum[both] ** 2
            d = stack_f[a][both] - stack_f[b][both]  # want c_a - c_b = -d
            rows += [na, nb, na, nb]
            cols += [na, nb, nb, na]
            vals += [ww, ww, -ww, -ww]
            rhs += np.bincount(nb, ww * d, n_nodes) - np.bincount(na, ww * d, n_nodes)
    c = np.zeros(n_nodes)
    if rows:
        L = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(n_nodes, n_nodes),
        )
        n_comp, comp = csgraph.connected_components(L, directed=False)
        first = np.unique(comp, return_index=True)[1]
        free = np.ones(n_nodes, dtype=bool)
        free[first] = False  # pin one constant per group of overlapping pieces
        if free.any():
            Lf = L[free][:, free].tocsc()
            c[free] = spla.spsolve(Lf, rhs[free])
    z = np.zeros(shape)
    for er, ec, node, f, w in layers:
        sel = w > 0
        z[er, ec] += np.where(sel, w * (f + c[np.maximum(node, 0)]), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(wsum > 0, z / wsum, 0.0)
