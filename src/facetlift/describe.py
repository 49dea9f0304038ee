"""What an input holds, before integrating it: ``facetlift info`` and :func:`describe`.

:func:`estimate` reports the memory the default integration would need from the memory
planner itself (:func:`facetlift.memory.estimate`, the figure :func:`facetlift.integrate`
checks against ``max_memory``), with the planner's route name, and a time range from the
mask-shape benchmark (:data:`SECONDS_PER_PIXEL`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ._warnings import recording, renamed

#: Planner route -> (fastest, slowest) seconds per mask pixel of the default dgp solve, over
#: the mask shapes of docs/benchmarks.md ("Mask-shape suite", the 2048² rows: orthographic and
#: perspective, bear / disk / human / many / torus masks; "spectral" from the full rectangle)
#: on the project's 2-core machine under load 2.3-6.4. ``"dgp-pcg"`` with missing normals
#: takes the ``"dgp-pcg-missing"`` row (the 30 %-missing tables); factorized routes take the
#: thin-spiral figures (4.0-4.3 s for 759k pixels), the slowest a map whose NaN normals (half
#: of them, no mask) leave it thin with holes that join the outside, factorized as a 2-D
#: system (512^2: 1.1-1.3 s for 130k pixels, 2026-12-07). Routes not listed get no time.
SECONDS_PER_PIXEL = {
    "dgp-spectral": (6.9e-7, 1.25e-6),
    "dgp-pcg": (1.8e-6, 1.2e-5),
    "dgp-pcg-missing": (3.8e-6, 1.6e-5),
    "dgp-superlu": (5.3e-6, 1.0e-5),
    # discontinuities=True (docs/benchmarks.md, "Discontinuities"), measured 2026-12-02/03:
    # fastest the 2048^2 disk of the mask suite's smooth surface (21.3 s, 3.3 M pixels; the
    # full square 37 s, 8.9e-6), the timing objects 1.7-3.6e-5 (0.7-2.4 s for 41-73k
    # pixels), the analytic occluder 2.8-8.0e-5 (256^2 1.8 s to 2048^2 335 s: long jumps
    # cost reweightings that grow with the side), slowest a user's check's 1536 x 2048
    # render of the armadillo, 548k pixels in 59 s on a shared machine
    "dgp-discontinuous": (6.5e-6, 1.1e-4),
}

#: With a depth prior the slowest rate of the route (a prior already moves a full rectangle
#: from the spectral route to the facet CG) is doubled. The time with / without a prior on the
#: same scene (docs/fusion.md, "Time"): medians 0.9-3.8 on masks and with discontinuities,
#: maxima 14-20 on small flat analytic scenes; blurred priors 3-6 in the median. Against the
#: route's slowest rate: a LiDAR user's 640 x 480 scene at weight 100 took 8.1 s against
#: 1.2-4.9 s estimated; a review's 480 x 640 plane, tent and sphere with 1 % samples at
#: weights 1 and 100, 0.33-1.38 s against 0.24-7.37 s. Since the discontinuity route starts a
#: sparse prior's reweightings from the prior-free pass's cuts (2026-12-04) its median with /
#: without such a prior is 1.81, 1.88 since the islands around samples are glued back
#: (2026-12-05; largest 8.65 on flat analytic scenes; docs/fusion.md, "Cuts from the normals
#: first"), within the doubled slowest rate.
PRIOR_SLOWER = 2.0


def estimate(problem, method: str = "dgp", **options) -> dict:
    """Peak memory (the planner's) and a time range for integrating a prepared problem.

    Parameters
    ----------
    problem : Problem
        A checked problem (:func:`facetlift.prepare`).
    method : str
    **options
        The method's options, as for :func:`facetlift.integrate` (validated).

    Returns
    -------
    dict
        ``bytes``: :func:`facetlift.memory.estimate`'s peak above the prepared problem (what
        ``max_memory`` is compared with); ``route``: the planner's route name;
        ``limit``: the default ``max_memory`` on this machine and ``fits``; ``seconds``:
        ``[fastest, slowest]`` from :data:`SECONDS_PER_PIXEL` (the slowest times
        :data:`PRIOR_SLOWER` with a depth prior), or None where no route was measured;
        ``estimate: True``; for the facet-CG routes ``bytes_factorized``, the peak where the
        system is factorized instead of iterated (where that is modelled faster and fits:
        :mod:`facetlift.linalg.facet`); for the discontinuity route the peak where its last
        solve is factorized (when CG is slow on it and the factorization fits). Neither is in
        the plan, which is CG's (a factorization is only taken where it fits the limit).

    Raises
    ------
    ValueError
        An unknown method or a bad option value.
    """
    from . import memory, methods
    from .options import validate

    values = validate(methods.get(method).specs(), dict(options), method)
    est, route = memory.estimate(problem, method, values)
    peak = int(min(est, 2**62))
    lim = memory.default_limit()
    key = route
    if route == "dgp-pcg" and not bool(problem.usable.all()):
        key = "dgp-pcg-missing"
    rate = SECONDS_PER_PIXEL.get(key) if method == "dgp" else None
    m = problem.domain.n_facets
    out = {
        "bytes": peak,
        "route": route,
        "limit": lim,
        "fits": peak <= lim,
        "seconds": None if rate is None else [
            rate[0] * m, rate[1] * m * (PRIOR_SLOWER if problem.has_prior else 1.0)],
        "estimate": True,
    }
    if route in ("dgp-pcg", "dgp-loop-pcg") and options.get("backend", "auto") == "auto":
        # (the facet CG factorizes the system instead where its model finds that faster and
        # it fits (linalg.facet: many components, scattered missing normals): outside the
        # plan, and unsaid; a mask of 340 small components peaked at 2.5x the plan, an audit)
        from .linalg.facet import FACTOR_CAP, _blocks

        blocks = _blocks(problem.domain)
        if blocks.size and blocks.max() <= FACTOR_CAP:
            out["bytes_factorized"] = peak + int(memory.factorization_bytes(
                problem.domain.n_vertices, blocks))
    if route == "dgp-discontinuous":
        # the last solve is factorized where CG is slow on it and the factorization fits
        # (DIRECT_POLISH, memory.factorization_fits): outside the plan, whose route is CG's.
        # A sixth fresh-user check measured 1.7-1.8x the plan's figure at 1024^2 so
        from .methods.dgp.discontinuous import DIRECT_POLISH

        n = problem.domain.n_vertices
        if n <= DIRECT_POLISH:
            out["bytes_factorized"] = peak + int(memory.factorization_bytes(n))
    return out


def _camera_warned(*caught) -> bool:
    """Whether one of the recorded warnings is a :class:`facetlift.errors.CameraWarning` (a K
    that looks wrong), as ``integrate --json``'s ``camera_warned``."""
    from .errors import CameraWarning

    return any(issubclass(w.category, CameraWarning) for ws in caught for w in ws)


