"""Anisotropic diffusion: weighted least squares with a 2x2 diffusion tensor per pixel.

Equation
    ``div(D (grad z - g)) = 0``: the ECCV 2006 generalized equation with ``D1 = D2 = D``,
    a symmetric positive-definite tensor per pixel built from the gradient field. It is the
    Euler-Lagrange equation of ``integral (grad z - g)^T D (grad z - g)``, which is what is
    discretised here, so the system is symmetric positive definite and ``D = I`` is exactly
    :mod:`facetlift.methods.poisson`.

Diffusion tensor (edge-enhancing, Weickert)
    1. Structure tensor ``J = K_sigma * (g g^T)`` of the measured slopes ``g = (p, q)``
       (``x`` right, ``y`` up), smoothed by a Gaussian of `sigma` pixels (default 0.5) as a
       normalised convolution over the known samples inside the mask (nothing leaks in from
       outside the mask or from missing samples; pixels with no known sample nearby get
       ``J = 0``).
    2. Eigenvalues ``mu1 >= mu2`` and unit eigenvector ``v1`` of ``J`` (the dominant gradient
       direction; ``v1 = (1, 0)`` where ``J`` is isotropic).
    3. ``D = lam1 v1 v1^T + lam2 v2 v2^T`` with ``lam2 = 1`` along the level lines and, across
       them, ``lam1 = beta + (1 - beta) (1 - exp(-3.31488 / (mu1 / contrast^2)^4))`` (1 where
       ``mu1 = 0``): Weickert's edge-enhancing diffusivity with ``m = 4``. Where the surface is
       steep (slope above about `contrast`, default 1.0) the residual along the gradient
       direction is trusted ``beta`` (default 0.02) times less than along the level line.
    These defaults are those of the ECCV 2006 method as re-implemented in the public
    ``AD_integration.m`` (M. Di Martino, 2014, after Agrawal's thesis): sigma 0.5, contrast 1,
    beta 0.02. That code uses ``lam1 = beta + g(mu1)`` (between beta and 1 + beta); we use
    ``beta + (1 - beta) g(mu1)`` so that ``beta = 1`` is exactly the identity tensor.

Discretisation on the pixel graph (:mod:`facetlift.methods._graph`)
    Edge residuals ``r_e = z_head - z_tail - t_e``; at pixel ``P`` the x-residuals are its left
    and right data edges, the y-residuals are minus its up and down data edges (rows grow
    downward, ``y`` up). For every pairing of one x-edge ``a`` with one y-edge ``b`` at ``P``
    the energy gets ``[s_x r_a, -s_y r_b] D_P [s_x r_a, -s_y r_b]^T`` with
    ``s_x^2 = 1 / (2 n_y)`` and ``s_y^2 = 1 / (2 n_x)`` (``n_x``, ``n_y`` = number of x- and
    y-edges at ``P``; a missing side pairs with a zero residual). Each edge thus gets half of
    ``D_11`` (or ``D_22``) from each end, which is Poisson for ``D = I``, every term is
    positive semi-definite, and the null space is the constants. Pinch diagonals use the
    isotropic weight 1 and edges without data the fill weight, as in Poisson.

Masks and missing samples
    As :mod:`facetlift.methods.poisson` for the data term; the tensor is estimated from the
    known samples only.

Options
    Declared in :data:`OPTIONS`.

Reference
    A. Agrawal, R. Raskar, R. Chellappa. What is the range of surface reconstructions from a
    gradient field? ECCV 2006 (diffusion / affine transformation of the gradients).
    J. Weickert. Anisotropic Diffusion in Image Processing. Teubner, 1998.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from ..operators import graph as pg
from ..options import Option
from ..problem import Problem
from . import MethodResult
from . import _graph as g

#: Weickert's constant for the m = 4 edge-enhancing diffusivity.
C4 = 3.31488

OPTIONS = (
    Option("sigma", 0.5, "Gaussian of the structure tensor, in pixels", low=0.0),
    Option("contrast", 1.0, "slope contrast of the edge-enhancing diffusivity",
           low=0.0, low_open=True, high=1e100),
    Option("beta", 0.02, "smallest diffusivity across level lines", low=0.0, low_open=True,
           high=1.0),
    g.BACKEND,
    g.PROGRESS,
)


def tensor(problem: Problem, *, sigma: float = 0.5, contrast: float = 1.0, beta: float = 0.02):
    """Diffusion tensor per pixel: (D11, D12, D22), each (m,), in x-right / y-up axes."""
    d = problem.domain
    p, q = problem.slopes
    known = np.isfinite(p) & np.isfinite(q)
    pk = np.where(known, p, 0.0)
    qk = np.where(known, q, 0.0)
    w = d.to_image(known.astype(float), fill=0.0)
    prods = [d.to_image(v, fill=0.0) for v in (pk * pk, pk * qk, qk * qk)]
    if sigma > 0:
        # (taps beyond the image meet only the zeros around it, and J is a ratio of two
        # filtered images, so a kernel cut there gives the same tensor: sigma=1e6 on a 48^2
        # map took 65 s with its 8e6 taps, an audit)
        radius = min(int(4.0 * sigma + 0.5), max(w.shape))
        w = ndi.gaussian_filter(w, sigma, mode="constant", radius=radius)
        prods = [ndi.gaussian_filter(v, sigma, mode="constant", radius=radius) for v in prods]
    r, c = d.pixels
    wp = w[r, c]
    ok = wp > 1e-12
    j11, j12, j22 = (np.where(ok, v[r, c] / np.where(ok, wp, 1.0), 0.0) for v in prods)
    half = 0.5 * (j11 - j22)
    root = np.sqrt(half**2 + j12**2)
    mu1 = 0.5 * (j11 + j22) + root
    # dominant eigenvector, from whichever row of (J - mu1 I) is better conditioned
    vx = np.where(j11 >= j22, mu1 - j22, j12)
    vy = np.where(j11 >= j22, j12, mu1 - j11)
    nrm = np.hypot(vx, vy)
    iso = nrm <= 1e-300
    vx = np.where(iso, 1.0, vx / np.where(iso, 1.0, nrm))
    vy = np.where(iso, 0.0, vy / np.where(iso, 1.0, nrm))
    pos = mu1 > 0
    with np.errstate(over="ignore", divide="ignore"):
        ratio = np.where(pos, mu1 / contrast**2, 1.0)
        gdiff = np.where(pos, 1.0 - np.exp(-C4 / ratio**4), 1.0)
    lam1 = beta + (1.0 - beta) * gdiff
    lam2 = 1.0
    a = lam1 - lam2
    return lam2 + a * vx * vx, a * vx * vy, lam2 + a * vy * vy


def quadrant_form(graph: pg.PixelGraph, has: np.ndarray, D11, D12, D22) -> sp.csr_matrix:
    """(R, E) matrix Q with ``energy = ||Q r||^2`` for edge residuals r (module docstring)."""
    n = graph.n
    xs = [np.where((e >= 0) & has[np.maximum(e, 0)], e, -1) for e in (graph.left, graph.right)]
    ys = [np.where((e >= 0) & has[np.maximum(e, 0)], e, -1) for e in (graph.up, graph.down)]
    nx = (xs[0] >= 0).astype(int) + (xs[1] >= 0)
    ny = (ys[0] >= 0).astype(int) + (ys[1] >= 0)
    none = np.full(n, -1, dtype=np.int64)
    sx = np.sqrt(1.0 / (2.0 * np.maximum(ny, 1)))
    sy = np.sqrt(1.0 / (2.0 * np.maximum(nx, 1)))
    # Cholesky D = R^T R, R = [[ca, cb], [0, cc]]
    ca = np.sqrt(D11)
    cb = D12 / ca
    cc = np.sqrt(np.maximum(D22 - cb**2, 0.0))
    rows, cols, vals = [], [], []
    nrow = 0
    for ea, a_none in ((xs[0], False), (xs[1], False), (none, True)):
        for eb, b_none in ((ys[0], False), (ys[1], False), (none, True)):
            if a_none and b_none:
                continue
            act_a = (nx == 0) if a_none else (ea >= 0)
            act_b = (ny == 0) if b_none else (eb >= 0)
            pix = np.nonzero(act_a & act_b)[0]
            k = pix.size
            r1 = nrow + 2 * np.arange(k)
            r2 = r1 + 1
            if not a_none:
                rows.append(r1)
                cols.append(ea[pix])
                vals.append(ca[pix] * sx[pix])
            if not b_none:  # y-residual is minus the vertical edge residual
                rows += [r1, r2]
                cols += [eb[pix], eb[pix]]
                vals += [-cb[pix] * sy[pix], -cc[pix] * sy[pix]]
            nrow += 2 * k
    rows = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
    cols = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
    vals = np.concatenate(vals) if vals else np.zeros(0)
    return sp.csr_matrix((vals, (rows, cols)), shape=(nrow, graph.n_edges))


def run(problem, *, sigma, contrast, beta, backend, progress) -> MethodResult:
    """Integrate `problem` with an anisotropic diffusion tensor; heights (m,) at pixel centres."""
    t0 = time.perf_counter()
    domain, graph, t, has, _ = g.setup(problem)
    D11, D12, D22 = tensor(problem, sigma=float(sigma), contrast=float(contrast), beta=float(beta))
    Q = quadrant_form(graph, has, D11, D12, D22)
    G = pg.difference(graph)
    M = (Q @ G).tocsr()
    # edges outside the tensor form: pinch diagonals (weight 1) and edges without data
    w_extra = np.where(has, (graph.kind == pg.DIAGONAL).astype(float), g.FILL_WEIGHT)
    K = pg.pin(domain, (M.T @ M) + pg.laplacian(graph, w_extra))
    rhs = M.T @ (Q @ t) + pg.divergence(graph, w_extra * t)
    t1 = time.perf_counter()
    z = g.spd_solve(K, rhs, backend, kind="spd", progress=progress, grid=domain.pixels)
    t2 = time.perf_counter()
    lam1 = D11 + D22 - 1.0  # trace = lam1 + lam2, lam2 = 1
    info = {
        "iterations": 1,
        "converged": True,
        # share of pixels where the residual across the level lines counts less than half
        "anisotropic_fraction": float((lam1 < 0.5).mean()),
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return MethodResult(values=z, info=info)
