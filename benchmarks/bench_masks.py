"""Mask-shape suite: time, CG iterations, peak memory and growth of every DGP route on hard masks.

Shapes (s x s images):

* ``rect``: the full square; ``disk``: a disk with a hole (64 % of the square);
* ``torus``: an obliquely viewed torus rendered analytically (sphere tracing of the exact
  distance function, float64 normals): a silhouette whose normals graze the view (the paper's
  outlier rule removes a rim of them) and a self-occlusion inside;
* ``thin``: an Archimedean spiral 4 pixels wide (one long thin component);
* ``many``: a grid of disks of radius 6 pixels every 16 pixels ((s/16)^2 components);
* ``bear``, ``human``: the real masks of ../shared/data/normal_maps/diligent_bear and
  bini_human_ortho_real, padded to a square and upsampled (nearest neighbour).

Normals: the torus has its own; every other shape takes the surface of bench_dgp.py
(``0.15 sin(2 pi u) cos(1.5 pi v)`` plus a sharp pyramid) inside its mask.

Routes: ``smooth`` (every normal known), ``missing`` (30 % of the mask's normals NaN, seeded),
``perspective`` (the same normals seen by a pinhole camera with f = s pixels, the principal
point at the centre), ``discontinuities`` (``facetlift.integrate(..., discontinuities=True)``
through the public API only).

Each case runs in its own subprocess: a 64^2 warm-up of the same shape and route through
both sides (``--cold`` skips it; facetlift's warm-up time is reported as ``cold_s``),
``facetlift.integrate`` once, then, in the same process, a plain Poisson solve of the same
mask as a user would write it with scipy and pyamg (4-neighbour graph Laplacian of the mask,
divergence of the slopes, one pin per component,
``pyamg.smoothed_aggregation_solver(...).solve(..., accel="cg", tol=1e-8)``; BLAS held to one
thread, :func:`poisson_baseline`).
Reported: wall time, CG iterations, peak resident memory of the facetlift part (ru_maxrss
before the baseline runs; it includes the input arrays, 24-36 bytes per pixel), bytes per
mask pixel, and the time ratio facetlift / baseline. Growth exponents are fitted per
(shape, route) over the sizes run, in the number of mask pixels.

Usage::

    .venv/bin/python benchmarks/bench_masks.py --sizes 512,1024,2048 --json out.json
    .venv/bin/python benchmarks/bench_masks.py --shapes torus --routes smooth --sizes 4096
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[0] / ".." / "shared" / "data" / "normal_maps"
CACHE = Path(os.environ.get("FACETLIFT_BENCH_CACHE", "/tmp/facetlift-bench-cache"))
SHAPES = ("rect", "disk", "torus", "thin", "many", "bear", "human")
ROUTES = ("smooth", "missing", "perspective", "discontinuities")


def torus(s: int, R: float = 1.0, r: float = 0.42, tilt: float = np.radians(62)):
    """Orthographic normals (s, s, 3) float32 (NaN outside) and mask of a tilted torus."""
    ext = (R + r) * 1.08
    c, sn = np.cos(tilt), np.sin(tilt)
    rot = np.array([[1, 0, 0], [0, c, -sn], [0, sn, c]])  # object -> image frame
    xs = (np.arange(s) + 0.5) / s * 2 * ext - ext
    normals = np.full((s * s, 3), np.nan, dtype=np.float32)
    d = np.array([0.0, 0.0, -1.0]) @ rot
    chunk = 1 << 20
    for a in range(0, s * s, chunk):
        idx = np.arange(a, min(a + chunk, s * s))
        o = np.stack([xs[idx % s], -xs[idx // s], np.full(idx.size, 3.0)], 1) @ rot
        t = np.zeros(idx.size)
        alive = np.arange(idx.size)
        hit = np.zeros(idx.size, bool)
        for _ in range(400):  # sphere tracing with the exact distance to the torus
            p = o[alive] + t[alive, None] * d
            dist = np.hypot(np.hypot(p[:, 0], p[:, 1]) - R, p[:, 2]) - r
            t[alive] += dist
            done = dist < 1e-9
            hit[alive[done]] = True
            alive = alive[~(done | (t[alive] > 6.0))]
            if alive.size == 0:
                break
        h = np.nonzero(hit)[0]
        p = o[h] + t[h, None] * d
        k = 1 - R / np.hypot(p[:, 0], p[:, 1])
        g = np.stack([p[:, 0] * k, p[:, 1] * k, p[:, 2]], 1)
        g /= np.linalg.norm(g, axis=1, keepdims=True)
        normals[idx[h]] = (g @ rot.T).astype(np.float32)
    normals = normals.reshape(s, s, 3)
    return normals, np.isfinite(normals[..., 0]) & (normals[..., 2] > 0)


def _real_mask(name: str, s: int) -> np.ndarray:
    import scipy.ndimage as ndi

    from facetlift import io

    folder = {"bear": "diligent_bear", "human": "bini_human_ortho_real"}[name]
    m = io.read_mask(DATA / folder / "mask.png")
    H, W = m.shape
    n = max(H, W)
    sq = np.zeros((n, n), bool)
    sq[(n - H) // 2 : (n - H) // 2 + H, (n - W) // 2 : (n - W) // 2 + W] = m
    rows = (np.arange(s) * n) // s  # nearest neighbour
    out = sq[rows][:, rows]
    return ndi.binary_opening(out) if s < n else out


def mask_of(shape: str, s: int) -> np.ndarray | None:
    r, c = np.mgrid[0:s, 0:s]
    u, v = (c + 0.5) / s - 0.5, (r + 0.5) / s - 0.5
    if shape == "rect":
        return None
    if shape == "disk":
        return (u**2 + v**2 < 0.45**2) & ~((u**2 + (v + 0.5 - 1 / 3) ** 2) < 0.1**2)
    if shape == "thin":  # Archimedean spiral, 4 px wide, 16 px pitch
        x, y = c - s / 2 + 0.5, r - s / 2 + 0.5
        rad, ang = np.hypot(x, y), np.arctan2(y, x)
        phase = (rad - 16 * ang / (2 * np.pi)) % 16
        return (phase < 4) & (rad < 0.48 * s) & (rad > 8)
    if shape == "many":
        return ((c % 16 - 7.5) ** 2 + (r % 16 - 7.5) ** 2) < 36
    return _real_mask(shape, s)


def inputs(shape: str, s: int, route: str):
    """(normals (s, s, 3) float64, mask or None, K or None)."""
    import facetlift

    if shape == "torus":
        CACHE.mkdir(parents=True, exist_ok=True)
        f = CACHE / f"torus_{s}.npy"
        if not f.exists():
            np.save(f, torus(s)[0])
        normals = np.load(f).astype(float)
        mask = np.isfinite(normals[..., 0]) & (normals[..., 2] > 0)
    else:
        sys.path.insert(0, str(HERE))
        from bench_dgp import test_surface

        p, q, _ = test_surface(s, "rect")
        normals = facetlift.normals_from_gradients(p, q)
        del p, q
        mask = mask_of(shape, s)
    if mask is not None:
        mask = facetlift.clean_mask(mask)
    K = None
    if mask is None and route == "missing":  # the default mask would drop the NaN pixels
        mask = np.ones((s, s), bool)
    if route == "missing":
        rng = np.random.default_rng(7)
        normals[rng.random((s, s)) < 0.3] = np.nan
    if route == "perspective":
        K = np.array([[s, 0, s / 2], [0, s, s / 2], [0, 0, 1.0]])
    return normals, mask, K


def poisson_baseline(normals: np.ndarray, mask: np.ndarray | None) -> dict:
    """A plain scipy + pyamg Poisson solve of the same mask (what a user would write), with
    BLAS held to one thread: pyamg's CG takes its norms and dots through BLAS, and on this
    2-core VM a call that hands work to a second, sleeping BLAS thread waits for it to wake.
    After two idle seconds the bear mask's 512^2 solve took 0.74-0.96 s instead of 0.12-0.15 s
    (the same 14 iterations; in the suite it runs after the slower input preparation), which
    flattered facetlift's ratio; held to one thread it took 0.12-0.15 s either way."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _poisson(normals, mask)


