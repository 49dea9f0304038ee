"""Memory planning: the peak memory of a job, estimated before anything that grows with the
input is allocated, and refused when it does not fit.

:func:`plan` is called once by :func:`facetlift.solve` (so by :func:`facetlift.integrate`
too), after the options are checked and before the method runs. It estimates the peak
*additional* resident memory of the method and route that will run (the input arrays and the
checked problem already exist) from per-pixel coefficients measured on this project's
machine (``benchmarks/bench_memory.py``, docs/benchmarks.md "Memory planning"), and raises
:class:`facetlift.errors.MemoryLimitError` naming the estimate, the limit and what to do when
it exceeds the limit.

The limit (``max_memory=``, ``--max-memory``) defaults to the smallest of

* the available physical memory (``MemAvailable``) minus a margin (:data:`MARGIN` of the
  total, at least 256 MiB),
* what the address-space limit (``RLIMIT_AS``, ``ulimit -v``) leaves above the process's
  current virtual size,
* what a cgroup memory limit (a container's) leaves above its current usage.

Counts
    ``m`` facets (mask pixels), ``n`` vertices, ``B`` cells of the mask's bounding box (what
    the methods work on, :func:`facetlift.api.crop`). Estimates are linear in them, except the
    sparse factorizations (SuperLU, PARDISO: ``n log2 n``, used up to
    :data:`facetlift.linalg.LARGE` unknowns) and the local dense fits of "kernel" and the
    Gaussian of "diffusion", whose size follows their options (an absurd ``sigma`` or
    ``tile`` is refused here, before it allocates).

Factorizations outside the plan
    The discontinuity route factorizes its final system where CG on it is slow (up to 2 M
    vertices, ``facetlift.methods.dgp.discontinuous.DIRECT_POLISH``) only when
    :func:`factorization_fits`: within half the free memory and within what the plan leaves
    of the limit (:func:`headroom`), else it keeps to CG, the route its plan is for.

Size limits
    :data:`SIZE_LIMITS` caps methods whose time, not memory, gets out of hand on large
    domains; it applies under the default limit, and an explicit ``max_memory`` lifts it.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import os
import re
import sys
from dataclasses import dataclass

import numpy as np

from .errors import MemoryLimitError

MiB = 2**20
GiB = 2**30

#: Share of the physical memory kept free by the default limit.
MARGIN = 0.05

#: Peak resident memory above the prepared problem, per route: bytes per facet (mask pixel)
#: ``m``, per cell ``B`` of the mask's bounding box, a fixed part, and bytes per
#: ``n log2 n`` where the route factorizes ``n`` unknowns (SuperLU / PARDISO, up to
#: :data:`facetlift.linalg.LARGE`). Fitted to benchmarks/bench_memory.py on rect and disk
#: domains at 512^2-1536^2, checked at 256^2-2048^2 (docs/benchmarks.md,
#: "Memory planning"); the facet-CG routes 8 bytes per facet above that fit since CG keeps
#: the iterate of its smallest residual (:data:`facetlift.linalg.cg.GROWTH`), not refitted,
#: and their fixed part 18 MiB since 2026-12-06 (was 12); the discontinuity route refitted
#: on rect and disk at 256^2-2048^2 on 2026-12-06 (1.01-1.09x its measured peaks there).
COEFFICIENTS = {
    "dgp-spectral": (0.0, 85.0, 8 * MiB, 0.0),
    "dgp-pcg": (172.0, 68.0, 18 * MiB, 0.0),
    "dgp-factor": (172.0, 68.0, 18 * MiB, 110.0),
    "dgp-loop-spectral": (0.0, 125.0, 5 * MiB, 0.0),
    "dgp-loop-pcg": (205.0, 68.0, 20 * MiB, 0.0),
    "dgp-loop-factor": (205.0, 68.0, 20 * MiB, 110.0),
    "dgp-discontinuous": (760.0, 65.0, 26 * MiB, 0.0),
    "poisson": (607.0, 0.0, 0.0, 45.0),
    "m_estimator": (894.0, 0.0, 0.0, 31.0),
    "alpha_surface": (934.0, 0.0, 0.0, 27.0),
    "regularization": (1242.0, 0.0, 0.0, 130.0),
    "diffusion": (1330.0, 0.0, 0.0, 60.0),
    "frankot_chellappa": (0.0, 500.0, 0.0, 0.0),
    "kernel": (390.0, 0.0, 0.0, 0.0),
}


#: Bytes per vertex of the Ruge-Stueben hierarchy (and its setup) that replaces the spectral
#: box on a thin domain (:func:`facetlift.linalg.facet.thin`) on the facet-CG routes. Measured
#: on 2026-12-07 on a map with 30 % of its normals NaN and no mask, thin through its holes by
#: the test of that morning (its small holes are filled before the test since), with
#: ``backend="pcg"``: the plan without it was 0.32-0.36 of the peak at 512^2-2048^2 (2048^2:
#: 772 MiB planned, 2,431 MiB peak), the difference 418-458 B per vertex; with it 1.00-1.07x.
#: A spiral 4 px wide at 1024^2: 0.92-0.95x with 30 % missing normals, 1.28-1.42x with every
#: normal known (two measurements).
THIN_MULTIGRID = 460.0


#: Mask pixels above which a method is refused by default although it would fit in memory:
#: its time grows past a minute on this project's 2-core machine ("regularization" with the
#: Laplacian prior: smoothed-aggregation CG on the biharmonic-like system, 48 s at 1.43 M and
#: 85 s at 2.54 M mask pixels; docs/benchmarks.md). An explicit ``max_memory`` lifts it.
SIZE_LIMITS = {"regularization": 1_600_000}


@dataclass(frozen=True)
class Plan:
    """A job's estimated peak (bytes, above what is allocated when it is planned), the limit
    it was checked against, and the route the estimate is for."""

    estimate: int
    limit: int
    route: str

    def __str__(self) -> str:
        return f"{_size(self.estimate)} ({self.route}) of {_size(self.limit)} allowed"


#: glibc's ``mallopt`` parameters (``malloc.h``).
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_MAX = -1, -2, -4

#: Environment variables that, when set, leave the C allocator to the user.
_MALLOC_ENV = ("MALLOC_MMAP_MAX_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_",
               "MALLOC_MMAP_THRESHOLD_")

#: glibc's C library once :func:`retain_freed_memory` has applied its setting (else None).
_RETAINED = None


def retain_freed_memory() -> bool:
    """Make the C allocator keep the memory the process frees for reuse (glibc on Linux;
    elsewhere nothing happens).

    By default every array above glibc's mapping threshold (at most 32 MiB) is mapped fresh
    from the system and unmapped when freed. Each first touch of fresh memory is a page fault,
    and on a virtual machine whose host reclaims free memory it faults to the host: 5-9 s per
    GiB on the project's VM (docs/benchmarks.md, "Fresh memory is slow on this VM"). Kept in
    the process, freed blocks serve the next arrays while they are still warm: measured there
    with runs started cold, 4096^2 with 30 % missing normals 85.5 -> 58.8 s, the 2048^2
    discontinuity square 62-69 -> 45-50 s, for up to 12 % more peak memory (the blocks
    fragment). It applies to the main thread's heap (other threads' large blocks keep their
    own mappings).

    The setting is process-wide and lasts as long as the process (it also ends glibc's
    adaptive thresholds): right for a command-line run, wrong for a library to impose on its
    host. The ``facetlift`` command calls this at start-up (``FACETLIFT_RETAIN_MEMORY=0``
    turns it off); the library never does, but :func:`plan` hands the kept memory back to the
    system before it measures what is available, so a later job in the same process is
    planned as before (the reuse that saves the time is within one solve). Returns whether
    the setting was applied: False off Linux and glibc, under a preloaded allocator
    (``LD_PRELOAD``), when one of :data:`_MALLOC_ENV` or a malloc entry of
    ``GLIBC_TUNABLES`` is set (the user's settings stand), or when glibc refuses it.
    """
    global _RETAINED
    if not sys.platform.startswith("linux") or any(k in os.environ for k in _MALLOC_ENV):
        return False
    if "malloc" in os.environ.get("GLIBC_TUNABLES", "") or os.environ.get("LD_PRELOAD"):
        return False
    try:
        import ctypes
        import platform

        if platform.libc_ver()[0] != "glibc":
            return False
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
        libc.mallopt.restype = ctypes.c_int
        # large blocks from the heap, not separate mappings; the heap's top never handed back
        # (-1: no trimming); the heap grown in steps of 256 MiB of address space
        if not (libc.mallopt(_M_MMAP_MAX, 0) and libc.mallopt(_M_TRIM_THRESHOLD, -1)
                and libc.mallopt(_M_TOP_PAD, 256 * 2**20)):
            return False
    except Exception:  # (no C library to load, an unexpected platform: leave it alone)
        return False
    _RETAINED = libc
    return True


def _release_retained() -> None:
    """Hand the memory that :func:`retain_freed_memory` keeps back to the system (before the
    available memory is measured), if it was applied."""
    if _RETAINED is not None:
        try:
            _RETAINED.malloc_trim(0)
        except Exception:  # pragma: no cover - (glibc has it since 2.0)
            pass


def _size(b: float) -> str:
    if b >= GiB:
        return f"{b / GiB:.2f} GiB"
    if b >= MiB:
        return f"{b / MiB:.0f} MiB"
    return f"{b / 1024:.0f} KiB" if b >= 1024 else f"{b:.0f} bytes"  # (1K read "0 MiB")


_UNITS = {"": 1, "b": 1, "k": 2**10, "m": MiB, "g": GiB, "t": 2**40}


def parse_size(value) -> int:
    """Bytes from a number or a string such as ``"8G"``, ``"512 MiB"``, ``"1.5GB"``.

    Raises
    ------
    ValueError
        Naming `max_memory`, for anything else or a non-positive size.
    """
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        out = float(value)
    elif isinstance(value, str):
        hit = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e[+-]?[0-9]+)?)\s*([kmgt]?)(?:i?b)?\s*",
                           value.lower())
        if hit is None:
            raise ValueError(
                f"`max_memory` must be a number of bytes or a size such as '8G' or '512M'; "
                f"got {value!r}"
            )
        out = float(hit.group(1)) * _UNITS[hit.group(2)]
    else:
        raise ValueError(f"`max_memory` must be a number of bytes or a size such as '8G'; got "
                         f"{value!r}")
    if math.isfinite(out) and out > 0 and out != int(out):
        raise ValueError(f"`max_memory` is in bytes without a unit, and a fraction of a byte "
                         f"is no size: got {value!r}; give a unit, e.g. '{value}G'")
    if not (math.isfinite(out) and out > 0):
        raise ValueError(f"`max_memory` must be a positive, finite size; got {value!r}"
                         + ("" if math.isfinite(out) else " (infinite: leave it out for no "
                            "limit)"))
    return int(out)


def _meminfo() -> dict:
    out = {}
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                key, val = line.split(":", 1)
                out[key] = int(val.split()[0]) * 1024
    except (OSError, ValueError):
        pass
    return out


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _cgroup_headroom() -> int | None:
    """What a cgroup memory limit leaves (v2 memory.max, v1 limit_in_bytes), or None."""
    for limit, usage in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                         ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                          "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        lim, use = _read_int(limit), _read_int(usage)
        if lim is not None and use is not None and lim < 2**60:
            return lim - use
    return None


def _vm_size() -> int:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return 0


#: Address space kept free under ``ulimit -v`` beyond the plan: threads' stacks and the
#: allocator's arenas take address space that is not resident memory (a 1024^2 job planned at
#: 93 MiB in 131 MiB of address space ran out of it).
ADDRESS_MARGIN = 256 * MiB


def _address_space_headroom() -> int | None:
    """What ``ulimit -v`` (RLIMIT_AS) leaves above the process's virtual size, less
    :data:`ADDRESS_MARGIN`; None without such a limit."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, ValueError, OSError):  # pragma: no cover - not POSIX
        return None
    if soft == resource.RLIM_INFINITY:
        return None
    return soft - _vm_size() - ADDRESS_MARGIN


def default_limit() -> int:
    """The default ``max_memory`` in bytes (module docstring)."""
    return default_limit_source()[0]


#: What bounds the default limit, as :func:`default_limit_source` names it.
FREE, ADDRESS_SPACE, CGROUP = ("the available memory", "what ulimit -v (the address-space "
                               "limit) leaves above this process", "the container's memory "
                               "limit")


#: How many processes share this machine's memory (:func:`share_among`): the batch's local
#: worker processes each plan against their share of the free memory and of a cgroup's
#: limit (both are the machine's, not the process's); 1 elsewhere.
_SHARE = 1


def share_among(n: int) -> None:
    """Plan this process's jobs against a 1/`n` share of the free memory (and of a cgroup's
    limit): set in each of a local batch's `n` worker processes, which otherwise each
    planned against all of it at once, so that items that each fit could together exhaust
    it and have a worker killed (a review: two workers both planned against 21.7 GiB)."""
    global _SHARE
    _SHARE = max(int(n), 1)


def default_limit_source() -> tuple[int, str]:
    """``(bytes, what bounds them)``: :func:`default_limit` and which of the free memory
    (:data:`FREE`), ``ulimit -v`` (:data:`ADDRESS_SPACE`) or a cgroup (:data:`CGROUP`) is the
    smallest; the first and the last divided among the processes of :func:`share_among`."""
    info = _meminfo()
    total = info.get("MemTotal")
    avail = info.get("MemAvailable")
    if avail is None:
        try:
            page = os.sysconf("SC_PAGE_SIZE")
            avail = os.sysconf("SC_AVPHYS_PAGES") * page
            total = os.sysconf("SC_PHYS_PAGES") * page
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
            avail = total = 2**62
    n = _SHARE
    shared = "" if n == 1 else f" (a 1/{n} share: this process is one of {n} batch workers)"
    limits = [((avail - max(256 * MiB, int(MARGIN * (total or avail)))) / n, FREE + shared)]
    space = _address_space_headroom()
    if space is not None:
        limits.append((space, ADDRESS_SPACE))
    cg = _cgroup_headroom()
    if cg is not None:
        limits.append((cg / n, CGROUP + shared))
    size, source = min(limits, key=lambda t: t[0])
    return max(int(size), 0), source


#: Bytes the running job may take beyond its plan's estimate (its limit minus the estimate),
#: set by :func:`facetlift.api.solve` for the method's run; None outside a job.
_headroom: contextvars.ContextVar[int | None] = contextvars.ContextVar("headroom", default=None)


@contextlib.contextmanager
def headroom(plan: Plan):
    """Within the block, :func:`factorization_fits` also keeps to what `plan` leaves of its
    limit (an explicit ``max_memory`` included)."""
    token = _headroom.set(max(plan.limit - plan.estimate, 0))
    try:
        yield
    finally:
        _headroom.reset(token)


def factorization_bytes(n: int, blocks=None) -> float:
    """Bytes a factorization of a 9-point system of `n` unknowns takes: the "dgp-factor"
    route's bytes per ``n log2 n`` (110: about 2.2 GB at 1 M unknowns, where SuperLU measured
    1.5 GB on the discontinuity route's final system). `blocks`: the unknowns of the system's
    independent blocks (its mask's components, which do not fill each other in), summing
    to `n`: each counts ``n_i log2 n_i``."""
    per = COEFFICIENTS["dgp-factor"][3]
    if blocks is None:
        return per * n * math.log2(max(n, 2))
    b = np.asarray(blocks, dtype=float)
    return per * float(np.sum(b * np.log2(np.maximum(b, 2.0))))


def factorization_fits(n: int, blocks=None) -> bool:
    """Whether factorizing a 9-point system of `n` unknowns (of independent `blocks`:
    :func:`factorization_bytes`) fits: its :func:`factorization_bytes` within half of
    :func:`default_limit` now and within the running job's :func:`headroom`. For a
    factorization a method takes only as a faster alternative to CG, outside its plan (whose
    route is CG's)."""
    need = factorization_bytes(n, blocks)
    room = _headroom.get()
    return need <= default_limit() / 2 and (room is None or need <= room)


def limit_source(max_memory=None) -> tuple[int, str]:
    """``(bytes, what bounds them)`` of the job's limit: :func:`default_limit_source` when
    `max_memory` is None, else `max_memory` (checked), which cannot go beyond what ``ulimit
    -v`` leaves (:data:`ADDRESS_SPACE`)."""
    if max_memory is None:
        return default_limit_source()
    lim = parse_size(max_memory)
    space = _address_space_headroom()
    if space is not None and space < lim:
        return max(space, 0), ADDRESS_SPACE
    return lim, "`max_memory`"


def _box(domain) -> tuple[int, int]:
    """Facet rows and columns of the mask's bounding box."""
    mask = domain.mask
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[-1] - rows[0] + 1), int(cols[-1] - cols[0] + 1)


