"""Input checking (facetlift.problem.prepare), gradients <-> normals, clean_mask."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift.problem import Problem, prepare


def up(shape=(6, 7)):
    """Normals all facing the viewer."""
    n = np.zeros((*shape, 3))
    n[..., 2] = 1.0
    return n


def random_normals(shape, seed):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(*shape, 3))
    n[..., 2] = np.abs(n[..., 2]) + 0.2
    return n


# ------------------------------------------------------------------------------------------
# a good problem


def test_prepare_normalises_and_orders_facets_row_major():
    n = random_normals((5, 6), 0) * 3.0
    mask = np.ones((5, 6), bool)
    mask[0, 0] = mask[4, 5] = False
    prob = facetlift.prepare(n, mask, pixel_size=0.5)
    assert isinstance(prob, Problem) and not prob.perspective
    r, c = prob.domain.pixels
    assert np.array_equal(r * 6 + c, np.flatnonzero(mask))
    np.testing.assert_allclose(np.linalg.norm(prob.normals, axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(prob.normals, n[r, c] / np.linalg.norm(n[r, c], axis=1)[:, None])
    assert prob.known.all() and prob.pixel_size == 0.5 and prob.K is None
    p, q = prob.slopes
    np.testing.assert_allclose(p, -n[r, c, 0] / n[r, c, 2])
    np.testing.assert_allclose(q, -n[r, c, 1] / n[r, c, 2])
    img = prob.normal_image()
    assert img.shape == (5, 6, 3) and np.isnan(img[0, 0]).all()
    np.testing.assert_allclose(img[mask], prob.normals)


def test_prepare_default_mask_is_finite_nonzero_normals():
    n = up((5, 5))
    n[0, :] = np.nan
    n[4, 4] = 0.0
    prob = facetlift.prepare(n)
    expected = np.ones((5, 5), bool)
    expected[0, :] = False
    expected[4, 4] = False
    assert np.array_equal(prob.domain.mask, expected)
    assert prob.known.all()


def test_prepare_missing_samples_and_known():
    n = up((5, 5))
    n[1, 1] = np.nan
    known = np.ones((5, 5), bool)
    known[3, 2] = False
    prob = facetlift.prepare(n, np.ones((5, 5), bool), known=known)
    assert prob.known.sum() == 23
    k = prob.domain.to_image(prob.known.astype(float))
    assert k[1, 1] == 0 and k[3, 2] == 0
    assert np.isnan(prob.normals[~prob.known]).all()
    assert np.isnan(prob.slopes[0][~prob.known]).all()
    # integer and float 0/1 masks are accepted like booleans
    prob2 = facetlift.prepare(n, np.ones((5, 5), int), known=known.astype(float))
    assert np.array_equal(prob2.known, prob.known)


@pytest.mark.parametrize("backfacing", ["missing", "outlier"])
def test_backfacing_normals_become_missing_samples(backfacing):
    n = up((4, 5))
    n[2, 3] = [0.3, 0.0, -1.0]
    n[1, 1] = [1.0, 0.0, 0.0]  # n_z == 0: edge-on, grazing (not facing away)
    with pytest.warns(UserWarning, match=r"2 normal\(s\) inside the mask cannot be used .*"
                      r"1 back-facing, 1 grazing.*first at \(row 1, col 1\)"):
        prob = facetlift.prepare(n, backfacing=backfacing)
    # (a back-facing normal is dropped, a grazing one kept without a target: the paper's rule)
    assert (~prob.known).sum() == 1 and (~prob.usable).sum() == 2
    assert prob.counts["back-facing"] == 1 and prob.counts["grazing"] == 1
    assert prob.counts["first_unusable"] == [1, 1]
    k = prob.domain.to_image(prob.known.astype(float))
    u = prob.domain.to_image(prob.usable.astype(float))
    assert k[2, 3] == 0 and k[1, 1] == 1 and u[1, 1] == 0


def test_bad_normals_inside_the_mask_become_missing_samples_counted_once():
    n = up((6, 7))
    n[0, 1] = [np.inf, 0.0, 1.0]
    n[2, 2] = 0.0
    n[3, 3] = [0.0, 0.999, 0.01]  # grazing: n_z below cos 85 deg
    n[4, 4] = np.nan  # a deliberately missing sample: no warning for it
    n[5, 6] = [0.0, 1e200, 1e200]  # huge but a fine normal
    with pytest.warns(UserWarning) as record:
        prob = facetlift.prepare(n, np.ones((6, 7), bool))
    assert len(record) == 1
    msg = str(record[0].message)
    assert "3 normal(s)" in msg and "1 non-finite" in msg and "1 zero-length" in msg
    assert "1 grazing" in msg and "first at (row 0, col 1)" in msg
    c = prob.counts
    assert (c["non-finite"], c["zero-length"], c["grazing"], c["missing"]) == (1, 1, 1, 1)
    assert c["usable"] == 42 - 4 and prob.usable.sum() == 38
    assert prob.known.sum() == 39  # the grazing normal is known, but not usable
    np.testing.assert_allclose(prob.normals[-1], [0, 2**-0.5, 2**-0.5])


def test_outside_the_mask_anything_goes():
    n = np.full((5, 6, 3), np.inf)
    n[1:4, 1:5] = [0.0, 0.0, 1.0]
    mask = np.zeros((5, 6), bool)
    mask[1:4, 1:5] = True
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prob = facetlift.prepare(n, mask)
    assert prob.usable.all() and prob.counts["usable"] == 12


@pytest.mark.parametrize("K", [
    [[500.0, 0.0, 3.0], [0.0, 400.0, 2.5], [0.0, 0.0, 1.0]],
    np.array([[500.0, 0.2, 3.0], [0.0, 500.0, 2.5], [0.0, 0.0, 1.0]], dtype=np.float32),
])
def test_prepare_accepts_K(K):
    prob = facetlift.prepare(up(), K=K)
    assert prob.perspective and prob.K.shape == (3, 3) and prob.K.dtype == float
    np.testing.assert_allclose(prob.K, np.asarray(K, float))


def test_prepare_does_not_modify_inputs():
    n = random_normals((4, 4), 1)
    n[0, 0] = np.nan
    mask = np.ones((4, 4), bool)
    n0, mask0 = n.copy(), mask.copy()
    facetlift.prepare(n, mask)
    assert np.array_equal(n, n0, equal_nan=True) and np.array_equal(mask, mask0)


# ------------------------------------------------------------------------------------------
# errors


def _with(n, idx, value):
    n = n.copy()
    n[idx] = value
    return n


@pytest.mark.parametrize(
    "normals, match",
    [
        (np.ones((6, 7)), r"`normals` must have shape \(H, W, 3\); got \(6, 7\)"),
        (np.ones((6, 7, 2)), r"`normals` must have shape \(H, W, 3\); got \(6, 7, 2\)"),
        (np.ones((6, 7, 3, 1)), r"`normals` must have shape \(H, W, 3\)"),
        (np.ones((0, 7, 3)), "`normals` must have at least one pixel"),
        (np.full((2, 2, 3), "a"), "`normals` must be a real numeric array; got dtype <U1"),
        (np.full((2, 2, 3), 1.0, dtype=object), "`normals` must be a real numeric array"),
        (np.full((2, 2, 3), 1 + 0j), "`normals` must be a real numeric array; got dtype complex"),
        ([[[0, 0, 1], [0, 0]]], "`normals` could not be read as an array"),
        (np.full((3, 3, 3), np.nan), "`normals` has no finite, non-zero normal"),
        # (a file name said "got dtype <U16", an embedding audit)
        ("normal_map.png", r"`normals` must be a real numeric array, not a file name "
         r"\('normal_map.png'\): read the file first \(facetlift.io.read_normals"),
        (Path("n.exr"), r"not a file name \('n.exr'\)"),
    ],
)
def test_bad_normals(normals, match):
    with pytest.raises(ValueError, match=match):
        facetlift.prepare(normals)


@pytest.mark.parametrize("bad", [[0.2, 0.1, -1.0], [1.0, 0.0, -1e-9]])
def test_backfacing_error_on_request(bad):
    with pytest.raises(ValueError, match=r"back-facing normals \(facing away from the camera\) "
                       r"inside the mask at 1 pixel\(s\), first at \(row 4, col 1\).*"
                       r"backfacing='missing'"):
        facetlift.prepare(_with(up(), (4, 1), bad), backfacing="error")


def test_no_usable_normal_is_refused():
    """An error alone: it came after a warning about the same normals (a library user's
    check); with every usable normal at confidence 0 the error names `confidence`."""
    import warnings

    n = np.zeros((3, 3, 3))
    n[..., 0] = 1.0  # every normal edge-on
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # (the counts in words, not a dict, a user's check)
        with pytest.raises(ValueError, match=r"no usable normal.*: 9 pixel\(s\): 9 grazing; "
                           r"grazing: view cosine < 0.08716, outlier_eps / --outlier-eps"):
            facetlift.prepare(n, np.ones((3, 3), bool))
        with pytest.raises(ValueError, match=r"`confidence` is 0 or NaN at every usable normal"
                           r".*\(\d+ pixel\(s\): \d+ zero confidence\)$"):
            facetlift.prepare(up(), np.ones(up().shape[:2], bool), confidence=0)


def test_zero_length_normal_inside_mask():
    n = _with(up(), (3, 4), 0.0)
    with pytest.warns(UserWarning, match=r"1 zero-length.*first at \(row 3, col 4\)"):
        assert (~facetlift.prepare(n, np.ones((6, 7), bool)).known).sum() == 1
    # ... and silent where `known` says the sample is missing
    known = np.ones((6, 7), bool)
    known[3, 4] = False
    assert (~facetlift.prepare(n, np.ones((6, 7), bool), known=known).known).sum() == 1


def test_a_vanishingly_short_normal_is_zero_length_but_a_scaled_map_is_not():
    """(1e-12, 0, 0) has no direction, only rounding: it was renormalised to (1, 0, 0), an
    edge-on normal taken as usable in perspective; it is a missing sample now. The rule is
    relative to the map's median length, so a map scaled as a whole keeps every normal."""
    n = up()
    n[3, 4] = [1e-12, 0.0, 0.0]
    with pytest.warns(UserWarning, match=r"1 zero-length.*first at \(row 3, col 4\)"):
        p = facetlift.prepare(n, np.ones((6, 7), bool))
    assert p.counts["zero-length"] == 1 and (~p.known).sum() == 1
    scaled = facetlift.prepare(up() * 1e-9, np.ones((6, 7), bool))
    assert scaled.counts["zero-length"] == 0 and scaled.known.all()
    # huge normals, some of whose squared lengths overflow (those are rescaled to about 1)
    rng = np.random.default_rng(3)
    huge = up() * rng.uniform(0.98, 1.02, (6, 7, 1)) * 1.32e154
    p = facetlift.prepare(huge, np.ones((6, 7), bool))
    assert p.counts["zero-length"] == 0 and p.known.all()