def describe(path=None, *, gradients=None, mask=None, K=None, normal_frame=None,
             normal_encoding: str = "xyz", normal_range: str = "signed", mat_keys=None,
             gradient_frame: str = "xy",
             prior_scale=None, prior=None, confidence=None, prior_fit=None,
             prior_blur=None, fov=None, world_to_camera=None, camera_to_world=None,
             dataset_prior: bool = True, dataset_confidence: bool = True,
             orthographic: bool = False) -> dict:
    """What ``facetlift info`` reports about an input: size, pixel type, detected frame and
    encoding, mask and components, unusable normals (with the first one's location), K, a
    dataset folder's depth prior and normal confidence (``prior`` / ``confidence``: known
    pixels and value range; one that ``integrate`` would refuse is left out and the refusal
    given as ``refused`` and a warning), and :func:`estimate` for the default method.

    Parameters
    ----------
    path : str or Path, optional
        A normal-map file, a dataset folder, or a ``.mat`` file.
    gradients : (str or Path, str or Path), optional
        Instead of `path`: the two files of a gradient field (p, q), as for ``integrate``'s
        ``--gradients``, in the layout `gradient_frame`.
    mask, K : str or Path, optional
        As for ``facetlift integrate``.
    fov : float, optional
        Horizontal field of view in degrees instead of `K` (as for ``integrate``).
    normal_frame : str, optional
        The frame to read it in (default facetlift's).
    world_to_camera, camera_to_world : str or Path, optional
        For normals in world space, a file of the camera's rotation, as for ``integrate``'s
        ``--world-to-camera`` / ``--camera-to-world`` (:func:`facetlift.io.read_rotation`; a
        dataset folder's own is read where neither is given): the checks and the frame guess
        look at the normals turned into the camera frame (``normal_rotation`` in the report).
    normal_encoding : {"xyz", "xy"}
        How the map stores its normals (as for ``integrate``; ``"xy"``: a two-channel map,
        z rebuilt, :func:`facetlift.io.read_normals`).
    normal_range : {"signed", "unsigned"}
        The range of a float map's components (as for ``integrate``; ``"unsigned"``: stored as
        ``(n + 1) / 2`` in [0, 1], decoded as ``2 v - 1``, :func:`facetlift.io.read_normals`).
    gradient_frame : str
        The layout of a gradient field in a ``.mat`` input (as for ``integrate``).
    prior_scale : float, optional
        Depth units per count of a 16-bit PNG prior, the dataset folder's ``prior_depth`` or
        `prior` (as for ``integrate``: such a prior is refused without it).
    prior, confidence : str or Path, optional
        A depth prior (map or points file) and a confidence map, as for ``integrate``'s
        ``--prior`` and ``--confidence``: read and checked against the map (a prior that
        ``integrate`` would refuse makes the input unusable, with the reason).
    prior_fit : str, optional
        What the prior is known up to, as for ``integrate`` (:mod:`facetlift.prior_fit`): its
        values are then not checked as depths (any sign), and the time estimate allows for
        the route's two runs.
    prior_blur : float, optional
        The prior's blur in pixels, as for ``integrate``: its relief is checked as a blurred
        map's (only a relief too large is named).
    dataset_prior, dataset_confidence : bool
        Read a dataset folder's ``prior_depth.*`` / ``confidence.*`` (``integrate``'s
        ``--no-prior`` / ``--no-confidence`` set them False).
    orthographic : bool
        Ignore K (a dataset folder's ``K.txt``), as ``integrate --orthographic``.

    Raises
    ------
    ValueError
        As the readers (unreadable file, bad frame).
    """
    from . import frames
    from .io.dataset import K_value
    from .jobs import Job, _folder_named, camera_source, read, recorded_warnings, rotation_record
    from .problem import UnusableNormalsWarning, no_camera_hint, prepare

    job = Job(normals=None if path is None else str(path),
              gradients=tuple(str(g) for g in gradients) if gradients else None,
              mask=None if mask is None else str(mask),
              K=K_value(K), normal_frame=normal_frame,
              normal_encoding=normal_encoding, normal_range=normal_range,
              mat_keys=None if mat_keys is None else tuple(mat_keys),
              gradient_frame=gradient_frame, prior_scale=prior_scale,
              prior=None if prior is None else str(prior),
              confidence=None if confidence is None else str(confidence), fov=fov,
              prior_fit=prior_fit,  # (a 16-bit relative PNG then needs no scale, as in
              # integrate: info refused it, a review)
              world_to_camera=None if world_to_camera is None else str(world_to_camera),
              camera_to_world=None if camera_to_world is None else str(camera_to_world),
              dataset_prior=dataset_prior, dataset_confidence=dataset_confidence,
              orthographic=orthographic)
    src = job.source
    unread = []
    with recorded_warnings() as read_caught:  # (a gradient layout's, ...)
        try:  # (first: a folder without a normal map is the reader's clear error)
            inp = read(job)
        except ValueError as e:
            if not src.is_dir():
                raise
            # a folder's prior or confidence that integrate would refuse: the rest is still
            # described (without the file at fault, if the folder reads so), the refusal in
            # "refused" and as a warning
            inp = None
            for use_prior, use_conf in ((False, True), (True, False), (False, False)):
                try:
                    inp = read(replace(job, dataset_prior=use_prior, dataset_confidence=use_conf,
                                       prior_scale=job.prior_scale if use_prior else None))
                    break
                except ValueError:
                    continue
            if inp is None:
                raise
            unread.append(f"integrate would refuse this folder: {e}")
    out = {"input": str(src), **_file_facts(src),
           "warnings": unread + [str(w.message) for w in read_caught]}
    if unread:
        out["refused"] = unread[0].split(": ", 1)[1]
    if out.get("encoding") == "as stored" and frames.normal_range(normal_range) == "unsigned":
        out["encoding"] = "2 v - 1 (unsigned: stored in [0, 1])"
    if out.get("encoding") and frames.normal_encoding(normal_encoding) == "xy":
        out["encoding"] += " on R and G alone (xy), z = sqrt(1 - x^2 - y^2)"
    # (a gradient field in the other layout: no frame of the normals made from it is right)
    layout = next((w.message.other for w in read_caught
                   if isinstance(w.message, frames.LayoutWarning)), None)
    n = inp.normals
    H, W = n.shape[:2]
    # (normals in world space: turned into the camera frame of normal_frame, in which they
    # were read already, before the checks that look at their facing, as integrate does)
    turn = frames.rotation_in_facetlift(inp.rotation, normal_frame)
    where = dict(shape=[H, W], mask_source=inp.mask_source,
                 normal_rotation=rotation_record(job, inp),
                 K=None if inp.K is None else inp.K.tolist(),
                 projection="perspective" if inp.K is not None else "orthographic",
                 # (a gradient field, not a normal map: info's lines name its samples)
                 gradient_field=bool(inp.field),
                 # (where K came from, as integrate's summary says: a DiLiGenT folder's is
                 # its parent's Calib_Results.mat, which info did not name, a second audit)
                 camera=camera_source(job, inp),
                 # (other tools' camera files beside it, unread without --K: a review)
                 **({"camera_files_unread": list(inp.camera_unread)} if inp.camera_unread
                    else {}))

    def unusable(e: ValueError) -> dict:  # (integrate would refuse it: why, and the frame)
        out.update(usable=False, problem=str(e),
                   frame=_frame_guess(n, inp.mask, inp.K, frame=normal_frame, layout=layout,
                                      normal_range=frames.normal_range(normal_range),
                                      field=inp.field, gradient_frame=gradient_frame,
                                      rotation=turn))
        return out

    from .prior_fit import check as check_fit

    fitted = check_fit(prior_fit, inp.prior is not None, inp.K is not None) != "none"
    prior_map = inp.prior
    if isinstance(prior_map, tuple):  # (a points file: as integrate places them, once)
        from .problem import prior_image

        with recorded_warnings() as placed:
            try:
                prior_map = prior_image(prior_map, (H, W),
                                        positive=inp.K is not None and not fitted)
            except ValueError as e:  # (every point outside: reported, as integrate refuses)
                out.update(where)
                return unusable(e)
        out["warnings"] += [str(w.message) for w in placed]
    def known_of(name, arr):
        """The pixels of a prior / confidence map that hold a value integrate uses: a
        perspective prior's zeros and negative values are left out (a depth sensor's 0 for
        unknown: not known pixels here either, a review), a fitted one's zeros."""
        from .problem import fit_zeros, left_out_depths

        known = np.isfinite(arr)
        if name != "prior" or inp.K is None:
            return known
        # (a fitted map's zeros are left out before the fit; an unfitted one's as integrate
        # leaves them out, and a prior it refuses, e.g. a negated relative depth, keeps its
        # values in the report beside the refusal, a review)
        out = fit_zeros(arr) if fitted else left_out_depths(arr, known)
        return known if out is None else known & ~out

    for name, arr in (("prior", prior_map), ("confidence", inp.confidence)):
        if arr is not None:  # (a prior / confidence file, or a dataset folder's)
            known = known_of(name, arr)
            given = prior if name == "prior" else confidence
            out[name] = {"source": "dataset file" if given is None else str(given),
                         "known_pixels": int(known.sum()),
                         "range": [float(arr[known].min()), float(arr[known].max())]
                         if known.any() else None}
    out.update(where)
    with recording() as caught:
        try:
            with frames.read_in(frames.GRADIENT_FIELD if inp.field else normal_frame,
                                normal_range=frames.normal_range(normal_range)), \
                    frames.rotation_given(turn is not None):
                # (read in it already: hints relative to it; a field's speak of its samples,
                # as integrate's do)
                checked = frames.checked(n, inp.mask, frame=None, rotation=turn)
            # (a prior to be aligned is checked as values, not as depths: any sign; a
            # folder's files named as integrate names them, a review)
            with renamed(lambda m: _folder_named(m, job, inp, warning=True)):
                # (the default integration's rules: the smooth DGP's lone steep normals too)
                from . import methods

                problem = prepare(checked, inp.mask, K=inp.K,
                                  prior=None if fitted else prior_map,
                                  prior_blur=None if fitted else prior_blur,
                                  confidence=inp.confidence,
                                  steep_isolated=methods.get("dgp").steep_isolated)
        except ValueError as e:
            # (the warnings that came first too: a K for another image is what makes a map
            # unusable, and its warning was dropped, a review)
            out["warnings"] += [str(w.message) for w in caught if not issubclass(
                w.category, UnusableNormalsWarning)]
            out["camera_warned"] = _camera_warned(read_caught, caught)
            return unusable(ValueError(_folder_named(str(e), job, inp)))
    d = problem.domain
    with_prior = None
    if fitted:
        out["prior"]["fit"] = prior_fit
        # (the second run fuses the aligned prior: planned with the prior's own support, the
        # values aside; info reported the first run's plan alone, 0.19x a fitted run's peak,
        # and --max-memory then refused the second run, an audit)
        support = known_of("prior", prior_map) if prior_map is not None else None
        if support is not None and support.any():
            with recording():
                try:
                    with frames.read_in(frames.GRADIENT_FIELD if inp.field else normal_frame,
                                        normal_range=frames.normal_range(normal_range)), \
                            frames.rotation_given(turn is not None):
                        with_prior = prepare(checked, inp.mask, K=inp.K,
                                             prior=np.where(support, 1.0, np.nan),
                                             confidence=inp.confidence)
                except ValueError:
                    with_prior = None
    for name, arr in (("prior", prior_map), ("confidence", inp.confidence)):
        if arr is not None and name in out:  # (the range over the mask, where it is used: a
            # user's confidence read "0 to 1" from the background's zeros)
            inside = d.mask & known_of(name, arr)
            out[name].update(known_in_mask=int(inside.sum()), range=[
                float(arr[inside].min()), float(arr[inside].max())] if inside.any() else None)
    counts = dict(problem.counts)
    frame = _frame_guess(n, inp.mask, inp.K, problem, frame=normal_frame, layout=layout,
                         normal_range=frames.normal_range(normal_range), field=inp.field,
                         gradient_frame=gradient_frame, rotation=turn)
    noise = frame.pop("noise", None)
    out.update(
        usable=True,
        mask_pixels=int(d.n_facets),
        components=int(d.n_components),
        counts=counts,
        first_unusable=counts.pop("first_unusable", None),
        # (the unusable normals have their own line: not again as a warning)
        warnings=out["warnings"] + [str(w.message) for w in caught if not issubclass(
            w.category, UnusableNormalsWarning)],
        # (as integrate's record says it: an audit)
        camera_warned=_camera_warned(read_caught, caught),
        frame=frame,
        estimate=_twice(estimate(problem), with_prior, None),
        # (what --discontinuities would need: a user planning a large job asked)
        estimate_discontinuities=_twice(estimate(problem, "dgp", discontinuities=True),
                                        with_prior, {"discontinuities": True}),
        discontinuity_grazing=_jump_grazing(problem),
        # (prepare's holes, as integrate counts and warns them: info's own fill of any size
        # said 109 where integrate said 9, a review; none with a mask, inside which such
        # pixels are missing samples)
        holes=counts.get("holes", 0),
        larger_holes=counts.get("larger_holes", 0),
        # (the unusable-normals warning's hint for a photo integrated without a camera: info
        # called such a map's frame consistent and said nothing else, an audit)
        camera_hint=no_camera_hint(counts, inp.K is not None, inp.field) or None,
        # (degrees; NaN without a 2x2 block of usable pixels: None in the record; the frame
        # check's, where it measured the curls, else measured here)
        noise=_finite(frames.normal_noise(problem) if noise is None else noise),
    )
    return out