def _cost(route: str, m: int, B: int, factorized: int = 0) -> float:
    a, b, c, f = COEFFICIENTS[route]
    out = a * m + b * B + c
    if factorized:
        out += f * factorized * math.log2(max(factorized, 2))
    return out


def _gaussian(sigma: float, B: int) -> float:
    """scipy's Gaussian filter: a kernel of 2 * int(4 sigma + 0.5) + 1 taps (its radius at
    most the image's side, at most `B`: :func:`facetlift.methods.diffusion.tensor`), an
    image-sized output per pass."""
    taps = 2 * int(min(4.0 * float(sigma) + 0.5, B)) + 1
    return 8.0 * taps + 16.0 * B


def _kernel_tiles(options: dict, shape) -> float:
    """The dense local fits of "kernel": per worker a (2k, 2k) Gram matrix and its three (k, k)
    distance and kernel tables (56 k^2 bytes, the Gram matrix factorized in place; with the
    old temporaries and LAPACK's copy it was about 80, an audit), k the samples of one fit
    window; plus the evaluation."""
    sigma = float(options.get("sigma", 2.0))
    tile = float(options.get("tile", 16))
    margin = options.get("margin")
    margin = math.ceil(2 * sigma) if margin is None else float(margin)
    o = math.ceil(sigma)
    tile = max(tile, 2 * o)
    side_r = min(tile + 2 * o + 2 * margin, shape[0])
    side_c = min(tile + 2 * o + 2 * margin, shape[1])
    k = side_r * side_c
    ev = min(tile + 2 * o, shape[0]) * min(tile + 2 * o, shape[1])
    from ._threads import cores

    workers = min(cores(), 8)  # (kernel's threads, one per tile in flight)
    return workers * (8.0 * 7 * k * k + 8.0 * 5 * ev * k)


