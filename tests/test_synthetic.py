import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import facetlift
from facetlift import normals_from_gradients, synthetic
from facetlift.synthetic import (
    GroundTruth,
    add_angular_noise,
    add_smooth_noise,
    analytic,
    analytic_height,
    continuous_region,
    depth_jumps,
    perturb_fraction,
    remove_samples,
    render_mesh,
)

DATA = Path(__file__).parents[1] / ".." / "shared" / "data"
SMOOTH = ("saddle", "face", "sphere", "vase", "plane")


def _angle(a, b):
    c = np.clip(np.einsum("...i,...i->...", a, b), -1, 1)
    return np.degrees(np.arccos(c))


@pytest.mark.parametrize("name", SMOOTH)
def test_analytic_gradient_matches_finite_differences(name):
    gt = analytic(name, 48)
    H, W = gt.shape
    rows, cols = np.nonzero(gt.mask)
    x = cols + 0.5 - W / 2
    y = H / 2 - rows - 0.5
    s = min(H, W) / 2
    e = 1e-5
    z, p, q, inside = analytic_height(name, x, y, scale=s)
    zx = (analytic_height(name, x + e, y, scale=s)[0] - analytic_height(name, x - e, y, scale=s)[0])
    zy = (analytic_height(name, x, y + e, scale=s)[0] - analytic_height(name, x, y - e, scale=s)[0])
    ok = np.isfinite(zx) & np.isfinite(zy)
    assert ok.mean() > 0.95
    np.testing.assert_allclose(zx[ok] / (2 * e), p[ok], atol=1e-5)
    np.testing.assert_allclose(zy[ok] / (2 * e), q[ok], atol=1e-5)
    # the stored normals are those of the gradient, the depth is -height
    n = normals_from_gradients(p[None], q[None])[0]
    np.testing.assert_allclose(gt.normals[rows, cols], n, atol=1e-12)
    np.testing.assert_allclose(gt.depth[rows, cols], -z, atol=1e-12)


def test_grid_differences_converge_at_second_order():
    # central differences of the sampled depth approach the exact slope as O(h^2)
    errs = []
    for n in (64, 128, 256):
        gt = analytic("face", n)
        p = -gt.normals[..., 0] / gt.normals[..., 2]
        fd = -(gt.depth[:, 2:] - gt.depth[:, :-2]) / 2  # pixel_size 1: dz/dx
        errs.append(np.abs(fd - p[:, 1:-1]).max())
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all(ratios > 3.3) and np.all(ratios < 4.7)


@pytest.mark.parametrize("name", ["pyramid", "ramps", "tent"])
def test_crease_surfaces_exact_on_planar_pieces(name):
    gt = analytic(name, 64)
    p = -gt.normals[..., 0] / gt.normals[..., 2]
    q = -gt.normals[..., 1] / gt.normals[..., 2]
    # where three horizontal neighbours lie on one plane, central differences are exact
    y, x = np.mgrid[0:64, 0:64]
    plane = np.stack([p, q, -gt.depth - p * x + q * y], axis=-1)
    same = (np.abs(plane[:, :-2] - plane[:, 1:-1]).max(-1) < 1e-9) & (
        np.abs(plane[:, 2:] - plane[:, 1:-1]).max(-1) < 1e-9
    )
    fd = -(gt.depth[:, 2:] - gt.depth[:, :-2]) / 2
    assert same.mean() > 0.5
    np.testing.assert_allclose(fd[same], p[:, 1:-1][same], atol=1e-9)


def test_analytic_masks_and_errors():
    assert analytic("sphere", 40).mask.sum() < 40 * 40
    assert analytic("saddle", (20, 30)).shape == (20, 30)
    assert np.isnan(analytic("vase", 40).depth[0, 0])
    with pytest.raises(ValueError, match="`name` must be one of"):
        analytic("teapot", 16)
    with pytest.raises(ValueError, match="`size`"):
        analytic("saddle", 1)
    with pytest.raises(ValueError, match="`pixel_size`"):
        analytic("saddle", 16, pixel_size=0)


def _tilted_plane(a, b):
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    v[:, 2] = a * v[:, 0] + b * v[:, 1] + 3.0
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


@pytest.mark.parametrize("flip", [False, True])
def test_render_tilted_plane_exact(flip):
    a, b = 0.4, -0.7
    mesh = _tilted_plane(a, b)
    if flip:
        mesh.invert()  # winding away from the viewer: normals must still face it
    gt = render_mesh(mesh, (40, 40), view="front", margin=0.0)
    assert gt.mask.all()
    n = normals_from_gradients(np.full((40, 40), a), np.full((40, 40), b))
    np.testing.assert_allclose(gt.normals, n, atol=1e-12)
    # pixel units: slopes are scale-free; depth = -height, y up = against the row index
    np.testing.assert_allclose(np.diff(gt.depth, axis=1), -a, atol=1e-9)
    np.testing.assert_allclose(np.diff(gt.depth, axis=0), b, atol=1e-9)


def test_render_box_views():
    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    gt = render_mesh(box, 64, view="front", margin=0.1)
    assert np.allclose(gt.normals[gt.mask], [0, 0, 1])
    assert gt.depth_range < 1e-9
    rows, cols = np.nonzero(gt.mask)
    assert cols.max() - cols.min() + 1 == pytest.approx(64 * 0.8, abs=1)
    assert rows.max() - rows.min() + 1 == pytest.approx(64 * 0.8 / 2, abs=1)
    # an oblique view of a box sees three faces, each with a constant normal
    ob = render_mesh(box, 64, view="oblique")
    assert len(np.unique(np.round(ob.normals[ob.mask], 9), axis=0)) == 3
    assert (ob.normals[ob.mask][:, 2] > 0).all()