def _finite(x: float) -> float | None:
    """`x`, or None where it is not finite (a JSON record's value)."""
    return float(x) if np.isfinite(x) else None


def _twice(est: dict, with_prior, options) -> dict:
    """`est` (of the normals alone) for a prior aligned by ``prior_fit``: the route runs on the
    normals alone, then with the prior, whose problem `with_prior` (None: not fitted) is
    planned too (with `options`): the larger peak and its route, the two times summed."""
    if with_prior is None:
        return est
    second = estimate(with_prior, "dgp", **(options or {}))
    out = dict(second) if second["bytes"] >= est["bytes"] else dict(est)
    out["bytes"] = max(est["bytes"], second["bytes"])
    out["route"] = second["route"]
    out["fits"] = out["bytes"] <= out["limit"]
    if est.get("seconds") and second.get("seconds"):
        out["seconds"] = [est["seconds"][0] + second["seconds"][0],
                          est["seconds"][1] + second["seconds"][1]]
    else:
        out["seconds"] = None
    factorized = [e["bytes_factorized"] for e in (est, second) if e.get("bytes_factorized")]
    if factorized:
        out["bytes_factorized"] = max(factorized)
    return out


def _jump_grazing(problem) -> dict:
    """How many more normals `--discontinuities` (dgp) treats as grazing, and how many fewer
    (the camera's default drops them, the route keeps them: an orthographic camera's cos 85
    deg): that route uses ``MethodInfo.jump_grazing`` on every camera; and how many it drops
    as isolated (``MethodInfo.jump_isolated``, found first: not counted as grazing)."""
    from . import methods

    route = methods.get("dgp")
    eps = route.jump_grazing
    if eps is None:
        return {}
    iso = None if route.jump_isolated is None else problem.isolated(route.jump_isolated)
    steep = problem.extras.get("steep_isolated")  # (the default route's, left out already)
    if iso is not None and steep is not None:
        iso = iso | steep
    camera = problem.counts.get("outlier_eps", eps)
    # (the route's edge-on share applies where its threshold is the larger one)
    between = problem.grazing_between(camera, eps, without=iso,
                                      share=route.jump_grazing_share if camera < eps else None)
    share = route.jump_grazing_share
    kept = 0 if share is None else problem.edge_on_kept(eps, share, without=iso)
    return {"outlier_eps": float(eps), "more_grazing": between if camera < eps else 0,
            "fewer_grazing": between if camera > eps else 0, "grazing_kept": kept,
            "isolated": 0 if iso is None else int(iso.sum()),
            "isolated_rule": route.jump_isolated}


