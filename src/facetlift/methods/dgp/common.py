"""Pieces every DGP route shares: targets from a problem, deviations, empty components."""

from __future__ import annotations

import numpy as np

from ..._warnings import warn
from ...operators.stencil import E_X, E_Y, grid_slopes


def targets(problem):
    """Per-facet target slopes (bx, by) of the unknown and the facets that have a target.

    ``(bx, by)`` are the problem's grid slopes (:attr:`facetlift.problem.Problem.grid_slopes`:
    the change of the camera's unknown across one facet along x and y), zero where a facet has
    no usable normal; ``target`` is :attr:`~facetlift.problem.Problem.usable`.
    """
    gx, gy = problem.grid_slopes
    target = problem.usable
    return np.where(target, gx, 0.0), np.where(target, gy, 0.0), target


def empty_components(domain, target):
    """Indices of the components without any target normal (warned about: they come out flat)."""
    have = np.bincount(domain.facet_component[target], minlength=domain.n_components)
    empty = np.nonzero(have == 0)[0]
    if empty.size:
        warn(
            f"{empty.size} connected component(s) have no usable normal (e.g. component "
            f"{empty[0] + 1}); they are reconstructed flat"
        )
    return empty


def flatten(domain, z, empty):
    """Components without a target normal are flat (their tilt is only weakly determined)."""
    if empty.size:
        z[np.isin(domain.vertex_component, empty)] = 0.0
    return z


def facet_slopes(domain, z):
    """Current (e_x . z_f, e_y . z_f) of every facet: h times its least-squares slopes."""
    zf = z[domain.corners]
    return zf @ E_X, zf @ E_Y


def average_deviation(domain, z, bx, by, target, h=1.0) -> float:
    """Mean angle (degrees) between current facet normals and target normals.

    `bx`, `by` and the current facet slopes are changes of the unknown across a facet of
    width `h` (the camera footprint), so the normals are ``(-gx, -gy, h)`` and
    ``(-bx, -by, h)``.
    """
    if not target.any():
        return 0.0
    # on the vertex image (grid slicing), not through the (m, 4) corner gather
    gx, gy = grid_slopes(domain.to_vertex_image(z, fill=0.0))
    return mean_angle(gx[domain.mask], gy[domain.mask], bx, by, target, h)


def mean_angle(gx, gy, bx, by, target, h) -> float:
    """Mean angle (degrees) between normals (-gx, -gy, h) and (-bx, -by, h) where `target`."""
    if not target.any():
        return 0.0
    gx, gy, bx, by = (np.ravel(a) for a in (gx, gy, bx, by))
    idx = np.flatnonzero(target)
    total = 0.0
    h2 = h * h
    for a in range(0, idx.size, _CHUNK):  # in chunks: no full-size temporaries
        k = idx[a : a + _CHUNK]
        gxk, gyk, bxk, byk = gx[k], gy[k], bx[k], by[k]
        # atan2(|a x b|, a . b), accurate near zero unlike arccos
        cross = np.sqrt(h2 * ((byk - gyk) ** 2 + (gxk - bxk) ** 2) + (gxk * byk - gyk * bxk) ** 2)
        total += float(np.arctan2(cross, gxk * bxk + gyk * byk + h2).sum())
    return float(np.degrees(total / idx.size))


#: Facets per chunk of :func:`mean_angle`.
_CHUNK = 1 << 20
