"""Normals given in world space: integrate(normal_rotation=), its checks and hints, and the
command line's --world-to-camera / --camera-to-world (and a dataset folder's files)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import facetlift
from facetlift import frames, synthetic
from facetlift.camera import K_from_fov


def random_rotation(seed: int) -> np.ndarray:
    """A proper rotation drawn uniformly (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def sphere():
    gt = synthetic.analytic("sphere", 48)
    return gt.normals, gt.mask


def to_world(cam: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Camera-frame normals (in whatever axes R maps world to) as world ones: R^T n."""
    return cam @ R  # (row vectors: (R^T n)^T = n^T R)


def messages(record) -> str:
    return "\n".join(str(w.message) for w in record)


@pytest.mark.parametrize("frame", ["opengl", "opencv"])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name, camera", [("sphere", False), ("face", True)])
def test_world_normals_rotated_integrate_as_the_camera_frame_ones(name, camera, frame, seed):
    """World normals with their world-to-camera rotation give the camera-frame result: in the
    default frame, and in OpenCV's (the camera frame's normals in OpenCV axes, then rotated by
    a rotation from world to that frame, as COLMAP's R is). (With a camera, a surface without
    normals near edge-on: the sphere's rim seen obliquely turns rounding into 1e-8.)"""
    gt = synthetic.analytic(name, 48)
    n, mask = gt.normals, gt.mask
    K = K_from_fov(mask.shape, 50.0) if camera else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = facetlift.integrate(n, mask, K=K)
        R = random_rotation(seed)
        world = to_world(frames.from_facetlift(n, frame), R)
        assert not np.allclose(world[mask], frames.from_facetlift(n, frame)[mask])
        got = facetlift.integrate(world, mask, K=K, normal_frame=frame, normal_rotation=R)
    np.testing.assert_allclose(got.depth[mask], ref.depth[mask], rtol=0, atol=1e-10)
    assert got.info["input"] == ref.info["input"]


def test_a_pose_gives_its_rotation_and_nans_stay_missing(sphere):
    """A 3x4 or 4x4 pose (with a translation) is taken for its upper-left 3x3; NaN normals
    inside the mask stay missing samples, counted as the camera-frame ones are."""
    n, mask = sphere
    n = n.copy()
    n[20:23, 20:23] = np.nan
    R = random_rotation(5)
    world = to_world(n, R)
    assert np.isnan(world[20:23, 20:23]).all()
    ref = facetlift.integrate(n, mask)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, [1.0, -2.0, 30.0]
    for matrix in (pose, pose[:3], R.tolist()):
        got = facetlift.integrate(world, mask, normal_rotation=matrix)
        np.testing.assert_allclose(got.depth[mask], ref.depth[mask], rtol=0, atol=1e-10)
        assert got.info["input"]["missing"] == ref.info["input"]["missing"] == 9


@pytest.mark.parametrize("matrix, match", [
    (np.eye(2), r"`normal_rotation` must be a 3x3 rotation matrix.*got shape \(2, 2\)"),
    (np.ones(9), r"`normal_rotation` must be a 3x3 rotation matrix.*got shape \(9,\)"),
    (np.eye(5), r"got shape \(5, 5\)"),
    ([["a", "b", "c"]] * 3, "`normal_rotation` must be a 3x3 rotation matrix .* of numbers"),
    (np.diag([1.0, np.nan, 1.0]), "`normal_rotation` has non-finite entries"),
    (np.diag([1.0, 1.0, np.inf, 1.0]), "`normal_rotation` has non-finite entries"),
    (2.0 * np.eye(3), r"`normal_rotation` is not a rotation: R R\^T differs from the "
     r"identity by up to 3 .* singular values are 2 to 2, .* scaled camera"),
    (np.array([[1.0, 0.01, 0], [0, 1, 0], [0, 0, 1]]), "is not a rotation"),
    (np.diag([1.0, -1.0, 1.0]), r"`normal_rotation` is a reflection \(determinant -1\).*"
     "normal_frame, --normal-frame"),
])
def test_bad_rotations_are_refused_naming_the_argument(sphere, matrix, match):
    n, mask = sphere
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(n, mask, normal_rotation=matrix)


def test_a_rotation_within_the_tolerance_is_taken():
    """A rotation written to 5 decimals (a text file's) is a rotation."""
    R = np.round(random_rotation(3), 5)
    assert np.allclose(frames.check_rotation(R), R)


def test_the_rotation_is_checked_before_the_normals(sphere):
    """Its error comes alone, not after the input's own (a map that faces away)."""
    n, mask = sphere
    with pytest.raises(ValueError, match="`normal_rotation`"):
        facetlift.integrate(-n, mask, normal_rotation=np.zeros((3, 3)))


def test_integrate_gradients_refuses_a_rotation():
    p = q = np.zeros((8, 8))
    with pytest.raises(ValueError, match="`normal_rotation` does not apply to a gradient "
                                         "field.*no world frame"):
        facetlift.integrate_gradients(p, q, normal_rotation=np.eye(3))


def run_integrate(normals, mask, **kw):
    """(error message or None, the warnings' text) of an integrate."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        try:
            facetlift.integrate(normals, mask, **kw)
        except ValueError as e:
            return str(e), messages(record)
    return None, messages(record)


# seeds of random_rotation whose world map (of the sphere) is refused as facing away (more
# than half) and warned about (5-50 % facing away), as found below
@pytest.mark.parametrize("seed", [3, 7])
def test_the_hint_names_the_rotation_for_world_normals_and_not_once_given(sphere, seed):
    n, mask = sphere
    R = random_rotation(seed)
    world = to_world(n, R)
    away = frames.facing_away(world[mask])
    error, said = run_integrate(world, mask)
    text = error or said
    assert (error is not None) == (away > 0.5)  # (the two paths: a refusal, a warning)
    assert "--world-to-camera FILE or --camera-to-world FILE (normal_rotation=R" in text
    error, said = run_integrate(world, mask, normal_rotation=R)
    assert error is None and "world" not in said and "rotation" not in said


def test_the_two_paths_are_both_tried(sphere):
    """The seeds above give one refusal and one warning (the test's own premise)."""
    n, mask = sphere
    shares = [frames.facing_away(to_world(n, random_rotation(s))[mask]) for s in (3, 7)]
    assert shares[0] > 0.5 and 0.05 < shares[1] < 0.5


def test_a_rotation_given_the_wrong_way_round_is_questioned(sphere):
    n, mask = sphere
    R = random_rotation(3)
    error, said = run_integrate(to_world(n, R), mask, normal_rotation=R.T)
    assert "right way round" in (error or said) and "Blender's matrix_world is camera to " \
        "world: --camera-to-world" in (error or said)


@pytest.mark.parametrize("stored", ["x,y,-z", "opencv"])
def test_no_world_hint_where_a_z_flip_explains_it(sphere, stored):
    """A camera-frame map read without its frame: told the frame, not about world space."""
    n, mask = sphere
    error, _ = run_integrate(frames.from_facetlift(n, stored), mask)
    assert error is not None and "face away" in error and "world" not in error
    error, said = run_integrate(n, mask)  # (and nothing on the right map)
    assert error is None and "world" not in said
