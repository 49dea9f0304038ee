"""facetlift demo: integrate an analytic normal map with creases, smooth parts and holes.

Run ``make demo`` or ``python examples/demo.py --out demo_output``. The script

1. builds a 4 x 4 (world units) scene analytically, with exact gradients at the pixel centres:
   a pyramid and a hip roof (sharp creases), a Gaussian bump (smooth), a tilted ground plane,
   a hole in the mask, and a second, separate component (a spherical cap inside a moat);
2. writes it as a 16-bit normal map PNG and a mask PNG (``input_normals.png``, ``input_mask.png``);
3. runs ``facetlift integrate`` on them through :func:`facetlift.cli.main`, writing
   ``depth.npy``, ``mesh.ply`` and ``preview.png`` into the output folder;
4. compares the reconstructed height with the analytic one (each component's mean removed).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import facetlift
from facetlift import io
from facetlift.cli import main as facetlift_main

EXTENT = 4.0  # the scene spans [0, 4] in x and [-4, 0] in y (world units)


def pyramid(dx, dy, half, slope):
    """Square pyramid: height, p, q; creases along the diagonals and around the base."""
    inside = np.maximum(np.abs(dx), np.abs(dy)) < half
    z = np.where(inside, slope * (half - np.maximum(np.abs(dx), np.abs(dy))), 0.0)
    xface = np.abs(dx) >= np.abs(dy)
    p = np.where(inside & xface, -slope * np.sign(dx), 0.0)
    q = np.where(inside & ~xface, -slope * np.sign(dy), 0.0)
    return z, p, q


def hip_roof(dx, dy, half_x, half_y, slope):
    """Hip roof over a rectangle: a ridge along x and four sloped faces."""
    ex, ey = half_x - np.abs(dx), half_y - np.abs(dy)
    inside = (ex > 0) & (ey > 0)
    z = np.where(inside, slope * np.minimum(ex, ey), 0.0)
    yface = ey <= ex
    p = np.where(inside & ~yface, -slope * np.sign(dx), 0.0)
    q = np.where(inside & yface, -slope * np.sign(dy), 0.0)
    return z, p, q


def gaussian(dx, dy, amplitude, sigma):
    z = amplitude * np.exp(-(dx**2 + dy**2) / (2 * sigma**2))
    return z, -z * dx / sigma**2, -z * dy / sigma**2


def scene(size: int):
    """Analytic scene on a size x size grid.

    Returns height (H, W), normals (H, W, 3), mask (H, W) bool, labels (H, W) int (component
    1 or 2, 0 outside) and the pixel size.
    """
    h = EXTENT / size
    r, c = np.mgrid[0:size, 0:size]
    x, y = (c + 0.5) * h, -(r + 0.5) * h  # pixel centres (facetlift.conventions)

    parts = [
        pyramid(x - 1.1, y + 1.3, half=0.75, slope=1.0),
        gaussian(x - 2.9, y + 1.3, amplitude=0.6, sigma=0.4),
        hip_roof(x - 1.8, y + 3.0, half_x=1.0, half_y=0.55, slope=0.6),
        (0.1 * x + 0.05 * y, np.full_like(x, 0.1), np.full_like(x, 0.05)),
    ]
    z = sum(part[0] for part in parts)
    p = sum(part[1] for part in parts)
    q = sum(part[2] for part in parts)

    # the second component: a spherical cap (radius 0.5) on a disc of radius 0.3 in a moat
    cx, cy = x - 3.45, y + 3.45
    rho2 = cx**2 + cy**2
    cap = rho2 < 0.3**2
    root = np.sqrt(np.maximum(0.5**2 - rho2, 1e-12))
    z = np.where(cap, root, z)
    p = np.where(cap, -cx / root, p)
    q = np.where(cap, -cy / root, q)

    # the main component: a square with rounded corners, minus a round hole and the moat
    m = 0.15
    ux = np.maximum(np.maximum(m + 0.3 - x, x - (EXTENT - m - 0.3)), 0)
    uy = np.maximum(np.maximum(m + 0.3 + y, -y - (EXTENT - m - 0.3)), 0)
    rounded = ux**2 + uy**2 < 0.3**2
    hole = (x - 2.05) ** 2 + (y + 2.2) ** 2 < 0.2**2
    moat = rho2 < 0.45**2
    main_part = rounded & ~hole & ~moat
    labels = np.where(main_part, 1, np.where(cap, 2, 0))
    normals = facetlift.normals_from_gradients(p, q)
    return z, normals, labels > 0, labels, h


def height_error(height, reference, labels) -> dict:
    """RMS and max error after removing each component's mean from both heights."""
    diff = np.zeros(np.count_nonzero(labels))
    sel = labels[labels > 0]
    a, b = height[labels > 0], reference[labels > 0]
    for k in np.unique(sel):
        on = sel == k
        diff[on] = (a[on] - a[on].mean()) - (b[on] - b[on].mean())
    span = float(np.ptp(b))
    return {"rms": float(np.sqrt(np.mean(diff**2))), "max": float(np.abs(diff).max()),
            "span": span}


def run(out: Path, size: int = 256, method: str = "dgp") -> dict:
    """Build the scene, integrate it with the CLI, print and return the height error."""
    out.mkdir(parents=True, exist_ok=True)
    height, normals, mask, labels, h = scene(size)
    npath = io.write_normals(out / "input_normals.png", normals, bits=16)
    mpath = io.write_mask(out / "input_mask.png", mask)
    print(f"facetlift demo: {size}x{size} analytic scene (pyramid, hip roof, Gaussian bump, "
          f"a hole and a second component), pixel size {h:g}")
    print(f"wrote {npath}\nwrote {mpath}")

    argv = ["integrate", str(npath), "--mask", str(mpath), "--pixel-size", repr(h),
            "--method", method, "-o", str(out), "--save", "npy", "--save", "ply",
            "--save", "png"]
    print("$ facetlift " + " ".join(argv))
    t0 = time.perf_counter()
    code = facetlift_main(argv)
    if code != 0:
        raise SystemExit(code)
    seconds = time.perf_counter() - t0

    depth = np.load(out / "depth.npy")
    err = height_error(-depth, height, labels)
    print(f"height error vs the analytic surface (per-component mean removed): "
          f"RMS {err['rms']:.3g}, max {err['max']:.3g} world units, "
          f"for a height range of {err['span']:.3g} "
          f"(RMS {100 * err['rms'] / err['span']:.2f}% of the range); {seconds:.2f} s")
    print(f"look at {out / 'preview.png'}; open {out / 'mesh.ply'} in a mesh viewer")
    return err


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("demo_output"),
                        help="output folder (default: demo_output)")
    parser.add_argument("--size", type=int, default=256, help="image size in pixels")
    parser.add_argument("--method", default="dgp", help="integration method")
    args = parser.parse_args(argv)
    if args.size < 16:
        parser.error("--size must be at least 16")
    run(args.out, args.size, args.method)
    return 0


if __name__ == "__main__":
    sys.exit(main())