def _file_facts(src: Path) -> dict:
    """Format, pixel type and bit depth of the file as stored (without decoding it)."""
    from .io.dataset import normals_file

    f = normals_file(src) if src.is_dir() else src  # (normal_map.*, or Normal_gt.mat)
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
        elif ext == ".pfm":  # (a review: no facts were given for it; its header alone)
            from .io.images import _pfm_header

            with open(f, "rb") as fh:
                channels, width, height, _, _ = _pfm_header(fh.read(256), f, "normals")
            facts.update(dtype="float32", encoding="as stored",
                         stored_shape=[height, width] + ([3] if channels == 3 else []))
        elif ext in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(f) as t:
                page = t.pages[0]  # (the series' shape: a two-channel page's was (W, 2))
                facts.update(dtype=str(page.dtype), stored_shape=list(t.series[0].shape),
                             encoding="v / max * 2 - 1" if page.dtype.kind == "u"
                             else "as stored")
        elif ext == ".exr":
            import OpenEXR

            from .io.images import _library_quiet

            # (what the library prints is dropped: the reading after this one passes it on,
            # or puts it in its error)
            with _library_quiet(), OpenEXR.File(str(f), separate_channels=True) as e:
                ch = e.channels()
                facts.update(channels=sorted(ch),
                             dtype=sorted({str(np.asarray(v.pixels).dtype) for v in ch.values()}),
                             encoding="as stored")
    except Exception:  # the reader reports unreadable files properly
        pass
    return facts


