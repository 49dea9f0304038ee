"""The facet-system preconditioner: box spectral solve plus an exact solve on weak vertices."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from facetlift.domain import Domain
from facetlift.linalg import cg
from facetlift.linalg.facet import CLUSTER, FacetPreconditioner, thin, weak_vertices
from facetlift.linalg.spectral import BoxPreconditioner
from facetlift.methods.dgp.fixed_point import SLOPE_BLOCK, TWIST_BLOCK
from facetlift.operators.stencil import facet_form, pin_components


def _disk(s):
    r, c = np.mgrid[0:s, 0:s]
    return (r - s / 2 + 0.5) ** 2 + (c - s / 2 + 0.5) ** 2 < (0.45 * s) ** 2


def _rim_system(s, width=1, seed=0):
    """A disk whose outer `width` pixels have no target (a grazing rim), random targets."""
    import scipy.ndimage as ndi

    mask = _disk(s)
    inner = ndi.binary_erosion(mask, iterations=width)
    d = Domain.from_mask(mask)
    strong = inner[d.pixels]
    wk = np.where(strong, 1.0, 1e-9)
    K = facet_form(d, [(wk, SLOPE_BLOCK), (1.0, TWIST_BLOCK)])
    rng = np.random.default_rng(seed)
    b = K @ rng.standard_normal(d.n_vertices)
    return d, strong, K, b


def test_weak_vertices_are_those_only_weak_facets_touch():
    mask = np.ones((4, 5), bool)
    d = Domain.from_mask(mask)
    strong = np.ones(d.n_facets, bool)
    assert not weak_vertices(d, strong).any()
    strong[int(d.to_image(np.arange(d.n_facets), fill=-1)[0, 0])] = False  # corner facet
    weak = d.to_vertex_image(weak_vertices(d, strong).astype(float), fill=0)
    assert weak.sum() == 1 and weak[0, 0] == 1  # only the outer corner vertex
    assert not weak_vertices(d, np.ones(d.n_facets, bool)).any()


def test_large_weak_clusters_give_all_their_vertices():
    s = 64
    d = Domain.from_mask(np.ones((s, s), bool))
    img = np.zeros((s, s), bool)
    img[:, :5] = True  # a 320-facet band: a cluster
    assert img.sum() >= CLUSTER
    strong = ~img[d.pixels]
    weak = d.to_vertex_image(weak_vertices(d, strong).astype(float), fill=0) > 0
    assert weak[:, :6].all() and not weak[:, 6:].any()
    img[:] = False
    img[1::4, 1::4] = True  # scattered single facets: no vertex is theirs alone
    assert not weak_vertices(d, ~img[d.pixels]).any()


def test_preconditioner_is_symmetric_positive_semidefinite():
    d, strong, K, _ = _rim_system(14)
    M = FacetPreconditioner(d, K, strong, dtype=np.float64)
    assert M.n_weak > 0
    P = np.column_stack([M(e) for e in np.eye(d.n_vertices)])
    scale = np.abs(P).max()  # ~1 / flat_weight on the rim's near-null mode: symmetric up to
    assert np.abs(P - P.T).max() <= 1e-6 * scale  # rounding amplified by that
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() > -1e-6 * scale


@pytest.mark.parametrize("width", [1, 2])
def test_grazing_rim_needs_few_iterations_and_matches_a_factorization(width):
    d, strong, K, b = _rim_system(96, width)
    x, info = cg(K, b, FacetPreconditioner(d, K, strong), rtol=1e-11, flexible=True)
    assert info.converged and info.iterations <= 40
    y = spla.spsolve(pin_components(d, K).tocsc(), b)
    diff = (x - x.mean()) - (y - y.mean())
    assert np.abs(diff).max() <= 1e-6 * np.ptp(y)
    # the box alone needs many more iterations on the same system
    _, box = cg(K, b, BoxPreconditioner(d), rtol=1e-11, maxiter=4 * info.iterations)
    assert box.iterations > 2 * info.iterations


def test_exact_on_full_rectangle_without_weak_facets():
    d = Domain.from_mask(np.ones((9, 12), bool))
    K = facet_form(d, [(1.0, SLOPE_BLOCK), (1.0, TWIST_BLOCK)])
    M = FacetPreconditioner(d, K, np.ones(d.n_facets, bool))
    assert M.exact and M.n_weak == 0
    b = K @ np.random.default_rng(1).standard_normal(d.n_vertices)
    assert np.abs(K @ M(b) - b).max() < 1e-10


def test_refresh_keeps_the_box_and_takes_the_new_weak_set():
    d, strong, K, b = _rim_system(40)
    M = FacetPreconditioner(d, K, np.ones(d.n_facets, bool))
    box = M.box
    assert M.n_weak == 0
    M.refresh(K, strong)
    assert M.box is box and M.n_weak > 0
    x, info = cg(K, b, M, rtol=1e-10, flexible=True)
    assert info.converged and info.iterations <= 40


def test_float32_box_converges_like_float64_with_flexible_cg():
    d, strong, K, b = _rim_system(64)
    its = {}
    for dt in (np.float32, np.float64):
        x, info = cg(K, b, FacetPreconditioner(d, K, strong, dtype=dt), rtol=1e-10,
                     flexible=True)
        assert info.converged
        its[dt] = info.iterations
    assert its[np.float32] <= its[np.float64] + 3


def _spiral(s):
    r, c = np.mgrid[0:s, 0:s]
    x, y = c - s / 2 + 0.5, r - s / 2 + 0.5
    rad, ang = np.hypot(x, y), np.arctan2(y, x)
    mask = ((rad - 16 * ang / (2 * np.pi)) % 16 < 4) & (rad < 0.48 * s) & (rad > 8)
    d = Domain.from_mask(mask)
    K = facet_form(d, [(1.0, SLOPE_BLOCK), (1.0, TWIST_BLOCK)])
    b = K @ np.random.default_rng(5).standard_normal(d.n_vertices)
    return d, np.ones(d.n_facets, bool), K, b


def test_thin_domain_takes_multigrid_and_converges():
    """A spiral 4 pixels wide: the box's fictitious material glues neighbouring arms, so
    multigrid is chosen up front (thin()); a fat domain keeps the box."""
    from facetlift.linalg.facet import solve

    d, strong, K, b = _spiral(256)
    pre = FacetPreconditioner(d, K, strong)
    assert thin(d) and pre.coarse == "amg"
    x, info = solve(K, b, pre, rtol=1e-10)
    assert info.converged and info.iterations <= 40
    assert np.linalg.norm(K @ x - b) <= 1e-9 * np.linalg.norm(b)
    d2, strong2, K2, b2 = _rim_system(64)
    pre2 = FacetPreconditioner(d2, K2, strong2)
    assert not thin(d2)
    _, info2 = solve(K2, b2, pre2, rtol=1e-10)
    assert info2.converged and pre2.coarse == "box"


def test_a_box_that_would_need_hundreds_of_iterations_is_replaced_by_measurement(monkeypatch):
    from facetlift.linalg import facet
    from facetlift.linalg.facet import BOX_LIMIT, solve

    d, strong, K, b = _spiral(512)
    # where a factorization is predicted to be faster it is taken (the thin spiral factorizes
    # cheaply) ...
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = solve(K, b, pre, rtol=1e-10)
    assert info.converged and pre.direct is not None and info.iterations == facet.PROBE
    # ... else the box is replaced by multigrid
    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 1e6)
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = solve(K, b, pre, rtol=1e-10)
    assert info.converged and pre.coarse == "amg" and info.iterations <= BOX_LIMIT + 40


def _many_disks_with_gaps(s=160, seed=3):
    """Small disks (radius 6 every 16 pixels) with 30 % of the facets without a target: the
    box needs ~100 iterations there, a factorization is cheap (issue 13)."""
    r, c = np.mgrid[0:s, 0:s]
    mask = ((r % 16 - 7.5) ** 2 + (c % 16 - 7.5) ** 2) < 36
    d = Domain.from_mask(mask)
    rng = np.random.default_rng(seed)
    strong = rng.random(d.n_facets) >= 0.3
    K = facet_form(d, [(np.where(strong, 1.0, 1e-9), SLOPE_BLOCK), (1.0, TWIST_BLOCK)])
    b = K @ rng.standard_normal(d.n_vertices)
    return d, strong, K, b


def test_a_slow_box_is_replaced_by_a_factorization_where_that_is_predicted_faster(monkeypatch):
    """After the probe, CG's predicted remaining time is compared with the factorization's
    model (FACTOR_PER_UNKNOWN, FACTOR_PER_WORK): a model that says "free" factorizes (pinned
    per component, kept for the next solve with the same K), one that says "costly" does not;
    both solve the system."""
    from facetlift.linalg import facet

    d, strong, K, b = _many_disks_with_gaps()
    monkeypatch.setattr(facet, "SCATTERED", 2.0)  # (no factorization before the probe)
    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 1e6)  # "costly": CG goes on
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x_cg, info_cg = facet.solve(K, b, pre, rtol=1e-10)
    assert info_cg.converged and pre.direct is None and info_cg.iterations > facet.PROBE

    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 0.0)
    monkeypatch.setattr(facet, "FACTOR_PER_WORK", 0.0)
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.converged and info.iterations == facet.PROBE and pre.direct is not None
    assert info.relative_residual < 1e-10
    # the same up to each component's constant (CG and the pins fix it differently)
    comp = d.vertex_component
    diff = x - x_cg
    diff -= (np.bincount(comp, diff) / np.bincount(comp))[comp]
    assert np.abs(diff).max() < 1e-6 * np.abs(x_cg).max()
    kept = pre.direct[1]
    x2, info2 = facet.solve(K, 2 * b, pre, rtol=1e-10)  # the same K: no iteration, same factor
    assert info2.iterations == 0 and pre.direct[1] is kept and np.allclose(x2, 2 * x)
    pre.refresh(K.copy(), strong)  # a new matrix: the factor is dropped
    assert pre.direct is None

    monkeypatch.undo()  # the model as it is decides by a model, not a clock: the same route
    monkeypatch.setattr(facet, "SCATTERED", 2.0)
    runs = []
    for _ in range(2):
        pre = FacetPreconditioner(d, K, strong, coarse="box")
        runs.append((facet.solve(K, b, pre, rtol=1e-10)[0], pre.direct is None))
    assert runs[0][1] == runs[1][1] and np.array_equal(runs[0][0], runs[1][0])


def test_the_route_reports_the_factorization_and_matches_the_pinned_direct_solve(monkeypatch):
    """Through facetlift.integrate: the smooth DGP route says "pcg-facet+superlu" and its
    surface is the factorized route's (backend="superlu")."""
    import facetlift
    from facetlift.linalg import facet

    r, c = np.mgrid[0:96, 0:96]
    mask = ((r % 16 - 7.5) ** 2 + (c % 16 - 7.5) ** 2) < 36
    rng = np.random.default_rng(5)
    n = np.dstack([0.3 * np.sin(c / 9.0), 0.2 * np.cos(r / 7.0), np.ones_like(r, float)])
    n[rng.random(mask.shape) < 0.3] = np.nan
    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 0.0)
    monkeypatch.setattr(facet, "FACTOR_PER_WORK", 0.0)
    monkeypatch.setattr(facet, "PROBE", 3)  # (so that the probe does not already converge)
    s = facetlift.integrate(n, mask)
    ref = facetlift.integrate(n, mask, backend="superlu")
    assert s.info["backend"] == "pcg-facet+superlu"
    assert np.nanmax(np.abs(s.depth - ref.depth)) < 1e-8


