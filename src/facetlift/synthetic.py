"""Ground truth for experiments: analytic surfaces, mesh rendering, perturbations.

Everything here follows :mod:`facetlift.conventions`: normals are ``(H, W, 3)`` with x right,
y up and z toward the viewer; depth is distance along the viewing axis (``height = -depth``),
NaN outside the mask; the value of pixel ``(r, c)`` is taken at its centre
``x = (c + 0.5) h``, ``y = -(r + 0.5) h``.

Analytic surfaces (:func:`analytic`)
    Height functions with exact gradients: the normal map is the exact derivative of the height
    at every pixel centre (at a crease the one-sided derivative of the branch that wins the
    ``min``/``max``), and the depth is the exact height at the centre. Slopes do not depend on
    the resolution: a surface is defined on normalised coordinates ``u, v`` in ``[-1, 1]``
    (``u`` right, ``v`` up, ``s = min(H, W) h / 2`` world units per unit) and its height is
    ``s * f(u, v)``, so ``p = df/du`` and ``q = df/dv``.

Mesh rendering (:func:`render_mesh`; :func:`render_perspective` for a pinhole camera)
    One orthographic ray per pixel centre along the view direction; depth is the hit distance
    along the view axis and the normal is the hit triangle's face normal in the image frame,
    turned toward the viewer. Because a rendered triangle mesh is piecewise planar, these
    normals are the exact derivative of the rendered depth at each pixel centre. Self-occlusions
    give depth discontinuities that no integrator can recover from normals alone;
    :func:`continuous_region` keeps the largest region free of them.

Perturbations
    :func:`add_angular_noise` (Gaussian angle about a random perpendicular axis, Sec. 5),
    :func:`add_smooth_noise` (a smooth, spatially correlated rotation field: an estimator's
    errors), :func:`perturb_fraction` (Fig. 5a: a fraction of the samples rotated by up to 20
    degrees),
    :func:`remove_samples` (missing samples as NaN), :func:`quantize` (8/16-bit storage),
    :func:`blur_normals` and :func:`resample_normals` (soft occlusion boundaries: a blurred
    map, or one estimated at a lower resolution and resampled).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

__all__ = [
    "ANALYTIC",
    "TABLE_VIEW",
    "VIEWS",
    "GroundTruth",
    "add_angular_noise",
    "add_smooth_noise",
    "analytic",
    "continuous_region",
    "perturb_fraction",
    "quantize",
    "remove_samples",
    "render_mesh",
    "render_perspective",
    "ROOM_ELEVATIONS",
    "room",
    "room_view",
    "tabletop",
    "vessel",
    "vessel_view",
    "DILIGENT_K",
    "VESSELS",
    "WITH_JUMPS",
    "jump_edges",
    "depth_jumps",
    "analytic_height",
    "blur_normals",
    "resample_normals",
]


@dataclass(eq=False)
class GroundTruth:
    """A test surface sampled on a pixel grid.

    Attributes
    ----------
    depth : (H, W) float
        Depth at pixel centres (larger is farther, ``height = -depth``), NaN outside `mask`.
    normals : (H, W, 3) float
        Unit normals (x right, y up, z toward the viewer), NaN outside `mask`.
    mask : (H, W) bool
        Pixels on the surface.
    pixel_size : float
        Pixel width in the units of `depth` (orthographic).
    name : str
        A label for tables.
    K : (3, 3) float or None
        Intrinsics of a perspective rendering (:func:`render_perspective`), None when
        orthographic.
    jump_sizes : (right (H, W-1), down (H-1, W)) float, or None
        A render's depth jumps from its geometry (``jumps=True`` of :func:`render_mesh` and
        :func:`render_perspective`, :func:`_jump_sizes`): the jump across each edge between
        4-neighbouring mask pixels in pixel footprints of the camera's unknown, 0 where the
        surface is continuous there (or the jump is under a quarter footprint), inf where
        a ray cast between the two centres misses the surface (a feature narrower than the
        rays' spacing, a quarter pixel at first, can go unseen). ``jump_edges(gt,
        geometric=True)`` cuts by it.
    """

    depth: np.ndarray
    normals: np.ndarray
    mask: np.ndarray
    pixel_size: float = 1.0
    name: str = ""
    K: np.ndarray | None = None
    jump_sizes: tuple | None = None

    def __post_init__(self):
        """The arrays checked against each other (ones that did not fit built and printed,
        then failed deep inside jump_edges or the camera, an audit)."""
        mask = np.asarray(self.mask)
        if mask.ndim != 2 or mask.dtype != bool:
            raise ValueError(f"GroundTruth: `mask` must be an (H, W) bool array; got "
                             f"{mask.dtype} of shape {mask.shape}")
        H, W = mask.shape
        if np.shape(self.depth) != (H, W):
            raise ValueError(f"GroundTruth: `depth` must have the mask's shape {(H, W)}; got "
                             f"{np.shape(self.depth)}")
        if np.shape(self.normals) != (H, W, 3):
            raise ValueError(f"GroundTruth: `normals` must have shape {(H, W, 3)}; got "
                             f"{np.shape(self.normals)}")

    def __repr__(self) -> str:  # (not the arrays: a notebook printed them whole, a user's)
        H, W = self.mask.shape
        view = "orthographic" if self.K is None else "perspective"
        return (f"GroundTruth({self.name!r}, {H}x{W}, {int(self.mask.sum())} pixels, {view}, "
                f"pixel_size={self.pixel_size:g})")

    @property
    def camera(self):
        """The :class:`facetlift.camera.Camera` the depth and normals are given in."""
        from .camera import make_camera

        return make_camera(self.pixel_size, self.K)

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape

    @property
    def depth_range(self) -> float:
        """max - min of the depth over the mask."""
        d = self.depth[self.mask]
        return float(d.max() - d.min()) if d.size else 0.0


# ----------------------------------------------------------------------------------------------
# analytic surfaces: each f(u, v) -> (f, f_u, f_v, inside)


def _saddle(u, v):
    return 0.5 * (u**2 - v**2), u, -v, np.ones(u.shape, bool)


def _pyramid(u, v):
    # The apex is off the image centre by a fraction of a unit so that, at the usual even image
    # sizes, no pixel centre lies exactly on a crease (where the gradient is a tie-break).
    # Note: a 45-degree crease keeps the same sub-pixel offset to the pixel lattice along its
    # whole length, and point samples of the gradient cannot tell where inside a pixel the
    # crease runs; an integrator puts it half-way between pixel centres, so every face comes
    # out shifted by up to (slope jump) x (offset). That error is a floor common to all methods.
    a, u0, v0 = 0.8, 0.0537, 0.0213
    du, dv = u - u0, v - v0
    use_u = np.abs(du) >= np.abs(dv)
    f = a * (1.0 - np.maximum(np.abs(du), np.abs(dv)))
    fu = np.where(use_u, -a * np.sign(du), 0.0)
    fv = np.where(use_u, 0.0, -a * np.sign(dv))
    return f, fu, fv, np.ones(u.shape, bool)


def _ramps(u, v):
    # terraces: slope 1 over the first half of every period T, flat over the second half,
    # plus a tilt along v; continuous, with creases at the ends of every ramp
    T, a, tilt = 0.5, 0.8, 0.3
    t = u + 1.0
    k = np.floor(t / T)
    r = t - k * T
    g = k * T / 2 + np.minimum(r, T / 2)
    gu = (r < T / 2).astype(float)
    return a * g + tilt * v, a * gu, np.full(u.shape, tilt), np.ones(u.shape, bool)


# (amplitude, u0, v0, sigma_u, sigma_v): head, nose, nose tip, brows, eye sockets, cheeks,
# lips, chin
_FACE = [
    (0.55, 0.0, 0.0, 0.45, 0.6),
    (0.18, 0.0, -0.05, 0.07, 0.18),
    (0.06, 0.0, -0.2, 0.06, 0.05),
    (0.07, -0.22, 0.22, 0.14, 0.05),
    (0.07, 0.22, 0.22, 0.14, 0.05),
    (-0.08, -0.22, 0.08, 0.09, 0.06),
    (-0.08, 0.22, 0.08, 0.09, 0.06),
    (0.06, -0.28, -0.2, 0.12, 0.12),
    (0.06, 0.28, -0.2, 0.12, 0.12),
    (0.05, 0.0, -0.4, 0.14, 0.03),
    (0.06, 0.0, -0.6, 0.15, 0.08),
]


def _face(u, v):
    f = np.zeros(u.shape)
    fu = np.zeros(u.shape)
    fv = np.zeros(u.shape)
    for a, u0, v0, su, sv in _FACE:
        g = a * np.exp(-0.5 * (((u - u0) / su) ** 2 + ((v - v0) / sv) ** 2))
        f += g
        fu -= g * (u - u0) / su**2
        fv -= g * (v - v0) / sv**2
    return f, fu, fv, np.ones(u.shape, bool)


def _sphere(u, v):
    R = 0.9
    rr = u**2 + v**2
    inside = rr < (0.95 * R) ** 2
    f = np.sqrt(np.where(inside, R**2 - rr, 1.0))
    return np.where(inside, f, np.nan), -u / f, -v / f, inside


def _vase(u, v):
    # surface of revolution about the vertical axis, radius profile R(v)
    R = 0.45 + 0.2 * np.sin(2.5 * v + 0.5)
    Rv = 0.5 * np.cos(2.5 * v + 0.5)
    inside = (np.abs(u) < 0.95 * R) & (np.abs(v) < 0.9)
    f = np.sqrt(np.where(inside, R**2 - u**2, 1.0))
    return np.where(inside, f, np.nan), -u / f, R * Rv / f, inside


def _tent(u, v):
    # a hipped roof on a flat ground: ridge along u, 45-degree roof planes, steeper hip ends
    a = 0.35 - np.abs(v)
    b = 2.0 * (0.6 - np.abs(u))
    roof = np.minimum(a, b)
    f = np.maximum(roof, 0.0)
    on_roof = roof > 0
    use_a = a <= b
    fu = np.where(on_roof & ~use_a, -2.0 * np.sign(u), 0.0)
    fv = np.where(on_roof & use_a, -np.sign(v), 0.0)
    return f, fu, fv, np.ones(u.shape, bool)


def _plane(u, v):
    return 0.3 * u - 0.2 * v, np.full(u.shape, 0.3), np.full(u.shape, -0.2), np.ones(u.shape, bool)


# surfaces with depth jumps (the discontinuity benchmark): the height is the front-most layer,
# the gradient that layer's; a jump is where two layers meet without a surface between them


def _steps(u, v):
    # three tilted terraces separated by vertical cliffs along v (closed cuts: the regions'
    # relative heights are not in the normals)
    k = np.digitize(u, [-0.3, 0.35])
    f = 0.2 * u + 0.15 * v + np.array([0.0, 0.35, 0.1])[k]
    return f, np.full(u.shape, 0.2), np.full(u.shape, 0.15), np.ones(u.shape, bool)


def _plateau(u, v):
    # a tilted disc-shaped table top standing above a sloped floor (a closed jump loop)
    top = (u - 0.1) ** 2 + (v + 0.05) ** 2 < 0.42**2
    f = np.where(top, 0.45 + 0.25 * u - 0.1 * v, 0.1 * v)
    return f, np.where(top, 0.25, 0.0), np.where(top, -0.1, 0.1), np.ones(u.shape, bool)


def _helix(u, v):
    # a spiral ramp around a hole: one turn rises by 0.6, so a cliff runs along the negative
    # u-axis, but the two sides are connected around the turn (their offset is in the normals)
    rr = u**2 + v**2
    inside = (rr > 0.2**2) & (rr < 0.95**2)
    c = 0.6 / (2 * np.pi)
    theta = np.arctan2(v, u)
    rr = np.where(inside, rr, 1.0)
    return c * theta + 0.1 * u, -c * v / rr + 0.1, c * u / rr, inside


def _occluder(u, v):
    # a ball in front of a tilted wall: the ball's rim (grazing normals) meets the wall
    R, u0, v0, h = 0.45, 0.15, 0.1, 0.55
    rr = (u - u0) ** 2 + (v - v0) ** 2
    ball = rr < (0.97 * R) ** 2
    s = np.sqrt(np.where(ball, R**2 - rr, 1.0))
    f = np.where(ball, h + s, -0.2 * u + 0.1 * v)
    return (f, np.where(ball, -(u - u0) / s, -0.2), np.where(ball, -(v - v0) / s, 0.1),
            np.ones(u.shape, bool))


def _fold(u, v):
    # a sheet lying over another: the cliff along u = 0.1 grows from nothing at v = -0.5 to
    # 0.375 at the top edge (a jump that fades out inside the image)
    upper = u > 0.1
    lift = 0.25 * np.maximum(v + 0.5, 0.0)
    f = 0.3 * u + np.where(upper, lift, 0.0)
    return f, np.full(u.shape, 0.3), np.where(upper, 0.25 * (v > -0.5), 0.0), np.ones(u.shape, bool)


_SURFACES = {
    "saddle": _saddle,
    "pyramid": _pyramid,
    "ramps": _ramps,
    "face": _face,
    "sphere": _sphere,
    "vase": _vase,
    "tent": _tent,
    "plane": _plane,
    "steps": _steps,
    "plateau": _plateau,
    "helix": _helix,
    "occluder": _occluder,
    "fold": _fold,
}

#: Names accepted by :func:`analytic`.
ANALYTIC = tuple(_SURFACES)

#: The analytic surfaces with depth jumps (the orthographic scenes of the discontinuity
#: benchmark); the others are continuous.
WITH_JUMPS = ("steps", "plateau", "helix", "occluder", "fold")


def _size(size, name: str = "size") -> tuple[int, int]:
    if np.ndim(size) == 0:
        size = (size, size)
    try:
        H, W = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be an int or a pair (H, W); got {size!r}") from None
    if H < 2 or W < 2 or (H, W) != tuple(size):
        raise ValueError(f"`{name}` must be integers >= 2; got {size!r}")
    return H, W


def analytic_height(name: str, x, y, *, scale: float = 1.0):
    """Height and exact gradient of an analytic surface at world points.

    Parameters
    ----------
    name : str
        One of :data:`ANALYTIC`.
    x, y : array_like of float
        World coordinates (x right, y up) relative to the image centre.
    scale : float
        World units per normalised unit (``s`` in the module docstring).

    Returns
    -------
    z, p, q : arrays like `x`
        Height and its derivatives ``dz/dx``, ``dz/dy`` (NaN outside the surface's domain).
    inside : array of bool
    """
    if not isinstance(name, str) or name not in _SURFACES:
        raise ValueError(f"`name` must be one of {list(ANALYTIC)}; got {name!r}")
    scale = _real(scale, "scale", 0, open_low=True)  # (0: inf and NaN; < 0: mirrored)
    u = np.asarray(x, float) / scale
    v = np.asarray(y, float) / scale
    with np.errstate(invalid="ignore", divide="ignore"):
        f, fu, fv, inside = _SURFACES[name](u, v)
    z = np.where(inside, scale * f, np.nan)
    p = np.where(inside, fu, np.nan)
    q = np.where(inside, fv, np.nan)
    return z, p, q, inside


def analytic(name: str, size=128, *, pixel_size: float = 1.0) -> GroundTruth:
    """Sample an analytic surface at the pixel centres of an image.

    Parameters
    ----------
    name : str
        One of :data:`ANALYTIC`: ``saddle`` (Fig. 6), ``pyramid`` and ``ramps`` (sharp creases,
        Fig. 7), ``face`` (a smooth face-like sum of anisotropic Gaussians, Fig. 8),
        ``sphere`` (a spherical cap on a disc), ``vase`` (a surface of revolution with an
        irregular outline), ``tent`` (a hipped roof on flat ground), ``plane``; with depth
        jumps (:data:`WITH_JUMPS`, :func:`jump_edges` gives them): ``steps`` (three terraces
        between cliffs), ``plateau`` (a table top above a sloped floor), ``helix`` (a spiral
        ramp whose cliff is joined around the turn), ``occluder`` (a ball in front of a tilted
        wall), ``fold`` (a sheet over another, its cliff fading out inside the image).
    size : int or (H, W)
    pixel_size : float
        Pixel width in world units.

    Returns
    -------
    GroundTruth
        Exact depth (``-height``) and normals at pixel centres.

    Raises
    ------
    ValueError
        Unknown `name`, bad `size` or `pixel_size`.
    """
    if not isinstance(name, str) or name not in _SURFACES:
        raise ValueError(f"`name` must be one of {list(ANALYTIC)}; got {name!r}")
    H, W = _size(size)
    h = _real(pixel_size, "pixel_size", 0, open_low=True)
    rows, cols = np.mgrid[0:H, 0:W].astype(float)
    x = (cols + 0.5 - W / 2) * h
    y = (H / 2 - rows - 0.5) * h
    z, p, q, inside = analytic_height(name, x, y, scale=min(H, W) * h / 2)
    n = np.stack([-p, -q, np.ones_like(p)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[~inside] = np.nan
    return GroundTruth(depth=-z, normals=n, mask=inside, pixel_size=h, name=name)


# ----------------------------------------------------------------------------------------------
# mesh rendering

_s3 = 1 / np.sqrt(3.0)

#: Named view directions (the direction the rays travel, in the mesh's coordinates).
VIEWS = {
    "front": (0.0, 0.0, -1.0),
    "back": (0.0, 0.0, 1.0),
    "right": (-1.0, 0.0, 0.0),
    "left": (1.0, 0.0, 0.0),
    "top": (0.0, -1.0, 0.0),
    "bottom": (0.0, 1.0, 0.0),
    "oblique": (-_s3, -_s3, -_s3),
    "oblique2": (_s3, -_s3, -_s3),
}


#: The view of :func:`tabletop` scenes: from the front, about 29 degrees above the table.
TABLE_VIEW = (0.0, -0.55, -1.0)


def tabletop(meshes, *, seed: int = 0, spacing: float = 0.9, behind=(0.1, 0.6),
             margin: float = 0.6):
    """A scene of several objects resting on a table, as one triangle mesh (y up).

    Each mesh is centred, scaled into the unit sphere and turned about the vertical by a
    random angle; they stand side by side along x, `spacing` radii apart, every second one
    set back behind its neighbours' bounding boxes by a random gap in `behind` (radii), so
    that the objects in front hide parts of it; each rests with its lowest point on the plane
    y = 0, and no two bounding boxes meet (an object that would reach into another's is moved
    along x until it does not): the objects touch the table, never one another. The table is
    a thin box under them, `margin` radii larger than their footprint. Seen from
    :data:`TABLE_VIEW` (render with ``view=TABLE_VIEW``), every object occludes the table
    (the jump fading where it rests on it) and the objects set back are partly hidden by
    their neighbours: jumps between separate objects, not only self-occlusions (as in
    DiLiGenT's `harvest`).

    Parameters
    ----------
    meshes : sequence of trimesh.Trimesh or paths
    seed : int or numpy.random.Generator
        Seeds the turns, the jitter along x and the gaps behind.
    spacing, behind, margin : float, (float, float), float
        In units of the objects' radius (1 after the scaling).

    Returns
    -------
    trimesh.Trimesh
    """
    trimesh = _trimesh("tabletop")
    parts, table = _tabletop_parts(meshes, seed, spacing, behind, margin)
    return trimesh.util.concatenate(parts + [table])


def _meshes(meshes, least: int = 1) -> list:
    """The `meshes` argument of :func:`tabletop` and :func:`room` as a list: one mesh or path
    alone is a list of one (a path's characters were taken for file names, an audit)."""
    if isinstance(meshes, (str, Path)) or hasattr(meshes, "faces"):
        return [meshes]
    try:
        out = list(meshes)
    except TypeError:
        raise ValueError("`meshes` must be a list of trimesh.Trimesh or mesh file paths; got "
                         f"{type(meshes).__name__}") from None
    if len(out) < least:
        raise ValueError("`meshes` must name at least one mesh")
    return out


def _pair(value, name: str, low: float, *, open_low: bool = False) -> tuple[float, float]:
    """`value` as two numbers ``low <= a <= b`` (above `low` with `open_low`), by `name`."""
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be two numbers (low, high); got {value!r}") from None
    a = _real(a, name, low, open_low=open_low)
    b = _real(b, name, low, open_low=open_low)
    if a > b:
        raise ValueError(f"`{name}` must be (low, high) with low <= high; got {value!r}")
    return a, b


def _seed(seed, name: str = "seed") -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"`{name}` must be an integer >= 0; got {seed!r}")
    return int(seed)


def _tabletop_parts(meshes, seed, spacing, behind, margin):
    """The objects of :func:`tabletop`, placed, and the table: (list, trimesh.Trimesh)."""
    trimesh = _trimesh("tabletop")

    meshes = _meshes(meshes)
    spacing = _real(spacing, "spacing", 0, open_low=True)
    behind = _pair(behind, "behind", 0)
    margin = _real(margin, "margin", 0)
    rng = _rng(seed, "seed")
    parts = []
    k = len(meshes)
    for i, mesh in enumerate(meshes):
        m = _load_mesh(mesh, "tabletop").copy()
        m.apply_translation(-m.bounds.mean(axis=0))
        m.apply_scale(1.0 / np.linalg.norm(m.vertices, axis=1).max())
        m.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(-np.pi, np.pi),
                                                                  [0.0, 1.0, 0.0]))
        centre = m.bounds.mean(axis=0)  # (after the turn: x and z centred again)
        m.apply_translation([(i - (k - 1) / 2) * spacing + rng.uniform(-0.15, 0.15)
                             - centre[0], -m.bounds[0, 1], -centre[2]])
        parts.append(m)
    for i in range(1, k, 2):  # set back behind the neighbours in front
        front = [parts[j].bounds[0, 2] for j in (i - 1, i + 1) if j < k]
        parts[i].apply_translation([0.0, 0.0, min(front) - rng.uniform(*behind)
                                    - parts[i].bounds[1, 2]])

    def meet(a, b):
        return bool(np.all(a.bounds[0] < b.bounds[1]) and np.all(b.bounds[0] < a.bounds[1]))

    for _ in range(k):  # (each pass moves objects right only: at most k passes)
        moved = False
        for i in range(k):
            for j in range(i):
                if meet(parts[i], parts[j]):
                    parts[i].apply_translation([parts[j].bounds[1, 0] - parts[i].bounds[0, 0]
                                                + 0.05, 0.0, 0.0])
                    moved = True
        if not moved:
            break
    lo = np.min([m.bounds[0] for m in parts], axis=0)
    hi = np.max([m.bounds[1] for m in parts], axis=0)
    table = trimesh.creation.box(extents=[hi[0] - lo[0] + 2 * margin, 0.02,
                                          hi[2] - lo[2] + 2 * margin])
    table.apply_translation([(hi[0] + lo[0]) / 2, -0.01, (hi[2] + lo[2]) / 2])
    return parts, table