def _poisson(normals: np.ndarray, mask: np.ndarray | None) -> dict:
    import pyamg
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csgraph

    t0 = time.perf_counter()
    s = normals.shape[0]
    m = np.ones((s, s), bool) if mask is None else mask
    ok = m & np.isfinite(normals).all(-1) & (normals[..., 2] > 1e-3)
    p = np.where(ok, -normals[..., 0] / np.where(ok, normals[..., 2], 1), 0.0)
    q = np.where(ok, -normals[..., 1] / np.where(ok, normals[..., 2], 1), 0.0)
    idx = -np.ones((s, s), np.int64)
    idx[m] = np.arange(int(m.sum()))
    n = int(m.sum())
    hm = m[:, :-1] & m[:, 1:]
    vm = m[:-1, :] & m[1:, :]
    i = np.concatenate([idx[:, :-1][hm], idx[:-1, :][vm]])
    j = np.concatenate([idx[:, 1:][hm], idx[1:, :][vm]])
    t = np.concatenate([(0.5 * (p[:, :-1] + p[:, 1:]))[hm], (-0.5 * (q[:-1, :] + q[1:, :]))[vm]])
    G = sp.csr_matrix((np.r_[-np.ones(i.size), np.ones(i.size)],
                       (np.r_[np.arange(i.size), np.arange(i.size)], np.r_[i, j])),
                      shape=(i.size, n))
    L = (G.T @ G).tocsr()
    b = G.T @ t
    ncomp, lab = csgraph.connected_components(L, directed=False)
    first = np.unique(lab, return_index=True)[1]
    L = L + sp.csr_matrix((np.ones(first.size), (first, first)), shape=(n, n))
    t1 = time.perf_counter()
    ml = pyamg.smoothed_aggregation_solver(L)
    res = []
    ml.solve(b, tol=1e-8, accel="cg", residuals=res, maxiter=500)
    t2 = time.perf_counter()
    return {"baseline_s": t2 - t0, "baseline_setup_s": t1 - t0, "baseline_its": len(res) - 1}


