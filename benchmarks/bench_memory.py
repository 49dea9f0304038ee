"""Peak memory of every method and route against facetlift.memory's estimate.

Each case runs in its own subprocess: the input is built, the peak-RSS counter is reset
(``/proc/self/clear_refs``), ``facetlift.integrate`` runs, and the job's own peak is
``VmHWM - VmRSS before``, the quantity :func:`facetlift.memory.estimate` predicts. The
coefficients of :data:`facetlift.memory.COEFFICIENTS` were fitted to this script's output
(docs/benchmarks.md, "Memory planning").

Usage::

    .venv/bin/python benchmarks/bench_memory.py --sizes 256,512,1024 --json mem.jsonl
    .venv/bin/python benchmarks/bench_memory.py --cases dgp:disk:smooth --sizes 2048
    .venv/bin/python benchmarks/bench_memory.py --cases dgp:rect:missing --sizes 4096 --retain
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: method:shape:route[:option=value,...]
CASES = (
    "dgp:rect:smooth", "dgp:disk:smooth", "dgp:disk:missing", "dgp:rect:missing",
    "dgp:disk:smooth:solver=iterative,max_iter=3", "dgp:rect:smooth:solver=iterative,max_iter=3",
    "poisson:disk:smooth", "m_estimator:disk:smooth:max_iter=2", "alpha_surface:disk:smooth",
    "regularization:disk:smooth", "diffusion:disk:smooth", "frankot_chellappa:disk:smooth",
    "kernel:disk:smooth",
)


def _status(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return 0


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _as_list(v) -> list:
    """CG iterations as a list: routes report one count, a list, or none."""
    if v is None:
        return []
    return list(v) if isinstance(v, (list, tuple)) else [v]


def run_case(case: str, s: int) -> dict:
    import gc

    import facetlift
    from facetlift import memory
    from facetlift.problem import prepare

    sys.path.insert(0, str(HERE))
    from bench_masks import inputs

    method, shape, route, *rest = case.split(":")
    opts = dict((kv.split("=", 1)[0], _value(kv.split("=", 1)[1]))
                for kv in (rest[0].split(",") if rest else []))
    normals, mask, K = inputs(shape, s, route)
    eps = None
    if route == "discontinuities":
        opts["discontinuities"] = True
        from facetlift.methods import get as method_info

        eps = method_info(method).jump_grazing  # as facetlift.integrate applies it
    # (the Problem without facetlift.prepare's input checks, whose freed temporaries the
    # heap would keep and the solve reuse: its measured peak fell 20-40 % at 256^2, below
    # what a fresh process's is)
    problem = prepare(normals, mask, pixel_size=1.0 / s if K is None else 1.0, K=K,
                      outlier_eps=eps)
    del normals
    gc.collect()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current RSS
    before = _status("VmRSS")
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # an explicit limit: measure every route, also beyond a method's size limit
        surf = facetlift.solve(problem, method, max_memory=memory.default_limit(), **opts)
    seconds = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    peak = _status("VmHWM") - before
    from facetlift import methods as _m
    from facetlift.options import validate

    values = validate(_m.get(method).specs(), opts, method)
    est, which = memory.estimate(problem, method, values)
    d = problem.domain
    return {"case": case, "size": s, "m": d.n_facets, "n": d.n_vertices, "seconds": seconds,
            "peak_mib": peak / 2**20, "estimate_mib": est / 2**20, "route": which,
            "ratio": est / peak if peak else None, "backend": surf.info.get("backend"),
            # CPU time in the process and in the kernel on its behalf (page faults: on a VM
            # whose host reclaims free memory, first-touching 1 GiB costs seconds here)
            "user_s": cpu1.ru_utime - cpu0.ru_utime, "sys_s": cpu1.ru_stime - cpu0.ru_stime,
            # the iterating routes (the discontinuity reweightings): count and CG iterations
            "iterations": surf.info.get("iterations"),
            "cg_iterations": int(sum(_as_list(surf.info.get("cg_iterations"))))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="256,512,1024")
    ap.add_argument("--cases", default=";".join(CASES),
                    help="';'-separated method:shape:route[:opt=val,...]")
    ap.add_argument("--json", help="append results here (one JSON per line)")
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--retain", action="store_true",
                    help="keep freed memory in each case's process, as the facetlift command "
                    "does (facetlift.memory.retain_freed_memory)")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        if args.retain:
            from facetlift.memory import retain_freed_memory

            if not retain_freed_memory():
                print("--retain: not applied (not Linux/glibc, MALLOC_* or LD_PRELOAD set, or "
                      "refused)", file=sys.stderr)
        case, s = args.case.rsplit("@", 1)
        print(json.dumps(run_case(case, int(s))))
        return 0
    print("| case | size | mask px | peak MiB | estimate MiB | estimate / peak | route | s | "
          "user / sys s | iterations (CG) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in (int(x) for x in args.sizes.split(",")):
        for case in args.cases.split(";"):
            cmd = [sys.executable, __file__, "--case", f"{case}@{s}"] + (
                ["--retain"] if args.retain else [])
            try:
                res = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
                r = json.loads(res.stdout.strip().splitlines()[-1]) if res.returncode == 0 \
                    else {"case": case, "size": s, "error": res.stderr.strip()[-200:]}
            except subprocess.TimeoutExpired:
                r = {"case": case, "size": s, "error": "timeout"}
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(r) + "\n")
            if "error" in r:
                print(f"| {case} | {s}² | failed: {r['error'][-100:]} |", flush=True)
                continue
            print(f"| {case} | {s}² | {r['m']:,} | {r['peak_mib']:,.0f} | "
                  f"{r['estimate_mib']:,.0f} | {r['ratio']:.2f} | {r['route']} | "
                  f"{r['seconds']:.1f} | {r['user_s']:.1f} / {r['sys_s']:.1f} | "
                  f"{r.get('iterations')} ({r.get('cg_iterations')}) |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
