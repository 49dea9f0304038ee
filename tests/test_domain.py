"""facetlift.domain.Domain: facets, vertices, components, operators and scatters."""

from __future__ import annotations

import numpy as np
import pytest

from facetlift.domain import Domain

# an irregular mask: a hole, a separate 2-pixel piece, a piece touching at a corner only
MASK = np.array(
    [
        [1, 1, 1, 0, 0, 0],
        [1, 0, 1, 0, 1, 1],
        [1, 1, 1, 0, 0, 0],
        [0, 0, 0, 1, 0, 0],
        [0, 0, 0, 0, 1, 1],
    ],
    dtype=bool,
)


@pytest.fixture
def domain():
    return Domain.from_mask(MASK)


def test_pixels_are_row_major(domain):
    r, c = domain.pixels
    assert domain.n_facets == MASK.sum() == r.size
    assert np.array_equal(r * MASK.shape[1] + c, np.flatnonzero(MASK))
    assert domain.shape == MASK.shape


def test_mask_is_a_readonly_copy():
    m = MASK.copy()
    d = Domain.from_mask(m)
    m[0, 0] = False
    assert d.mask[0, 0]
    with pytest.raises(ValueError):
        d.mask[0, 0] = False


def test_vertex_mask_and_index(domain):
    H, W = MASK.shape
    vm = domain.vertex_mask
    assert vm.shape == (H + 1, W + 1)
    expected = np.zeros((H + 1, W + 1), bool)
    for r, c in zip(*np.nonzero(MASK), strict=True):
        expected[r : r + 2, c : c + 2] = True
    assert np.array_equal(vm, expected)
    vi = domain.vertex_index
    assert np.array_equal(vi[vm], np.arange(vm.sum()))  # row-major numbering
    assert np.all(vi[~vm] == -1)
    assert domain.n_vertices == vm.sum()
    # the hole's centre pixel (1, 1) still has all four corners (they belong to its neighbours)
    assert vm[1:3, 1:3].all()


def test_corner_order_follows_the_conventions(domain):
    """Facet (r, c) has corners (r,c), (r,c+1), (r+1,c+1), (r+1,c) in that order."""
    vi = domain.vertex_index
    for k, (r, c) in enumerate(zip(*domain.pixels, strict=True)):
        assert list(domain.corners[k]) == [vi[r, c], vi[r, c + 1], vi[r + 1, c + 1],
                                           vi[r + 1, c]]
    assert domain.corners.shape == (domain.n_facets, 4)
    assert domain.corners.min() >= 0


def test_components_are_8_connected(domain):
    # the ring + the corner-touching pixel (3, 3) + the pair (4, 4:6) are one component
    # through shared vertices; the pair (1, 4:6) is separate
    assert domain.n_components == 2
    labels = domain.labels
    assert labels[0, 0] == labels[3, 3] == labels[4, 5]
    assert labels[1, 4] == labels[1, 5] != labels[0, 0]
    assert np.all(labels[~MASK] == 0) and set(np.unique(labels[MASK])) == {1, 2}
    assert sorted(domain.component_sizes) == [2, 11]
    r, c = domain.pixels
    assert np.array_equal(domain.facet_component, labels[r, c] - 1)
    # each vertex's component is that of every facet it touches
    for k in range(domain.n_facets):
        assert np.all(domain.vertex_component[domain.corners[k]] == domain.facet_component[k])


def test_4_connected_pieces_touching_diagonally_are_one_component():
    m = np.zeros((4, 4), bool)
    m[:2, :2] = True
    m[2:, 2:] = True
    assert Domain.from_mask(m).n_components == 1
    m2 = np.zeros((4, 5), bool)
    m2[:2, :2] = True
    m2[2:, 3:] = True
    assert Domain.from_mask(m2).n_components == 2


def test_gather_picks_corners(domain):
    rng = np.random.default_rng(0)
    z = rng.normal(size=domain.n_vertices)
    C = domain.gather
    assert C.shape == (4 * domain.n_facets, domain.n_vertices)
    np.testing.assert_array_equal(C @ z, z[domain.corners].ravel())


def test_facet_operator_and_centres(domain):
    rng = np.random.default_rng(1)
    z = rng.normal(size=domain.n_vertices)
    w = np.array([0.5, -1.0, 2.0, 0.25])
    A = domain.facet_operator(w)
    assert A.shape == (domain.n_facets, domain.n_vertices)
    np.testing.assert_allclose(A @ z, z[domain.corners] @ w, rtol=1e-14)
    # per-facet weights
    W4 = rng.normal(size=(domain.n_facets, 4))
    np.testing.assert_allclose(domain.facet_operator(W4) @ z,
                               np.einsum("ij,ij->i", z[domain.corners], W4), rtol=1e-14)
    np.testing.assert_allclose(domain.facet_centres(z),
                               domain.facet_operator(np.full(4, 0.25)) @ z, rtol=1e-14)


def test_facet_operator_of_a_plane(domain):
    """Corner differences of z = a x + b y give the exact slopes (conventions: vertex (i, j)
    at x = j h, y = -i h)."""
    h, a, b = 0.5, 1.7, -0.3
    i, j = np.indices(domain.vertex_mask.shape)
    z = (a * j * h + b * (-i * h))[domain.vertex_mask]
    ex = domain.facet_operator(np.array([-1, 1, 1, -1]) / (2 * h))
    ey = domain.facet_operator(np.array([1, 1, -1, -1]) / (2 * h))
    np.testing.assert_allclose(ex @ z, a, rtol=1e-12)
    np.testing.assert_allclose(ey @ z, b, rtol=1e-12)


def test_image_round_trips(domain):
    rng = np.random.default_rng(2)
    f = rng.normal(size=domain.n_facets)
    img = domain.to_image(f)
    assert img.shape == MASK.shape
    assert np.isnan(img[~MASK]).all()
    np.testing.assert_array_equal(img[domain.pixels], f)
    np.testing.assert_array_equal(img[MASK], f)
    assert np.all(domain.to_image(f, fill=-7.0)[~MASK] == -7.0)
    v = rng.normal(size=domain.n_vertices)
    vimg = domain.to_vertex_image(v)
    assert vimg.shape == (MASK.shape[0] + 1, MASK.shape[1] + 1)
    assert np.isnan(vimg[~domain.vertex_mask]).all()
    np.testing.assert_array_equal(vimg[domain.vertex_mask], v)
    assert domain.to_vertex_image(v, fill=0.0)[~domain.vertex_mask].sum() == 0
    # integer values come back as float images (NaN needs a float)
    assert domain.to_image(np.arange(domain.n_facets)).dtype == float


def test_full_rectangle():
    d = Domain.from_mask(np.ones((3, 4), bool))
    assert d.n_facets == 12 and d.n_vertices == 20 and d.n_components == 1
    assert d.vertex_mask.all()
    assert np.array_equal(d.corners[0], [0, 1, 6, 5])
    assert np.array_equal(d.corners[-1], [13, 14, 19, 18])