@pytest.mark.parametrize(
    "mask, match",
    [
        (np.zeros((6, 7), bool), "`mask` is empty"),
        (np.ones((7, 6), bool),
         r"`mask` must have shape \(6, 7\) to match `normals`; got \(7, 6\)"),
        (np.ones((6, 7, 1), bool), r"`mask` must have shape \(6, 7\)"),
        (np.full((6, 7), "x"), "`mask` must be a boolean or numeric array; got dtype <U1"),
        (np.full((6, 7), None), "`mask` must be a boolean or numeric array; got dtype object"),
        (_with(np.ones((6, 7)), (1, 1), np.nan), "`mask` contains NaN or inf"),
    ],
)
def test_bad_mask(mask, match):
    with pytest.raises(ValueError, match=match):
        facetlift.prepare(up(), mask)


def test_bad_known():
    with pytest.raises(ValueError, match=r"`known` must have shape \(6, 7\)"):
        facetlift.prepare(up(), known=np.ones((6, 6), bool))
    with pytest.raises(ValueError, match="`known` contains NaN or inf"):
        facetlift.prepare(up(), known=_with(np.ones((6, 7)), (0, 0), np.inf))


def test_one_pixel_components_and_clean_mask():
    mask = np.zeros((8, 9), bool)
    mask[1:4, 1:5] = True
    mask[6, 7] = True  # isolated
    mask[0, 8] = True  # isolated (corner)
    mask[6, 1:3] = True  # two pixels: fine
    # a mask's stray pixels are left out with a warning (a few pixels never refuse the job)
    with pytest.warns(UserWarning, match=r"`mask` has 2 one-pixel component\(s\) \(first at "
                      r"row 0, col 8\).*left out \(NaN in the output; facetlift.clean_mask"):
        prob = facetlift.prepare(up((8, 9)), mask)
    assert prob.domain.n_components == 2 and not prob.domain.mask[6, 7]
    assert not prob.domain.mask[0, 8] and prob.domain.mask.sum() == 14
    with pytest.warns(UserWarning, match="one-pixel component"):
        surface = facetlift.integrate(up((8, 9)), mask, method="poisson")
    assert np.isnan(surface.depth[6, 7]) and np.isfinite(surface.depth[1:4, 1:5]).all()
    lone = np.zeros((5, 5), bool)
    lone[0, 0] = lone[3, 3] = True
    with pytest.raises(ValueError, match="`mask`: every pixel of it is isolated"):
        facetlift.prepare(up((5, 5)), lone)
    cleaned = facetlift.clean_mask(mask)
    expected = mask.copy()
    expected[6, 7] = expected[0, 8] = False
    assert cleaned.dtype == bool and np.array_equal(cleaned, expected)
    assert facetlift.prepare(up((8, 9)), cleaned).domain.n_components == 2
    # a pixel touching another only at a corner is not isolated (8-connectivity)
    diag = np.zeros((4, 4), bool)
    diag[1, 1] = diag[2, 2] = True
    assert np.array_equal(facetlift.clean_mask(diag), diag)
    block = np.zeros_like(mask)
    block[1:4, 1:5] = True
    assert np.array_equal(facetlift.clean_mask(mask, min_size=3), block)