def _frame_guess(n, mask, K, problem=None, *, frame=None, layout=None,
                 field: bool = False, gradient_frame: str = "xy", rotation=None,
                 normal_range: str = "signed") -> dict:
    """Whether the frame the map was read in looks right, from the view direction and the
    integrability; ``likely`` says what to change. `layout`: the other gradient layout, where
    the field was read in the wrong one (:class:`facetlift.frames.LayoutWarning`), which
    ``likely`` then names: its normals are in no frame that a flip would fix. `rotation`
    (3, 3): world-space normals' turn into the camera frame, in facetlift's axes
    (:func:`facetlift.frames.rotation_in_facetlift`). `normal_range`: the range the map was
    read with (an ``"unsigned"`` map still in [0, 1] is not told to give that flag). `field`:
    the normals were made from a gradient field in the layout `gradient_frame`, which
    ``as_read`` names instead of a normal frame."""
    from . import frames

    guess = _frame_evidence(n, mask, K, problem, frame=frame, field=field, rotation=rotation,
                            normal_range=normal_range)
    if field:  # (no normal frame was given: "read as opengl (x,y,z)" was a normal map's words)
        g = frames.gradient_frame(gradient_frame)
        guess["as_read"] = f"a gradient field, --gradient-frame {g} ({frames.GRADIENT_FRAMES[g]})"
    if layout == "swapped":  # (p and q exchanged: "--gradient-frame swapped" was advised,
        # which is no frame, a review)
        guess["likely"] = ("p and q exchanged: give them in the other order (--gradients Q "
                           "P; integrate_gradients(q, p))")
    elif layout is not None:
        guess["likely"] = (f"the other gradient layout: --gradient-frame {layout} "
                           f"(gradient_frame='{layout}')")
    return guess


