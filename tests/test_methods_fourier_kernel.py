"""Frankot-Chellappa and the Gaussian-kernel method on analytic surfaces.

Errors are measured at the pixel centres after removing the mean (depth is defined up to a
constant) and, where a range is used, relative to the true depth range.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import facetlift
from facetlift.problem import normals_from_gradients, prepare


def centres(H, W, h, x0=0.0, y0=0.0):
    """x, y of the pixel centres (x right, y up; row 0 at the top, at y0 - h/2)."""
    r, c = np.mgrid[0:H, 0:W]
    return x0 + (c + 0.5) * h, y0 - (r + 0.5) * h


def saddle(N):
    """z = (x^2 - y^2) / 2 on [-1, 1]^2 sampled N x N: depth range 1, |grad z| <= 1."""
    h = 2.0 / N
    x, y = centres(N, N, h, -1.0, 1.0)
    return (x**2 - y**2) / 2, x, -y, h


def wavy(N):
    """A smooth non-periodic surface on [-1, 1]^2 (saddle-like plus a tilted bump)."""
    h = 2.0 / N
    x, y = centres(N, N, h, -1.0, 1.0)
    z = 0.3 * np.sin(2 * x) * np.cos(1.5 * y) + 0.2 * x * y
    p = 0.6 * np.cos(2 * x) * np.cos(1.5 * y) + 0.2 * y
    q = -0.45 * np.sin(2 * x) * np.sin(1.5 * y) + 0.2 * x
    return z, p, q, h


def err(surface, z, where=None):
    """Max and RMS of the height error over `where` (default: the surface mask), mean removed."""
    where = surface.mask if where is None else where
    e = (surface.height - z)[where]
    e = e - e.mean()
    return np.abs(e).max(), np.sqrt(np.mean(e**2))


# --------------------------------------------------------------------------------------------
# Frankot-Chellappa


def test_fc_periodic_surface_exact():
    # A trigonometric polynomial below Nyquist, periodic on a non-square grid: the spectral
    # derivative model of FC is exact for it, so the error is round-off, not O(h^2). The
    # y terms are not even in y, so a wrong sign of q (y is up) would show.
    H, W, h = 24, 32, 0.05
    Lx, Ly = W * h, H * h
    x, y = centres(H, W, h, 0.3, 0.7)
    kx, ky = 2 * np.pi / Lx, 2 * np.pi / Ly
    z = np.sin(kx * x + 0.3) * np.cos(2 * ky * y) + 0.5 * np.sin(ky * y + 1.1)
    p = kx * np.cos(kx * x + 0.3) * np.cos(2 * ky * y)
    q = -2 * ky * np.sin(kx * x + 0.3) * np.sin(2 * ky * y) + 0.5 * ky * np.cos(ky * y + 1.1)
    # slopes reach 13 (86 deg): keep them all (outlier_eps=0), the default would drop the
    # steepest as grazing
    s = facetlift.integrate(
        normals_from_gradients(p, q), method="frankot_chellappa", pixel_size=h, pad="none",
        outlier_eps=0.0,
    )
    assert err(s, z)[0] < 1e-12 * np.ptp(z) * 1e3  # ~1e-13: machine precision of the FFT
    # The mirror padding (default) breaks periodicity's exactness: kinks at the box edges.
    s2 = facetlift.integrate(normals_from_gradients(p, q), method="frankot_chellappa",
                             pixel_size=h, outlier_eps=0.0)
    assert err(s2, z)[0] > 1e-4


def test_fc_saddle_first_order_at_edges():
    # The saddle is not periodic; its even reflection is continuous but its slope jumps by
    # 2|p| <= 2 at the box edges. A spectral projection of a kinked function converges O(h)
    # next to the kink and O(h^2) away from it: at 64 x 64 (h = 1/32) we require a max error
    # below h/4 |grad z|_max (measured 0.18 h) and, on the central half, below h^2/2
    # (measured 0.29 h^2); halving h must roughly halve the max error.
    errs = []
    for N in (32, 64):
        z, p, q, h = saddle(N)
        s = facetlift.integrate(normals_from_gradients(p, q), method="frankot_chellappa",
                                pixel_size=h)
        errs.append(err(s, z)[0])
        if N == 64:
            inner = np.zeros_like(s.mask)
            inner[16:48, 16:48] = True
            assert errs[-1] < 0.25 * h * 1.0
            assert err(s, z, inner)[0] < 0.5 * h**2
    assert 1.8 < errs[0] / errs[1] < 2.2


def test_fc_mirror_padding_on_non_periodic_surface():
    # exp(x) sin(y + 0.3) on [0, 1] x [-1, 0]: far from periodic. Periodic FC sees a jump of
    # the surface at the wrap-around and fails; the mirror extension is continuous.
    N = 48
    h = 1.0 / N
    x, y = centres(N, N, h)
    z = np.exp(x) * np.sin(y + 0.3)
    n = normals_from_gradients(z, np.exp(x) * np.cos(y + 0.3))
    mirror = facetlift.integrate(n, method="frankot_chellappa", pixel_size=h)
    periodic = facetlift.integrate(n, method="frankot_chellappa", pixel_size=h, pad="none")
    rng_z = np.ptp(z)
    assert err(mirror, z)[0] < 0.01 * rng_z
    assert err(periodic, z)[0] > 0.2 * rng_z


def test_fc_mask_with_hole():
    # Annulus: FC works on the bounding box with the outside filled in. The fill is not
    # integrable, so errors appear near the mask boundary: a few percent of h |grad z| is
    # expected (measured max 0.0087 for a range ~0.9 with harmonic fill); a zero fill puts
    # a gradient jump on the boundary and is an order of magnitude worse.
    z, p, q, h = saddle(64)
    x, y = centres(64, 64, h, -1.0, 1.0)
    rad = np.hypot(x, y)
    mask = (rad < 0.95) & (rad > 0.3)
    n = normals_from_gradients(p, q)
    errors = {}
    for fill in ("harmonic", "nearest", "zero"):
        s = facetlift.integrate(n, mask, method="frankot_chellappa", pixel_size=h, fill=fill)
        assert np.isnan(s.depth[~mask]).all() and np.isfinite(s.depth[mask]).all()
        errors[fill] = err(s, z)[0]
        rr, cc = np.nonzero(mask)
        box = mask[rr.min() : rr.max() + 1, cc.min() : cc.max() + 1]
        assert s.info["filled"] == int((~box).sum()) > 0
    assert errors["harmonic"] < 0.02
    assert errors["nearest"] < 0.02
    assert errors["zero"] > 3 * errors["harmonic"]


def test_fc_fills_missing_samples_like_the_box():
    z, p, q, h = saddle(32)
    known = np.random.default_rng(3).random(z.shape) > 0.3
    n = normals_from_gradients(p, q)
    full = facetlift.integrate(n, method="frankot_chellappa", pixel_size=h)
    gaps = facetlift.integrate(n, known=known, method="frankot_chellappa", pixel_size=h)
    assert gaps.info["filled"] == int((~known).sum())
    # 30 % random gaps filled harmonically cost little against the full field
    assert err(gaps, z)[1] < 3 * err(full, z)[1] + 1e-3 * np.ptp(z)


def test_fc_bad_options():
    z, p, q, h = saddle(8)
    n = normals_from_gradients(p, q)
    with pytest.raises(ValueError, match="`pad` must be one of"):
        facetlift.integrate(n, method="frankot_chellappa", pad="reflect")
    with pytest.raises(ValueError, match="`fill` must be one of"):
        facetlift.integrate(n, method="frankot_chellappa", fill="linear")
    K = np.array([[10.0, 0, 4], [0, 10, 4], [0, 0, 1]])
    with pytest.raises(ValueError, match="'frankot_chellappa' does not support perspective"):
        facetlift.integrate(n, method="frankot_chellappa", K=K)


# --------------------------------------------------------------------------------------------
# Gaussian kernel


def test_kernel_saddle():
    # sigma = 2 pixels: the Gaussian's approximation error is negligible (exp(-8 pi^2)), so
    # the interior is exact to the regularisation and tiling (measured 4.9e-6 at 48 x 48);
    # at the box boundary the fit has data on one side only (measured 3.5e-4, ~0.01 h).
    z, p, q, h = saddle(48)
    s = facetlift.integrate(normals_from_gradients(p, q), method="kernel", pixel_size=h)
    inner = np.zeros_like(s.mask)
    inner[12:36, 12:36] = True
    assert err(s, z)[0] < 1e-3
    assert err(s, z, inner)[0] < 3e-5
    assert s.info["tiles"] == 9 and s.info["factorizations"] <= 9


def test_kernel_missing_samples():
    # 30 % of the samples missing at random: the kernel fit bridges one- and two-pixel gaps
    # with sigma = 2 (measured max 9.9e-4 of the range on this surface).
    z, p, q, h = wavy(48)
    known = np.random.default_rng(7).random(z.shape) > 0.3
    s = facetlift.integrate(normals_from_gradients(p, q), known=known, method="kernel",
                            pixel_size=h)
    assert np.isfinite(s.depth).all()
    assert err(s, z)[0] < 2e-3 * np.ptp(z)


def test_kernel_fills_missing_block_smoothly():
    # An 8 x 8 block without samples. A Gaussian fit flattens towards the middle of a gap
    # wider than about 2 sigma, so with the default sigma = 2 the error in the block is
    # larger than elsewhere (measured 1.5 % of the range; a flat fill at the rim's mean
    # height would be off by ~|grad z| * 4 h, 17 % of the range). With sigma = 3, of the
    # order of the gap as documented for sparse input, the block is filled almost exactly
    # (measured 2.4e-4 of the range) and without a kink at its rim: the discrete Laplacian
    # of the result stays within 10 % of the true surface's largest one (measured 5 %).
    z, p, q, h = wavy(48)
    known = np.ones(z.shape, dtype=bool)
    known[20:28, 14:22] = False
    n = normals_from_gradients(p, q)
    s2 = facetlift.integrate(n, known=known, method="kernel", pixel_size=h)
    assert err(s2, z, ~known)[0] < 0.02 * np.ptp(z)
    assert err(s2, z, known)[0] < 0.002 * np.ptp(z)
    s3 = facetlift.integrate(n, known=known, method="kernel", pixel_size=h, sigma=3)
    assert err(s3, z, ~known)[0] < 1e-3 * np.ptp(z)

    def lap(a):
        return a[:-2, 1:-1] + a[2:, 1:-1] + a[1:-1, :-2] + a[1:-1, 2:] - 4 * a[1:-1, 1:-1]

    d = (lap(s3.height) - lap(z))[18:28, 12:22]
    assert np.abs(d).max() < 0.1 * np.abs(lap(z)).max()


def test_kernel_tiles_agree_with_single_window_fit():
    # tile >= the image: one window, the exact kernel fit. Small tiles change the interior
    # by about the exact fit's own interior error (measured 9e-6 of the range), and the
    # boundary, where both fits are one-sided, by up to that error (measured 4e-4).
    z, p, q, h = wavy(40)
    n = normals_from_gradients(p, q)
    exact = facetlift.integrate(n, method="kernel", pixel_size=h, tile=40)
    assert exact.info["tiles"] == 1
    tiled = facetlift.integrate(n, method="kernel", pixel_size=h, tile=8)
    assert tiled.info["tiles"] == 25
    d = tiled.height - exact.height
    d = d - d.mean()
    assert np.abs(d[6:-6, 6:-6]).max() < 2e-5 * np.ptp(z)
    assert np.abs(d).max() < 1e-3 * np.ptp(z)


def test_kernel_mask_with_hole_and_two_components():
    # An annulus and a separate blob; a U-turn of the annulus enters some tiles twice, so
    # each tile piece needs its own constant. Each component is checked on its own
    # (measured 2.4e-4 and 1.4e-4 of the range).
    z, p, q, h = wavy(48)
    x, y = centres(48, 48, h, -1.0, 1.0)
    rad = np.hypot(x + 0.2, y)
    ring = (rad < 0.7) & (rad > 0.35)
    blob = np.hypot(x - 0.8, y - 0.75) < 0.15
    mask = ring | blob
    s = facetlift.integrate(normals_from_gradients(p, q), mask, method="kernel", pixel_size=h,
                            tile=8)
    for part in (ring, blob):
        assert err(s, z, part)[0] < 2e-3 * np.ptp(z)


def test_deterministic():
    z, p, q, h = wavy(32)
    known = np.random.default_rng(11).random(z.shape) > 0.3
    n = normals_from_gradients(p, q)
    a = facetlift.integrate(n, known=known, method="kernel", pixel_size=h)
    b = facetlift.integrate(n, known=known, method="kernel", pixel_size=h)
    np.testing.assert_array_equal(a.depth, b.depth)
    a = facetlift.integrate(n, method="frankot_chellappa", pixel_size=h)
    b = facetlift.integrate(n, method="frankot_chellappa", pixel_size=h)
    np.testing.assert_array_equal(a.depth, b.depth)


@pytest.mark.parametrize(
    "options, match",
    [
        ({"sigma": 0}, "`sigma` must be a number >= 0.75; got 0"),
        ({"sigma": float("nan")}, "`sigma` must be a number >= 0.75; got nan"),
        ({"sigma": "wide"}, "`sigma` must be a number >= 0.75; got 'wide'"),
        ({"reg": -1e-3}, "`reg` must be a number >= 0; got -0.001"),
        ({"tile": 3}, "`tile` must be an integer >= 4"),
        ({"tile": 8.5}, "`tile` must be an integer >= 4"),
        ({"margin": -1}, "`margin` must be an integer >= 0 or None"),
        ({"margin": True}, "`margin` must be an integer >= 0 or None"),
    ],
)
def test_kernel_bad_options(options, match):
    z, p, q, h = saddle(8)
    with pytest.raises(ValueError, match=match):
        facetlift.integrate(normals_from_gradients(p, q), method="kernel", **options)


def test_kernel_refuses_perspective_and_no_samples():
    z, p, q, h = saddle(8)
    n = normals_from_gradients(p, q)
    K = np.array([[10.0, 0, 4], [0, 10, 4], [0, 0, 1]])
    with pytest.raises(ValueError, match="'kernel' does not support perspective"):
        facetlift.integrate(n, method="kernel", K=K)
    with pytest.raises(ValueError, match="no usable normal"):
        prepare(n, np.ones((8, 8), bool), known=np.zeros((8, 8), bool))


def test_frankot_chellappa_integrates_separate_components_apart():
    """A plane beside a sphere: each in its own box, as each alone (the one box around both
    carried the sphere's slopes into the plane: rms 0.62 of a 18-unit range)."""
    H, W = 64, 96
    r, c = np.indices((H, W)).astype(float)
    d2 = (r - 32) ** 2 + (c - 28) ** 2
    sph = d2 < 19.0**2
    pl = (r > 8) & (r < 56) & (c > 58) & (c < 90)
    x, y = c + 0.5, -(r + 0.5)
    root = np.sqrt(np.maximum(400.0 - d2, 1e-9))
    p = np.where(sph, -(x - 28.5) / root, 0.3)
    q = np.where(sph, -(y + 32.5) / root, 0.2)
    n = facetlift.normals_from_gradients(p, q)
    both = facetlift.integrate(n, sph | pl, method="frankot_chellappa")
    for part in (sph, pl):
        alone = facetlift.integrate(n, part, method="frankot_chellappa")
        np.testing.assert_allclose(both.depth[part], alone.depth[part], atol=1e-9)
    assert both.info["boxes"] == 2


@pytest.mark.parametrize("method, kw", [("frankot_chellappa", {}), ("kernel", {}),
                                        ("poisson", {}), ("dgp", {"discontinuities": True})])
def test_a_component_without_any_normal_is_flat_and_warned(method, kw):
    """As dgp does: FC and kernel made up a 12- and 4-unit shape there, the graph methods
    returned it flat in silence."""
    from facetlift import synthetic

    gt = synthetic.analytic("pyramid", 48)
    n = gt.normals.copy()
    mask = np.ones((48, 48), bool)
    mask[:, 22:26] = False
    n[:, 26:] = np.nan
    with pytest.warns(UserWarning) as record:
        s = facetlift.integrate(n, mask, method=method, **kw)
    said = [str(w.message) for w in record if "have no usable normal" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("1 connected component(s)")  # (once)
    assert np.ptp(s.depth[:, 26:]) == 0.0


def test_frankot_chellappa_shares_one_box_where_component_boxes_overlap():
    r, c = np.indices((96, 96))
    mask = ((r + c) % 8) < 3  # diagonal stripes: every component's box is nearly the image
    n = np.dstack([np.zeros((96, 96, 2)), np.ones((96, 96))])
    s = facetlift.integrate(n, mask, method="frankot_chellappa")
    assert s.info["boxes"] == 1 and np.nanmax(np.abs(s.depth)) < 1e-12


def test_kernel_keeps_close_components_apart():
    """A flat part 3 pixels from a pyramid stays flat (its fit windows took the pyramid's
    samples: 0.086 high)."""
    from facetlift import synthetic

    gt = synthetic.analytic("pyramid", 64)
    n = gt.normals.copy()
    mask = np.ones((64, 64), bool)
    mask[:, 30:33] = False
    n[:, 33:] = [0.0, 0.0, 1.0]
    s = facetlift.integrate(n, mask, method="kernel")
    assert np.ptp(s.depth[:, 33:]) < 1e-12 and s.info["boxes"] == 2


def test_a_map_that_does_not_tile_is_named_under_periodic_integration():
    """A texture artist's audit: pad='none' on a crop that does not tile came out 28 % RMS
    off with no word. A tileable map, also with a constant slope bias (which the periodic
    solve removes), is silent; its crop is warned about."""
    import warnings

    import facetlift

    y, x = np.mgrid[0:128, 0:128] + 0.5
    h = 3 * np.sin(2 * np.pi * x / 32) * np.sin(2 * np.pi * y / 32)
    gr, gx = np.gradient(h)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for bias in (0.0, np.tan(np.radians(2))):
            n = facetlift.normals_from_gradients(gx + bias, -gr)
            facetlift.integrate(n, method="frankot_chellappa", pad="none")
    n = facetlift.normals_from_gradients(gx[:100, :100], -gr[:100, :100])
    with pytest.warns(UserWarning, match=r"pad='none' integrates the map as periodic, but it "
                      "does not tile"):
        facetlift.integrate(n, method="frankot_chellappa", pad="none")


def test_noisy_tileable_maps_are_not_told_they_do_not_tile():
    """A review: slope noise made each row's climb a random walk, and tileable noisy maps
    were told they did not tile (then worse with the advice's pad='mirror'); so was a
    low-relief 8-bit map. The climbs' white part is left out, near-flat maps not judged."""
    import warnings

    import facetlift

    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:256, 0:256].astype(float)
    f = 2 * np.pi * 8 / 256
    P = 0.3 * f * np.cos(f * x + f * y)
    n = facetlift.normals_from_gradients(P + rng.normal(0, 0.02, P.shape),
                                         -(P + rng.normal(0, 0.02, P.shape)))
    low = facetlift.normals_from_gradients(0.015 * np.cos(f * x), -0.015 * np.sin(f * y))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        warnings.simplefilter("ignore", facetlift.FrameWarning)  # (8-bit decoded)
        facetlift.integrate(n, method="frankot_chellappa", pad="none")
        facetlift.integrate(np.round((low + 1) / 2 * 255).astype(np.uint8),
                            method="frankot_chellappa", pad="none")


def test_kernel_refuses_a_width_too_small_to_fit():
    """Below 3/4 of a pixel the fit fails without a sign (an audit: a 64^2 paraboloid 0.63 of its
    range off at sigma 0.5, mean deviation 33 deg): refused, naming the option."""
    z, p, q, h = saddle(32)
    n = normals_from_gradients(p, q)
    with pytest.raises(ValueError, match="sigma"):
        facetlift.integrate(n, method="kernel", pixel_size=h, sigma=0.5)
    s = facetlift.integrate(n, method="kernel", pixel_size=h, sigma=0.75)
    assert err(s, z)[0] < 0.05 * np.ptp(z)


def test_kernel_info_reports_the_tile_it_used():
    """fit_tiles widens a tile below two blend widths; info says the tile used (an audit)."""
    z, p, q, h = saddle(32)
    n = normals_from_gradients(p, q)
    s = facetlift.integrate(n, method="kernel", pixel_size=h, sigma=3.0, tile=4)
    assert s.info["tile"] == 6


def test_kernel_gram_matrix_within_the_planned_bytes():
    """The Gram matrix of a fit window is built in place (56 n^2 bytes with its tables), which
    memory._kernel_tiles plans; its temporaries and LAPACK's copy once took about 80 n^2, so
    a job passed max_memory and went over it (an audit)."""
    import tracemalloc

    from facetlift.methods.kernel import _factor

    known = np.ones((24, 24), bool)
    known[5:9, 7:12] = False
    n = int(known.sum())
    tracemalloc.start()
    try:
        _factor(known, 3.0, 1e-6)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= 56 * n * n * 1.05


def test_periodic_fc_says_it_drops_a_tilt():
    """pad='none' drops the mean slope (a periodic height has none): a tilted plane came back
    flat with no word (an audit); now a warning says so, and a tileable map gets none."""
    N = 48
    h = 1.0 / N
    p = np.full((N, N), 0.3)
    q = np.full((N, N), -0.2)
    with pytest.warns(UserWarning, match="no mean slope"):
        facetlift.integrate(normals_from_gradients(p, q), method="frankot_chellappa",
                            pixel_size=h, pad="none")
    x, y = centres(N, N, h)
    # (a small tilt under a fine texture: 0.44 of the range off, not warned, a review)
    p = 0.1 + 0.3 * np.cos(8 * np.pi * x) * np.cos(8 * np.pi * y)
    q = -0.3 * np.sin(8 * np.pi * x) * np.sin(8 * np.pi * y)
    with pytest.warns(UserWarning, match="no mean slope"):
        facetlift.integrate(normals_from_gradients(p, q), method="frankot_chellappa",
                            pixel_size=h, pad="none")
    p = 2 * np.pi * np.cos(2 * np.pi * x) * np.cos(2 * np.pi * y) * 0.1
    q = -2 * np.pi * np.sin(2 * np.pi * x) * np.sin(2 * np.pi * y) * 0.1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        facetlift.integrate(normals_from_gradients(p, q), method="frankot_chellappa",
                            pixel_size=h, pad="none")


def test_a_long_kernel_fit_is_said_before_it_starts(monkeypatch):
    """A review: sigma=12 at 512^2 (about 1.9e14 flops of factorizations, hours) ran past a
    minute with no word, within memory. The fits' work is estimated from their sizes once
    they are grouped, and a long one warned about before any is factorized."""
    from facetlift.methods import kernel

    g = facetlift.synthetic.analytic("sphere", 40)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        facetlift.integrate(g.normals, g.mask, method="kernel")
    assert not [w for w in rec if "local fits" in str(w.message)]
    monkeypatch.setattr(kernel, "KERNEL_WARN_SECONDS", 0.0)
    with pytest.warns(UserWarning, match=r"kernel: \d+ local fits of up to [\d,]+ unknowns "
                      r"\(sigma 2, tile 16, margin 4\).*a smaller sigma"):
        facetlift.integrate(g.normals, g.mask, method="kernel")
    # once for the whole run, over every piece of the mask (per piece, four pieces each under
    # the limit went unsaid, the next review)
    calls = []
    monkeypatch.setattr(kernel, "_time_check", lambda sizes, *a: calls.append(list(sizes)))
    pieces = np.zeros((64, 64), bool)
    pieces[2:28, 2:28] = pieces[36:62, 2:28] = pieces[2:28, 36:62] = pieces[36:62, 36:62] = True
    n = np.where(pieces[..., None], facetlift.synthetic.analytic("sphere", 64).normals, np.nan)
    s = facetlift.integrate(n, pieces, method="kernel")
    assert len(calls) == 1 and len(calls[0]) == s.info["factorizations"] > 4
