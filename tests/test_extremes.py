"""Extreme weights and option values: refused by name or handled, never lost to rounding
(an audit of degenerate inputs)."""

import numpy as np
import pytest

import facetlift

H, W = 20, 24


@pytest.fixture(scope="module")
def plane():
    r, c = np.mgrid[0:H, 0:W].astype(float)
    n = np.dstack([np.full((H, W), -0.3), np.full((H, W), 0.2), np.ones((H, W))])
    return n / np.linalg.norm(n, axis=-1, keepdims=True), -(0.3 * c + 0.2 * r)


@pytest.mark.parametrize("kw", [
    dict(method="poisson", prior_weight=1e-16),
    dict(prior_weight=1e-16),
    dict(discontinuities=True, confidence=np.full((H, W), 1e16)),
    dict(confidence=np.full((H, W), 1e12)),
])
def test_a_prior_too_weak_to_resolve_is_refused(plane, kw):
    """At 1e-16 of the normals' weight the prior's offset was lost to rounding (0.96 off on
    poisson), or the solver failed without naming anything."""
    n, exact = plane
    with pytest.raises(ValueError, match=r"`prior_weight`: the prior's largest weight .* below "
                                         r"1e-10 of the normals' weight"):
        facetlift.integrate(n, prior=exact + 5, **kw)


def test_a_weak_prior_within_the_range_is_met(plane):
    n, exact = plane
    s = facetlift.integrate(n, prior=exact + 5, prior_weight=1e-9)
    assert np.abs(s.depth - exact - 5).max() < 1e-5


def test_confidences_below_the_resolvable_range_are_raised(plane):
    """A confidence of 1e-12 beside ones of 1 flattened the half it weighed (46 % of the
    depth range off); raised to 1e-8 of the largest, with a warning, the plane is exact."""
    n, exact = plane
    conf = np.ones((H, W))
    conf[:, :12] = 1e-12
    with pytest.warns(UserWarning, match=r"240 normal\(s\) have a confidence below 1e-08"):
        s = facetlift.integrate(n, confidence=conf)
    assert np.ptp(s.depth - exact) < 1e-5


def test_an_empty_point_list_is_named(plane):
    n, _ = plane
    with pytest.raises(ValueError, match=r"list of points \(rows, cols, depths\) is empty"):
        facetlift.integrate(n, prior=([], [], []))


def test_discontinuities_false_is_every_routes_no_op(plane):
    n, exact = plane
    s = facetlift.integrate(n, solver="iterative", discontinuities=False)
    assert np.ptp(s.depth - exact) < 1e-3


@pytest.mark.parametrize("kw, match", [
    (dict(method="diffusion", contrast=1e200), r"`contrast` must be a number > 0 and <= 1e\+100"),
    (dict(flat_weight=1e12), r"`flat_weight` must be a number > 0 and <= 1;"),
    (dict(method="regularization", lam=1e300), r"`lam` must be a number >= 0 and <= 1e\+08"),
])
def test_absurd_option_values_are_refused_by_name(plane, kw, match):
    """They ended in an OverflowError or a solver error naming no option."""
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(plane[0], **kw)
