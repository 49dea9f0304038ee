"""The discontinuity development benchmark (``facetlift bench --experiments discontinuities``).

Built so that no single object can steer it: every mesh of the data folder rendered with a
DiLiGenT-like pinhole camera (512 x 612, f = 3,700 px, about 1.5 m away) from several views and
with a wide-angle camera (f = 600 px), rendered orthographically, plus the analytic surfaces
with jumps (:data:`facetlift.synthetic.WITH_JUMPS`) and scenes of two or three meshes on a
table (:func:`facetlift.synthetic.tabletop`: jumps between separate objects) and open vessels
seen from above the rim (:func:`facetlift.synthetic.vessel`: the inside joined to the outside
only across a rim a few pixels wide), each as exact,
16-bit and 8-bit quantised normals and with angular noise; and the real normal maps of the
data folder with the defaults.

Every scene is integrated by the smooth DGP, the discontinuity-preserving DGP (defaults and a
sweep of ``discontinuity_k``), BiNI, and the **oracle**: the same facet integration with the
true jump edges cut (:func:`facetlift.synthetic.jump_edges` of the ground truth) and the
route's rule for the separated pieces' offsets
(:func:`facetlift.methods.dgp.split.occlusion_offsets`) with every pair closed (no
``TOUCH``: started from the true places, it would leave far pairs at their truth) and each
pair's occluding side taken from the ground truth too (:func:`oracle`), and
**oracle-placed**, the oracle's cuts with every piece moved to its
true place (what the occlusion rule's guesses cost). Reported per run: MADE (median scale, as
BiNI evaluates, for pinhole scenes) or the paper's normalised error in % (orthographic
scenes), the mean angle between the result and its input normals, the time, the reweightings
and whether they converged.

Meshes made of flat CAD patches (most adjacent faces coplanar) are rendered as they are; the
others are loop-subdivided to at least 100k faces first, and the normals are averaged over
``disc_samples`` x ``disc_samples`` rays per pixel, so that they resemble real photometric
stereo normals rather than a faceted low-poly model. Rendered scenes are cached as ``.npz``
in ``<out>/cache`` (or ``$FACETLIFT_BENCH_CACHE``).

The spiral ramp (``helix``) is left out: its cliff can run along any radius, all equally
consistent with the normals, so its error measures where a method happens to put the cut.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import math
import os
import secrets
import time
import warnings
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import metrics, synthetic
from .core import SEED, Context, Spec, bar, method_status, run_method
from .tables import md_table, write_csv, write_text

log = logging.getLogger(__name__)

#: Condition name -> ("quantize", bits), ("noise", degrees), ("smooth", RMS degrees,
#: smoothing sigma px: :func:`facetlift.synthetic.add_smooth_noise`), ("ps", lights, their
#: spread in degrees, specular strength, shininess), ("outliers", fraction,
#: largest degrees: :func:`facetlift.synthetic.perturb_fraction`), ("blur", sigma px: soft
#: occlusion boundaries, :func:`facetlift.synthetic.blur_normals`) or None. The last three are
#: not in the default run (``Settings.disc_conditions``), nor is ``noise6`` (6 degrees of
#: angular noise, where BiNI draws level: docs/results.md, "Six degrees of noise") or
#: ``blur3`` (a 3 px blur, as a normal estimator smooths an occlusion boundary; docs/results.md,
#: "Stronger blur, smooth errors and a fresh held-out set"):
#: ``facetlift bench --experiments discontinuities --conditions smooth3,outliers,blur1.5`` runs
#: them (``benchmarks/bench_jump_free.py --conditions`` too). ``ps`` (not in the default run
#: either): normals as a photometric stereo gives them, :func:`facetlift.photometric.fit` of
#: :func:`facetlift.photometric.simulate`'s images under 20 lights within 40 degrees of the
#: axis (shadows cast and attached, highlights, image noise, 16 bits), NaN where fewer than
#: three lights are usable; ``ps_shiny`` the same with broader and brighter highlights (the
#: fit's mean angle to the true normals about 4 degrees on the perspective scenes against 1,
#: nearer a least-squares photometric stereo on shiny real objects). Their parameters were set
#: by the fit's angular error, not by the integrators' results; nothing in the methods was
#: changed for them (docs/results.md, "Photometric-stereo normals").
CONDITIONS = {"exact": None, "16bit": ("quantize", 16), "8bit": ("quantize", 8),
              "noise3": ("noise", 3.0), "noise6": ("noise", 6.0), "smooth3": ("smooth", 3.0, 8.0),
              "outliers": ("outliers", 0.02, 45.0), "blur1.5": ("blur", 1.5),
              "blur3": ("blur", 3.0), "blur0.7": ("blur", 0.7),
              "resample2": ("resample", 2), "resample4": ("resample", 4),
              "ps": ("ps", 20, 40.0, 0.2, 100.0),
              "ps_shiny": ("ps", 20, 40.0, 0.6, 20.0)}
#: Analytic jump scenes of the benchmark (see the module docstring for ``helix``).
ANALYTIC = tuple(n for n in synthetic.WITH_JUMPS if n != "helix")
#: Focal length (px) of the wide-angle camera and its distance to the object.
WIDE_F, WIDE_DISTANCE = 600.0, 300.0
#: Fewest faces of an organic mesh after loop subdivision.
MIN_FACES = 100_000
#: A mesh whose adjacent faces are coplanar (< 1 degree) at least this often is a CAD model.
CAD_FLAT = 0.4


def specs(ctx: Context) -> list[Spec]:
    """Columns: smooth DGP, discontinuity DGP (defaults, then the k sweep), BiNI."""
    out = [Spec("dgp", "dgp"), Spec("dgp-disc", "dgp", (("discontinuities", True),))]
    out += [Spec(f"dgp-disc k={k:g}", "dgp", (("discontinuities", True),
                                               ("discontinuity_k", float(k))))
            for k in ctx.settings.disc_k_sweep]
    if not method_status(["bini"]).get("bini", "missing"):
        out.append(Spec("bini", "bini"))
    return out


# ----------------------------------------------------------------------------------------------
# scenes


def load_mesh(path: Path):
    """The mesh at `path`, loop-subdivided to >= :data:`MIN_FACES` unless it is a CAD model."""
    from ..synthetic import _trimesh

    m = _trimesh("render_perspective").load(path, force="mesh")
    flat = float(np.mean(m.face_adjacency_angles < np.radians(1.0))) if len(m.faces) > 1 else 1
    if flat < CAD_FLAT and len(m.faces) < MIN_FACES:
        m = m.subdivide_loop(iterations=math.ceil(math.log(MIN_FACES / len(m.faces), 4)))
    return m


def _cache_dir(ctx: Context) -> Path:
    d = Path(os.environ.get("FACETLIFT_BENCH_CACHE") or ctx.out / "cache")
    d.mkdir(parents=True, exist_ok=True)
    return d


@functools.lru_cache(maxsize=None)
def _file_digest(path: str, size: int, mtime_ns: int) -> str:
    """SHA-1 of a file's bytes (cached per path, size and modification time)."""
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