def test_render_errors():
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match="`view` must be one of"):
        render_mesh(box, 16, view="sideways")
    with pytest.raises(ValueError, match="`view` must be"):
        render_mesh(box, 16, view=(0, 0, 0))
    with pytest.raises(ValueError, match="`margin`"):
        render_mesh(box, 16, margin=0.6)
    with pytest.raises(ValueError, match="`mesh` file not found"):
        render_mesh("/nonexistent/mesh.ply", 16)
    with pytest.raises(ValueError, match="`mesh` must be"):
        render_mesh(3.0, 16)
    with pytest.raises(ValueError, match="`resolution`"):
        render_mesh(box, (16, 0))


def test_without_trimesh_only_render_mesh_needs_it():
    """Analytic ground truth works without trimesh; render_mesh names the extra to install."""
    code = (
        "import sys\n"
        "sys.modules['trimesh'] = None  # `import trimesh` now fails\n"
        "from facetlift import synthetic\n"
        "assert synthetic.analytic('saddle', 8).normals.shape == (8, 8, 3)\n"
        "for call in (lambda: synthetic.render_mesh('mesh.ply', 8), synthetic.vessel):\n"
        "    try:\n"
        "        call()\n"
        "    except ImportError as e:\n"
        "        print(e)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.count("needs trimesh") == 2
    assert run.stdout.count("pip install 'facetlift[render]'") == 2


@pytest.mark.skipif(not (DATA / "meshes" / "spot.ply").is_file(), reason="data absent")
def test_render_real_mesh_normals_match_depth():
    gt = render_mesh(DATA / "meshes" / "spot.ply", 96, view="oblique")
    assert gt.mask.sum() > 1000
    assert (gt.normals[gt.mask][:, 2] > 0).all()
    # away from jumps and creases, depth differences follow the normals
    p = -gt.normals[..., 0] / gt.normals[..., 2]
    same = np.abs(p[:, 1:] - p[:, :-1]) < 1e-12
    fd = -np.diff(gt.depth, axis=1)
    np.testing.assert_allclose(fd[same], p[:, 1:][same], atol=1e-6)


def test_depth_jumps_and_continuous_region():
    H, W = 20, 30
    depth = np.zeros((H, W))
    depth[:, 20:] = 10.0  # a step: a depth discontinuity with flat normals
    normals = np.zeros((H, W, 3))
    normals[..., 2] = 1.0
    gt = GroundTruth(depth, normals, np.ones((H, W), bool), 1.0, "step")
    jumps = depth_jumps(gt)
    assert jumps[:, 19].all() and jumps[:, 20].all() and jumps.sum() == 2 * H
    part = continuous_region(gt)
    assert part.mask[:, :19].all() and not part.mask[:, 19:].any()
    # a crease is not a jump
    crease = analytic("pyramid", 32)
    assert not depth_jumps(crease).any()
    with pytest.raises(ValueError, match="`tol`"):
        depth_jumps(gt, tol=-1)


def test_angular_noise_statistics():
    rng = np.random.default_rng(3)
    n = normals_from_gradients(rng.normal(0, 0.3, (100, 100)), rng.normal(0, 0.3, (100, 100)))
    n[0, 0] = np.nan
    noisy = add_angular_noise(n, 5.0, np.random.default_rng(7))
    assert np.isnan(noisy[0, 0]).all()
    ang = _angle(n, noisy)[1:].ravel()
    np.testing.assert_allclose(np.linalg.norm(noisy[1:], axis=-1), 1.0, atol=1e-12)
    # |N(0, sigma)|: RMS = sigma, mean = sigma sqrt(2/pi)
    assert np.sqrt(np.mean(ang**2)) == pytest.approx(5.0, rel=0.03)
    assert ang.mean() == pytest.approx(5.0 * np.sqrt(2 / np.pi), rel=0.03)
    # keep_front: strong noise never turns a normal away from the viewer
    big = add_angular_noise(n, 20.0, np.random.default_rng(8))
    assert (big[1:, :, 2] > 0).all() and (big[0, 1:, 2] > 0).all()
    with pytest.raises(ValueError, match="`sigma_deg`"):
        add_angular_noise(n, -1.0, rng)
    with pytest.raises(ValueError, match="`normals`"):
        add_angular_noise(np.zeros((4, 2)), 1.0, rng)


def test_blur_normals_softens_a_boundary_inside_the_mask_only():
    # two planes meeting at a column: the blur turns the boundary's normals gradually
    n = np.zeros((20, 30, 3))
    n[:, :15] = np.array([0.6, 0.0, 0.8])
    n[:, 15:] = np.array([-0.6, 0.0, 0.8])
    mask = np.ones((20, 30), bool)
    mask[:, 25:] = False
    n[~mask] = np.nan
    out = synthetic.blur_normals(n, 1.5)
    np.testing.assert_allclose(np.linalg.norm(out[mask], axis=-1), 1.0, atol=1e-12)
    assert np.isnan(out[~mask]).all()
    x = out[10, :25, 0]
    assert x[0] == pytest.approx(0.6) and x[24] == pytest.approx(-0.6)  # far from the seam
    assert 0.0 < x[14] < 0.6 and -0.6 < x[15] < 0.0  # the seam softened ...
    assert np.all(np.diff(x) <= 1e-12)  # ... monotonically
    # pixels outside the mask give no weight: the same as a map cut at the mask's edge
    np.testing.assert_allclose(synthetic.blur_normals(n[:, :25], 1.5), out[:, :25], atol=1e-12)
    # an explicit mask leaves its outside as it was
    inner = mask.copy()
    inner[:, :3] = False
    kept = synthetic.blur_normals(n, 1.5, mask=inner)
    np.testing.assert_array_equal(kept[:, :3], n[:, :3])
    np.testing.assert_array_equal(synthetic.blur_normals(n, 0.0), n)
    for bad in (-1.0, np.inf, (1.0, 2.0), "wide"):
        with pytest.raises(ValueError, match="`sigma`"):
            synthetic.blur_normals(n, bad)
    with pytest.raises(ValueError, match="`mask`"):
        synthetic.blur_normals(n, 1.0, mask=mask[:, :5])
    with pytest.raises(ValueError, match="`normals`"):
        synthetic.blur_normals(np.zeros((4, 3)), 1.0)


def test_resample_normals_softens_a_boundary_over_the_blocks_inside_the_mask_only():
    # two planes meeting at a column, resampled at half and a quarter of the resolution
    n = np.zeros((20, 32, 3))
    n[:, :16] = np.array([0.6, 0.0, 0.8])
    n[:, 16:] = np.array([-0.6, 0.0, 0.8])
    mask = np.ones((20, 32), bool)
    mask[:, 28:] = False
    n[~mask] = np.nan
    for f in (2, 4):
        out = synthetic.resample_normals(n, f)
        np.testing.assert_allclose(np.linalg.norm(out[mask], axis=-1), 1.0, atol=1e-12)
        assert np.isnan(out[~mask]).all()
        x = out[10, :28, 0]
        assert x[0] == pytest.approx(0.6) and x[27] == pytest.approx(-0.6)  # far from the seam
        assert np.all(np.diff(x) <= 1e-12)  # monotonic
        soft = int(np.sum(np.abs(x) < 0.59))  # (pixels between the two planes' normals)
        assert f - 1 <= soft <= 2 * f, (f, soft)  # (about a block on each side)
    # a plane stays the plane, a factor of 1 returns a copy, and bad input is named
    plane = np.broadcast_to(np.array([0.0, 0.6, 0.8]), (9, 10, 3))
    np.testing.assert_allclose(synthetic.resample_normals(plane, 3), plane, atol=1e-12)
    np.testing.assert_array_equal(synthetic.resample_normals(n, 1), n)
    for bad in (0, 1.5, True, "2"):
        with pytest.raises(ValueError, match="`factor`"):
            synthetic.resample_normals(n, bad)
    with pytest.raises(ValueError, match="`mask`"):
        synthetic.resample_normals(n, 2, mask=mask[:, :5])


def test_smooth_noise_is_correlated_with_the_rms_asked():
    rng = np.random.default_rng(3)
    n = normals_from_gradients(rng.normal(0, 0.3, (160, 160)), rng.normal(0, 0.3, (160, 160)))
    n[0, 0] = np.nan
    out = add_smooth_noise(n, 3.0, np.random.default_rng(5), length=8.0)
    assert np.isnan(out[0, 0]).all()
    np.testing.assert_allclose(np.linalg.norm(out[1:], axis=-1), 1.0, atol=1e-12)
    ang = _angle(n, out)
    ang[0, 0] = np.nan
    # the RMS over the image is the one asked (a 160^2 image holds ~100 correlation areas)
    assert np.sqrt(np.nanmean(ang**2)) == pytest.approx(3.0, rel=0.05)
    # neighbours' errors agree: on a constant normal map the change of the error between
    # neighbours is far below the error itself (independent noise: sqrt(2) of it)
    flat = np.broadcast_to(np.array([0.3, 0.0, 1.0]) / np.hypot(0.3, 1.0), (160, 160, 3))
    err = add_smooth_noise(flat, 3.0, np.random.default_rng(5), length=8.0) - flat
    step = np.linalg.norm(err[1:] - err[:-1], axis=-1)
    assert np.sqrt(np.mean(step**2)) < 0.3 * np.sqrt(np.mean(np.sum(err**2, -1)))
    # the RMS is the one asked on a masked, strongly tilted map too (the field is turned onto
    # every normal's tangent plane, and the RMS taken over the finite normals)
    sphere = analytic("sphere", 96)
    ang = _angle(sphere.normals, add_smooth_noise(sphere.normals, 3.0, 1, length=6.0))
    assert np.sqrt(np.nanmean(ang[sphere.mask] ** 2)) == pytest.approx(3.0, rel=1e-6)
    # keep_front: a strong field never turns a normal away from the viewer
    big = add_smooth_noise(n, 30.0, np.random.default_rng(8), length=4.0)
    assert (big[1:, :, 2] > 0).all()
    # seeded: the same field for the same seed
    np.testing.assert_array_equal(
        out, add_smooth_noise(n, 3.0, np.random.default_rng(5), length=8.0))
    with pytest.raises(ValueError, match="`sigma_deg`"):
        add_smooth_noise(n, -1.0)
    with pytest.raises(ValueError, match="`sigma_deg`"):
        add_smooth_noise(n, 45.0)
    with pytest.raises(ValueError, match="`length`"):
        add_smooth_noise(n, 1.0, length=0.0)
    with pytest.raises(ValueError, match="`normals`"):
        add_smooth_noise(np.zeros((4, 3)), 1.0)


@pytest.mark.parametrize("fraction", [0.15, 0.3, 0.5, 0.55])
def test_perturb_fraction(fraction):
    gt = analytic("sphere", 64)
    out, chosen, angles = perturb_fraction(gt.normals, fraction, rng=np.random.default_rng(1))
    k = int(gt.mask.sum())
    assert chosen.sum() == round(fraction * k)
    assert not (chosen & ~gt.mask).any()
    np.testing.assert_array_equal(out[gt.mask & ~chosen], gt.normals[gt.mask & ~chosen])
    meas = _angle(out[chosen], gt.normals[chosen])
    np.testing.assert_allclose(meas, angles[chosen], atol=1e-5)
    assert angles[chosen].max() <= 20.0 and angles[chosen].mean() == pytest.approx(10, rel=0.1)
    with pytest.raises(ValueError, match="`fraction`"):
        perturb_fraction(gt.normals, 1.5, rng=np.random.default_rng(1))
    with pytest.raises(ValueError, match="`max_deg`"):
        perturb_fraction(gt.normals, 0.1, max_deg=100, rng=np.random.default_rng(1))


def test_remove_samples():
    gt = analytic("face", 40)
    out, removed = remove_samples(gt.normals, 0.3, np.random.default_rng(2))
    assert removed.sum() == round(0.3 * 1600)
    assert np.isnan(out[removed]).all() and np.isfinite(out[~removed]).all()
    np.testing.assert_array_equal(out[~removed], gt.normals[~removed])


def test_views_are_orthonormal_right_handed():
    for view in synthetic.VIEWS:
        F = synthetic._view_frame(view)
        np.testing.assert_allclose(F @ F.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.cross(F[0], F[1]), F[2], atol=1e-12)


# ----------------------------------------------------------------------------------------------
# perspective rendering, quantisation, ground-truth jumps


def _sphere_on_wall():
    """A sphere in front of a square wall: an occluding contour all around the sphere."""
    ball = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    wall = trimesh.creation.box(extents=(6.0, 6.0, 0.1))
    wall.apply_translation((0.0, 0.0, -2.0))
    return trimesh.util.concatenate([ball, wall])


def test_render_perspective_depth_normals_and_camera():
    from facetlift.perspective import normals_from_depth

    K = np.array([[400.0, 0.0, 63.5], [0.0, 400.0, 47.5], [0.0, 0.0, 1.0]])
    gt = synthetic.render_perspective(trimesh.creation.icosphere(subdivisions=5), K, (96, 128),
                                      distance=10.0, fill=0.5)
    assert gt.K is not None and gt.camera.perspective and gt.mask.sum() > 1000
    # the sphere's nearest point is 1 radius in front of its centre (radius fills 1/4 of 96 rows)
    radius = 10.0 * np.tan(np.arctan(0.5 * 96 / 800)) / 1.0
    assert abs(np.nanmin(gt.depth) - (10.0 - radius)) < 0.01 * radius
    nd = normals_from_depth(gt.depth, K)
    ok = gt.mask & np.isfinite(nd).all(-1)
    ang = np.degrees(np.arccos(np.clip((nd[ok] * gt.normals[ok]).sum(-1), -1, 1)))
    assert np.median(ang) < 1.0  # central differences span several facets: ~0.6 deg
    # supersampled normals stay close to the centre ray's (faceting of the icosphere: ~0.6 deg;
    # a frame or sign error would show tens of degrees)
    gt3 = synthetic.render_perspective(trimesh.creation.icosphere(subdivisions=5), K, (96, 128),
                                       distance=10.0, fill=0.5, samples=3)
    both = gt.mask & gt3.mask
    ang3 = np.degrees(np.arccos(np.clip((gt.normals[both] * gt3.normals[both]).sum(-1), -1, 1)))
    assert np.median(ang3) < 1.0
    with pytest.raises(ValueError, match="`samples` must be an integer >= 1"):
        synthetic.render_perspective(trimesh.creation.icosphere(), K, (8, 8), samples=0)
    with pytest.raises(ValueError, match="`distance` must be a finite number > 0"):
        synthetic.render_perspective(trimesh.creation.icosphere(), K, (8, 8), distance=-1)
    # the default camera at another aspect ratio keeps DiLiGenT's pixel shape (both focal
    # lengths scaled by W / 612: per axis, 1536 x 2048 got fx / fy 1.12, a user's check)
    # and its principal point's place in the image
    tall = synthetic.render_perspective(trimesh.creation.icosphere(), None, (48, 40))
    D = synthetic.DILIGENT_K
    assert tall.K[0, 0] / tall.K[1, 1] == pytest.approx(D[0, 0] / D[1, 1], rel=1e-12)
    assert tall.K[0, 2] / 40 == pytest.approx(D[0, 2] / 612)
    assert tall.K[1, 2] / 48 == pytest.approx(D[1, 2] / 512)


def test_jump_edges_find_the_occluding_contour_and_nothing_else():
    K = np.array([[300.0, 0.0, 47.5], [0.0, 300.0, 47.5], [0.0, 0.0, 1.0]])
    gt = synthetic.render_perspective(_sphere_on_wall(), K, (96, 96), distance=12.0, fill=0.9)
    right, down = synthetic.jump_edges(gt)
    assert right.sum() + down.sum() > 40
    # the cut edges form a closed loop around the sphere: cutting them separates two pieces
    pr = facetlift.prepare(gt.normals, gt.mask, K=K)
    from facetlift.methods.dgp import split as spl

    assert spl.split(pr.domain, right, down).n_pieces >= 2
    ball = synthetic.render_perspective(trimesh.creation.icosphere(subdivisions=5), K, (96, 96),
                                        distance=12.0, fill=0.5)
    r2, d2 = synthetic.jump_edges(ball)
    assert r2.sum() + d2.sum() == 0  # a smooth sphere alone has no jump


def test_tabletop_sets_objects_on_a_table_that_they_occlude():
    """synthetic.tabletop: the objects stand on the plane y = 0 with the table under them;
    seen from TABLE_VIEW the table is behind them (jumps along their outlines); the same seed
    gives the same scene."""
    K = np.array([[300.0, 0.0, 63.5], [0.0, 300.0, 47.5], [0.0, 0.0, 1.0]])
    parts = [trimesh.creation.icosphere(subdivisions=3), trimesh.creation.box((1.0, 1.4, 0.8))]
    scene = synthetic.tabletop(parts, seed=1)
    assert isinstance(scene, trimesh.Trimesh)
    assert scene.bounds[0, 1] == pytest.approx(-0.02)  # the table's underside
    # every object rests on the table top, and no two objects' bounding boxes meet (they
    # touch the table, never one another), also with three objects and other seeds
    for seed in range(6):
        objs, table = synthetic._tabletop_parts(parts + [parts[0]], seed, 0.9, (0.1, 0.6), 0.6)
        assert table.bounds[1, 1] == pytest.approx(0.0)
        for i, a in enumerate(objs):
            assert a.bounds[0, 1] == pytest.approx(0.0, abs=1e-9)
            for b in objs[:i]:
                assert not (np.all(a.bounds[0] < b.bounds[1])
                            and np.all(b.bounds[0] < a.bounds[1])), seed
        assert objs[1].bounds[1, 2] < min(objs[0].bounds[0, 2], objs[2].bounds[0, 2])
    np.testing.assert_array_equal(synthetic.tabletop(parts, seed=1).vertices, scene.vertices)
    assert not np.array_equal(synthetic.tabletop(parts, seed=2).vertices, scene.vertices)
    gt = synthetic.render_perspective(scene, K, (96, 128), view=synthetic.TABLE_VIEW,
                                      distance=10.0, fill=0.9)
    right, down = synthetic.jump_edges(gt)
    assert right.sum() + down.sum() > 40  # the objects' outlines against the table
    from scipy import ndimage

    assert ndimage.label(gt.mask)[1] == 1 and gt.mask.sum() > 1000
    with pytest.raises(ValueError, match="at least one mesh"):
        synthetic.tabletop([])


def test_room_stands_objects_on_a_floor_between_walls():
    """synthetic.room: objects rest on the floor y = 0 inside the room, no two bounding boxes
    meet; seen from room_view from inside (fill > 1) the bare room's floor and two walls meet
    in creases that are no jumps, and the objects add jumps along their outlines; the same
    seed gives the same scene."""
    K = np.array([[120.0, 0.0, 63.5], [0.0, 120.0, 47.5], [0.0, 0.0, 1.0]])
    parts = [trimesh.creation.icosphere(subdivisions=3), trimesh.creation.box((1.0, 1.4, 0.8))]
    scene = synthetic.room(parts, seed=1)
    assert isinstance(scene, trimesh.Trimesh)
    np.testing.assert_array_equal(synthetic.room(parts, seed=1).vertices, scene.vertices)
    assert not np.array_equal(synthetic.room(parts, seed=3).vertices, scene.vertices)
    assert scene.bounds[0, 1] == pytest.approx(-0.02)  # the floor's underside
    assert scene.bounds[1, 1] == pytest.approx(2.0)  # the walls' top
    # (the objects are the first 3 x 12 ... faces: split off by connected pieces instead)
    pieces = [p for p in scene.split(only_watertight=False) if p.bounds[1, 1] < 1.99
              and p.bounds[0, 1] > -0.01]
    assert len(pieces) == 3  # ball, box and the extra box
    for i, a in enumerate(pieces):
        assert a.bounds[0, 1] == pytest.approx(0.0, abs=1e-9)
        assert np.all(np.abs(a.bounds[:, [0, 2]]) < 2.0)
        for b in pieces[:i]:
            assert not (np.all(a.bounds[0] < b.bounds[1]) and np.all(b.bounds[0] < a.bounds[1]))
    bare = synthetic.render_perspective(synthetic.room([], boxes=0, seed=0), K, (96, 128),
                                        view=synthetic.room_view(0), distance=10.0, fill=1.8)
    right, down = synthetic.jump_edges(bare)
    assert bare.mask.mean() > 0.6 and right.sum() + down.sum() == 0
    faces = np.unique(np.round(bare.normals[bare.mask], 3), axis=0)
    assert len(faces) == 3  # floor, back wall, side wall
    gt = synthetic.render_perspective(scene, K, (96, 128), view=synthetic.room_view(1),
                                      distance=10.0, fill=1.8)
    right, down = synthetic.jump_edges(gt)
    assert right.sum() + down.sum() > 20
    with pytest.raises(ValueError, match="no free place"):
        synthetic.room(parts * 10, size=2.0)
    with pytest.raises(ValueError, match="fill"):
        synthetic.render_perspective(scene, K, (96, 128), fill=4.5)


def test_quantize():
    rng = np.random.default_rng(3)
    n = rng.standard_normal((20, 20, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[0, 0] = np.nan
    for bits in (8, 16):
        q = synthetic.quantize(n, bits)
        assert np.isnan(q[0, 0]).all()
        assert np.nanmax(np.abs(q - n)) <= 1.0 / (2**bits - 1) + 1e-12
    with pytest.raises(ValueError, match="`bits` must be 8 or 16"):
        synthetic.quantize(n, 12)


@pytest.mark.parametrize("rim", ["round", "flat"])
@pytest.mark.parametrize("kind", synthetic.VESSELS)
def test_vessels_are_open_with_walls_of_the_given_thickness(kind, rim):
    m = synthetic.vessel(kind, thickness=0.04, sections=32, rim=rim)
    assert m.is_watertight and m.volume > 0
    assert m.bounds[0, 1] == pytest.approx(0.0, abs=1e-12) and 0.4 < m.bounds[1, 1] <= 1.03
    top = m.bounds[1, 1]
    ring = m.vertices[np.isclose(m.vertices[:, 1], top)]
    radii = np.unique(np.round(np.hypot(ring[:, 0], ring[:, 2]), 9))
    if rim == "flat":  # a flat band 0.04 wide at the top
        assert radii.size == 2 and radii[1] - radii[0] == pytest.approx(0.04)
    else:  # a half circle over the wall: its top one ring, half the wall above the walls' tops
        assert radii.size == 1
        walls = m.vertices[np.isclose(np.hypot(m.vertices[:, 0], m.vertices[:, 2]),
                                      radii[0] + 0.02)]
        assert top - walls[:, 1].max() == pytest.approx(0.02)
    # down the axis from above: the inside's floor, well below the rim (not a solid top)
    hits, _, _ = m.ray.intersects_location([[0.0, 2.0, 0.0]], [[0.0, -1.0, 0.0]])
    floor = hits[:, 1].max()
    assert 0.05 < floor < 0.6 * top
    # across a wall half-way up the inside, along a section's plane: 0.04 along the radius
    mid = 0.5 * (floor + top)
    hits, _, _ = m.ray.intersects_location([[0.0, mid, 0.0]], [[1.0, 0.0, 0.0]])
    x = np.sort(hits[:, 0])
    assert x.size == 2 and x[1] - x[0] == pytest.approx(0.04, abs=1e-9)


def test_vessel_errors():
    with pytest.raises(ValueError, match="`kind`"):
        synthetic.vessel("mug")
    with pytest.raises(ValueError, match="`thickness`"):
        synthetic.vessel("vase", thickness=0.2)
    with pytest.raises(ValueError, match="`sections`"):
        synthetic.vessel("cup", sections=3)
    with pytest.raises(ValueError, match="`sections`"):
        synthetic.vessel("cup", sections=8.5)
    with pytest.raises(ValueError, match="`thickness`"):
        synthetic.vessel("cup", thickness=None)
    with pytest.raises(ValueError, match="`rim`"):
        synthetic.vessel("cup", rim="square")
    with pytest.raises(ValueError, match="`elevation_deg`"):
        synthetic.vessel_view(90)
    with pytest.raises(ValueError, match="`elevation_deg`"):
        synthetic.vessel_view("high")
    v = np.array(synthetic.vessel_view(30))
    np.testing.assert_allclose([np.linalg.norm(v), v[1]], [1.0, -0.5])


def test_ground_truth_repr_is_a_summary():
    """Not the arrays (a notebook printed them whole, a user's check)."""
    gt = synthetic.analytic("sphere", 32)
    assert repr(gt) == "GroundTruth('sphere', 32x32, %d pixels, orthographic, pixel_size=1)" % (
        int(gt.mask.sum()))


def test_depth_jumps_take_the_camera_of_a_perspective_render():
    """An audit: depth_jumps took orthographic slopes in pixel-size units, so a perspective
    render (depth in mm) of a sphere had 4,066 of its 4,664 pixels flagged and
    continuous_region kept 598; it now tests in the camera's unknown, as jump_edges."""
    gt = synthetic.render_perspective(trimesh.creation.icosphere(4), None, (96, 112), fill=0.8)
    assert not synthetic.depth_jumps(gt).any()
    assert synthetic.continuous_region(gt).mask.sum() == gt.mask.sum()
    steps = synthetic.analytic("steps", 64)
    assert synthetic.depth_jumps(steps).any()
    # a perspective jump (a small sphere in front of a large one) is flagged, on every pixel
    # beside an edge jump_edges finds (a review)
    front = trimesh.creation.icosphere(3, radius=0.5)
    front.apply_translation([0.6, 0.3, 1.2])
    both = trimesh.util.concatenate([trimesh.creation.icosphere(3, radius=1.0), front])
    gt = synthetic.render_perspective(both, None, (96, 112), fill=0.8)
    right, down = synthetic.jump_edges(gt)
    beside = np.zeros(gt.mask.shape, bool)
    beside[:, :-1] |= right
    beside[:, 1:] |= right
    beside[:-1] |= down
    beside[1:] |= down
    flagged = synthetic.depth_jumps(gt)
    assert beside.any() and not (beside & ~flagged).any()


@pytest.mark.parametrize("call", ["tabletop", "room"])
def test_scene_builders_name_the_render_extra_without_trimesh(call, monkeypatch):
    """tabletop and room imported trimesh bare: a ModuleNotFoundError traceback (an audit)."""
    import sys

    monkeypatch.setitem(sys.modules, "trimesh", None)  # (import trimesh -> ImportError)
    with pytest.raises(ImportError, match=rf"synthetic\.{call} needs trimesh.*facetlift\[render\]"):
        getattr(synthetic, call)(["mesh.ply"])


def test_render_jumps_come_from_the_geometry():
    """jumps=True: the edges a depth jump crosses, from rays between the pixel centres (the
    pixel-centre test cut continuous surfaces and missed grazing jumps on the benchmark's
    renders, a review). A sphere alone has none; a sphere half behind another has them
    exactly along the front one's outline, where the depth steps."""
    trimesh = pytest.importorskip("trimesh")
    front = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    alone = synthetic.render_mesh(front, 48, view="front", jumps=True)
    assert not any(j.any() for j in synthetic.jump_edges(alone, geometric=True))
    back = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    back.apply_translation([1.0, 0.3, -2.0])
    pair = trimesh.util.concatenate([front, back])
    for gt in (synthetic.render_mesh(pair, 64, view="front", jumps=True),
               synthetic.render_perspective(pair, resolution=(64, 80), view="front",
                                            distance=12.0, fill=0.8, samples=3, jumps=True)):
        right, down = synthetic.jump_edges(gt, geometric=True)
        u = gt.camera.from_depth(gt.depth)
        step_r, step_d = np.abs(np.diff(u, axis=1)), np.abs(np.diff(u, axis=0))
        scale = np.nanmax(np.r_[step_r[np.isfinite(step_r)], step_d[np.isfinite(step_d)]])
        assert right.sum() + down.sum() > 10
        # every cut crosses a large step, and every large step is cut
        assert np.all(step_r[right] > 0.2 * scale) and np.all(step_d[down] > 0.2 * scale)
        m = gt.mask
        big_r = (step_r > 0.5 * scale) & m[:, :-1] & m[:, 1:]
        big_d = (step_d > 0.5 * scale) & m[:-1] & m[1:]
        assert np.all(right[big_r]) and np.all(down[big_d])
    with pytest.raises(ValueError, match=r"render it with jumps=True"):
        synthetic.jump_edges(synthetic.render_mesh(front, 16), geometric=True)


def test_perturbations_read_normals_as_integrate_does():
    """A uint8 map is decoded as integrate decodes it (its raw codes were rotated as vectors:
    0.577 normalised error after 1 degree of noise), signed integers are numbers, and normals
    off unit length are scaled first (a map times 2 was turned by half the angle asked and
    perturb_fraction recorded angles it had not applied); a zero vector becomes missing."""
    from facetlift.frames import FrameWarning

    gt = analytic("face", (48, 56))
    n = np.where(gt.mask[..., None], gt.normals, np.nan)
    codes = np.round((np.nan_to_num(n) + 1) / 2 * 255).astype(np.uint8)
    with pytest.warns(FrameWarning, match="decoded as v / 255"):
        same = add_angular_noise(codes, 0.0, 0)
    assert np.nanmax(_angle(same, n)[gt.mask]) < 0.5  # (8-bit rounding)
    with pytest.warns(FrameWarning):
        assert np.isfinite(synthetic.quantize(codes, 8)).all()
    up = add_angular_noise(np.array([[0, 0, 1]]), 1.0, 0)  # (integers as numbers, as before)
    assert abs(_angle(up, np.array([0.0, 0.0, 1.0]))[0] - 1.0) < 1.0
    a = add_angular_noise(n, 5.0, np.random.default_rng(3))
    b = add_angular_noise(2.0 * n, 5.0, np.random.default_rng(3))
    np.testing.assert_allclose(b[gt.mask], a[gt.mask], atol=1e-12)
    moved, chosen, angles = perturb_fraction(2.0 * n, 1.0, rng=0)
    assert chosen.sum() == gt.mask.sum()
    np.testing.assert_allclose(_angle(moved, n)[gt.mask], angles[gt.mask], atol=1e-6)
    z = n.copy()
    z[20, 20] = 0.0
    with np.errstate(all="raise"):  # (no 0 / 0 left to numpy)
        out = add_angular_noise(z, 1.0, 0)
    rest = gt.mask.copy()
    rest[20, 20] = False
    assert gt.mask[20, 20] and np.isnan(out[20, 20]).all() and np.isfinite(out[rest]).all()
    assert remove_samples(2.0 * n, 0.0, 0)[0][gt.mask].max() > 1.5  # (values kept as given)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (no file-encoding warning for a scaled map)
        np.testing.assert_array_equal(synthetic.quantize(2.0 * n, 8), synthetic.quantize(n, 8))


@pytest.mark.parametrize("call, message", [
    (lambda n: add_angular_noise(n, 40.0), "`sigma_deg` must be a finite number in \\[0, 30\\]"),
    (lambda n: add_angular_noise(n, "5"), "`sigma_deg` must be a finite number"),
    (lambda n: add_angular_noise(n, None), "`sigma_deg` must be a finite number"),
    (lambda n: add_angular_noise(n, 1.0, "x"), "`rng` must be a numpy.random.Generator"),
    (lambda n: add_smooth_noise(n, 1.0, 0, length="8"), "`length` must be a finite number > 0"),
    (lambda n: perturb_fraction(n, "0.5"), "`fraction` must be a finite number in \\[0, 1\\]"),
    (lambda n: perturb_fraction(n, 0.5, max_deg=None), "`max_deg` must be a finite number"),
    (lambda n: remove_samples(n, 2.0), "`fraction` must be a finite number in \\[0, 1\\]"),
])
def test_perturbations_name_a_bad_argument(call, message):
    n = analytic("sphere", 16).normals
    with pytest.raises(ValueError, match=message):
        call(n)


def test_scene_builders_check_their_arguments(tmp_path):
    """tabletop, room, room_view, analytic and GroundTruth refuse what built a wrong scene
    or failed deep inside numpy (an audit), and take one mesh path as a list of one."""
    box = trimesh.creation.box(extents=(0.4, 0.3, 0.2))
    path = tmp_path / "box.ply"
    box.export(path)
    one = synthetic.tabletop(str(path))  # (its characters were taken for file names)
    np.testing.assert_array_equal(one.vertices, synthetic.tabletop([str(path)]).vertices)
    bad = [
        (lambda: synthetic.tabletop([box], margin=-5), "`margin` must be a finite number >= 0"),
        (lambda: synthetic.tabletop([box], spacing=-1), "`spacing` must be a finite number > 0"),
        (lambda: synthetic.tabletop([box], behind=(0.6, 0.1)), "`behind` must be \\(low, high\\)"),
        (lambda: synthetic.tabletop(3), "`meshes` must be a list"),
        (lambda: synthetic.room([box], size=0), "`size` must be a finite number > 0"),
        (lambda: synthetic.room([box], height=-2), "`height` must be a finite number > 0"),
        (lambda: synthetic.room([box], radius=(0.6, 0.35)), "`radius` must be \\(low, high\\)"),
        (lambda: synthetic.room([box], radius=(0, 0)), "`radius` must be a finite number > 0"),
        (lambda: synthetic.room([box], boxes=1.5), "`boxes` must be an integer >= 0"),
        (lambda: synthetic.room([box], seed=None), "`seed` must be an integer >= 0"),
        (lambda: synthetic.tabletop([box], seed=-1), "`seed` must be a numpy.random.Generator"),
        (lambda: synthetic.room([box], size=np.array(0.0)), "`size` must be a finite number"),
        (lambda: synthetic.room_view("a"), "`seed` must be an integer >= 0"),
        (lambda: synthetic.room_view(1.5), "`seed` must be an integer >= 0"),
        (lambda: render_mesh(trimesh.Trimesh(), 32), "`mesh` holds no triangles"),
        (lambda: render_mesh(box, 32, margin="0.1"), "`margin` must be a finite number"),
        (lambda: synthetic.render_perspective(trimesh.Trimesh(), None, 32),
         "`mesh` holds no triangles"),
        (lambda: synthetic.render_perspective(box, None, 32, samples=None),
         "`samples` must be an integer >= 1"),
        (lambda: analytic_height("face", 0.0, 0.0, scale=0), "`scale` must be a finite number > 0"),
        (lambda: analytic_height("face", 0.0, 0.0, scale=-1), "`scale` must be a finite number"),
        (lambda: analytic("plane", 16, pixel_size=None), "`pixel_size` must be a finite number"),
        (lambda: analytic(["plane"], 16), "`name` must be one of"),
        (lambda: synthetic.jump_edges(analytic("steps", 16), tol=None), "`tol` must be a finite"),
        (lambda: GroundTruth(np.zeros((2, 2)), np.zeros((3, 3, 3)), np.ones((4, 4), bool)),
         "`depth` must have the mask's shape \\(4, 4\\)"),
        (lambda: GroundTruth(np.zeros((4, 4)), np.zeros((4, 4, 2)), np.ones((4, 4), bool)),
         "`normals` must have shape \\(4, 4, 3\\)"),
        (lambda: GroundTruth(np.zeros((4, 4)), np.zeros((4, 4, 3)), np.ones((4, 4))),
         "`mask` must be an \\(H, W\\) bool array"),
    ]
    for call, message in bad:
        with pytest.raises(ValueError, match=message):
            call()
    assert synthetic.render_perspective(box, None, 32, samples=2.0).mask.any()
    ball = trimesh.creation.icosphere(subdivisions=2)
    wide = [[20.0, 0.0, 12.0], [0.0, 20.0, 12.0], [0.0, 0.0, 1.0]]  # (about 62 deg across)
    with pytest.raises(ValueError, match="the camera sits inside the closed mesh"):
        synthetic.render_perspective(ball, wide, 24, fill=4.0)
    assert synthetic.render_perspective(ball, wide, 24, fill=1.5).mask.all()  # (outside it)
    assert synthetic.room([box], size=np.array(4.0), seed=2).faces.size  # (a 0-d array: a number)


def test_flags_and_masks_of_the_renders_and_filters():
    """`jumps='no'` ran the jump search (a string is true) and a float mask of 0.5 was cast
    to all True: both are named."""
    box = trimesh.creation.box(extents=(0.4, 0.3, 0.2))
    with pytest.raises(ValueError, match="`jumps` must be True or False"):
        render_mesh(box, 24, jumps="no")
    with pytest.raises(ValueError, match="`jumps` must be True or False"):
        synthetic.render_perspective(box, None, 24, jumps="no")
    n = analytic("sphere", 16).normals
    with pytest.raises(ValueError, match="`mask` must be a bool"):
        synthetic.blur_normals(n, 1.0, mask=np.full((16, 16), 0.5))
    ones = np.isfinite(n).all(axis=-1).astype(np.uint8)
    np.testing.assert_array_equal(synthetic.resample_normals(n, 2, mask=ones),
                                  synthetic.resample_normals(n, 2, mask=ones.astype(bool)))
