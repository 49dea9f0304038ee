"""What an input holds, before integrating it: ``facetlift info`` and :func:`describe`.

:func:`estimate` gives the memory and time the default integration would need from a simple
per-pixel model (:data:`COST`, measured for ``dgp`` at 2048² on the project's 2-core machine,
docs/benchmarks.md). It is an estimate, not a plan: the memory planner of :mod:`facetlift.linalg`
is the authority where it exists.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

#: route -> (bytes per pixel of the mask's bounding box, seconds per mask pixel), from the
#: default dgp solve at 2048² (docs/benchmarks.md: 1,218 MiB / 2.6 s on the full square,
#: 1,780 MiB / 9.3 s on a masked disk covering 64 % of it); plus :data:`BASE_BYTES`.
COST = {"spectral": (287.0, 6.3e-7), "pcg-spectral": (427.0, 3.5e-6)}
#: The interpreter with numpy and scipy loaded.
BASE_BYTES = 70 * 2**20


def estimate(shape, method: str = "dgp", *, mask=None) -> dict:
    """Memory (bytes) and time (seconds) the default integration of a map would need.

    Parameters
    ----------
    shape : (H, W) or a Problem
        The map's size (or a prepared problem: its domain's mask is used).
    method : str
        Only ``"dgp"`` has measured coefficients; other methods get dgp's, marked
        ``"basis": "dgp coefficients"``.
    mask : (H, W) bool, optional
        The domain; default the full rectangle.

    Returns
    -------
    dict
        ``bytes``, ``seconds``, ``route`` (``spectral`` on a full rectangle, else
        ``pcg-spectral``), ``basis`` and ``estimate: True``.
    """
    if hasattr(shape, "domain"):
        mask = shape.domain.mask
        shape = mask.shape
    H, W = (int(v) for v in shape)
    if mask is None:
        box, pixels, full = H * W, H * W, True
    else:
        m = np.asarray(mask, bool)
        rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
        if rows.size == 0:
            box = pixels = 0
        else:
            box = (rows[-1] - rows[0] + 1) * (cols[-1] - cols[0] + 1)
            pixels = int(m.sum())
        full = pixels == box
    route = "spectral" if full else "pcg-spectral"
    per_byte, per_second = COST[route]
    return {
        "bytes": int(BASE_BYTES + per_byte * box),
        "seconds": float(per_second * pixels),
        "route": route,
        "basis": "measured" if method == "dgp" else "dgp coefficients",
        "estimate": True,
    }


def describe(path, *, mask=None, K=None, normal_frame=None, mat_keys=None) -> dict:
    """What ``facetlift info`` reports about an input: size, pixel type, detected frame and
    encoding, mask and components, unusable normals (with the first one's location), K, and
    :func:`estimate`.

    Parameters
    ----------
    path : str or Path
        A normal-map file, a dataset folder, or a ``.mat`` file.
    mask, K : str or Path, optional
        As for ``facetlift integrate``.
    normal_frame : str, optional
        The frame to read it in (default facetlift's).

    Raises
    ------
    ValueError
        As the readers (unreadable file, bad frame).
    """
    from . import frames
    from .jobs import Job, read
    from .problem import prepare

    job = Job(normals=str(path), mask=None if mask is None else str(mask),
              K=None if K is None else str(K), normal_frame=normal_frame,
              mat_keys=None if mat_keys is None else tuple(mat_keys))
    src = job.source
    out = {"input": str(src), **_file_facts(src)}
    inp = read(job)
    n = inp.normals
    H, W = n.shape[:2]
    out.update(shape=[H, W], mask_source=inp.mask_source,
               K=None if inp.K is None else inp.K.tolist(),
               projection="perspective" if inp.K is not None else "orthographic")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            checked = frames.checked(n, inp.mask, frame=None)
            problem = prepare(checked, inp.mask, K=inp.K)
        except ValueError as e:
            out["usable"] = False
            out["problem"] = str(e)
            out["frame"] = _frame_guess(n, inp.mask, inp.K, frame=normal_frame)
            return out
    d = problem.domain
    counts = dict(problem.counts)
    out.update(
        usable=True,
        mask_pixels=int(d.n_facets),
        components=int(d.n_components),
        counts=counts,
        first_unusable=counts.pop("first_unusable", None),
        warnings=[str(w.message) for w in caught],
        frame=_frame_guess(n, inp.mask, inp.K, problem, frame=normal_frame),
        estimate=estimate(problem),
    )
    return out


def _file_facts(src: Path) -> dict:
    """Format, pixel type and bit depth of the file as stored (without decoding it)."""
    from .io.dataset import _find
    from .io.images import NORMAL_READ_FORMATS

    f = _find(src, "normal_map", NORMAL_READ_FORMATS) if src.is_dir() else src
    facts = {"file": str(f), "format": f.suffix.lower().lstrip(".")}
    ext = f.suffix.lower()
    try:
        if ext == ".png":
            head = f.read_bytes()[:26]
            depth, colour = head[24], head[25]
            kinds = {0: "grey", 2: "RGB", 3: "palette", 4: "grey+alpha", 6: "RGBA"}
            facts.update(bit_depth=int(depth), channels=kinds.get(colour, str(colour)),
                         encoding=f"v / {2 ** depth - 1} * 2 - 1" if colour in (2, 6) else None)
        elif ext == ".npy":
            a = np.load(f, mmap_mode="r", allow_pickle=False)
            facts.update(dtype=str(a.dtype), stored_shape=list(a.shape), encoding="as stored")
        elif ext in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(f) as t:
                page = t.pages[0]
                facts.update(dtype=str(page.dtype), stored_shape=list(page.shape),
                             encoding="v / max * 2 - 1" if page.dtype.kind == "u"
                             else "as stored")
        elif ext == ".exr":
            import OpenEXR

            with OpenEXR.File(str(f), separate_channels=True) as e:
                ch = e.channels()
                facts.update(channels=sorted(ch),
                             dtype=sorted({str(np.asarray(v.pixels).dtype) for v in ch.values()}),
                             encoding="as stored")
    except Exception:  # the reader reports unreadable files properly
        pass
    return facts


def _frame_guess(n, mask, K, problem=None, *, frame=None) -> dict:
    """Whether the frame the map was read in looks right, from the view direction and the
    integrability; ``likely`` says what to change."""
    from . import frames
    from .problem import prepare

    name = "opengl" if frame is None else frame
    guess = {"as_read": f"{name} ({frames.axis_string(frame)})"}
    inside = frames._inside(n, mask)
    if inside is not None and len(inside):
        away = float(np.mean(inside[:, 2] < 0))
        guess["facing_away"] = away
        if away > 0.5:
            guess["likely"] = ("z flipped: the normals face away from the viewer as read "
                               "(read as opengl, that is --normal-frame opencv)")
            return guess
        lo = inside[:, :2].min()
        if lo >= 0:
            guess["likely"] = "[0, 1]-encoded floats: decode with 2 * v - 1"
            return guess
    if problem is None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem = prepare(n, mask, K=K)
        except ValueError:
            return guess
    curls = {
        "curl": frames.relative_curl(problem),
        "curl_y_flipped": frames.relative_curl(problem, (1.0, -1.0, 1.0)),
    }
    guess.update(curls)
    own, flipped = curls["curl"], curls["curl_y_flipped"]
    if own > frames.FLIP_MIN_CURL and flipped < frames.FLIP_RATIO * own:
        guess["likely"] = ("y flipped: far more integrable with y negated (read as opengl, "
                           "that is --normal-frame directx, or -x,y,z if inside-out)")
    else:
        guess["likely"] = "as read (consistent)"
    return guess
