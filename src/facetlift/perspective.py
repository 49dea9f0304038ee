"""Perspective helpers kept for callers of earlier versions; the model lives in
:mod:`facetlift.camera` (:class:`~facetlift.camera.Pinhole`)."""

from __future__ import annotations

import numpy as np

from .camera import Pinhole


def rays(K, rows, cols) -> np.ndarray:
    """Viewing rays ``K^{-1} (col, row, 1)`` (OpenCV frame, unit z); see :meth:`Pinhole.rays`."""
    return Pinhole(K).rays(rows, cols)


def view_cosine(K, rows, cols, normals) -> np.ndarray:
    """Cosine between each normal and the direction toward the camera
    (:meth:`Pinhole.view_cosine`)."""
    return Pinhole(K).view_cosine(rows, cols, normals)


def log_depth_slopes(K, rows, cols, normals):
    """``(d log Z / d col, d log Z / d row)`` (:meth:`Pinhole.log_depth_slopes`)."""
    return Pinhole(K).log_depth_slopes(rows, cols, normals)


def normals_from_depth(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Normals of a perspective depth map by central differences of back-projected points.

    A convenience for checks and examples (interior pixels only; borders and pixels next to
    NaN get NaN).

    Parameters
    ----------
    depth : (H, W) float
        z-depth, NaN outside the surface.
    K : (3, 3) float

    Returns
    -------
    (H, W, 3) float
        Unit normals, facetlift convention (x right, y up, z toward the viewer).
    """
    depth = np.asarray(depth, dtype=float)
    H, W = depth.shape
    rr, cc = np.mgrid[0:H, 0:W]
    P = Pinhole(K).points(rr.ravel() + 0.5, cc.ravel() + 0.5, depth.ravel()).reshape(H, W, 3)
    du = np.full_like(P, np.nan)
    dv = np.full_like(P, np.nan)
    du[:, 1:-1] = P[:, 2:] - P[:, :-2]
    dv[1:-1] = P[:-2] - P[2:]  # points are y up: the row above is +y
    n = np.cross(du, dv)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