#: Camera elevations (degrees below the horizontal) of :func:`room_view`, by seed in turn:
#: from eye level, where the floor recedes steeply and the walls face the camera, to above.
ROOM_ELEVATIONS = (8.0, 16.0, 24.0)


def room_view(seed: int = 0) -> tuple[float, float, float]:
    """The view of :func:`room` scene `seed` (the direction the rays travel, toward -z):
    :data:`ROOM_ELEVATIONS` below the horizontal in turn, turned 20 degrees toward its side
    wall (render with ``view=room_view(seed)``)."""
    seed = _seed(seed)
    side = -1.0 if seed % 2 == 0 else 1.0  # (the wall's side: left for even seeds)
    el = np.radians(ROOM_ELEVATIONS[seed % len(ROOM_ELEVATIONS)])
    az = np.radians(20.0)
    return (float(side * np.sin(az) * np.cos(el)), float(-np.sin(el)),
            float(-np.cos(az) * np.cos(el)))


def room(meshes, *, seed: int = 0, size: float = 4.0, height: float = 2.0, boxes: int = 1,
         radius=(0.35, 0.6)):
    """The corner of a room with objects standing on its floor, as one triangle mesh (y up):
    the scenes of a photo that a monocular normal estimator is run on.

    A square floor of side `size` (y = 0), a back wall (z = -size/2) and one side wall
    (x = -size/2 for even seeds, +size/2 for odd ones), both `height` high, all thin boxes;
    on the floor each mesh, centred, scaled to a random radius in `radius`, turned about the
    vertical at random and resting with its lowest point on it, and `boxes` boxes of random
    sides (0.3-0.8) turned about the vertical; positions drawn at random on the floor (seeded)
    until no two bounding boxes meet and none reaches a wall. Seen from
    :func:`room_view` (``seed``), the walls and the floor meet in creases that are no jumps
    (concave, depth continuous), the boxes stand on the floor along creases, and every
    object hides the floor or a wall behind it (jumps fading where it stands).

    Returns
    -------
    trimesh.Trimesh
    """
    trimesh = _trimesh("room")
    meshes, seed = _meshes(meshes, least=0), _seed(seed)  # (an empty room is a room)
    size = _real(size, "size", 0, open_low=True)
    height = _real(height, "height", 0, open_low=True)
    boxes = _seed(boxes, "boxes")
    radius = _pair(radius, "radius", 0, open_low=True)
    rng = np.random.default_rng(seed)
    half = size / 2.0
    parts = []
    for mesh in meshes:
        m = _load_mesh(mesh, "room").copy()
        m.apply_translation(-m.bounds.mean(axis=0))
        m.apply_scale(rng.uniform(*radius) / np.linalg.norm(m.vertices, axis=1).max())
        parts.append(m)
    for _ in range(boxes):
        parts.append(trimesh.creation.box(extents=rng.uniform(0.3, 0.8, size=3)))
    placed = []
    for m in parts:
        m.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(-np.pi, np.pi),
                                                                  [0.0, 1.0, 0.0]))
        lo, hi = m.bounds
        for _ in range(200):  # (a free spot: boxes that do not meet, off the walls)
            x = rng.uniform(-half + 0.1 - lo[0], half - 0.1 - hi[0])
            z = rng.uniform(-half + 0.1 - lo[2], half - 0.1 - hi[2])
            a, b = lo + [x, -lo[1], z], hi + [x, -lo[1], z]
            if all(np.any(a >= q[1]) or np.any(b <= q[0]) for q in placed):
                break
        else:
            raise ValueError(f"room: no free place on a floor of side {size:g} for "
                             f"{len(parts)} objects; pass fewer or a larger `size`")
        m.apply_translation([x, -lo[1], z])
        placed.append(m.bounds)
    t = 0.02
    floor = trimesh.creation.box(extents=[size, t, size])
    floor.apply_translation([0.0, -t / 2, 0.0])
    back = trimesh.creation.box(extents=[size, height, t])
    back.apply_translation([0.0, height / 2, -half - t / 2])
    side = trimesh.creation.box(extents=[t, height, size])
    side.apply_translation([(-1.0 if seed % 2 == 0 else 1.0) * (half + t / 2), height / 2,
                            0.0])
    return trimesh.util.concatenate(parts + [floor, back, side])