def _sources_digest(sources) -> str:
    """One digest of the files a scene is rendered from (its meshes): a render cached under
    a key of their stems alone came back for another mesh of the same name, an edited one or
    another data folder's (an audit)."""
    parts = []
    for p in sources:
        st = os.stat(p)
        parts.append(_file_digest(str(Path(p).resolve()), st.st_size, st.st_mtime_ns))
    return hashlib.sha1(("|".join(parts) + f"|{CACHE_VERSION}").encode()).hexdigest()


#: Part of every cached render's digest: raise it when the renderer changes what it returns
#: (2: the renders carry their depth jumps from the geometry, ``GroundTruth.jump_sizes``).
CACHE_VERSION = 2


def _cached(ctx: Context, key: str, make, sources=()) -> synthetic.GroundTruth:
    """The scene `key` from the render cache, or made (`make`) and stored there. With
    `sources` (the mesh files it is rendered from) a cached file is used only where it
    holds the same digest of them (:func:`_sources_digest`); a file that cannot be read is
    rendered anew (it was dropped from every later run, an audit)."""
    path = _cache_dir(ctx) / f"{key}.npz"
    digest = _sources_digest(sources)  # (CACHE_VERSION alone where there is no file)
    if path.is_file():
        try:
            with np.load(path) as z:
                stored = str(z["sources"]) if "sources" in z.files else ""
                if stored == digest:
                    K = z["K"] if z["K"].size else None
                    jumps = ((z["jump_right"], z["jump_down"]) if "jump_right" in z.files
                             else None)
                    return synthetic.GroundTruth(z["depth"], z["normals"], z["mask"],
                                                 float(z["pixel_size"]), str(z["name"]), K,
                                                 jumps)
            log.info("cached scene %s was rendered from other files: rendered anew", path)
        except Exception as e:  # (a truncated or foreign file: rendered anew)
            log.warning("cached scene %s cannot be read (%s): rendered anew", path, e)
    gt = make()
    tmp = path.with_name(f"{key}.{os.getpid()}.{secrets.token_hex(4)}.tmp.npz")
    try:  # (a name of its own: two runs sharing the cache moved each other's away, an audit)
        jumps = {} if gt.jump_sizes is None else {"jump_right": gt.jump_sizes[0],
                                                   "jump_down": gt.jump_sizes[1]}
        np.savez_compressed(tmp, depth=gt.depth, normals=gt.normals, mask=gt.mask,
                            pixel_size=gt.pixel_size, name=gt.name,
                            K=np.zeros(0) if gt.K is None else gt.K, sources=digest, **jumps)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()
    return gt