def _sparse_prior(problem) -> bool:
    """Whether the smooth DGP route will try its multigrid for a sparse prior."""
    from .methods.dgp.fixed_point import sparse_prior

    return (problem.has_prior and problem.prior_blur == 0  # (a blurred prior skips it)
            and sparse_prior(problem.prior_weight, problem.prior_components))


#: Bytes per vertex of the facet preconditioner's local block in its small connected groups
#: (tiny blocks, a linear factorization), and the group size from which a group is charged
#: as a 2-D factorization (:func:`_local_block_bytes`).
LOCAL_SCATTERED, LOCAL_GROUP = 200.0, 256


def _local_block_bytes(domain, usable) -> float:
    """Planned bytes of the facet preconditioner's local factorization
    (:func:`facetlift.linalg.facet.weak_vertices`): its 8-connected groups of vertices of
    :data:`LOCAL_GROUP` or more as 2-D factorizations (:func:`factorization_bytes` each: a
    hole in the data), the rest linear (:data:`LOCAL_SCATTERED`: random gaps, whose
    factor held 4.5 MiB at 4096^2 where n log n planned 250 MiB, a review)."""
    import scipy.ndimage as ndi

    from .linalg.facet import weak_vertices

    local = weak_vertices(domain, usable)
    if not local.any():
        return 0.0
    img = np.zeros(domain.vertex_mask.shape, dtype=bool)
    img[domain.vertex_mask] = local
    labels, _ = ndi.label(img, structure=np.ones((3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel())[1:]
    big = sizes[sizes >= LOCAL_GROUP]
    return float(sum(factorization_bytes(int(k)) for k in big)
                 + LOCAL_SCATTERED * (int(sizes.sum()) - int(big.sum())))


def estimate(problem, method: str, options: dict) -> tuple[float, str]:
    """Estimated peak bytes of `method` with checked `options` on `problem`, and its route.

    Parameters
    ----------
    problem : Problem
    method : str
    options : dict
        The validated options (:func:`facetlift.options.validate`).
    """
    from .linalg import choose

    d = problem.domain
    m = d.n_facets
    hb, wb = _box(d)
    B = (hb + 1) * (wb + 1)
    backend = options.get("backend", "auto")
    # a depth prior (docs/fusion.md): its (m,) values and weights, and for the facet routes
    # its 9-point matrix and the sum with the normal matrix (int32 indices, float64 values)
    fused = problem.prior is not None or problem.confidence is not None
    prior_bytes = 3 * 8 * m if fused else 0
    if method == "dgp":
        if problem.prior is not None:
            prior_bytes += 2 * 9 * 12 * d.n_vertices
        if problem.prior_blur > 0:  # PlaneBlur's kept maps (32 B per box cell) and one
            prior_bytes += 80 * B  # update's filtered images (the review's count, 2026-12)
        if options.get("discontinuities"):
            if problem.prior is not None:  # the prior's own matrix, sum and normals' part:
                prior_bytes += 330 * m  # measured 0.79-0.82 of the peak without this
            gaps = problem.extras.get("no_normal")
            if gaps is not None and gaps.any():  # the filled gaps' targets and weights
                # (methods.dgp.fill_gaps; a review at 300^2: 137-182 B per facet more peak)
                prior_bytes += 180 * m
            return _cost("dgp-discontinuous", m, B) + prior_bytes, "dgp-discontinuous"
        loop = "dgp-loop" if options.get("solver") == "iterative" else "dgp"
        from .linalg.facet import thin

        slim = thin(d)
        route = choose(d.n_vertices, backend, kind="facet", thin=slim)
        full = m == hb * wb and (loop == "dgp-loop" or bool(problem.usable.all())) and not fused
        if route != "pcg":
            return (_cost(f"{loop}-factor", m, B, d.n_vertices) + prior_bytes,
                    f"{loop}-{route}")
        name = f"{loop}-spectral" if full else f"{loop}-pcg"
        if slim:  # the multigrid that replaces the box on a thin domain
            prior_bytes += THIN_MULTIGRID * d.n_vertices
        if not bool(problem.usable.all()):
            # the facet preconditioner's exact local solve on the vertices of facets without
            # a normal (linalg.facet.weak_vertices): a factorization of its own, which a large
            # hole makes a 2-D system (an audit: a 1024^2 sphere with 64 % of it missing
            # planned 160 MiB and peaked at 1,257 MiB)
            prior_bytes += _local_block_bytes(d, problem.usable)
        if loop == "dgp" and _sparse_prior(problem):
            # the Ruge-Stueben trial's hierarchy (methods.dgp.fixed_point.SPARSE_PRIOR): about
            # 150-170 B per vertex measured at 1024^2 (rect, disk)
            prior_bytes += 180 * d.n_vertices
        return _cost(name, m, B) + prior_bytes, name
    if method == "frankot_chellappa":
        return _cost(method, m, B), method
    if method == "kernel":
        return _cost(method, m, B) + _kernel_tiles(options, (hb, wb)), method
    if method == "bini":  # (Jacobi-CG on the pixel graph, no factorization: Poisson's
        # figures without one; 141 MiB planned against 145 measured at 768^2, an audit, where
        # the route read "bini-unplanned")
        return _cost("poisson", m, B), "bini-cg"
    if method not in COEFFICIENTS:  # a method registered elsewhere: plan it like Poisson
        return _cost("poisson", m, B), f"{method}-unplanned"
    spd = method in ("regularization", "diffusion")
    route = choose(m, backend, kind="spd" if spd else "graph")
    out = _cost(method, m, B, m if route in ("superlu", "pardiso") else 0) + prior_bytes
    if method == "diffusion":
        out += _gaussian(options.get("sigma", 0.5), B)
    return out, f"{method}-{route}"


#: The options that size a method's memory beside the map (its dense tables and filters):
#: a refusal names those given where the defaults would fit.
SIZED_BY = {"kernel": ("sigma", "tile", "margin"), "diffusion": ("sigma",)}


def plan(problem, method: str, options: dict, max_memory=None) -> Plan:
    """Estimate the job's peak and refuse it when it exceeds the limit.

    Raises
    ------
    facetlift.errors.MemoryLimitError
        The estimate exceeds `max_memory` (default :func:`default_limit`), or the domain is
        larger than the method's :data:`SIZE_LIMITS` entry under the default limit; the
        message names the figures and what to do.
    ValueError
        A bad `max_memory`.
    """
    _release_retained()  # (the memory a previous job left in the process counts as free)
    lim, source = limit_source(max_memory)
    m = problem.domain.n_facets
    cap = SIZE_LIMITS.get(method)
    if cap is not None and m > cap and max_memory is None:
        raise MemoryLimitError(
            f"method {method!r} is limited to {cap:,} mask pixels by default (beyond that it "
            f"takes minutes on a 2-core machine); this job has {m:,}: crop or downsample the "
            "input, use method='poisson' or 'dgp' (--method poisson or dgp), or pass "
            "max_memory= / --max-memory to run it anyway"
        )
    est, route = estimate(problem, method, options)
    p = Plan(int(min(est, 2**62)), lim, route)
    if est > lim:
        leaner = first = ""
        if method != "dgp":
            leaner = "use a route that needs less (the default method='dgp' is the leanest), "
            from .methods import REGISTRY

            defaults = REGISTRY[method].options() if method in REGISTRY else {}
            # (those given away from their default that ask for more than it: a review saw
            # defaults and a tile below its default named)
            given = {k: v for k, v in options.items()
                     if k in SIZED_BY.get(method, ()) and k in defaults and v != defaults[k]
                     and estimate(problem, method, {**options, k: defaults[k]})[0] < est}
            plain = estimate(problem, method, {**options, **{k: defaults[k] for k in given}})[0]
            if given and plain <= lim:  # (the options ask for it, not the map's size)
                first = (f"lower its {', '.join(f'{k}={v!r}' for k, v in given.items())} "
                         f"(at {'their defaults' if len(given) > 1 else 'its default'} "
                         f"about {_size(plain)}), ")
        elif options.get("discontinuities"):
            smooth = estimate(problem, method, {**options, "discontinuities": False})[0]
            if smooth <= lim:
                leaner = (f"integrate without discontinuities (about {_size(smooth)}), ")
        raise MemoryLimitError(
            f"method {method!r} would need about {_size(est)} at its peak ({route}, "
            f"{problem.domain.n_facets:,} mask pixels), more than the "
            f"{_size(lim)} allowed ({source}); "
            + first + "crop the input or lower its resolution, " + leaner
            + ("or raise or lift ulimit -v (max_memory= / --max-memory cannot go beyond it)"
               if source == ADDRESS_SPACE else
               "or raise the limit with max_memory= / --max-memory if the memory is there")
        )
    return p
