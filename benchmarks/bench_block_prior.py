"""A coarse prior that is not the blur model's Gaussian: block means, upsampled bilinearly.

The DiLiGenT bear (../shared/data/normal_maps/diligent_bear) with a prior made of the 8 x 8
block means of its ground-truth depth (the mask's pixels of each block), upsampled by
``scipy.ndimage.zoom(order=1)``; integrated pointwise and with ``prior_blur = 4`` (the
recommendation for block means of 8 upsampled bilinearly) at several weights, with and
without discontinuities. Prints the mean absolute depth error (mm, no alignment: the prior
makes the depth metric) and the mean deviation from the input normals. docs/fusion.md,
"Blurred priors", records the output.

Usage::

    .venv/bin/python benchmarks/bench_block_prior.py
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
BEAR = HERE.parent.parent / "shared" / "data" / "normal_maps" / "diligent_bear"


def block_prior(depth: np.ndarray, mask: np.ndarray, block: int) -> np.ndarray:
    """Block means of `depth` over `mask` (blocks without a mask pixel: the mean of the
    others), upsampled bilinearly, NaN outside `mask`."""
    from scipy import ndimage

    H, W = depth.shape
    hb, wb = H // block, W // block
    d = np.where(mask, depth, np.nan)[:hb * block, :wb * block]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (empty blocks)
        means = np.nanmean(d.reshape(hb, block, wb, block), axis=(1, 3))
    means = np.where(np.isfinite(means), means, np.nanmean(means))
    out = np.full((H, W), np.nan)
    out[:hb * block, :wb * block] = ndimage.zoom(means, block, order=1)
    return np.where(mask, out, np.nan)


def main(argv=None) -> int:
    import facetlift
    from facetlift import io

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--block", type=int, default=8)
    ap.add_argument("--sigma", type=float, default=None, help="default: block / 2")
    ap.add_argument("--weights", default="1,0.01,0.003")
    args = ap.parse_args(argv)
    sigma = args.block / 2 if args.sigma is None else args.sigma
    ds = io.read_dataset(BEAR)
    with np.load(BEAR / "depth_gt.npz") as z:
        gt = np.asarray(z["depth_gt"], float)
    mask = ds["mask"] & np.isfinite(gt)
    prior = block_prior(gt, mask, args.block)
    print(f"prior alone: {np.nanmean(np.abs(prior - gt)[mask]):.3f} mm")
    print("| route | weight | pointwise mm (deviation) | blurred mm (deviation) |")
    print("|---|---|---|---|")
    for disc in (False, True):
        for w in (float(x) for x in args.weights.split(",")):
            cells = []
            for blur in (None, sigma):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    s = facetlift.integrate(ds["normals"], ds["mask"], K=ds["K"], prior=prior,
                                            prior_weight=w, prior_blur=blur,
                                            discontinuities=disc)
                err = float(np.nanmean(np.abs(s.depth - gt)[mask]))
                cells.append(f"{err:.3f} ({s.info['mean_deviation']:.1f} deg)")
            print(f"| {'dgp-disc' if disc else 'dgp'} | {w:g} | {cells[0]} | {cells[1]} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