def test_one_pixel_domain_from_default_mask():
    n = np.full((5, 5, 3), np.nan)
    n[2, 2] = [0, 0, 1]
    with pytest.raises(ValueError, match="every finite, non-zero normal is an isolated pixel"):
        facetlift.prepare(n)
    # beside a larger part, a lone pixel of the normals' own mask is left out, with a warning
    # (a map with 30 % NaN normals and no mask was refused for its one-pixel islands)
    n[0:3, 0:3] = [0, 0, 1]
    n[2, 2] = np.nan
    n[4, 4] = [0, 0, 1]
    with pytest.warns(UserWarning, match=r"1 isolated pixel\(s\) .* left out \(first at row 4"):
        prob = facetlift.prepare(n)
    assert prob.domain.mask.sum() == 8 and not prob.domain.mask[4, 4]
    with pytest.warns(UserWarning, match="one-pixel component"):  # (a mask given: said too)
        prob = facetlift.prepare(n, np.isfinite(n[..., 0]))
    assert prob.domain.mask.sum() == 8 and not prob.domain.mask[4, 4]


def test_pixels_without_a_normal_enclosed_by_the_object_are_reported_once():
    """An audit: 39 black (0, 0, 0) pixels of an 8-bit map, NaN once decoded, became holes in
    the depth and the mesh without a word (the domain without a mask is the valid normals).
    Small holes surrounded by valid normals are counted and named in the one unusable-normals
    warning; a background, and a large enclosed hole (a ring's), stay silent."""
    from facetlift.problem import HOLE_PIXELS, UnusableNormalsWarning

    n = np.full((30, 40, 3), np.nan)
    n[3:27, 4:36] = [0.0, 0.0, 1.0]  # the object; NaN background around it
    n[10, 10] = n[20, 30] = np.nan  # two one-pixel holes
    n[5:8, 20:23] = 0.0  # and a 3 x 3 one of zero vectors
    with pytest.warns(UnusableNormalsWarning, match=r"^11 pixel\(s\) enclosed by the object "
                      r"hold no normal .* black \(0, 0, 0\)\) and were left out as holes.*first "
                      r"at \(row 5, col 20\).*give one \(--mask, mask=\)") as rec:
        prob = facetlift.prepare(n)
    assert len(rec) == 1 and prob.counts["holes"] == 11
    # with other unusable normals: the same, one warning
    n[15, 15] = [0.0, 0.0, -1.0]
    with pytest.warns(UnusableNormalsWarning, match=r"1 back-facing.*Also: 11 pixel\(s\) "
                      r"enclosed") as rec:
        facetlift.prepare(n)
    assert len(rec) == 1
    n[15, 15] = [0.0, 0.0, 1.0]
    # a hole larger than HOLE_PIXELS (a ring's), a notch open to the background, a mask given:
    # silent (with a mask, NaN inside it is a missing sample, filled)
    n[5:8, 20:23] = [0.0, 0.0, 1.0]
    n[10, 10] = n[20, 30] = [0.0, 0.0, 1.0]
    side = int(np.ceil(np.sqrt(HOLE_PIXELS + 1)))
    n[5:5 + side, 5:5 + side] = np.nan
    n[20:27, 20:22] = np.nan  # (reaches the object's edge: a notch)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prob = facetlift.prepare(n)
        assert "holes" not in prob.counts
        assert prob.counts["larger_holes"] == side**2  # (counted apart: info says it too)
        box = np.zeros((30, 40), bool)
        box[3:27, 4:36] = True
        n[16, 30] = np.nan
        assert facetlift.prepare(n, box).counts["missing"] == side**2 + 7 * 2 + 1


