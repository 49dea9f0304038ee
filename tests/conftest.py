"""Shared test helpers: analytic height fields sampled on the facet grid.

An :class:`Analytic` is a height ``z(x, y)`` with its gradient ``(p, q) = (dz/dx, dz/dy)``,
sampled with the facetlift conventions: pixel ``(r, c)`` has its centre at
``x = x0 + (c + 0.5) h``, ``y = y0 - (r + 0.5) h`` and vertex ``(i, j)`` is at
``x = x0 + j h``, ``y = y0 - i h``, where ``(x0, y0)`` is the world position of vertex (0, 0).

Fixtures: ``make_plane(p, q)``, ``saddle`` (x^2 - y^2), ``wave`` (sin x cos y) and
``rel_err(estimate, truth)``;  ``brick_texture``
(:func:`bricks`: a brick texture's height and normals); ``load_script`` (a script of the
repository, e.g. ``benchmarks/bench_ab.py``, loaded as a module); ``near_sphere``
(:func:`sphere_seen_close`: a pinhole view of a sphere 1.2-1.5 units away).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

import facetlift


@dataclass(frozen=True)
class Analytic:
    """A height field z(x, y) (z toward the viewer) and its gradient."""

    z: Callable
    p: Callable
    q: Callable
    name: str = ""

    def facet_xy(self, shape, h=1.0, origin=(0.0, 0.0)):
        """World (x, y), each (H, W), of the pixel centres."""
        r, c = np.indices(shape)
        return origin[0] + (c + 0.5) * h, origin[1] - (r + 0.5) * h

    def vertex_xy(self, shape, h=1.0, origin=(0.0, 0.0)):
        """World (x, y), each (H+1, W+1), of the vertices."""
        i, j = np.indices((shape[0] + 1, shape[1] + 1))
        return origin[0] + j * h, origin[1] - i * h

    def height(self, shape, h=1.0, origin=(0.0, 0.0)) -> np.ndarray:
        """(H, W) heights at the pixel centres."""
        return self.z(*self.facet_xy(shape, h, origin))

    def vertex_height(self, shape, h=1.0, origin=(0.0, 0.0)) -> np.ndarray:
        """(H+1, W+1) heights at the vertices."""
        return self.z(*self.vertex_xy(shape, h, origin))

    def gradients(self, shape, h=1.0, origin=(0.0, 0.0)):
        """(p, q), each (H, W), at the pixel centres."""
        x, y = self.facet_xy(shape, h, origin)
        return self.p(x, y) + 0 * x, self.q(x, y) + 0 * y

    def normals(self, shape, h=1.0, origin=(0.0, 0.0)) -> np.ndarray:
        """(H, W, 3) unit normals at the pixel centres."""
        return facetlift.normals_from_gradients(*self.gradients(shape, h, origin))


def plane(p: float, q: float, c: float = 0.0) -> Analytic:
    """z = p x + q y + c."""
    return Analytic(
        lambda x, y: p * x + q * y + c, lambda x, y: p + 0 * x, lambda x, y: q + 0 * y,
        name=f"plane({p}, {q})",
    )


SADDLE = Analytic(
    lambda x, y: x**2 - y**2, lambda x, y: 2 * x, lambda x, y: -2 * y, name="x^2 - y^2"
)
WAVE = Analytic(
    lambda x, y: np.sin(x) * np.cos(y),
    lambda x, y: np.cos(x) * np.cos(y),
    lambda x, y: -np.sin(x) * np.sin(y),
    name="sin(x) cos(y)",
)


def relative_error(estimate, truth) -> float:
    """max |(estimate - truth) - mean| / (max(truth) - min(truth)) over finite entries.

    The mean difference is removed first (orthographic depth is defined up to a constant).
    Both arrays must be finite at the same places.
    """
    estimate = np.asarray(estimate, dtype=float)
    truth = np.asarray(truth, dtype=float)
    ok = np.isfinite(truth)
    if not np.array_equal(ok, np.isfinite(estimate)):
        raise AssertionError("estimate and truth are finite at different places")
    d = estimate[ok] - truth[ok]
    span = np.ptp(truth[ok])
    return float(np.abs(d - d.mean()).max() / (span if span > 0 else 1.0))


def bricks(size=512, brick=(128, 64), depth=6.0, bevel=(1.5, 7.0), heights=None):
    """A brick texture (a second audit's): ``(height, normals)``, (H, W) and (H, W, 3) in the
    facetlift frame, `size` texels square, bricks `brick` = (width, height) texels in rows
    offset by half a brick, grooves `depth` texels deep whose flat bottom ends `bevel[0]`
    texels from the joint and whose smooth bevel `bevel[1]`. `heights`: per brick row, a
    factor of `depth` for its faces (different heights: a displacement map that a mask cannot
    be)."""
    bw, bh = brick
    w0, w1 = bevel

    def smooth(t):
        t = np.clip(t, 0, 1)
        return t * t * t * (t * (6 * t - 15) + 10)

    def height(x, down):
        row = np.floor(down / bh)
        u = np.mod(x - np.where(row % 2 == 1, bw / 2, 0.0), bw)
        v = np.mod(down, bh)
        level = 1.0 if heights is None else np.asarray(heights)[row.astype(int) % len(heights)]
        return (depth * level * smooth((np.minimum(u, bw - u) - w0) / (w1 - w0))
                * smooth((np.minimum(v, bh - v) - w0) / (w1 - w0)))

    r, c = np.indices((size, size)).astype(float)
    x, down, e = c + 0.5, r + 0.5, 1e-5
    p = (height(x + e, down) - height(x - e, down)) / (2 * e)
    q = -(height(x, down + e) - height(x, down - e)) / (2 * e)  # (y up: rows run down)
    return height(x, down), facetlift.normals_from_gradients(p, q)


@pytest.fixture(scope="session")
def load_script():
    """``load(path, name=None)``: the file at `path` (relative to the repository) executed
    as a module named `name` (default: its stem), for the scripts outside the package."""
    root = Path(__file__).resolve().parent.parent

    def load(path: str, name: str | None = None):
        spec = importlib.util.spec_from_file_location(name or Path(path).stem, root / path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture
def own_bench_cache(tmp_path, monkeypatch):
    """$FACETLIFT_BENCH_CACHE, which a benchmark script run in-process points at its
    --cache, restored after the test (a module's ``pytestmark = usefixtures(...)``)."""
    monkeypatch.setenv("FACETLIFT_BENCH_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def brick_texture():
    """:func:`bricks`."""
    return bricks


@pytest.fixture
def make_plane():
    return plane


@pytest.fixture
def saddle():
    return SADDLE


@pytest.fixture
def wave():
    return WAVE


@pytest.fixture
def rel_err():
    return relative_error


@pytest.fixture
def analytic():
    """The :class:`Analytic` class, to build other height fields: ``analytic(z, p, q)``."""
    return Analytic


def sphere_seen_close(H: int = 192, W: int = 256):
    """A sphere of radius 1 whose front is 1.2 from a pinhole camera (f = 1.25 W): normals
    (H, W, 3), depth (NaN off it), mask and K. Its log-depth relief is large enough for the
    prior checks' relief ratio (:func:`facetlift.prior_fit.relief_ratio`)."""
    from facetlift.perspective import normals_from_depth, rays

    K = np.array([[1.25 * H, 0, W / 2 - 0.3], [0, 1.25 * H, H / 2 + 0.2], [0, 0, 1]])
    rr, cc = np.mgrid[0:H, 0:W]
    d = rays(K, rr.ravel(), cc.ravel()).reshape(H, W, 3)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    b = d[..., 2] * 2.2
    disc = b * b - (2.2 ** 2 - 1.0)
    depth = (b - np.sqrt(np.where(disc > 0, disc, np.nan))) * d[..., 2]
    mask = np.isfinite(depth) & (disc > 0.1)
    n = normals_from_depth(np.where(mask, depth, np.nan), K)
    mask &= np.isfinite(n).all(-1)
    return n, depth, mask, K


@pytest.fixture
def near_sphere():
    """:func:`sphere_seen_close` at 192 x 256."""
    return sphere_seen_close()