def test_no_switch_when_cg_was_asked_for_and_cg_goes_on_when_the_factorization_fails(
        monkeypatch):
    import facetlift
    from facetlift.errors import SolverError
    from facetlift.linalg import direct, facet

    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 0.0)
    monkeypatch.setattr(facet, "FACTOR_PER_WORK", 0.0)
    monkeypatch.setattr(facet, "PROBE", 3)
    r, c = np.mgrid[0:64, 0:64]
    mask = ((r % 16 - 7.5) ** 2 + (c % 16 - 7.5) ** 2) < 36
    n = np.dstack([0.3 * np.sin(c / 9.0), 0.2 * np.cos(r / 7.0), np.ones_like(r, float)])
    n[np.random.default_rng(2).random(mask.shape) < 0.3] = np.nan
    assert facetlift.integrate(n, mask, backend="pcg").info["backend"] == "pcg-facet"

    real = direct.superlu

    def broken(K, grid=None):  # (the whole system's; the local block's factorizes)
        if K.shape[0] == d.n_vertices:
            raise SolverError("SuperLU factorization failed: singular")
        return real(K, grid)

    d, strong, K, b = _many_disks_with_gaps()
    monkeypatch.setattr(direct, "superlu", broken)
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.converged and pre.direct is None and pre.direct_failed
    assert info.iterations > facet.PROBE
    assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)