@pytest.mark.parametrize(
    "pixel_size, match",
    [
        (0, "`pixel_size` must be a positive finite number; got 0"),
        (-1, "`pixel_size` must be a positive finite number; got -1"),
        (float("nan"), "`pixel_size` must be a positive finite number; got nan"),
        (float("inf"), "`pixel_size` must be a positive finite number; got inf"),
        ("a", "`pixel_size` must be a positive number; got 'a'"),
        (None, "`pixel_size` must be a positive number; got None"),
        ([1.0, 2.0], "`pixel_size` must be a positive number"),
        (1e100, r"`pixel_size` must lie in \[1e-12, 1e\+12\]"),
        (1e-100, r"`pixel_size` must lie in"),
    ],
)
def test_bad_pixel_size(pixel_size, match):
    with pytest.raises(ValueError, match=match):
        facetlift.prepare(up(), pixel_size=pixel_size)


@pytest.mark.parametrize(
    "K, match",
    [
        (np.eye(2), r"`K` must be a 3x3 intrinsics matrix, its nine numbers row by row, or "
                    r"four numbers \(fx, fy, cx, cy\); got shape \(2, 2\)"),
        (np.ones(8), r"`K` must be a 3x3 intrinsics matrix.*; got shape \(8,\)"),
        (np.ones(9), r"`K` must be upper-triangular"),  # (nine: the matrix row by row)
        ([500, -500, 3, 3], r"`K` must have positive focal lengths"),
        ([[500, 0, np.nan], [0, 500, 3], [0, 0, 1]], "`K` contains NaN or inf"),
        ([[np.inf, 0, 3], [0, 500, 3], [0, 0, 1]], "`K` contains NaN or inf"),
        ([[-500, 0, 3], [0, 500, 3], [0, 0, 1]], r"`K` must have positive focal lengths"),
        ([[500, 0, 3], [0, 0, 3], [0, 0, 1]], r"`K` must have positive focal lengths"),
        ([[500, 0, 3], [0, 500, 3], [0, 0, 2]], r"`K` must be upper-triangular with last row"),
        ([[500, 0, 3], [1, 500, 3], [0, 0, 1]], r"`K` must be upper-triangular"),
        ([["a", 0, 3], [0, 500, 3], [0, 0, 1]], "`K` must be a real numeric array"),
        ([[1e-300, 0, 3], [0, 1e-300, 3], [0, 0, 1]], r"focal lengths .* must lie in"),
        ([[500, 0, 3], [0, 1e300, 3], [0, 0, 1]], r"focal lengths .* must lie in"),
    ],
)
def test_bad_K(K, match):
    with pytest.raises(ValueError, match=match):
        facetlift.prepare(up(), K=K)