#: Where the field's own relative curl is above :data:`facetlift.frames.FLIP_MIN_CURL` and the
#: y-flipped field's is below this multiple of it, ``info`` says the frame check cannot tell.
UNTOLD = 1.5


def _try(frame, axes: str, field: bool) -> str:
    """:func:`facetlift.frames.flip_advice` for a map read in `frame`, or for a gradient field
    (`field`)."""
    from . import frames

    return frames.flip_advice(frames.GRADIENT_FIELD if field else frame, axes)


def _facing_says_as_read(problem, away: float):
    """``(x share, y share)``: the shares of the clear normals that would face away from a
    pinhole camera with x or with y negated, where both are above
    :data:`facetlift.problem.BACKFACING_FRAME_HINT` and the map as read faces it (`away` at
    most that): the facing then says the frame is right. None otherwise (no camera)."""
    from .frames import EDGE_ON
    from .problem import BACKFACING_FRAME_HINT, _flip_shares

    cam = problem.camera
    if not cam.perspective or not away <= BACKFACING_FRAME_HINT:
        return None
    r, c = problem.domain.pixels
    nf = problem.normals
    with np.errstate(invalid="ignore"):
        cos = cam.view_cosine(r, c, nf, unit=True)
    clear = np.asarray(problem.known, bool) & (np.abs(cos) > EDGE_ON)
    shares = _flip_shares(cam, r, c, nf, clear)
    if not shares or min(shares["x"], shares["y"]) <= BACKFACING_FRAME_HINT:
        return None
    return shares["x"], shares["y"]


