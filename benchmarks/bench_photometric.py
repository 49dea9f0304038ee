"""Time and peak memory of :func:`facetlift.photometric.fit` by image size and light count.

Each case runs in its own subprocess: Lambertian images of random front-facing normals under
lights within 40 degrees of the axis are built, then fitted; the subprocess reports the fit's
wall time, the process's peak resident memory (``ru_maxrss``: the images and the normals they
were rendered from included) and the images' own size.

Usage::

    .venv/bin/python benchmarks/bench_photometric.py --sizes 512,1024 --lights 20,96
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys


def case(size: int, lights: int) -> dict:
    import resource
    import time

    import numpy as np

    from facetlift import photometric

    rng = np.random.default_rng(0)
    n = np.dstack([rng.normal(0.0, 0.2, (size, size, 2)), np.ones((size, size))])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    L = photometric.lights_on_cap(lights, 40.0, rng)
    images = np.clip(np.einsum("hwi,ki->khw", n, L), 0.0, None)
    t = time.perf_counter()
    got, _ = photometric.fit(images, L)
    seconds = time.perf_counter() - t
    error = float(np.nanmax(np.abs(got - n)))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # (KiB on Linux)
    return {"size": size, "lights": lights, "seconds": round(seconds, 2),
            "peak_MiB": round(peak), "images_MiB": round(images.nbytes / 2**20),
            "max_error": error}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="512,1024", help="comma-separated image sides")
    ap.add_argument("--lights", default="20,96", help="comma-separated light counts")
    ap.add_argument("--case", default=None, help=argparse.SUPPRESS)  # (a subprocess's own)
    args = ap.parse_args(argv)
    if args.case:
        size, lights = map(int, args.case.split(","))
        print(json.dumps(case(size, lights)))
        return 0
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
        counts = [int(k) for k in args.lights.split(",")]
    except ValueError:
        ap.error("--sizes and --lights take comma-separated integers")
    print("| size | lights | fit s | peak MiB (process) | images MiB | max normal error |")
    print("|---|---|---|---|---|---|")
    for size in sizes:
        for lights in counts:
            out = subprocess.run([sys.executable, __file__, "--case", f"{size},{lights}"],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"| {r['size']}² | {r['lights']} | {r['seconds']} | {r['peak_MiB']:,} | "
                  f"{r['images_MiB']:,} | {r['max_error']:.1e} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
