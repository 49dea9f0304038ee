"""DGP on DiLiGenT-format perspective data (the bear): accuracy (MADE) and time, beside BiNI.

Loads a folder in the BiNI/DiLiGenT layout (``normal_map.png`` RGB decoded at its stored bit
depth as BiNI does with ``cv2.IMREAD_UNCHANGED``: ``n = v / vmax * 2 - 1`` with vmax 255 or
65535, then renormalised; R = x right, G = y up, B = z toward the camera; ``mask.png``;
``K.txt`` in the OpenCV layout; ``depth_gt.npz['depth_gt']`` z-depth in mm). The bear's
``normal_map.png`` is a 16-bit PNG (IHDR bit depth 16), although ../shared/data/SOURCES.md
calls it 8-bit: PIL (and imageio through it) silently keep only the high byte. The table
therefore also shows the discontinuity-preserving run on that truncated 8-bit reading.
runs the perspective DGP method without and with ``discontinuities=True`` and evaluates
exactly as BiNI's ``evaluation_diligent.py``: ``scale = nanmedian(gt / est)`` over the mask,
``MADE = nanmean(|scale * est - gt|)`` over the mask (mm).

Time: wall clock of ``facetlift.integrate`` (input checks, solve and Surface), the median of
``--repeat`` runs after one warm-up call (so first-call imports are excluded); the process
CPU time of the same calls is printed beside it, because on a shared machine the wall clock
also measures the other processes.

Usage::

    .venv/bin/python benchmarks/bench_diligent.py OUT_DIR
    .venv/bin/python benchmarks/bench_diligent.py OUT_DIR --data PATH/TO/diligent_bear --k 0.3

Writes ``OUT_DIR/<name>_error.png`` (absolute error maps, mm) and ``OUT_DIR/<name>.json``.

``--meshes DIR`` adds DiLiGenT-like synthetic scenes: every ``*.ply`` in DIR rendered by a
perspective camera like DiLiGenT's (f = 3770 px, 512 x 612, object ~300 px wide at 1500 mm,
front view), z-depth and the hit triangle's normal at the pixel centres (exactly consistent
with the depth), normals quantised to 8 bits as in the PNGs; MADE in the same units (mm).
A check that the defaults carry over to objects they were not chosen on.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "normal_maps" / \
    "diligent_bear"

TARGET_MADE = 0.30  # mm
TARGET_SECONDS = 0.75
BINI = {"made": 0.334, "seconds": 1.5}  # bear, k=2, perspective (BiNI repo, 2-core machine)


def load(folder: Path, *, high_byte: bool = False):
    """(normals (H, W, 3), mask (H, W) bool, K (3, 3), depth_gt (H, W) mm).

    ``high_byte=True`` reads the normal map as PIL/imageio do (8 bits, the high byte of a
    16-bit file) instead of at its stored depth.
    """
    import imagecodecs

    path = folder / "normal_map.png"
    if high_byte:  # (only to read as PIL/imageio do; the rest needs neither)
        try:
            import imageio.v3 as iio
        except ImportError:
            raise SystemExit("high_byte needs imageio: pip install -e '.[bench]'") from None
        rgb = iio.imread(path)
    else:
        rgb = imagecodecs.png_decode(path.read_bytes())
    if rgb.dtype not in (np.uint8, np.uint16) or rgb.ndim != 3:
        raise ValueError(f"{path}: expected 8- or 16-bit RGB; got {rgb.dtype} {rgb.shape}")
    n = rgb[..., :3].astype(np.float64) / np.iinfo(rgb.dtype).max * 2 - 1
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    mask = imagecodecs.png_decode((folder / "mask.png").read_bytes())
    if mask.ndim == 3:
        mask = mask[..., 0]
    mask = mask > 127
    K = np.loadtxt(folder / "K.txt")
    gt = np.load(folder / "depth_gt.npz")["depth_gt"].astype(np.float64)
    return n, mask, K, gt


def render_perspective(path, *, H=512, W=612, f=3770.0, distance=1500.0, width_px=300):
    """(normals (H, W, 3) 8-bit quantised, mask, K, depth) of a mesh seen in perspective."""
    import trimesh

    m = trimesh.load(path, force="mesh")
    V = np.asarray(m.vertices, float)
    V = V - (V.max(0) + V.min(0)) / 2
    V *= width_px / f * distance / (V.max(0) - V.min(0))[:2].max()
    # mesh x right / y up / z toward the viewer -> OpenCV camera frame, object at `distance`
    mesh = trimesh.Trimesh(V * [1, -1, -1] + [0, 0, distance], m.faces, process=False)
    K = np.array([[f, 0, W / 2 - 0.3], [0, f, H / 2 + 0.125], [0, 0, 1]])
    rr, cc = np.mgrid[0:H, 0:W]
    rays = np.stack([cc.ravel(), rr.ravel(), np.ones(H * W)], 1) @ np.linalg.inv(K).T
    dirs = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError:  # pragma: no cover
        from trimesh.ray.ray_triangle import RayMeshIntersector
    tri, idx, loc = RayMeshIntersector(mesh).intersects_id(
        np.zeros_like(dirs), dirs, multiple_hits=False, return_locations=True
    )
    nn = np.array(mesh.face_normals[tri])  # exactly the normals of the rendered facets
    nn[(nn * dirs[idx]).sum(1) > 0] *= -1  # toward the camera
    depth = np.full(H * W, np.nan)
    depth[idx] = loc[:, 2]
    normals = np.full((H * W, 3), np.nan)
    normals[idx] = nn * [1, -1, -1]  # back to x right / y up / z toward the viewer
    normals = np.round((normals + 1) / 2 * 255) / 255 * 2 - 1  # 8-bit, as in the PNGs
    from facetlift import clean_mask

    mask = clean_mask(np.isfinite(depth.reshape(H, W)))
    return normals.reshape(H, W, 3), mask, K, depth.reshape(H, W)


def mesh_table(folder: Path, repeat: int):
    """MADE and CPU time of smooth / discontinuity-preserving DGP on rendered meshes."""
    import facetlift

    print(f"\nsynthetic perspective scenes from {folder} (8-bit normals, MADE in mm at 1.5 m)")
    print("| mesh | pixels | smooth MADE | discontinuities MADE | CPU s | detached |")
    print("|---|---|---|---|---|---|")
    rows = []
    for path in sorted(folder.glob("*.ply")):
        n, mask, K, gt = render_perspective(path)
        smooth = facetlift.integrate(n, mask, K=K, backfacing="outlier")
        sharp, _, cpu = run_case(n, mask, K, repeat, backfacing="outlier", discontinuities=True)
        m0, m1 = made(smooth.depth, gt, mask)[0], made(sharp.depth, gt, mask)[0]
        rows.append({"mesh": path.stem, "pixels": int(mask.sum()), "smooth_made": m0,
                     "made": m1, "cpu_s": cpu, "detached": sharp.info["detached"]})
        print(f"| {path.stem} | {int(mask.sum())} | {m0:.3f} | {m1:.3f} | {cpu:.2f} | "
              f"{sharp.info['detached']:.4f} |", flush=True)
    return rows


def made(est, gt, mask):
    """BiNI's MADE (mm) and the absolute error map."""
    scale = np.nanmedian(gt[mask] / est[mask])
    err = np.full(gt.shape, np.nan)
    err[mask] = np.abs(scale * est[mask] - gt[mask])
    return float(np.nanmean(err[mask])), err