def test_scattered_gaps_factorize_before_the_probe_where_the_model_says_it_is_cheap(
        monkeypatch):
    """30 % of the facets without a target, scattered: CG would need about twice its usual
    iterations, so a factorization the model prices below FIRST_ITERATIONS box iterations is
    taken before any iteration (and the local block is never factorized); priced above, or
    with fewer scattered gaps, or where the caller asked for CG, the probe runs as before."""
    from facetlift.linalg import facet

    d, strong, K, b = _many_disks_with_gaps()
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    assert pre.scattered > facet.SCATTERED and pre.n_weak > 0
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.converged and info.iterations == 0 and pre.direct is not None
    assert info.relative_residual < 1e-10 and pre._lu is None
    ref_pre = FacetPreconditioner(d, K, strong, coarse="box")
    ref_pre.may_factorize = False  # (CG, as asked: no factorization at all)
    x_cg, info_cg = facet.solve(K, b, ref_pre, rtol=1e-10)
    assert ref_pre.direct is None and info_cg.iterations > facet.PROBE
    comp = d.vertex_component
    diff = x - x_cg
    diff -= (np.bincount(comp, diff) / np.bincount(comp))[comp]
    assert np.abs(diff).max() < 1e-6 * np.abs(x_cg).max()

    monkeypatch.setattr(facet, "FIRST_ITERATIONS", 1e-3)  # priced above: the probe first
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.iterations >= facet.PROBE
    monkeypatch.undo()
    monkeypatch.setattr(facet, "SCATTERED", 0.5)  # fewer scattered gaps than the rule's
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.iterations >= facet.PROBE