def _pinhole(resolution, f=None):
    H, W = resolution
    if f is None:  # DiLiGenT's intrinsics, scaled to the resolution
        K = np.array(synthetic.DILIGENT_K, float)
        s = W / 612.0
        K[:2] *= s
        return K
    return np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])


#: How much of the image's shorter side a :func:`facetlift.synthetic.tabletop` scene spans.
TABLE_FILL = 0.9

#: Version of the tabletop scenes in the render cache's keys (2: objects never meet).
TABLE_VERSION = 2


#: Version of the vessel scenes (:func:`facetlift.synthetic.vessel`) in the render cache's keys (3:
#: rounded rims; 2: flat rims; 1 had a cone from the rim to the floor's centre).
VESSEL_VERSION = 3


#: How much of the image's shorter side a :func:`facetlift.synthetic.room` scene's bounding
#: sphere would span: above 1, the camera sees a part of the room from inside it.
ROOM_FILL = 1.8

#: Version of the room scenes in the render cache's keys (2: three camera elevations).
ROOM_VERSION = 2


def room_meshes(meshes: list, i: int) -> list:
    """The meshes of the `i`-th room scene: the next two (even `i`) or three of `meshes` in
    turn (every mesh once before any comes again; never more than there are)."""
    size = [min(2 + j % 2, len(meshes)) for j in range(i + 1)]
    start = sum(size[:-1])
    return [meshes[(start + j) % len(meshes)] for j in range(size[-1])]


def tabletop_meshes(meshes: list, i: int) -> list:
    """The meshes of the `i`-th tabletop scene: the next two of `meshes` in turn, every third
    scene three (every mesh once before any comes again; never more than there are)."""
    size = [min(3 if j % 3 == 2 else 2, len(meshes)) for j in range(i + 1)]
    start = sum(size[:-1])
    return [meshes[(start + j) % len(meshes)] for j in range(size[-1])]