def _frame_evidence(n, mask, K, problem=None, *, frame=None, field: bool = False,
                    rotation=None, normal_range: str = "signed") -> dict:
    """:func:`_frame_guess` from the normals alone."""
    from . import frames
    from .problem import prepare

    name = "opengl" if frame is None else frame
    guess = {"as_read": f"{name} ({frames.axis_string(frame)})"}
    inside = frames._inside(n, mask)
    if inside is not None and len(inside):
        raw, stored = inside, frames.from_facetlift(inside, frame)
        inside = frames.rotate(inside, rotation)  # (as the camera sees them)
        away = frames.facing_away(inside)
        guess["facing_away"] = away
        # the encodings first, on the values as stored (before the frame: a [0, 1] map read
        # in a camera frame faces away, and the frame was blamed; frames.checked's order)
        scale = frames.encoded_scale(stored)
        if scale is not None:
            guess["likely"] = (f"undecoded {8 if scale == 255 else 16}-bit values as floats: "
                               f"decode with v / {scale} * 2 - 1")
            return guess
        # (all >= 0, x and y around the encoding's 0.5: a flat view has them all near 0)
        if stored.min() >= 0 and float(np.median(stored[:, :2])) > 0.25:
            guess["likely"] = (
                "[0, 1]-encoded floats after --normal-range unsigned's decoding (2 * v - 1): "
                "was it encoded twice?" if normal_range == "unsigned" else
                "[0, 1]-encoded floats: read with --normal-range unsigned, which decodes "
                "2 * v - 1")  # (the flag given told to give it, a review)
            return guess
        missing = frames.z_not_stored(raw) if away is not None and away > 0.5 else None
        if missing is not None and missing[1]:  # (a two-channel map: no frame to suggest)
            guess["likely"] = (f"z not stored (z is {float(raw[0, 2]):g} everywhere: a "
                               "two-channel map, BC5 or RG): read it with --normal-encoding xy, "
                               "which rebuilds z = sqrt(1 - x^2 - y^2) (docs/recipes.md)")
            return guess
        if away is not None and away > 0.5:
            what = ("z flipped" if away > frames.SWAP_RANGE[1] else
                    "z flipped or channels in another order")
            guess["likely"] = (f"{what}: the normals face away from the viewer as read "
                               f"({frames.facing_hint(frame, inside, rotation is not None)})")
            return guess
    if problem is None:
        try:
            with recording(record=False, action="ignore"):
                problem = prepare(frames.rotate(n, rotation), mask, K=K)
        except ValueError:
            # (no usable normal to judge by: said, not "?", a user's check)
            guess["likely"] = "cannot tell (no usable normal to judge the frame by)"
            return guess
    curls = frames.flip_curls(problem)
    guess.update(curls)  # ("noise" taken out by describe: its own line)
    # (the verdict on the better flip, named, as integrate's warning: info called a map "not
    # by the margin" that integrate called far more integrable flipped, a user's check; where
    # the two flips tie, the silhouette names the axis: a DSINE map, x flipped, was told y
    # first, and following that advice made it inside-out, a user's check)
    f = frames.flip_assessment(problem, curls)
    a, b, says, verdict = f["a"], f["b"], f["says"], f["verdict"]
    own = curls["curl"]
    flipped = min(curls["curl_y_flipped"], curls["curl_x_flipped"])
    from .problem import BACKFACING_FRAME_HINT

    away = f["facing_away"]  # (the share prepare's warning takes)
    if verdict == "claim" and says[a] == "in" and says[b] == "out":
        guess["likely"] = (f"{a} flipped: far more integrable with {a} negated, and at the "
                           f"object's silhouette the normals point into it along {a} (try "
                           f"{_try(frame, a, field)}; your estimator's frame is in "
                           "docs/conventions.md)")
    elif verdict == "claim" and not f["decided"]:
        # (about as integrable flipped either way and no silhouette: both named alike, as
        # integrate's warning; a user's DSINE map with K was told y first, the wrong one)
        guess["likely"] = ("x or y flipped: far more integrable with either negated, and no "
                           f"silhouette in view says which (try {_try(frame, a, field)} or "
                           f"{_try(frame, b, field)}: inside-out from each other; keep the one "
                           "whose surface bulges toward the camera where the object does; your "
                           "estimator's frame is in docs/conventions.md)")
    elif verdict == "claim":
        guess["likely"] = (f"{a} flipped: far more integrable with {a} negated (try "
                           f"{_try(frame, a, field)}, or {_try(frame, b, field)}: inside-out "
                           "from each other; your estimator's frame is in docs/conventions.md)")
    elif f["inside_out"]:  # (as integrate's check: frames.flip_check)
        guess["likely"] = ("as read, or inside-out: at the mask's edge the normals point into "
                           "the object along x and y (if that edge is its silhouette, try "
                           f"{_try(frame, 'xy', field)}; a concave surface masked alone, a "
                           "bowl's inside or a crater, does this too)")
    elif verdict == "hint":
        other = ("" if f["decided"] else
                 f" or {_try(frame, b, field)} (inside-out from each other: no silhouette in "
                 "view says which)")
        guess["likely"] = (f"as read, or {a} flipped: more integrable with {a} negated, not by "
                           "the margin that says so (correlated errors on a flat view do this "
                           f"too); if the surface looks wrong, try {_try(frame, a, field)}"
                           f"{other}")
    else:
        mend = problem.counts.get("facing_away_flip")
        axial = problem.counts.get("facing_away_axial")
        if axial is not None:  # (as prepare's warning: an orthographic map given a camera)
            guess["likely"] = (f"no camera, or a narrower one: {away:.0%} of the normals face "
                               f"away from the camera's rays, yet {1 - axial:.1%} face the "
                               "viewer along the optical axis, as an orthographic view's map "
                               "does (try --orthographic, or check the K or --fov; "
                               + (f"or x and y both flipped, which the facing cannot tell "
                                  f"apart: try {_try(frame, 'xy', field)})"
                                  if problem.counts.get("facing_away_both") else
                                  "a flip would not mend it)"))
        elif mend is not None:  # (as prepare's warning: a y-down map over a floor, an audit)
            which = "x and y" if mend[0] == "xy" else mend[0]
            guess["likely"] = (f"{which} flipped: {away:.0%} of the normals face away from "
                               f"the camera as read, {mend[1]:.1%} with {which} negated (try "
                               f"{_try(frame, mend[0], field)}; your estimator's frame is in "
                               "docs/conventions.md)")
        elif away > BACKFACING_FRAME_HINT:
            # (the channel orders that face them, named as integrate names them: info said
            # only "channels in BGR order?", an audit)
            swapped = (frames._swapped_orders(frame, inside)
                       if rotation is None and inside is not None and len(inside)
                       and frames.SWAP_RANGE[0] <= away <= frames.SWAP_RANGE[1] else None)
            guess["likely"] = (f"another frame? {away:.0%} of the normals face away from the "
                               "camera (a world-frame export, or channels in BGR order?): "
                               + (f"{swapped}; " if swapped else "")
                               + f"see docs/conventions.md; "
                               f"{frames.world_note(rotation is not None)}")
        elif (own > frames.FLIP_MIN_CURL and flipped < UNTOLD * own
              and (facing := _facing_says_as_read(problem, away)) is not None):
            # (with a camera the facing can tell where the curls cannot: a review's right room
            # with --fov 60 was told "as read, or y flipped", and its y-down version was caught
            # by the facing, 22 % away)
            guess["likely"] = (f"as read (consistent with the camera: {away:.1%} of the "
                               f"normals face away from it as read, {facing[0]:.0%} with x "
                               f"negated, {facing[1]:.0%} with y negated)")
        elif own > frames.FLIP_MIN_CURL and flipped < UNTOLD * own:
            # (a texture artist's y-down detail map, slopes under 1 deg in 8 bits, was called
            # consistent: as read 43.9 % RMS, with --y-down 1.7 %)
            guess["likely"] = ("as read, or y flipped: the check cannot tell (about as "
                               "integrable either way: slopes near the quantisation step, "
                               "noise, or planes meeting at creases and jumps); if the map's "
                               "y runs the other way, name that frame: "
                               f"{_try(frame, 'y', field)}")
        else:
            guess["likely"] = "as read (consistent)"
    return guess