def test_many_components_factorize_group_by_group_and_the_cap_counts_a_component(
        monkeypatch):
    """Components do not couple: where the whole system has more unknowns than FACTOR_CAP but
    each component fewer, it is still factorized (4096^2 many small disks with 30 % missing
    normals: 98 s by CG, 35 s so), group by group of whole components (BLOCK_UNKNOWNS), with
    the solution of one factorization of the whole; a component above the cap is not."""
    from facetlift.linalg import direct, facet
    from facetlift.linalg.direct import superlu
    from facetlift.memory import factorization_bytes

    d, strong, K, b = _many_disks_with_gaps()
    sizes = np.bincount(d.vertex_component)
    assert sizes.size == 100 and sizes.max() < 200
    # the memory model counts each component's own fill
    assert factorization_bytes(d.n_vertices, sizes) < 0.6 * factorization_bytes(d.n_vertices)
    monkeypatch.setattr(facet, "FACTOR_CAP", 1000)  # below the whole, above a component
    monkeypatch.setattr(facet, "BLOCK_UNKNOWNS", 1500)  # 10-11 groups of whole components
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.converged and info.iterations == 0 and pre.direct is not None
    pinned = pin_components(d, K)
    whole = superlu(pinned, d.vertices).solve(b)
    assert np.abs(x - whole).max() < 1e-8 * np.abs(whole).max()
    groups = []  # (the groups: whole components, about BLOCK_UNKNOWNS unknowns each)
    monkeypatch.setattr(direct, "superlu", lambda A, grid: groups.append(A.shape[0])
                        or superlu(A, grid))
    facet._by_blocks(pinned, d)
    assert sum(groups) == d.n_vertices and len(groups) >= d.n_vertices // 1500
    assert max(groups) < 1500 + sizes.max()
    # the memory check counts the components' own fill: a limit between the grouped and the
    # whole system's modelled bytes still factorizes, one below both does not
    from facetlift import memory

    grouped, whole_bytes = (factorization_bytes(d.n_vertices, sizes),
                            factorization_bytes(d.n_vertices))
    monkeypatch.setattr(memory, "default_limit", lambda: grouped + whole_bytes)
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.iterations == 0 and pre.direct is not None
    monkeypatch.setattr(memory, "default_limit", lambda: grouped)
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert pre.direct is None and info.iterations > facet.PROBE
    monkeypatch.undo()
    monkeypatch.setattr(facet, "FACTOR_CAP", int(sizes.max()) - 1)  # a component above it
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert pre.direct is None and info.iterations > facet.PROBE