def test_K_as_four_numbers_is_the_matrix():
    """The command line's K files take fx fy cx cy; the API refused the same four numbers."""
    K = np.array([[520.0, 0, 3.5], [0, 510.0, 2.5], [0, 0, 1]])
    a = facetlift.integrate(up(), K=[520, 510, 3.5, 2.5], method="poisson").depth
    np.testing.assert_array_equal(a, facetlift.integrate(up(), K=K, method="poisson").depth)


def test_bad_backfacing_option():
    with pytest.raises(ValueError, match=r"`backfacing` must be one of \('missing', 'error'\); "
                       "got 'skip'"):
        facetlift.prepare(up(), backfacing="skip")


# ------------------------------------------------------------------------------------------
# gradients <-> normals


def test_gradients_normals_round_trip():
    rng = np.random.default_rng(2)
    p, q = rng.normal(0, 3, size=(2, 7, 9))
    p[1, 2] = np.nan
    n = facetlift.normals_from_gradients(p, q)
    assert n.shape == (7, 9, 3)
    ok = np.isfinite(p)
    np.testing.assert_allclose(np.linalg.norm(n[ok], axis=-1), 1.0, rtol=1e-14)
    assert np.all(n[ok][:, 2] > 0)
    assert np.isnan(n[1, 2]).all()
    p2, q2 = facetlift.gradients_from_normals(n)
    np.testing.assert_allclose(p2[ok], p[ok], rtol=1e-12)
    np.testing.assert_allclose(q2[ok], q[ok], rtol=1e-12)
    assert np.isnan(p2[1, 2]) and np.isnan(q2[1, 2])
    # and the other way, for unnormalised normals too
    m = random_normals((4, 5), 3) * 7
    np.testing.assert_allclose(
        facetlift.normals_from_gradients(*facetlift.gradients_from_normals(m)),
        m / np.linalg.norm(m, axis=-1, keepdims=True), rtol=1e-12,
    )


def test_gradient_sign_convention():
    """A height rising to the right (p > 0) and up (q > 0) tilts the normal left and down."""
    n = facetlift.normals_from_gradients([[1.0]], [[2.0]])
    np.testing.assert_allclose(n[0, 0], np.array([-1.0, -2.0, 1.0]) / np.sqrt(6))
    n_int = facetlift.normals_from_gradients(np.ones((2, 2), int), np.zeros((2, 2), bool))
    np.testing.assert_allclose(n_int[0, 0], np.array([-1.0, 0.0, 1.0]) / np.sqrt(2))


