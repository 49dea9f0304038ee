"""Many small maps: `facetlift batch` against one Python process and a shell loop.

N normal maps of S x S pixels (a smooth wave plus a ridge, 16-bit PNG) are integrated three
ways, each writing depth.npy, mesh.ply and preview.png per map:

- ``batch``: ``facetlift batch DIR -o OUT --workers W`` (the Dask local scheduler, W processes);
- ``batch-1``: ``facetlift batch DIR -o OUT --workers 1`` (one process, no Dask);
- ``loop``: one ``facetlift integrate`` command per map from a shell loop.

    .venv/bin/python benchmarks/bench_batch.py --maps 100 --size 128 --workers 2
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import facetlift
from facetlift import io


def make_maps(folder: Path, n: int, size: int) -> None:
    r, c = np.indices((size, size)) + 0.5
    for i in range(n):
        p = 0.3 * np.cos(2 * np.pi * c / size + i) + np.where(c < size / 2, 0.2, -0.2)
        q = 0.2 * np.sin(2 * np.pi * r / size - i)
        io.write_normals(folder / f"map{i:03d}.png", facetlift.normals_from_gradients(p, q))


def timed(cmd, **kw) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, **kw)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=int, default=100)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the timings here")
    args = ap.parse_args()
    exe = str(Path(sys.executable).with_name("facetlift"))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        maps = tmp / "maps"
        maps.mkdir()
        make_maps(maps, args.maps, args.size)
        env = dict(os.environ)
        out = {}
        out["batch"] = timed([exe, "batch", str(maps), "-o", str(tmp / "b"), "--workers",
                              str(args.workers), "--no-progress"], env=env)
        out["batch-1"] = timed([exe, "batch", str(maps), "-o", str(tmp / "b1"), "--workers",
                                "1", "--no-progress"], env=env)
        loop = (f'for f in "{maps}"/*.png; do "{exe}" integrate "$f" '
                f'-o "{tmp}/l/$(basename "$f" .png)"; done')
        out["loop"] = timed(["bash", "-c", loop], env=env)
        a = np.load(tmp / "b" / "map007" / "depth.npy")
        b = np.load(tmp / "l" / "map007" / "depth.npy")
        assert np.allclose(a, b, equal_nan=True, atol=1e-12)
        shutil.rmtree(tmp / "l")
    per = {k: v / args.maps for k, v in out.items()}
    print(f"{args.maps} maps of {args.size}x{args.size}, {args.workers} workers, "
          f"{os.cpu_count()} CPUs")
    for k, v in out.items():
        print(f"  {k:8s} {v:7.1f} s  ({per[k] * 1000:6.0f} ms per map)")
    if args.json:
        Path(args.json).write_text(json.dumps({"seconds": out, "args": vars(args)}))


if __name__ == "__main__":
    main()