def test_a_local_block_of_most_unknowns_factorizes_the_whole_system_first(monkeypatch):
    """Half the facets without a target percolate into one cluster: the local block would be
    a 2-D system nearly as large as the whole, so the whole is factorized first, whatever
    the time model says (LOCAL_WHOLE); the answer is the CG answer."""
    from facetlift.linalg import facet

    r, c = np.mgrid[0:96, 0:96]
    d = Domain.from_mask((r - 47.5) ** 2 + (c - 47.5) ** 2 < 45 ** 2)
    rng = np.random.default_rng(5)
    strong = rng.random(d.n_facets) >= 0.5
    K = facet_form(d, [(np.where(strong, 1.0, 1e-9), SLOPE_BLOCK), (1.0, TWIST_BLOCK)])
    b = K @ rng.standard_normal(d.n_vertices)
    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 1e6)  # (the model says "costly")
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    assert pre.n_weak > facet.LOCAL_WHOLE * d.n_vertices
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.iterations == 0 and pre.direct is not None and info.relative_residual < 1e-10
    ref = FacetPreconditioner(d, K, strong, coarse="box")
    ref.may_factorize = False
    x_cg, info_cg = facet.solve(K, b, ref, rtol=1e-10)
    assert info_cg.converged and ref.direct is None
    diff = (x - x_cg) - np.mean(x - x_cg)  # (one component: one constant)
    assert np.abs(diff).max() < 1e-6 * np.abs(x_cg).max()


def test_an_inexact_factorization_never_replaces_a_better_iterate(monkeypatch):
    """A factor whose answer misses rtol (here of 1.03 K) is not taken over the probe's better
    iterate, CG still converges; a start already within rtol is returned as it is."""
    from facetlift.linalg import direct, facet

    real = direct.superlu
    monkeypatch.setattr(direct, "superlu", lambda K, grid=None: real(1.03 * K, grid))
    monkeypatch.setattr(facet, "FACTOR_PER_UNKNOWN", 0.0)
    monkeypatch.setattr(facet, "FACTOR_PER_WORK", 0.0)
    d, strong, K, b = _many_disks_with_gaps()
    pre = FacetPreconditioner(d, K, strong, coarse="box")
    x, info = facet.solve(K, b, pre, rtol=1e-10)
    assert info.converged and np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert pre.direct is not None and info.iterations > facet.PROBE
    res = info.residuals
    assert max(res[facet.PROBE:]) <= 10 * res[facet.PROBE]  # (no jump back to the factor's)
    x2, info2 = facet.solve(K, b, pre, rtol=1e-10, x0=x)  # cached factor, converged start
    assert info2.iterations == 0 and info2.converged and x2 is x


def test_the_factorization_model_skips_the_separators_work_only_where_it_cannot_decide(
        monkeypatch):
    """The model's part per unknown is a lower bound of its estimate: where it alone is over
    the budget the separators' work is not computed (a quarter of a second on a 2048^2
    square); everywhere the answer is the full model's."""
    from facetlift.linalg import facet, ordering

    d = Domain.from_mask(np.ones((40, 50), bool))
    n = d.n_vertices
    calls = []
    real = ordering.factorization_work

    def counted(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(ordering, "factorization_work", counted)
    work = real(*d.vertices)
    base = facet.FACTOR_PER_UNKNOWN * n
    full = base + facet.FACTOR_PER_WORK * work
    for budget in (0.5 * base, base, 0.5 * (base + full), full, 2 * full, np.inf, np.nan):
        calls.clear()
        assert facet._cheaper(n, d, budget) == bool(full < budget)
        assert len(calls) == (1 if base < budget else 0)