#: The kinds of :func:`vessel`.
VESSELS = ("cup", "bowl", "goblet", "vase")


def _vessel_outer(kind: str) -> tuple[np.ndarray, float]:
    """Outer profile (radius, height) from the axis at the bottom up to the rim, and the
    height of the inside's floor."""
    if kind == "cup":  # slightly flared walls on a flat bottom
        return np.array([(0.0, 0.0), (0.35, 0.0), (0.38, 0.05), (0.42, 0.8)]), 0.06
    if kind == "bowl":  # a quarter ellipse on a low foot
        a = np.linspace(0.1, np.pi / 2, 14)
        arc = np.c_[0.25 + 0.35 * np.sin(a), 0.03 + 0.4 * (1.0 - np.cos(a))]
        return np.vstack([[(0.0, 0.0), (0.25, 0.0), (0.25, 0.03)], arc]), 0.06
    if kind == "goblet":  # a foot, a thin stem and a rounded cup above it
        a = np.linspace(0.15, np.pi / 2, 12)
        arc = np.c_[0.12 + 0.26 * np.sin(a), 0.48 + 0.5 * (1.0 - np.cos(a))]
        base = [(0.0, 0.0), (0.35, 0.0), (0.35, 0.03), (0.06, 0.06), (0.045, 0.2),
                (0.045, 0.4), (0.12, 0.48)]
        return np.vstack([base, arc]), 0.55
    if kind == "vase":  # a bulging body narrowing to the mouth
        h = np.linspace(0.0, 1.0, 24)
        body = np.c_[0.2 + 0.15 * np.sin(1.3 * np.pi * h) + 0.05 * h, h]
        return np.vstack([[(0.0, 0.0)], body]), 0.06
    raise ValueError(f"`kind` must be one of {list(VESSELS)}; got {kind!r}")


