"""Cameras as users know them: the discontinuity route and BiNI with intrinsics a little off.

Few users calibrate: a neural estimator's map comes with a guessed field of view, a phone's K
with its nominal focal length, a crop or resize keeps the old principal point. On the pinhole
renders of the development benchmark (``facetlift bench --experiments discontinuities``;
every ``--step``-th scene of ``--groups``, exact normals), each method integrates the map with

* ``true``: the render's own K;
* ``f0.8`` / ``f1.25``: the focal length (fx and fy) 0.8 or 1.25 times the true one (a field
  of view guessed about 20 % too wide or too narrow);
* ``centre``: the principal point 5 % of the image's width right and 5 % of its height up of
  the true one (a crop's or a default's principal point).

Printed per scene and per variant: MADE in mm (median scale, as BiNI) over the render's mask;
then the mean per variant and method, and the scenes each method wins by more than 1 %. The
depth of a wrong camera is compared with the true depth as it is: the error is that of the
shape the user gets. Nothing is tuned on it (docs/results.md, "Discontinuities: cameras a
little off").

Usage::

    FACETLIFT_BENCH_CACHE=/tmp/bcache .venv/bin/python benchmarks/bench_camera_errors.py \\
        --groups perspective,wide --step 3
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
VARIANTS = ("true", "f0.8", "f1.25", "centre")


def variants(gt) -> dict:
    """``{variant: (normals, mask, K)}`` of the pinhole render `gt` (module docstring)."""
    K = np.asarray(gt.K, float)
    h, w = gt.mask.shape
    out = {"true": K}
    for name, scale in (("f0.8", 0.8), ("f1.25", 1.25)):
        k = K.copy()
        k[0, 0] *= scale
        k[1, 1] *= scale
        out[name] = k
    k = K.copy()
    k[0, 2] += 0.05 * w
    k[1, 2] -= 0.05 * h
    out["centre"] = k
    return {name: (gt.normals, gt.mask, k) for name, k in out.items()}


def main(argv=None) -> int:
    sys.path.insert(0, str(HERE))
    from bench_mask_errors import compare

    return compare(argv, __doc__, variants, VARIANTS, groups="perspective,wide")


if __name__ == "__main__":
    sys.exit(main())