def scenes(ctx: Context) -> list[tuple[str, str, object]]:
    """(group, name, loader) of every synthetic scene; groups ``perspective``, ``wide``,
    ``tabletop`` (several meshes on a table, DiLiGenT's camera), ``room`` (the corner of a room
    with objects on its floor, seen from inside with a 54-degree camera,
    :func:`facetlift.synthetic.room`), ``vessel`` (open vessels seen from above the rim,
    :func:`facetlift.synthetic.vessel`) and ``ortho``."""
    s = ctx.settings
    meshes = ctx.meshes(s.disc_meshes)
    res = tuple(s.disc_resolution)
    f_wide = WIDE_F * res[1] / 612.0
    out = []

    def add(group, name, key, make, sources):
        out.append((group, name, lambda: _cached(ctx, key, make, sources)))

    tag = f"{res[0]}x{res[1]}_s{s.disc_samples}"
    for path in meshes:
        for view in s.disc_views:
            add("perspective", f"{path.stem}@{view}", f"pin_{path.stem}_{view}_{tag}",
                lambda p=path, v=view: synthetic.render_perspective(
                    load_mesh(p), _pinhole(res), res, view=v, samples=s.disc_samples,
                    jumps=True, name=f"{p.stem}@{v}"), (path,))
        for view in s.disc_wide_views:
            add("wide", f"{path.stem}@{view}", f"wide_{path.stem}_{view}_{tag}",
                lambda p=path, v=view: synthetic.render_perspective(
                    load_mesh(p), _pinhole(res, f_wide), res, view=v, distance=WIDE_DISTANCE,
                    samples=s.disc_samples, jumps=True, name=f"{p.stem}@{v}"), (path,))
        for view in s.disc_ortho_views:
            n = s.disc_ortho_size
            add("ortho", f"{path.stem}@{view}", f"ortho_{path.stem}_{view}_{n}",
                lambda p=path, v=view, n=n: synthetic.render_mesh(load_mesh(p), n, view=v,
                                                                   name=f"{p.stem}@{v}",
                                                                   jumps=True),
                (path,))
    for i in range(s.disc_tabletop if len(meshes) >= 2 else 0):
        pick = tabletop_meshes(meshes, i)
        name = "+".join(p.stem for p in pick) + f"@table{i}"
        # (the version and the framing in the cache key: a changed composer renders anew)
        add("tabletop", name, f"table{TABLE_VERSION}_{i}_{name}_f{TABLE_FILL:g}_{tag}",
            lambda pick=pick, i=i, name=name: synthetic.render_perspective(
                synthetic.tabletop([load_mesh(p) for p in pick], seed=i), _pinhole(res), res,
                view=synthetic.TABLE_VIEW, fill=TABLE_FILL, samples=s.disc_samples,
                jumps=True, name=name),
            tuple(pick))
    rres = tuple(s.disc_room_resolution)
    rtag = f"{rres[0]}x{rres[1]}_s{s.disc_samples}"
    for i in range(s.disc_rooms if meshes else 0):
        pick = room_meshes(meshes, i)
        name = "+".join(p.stem for p in pick) + f"@room{i}"
        add("room", name, f"room{ROOM_VERSION}_{i}_{name}_f{ROOM_FILL:g}_{rtag}",
            lambda pick=pick, i=i, name=name: synthetic.render_perspective(
                synthetic.room([load_mesh(p) for p in pick], seed=i),
                _pinhole(rres, WIDE_F * rres[1] / 612.0), rres, view=synthetic.room_view(i),
                fill=ROOM_FILL, distance=WIDE_DISTANCE, samples=s.disc_samples, jumps=True,
                name=name),
            tuple(pick))
    for kind in s.disc_vessels:
        for elev in s.disc_vessel_elevations:
            name = f"{kind}@e{elev:g}"
            add("vessel", name, f"vessel{VESSEL_VERSION}_{kind}_e{elev:g}_{tag}",
                lambda kind=kind, elev=elev, name=name: synthetic.render_perspective(
                    synthetic.vessel(kind), _pinhole(res), res,
                    view=synthetic.vessel_view(elev), samples=s.disc_samples, jumps=True,
                    name=name), ())
    for name in s.disc_analytic:
        n = s.disc_ortho_size
        out.append(("ortho", name, lambda name=name, n=n: synthetic.analytic(name, n)))
    if ctx.models:
        out = [t for t in out if t[1] in ctx.models or t[1].split("@")[0] in ctx.models]
    return out


#: Camera elevations (degrees above the mesh's horizontal plane) and framings (``fill``) the
#: held-out views are drawn from (:func:`heldout_views`).
HELDOUT_ELEVATION = (-15.0, 45.0)
HELDOUT_FILL = (0.45, 0.75)


def heldout_views(name: str, n: int, seed: int) -> list[tuple[tuple, float]]:
    """`n` (view direction, fill) pairs for the mesh `name`, drawn from `seed`: azimuth
    uniform around the vertical (the mesh's y axis), elevation uniform in
    :data:`HELDOUT_ELEVATION`, fill uniform in :data:`HELDOUT_FILL`. The same `name`, `n`
    and `seed` give the same views (the first ``n - 1`` of them are those of ``n - 1``)."""
    rng = np.random.default_rng([int(seed), zlib.crc32(name.encode())])
    out = []
    for _ in range(int(n)):
        az = rng.uniform(0.0, 2.0 * math.pi)
        el = math.radians(rng.uniform(*HELDOUT_ELEVATION))
        fill = float(rng.uniform(*HELDOUT_FILL))
        # (the direction the rays travel: from a camera at azimuth az, elevation el)
        view = (-math.cos(el) * math.sin(az), -math.sin(el), -math.cos(el) * math.cos(az))
        out.append((tuple(round(v, 12) for v in view), round(fill, 6)))
    return out


def heldout_scenes(ctx: Context) -> list[tuple[str, str, object]]:
    """(group ``heldout``, name, loader) of the held-out scenes: every mesh of the data folder
    from ``Settings.heldout_views`` random views (:func:`heldout_views`, seeded by
    ``Settings.heldout_seed``) with DiLiGenT's camera, rendered as the ``perspective``
    group is. No default was chosen on these scenes: they are the test set beside the
    development benchmark (docs/results.md); a new seed draws a fresh one."""
    s = ctx.settings
    res = tuple(s.disc_resolution)
    tag = f"{res[0]}x{res[1]}_s{s.disc_samples}"
    out = []
    for path in ctx.meshes(s.disc_meshes):
        for i, (view, fill) in enumerate(heldout_views(path.stem, s.heldout_views,
                                                       s.heldout_seed)):
            name = f"{path.stem}@h{i}"
            key = f"held_{path.stem}_{s.heldout_seed}_{i}_{tag}"
            out.append(("heldout", name, lambda p=path, v=view, f=fill, name=name, key=key: _cached(
                ctx, key, lambda: synthetic.render_perspective(
                    load_mesh(p), _pinhole(res), res, view=v, fill=f, samples=s.disc_samples,
                    jumps=True, name=name), (p,))))
    if ctx.models:
        out = [t for t in out if t[1] in ctx.models or t[1].split("@")[0] in ctx.models]
    return out