def vessel(kind: str = "cup", *, thickness: float = 0.03, sections: int = 256,
           rim: str = "round"):
    """An open vessel as one closed triangle mesh (y up, resting on y = 0, about 0.45-1 unit
    tall): a surface of revolution whose profile runs up the outside, over a rim `thickness`
    wide, down the inside (the outside wall moved inward by `thickness` along the radius) and
    across a flat floor to the axis.

    Seen from above the rim (:func:`vessel_view`), the inside shows through the mouth: the
    front of the rim hides part of the inside (a depth jump whose height grows toward the
    middle), the back of the rim folds into the inside wall (a crease, no jump), and the rim
    itself is a band a few pixels wide. Photometric-stereo objects of this kind (cups, bowls,
    goblets, vases, pots) are common, and the pieces the jumps separate are joined only across
    such thin folds.

    Parameters
    ----------
    kind : {"cup", "bowl", "goblet", "vase"}
        Straight flared walls on a flat bottom; a shallow rounded bowl on a low foot; a rounded
        cup on a thin stem and a foot (whose foot the cup can hide from the stem); a bulging
        body with a narrow mouth.
    thickness : float
        Radial thickness of the walls (the rim's width), in the profile's units.
    sections : int
        Facets around the axis (at least 8).
    rim : {"round", "flat"}
        The rim's top: a half circle across the wall (as turned or moulded rims are: its
        normals turn to grazing at both edges, so the edge that hides the inside shows in the
        normals), or a flat ring with sharp edges (whose normal is the floor's where both are
        level: a jump between the two is then in no normal).

    Returns
    -------
    trimesh.Trimesh

    Raises
    ------
    ValueError
        For an unknown `kind` or `rim`, a `thickness` outside (0, half the mouth's radius) or
        fewer than 8 `sections`.
    ImportError
        Without trimesh (the render extra).
    """
    trimesh = _trimesh("vessel")
    outer, floor = _vessel_outer(kind)
    top_r = float(outer[-1, 0])
    try:
        t = float(thickness)
        n = int(sections)
    except (TypeError, ValueError):
        raise ValueError(f"`thickness` must be a number and `sections` an integer; got "
                         f"{thickness!r}, {sections!r}") from None
    if not 0.0 < t < 0.5 * top_r:
        raise ValueError(f"`thickness` must be in (0, {0.5 * top_r:g}) for {kind!r}; got "
                         f"{thickness!r}")
    if n != sections or n < 8:
        raise ValueError(f"`sections` must be an integer of at least 8; got {sections!r}")
    if rim not in ("round", "flat"):
        raise ValueError(f"`rim` must be 'round' or 'flat'; got {rim!r}")
    # the inside: the outside wall above the floor moved inward by the thickness, from the rim
    # down to where the outside crosses the floor's height, then the floor to the axis
    above = np.flatnonzero(outer[:, 1] > floor)
    first = int(above[0])  # (the outside rises monotonically from here: every kind's profile)
    (r0, h0), (r1, h1) = outer[first - 1], outer[first]
    r_floor = r0 + (r1 - r0) * (floor - h0) / (h1 - h0)
    inner = np.c_[outer[first:, 0] - t, outer[first:, 1]][::-1]
    top = np.empty((0, 2))
    if rim == "round":  # a half circle from the outside's top to the inside's, over the wall
        a = np.linspace(0.0, np.pi, 11)[1:-1]
        top_h = float(outer[-1, 1])
        top = np.c_[top_r - 0.5 * t + 0.5 * t * np.cos(a), top_h + 0.5 * t * np.sin(a)]
    profile = np.vstack([outer, top, inner, [(r_floor - t, floor), (0.0, floor)]])
    mesh = trimesh.creation.revolve(profile, sections=n)
    # (revolve turns about z: make z the up axis y)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1.0, 0.0, 0.0]))
    return mesh


def vessel_view(elevation_deg: float) -> tuple[float, float, float]:
    """The viewing direction of a camera `elevation_deg` degrees above the horizontal (below it
    for a negative angle), looking at a y-up scene from its front (for
    ``render_perspective(..., view=...)``; the image's up is the scene's up, turning toward
    its back, -z, as the camera rises: no jump in between)."""
    try:
        e = float(elevation_deg)
    except (TypeError, ValueError):
        e = float("nan")
    if not -90.0 < e < 90.0:
        raise ValueError(f"`elevation_deg` must be a number in (-90, 90); got {elevation_deg!r}")
    e = np.radians(e)
    return (0.0, -float(np.sin(e)), -float(np.cos(e)))


def _view_frame(view) -> np.ndarray:
    """Rows X (right), Y (up), Z (toward the viewer) of the image frame in mesh coordinates."""
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"`view` must be one of {list(VIEWS)} or a 3-vector; got {view!r}")
        d = np.array(VIEWS[view])
    else:
        d = np.asarray(view, dtype=float)
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError(f"`view` must be a view name or a non-zero 3-vector; got {view!r}")
    Z = -d / np.linalg.norm(d)
    up = np.array([0.0, 1.0, 0.0])
    if abs(Z @ up) > 0.99:  # looking along +-y: the mesh's -z/+z is up in the image
        up = np.array([0.0, 0.0, -1.0 if Z[1] > 0 else 1.0])
    Y = up - (up @ Z) * Z
    Y /= np.linalg.norm(Y)
    X = np.cross(Y, Z)
    return np.stack([X, Y, Z])


def _trimesh(caller: str):
    """The trimesh module, or an ImportError naming `caller` and the extra that brings it."""
    try:
        import trimesh
    except ImportError as e:
        raise ImportError(
            f"facetlift.synthetic.{caller} needs trimesh, which comes with the render extra: "
            "pip install 'facetlift[render]'"
        ) from e
    return trimesh


def _load_mesh(mesh, caller: str = "render_mesh"):
    trimesh = _trimesh(caller)
    if isinstance(mesh, trimesh.Trimesh):
        if len(mesh.faces) == 0:  # (numpy's "zero-size array to reduction" otherwise)
            raise ValueError("`mesh` holds no triangles")
        return mesh
    if isinstance(mesh, (str, Path)):
        p = Path(mesh)
        if not p.is_file():
            raise ValueError(f"`mesh` file not found: {p}")
        m = trimesh.load(p, force="mesh")
        if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
            raise ValueError(f"`mesh` {p} holds no triangles")
        return m
    raise ValueError(f"`mesh` must be a trimesh.Trimesh or a file path; got {type(mesh).__name__}")


def _first_hits(mesh, origins, direction):
    """Index of the first triangle hit by each ray (-1 for a miss). The ray caster's scene is
    built once per mesh (kept on it: the jump search, :func:`_jump_sizes`, casts a few
    dozen times, and rebuilt it each time, two thirds of its cost)."""
    dirs = np.broadcast_to(direction, origins.shape)
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        key, caster = getattr(mesh, "_facetlift_caster", (None, None))
        if caster is None or key != hash(mesh):  # (trimesh's hash follows its geometry)
            caster = RayMeshIntersector(mesh)
            with contextlib.suppress(AttributeError):
                mesh._facetlift_caster = (hash(mesh), caster)
        return caster.intersects_first(origins, dirs)
    except ImportError:  # pragma: no cover - embreex is installed in the test setup
        from trimesh.ray.ray_triangle import RayMeshIntersector

        try:
            return RayMeshIntersector(mesh).intersects_first(origins, dirs)
        except ImportError as e:  # (trimesh's own caster needs rtree: named, an audit)
            raise ImportError("facetlift.synthetic's ray casting needs embreex (or rtree for "
                              "trimesh's slower caster), which come with the render extra: "
                              "pip install 'facetlift[render]'") from e


#: :func:`_jump_sizes`: rays along each edge at first (the points between the two centres),
#: halvings of the intervals, the halvings over which a step must keep more than half its
#: size to be a jump (a continuous surface's step halves with each, a grazing one's shrinks
#: by 1/sqrt(2), a jump's stays), and the most intervals followed per edge (those of the
#: largest steps: a jump's interval keeps its step while a ramp's shrink, but beside a ramp
#: that runs the other way at more than about 64 times the jump per pixel the ramp's fill
#: the places first and the jump is lost, a review; the cap bounds the cost on surfaces
#: steep everywhere).
JUMP_SAMPLES, JUMP_HALVINGS, JUMP_KEEP, JUMP_LIVE = 4, 10, 3, 64


