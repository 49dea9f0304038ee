"""Speed and memory of the DGP method at growing sizes, beside the paper's Table 1.

Each (size, domain, solver) case runs in its own subprocess so that its peak memory (VmHWM /
ru_maxrss) is its own. Cases:

* ``direct``: one full ``facetlift.integrate`` call (input checks + set-up + solve), the
  default solver: the fixed point of the local/global loop in one solve.
* ``loop``: the paper's local/global loop (``solver="iterative"``): set-up, "factorization"
  (the global step's prepared solver) and the mean time of one iteration's local shaping and
  global blending, over ``--loop-iters`` iterations (the paper averages 50).

Domains: ``rect`` is the full s x s square (the paper's Table 1); ``disk`` a disk with a hole
(64% of the square), for the masked path.

The test surface is the one of ``../shared/notes/solver-bench.md``: 0.15 sin(2 pi u)
cos(1.5 pi v) plus a sharp square pyramid (height 0.35, half-width 0.45), exact gradients at
pixel centres.

Usage::

    .venv/bin/python benchmarks/bench_dgp.py                  # 128 .. 2048, markdown table
    .venv/bin/python benchmarks/bench_dgp.py --sizes 512 --json out.json
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
import warnings

import numpy as np

PAPER = {  # Table 1 of Xie et al. (ms): factorization, local step, global step
    128: (187, 0.62, 6.21),
    256: (905, 3.42, 25.2),
    512: (4961, 17.5, 101.8),
}
TARGETS = {512: (0.5, None), 2048: (10.0, 4096)}  # seconds for a full solve, MiB


def test_surface(s: int, domain: str):
    r, c = np.mgrid[0:s, 0:s]
    u = (c + 0.5) / s
    v = (r + 0.5) / s
    # height z(u, v) in units of the square's side; x = u, y = -v (rows go down)
    p = 0.15 * 2 * np.pi * np.cos(2 * np.pi * u) * np.cos(1.5 * np.pi * v)
    q = 0.15 * np.sin(2 * np.pi * u) * 1.5 * np.pi * np.sin(1.5 * np.pi * v)
    du, dv = u - 0.5, v - 0.5
    inside = np.maximum(np.abs(du), np.abs(dv)) < 0.45
    slope = 0.35 / 0.45
    xs = np.abs(du) >= np.abs(dv)
    p = p + np.where(inside & xs, -slope * np.sign(du), 0.0)
    q = q + np.where(inside & ~xs, slope * np.sign(dv), 0.0)
    mask = None
    if domain == "disk":
        disk = du**2 + dv**2 < 0.45**2
        mask = disk & ~((du**2 + (v - 1 / 3) ** 2) < 0.1**2)
    return p, q, mask


def run_case(s: int, domain: str, kind: str, loop_iters: int) -> dict:
    import facetlift
    from facetlift.methods import dgp

    p, q, mask = test_surface(s, domain)
    normals = facetlift.normals_from_gradients(p, q)
    out = {"size": s, "domain": domain, "kind": kind}
    if kind == "direct":
        t0 = time.perf_counter()
        surf = facetlift.integrate(normals, mask, pixel_size=1.0 / s)
        out["total_s"] = time.perf_counter() - t0
        sec = surf.info["seconds"]
        out["prepare_s"] = sec["prepare"]
        out["setup_s"] = sec["setup"]
        out["solve_s"] = sec["solve"]
        out["backend"] = surf.info.get("backend")
        out["cg_iterations"] = surf.info.get("cg_iterations")
    else:
        problem = facetlift.prepare(normals, mask, pixel_size=1.0 / s)
        bx, by, target = dgp.targets(problem)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, info = dgp.solve_iterative(
                problem.domain, bx, by, target, problem.camera.footprint(),
                max_iter=loop_iters, tol=0.0,
            )
        sec = info["seconds"]
        out["setup_s"] = sec["setup"]
        out["factorization_s"] = sec["factorization"]
        out["local_ms"] = 1e3 * sec["local"] / info["iterations"]
        out["global_ms"] = 1e3 * sec["global"] / info["iterations"]
        out["backend"] = info.get("backend")
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def spawn(s, domain, kind, loop_iters) -> dict:
    cmd = [sys.executable, __file__, "--case", f"{s},{domain},{kind}", "--loop-iters",
           str(loop_iters)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        return {"size": s, "domain": domain, "kind": kind, "error": res.stderr.strip()[-300:]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def median_case(s, domain, kind, loop_iters, repeat) -> dict:
    runs = [spawn(s, domain, kind, loop_iters) for _ in range(repeat)]
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return runs[0]
    out = dict(ok[0])
    for key, val in ok[0].items():
        if isinstance(val, float):
            out[key] = float(np.median([r[key] for r in ok]))
    return out


def fmt(x, scale=1.0, digits=1):
    return "–" if x is None else f"{x * scale:,.{digits}f}"


def markdown(results: list[dict]) -> str:
    lines = [
        "### Full solve (default `solver=\"direct\"`), one `facetlift.integrate` call",
        "",
        "| size | domain | total s | checks s | set-up s | solve s | route | CG its | peak MiB |"
        " target |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if r["kind"] != "direct":
            continue
        if "error" in r:
            lines.append(f"| {r['size']}² | {r['domain']} | failed: {r['error']} |")
            continue
        tgt = TARGETS.get(r["size"]) if r["domain"] == "rect" else None
        tgt_s = "–"
        if tgt:
            ok_t = r["total_s"] <= tgt[0]
            ok_m = tgt[1] is None or r["peak_mib"] <= tgt[1]
            tgt_s = f"≤ {tgt[0]} s" + (f", ≤ {tgt[1]} MiB" if tgt[1] else "")
            tgt_s += " **met**" if ok_t and ok_m else " **missed**"
        lines.append(
            f"| {r['size']}² | {r['domain']} | {fmt(r['total_s'], 1, 3)} | "
            f"{fmt(r['prepare_s'], 1, 3)} | {fmt(r['setup_s'], 1, 3)} | {fmt(r['solve_s'], 1, 3)}"
            f" | {r['backend']} | {r.get('cg_iterations') or '–'} | {fmt(r['peak_mib'], 1, 0)} |"
            f" {tgt_s} |"
        )
    lines += [
        "",
        "### The paper's loop (`solver=\"iterative\"`) beside Table 1 (ms)",
        "",
        "| size | domain | factorization | paper | local / step | paper | global / step | paper |"
        " global step route | peak MiB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if r["kind"] != "loop":
            continue
        if "error" in r:
            lines.append(f"| {r['size']}² | {r['domain']} | failed: {r['error']} |")
            continue
        paper = PAPER.get(r["size"]) if r["domain"] == "rect" else None
        pf, pl, pg = paper if paper else (None, None, None)
        lines.append(
            f"| {r['size']}² | {r['domain']} | {fmt(r['factorization_s'], 1e3)} | {fmt(pf)} | "
            f"{fmt(r['local_ms'], 1, 2)} | {fmt(pl, 1, 2)} | {fmt(r['global_ms'], 1, 2)} | "
            f"{fmt(pg, 1, 2)} | {r['backend']} | {fmt(r['peak_mib'], 1, 0)} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="128,256,512,1024,2048")
    ap.add_argument("--domains", default="rect,disk")
    ap.add_argument("--kinds", default="direct,loop")
    ap.add_argument("--repeat", type=int, default=3, help="runs per case (median)")
    ap.add_argument("--loop-iters", type=int, default=10)
    ap.add_argument("--json", help="also write the raw results here")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        s, domain, kind = args.case.split(",")
        print(json.dumps(run_case(int(s), domain, kind, args.loop_iters)))
        return 0
    results = []
    for s in (int(x) for x in args.sizes.split(",")):
        for domain in args.domains.split(","):
            for kind in args.kinds.split(","):
                # SuperLU on a 2048^2 masked loop is not a useful measurement (minutes, >10 GB)
                rep = 1 if s >= 2048 else args.repeat
                r = median_case(s, domain, kind, args.loop_iters, rep)
                results.append(r)
                print(json.dumps(r), file=sys.stderr, flush=True)
    print(markdown(results))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