def test_infinite_slopes_are_edge_on_normals_counted_as_grazing():
    """A few infinite slopes (a vertical facet) never refuse the job: their normal is the
    limit, edge-on, which the grazing rule turns into a counted missing sample."""
    p, q = np.zeros((5, 6)), np.zeros((5, 6))
    p[1, 2], q[3, 4] = np.inf, -np.inf
    n = facetlift.normals_from_gradients(p, q)
    assert np.allclose(n[1, 2], [-1, 0, 0]) and np.allclose(n[3, 4], [0, 1, 0])
    with pytest.warns(UserWarning, match=r"2 normal\(s\).*2 grazing.*first at \(row 1, col 2\)"):
        prob = facetlift.prepare(n, np.ones((5, 6), bool))
    assert prob.counts["grazing"] == 2 and prob.usable.sum() == 28


@pytest.mark.parametrize(
    "p, q, match",
    [
        (np.ones(5), np.ones(5), r"`p` must be a 2-D \(H, W\) array; got shape \(5,\)"),
        (np.ones((3, 4)), np.ones((4, 3)),
         r"`q` must have the shape of `p` \(3, 4\); got \(4, 3\)"),
        (np.full((3, 4), "1"), np.ones((3, 4)), "`p` must be a real numeric array"),
        (np.ones((3, 4)), np.ones((3, 4), complex), "`q` must be a real numeric array"),
    ],
)
def test_normals_from_gradients_errors(p, q, match):
    with pytest.raises(ValueError, match=match):
        facetlift.normals_from_gradients(p, q)


@pytest.mark.parametrize(
    "normals, match",
    [
        (np.ones((3, 4)), r"`normals` must have shape \(H, W, 3\); got \(3, 4\)"),
        (np.ones((3, 4, 2)), r"`normals` must have shape \(H, W, 3\); got \(3, 4, 2\)"),
        (np.full((3, 4, 3), "a"), "`normals` must be a real numeric array"),
    ],
)
def test_gradients_from_normals_errors(normals, match):
    with pytest.raises(ValueError, match=match):
        facetlift.gradients_from_normals(normals)


def test_boolean_normals_or_prior_are_refused_as_a_mask_by_mistake():
    with pytest.raises(ValueError, match=r"`normals` is a boolean array \(a mask\?\)"):
        facetlift.prepare(np.ones((4, 5, 3), bool))
    with pytest.raises(ValueError, match=r"`prior` is a boolean array \(a mask\?\)"):
        facetlift.prepare(up((4, 5)), prior=np.ones((4, 5), bool))
    with pytest.raises(ValueError, match=r"`path` must be a path"):
        facetlift.io.read_normals(None)


def test_huge_finite_slopes_do_not_overflow():
    p, q = np.zeros((5, 6)), np.zeros((5, 6))
    p[2, 2] = 1e300
    with np.errstate(over="raise"):
        n = facetlift.normals_from_gradients(p, q)
    assert np.isfinite(n).all() and np.allclose(np.linalg.norm(n, axis=-1), 1.0)
    assert n[2, 2, 0] == pytest.approx(-1.0)


def test_many_normals_facing_away_ask_about_the_frame():
    """A map turned into another frame (here 60 deg about x, as a world-frame export): the
    unusable-normal warning asks about the frame; a few quantised ones do not."""
    r, c = np.indices((30, 30))
    n = facetlift.normals_from_gradients(0.8 * np.cos(c / 4), 0.8 * np.sin(r / 5))
    a = np.radians(60)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    with pytest.warns(UserWarning, match=r"face away from the camera.* another frame"):
        facetlift.prepare(n @ rot.T)
    few = n.copy()
    few[3, 4] = [0.1, 0.0, -1.0]
    with pytest.warns(UserWarning) as record:
        facetlift.prepare(few)
    assert not any("another frame" in str(w.message) for w in record)


def test_a_mask_of_another_view_is_questioned_and_its_transpose_named():
    """An audit: the BiNI human map with its mask transposed ran with 48 % of the mask
    without a normal (the map's background, decoded to NaN), and the only word was the
    depth-jump hint."""
    import warnings

    r, c = np.mgrid[0:40, 0:40] + 0.5
    x, y = (c - 14) / 12, -(r - 22) / 16
    inside = x**2 + y**2 < 1
    n = np.full((40, 40, 3), np.nan)
    n[inside] = np.c_[0.3 * x[inside], 0.2 * y[inside], np.ones(inside.sum())]
    with pytest.warns(UserWarning, match=r"`mask`: \d+% of its pixels have no normal .* The "
                      r"mask transposed, 0% of its pixels would have none"):
        prepare(n, inside.T)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare(n, inside)
        gappy = n.copy()
        gappy[np.random.default_rng(0).random((40, 40)) < 0.3] = np.nan  # (random gaps)
        prepare(gappy, inside)
        finite = n.copy()  # (a map with a finite background: its NaNs are holes, a review)
        finite[~inside] = [0.0, 0.0, 1.0]
        finite[inside & (np.random.default_rng(1).random((40, 40)) < 0.3)] = np.nan
        prepare(finite, inside[:, ::-1])
    assert not [w for w in caught if "`mask`:" in str(w.message)]