def run_case(n, mask, K, repeat, **options):
    import facetlift

    facetlift.integrate(n, mask, K=K, **options)  # warm-up: imports, caches
    walls, cpus = [], []
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        surface = facetlift.integrate(n, mask, K=K, **options)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return surface, statistics.median(walls), statistics.median(cpus)


def write_error_png(path: Path, panels, mask):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from facetlift.io import atomic_path

    rows, cols = np.nonzero(mask)
    sl = np.s_[max(rows.min() - 5, 0): rows.max() + 6, max(cols.min() - 5, 0): cols.max() + 6]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.6))
    for ax, (title, err) in zip(np.atleast_1d(axes), panels, strict=True):
        im = ax.imshow(err[sl], cmap="jet", vmin=0, vmax=1.0)
        ax.set_title(title, fontsize=10)
        ax.axis("off")
        fig.colorbar(im, ax=ax, fraction=0.046, label="|error| (mm)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="output directory for the error map and JSON")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="DiLiGenT-format folder")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--k", type=float, default=None,
                    help="discontinuity_k (default: the method's default)")
    ap.add_argument("--meshes", type=Path, default=None,
                    help="also render every *.ply here as a DiLiGenT-like perspective scene")
    args = ap.parse_args(argv)
    if not (args.data / "depth_gt.npz").is_file():
        print(f"no DiLiGenT data at {args.data}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    name = args.data.name
    n, mask, K, gt = load(args.data)
    extra = {} if args.k is None else {"discontinuity_k": args.k}
    n8 = load(args.data, high_byte=True)[0]
    cases = [("dgp perspective", n, {}),
             ("dgp perspective + discontinuities", n, dict(discontinuities=True, **extra)),
             ("same, 8-bit (high byte) reading", n8, dict(discontinuities=True, **extra))]
    rows, panels = [], []
    for label, normals, options in cases:
        surface, wall, cpu = run_case(normals, mask, K, args.repeat, **options)
        m, err = made(surface.depth, gt, mask)
        info = surface.info
        rows.append({
            "case": label, "made_mm": m, "wall_s": wall, "cpu_s": cpu,
            "iterations": info.get("iterations"), "converged": info.get("converged"),
            "detached": info.get("detached"), "outliers": info.get("outliers"),
        })
        panels.append((f"{label}\nMADE {m:.3f} mm", err))
    write_error_png(args.out / f"{name}_error.png", panels, mask)
    meta = {
        "data": str(args.data), "pixels": int(mask.sum()), "shape": list(mask.shape),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "load_average": os.getloadavg(), "repeat": args.repeat, "rows": rows,
    }
    from facetlift.io import atomic_path

    with atomic_path(args.out / f"{name}.json") as tmp:
        tmp.write_text(json.dumps(meta, indent=2))

    print(f"{name}: {int(mask.sum())} pixels, {mask.shape[0]}x{mask.shape[1]}, "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    print(f"| case | MADE (mm) | wall s (median of {args.repeat}) | CPU s | reweightings "
          f"| MADE <= {TARGET_MADE} | wall <= {TARGET_SECONDS} s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        ok_m = "yes" if r["made_mm"] <= TARGET_MADE else "NO"
        ok_t = "yes" if r["wall_s"] <= TARGET_SECONDS else "NO"
        its = r["iterations"] if r["detached"] is not None else "-"
        print(f"| {r['case']} | {r['made_mm']:.3f} | {r['wall_s']:.3f} | {r['cpu_s']:.3f} | "
              f"{its} | {ok_m} | {ok_t} |")
    print(f"| BiNI (k=2), reference | {BINI['made']:.3f} | ~{BINI['seconds']} | | | | |")
    print(f"error map: {args.out / (name + '_error.png')}")
    if args.meshes is not None:
        meta["meshes"] = mesh_table(args.meshes, args.repeat)
        with atomic_path(args.out / f"{name}.json") as tmp:
            tmp.write_text(json.dumps(meta, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