#: Side of the warm-up case (the same shape and route) that each process integrates, and
#: solves with the baseline, before either is timed (``--cold`` skips it).
WARM_SIZE = 64


def _integrate(facetlift, normals, mask, K, s: int, route: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return facetlift.integrate(normals, mask, pixel_size=1.0 / s if K is None else 1.0, K=K,
                                   discontinuities=route == "discontinuities")


def run_case(shape: str, s: int, route: str, baseline: bool, warm: bool = True) -> dict:
    """One case in this process. With `warm`, both sides first run a :data:`WARM_SIZE` case of
    the same shape and route: the first call of a process pays one-time costs (lazy imports
    of scipy.sparse.linalg, scipy.fft, scipy.ndimage and pyamg, first-use caches: 0.1-0.2 s
    on a 512^2 map) that the baseline, run second, did not pay; ``cold_s`` is facetlift's
    warm-up call."""
    import facetlift

    out = {"shape": shape, "size": s, "route": route, "warm": warm}
    if warm:
        n0, m0, K0 = inputs(shape, WARM_SIZE, route)
        t0 = time.perf_counter()
        _integrate(facetlift, n0, m0, K0, WARM_SIZE, route)
        out["cold_s"] = time.perf_counter() - t0
        if baseline:
            poisson_baseline(n0, m0)
    normals, mask, K = inputs(shape, s, route)
    out["pixels"] = int(s * s if mask is None else mask.sum())
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    surf = _integrate(facetlift, normals, mask, K, s, route)
    out["total_s"] = time.perf_counter() - t0
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["input_mib"] = before
    info = surf.info
    cg = info.get("cg_iterations")
    out["cg_iterations"] = int(np.sum(cg)) if cg is not None else None
    out["backend"] = info.get("backend", info.get("solver"))
    out["seconds"] = info.get("seconds", {})
    del surf
    if baseline:
        out.update(poisson_baseline(normals, mask))
    return out


def spawn(shape, s, route, baseline, timeout, warm: bool = True) -> dict:
    cmd = [sys.executable, __file__, "--case", f"{shape},{s},{route},{int(baseline)},{int(warm)}"]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"shape": shape, "size": s, "route": route, "error": f"timeout {timeout} s"}
    if res.returncode != 0:
        return {"shape": shape, "size": s, "route": route, "error": res.stderr.strip()[-300:]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def exponents(results: list[dict]) -> dict:
    """Least-squares slope of log(time) over log(mask pixels), per (shape, route)."""
    out = {}
    keys = {(r["shape"], r["route"]) for r in results if "error" not in r}
    for key in sorted(keys):
        rs = sorted((r for r in results if (r["shape"], r["route"]) == key and "error" not in r),
                    key=lambda r: r["size"])
        rs = [r for r in rs if r["size"] >= 512]
        if len(rs) >= 2:
            x = np.log([r["pixels"] for r in rs])
            y = np.log([r["total_s"] for r in rs])
            out[key] = float(np.polyfit(x, y, 1)[0])
    return out


def markdown(results: list[dict]) -> str:
    lines = [
        "| shape | route | size | mask px | total s | CG its | peak MiB | B/px | baseline s |"
        " ratio | route taken |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if "error" in r:
            lines.append(f"| {r['shape']} | {r['route']} | {r['size']}² | failed: "
                         f"{r['error'][-120:]} |")
            continue
        base = r.get("baseline_s")
        ratio = f"{r['total_s'] / base:.2f}" if base else "–"
        bpp = r["peak_mib"] * 2**20 / r["pixels"]
        lines.append(
            f"| {r['shape']} | {r['route']} | {r['size']}² | {r['pixels']:,} | "
            f"{r['total_s']:.2f} | {r.get('cg_iterations') or '–'} | {r['peak_mib']:,.0f} | "
            f"{bpp:.0f} | {'–' if base is None else f'{base:.2f}'} | {ratio} | {r['backend']} |"
        )
    ex = exponents(results)
    if ex:
        lines += ["", "| shape | route | growth exponent (time vs mask pixels) |", "|---|---|---|"]
        lines += [f"| {k[0]} | {k[1]} | {v:.2f} |" for k, v in ex.items()]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="512,1024,2048")
    ap.add_argument("--shapes", default=",".join(SHAPES))
    ap.add_argument("--routes", default="smooth,missing,perspective")
    ap.add_argument("--baseline-routes", default="smooth,missing,perspective",
                    help="routes that also run the scipy + pyamg Poisson baseline ('' for none)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per case (median time)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per case")
    ap.add_argument("--cold", action="store_true",
                    help="time each case's first call in its process (no warm-up; the "
                         "baseline, run second, is then warm)")
    ap.add_argument("--json", help="append the raw results to this file (one JSON per line)")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        shape, s, route, base, warm = args.case.split(",")
        print(json.dumps(run_case(shape, int(s), route, bool(int(base)), bool(int(warm)))))
        return 0
    results = []
    for s in (int(x) for x in args.sizes.split(",")):
        for shape in args.shapes.split(","):
            for route in args.routes.split(","):
                base = route in args.baseline_routes.split(",")
                runs = [spawn(shape, s, route, base, args.timeout, not args.cold)
                        for _ in range(args.repeat)]
                ok = [r for r in runs if "error" not in r]
                r = dict(ok[0]) if ok else runs[0]
                for key in ("total_s", "baseline_s"):
                    if ok and key in r:
                        r[key] = float(np.median([x[key] for x in ok]))
                r["load"] = os.getloadavg()
                results.append(r)
                print(json.dumps(r), file=sys.stderr, flush=True)
                if args.json:
                    with open(args.json, "a") as f:
                        f.write(json.dumps(r) + "\n")
    print(markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