@pytest.mark.parametrize("shape, advice", [
    ((1, 20, 30, 3), r"a batch of one \(1, H, W, 3\); normals\[0\] gives"),
    ((1, 3, 20, 30), r"a batch of one, channel-first .*moveaxis\(normals\[0\], 0, -1\)"),
    ((3, 20, 30), r"channel-first \(3, H, W\); numpy.moveaxis\(normals, 0, -1\)"),
    ((20, 30, 4), r"RGB and alpha\? give normals\[\.\.\., :3\] and mask=normals"),
])
def test_a_network_tensor_shape_gets_the_indexing_that_makes_a_map(shape, advice):
    """An audit: (1, H, W, 3) and (1, 3, H, W), a network's batch of one, got only 'must
    have shape (H, W, 3)'."""
    with pytest.raises(ValueError, match=advice):
        facetlift.integrate(np.ones(shape))


def test_masked_arrays_mask_their_entries():
    """An audit: np.asarray dropped a numpy masked array's mask, so masked normals were
    integrated as valid (depth off by 8 on a range of 20) and, without a mask, the domain
    took the masked pixels in. Masked normals are missing samples; a masked prior's entries
    unknown; a masked mask's entries outside."""
    gt = facetlift.synthetic.analytic("sphere", 48)
    n = np.nan_to_num(gt.normals, nan=0.0)
    n[~gt.mask] = [0.0, 0.0, 1.0]  # (finite outside the object)
    bad = np.zeros(gt.mask.shape, bool)
    bad[20:24, 20:24] = True
    n[bad] = [0.9, 0.0, 0.1]
    ma = np.ma.masked_array(n, mask=np.repeat(bad[..., None], 3, axis=-1))
    a = facetlift.integrate(ma, gt.mask)
    b = facetlift.integrate(np.where(bad[..., None], np.nan, n), gt.mask)
    assert a.info["input"]["missing"] == 16
    np.testing.assert_array_equal(a.depth, b.depth)
    outside = np.ma.masked_array(n, mask=np.repeat(~gt.mask[..., None], 3, axis=-1))
    assert facetlift.integrate(outside).mask.sum() == gt.mask.sum()
    m = np.ma.masked_array(np.ones(gt.mask.shape, bool), mask=~gt.mask)
    assert facetlift.integrate(n, m).mask.sum() == gt.mask.sum()


def test_a_soft_float_mask_is_named():
    """An audit: a blurred 0/1 mask (a soft matte) grew the domain by 66 % in silence, where
    read_mask warns about soft files; a 0/1 float mask stays silent."""
    import warnings

    from scipy import ndimage

    gt = facetlift.synthetic.analytic("sphere", 48)
    soft = ndimage.gaussian_filter(gt.mask.astype(float), 2)
    with pytest.warns(UserWarning, match=r"`mask` holds \d+ values between 0 and 1 .* "
                      r"threshold it first \(e\.g\. mask > 0\.5\)"):
        facetlift.integrate(gt.normals, soft)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(np.nan_to_num(gt.normals), gt.mask.astype(float))


def test_entry_points_name_a_wrong_argument_kind():
    """An audit: solve(array) raised "no attribute 'counts'", clean_mask of a 3-D mask
    "too many values to unpack", of min_size '2' numpy's UFuncTypeError (and -5 passed),
    K_from_fov of an image printed the whole array in its message."""
    from facetlift.camera import K_from_fov

    with pytest.raises(ValueError, match=r"solve\(\) takes a Problem .* got ndarray .*"
                       r"facetlift.integrate"):
        facetlift.solve(np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match=r"`mask` must be an \(H, W\) array; got shape"):
        facetlift.clean_mask(np.ones((3, 3, 3)))
    for bad in ("2", -5, float("nan"), True):
        with pytest.raises(ValueError, match="`min_size` must be a number of pixels >= 0"):
            facetlift.clean_mask(np.ones((3, 3)), bad)
    m = np.zeros((6, 6), bool)
    m[0, 0] = m[3:5, 3:5] = True  # (a float size, e.g. a share of the mask, and 0 work)
    assert facetlift.clean_mask(m, 0).sum() == 5 and facetlift.clean_mask(m, 2.5).sum() == 4
    with pytest.raises(ValueError, match=r"got ndarray of shape \(100, 100, 3\)$"):
        K_from_fov(np.zeros((100, 100, 3)), 60)


