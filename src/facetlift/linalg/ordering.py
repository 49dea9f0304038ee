"""Fill-reducing orderings of unknowns that lie on a pixel or vertex grid.

Every system facetlift factorizes couples each unknown only with its grid neighbours (the
9-point stencil of the facet vertices, the 5-point one of the pixel graphs, a split mesh's
copies of one vertex). Such a matrix is cut in two by any straight grid line: nested
dissection on the grid (George, 1973) orders each half recursively and the line last, so its
factor grows by O(n log n) with O(n^1.5) work. SuperLU's own minimum-degree ordering has no
such bound and does worse on these systems as they grow (measured on a masked disk, 9-point
facet systems, factorization and solve: 42k unknowns 0.63 -> 0.32 s, 168k 3.5 -> 1.3 s with
a fifth less fill, 669k 25.4 -> 7.3 s; docs/benchmarks.md). The ordering needs no graph: only
the grid positions.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LEAF", "factorization_work", "nested_dissection"]

#: Boxes of at most this many positions are not split further (kept in row-major order).
#: Measured on the masked disks (9-point facet systems): the time is flat from 16 to 64
#: (1024^2: 7.2-7.6 s both), the fill falls with the size (16: 74 M non-zeros, 64: 80 M,
#: 256 at 512^2: 1.27x 16's), so the smallest measured.
LEAF = 16


def nested_dissection(rows, cols, leaf: int = LEAF) -> np.ndarray:
    """A permutation (n,) of the unknowns at grid positions (`rows`, `cols`) (each (n,) int):
    nested dissection by straight grid lines. The positions' bounding box is split across its
    longer side by its middle line, each half likewise, down to boxes of about `leaf`
    positions; in the order the lower half comes first, then the upper one, then the line.

    Every box of one level has the same size to within a line, so one schedule of splits
    serves them all and the order factors into a bisection of the rows and one of the
    columns: a few array operations on the positions and one sort (1M in 0.2-0.3 s). On a
    masked grid the lines through empty parts of a box are empty and cost nothing.

    A valid separator only where every coupling is between positions at most one row and one
    column apart (the facet and pixel-graph stencils; for wider couplings pass coarser
    positions, e.g. ``rows // 2`` for second differences); any other matrix is still
    factorized correctly in this order, only with more fill.
    """
    key, _, _, _, _ = _paths(rows, cols, leaf)
    return np.argsort(key, kind="stable")


def factorization_work(rows, cols, leaf: int = LEAF) -> float:
    """An estimate of the work of factorizing a grid system in :func:`nested_dissection`'s
    order: the sum of the cubes of its separators' lengths, each separator counted as the
    runs of consecutive positions along its line (parts of a mask that a line crosses
    separately do not fill each other in). Dense fronts dominate a nested-dissection
    factorization, so its time is about linear in this sum plus a part linear in the
    unknowns (fitted in :mod:`facetlift.linalg.facet`)."""
    key, stop, schedule, r, c = _paths(rows, cols, leaf)
    if key.size == 0 or not schedule:
        return 0.0
    total = len(schedule)
    digit = (key // 3 ** (total - stop)) % 3  # the last digit of each path
    sep = np.flatnonzero(digit == 2)
    if sep.size == 0:
        return 0.0
    axis = np.asarray(schedule)[stop[sep] - 1]  # 0: a line across the rows (a row)
    along = np.where(axis == 0, c[sep], r[sep])
    order = np.lexsort((along, key[sep]))
    k, a = key[sep][order], along[order]
    new = np.r_[True, (k[1:] != k[:-1]) | (np.diff(a) != 1)]
    runs = np.diff(np.r_[np.flatnonzero(new), k.size]).astype(float)
    return float(np.sum(runs ** 3))


def _paths(rows, cols, leaf):
    """(key, stop, schedule, rows, cols) of :func:`nested_dissection`: each position's path as
    a base-3 number, the level it ends at, the split axes, and the positions from the box's
    corner."""
    r = np.asarray(rows, dtype=np.int64)
    c = np.asarray(cols, dtype=np.int64)
    if r.shape != c.shape or r.ndim != 1:
        raise ValueError(f"nested_dissection: `rows` and `cols` must be (n,) arrays of one "
                         f"length; got shapes {r.shape} and {c.shape}")
    if r.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), [], r, c
    r = r - r.min()
    c = c - c.min()
    H, W = int(r.max()) + 1, int(c.max()) + 1
    # the schedule: split the longer side of the (nominal) box until it holds `leaf` positions
    schedule = []
    h, w = float(H), float(W)
    while h * w > max(int(leaf), 1) and max(h, w) >= 2.0:
        axis = 0 if h >= w else 1
        schedule.append(axis)
        if axis == 0:
            h = (h - 1.0) / 2.0
        else:
            w = (w - 1.0) / 2.0
    total = len(schedule)
    if total > 39:  # (3^40 > 2^63; boxes of more than 2^39 leaves: no image is that large)
        raise ValueError(f"nested_dissection: {total} levels do not fit the sort key")
    # a position's path: one base-3 digit per level (0 the lower half, 1 the upper half, 2 the
    # separating line, which ends the path); a path that ends is padded with zeros, and sorted
    # by the paths every half comes before its line (a box keeps its row-major order: the
    # stable sort). The digits of a row level depend on the row alone, those of a column level
    # on the column: the key is the sum of a row part and a column part, each summed up to
    # where the first of the two paths ends
    parts = []
    for axis, size in ((0, H), (1, W)):
        prefix = np.zeros((total + 1, size), dtype=np.int64)  # the part up to each level
        end = np.full(size, total, dtype=np.int64)  # the level (1-based) its path ends at
        x = np.arange(size)
        lo, hi = np.zeros(size, dtype=np.int64), np.full(size, size, dtype=np.int64)
        acc = np.zeros(size, dtype=np.int64)
        done = np.zeros(size, dtype=bool)
        for level, split in enumerate(schedule):
            if split == axis:
                mid = (lo + hi) // 2
                digit = np.where(x < mid, 0, np.where(x == mid, 2, 1))
                digit[done] = 0
                acc += digit * 3 ** (total - 1 - level)
                line = (digit == 2)
                end[line] = level + 1
                done |= line
                lo = np.where(digit == 1, mid + 1, lo)
                hi = np.where(digit == 0, mid, hi)
            prefix[level + 1] = acc
        parts.append((prefix, end))
    (pr, er), (pc, ec) = parts
    stop = np.minimum(er[r], ec[c])
    key = pr[stop, r] + pc[stop, c]
    return key, stop, schedule, r, c