def _flat(gt) -> float:
    """Depth range below which a scene is a flat view (its normalised error is undefined)."""
    if gt.K is None:
        return 2.0 * gt.pixel_size
    return 2.0 * float(np.nanmedian(gt.depth)) / gt.K[0, 0]


def condition(gt, cond: str, name: str):
    """The normals of `gt` under condition `cond` (seeded by the scene `name`)."""
    how = CONDITIONS[cond]
    if how is None:
        return gt.normals
    if how[0] == "quantize":
        return synthetic.quantize(gt.normals, how[1])
    if how[0] == "blur":
        return synthetic.blur_normals(gt.normals, how[1], mask=gt.mask)
    if how[0] == "resample":
        return synthetic.resample_normals(gt.normals, how[1], mask=gt.mask)
    rng = np.random.default_rng([SEED, zlib.crc32(name.encode())])
    if how[0] == "smooth":
        return synthetic.add_smooth_noise(gt.normals, how[1], rng, length=how[2])
    if how[0] == "outliers":
        return synthetic.perturb_fraction(gt.normals, how[1], max_deg=how[2], rng=rng)[0]
    if how[0] == "ps":
        from .. import photometric

        lights = photometric.lights_on_cap(how[1], how[2], rng)
        images = photometric.simulate(gt, lights, rng, specular=how[3], shininess=how[4])
        return photometric.fit(images, lights, gt.mask)[0]
    return synthetic.add_angular_noise(gt.normals, how[1], rng)


# ----------------------------------------------------------------------------------------------
# runs


def error_of(gt, depth) -> float:
    """MADE for a pinhole scene, the paper's normalised error in % for an orthographic one."""
    if gt.K is not None:
        return metrics.made(depth, gt.depth, gt.mask)[0]
    return 100.0 * metrics.normalized_error(depth, gt.depth, gt.mask)[0]