def _disk_on_flat_fill(shape=(40, 50)):
    """A hemisphere's normals on a background filled with (0, 0, 1), and its disk mask."""
    H, W = shape
    r, c = np.indices(shape)
    x, y = (c - W / 2 + 0.5) / 15.0, (H / 2 - r - 0.5) / 15.0
    disk = x**2 + y**2 < 0.9
    n = np.zeros(shape + (3,))
    n[..., 2] = 1.0
    zz = np.sqrt(np.clip(1 - x**2 - y**2, 1e-6, None))
    n[disk] = np.stack([x, y, zz], -1)[disk]
    return n, disk


def test_an_inverted_mask_is_questioned():
    """A mask with the object black and the background white (a fresh user's): where the
    background is a flat fill the run integrated it without a word; where it is NaN the error
    only counted missing normals. Both now ask whether the mask is inverted; the right mask,
    and a flat object on a flat background, stay silent."""
    n, disk = _disk_on_flat_fill()
    with pytest.warns(UserWarning, match=r"`mask`: 100% of its pixels hold one and the same "
                      r"normal .*is the mask inverted"):
        prepare(n, ~disk)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(n, disk)
        flat = np.zeros_like(n)
        flat[..., 2] = 1.0
        prepare(flat, disk)  # (a flat object: the outside is no different)
    holed = n.copy()
    holed[~disk] = np.nan
    with pytest.raises(ValueError, match=r"no usable normal inside the mask .*outside the "
                       r"mask \d[\d,]* of \d[\d,]* pixels hold a normal: is the mask inverted"):
        prepare(holed, ~disk)
    # ... and with one ring of the object's pixels in it, it ran without a word (a review)
    H, W = disk.shape
    r, c = np.indices((H, W))
    smaller = ((c - W / 2 + 0.5) ** 2 + (H / 2 - r - 0.5) ** 2) / 225.0 < 0.75
    with pytest.warns(UserWarning, match=r"`mask`: \d+% of its pixels have no normal while "
                      r"100% of those outside it hold varied ones \(an object.s\): is the "
                      r"mask inverted"):
        prepare(holed, ~smaller)
    # a flat object (a box's face) masked inside a scene of varied normals: its mask does not
    # reach the image's border, as an inverted one would (a review's false alarm)
    box = np.zeros_like(disk)
    box[15:25, 5:12] = True
    edge = np.zeros_like(disk)
    scene = facetlift.normals_from_gradients(0.5 * np.sin(c / 3.0), 0.5 * np.cos(r / 4.0))
    scene[box] = [0.0, 0.0, 1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(scene, box)
    edge[:, :7] = True  # (small at the image's border: still silent)
    scene[edge] = [0.0, 0.0, 1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(scene, edge)
    edge = np.zeros_like(disk)  # (a large one: what it leaves out reaches the border too)
    edge[:, 0:20] = True
    scene[edge] = [0.0, 0.0, 1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(scene, edge)
    # a right mask with many holes over a zero or flat fill: no object outside it (a review)
    holes = n.copy()
    holes[disk & (np.random.default_rng(0).random(disk.shape) < 0.6)] = np.nan
    for fill in ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]):
        filled = holes.copy()
        filled[~disk] = fill
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the holes' own warnings)
            warnings.simplefilter("error", UserWarning)
            try:
                prepare(filled, disk)
            except UserWarning as w:
                assert "inverted" not in str(w), w


def test_a_focal_length_in_mm_is_questioned():
    """fx = fy = 4.2 (a phone's focal length in mm) for a 240-pixel-wide image: a field of view
    of 176 deg, 40 % of the normals then dropped as back-facing and a warning about BGR order
    (a fresh user's check); named now. A wide-angle K (90 deg across the width) stays
    silent."""
    n = np.zeros((180, 240, 3))
    n[..., 2] = 1.0
    K = np.array([[4.2, 0, 119.5], [0, 4.2, 89.5], [0, 0, 1]])
    with pytest.warns(UserWarning, match=r"`K`: the focal lengths fx 4.2, fy 4.2 give a field "
                      r"of view of 176 deg .*in mm"):
        prepare(n, K=K)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prepare(n, K=np.array([[120.0, 0, 119.5], [0, 120.0, 89.5], [0, 0, 1]]))  # (90 deg)