def _jump_sizes(cast, camera, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(right (H, W-1), down (H-1, W)) float: the depth jump between each pair of
    4-neighbouring `mask` pixels in pixel footprints of `camera`'s unknown (height, or
    log-depth), from the geometry: `cast(rows, cols)` (m,) gives the depth where the rays
    through image points (row, col) (pixel centres at integers) hit the surface, NaN where
    they miss it (or hit it edge-on).

    Each edge's line between the two centres is sampled at :data:`JUMP_SAMPLES` intervals.
    Where one of them steps by more than a quarter footprint in the unknown, each is halved,
    all halves for the first :data:`JUMP_KEEP` halvings and then those whose step still
    exceeds a quarter footprint, :data:`JUMP_HALVINGS` times (at most :data:`JUMP_LIVE`
    intervals per edge, those of the largest steps; a miss is an infinite step). A continuous
    surface's step shrinks with the halvings (by half where it is smooth, by 1/sqrt(2) where
    it turns edge-on), a jump's does not: the edge's size is the largest final step of an
    interval that kept more than half of its step over the last :data:`JUMP_KEEP` halvings,
    else 0 (the step over the last interval: a steep ramp adds up to its slope / 4096).
    Following only the larger half at each halving lost a jump of 2 footprints beside a
    steep ramp of 16; the cap of :data:`JUMP_LIVE` can still lose one beside a much steeper
    ramp running the other way, and a feature narrower than the first rays' spacing (a
    quarter pixel) goes unseen. Steps under a quarter footprint read as 0; inf where a ray
    cast between the two centres misses the surface. The pixel-centre test
    (:func:`jump_edges` without them) cut continuous surfaces and missed grazing jumps on
    the benchmark's renders (docs/results.md, "Known limits")."""
    H, W = mask.shape
    foot = camera.footprint()
    least = 0.25 * foot
    out = []
    for dr, dc in ((0, 1), (1, 0)):
        both = mask[: H - dr, : W - dc] & mask[dr:, dc:]
        r0, c0 = np.nonzero(both)
        n = JUMP_SAMPLES
        t = np.arange(n + 1) / n
        rows = r0[:, None] + dr * t[None, :]
        cols = c0[:, None] + dc * t[None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            u = camera.from_depth(cast(rows.ravel(), cols.ravel())).reshape(rows.shape)
            step = np.abs(np.diff(u, axis=1))
        step = np.where(np.isfinite(step), step, np.inf)
        # every interval of an edge with some step above a quarter footprint (a jump beside
        # an opposite ramp can leave its own interval's step small at first)
        edge, k = np.nonzero(np.repeat((step > least).any(axis=1, keepdims=True), n, axis=1))
        lo, width = t[k], 1.0 / n  # (every interval of a level is as wide)
        ulo, uhi = u[edge, k], u[edge, k + 1]
        hist = np.repeat(step[edge, k][:, None], JUMP_KEEP + 1, axis=1)  # (the last steps)
        for level in range(JUMP_HALVINGS):
            mid = lo + 0.5 * width
            with np.errstate(invalid="ignore", divide="ignore"):
                um = camera.from_depth(cast(r0[edge] + dr * mid, c0[edge] + dc * mid))
                left, right = np.abs(um - ulo), np.abs(uhi - um)
            left = np.where(np.isfinite(left), left, np.inf)
            right = np.where(np.isfinite(right), right, np.inf)
            # both halves, each with its own step; those above a quarter footprint go on
            edge = np.r_[edge, edge]
            lo = np.r_[lo, mid]
            width *= 0.5
            ulo, uhi = np.r_[ulo, um], np.r_[um, uhi]
            new = np.r_[left, right]
            hist = np.column_stack([np.r_[hist[:, 1:], hist[:, 1:]], new])
            # (all of them over the first JUMP_KEEP halvings: as above)
            keep = (new > 0.4 * least) | (level < JUMP_KEEP)
            # at most JUMP_LIVE per edge, the largest steps first
            order = np.lexsort((-new, edge))
            rank = np.empty(order.size, np.int64)
            first = np.r_[0, np.flatnonzero(np.diff(edge[order])) + 1]
            counts = np.diff(np.r_[first, order.size])
            rank[order] = np.arange(order.size) - np.repeat(first, counts)
            keep &= rank < JUMP_LIVE
            edge, lo, ulo, uhi, hist = (a[keep] for a in (edge, lo, ulo, uhi, hist))
        last, before = hist[:, -1], hist[:, 0]
        with np.errstate(invalid="ignore"):
            jump = (last > 0.5 * before) | np.isinf(last)
        value = np.where(jump, last / foot, 0.0)
        flat = np.zeros(r0.size)
        np.maximum.at(flat, edge, value)
        size = np.zeros(both.shape)
        size[r0, c0] = flat
        out.append(size)
    return out[0], out[1]


def _hits(depth, normals, mask, **kw) -> GroundTruth:
    """The ground truth of a render: the pixels whose ray hit (`mask`), without lone pixels;
    NaN elsewhere. Refuses a view that covers no pixel."""
    from .problem import clean_mask

    if mask.any():
        mask = clean_mask(mask, min_size=2)
    if not mask.any():
        raise ValueError("`mesh` covers no pixel of the image in this view")
    depth[~mask] = np.nan
    normals[~mask] = np.nan
    return GroundTruth(depth=depth, normals=normals, mask=mask, **kw)


def _mesh_in_view(mesh, view, name, caller: str = "render_mesh"):
    """(label, trimesh mesh, the view's frame (3, 3), the vertices (n, 3) in it: x right, y up,
    z toward the viewer) of a mesh to render; the label is `name` or ``"<stem>@<view>"``."""
    label = name
    if label is None:
        stem = Path(mesh).stem if isinstance(mesh, (str, Path)) else "mesh"
        label = f"{stem}@{view if isinstance(view, str) else 'custom'}"
    m = _load_mesh(mesh, caller)
    frame = _view_frame(view)
    return label, m, frame, np.asarray(m.vertices, dtype=float) @ frame.T


def render_mesh(
    mesh,
    resolution=128,
    *,
    view="front",
    margin: float = 0.05,
    pixel_size: float = 1.0,
    name: str | None = None,
    jumps: bool = False,
) -> GroundTruth:
    """Orthographic depth and normal maps of a triangle mesh, one ray per pixel centre.

    The mesh is scaled so that its projection fits the image with `margin` (a fraction of the
    image size) on the tighter side, centred. Depth is the hit distance along the view axis from
    a plane in front of the mesh, computed in float64 from the hit triangle's plane (the ray
    caster only picks the triangle); the normal is that triangle's face normal in the image
    frame (x right, y up, z toward the viewer), flipped toward the viewer where the winding
    makes it face away. Pixels whose hit triangle is seen edge-on (``|n_z| < 1e-6``) are left
    out of the mask, as are isolated single pixels.

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
    resolution : int or (H, W)
    view : str or (3,) array_like
        A name in :data:`VIEWS` or the direction the rays travel, in mesh coordinates. The
        image's up is the mesh's +y (or +-z when looking within 8.1 degrees of the y axis: seen
        from above, the mesh's -z, its back, is up).
    margin : float
        Empty border on each side, as a fraction of the image size, in [0, 0.45].
    pixel_size : float
        Pixel width in the output's units (the depth is expressed in these units).
    name : str, optional
        Label; default ``"<file stem>@<view>"``.
    jumps : bool
        Also find the depth jumps between neighbouring pixels from the geometry
        (``GroundTruth.jump_sizes``, :func:`_jump_sizes`: more rays between the centres).

    Returns
    -------
    GroundTruth

    Raises
    ------
    ValueError
        Bad `mesh`, `resolution`, `view`, `margin` or `pixel_size`, or a mesh that covers no
        pixel.
    ImportError
        If trimesh is not installed (``pip install 'facetlift[render]'``).
    """
    H, W = _size(resolution, "resolution")
    margin = _real(margin, "margin", 0, 0.45)
    h = _real(pixel_size, "pixel_size", 0, open_low=True)
    _flag(jumps, "jumps")
    label, m, frame, P = _mesh_in_view(mesh, view, name)
    lo, hi = P.min(axis=0), P.max(axis=0)
    ext = hi - lo
    if ext[0] <= 0 and ext[1] <= 0:
        raise ValueError("`mesh` projects to a single point in this view")
    world_h = max(ext[0] / (W * (1 - 2 * margin)), ext[1] / (H * (1 - 2 * margin)))
    centre = (lo + hi) / 2
    z0 = hi[2] + 0.01 * max(ext.max(), world_h)
    direction = -frame[2]
    faces_n = np.asarray(m.face_normals, dtype=float) @ frame.T

    def cast(rows, cols):  # (depth and the hit facet's normal at image points (row, col))
        x = centre[0] + (np.asarray(cols, float) + 0.5 - W / 2) * world_h
        y = centre[1] + (H / 2 - np.asarray(rows, float) - 0.5) * world_h
        origins = np.column_stack([x, y, np.full_like(x, z0)]) @ frame
        tri = _first_hits(m, origins, direction)
        hit = tri >= 0
        fn = faces_n[tri[hit]]
        fn[fn[:, 2] < 0] *= -1
        ok = np.abs(fn[:, 2]) > 1e-6
        idx = np.nonzero(hit)[0][ok]
        fn = fn[ok]
        # exact ray/plane intersection in float64: t = n.(v0 - o) / n.d, in the image frame
        v0 = P[m.faces[tri[idx], 0]]
        o = np.column_stack([x[idx], y[idx], np.full(idx.size, z0)])
        t = np.einsum("ij,ij->i", fn, v0 - o) / (-fn[:, 2])
        depth = np.full(x.size, np.nan)
        normals = np.full((x.size, 3), np.nan)
        depth[idx] = t / world_h * h
        normals[idx] = fn / np.linalg.norm(fn, axis=1, keepdims=True)
        return depth, normals

    rows, cols = np.mgrid[0:H, 0:W].astype(float)
    depth, normals = cast(rows.ravel(), cols.ravel())
    gt = _hits(depth.reshape(H, W), normals.reshape(H, W, 3),
               np.isfinite(depth.reshape(H, W)), pixel_size=h, name=label)
    if jumps:
        gt.jump_sizes = _jump_sizes(lambda r, c: cast(r, c)[0], gt.camera, gt.mask)
    return gt


#: Intrinsics of the DiLiGenT camera (OpenCV layout; 512 x 612 images, f ~ 3,770 px).
DILIGENT_K = np.array([[3772.0775, 0.0, 305.875], [0.0, 3759.0054, 255.125], [0.0, 0.0, 1.0]])


def render_perspective(
    mesh,
    K=None,
    resolution=(512, 612),
    *,
    view="front",
    distance: float = 1500.0,
    fill: float = 0.6,
    samples: int = 1,
    name: str | None = None,
    jumps: bool = False,
) -> GroundTruth:
    """Perspective depth and normal maps of a triangle mesh, rays through the pixel centres.

    The camera sits at the origin of an OpenCV frame (x right, y down, z forward) with
    intrinsics `K` (pixel centres at integer indices, :mod:`facetlift.conventions`). The mesh
    is turned so that `view` is the viewing direction, scaled so that its bounding sphere
    spans `fill` of the shorter image side, and centred on the optical axis at `distance`
    along it. Depth is the z-coordinate of the hit, in float64 from the hit triangle's plane
    (the ray caster only picks the triangle); the normal is that triangle's face normal turned
    toward the camera, in the facetlift frame (x right, y up, z toward the viewer). Pixels
    whose triangle is seen edge-on are left out of the mask, as are isolated pixels. Because
    the rendered surface is piecewise planar, these normals are exact at every pixel centre.
    With ``samples=s > 1`` the normal is instead the normalised mean over an ``s x s`` grid
    of rays across the pixel (what a camera integrates: fine detail is averaged, pixels that
    straddle an occlusion mix the two surfaces), while depth and mask stay those of the
    centre ray.

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
    K : (3, 3) array_like, optional
        Default :data:`DILIGENT_K`, scaled to `resolution` if it differs from 512 x 612: both
        focal lengths by W / 612 and the principal point too (``s * c``: a quarter to half a
        pixel from the same place in the image, ``s * (c + 0.5) - 0.5`` of docs/conventions.md;
        kept so that the benchmark's cached renders stay the same).
    resolution : (H, W) or int
    view : str or (3,) array_like
        A name in :data:`VIEWS` or the direction the rays travel, in mesh coordinates.
    distance : float
        Distance of the object's centre from the camera, in the output depth units
        (default 1,500 like DiLiGenT, in mm).
    fill : float
        Fraction of the shorter image side the object's bounding sphere spans, in (0, 4]:
        above 1 the image shows a part of the mesh (a room seen from inside it,
        :func:`room`; the camera must not sit inside a closed surface).
    samples : int
        Rays per pixel side for the normals (1: the centre ray only).
    name : str, optional
        Label; default ``"<file stem>@<view>"``.
    jumps : bool
        Also find the depth jumps between neighbouring pixels from the geometry
        (``GroundTruth.jump_sizes``, :func:`_jump_sizes`: more rays between the centres).

    Returns
    -------
    GroundTruth
        With ``K`` set; depth is z-depth along the optical axis.

    Raises
    ------
    ValueError
        Bad arguments, or a mesh that covers no pixel.
    ImportError
        If trimesh is not installed (``pip install 'facetlift[render]'``).
    """
    from .camera import check_K

    H, W = _size(resolution, "resolution")
    if K is None:
        K = DILIGENT_K.copy()
        if (H, W) != (512, 612):  # the focal lengths by one factor (square pixels stay
            # square: scaled per axis, a 1536 x 2048 image got fx / fy 1.12), the principal
            # point scaled with the image: within half a pixel of the same place (the resize
            # rule s (c + 1/2) - 1/2 of docs/perspective.md; kept, the renders of other sizes
            # were made so; the K returned is the one used, a review)
            K[0] *= W / 612
            K[1, 1] *= W / 612
            K[1, 2] *= H / 512
    K = check_K(K)
    _flag(jumps, "jumps")
    distance = _real(distance, "distance", 0, open_low=True)
    fill = _real(fill, "fill", 0, 4, open_low=True)
    if (isinstance(samples, (bool, np.bool_))
            or not isinstance(samples, (int, float, np.integer, np.floating))
            or not float(samples).is_integer() or samples < 1):
        raise ValueError(f"`samples` must be an integer >= 1; got {samples!r}")
    label, m, frame, P = _mesh_in_view(mesh, view, name, "render_perspective")
    centre = (P.min(axis=0) + P.max(axis=0)) / 2
    radius = float(np.linalg.norm(P - centre, axis=1).max())
    f = float(min(K[0, 0], K[1, 1]))
    half = np.arctan(fill * min(H, W) / (2 * f))
    scale = distance * np.tan(half) / radius
    # to the OpenCV camera frame: y down, z forward, centre on the optical axis at `distance`
    C = (P - centre) * scale * np.array([1.0, -1.0, -1.0]) + np.array([0.0, 0.0, distance])
    import trimesh

    cam_mesh = trimesh.Trimesh(vertices=C, faces=np.asarray(m.faces), process=False)
    if fill > 1 and cam_mesh.is_watertight and bool(cam_mesh.contains(np.zeros((1, 3)))[0]):
        # (it rendered the inside, every pixel in the mask, without a word: an audit's wish)
        raise ValueError(f"render_perspective: at fill={fill:g} the camera sits inside the "
                         f"closed mesh {label!r}; lower `fill` (1 frames the whole object)")
    faces_n = np.asarray(cam_mesh.face_normals, dtype=float)
    Kinv = np.linalg.inv(K).T

    def cast(rows, cols):  # (z-depth and the camera-facing normal at image points)
        rows, cols = np.asarray(rows, float), np.asarray(cols, float)
        dirs = np.column_stack([cols, rows, np.ones(rows.size)]) @ Kinv
        tri = _first_hits(cam_mesh, np.zeros_like(dirs), dirs)
        hit = np.nonzero(tri >= 0)[0]
        fn = faces_n[tri[hit]]
        d = dirs[hit]
        dn = np.einsum("ij,ij->i", fn, d)
        fn[dn > 0] *= -1  # toward the camera
        dn = -np.abs(dn)
        ok = np.abs(dn) / np.linalg.norm(d, axis=1) > 1e-6
        hit, fn, dn = hit[ok], fn[ok], dn[ok]
        v0 = C[cam_mesh.faces[tri[hit], 0]]
        t = np.einsum("ij,ij->i", fn, v0) / dn  # ray point t * d (d has unit z): depth = t
        depth = np.full(rows.size, np.nan)
        normals = np.full((rows.size, 3), np.nan)
        depth[hit] = t
        normals[hit] = (fn / np.linalg.norm(fn, axis=1, keepdims=True)
                        * np.array([1.0, -1.0, -1.0]))
        return depth, normals

    rows, cols = np.mgrid[0:H, 0:W].astype(float)
    depth, normals = cast(rows.ravel(), cols.ravel())
    depth = depth.reshape(H, W)
    normals = normals.reshape(H, W, 3)
    if samples > 1:
        normals = _supersampled_normals(cam_mesh, K, H, W, int(samples))
    gt = _hits(depth, normals, np.isfinite(depth) & np.isfinite(normals).all(-1), name=label,
               K=K)
    if jumps:
        gt.jump_sizes = _jump_sizes(lambda r, c: cast(r, c)[0], gt.camera, gt.mask)
    return gt


def _supersampled_normals(cam_mesh, K, H, W, s):
    """Normalised mean camera-facing normal of an s x s ray grid per pixel (facetlift frame)."""
    acc = np.zeros((H * W, 3))
    offsets = (np.arange(s) + 0.5) / s - 0.5
    rows, cols = np.mgrid[0:H, 0:W].astype(float)
    Kinv = np.linalg.inv(K).T
    faces_n = np.asarray(cam_mesh.face_normals, dtype=float)
    for dr in offsets:
        for dc in offsets:
            dirs = np.column_stack([cols.ravel() + dc, rows.ravel() + dr, np.ones(H * W)]) @ Kinv
            tri = _first_hits(cam_mesh, np.zeros_like(dirs), dirs)
            hit = np.nonzero(tri >= 0)[0]
            fn = faces_n[tri[hit]]
            fn[np.einsum("ij,ij->i", fn, dirs[hit]) > 0] *= -1
            acc[hit] += fn
    with np.errstate(invalid="ignore", divide="ignore"):
        n = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    n[~np.isfinite(n).all(1)] = np.nan
    return (n * np.array([1.0, -1.0, -1.0])).reshape(H, W, 3)


def quantize(normals, bits: int) -> np.ndarray:
    """Normals as stored in an integer image and read back: ``round((n + 1) / 2 * max)``, then
    decoded as facetlift's reader decodes a PNG (:func:`facetlift.frames.decode`: ``v / max *
    2 - 1``, and an 8-bit zero plateau, code 128 in a flat area, read as exactly 0); not
    renormalised after the decoding (:func:`facetlift.prepare` does that).

    `bits` is 8 or 16; NaN stays NaN. Normals off unit length are scaled to it first, as the
    perturbations do (a map times 2 was clipped to the cube's faces and then warned about as
    a file's encoding).
    """
    from .frames import decode

    if bits not in (8, 16):
        raise ValueError(f"`bits` must be 8 or 16; got {bits!r}")
    n = _check_normals(normals)  # (scaled to unit length: the codes hold unit vectors)
    top = 2**bits - 1
    finite = np.isfinite(n).all(axis=-1)
    with np.errstate(invalid="ignore"):
        codes = np.round((np.clip(np.where(finite[..., None], n, 0.0), -1, 1) + 1) / 2 * top)
    out = decode(codes.astype(np.uint8 if bits == 8 else np.uint16), where=finite)
    out[~finite] = np.nan
    return out


def jump_edges(gt: GroundTruth, *, tol: float = 0.5,
               geometric: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The edges between 4-neighbouring pixels that a depth jump crosses, from ground truth.

    In the camera's unknown (height, or log-depth for a perspective rendering), the difference
    across an edge is compared with the one the two normals predict (trapezoid rule on their
    grid slopes); the edge is a jump when they differ by more than
    ``0.5 |g_a - g_b| + tol`` pixel footprints -- a bound a single crease of a continuous
    piecewise planar surface never exceeds. Approximate on renders: a curved surface whose
    slope between the centres exceeds both ends', and a silhouette pixel whose supersampled
    normal mixes two surfaces, are cut where the surface is continuous; a grazing jump,
    where the allowance grows with the slope, can be missed (measured in docs/results.md,
    "Known limits"). With `geometric`, the jumps a render made with ``jumps=True`` carries
    from its geometry (``gt.jump_sizes``, rays between the pixel centres) are used instead,
    cut where larger than `tol` footprints. The benchmark's oracle keeps the test above
    (docs/results.md, "Known limits": with the geometric cuts it is higher on most groups).

    Returns
    -------
    right : (H, W-1) bool
        Jump between pixel (r, c) and (r, c+1) (both in the mask).
    down : (H-1, W) bool
        Jump between pixel (r, c) and (r+1, c).
    """
    tol = _real(tol, "tol", 0)
    if geometric:  # (a render's own, from its geometry)
        if gt.jump_sizes is None:
            raise ValueError(f"jump_edges(geometric=True): {gt.name or 'the ground truth'} "
                             "carries no jumps from its geometry; render it with jumps=True")
        right, down = gt.jump_sizes
        m = gt.mask
        return ((right > tol) & m[:, :-1] & m[:, 1:]), ((down > tol) & m[:-1] & m[1:])
    cam = gt.camera
    H, W = gt.shape
    rr, cc = np.mgrid[0:H, 0:W]
    with np.errstate(invalid="ignore", divide="ignore"):
        gx, gy = cam.grid_slopes(rr, cc, gt.normals)
        u = cam.from_depth(gt.depth)
    s = cam.footprint()
    m = gt.mask & np.isfinite(u) & np.isfinite(gx) & np.isfinite(gy)

    def test(a, b, ga, gb):
        with np.errstate(invalid="ignore"):
            bad = np.abs(u[b] - u[a] - 0.5 * (ga + gb)) > 0.5 * np.abs(ga - gb) + tol * s
        return bad & m[a] & m[b]

    a, b = (slice(None), slice(0, W - 1)), (slice(None), slice(1, W))
    right = test(a, b, gx[a], gx[b])
    a, b = (slice(0, H - 1), slice(None)), (slice(1, H), slice(None))
    down = test(a, b, -gy[a], -gy[b])  # one row down is -1 in y
    return right, down


def depth_jumps(gt: GroundTruth, *, tol: float = 0.5) -> np.ndarray:
    """Pixels next to a depth discontinuity.

    Two 8-neighbours ``a, b`` in the mask are split by a jump when their difference in the
    camera's unknown (height, or log-depth with a pinhole camera: :func:`jump_edges`'s test)
    departs from the one their normals predict (trapezoid rule on the slopes) by more than
    ``0.5 |g_a - g_b| + tol`` pixel footprints, ``g`` the slope along the offset: that bound
    is never exceeded across a single crease of a continuous piecewise planar surface.

    Returns
    -------
    (H, W) bool
        Mask pixels with at least one such neighbour.
    """
    tol = _real(tol, "tol", 0)
    # (in the camera's unknown and footprints, as jump_edges: with orthographic slopes in
    # pixel-size units a perspective render in mm had 4,066 of a sphere's 4,664 pixels
    # flagged, and continuous_region kept 598, an audit)
    cam = gt.camera
    H, W = gt.shape
    rr, cc = np.mgrid[0:H, 0:W]
    with np.errstate(invalid="ignore", divide="ignore"):
        gx, gy = cam.grid_slopes(rr, cc, gt.normals)
        u = cam.from_depth(gt.depth)
    s = cam.footprint()
    m = gt.mask & np.isfinite(u) & np.isfinite(gx) & np.isfinite(gy)
    out = np.zeros((H, W), bool)
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, H - dr), slice(max(0, -dc), W - max(0, dc)))
        b = (slice(dr, H), slice(max(0, dc), W - max(0, -dc) if dc < 0 else W))
        ga = gx[a] * dc - gy[a] * dr  # (one row down is -1 in y)
        gb = gx[b] * dc - gy[b] * dr
        with np.errstate(invalid="ignore"):
            bad = np.abs(u[b] - u[a] - 0.5 * (ga + gb)) > 0.5 * np.abs(ga - gb) + tol * s
        bad &= m[a] & m[b]
        out[a] |= bad
        out[b] |= bad
    return out


def continuous_region(gt: GroundTruth, *, tol: float = 0.5) -> GroundTruth:
    """The largest 8-connected part of `gt` after removing the pixels next to depth jumps.

    See :func:`depth_jumps` for the test. Where a jump fades out inside the object (a fold),
    the two sides stay connected around its end: the result is free of jumps between
    neighbours, not necessarily of every inconsistency.
    """
    from .domain import Domain

    keep = gt.mask & ~depth_jumps(gt, tol=tol)
    if not keep.any():
        raise ValueError("`gt` has no pixel away from depth jumps")
    d = Domain.from_mask(keep)
    big = int(np.argmax(d.component_sizes)) + 1
    mask = d.labels == big
    depth = np.where(mask, gt.depth, np.nan)
    normals = np.where(mask[..., None], gt.normals, np.nan)
    return replace(gt, depth=depth, normals=normals, mask=mask, name=gt.name + "+cont")


# ----------------------------------------------------------------------------------------------
# perturbations


#: How far from unit length a normal may be and still be taken as it is by the perturbations
#: (others are scaled to unit length first: their rotations assume unit vectors).
UNIT_TOL = 1e-6


def _check_normals(normals, unit: bool = True) -> np.ndarray:
    """`normals` (..., 3) as floats: a uint8 / uint16 map decoded as :func:`facetlift.integrate`
    decodes it (``v / max * 2 - 1``, with the reader's warning; its raw codes were perturbed
    as vectors, an audit), other numbers taken as they are. With `unit`, a finite
    row further than :data:`UNIT_TOL` from unit length is scaled to it and a zero-length one
    set to NaN (a missing sample): the rotations assume unit vectors (a map scaled by 2 was
    turned by half the angle asked, and ``perturb_fraction`` recorded angles it did not
    apply)."""
    from .frames import as_float_normals

    a = np.asarray(normals)
    if a.dtype.kind == "u" and a.ndim >= 1 and a.shape[-1] == 3:
        a = as_float_normals(a, "normals")
    try:
        n = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"`normals` must be an array of numbers; got {a.dtype} values") from None
    if n.ndim < 1 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must have shape (..., 3); got {n.shape}")
    if unit:
        length = np.linalg.norm(n, axis=-1, keepdims=True)
        off = np.isfinite(length) & (np.abs(length - 1.0) > UNIT_TOL)
        if off.any():
            with np.errstate(invalid="ignore", divide="ignore"):
                n = np.where(off, np.where(length > 0, n / length, np.nan), n)
    return n


def _real(value, name: str, low=None, high=None, *, open_low: bool = False) -> float:
    """`value` as a float, refused by `name` unless a finite real number within the bounds
    (a 0-d array is its number)."""
    import numbers

    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    ok = isinstance(value, (numbers.Real, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)) and bool(np.isfinite(float(value)))
    if ok and low is not None:
        ok = value > low if open_low else value >= low
    if ok and high is not None:
        ok = value <= high
    if not ok:
        where = ("" if low is None and high is None else
                 f" {'>' if open_low else '>='} {low}" if high is None else
                 f" in {'(' if open_low else '['}{low}, {high}]")
        raise ValueError(f"`{name}` must be a finite number{where}; got {value!r}")
    return float(value)


def _flag(value, name: str) -> None:
    if not isinstance(value, (bool, np.bool_)):  # ('no' is true: the jump search ran, an audit)
        raise ValueError(f"`{name}` must be True or False; got {value!r}")


def _check_map(normals) -> np.ndarray:
    n = _check_normals(normals)
    if n.ndim != 3:
        raise ValueError(f"`normals` must be an (H, W, 3) map; got shape {n.shape}")
    return n


def _rng(rng, name: str = "rng"):
    if isinstance(rng, np.random.Generator):
        return rng
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a numpy.random.Generator, a seed (an integer >= 0) "
                         f"or None; got {rng!r}") from None


def _rotate(n, angles, rng, keep_front):
    """Rotate unit vectors n (k, 3) by `angles` (rad) about random axes perpendicular to them."""
    a = rng.normal(size=n.shape)
    axis = a - np.einsum("ij,ij->i", a, n)[:, None] * n
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    side = np.cross(axis, n)  # unit, perpendicular to n, in the rotation plane
    return _turn(n, side, angles, keep_front)


def add_angular_noise(normals, sigma_deg: float, rng=None, *, keep_front: bool = True):
    """Rotate every normal by an angle ~ N(0, sigma) about a random perpendicular axis.

    Parameters
    ----------
    normals : (..., 3) array_like
        Unit normals (others are scaled to unit length, a zero-length one becomes NaN;
        uint8 / uint16 codes are decoded as ``integrate`` decodes them); NaN rows stay NaN.
    sigma_deg : float
        Standard deviation of the rotation angle in degrees (the paper uses 5), at most 30:
        beyond, angles past 90 degrees are common and the distribution below no longer holds.
    rng : numpy.random.Generator or seed
    keep_front : bool
        Where a rotation would turn a front-facing normal away from the viewer (``n_z <= 0``),
        rotate by the opposite angle instead (same angle, so the angle distribution is kept).

    Returns
    -------
    (..., 3) float
        The noisy normals; the angle to the input is ``|N(0, sigma)|`` per normal.
    """
    n = _check_normals(normals)
    sigma_deg = _real(sigma_deg, "sigma_deg", 0, 30)
    rng = _rng(rng)
    flat = n.reshape(-1, 3).copy()
    ok = np.isfinite(flat).all(axis=1)
    angles = np.radians(sigma_deg) * rng.normal(size=int(ok.sum()))
    flat[ok] = _rotate(flat[ok], angles, rng, keep_front)
    return flat.reshape(n.shape)


def add_smooth_noise(normals, sigma_deg: float, rng=None, *, length: float = 8.0,
                     keep_front: bool = True):
    """Rotate the normals by a smooth random field: correlated errors, as a normal estimator
    makes them (a network's low-frequency bias, a photometric stereo's wrong light), where
    :func:`add_angular_noise` draws every pixel's error alone.

    A field of rotation vectors in the image plane, white noise smoothed by a Gaussian of
    standard deviation `length` pixels, is projected on every normal's tangent plane (so that
    the normal turns by the vector's length) and scaled so that the root mean square of the
    rotation angle over the finite normals is `sigma_deg`.

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Unit normals (as in :func:`add_angular_noise`); NaN rows stay NaN.
    sigma_deg : float
        Root mean square rotation angle in degrees, at most 30 (single angles reach about
        three times the RMS).
    rng : numpy.random.Generator or seed
    length : float
        Standard deviation of the smoothing Gaussian in pixels (> 0); the field's correlation
        falls to 1/e at about twice that distance.
    keep_front : bool
        Where a rotation would turn a front-facing normal away from the viewer, rotate by the
        opposite angle instead (:func:`add_angular_noise`; the field is then not smooth there).

    Returns
    -------
    (H, W, 3) float
    """
    from scipy.ndimage import gaussian_filter

    n = _check_map(normals)
    sigma_deg = _real(sigma_deg, "sigma_deg", 0, 30)
    length = _real(length, "length", 0, open_low=True)
    rng = _rng(rng)
    field = np.zeros(n.shape)
    for i in range(2):
        field[..., i] = gaussian_filter(rng.normal(size=n.shape[:2]), length, mode="reflect")
    out = n.copy()
    ok = np.isfinite(n).all(axis=-1)
    v, r = n[ok], field[ok]
    r -= np.einsum("ij,ij->i", r, v)[:, None] * v  # (on the tangent plane: turns v by |r|)
    angle = np.linalg.norm(r, axis=1)
    rms = float(np.sqrt(np.mean(angle**2))) if angle.size else 0.0
    if rms == 0.0 or sigma_deg == 0:
        return out
    angle *= np.radians(sigma_deg) / rms
    moved = angle > 0
    v, r, angle = v[moved], r[moved], angle[moved]
    side = np.cross(r / np.linalg.norm(r, axis=1, keepdims=True), v)  # unit, tangent
    rot = _turn(v, side, angle, keep_front)
    idx = np.flatnonzero(ok.ravel())[moved]
    out.reshape(-1, 3)[idx] = rot
    return out


def blur_normals(normals, sigma: float, mask=None):
    """The normal map seen through a Gaussian blur of `sigma` pixels: soft occlusion
    boundaries, as a normal estimator's output (a network's, or photometric stereo at a
    coarser resolution) has them, where a rendered map changes from one surface to the other
    between two pixels.

    Every component is averaged over the mask only (a normalised convolution: pixels outside
    it give no weight), and the mean renormalised to unit length; a mean of length zero
    (opposite normals) keeps the pixel's own normal.

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Unit normals (others are scaled to unit length first; a zero-length one is a missing
        sample, as NaN; uint8 / uint16 codes are decoded as ``integrate`` decodes them); NaN
        rows stay NaN and give no weight.
    sigma : float
        Standard deviation of the Gaussian in pixels (>= 0; 0 returns a copy, scaled to unit
        length where the input was not).
    mask : (H, W) bool, optional
        The pixels that are blurred and give weight (default: the finite normals).

    Returns
    -------
    (H, W, 3) float
    """
    from scipy.ndimage import gaussian_filter

    n = _check_map(normals)
    try:
        good = bool(np.isfinite(float(sigma)) and float(sigma) >= 0)
    except (TypeError, ValueError):
        good = False
    if not good:
        raise ValueError(f"`sigma` must be a finite number of pixels >= 0; got {sigma!r}")
    sigma = float(sigma)
    ok = _filtered_pixels(n, mask)
    if sigma == 0:
        return n.copy()
    return _filtered_normals(n, ok, lambda a: gaussian_filter(a, sigma, mode="constant"))


def _filtered_pixels(n: np.ndarray, mask) -> np.ndarray:
    """The (H, W) pixels of the map `n` that a normalised filter averages and that give it
    weight: the finite normals, within `mask` where given (a ValueError naming `mask` where
    its shape is not the map's)."""
    ok = np.isfinite(n).all(axis=-1)
    if mask is not None:
        raw = np.asarray(mask)
        if raw.dtype != bool and not (raw.dtype.kind in "iuf" and np.isin(raw, (0, 1)).all()):
            # (0.5 everywhere was cast to all True without a word, an audit)
            raise ValueError(f"`mask` must be a bool (or 0 / 1) array; got {raw.dtype} values "
                             "other than 0 and 1")
        mask = raw.astype(bool)
        if mask.shape != n.shape[:2]:
            raise ValueError(f"`mask` must have shape {n.shape[:2]}; got {mask.shape}")
        ok &= mask
    return ok


def _filtered_normals(n: np.ndarray, ok: np.ndarray, linear) -> np.ndarray:
    """The map `n` with its pixels `ok` replaced by the normalised `linear` filter's mean of
    the normals at `ok` (each component filtered with weight 1 at `ok` and 0 elsewhere),
    renormalised to unit length; a pixel of weight 0 or a mean of length zero (opposite
    normals) keeps its own normal, the others stay as they are."""
    out = n.copy()
    if not ok.any():
        return out
    weight = linear(ok.astype(float))
    mean = np.stack([linear(np.where(ok, n[..., i], 0.0)) for i in range(3)], axis=-1)
    length = np.linalg.norm(mean, axis=-1)
    use = ok & (weight > 0) & (length > 1e-12 * np.maximum(weight, 1e-300))
    out[use] = mean[use] / length[use][:, None]
    return out


def resample_normals(normals, factor: int, mask=None):
    """The normal map estimated at `factor` times lower resolution and upsampled back: each
    `factor` x `factor` block's mean normal over the mask, interpolated bilinearly between the
    blocks' centres to every pixel (as a network run on a downsized image and resized to the
    input gives its normals), renormalised to unit length. Block means and interpolation are
    normalised by the mask (pixels outside it give no weight); a pixel whose interpolated
    mean has length zero keeps its own normal, NaN rows stay NaN.

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Unit normals (read as by :func:`blur_normals`).
    factor : int
        The resolution's reduction (>= 1; 1 returns a copy).
    mask : (H, W) bool, optional
        The pixels that are resampled and give weight (default: the finite normals).

    Returns
    -------
    (H, W, 3) float
    """
    from scipy.ndimage import map_coordinates

    n = _check_map(normals)
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise ValueError(f"`factor` must be an integer >= 1; got {factor!r}")
    f = int(factor)
    ok = _filtered_pixels(n, mask)
    if f == 1:
        return n.copy()
    H, W = ok.shape
    h, w = -(-H // f), -(-W // f)
    pad = ((0, h * f - H), (0, w * f - W))
    # (pixel centres: pixel r lies at block coordinate (r + 0.5) / f - 0.5)
    rr, cc = np.meshgrid((np.arange(H) + 0.5) / f - 0.5, (np.arange(W) + 0.5) / f - 0.5,
                         indexing="ij")
    at = np.array([rr.ravel(), cc.ravel()])

    def linear(a):
        """Block sums of `a`, interpolated bilinearly back to every pixel."""
        blocks = np.pad(a, pad).reshape(h, f, w, f).sum(axis=(1, 3))
        return map_coordinates(blocks, at, order=1, mode="nearest").reshape(H, W)

    return _filtered_normals(n, ok, linear)


def _turn(v, side, angle, keep_front):
    """Unit vectors `v` turned by `angle` (rad) toward the unit tangents `side`."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    out = v * c + side * s
    if keep_front:
        flip = (out[:, 2] <= 0) & (v[:, 2] > 0)
        out[flip] = v[flip] * c[flip] - side[flip] * s[flip]
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _pick(ok: np.ndarray, fraction: float, rng) -> np.ndarray:
    fraction = _real(fraction, "fraction", 0, 1)
    idx = np.nonzero(ok)[0]
    k = int(round(fraction * idx.size))
    chosen = np.zeros(ok.size, bool)
    chosen[rng.choice(idx, size=k, replace=False)] = True
    return chosen


def perturb_fraction(
    normals, fraction: float, *, max_deg: float = 20.0, rng=None, keep_front: bool = True
):
    """Rotate a random `fraction` of the samples by angles uniform in [0, `max_deg`] (Fig. 5a).

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Unit normals (as in :func:`add_angular_noise`); NaN samples are never chosen.
    fraction : float
        In [0, 1]; ``round(fraction * number of finite samples)`` are perturbed.
    max_deg : float
        Largest rotation angle in degrees.
    rng : numpy.random.Generator or seed
    keep_front : bool
        See :func:`add_angular_noise`.

    Returns
    -------
    perturbed : (H, W, 3) float
    chosen : (H, W) bool
        The perturbed samples (use them as inliers, or drop them with ``perturbed[chosen] =
        nan`` to make them missing samples, Fig. 5b/c).
    angles : (H, W) float
        The rotation angle in degrees (0 where not perturbed, NaN where the input is NaN).
    """
    n = _check_normals(normals)
    max_deg = _real(max_deg, "max_deg", 0, 90)
    rng = _rng(rng)
    flat = n.reshape(-1, 3).copy()
    ok = np.isfinite(flat).all(axis=1)
    chosen = _pick(ok, fraction, rng)
    ang = rng.uniform(0.0, max_deg, size=int(chosen.sum()))
    flat[chosen] = _rotate(flat[chosen], np.radians(ang), rng, keep_front)
    angles = np.where(ok, 0.0, np.nan)
    angles[chosen] = ang
    shape = n.shape[:-1]
    return flat.reshape(n.shape), chosen.reshape(shape), angles.reshape(shape)


def remove_samples(normals, fraction: float, rng=None):
    """Set a random `fraction` of the finite normals to NaN (missing samples).

    Returns
    -------
    normals : (..., 3) float
        A copy with NaN rows at the removed samples.
    removed : (...) bool
    """
    n = _check_normals(normals, unit=False)
    rng = _rng(rng)
    flat = n.reshape(-1, 3).copy()
    ok = np.isfinite(flat).all(axis=1)
    chosen = _pick(ok, fraction, rng)
    flat[chosen] = np.nan
    return flat.reshape(n.shape), chosen.reshape(n.shape[:-1])