def oracle(gt, normals, geometric: bool = False, *, cuts=None,
           sides=None) -> tuple[float, float, float, float]:
    """(error, deviation, seconds, placed error) of the facet integration with the true jumps
    cut: the pieces they separate placed by the occlusion rule, and (the last) each piece moved
    to its true place, the median difference to the ground truth in the camera's unknown (an
    offset, or a scale for a pinhole camera): about what knowing every piece's place would
    give (the metric's own alignment follows, so it is not a strict bound), which normals
    alone cannot reach where a piece touches nothing. NaN where that step fails.

    The occlusion rule starts from the true placement, so each pair of pieces takes its
    occluding side (the sign of its jumps) from the ground truth, as the jumps' edges are:
    started from the split solve's arbitrary constant per piece, as until the twenty-seventh
    session, the side was a coin flip on the pairs of large pieces (53 % right on the
    development renders; `dgp-disc`, whose own soft solve decides it, 100 %), so the oracle
    was no floor (docs/results.md, "The oracle's occluding sides").

    `geometric`: cut the jumps of the render's geometry (``synthetic.jump_edges(gt,
    geometric=True)``, a render made with ``jumps=True``) instead of the pixel-centre test's
    (benchmarks/bench_oracle_cuts.py compares the two).

    `cuts`: other edges to cut, ``(right, down)`` as :attr:`facetlift.Surface.cuts` (a route's
    own, or a mix of its and the truth's: benchmarks/bench_cut_errors.py); `sides`: a depth map
    (H, W) whose per-piece placement starts the occlusion rule instead of the truth's, so that
    it decides the occluding sides (a route's result). The placed error still moves each piece
    to the truth."""
    from scipy import ndimage

    from .. import methods
    from ..api import make_surface
    from ..methods import MethodResult
    from ..methods.dgp import SMALL_PIECE, targets
    from ..methods.dgp.split import occlusion_offsets, solve_pieces, split
    from ..problem import prepare  # (the renders' normals need no input checks)

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the input rules of the discontinuity route (methods.REGISTRY["dgp"]: jump_grazing,
        # jump_isolated)
        route = methods.get("dgp")
        problem = prepare(normals, gt.mask, pixel_size=gt.pixel_size, K=gt.K,
                          outlier_eps=route.jump_grazing, isolated=route.jump_isolated,
                          grazing_share=route.jump_grazing_share)
        bx, by, target = targets(problem)
        right, down = synthetic.jump_edges(gt, geometric=geometric) if cuts is None else cuts
        mesh = split(problem.domain, right, down)
        z, _ = solve_pieces(mesh, bx, by, target)  # (an arbitrary constant per piece)
        k = mesh.n_pieces
        cam, (r, c) = problem.camera, problem.domain.pixels

        def surface_of(v):
            return make_surface(problem, MethodResult(values=v[mesh.corners].mean(axis=1),
                                                      extras={"corner_values": v[mesh.corners]}))

        with np.errstate(invalid="ignore", divide="ignore"):
            mine = cam.from_depth(surface_of(z).depth[r, c])

        def moves(depth):  # each piece's median difference to `depth` over the pixels where
            # both are finite (the surface's depth, as returned: not at facets without a
            # normal; a piece without one stays put: scipy's median of an empty label is not
            # NaN)
            with np.errstate(invalid="ignore", divide="ignore"):
                ref = cam.from_depth(depth[r, c])
            ok = np.isfinite(ref) & np.isfinite(mine)
            out = np.atleast_1d(ndimage.median(np.where(ok, ref - mine, 0.0),
                                               np.where(ok, mesh.facet_piece + 1, 0),
                                               np.arange(1, k + 1)))
            return np.where(np.bincount(mesh.facet_piece[ok], minlength=k) > 0, out, 0.0)

        try:
            move = moves(gt.depth)
        except Exception as e:  # (the rule then decides the sides from the arbitrary start)
            log.info("true placement failed on %s: %s", gt.name, e)
            move = None
        if sides is not None:
            sides = np.asarray(sides, float)
            if sides.shape != gt.mask.shape:
                raise ValueError(f"oracle: `sides` must be a depth map of the scene's shape "
                                 f"{gt.mask.shape}; got {sides.shape}")
            if not np.isfinite(sides[gt.mask]).any():
                raise ValueError("oracle: `sides` has no finite depth inside the mask")
        first = move if sides is None else moves(sides)
        start = z if first is None else z + first[mesh.piece]
        # (the route's rule, line pieces included: SMALL_PIECE; every pair closed, as with a
        # prior: split.TOUCH would keep far pairs at their true places)
        offsets = occlusion_offsets(mesh, start, bx, by, target,
                                    scale=problem.camera.footprint(), small=SMALL_PIECE)
        placed_z = start + offsets[mesh.piece]

        surface = surface_of(placed_z)
    dev = metrics.input_deviation(problem, surface)
    seconds = time.perf_counter() - t0
    placed_error = float("nan")
    if move is not None:  # (each pixel's own value moved: a facet's depth as the surface
        try:  # returns it, not its corners' again)
            placed = np.full(gt.depth.shape, np.nan)
            placed[r, c] = cam.to_depth(mine + move[mesh.facet_piece])
            placed_error = error_of(gt, placed)
        except Exception as e:  # (the oracle's own figures stand)
            log.info("placed oracle failed on %s: %s", gt.name, e)
    return error_of(gt, surface.depth), dev, seconds, placed_error


def run_scene(ctx: Context, group: str, name: str, gt, cols) -> list[dict]:
    """Every column and the oracle on one scene under every condition: table rows."""
    right, down = synthetic.jump_edges(gt)
    jumps = int(right.sum() + down.sum())
    rows = []
    status = method_status({c.method for c in cols})
    for cond in ctx.settings.disc_conditions:
        n = condition(gt, cond, f"{group}:{name}")
        base = {"group": group, "scene": name, "condition": cond, "pixels": int(gt.mask.sum()),
                "jump_edges": jumps}
        for spec in cols:
            sweep = spec.label.startswith("dgp-disc k=")
            if sweep and cond not in ctx.settings.disc_sweep_conditions:
                continue
            r = run_method(spec, n, gt.mask, pixel_size=gt.pixel_size, K=gt.K, status=status)
            err = error_of(gt, r.surface.depth) if r.status == "ok" else None
            info = r.surface.info if r.surface is not None else {}
            rows.append({**base, "method": spec.label, "status": r.status, "error": err,
                         "deviation": info.get("mean_deviation"), "seconds": r.seconds,
                         "iterations": info.get("iterations"), "grown": info.get("grown"),
                         "converged": info.get("converged"), "message": r.message})
        try:
            err, dev, sec, placed = oracle(gt, n)
            rows.append({**base, "method": "oracle", "status": "ok", "error": err,
                         "deviation": dev, "seconds": sec})
            rows.append({**base, "method": "oracle-placed",
                         "status": "ok" if np.isfinite(placed) else "failed",
                         "error": placed if np.isfinite(placed) else None})
        except Exception as e:  # recorded, the run goes on
            log.info("oracle failed on %s: %s", name, e)
            for label in ("oracle", "oracle-placed"):
                rows.append({**base, "method": label, "status": "failed",
                             "message": f"{type(e).__name__}: {e}"[:300]})
    return rows


def real_maps(ctx: Context, cols) -> list[dict]:
    """The columns on every real normal map of the data folder, read and run as a user would
    (``facetlift.io.read_dataset``, defaults): deviation from the input, time, MADE where the
    folder has ground-truth depth."""
    from ..api import integrate
    from ..camera import Pinhole
    from ..io import read_dataset

    if ctx.data is None or not (ctx.data / "normal_maps").is_dir():
        return []
    rows = []
    folders = sorted(p for p in (ctx.data / "normal_maps").iterdir() if p.is_dir())
    folders += [Path(p) for p in ctx.extra_normal_maps]
    for folder in folders:
        ds = read_dataset(folder)
        n, mask, K = ds["normals"], ds["mask"], ds["K"]
        truth = None
        if (folder / "depth_gt.npz").is_file():
            with np.load(folder / "depth_gt.npz") as z:
                truth = np.asarray(z["depth_gt"], float)
        st = int(ctx.settings.disc_real_stride)
        if st > 1:
            n, mask = n[::st, ::st], None if mask is None else mask[::st, ::st]
            truth = None if truth is None else truth[::st, ::st]
            K = None if K is None else Pinhole(K).subsampled(st).K
        for spec in cols:
            t0 = time.perf_counter()
            row = {"data": folder.name, "size": f"{n.shape[0]}x{n.shape[1]}",
                   "method": spec.label}
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    s = integrate(n, mask, K=K, method=spec.method, **dict(spec.options))
            except Exception as e:
                rows.append({**row, "status": "failed", "message": f"{type(e).__name__}: {e}"})
                continue
            made = None
            if truth is not None:
                m = s.mask & np.isfinite(truth)
                made = metrics.made(s.depth, truth, m)[0]
            rows.append({**row, "status": "ok", "pixels": int(s.mask.sum()),
                         "missing": s.info.get("missing"),
                         "deviation": s.info.get("mean_deviation"), "made_mm": made,
                         "seconds": time.perf_counter() - t0,
                         "iterations": s.info.get("iterations"),
                         "grown": s.info.get("grown"),
                         "converged": s.info.get("converged")})
    return rows


# ----------------------------------------------------------------------------------------------
# summary


def summary(rows: list[dict], labels: list[str]) -> list[dict]:
    """Per group and condition: mean and median error of every method, its ratio to the
    oracle's mean, wins and losses against BiNI (1 % margin), converged fraction, time."""
    out = []
    keys = dict.fromkeys((r["group"], r["condition"]) for r in rows)
    for group, cond in keys:
        sub = [r for r in rows if r["group"] == group and r["condition"] == cond]
        by = {}
        for r in sub:
            if r["status"] == "ok" and r.get("error") is not None:
                by.setdefault(r["method"], {})[r["scene"]] = r
        ora = by.get("oracle", {})
        bini = by.get("bini", {})
        for label in labels + ["oracle", "oracle-placed"]:
            runs = by.get(label, {})
            common = [sc for sc in runs if sc in ora]
            if not common:
                continue
            e = np.array([runs[sc]["error"] for sc in common])
            o = np.array([ora[sc]["error"] for sc in common])
            row = {"group": group, "condition": cond, "method": label, "scenes": len(common),
                   "mean_error": float(e.mean()), "median_error": float(np.median(e)),
                   "vs_oracle": float(e.mean() / o.mean()) if o.mean() > 0 else float("nan"),
                   "mean_deviation": _mean_of(runs, common, "deviation"),
                   "seconds": _mean_of(runs, common, "seconds")}
            both = [sc for sc in common if sc in bini]
            if label != "bini" and both:
                a = np.array([runs[sc]["error"] for sc in both])
                b = np.array([bini[sc]["error"] for sc in both])
                row["wins_vs_bini"] = int((a < 0.99 * b).sum())
                row["losses_vs_bini"] = int((a > 1.01 * b).sum())
            conv = [runs[sc].get("converged") for sc in common]
            conv = [c for c in conv if c is not None]
            if conv:
                row["converged"] = float(np.mean(conv))
            out.append(row)
    return out


def _mean_of(runs: dict, scenes: list, key: str) -> float:
    """Mean of `key` over the runs of `scenes` that have it (NaN if none: the placed oracle
    has no deviation or time of its own)."""
    v = [runs[sc][key] for sc in scenes if runs[sc].get(key) is not None]
    v = [x for x in v if np.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def jump_free(rows: list[dict], label: str = "dgp-disc") -> list[dict]:
    """Scenes without a ground-truth jump: the discontinuity DGP's error over the smooth one."""
    out = []
    smooth = {(r["group"], r["scene"], r["condition"]): r for r in rows
              if r["method"] == "dgp" and r["status"] == "ok" and r["jump_edges"] == 0}
    for r in rows:
        key = (r["group"], r["scene"], r["condition"])
        if r["method"] == label and r["status"] == "ok" and key in smooth:
            e0 = smooth[key]["error"]
            out.append({"group": key[0], "scene": key[1], "condition": key[2],
                        "smooth_error": e0, "disc_error": r["error"],
                        "ratio": r["error"] / e0 if e0 > 0 else 1.0 + r["error"]})
    return out


def usable(ctx: Context, data, label: str):
    """(group, name, ground truth) of the scenes of `data` (:func:`scenes`) that load and are
    neither too small nor flat, with a progress bar called `label`; the others are logged."""
    for group, name, load in bar(data, ctx.progress, label):
        try:
            gt = load()
        except Exception as e:
            log.warning("scene %s unavailable: %s", name, e)
            # (listed in the report, an audit; by group too: one name in two groups)
            ctx.unavailable[f"{name} ({group})"] = str(e)
            continue
        if gt.mask.sum() < ctx.settings.disc_min_pixels or gt.depth_range < _flat(gt):
            log.info("scene %s skipped: %d pixels, depth range %g", name, gt.mask.sum(),
                     gt.depth_range)
            continue
        yield group, name, replace(gt, name=name)


def discontinuities(ctx: Context) -> None:
    """Run the benchmark; writes ``discontinuities_runs.csv``, ``discontinuities.csv`` (the
    summary), ``discontinuities_real.csv`` and ``discontinuities.md``."""
    _benchmark(ctx, scenes(ctx), "discontinuities", "Discontinuities: development benchmark",
               real=True)


def heldout(ctx: Context) -> None:
    """The same runs on the held-out scenes (:func:`heldout_scenes`); writes
    ``heldout_runs.csv``, ``heldout.csv`` (the summary) and ``heldout.md``."""
    _benchmark(ctx, heldout_scenes(ctx), "heldout",
               f"Discontinuities: held-out views (seed {ctx.settings.heldout_seed})",
               real=False)


def _benchmark(ctx: Context, data, stem: str, title: str, real: bool) -> None:
    cols = specs(ctx)
    rows = []
    for group, name, gt in usable(ctx, data, stem):
        rows += run_scene(ctx, group, name, gt, cols)
        write_csv(ctx.out / f"{stem}_runs.csv", rows)  # partial results survive
    labels = [c.label for c in cols]
    table = summary(rows, labels)
    free = jump_free(rows)
    real = real_maps(ctx, [c for c in cols if c.label in ("dgp", "dgp-disc", "bini")]
                     ) if real else []
    write_csv(ctx.out / f"{stem}_runs.csv", rows)
    write_csv(ctx.out / f"{stem}.csv", table)
    if real:
        write_csv(ctx.out / f"{stem}_real.csv", real)
    n_scenes = len({(r["group"], r["scene"]) for r in rows})
    text = [f"{n_scenes} synthetic scenes x {len(ctx.settings.disc_conditions)} conditions; "
            "error = MADE for the pinhole groups (perspective, wide, tabletop, room, vessel, "
            "heldout), the paper's normalised error in % for ortho; vs_oracle = mean error / "
            "the oracle's mean error.\n",
            md_table(table, ["group", "condition", "method", "scenes", "mean_error",
                             "median_error", "vs_oracle", "wins_vs_bini", "losses_vs_bini",
                             "converged", "mean_deviation", "seconds"])]
    if free:
        worst = max(free, key=lambda r: r["ratio"])
        text.append(f"\nJump-free scene-conditions: {len(free)}; largest error ratio of "
                    f"dgp-disc over dgp: {worst['ratio']:.4f} ({worst['scene']}, "
                    f"{worst['condition']}).\n")
    if real:
        text += ["\nReal normal maps (defaults):\n",
                 md_table(real, ["data", "size", "method", "status", "pixels", "missing",
                                 "deviation", "made_mm", "seconds", "iterations",
                                 "grown", "converged"])]
    text = "\n".join(text)
    write_text(ctx.out / f"{stem}.md", text)
    ctx.add(title, text)
