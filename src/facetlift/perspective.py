"""Perspective cameras: viewing rays and log-depth slopes from normals.

A perspective surface is described by its z-depth ``Z(u, v) > 0`` over pixel coordinates
(``u`` the column, ``v`` the row, pixel centres at integer indices, see
:mod:`facetlift.conventions`). The surface point is ``X = Z r`` with the viewing ray
``r(u, v) = K^{-1} (u, v, 1)`` in the OpenCV camera frame (x right, y down, z forward). Its
tangents are ``X_u = Z_u r + Z K^{-1} e_u`` and ``X_v = Z_v r + Z K^{-1} e_v``; a normal
``m`` (OpenCV frame) is orthogonal to both, so with the log-depth ``Z~ = log Z``::

    dZ~/du = -(m . K^{-1} e_u) / (m . r),      dZ~/dv = -(m . K^{-1} e_v) / (m . r).

facetlift normals are given x right, y up, z toward the viewer, i.e. ``m = (n_x, -n_y, -n_z)``.
The slopes depend on the normal only through ratios, so its length is irrelevant, and they
are exact (no small-angle or weak-perspective approximation). They are finite unless the
surface is seen edge-on: ``m . r = 0``. The quantity that tells how grazing a normal is in
a perspective view is therefore the cosine between the normal and the direction toward the
camera, ``-m . r / |r|`` (:func:`view_cosine`), not ``n_z``; off-axis pixels of a wide-angle
camera can see surfaces with ``n_z < 0``.

In the orthographic limit (``fx, fy -> inf``) the log-depth slopes tend to
``(-p, q) / (f Z)`` times the pixel footprint, the usual height slopes.
"""

from __future__ import annotations

import numpy as np


def rays(K: np.ndarray, rows, cols) -> np.ndarray:
    """Viewing rays ``K^{-1} (col, row, 1)`` in the OpenCV camera frame.

    Parameters
    ----------
    K : (3, 3) float
        Intrinsics, OpenCV layout (``cx`` a column, ``cy`` a row from the top).
    rows, cols : (m,) array_like of float
        Pixel coordinates; pixel centres are at integer indices.

    Returns
    -------
    (m, 3) float
        Rays with unit z-component (so ``depth * ray`` is the camera-frame point).
    """
    rows = np.asarray(rows, dtype=float)
    cols = np.asarray(cols, dtype=float)
    pix = np.stack([cols, rows, np.ones_like(cols)], axis=-1)
    return pix @ np.linalg.inv(np.asarray(K, dtype=float)).T


def opencv_normals(normals: np.ndarray) -> np.ndarray:
    """facetlift normals (x right, y up, z to the viewer) -> OpenCV frame ``(n_x, -n_y, -n_z)``."""
    n = np.asarray(normals, dtype=float)
    return n * np.array([1.0, -1.0, -1.0])


def view_cosine(K: np.ndarray, rows, cols, normals: np.ndarray) -> np.ndarray:
    """Cosine between each normal and the direction from the surface toward the camera.

    Parameters
    ----------
    K : (3, 3) float
    rows, cols : (m,) pixel coordinates
    normals : (m, 3) unit normals, facetlift convention (x right, y up, z toward the viewer)

    Returns
    -------
    (m,) float
        1 for a surface facing the camera head-on, 0 when seen edge-on, < 0 when back-facing;
        NaN where the normal is NaN.
    """
    r = rays(K, rows, cols)
    m = opencv_normals(normals)
    return -np.einsum("ij,ij->i", m, r) / np.linalg.norm(r, axis=1)


def log_depth_slopes(K: np.ndarray, rows, cols, normals: np.ndarray):
    """Derivatives of ``log(depth)`` along columns and rows implied by the normals.

    Parameters
    ----------
    K : (3, 3) float
        Intrinsics, OpenCV layout.
    rows, cols : (m,) array_like of float
        Pixel coordinates where the normals are given (pixel centres at integer indices).
    normals : (m, 3) float
        Normals, facetlift convention; NaN rows give NaN slopes.

    Returns
    -------
    du, dv : (m,) float
        ``d log Z / d col`` and ``d log Z / d row`` (per pixel); inf/NaN where the normal is
        perpendicular to the viewing ray (callers exclude those, see :func:`view_cosine`).
    """
    Kinv = np.linalg.inv(np.asarray(K, dtype=float))
    r = rays(K, rows, cols)
    m = opencv_normals(normals)
    mr = np.einsum("ij,ij->i", m, r)
    with np.errstate(divide="ignore", invalid="ignore"):
        du = -(m @ Kinv[:, 0]) / mr
        dv = -(m @ Kinv[:, 1]) / mr
    return du, dv


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
    P = rays(K, rr.ravel(), cc.ravel()).reshape(H, W, 3) * depth[..., None]
    du = np.full_like(P, np.nan)
    dv = np.full_like(P, np.nan)
    du[:, 1:-1] = P[:, 2:] - P[:, :-2]
    dv[1:-1] = P[2:] - P[:-2]
    m = np.cross(du, dv)  # OpenCV frame: u right, v down -> (du x dv) points away from camera
    m = -m / np.linalg.norm(m, axis=-1, keepdims=True)
    return m * np.array([1.0, -1.0, -1.0])
