"""The hints of a finished integration job: where a smooth result bends across depth jumps
(:func:`jump_hint`), or a dense prior tore the mesh into many pieces (:func:`torn_hint`).
``facetlift integrate`` prints them as ``hint:`` lines and keeps them in its ``--json``
object's ``hints``; ``facetlift batch`` keeps them in each record's ``hints``
(:func:`job_hints`). They name the command line's flags. No click here."""

from __future__ import annotations

from . import methods


def job_hints(job, info: dict, camera_warned: bool = False, field: bool = False) -> list[str]:
    """The hints that apply to a job's result whose ``Surface.info`` is `info` (JSON-ready, as
    a job's record keeps it), in the order ``integrate`` prints them; `camera_warned`: the
    run warned that its camera looks wrong (the record's ``camera_warned``)."""
    return [h for h in (jump_hint(job, info, camera_warned, field), torn_hint(job, info))
            if h is not None]


#: Share of the facets deviating by more than 10 degrees from their normals above which a
#: smooth result gets the hint to keep depth jumps (:func:`jump_hint`). Measured on the
#: discontinuity benchmark's 63 renders at exact, 8-bit and 3-deg-noise normals, smooth dgp
#: (192 scene-conditions, 2026-12-04): above it on all 84 where the discontinuity route more
#: than halves the error (0.50-63 %; the DiLiGenT bear 0.49 %, 18x better with jumps) and on
#: every one where it helps by 20 % or more; below on the flat, nearly jump-free views (at
#: most 0.1 %, with noise); 12 of the 165 hinted are ones where that route is worse by more
#: than 1 % (fandisk orthographic, featuretype@left, mountain@left, wide mountain@front).
#: And only where the field is not integrable to within JUMP_HINT_CURL (its relative curl,
#: ``info["integrability"]["curl"]``): the demo's creased roofs deviate by 10 deg on 0.7 % of
#: the facets at their creases, but their exact field is integrable (0.004) and has no jump
#: to keep; every render above with jumps is at 0.04 or more with exact normals (0.12 and
#: more where the discontinuity route halves the error), the DiLiGenT bear at 0.22.
JUMP_HINT_SHARE, JUMP_HINT_CURL = 0.002, 0.02
#: Where the flipped field's relative curl is below this fraction of the field's own (and the
#: own above :data:`facetlift.frames.FLIP_MIN_CURL`), short of the frame check's hint
#: (:data:`facetlift.frames.FLIP_HINT`), the jump hint names the frame first: a second audit's
#: y-down brick texture read 0.94 as given and 0.74 flipped (0.79; a sampling artefact since
#: mended, :func:`facetlift.frames._strided`), was told only of --discontinuities, and
#: following it gave an inside-out result (61 % height error, 0.6 % in its frame). In their
#: right frame the discontinuity benchmark's 80 cached renders (exact, 8-bit, 3-deg noise,
#: smoothed noise, 2 % outliers; 2026-12-06) came to 0.88 at the least (wide tray_bottom
#: with outliers), 0.94 without outliers.
JUMP_FRAME_RATIO = 0.85
#: Share of the facets deviating by more than 10 degrees above which the jump hint no longer
#: names the jumps: bent-across jumps deviate that widely nowhere in the discontinuity
#: benchmark (63 % at most, JUMP_HINT_SHARE's note; a few scenes of several meshes on a table
#: 33-35 % at 128 x 153), while a K in the wrong units does (the DiLiGenT bear with K / 100,
#: fx 37.7 px: 92 %, and a hint to flip the frame, a fresh user's review).
JUMP_HINT_WIDE = 0.75


def jump_hint(job, info: dict, camera_warned: bool = False,
              field: bool = False) -> str | None:
    """The hint where a smooth integration by a method that can keep depth
    jumps, but did not (its own default, e.g. bini's, or the option given), deviates from its
    normals in the way bent-across jumps do (:data:`JUMP_HINT_SHARE`); not where the map
    seems read in the wrong frame (that warning explains the deviation); None where there is
    no hint. Where the field is more integrable flipped (:data:`JUMP_FRAME_RATIO`) it names
    the frame to try first, and the jumps only if the frame is right. Where the run warned
    that its camera looks wrong (`camera_warned`: a :class:`facetlift.CameraWarning`, a K in
    mm or a principal point 10x off on the DiLiGenT bear) it points at that warning instead,
    and where the deviation is wider than jumps make (:data:`JUMP_HINT_WIDE`) at the input
    as a whole: neither names the jumps."""
    from . import frames

    share = info.get("deviation_over_10")
    method = methods.REGISTRY.get(info.get("method") or job.method)
    if share is None or not share > JUMP_HINT_SHARE or method is None:
        return None
    if "discontinuities" in job.options:
        return None
    if method.options().get("discontinuities") or info.get("solver") == "discontinuous":
        return None  # (bini keeps jumps by default: the flag would change nothing, a review)
    if (job.options or {}).get("pad") == "none":
        return None  # (a periodic integration, a tileable texture's: its heights interpolated
        # to the corners deviate on narrow bevels without a jump, and dgp is not periodic;
        # docs/recipes.md's own tileable recipe was sent to dgp, worse there, an audit)
    prior = info.get("prior")
    prior = prior if isinstance(prior, dict) else {}  # (regularization's is its option's name)
    if prior.get("relief_warned"):
        return None  # (a prior in other units explains it, warned about: an audit)
    ic = info.get("integrability") or {}
    if ic.get("other_layout"):  # (a gradient field in the other layout: its warning's advice
        return None  # stands alone, not beside "--discontinuities keeps them", an audit)
    own = ic.get("curl")
    # (None where a curl could not be measured, e.g. a map mostly without normals: a review
    # saw the run end in an internal error here after its depth was written)
    flipped = min((v for v in (ic.get("curl_y_flipped"), ic.get("curl_x_flipped"))
                   if v is not None), default=float("inf"))
    if own is not None and (frames.flip_verdict(own, flipped) is not None
                            or not own >= JUMP_HINT_CURL):
        return None  # (a wrong frame explains it; an integrable field has no jump to keep)
    head = f"{share:.1%} of the facets deviate from their normals by more than 10 deg"
    if camera_warned:  # (a wrong K bends the whole surface: --discontinuities was named to a
        # K in mm and to a principal point 10x off, beside the K warning, a fresh user's review)
        return (f"{head}: a camera that is not the image's bends a whole surface so; mend the "
                "camera the warning names first (--K, --fov; docs/conventions.md, 'Perspective "
                "cameras: K') and run again: depth jumps are named then if the deviation stays")
    # (a prior with samples on over a quarter of the usable normals: a dense map, whose own
    # noise or units bend the surface too)
    dense = prior.get("samples", 0) > 0.25 * max(int(info.get("input", {}).get("usable", 1)), 1)
    frame = frame_first(job, ic, field) if own is not None else None
    if share > JUMP_HINT_WIDE:
        # (a dense prior in other units pulls the whole surface off its normals: an audit's
        # orthographic run with a prior in mm was told of frame, camera and encoding only)
        fit = "" if prior.get("fit") else ", or --prior-fit for one known up to scale"
        units = ("; and the dense depth prior: its depths in the units of the pixel size "
                 f"(--pixel-size) for an orthographic map, metric z-depth with --K{fit} "
                 "(docs/fusion.md, 'A prior in other units, or a relative depth given as "
                 "metric')") if dense else ""
        return (f"{head}{frame or ''}: far more than bent-across depth jumps make (63 % at "
                "most on the discontinuity benchmark's scenes, the DiLiGenT bear's 0.5 %), so "
                "the input is off as a whole: check its frame (facetlift info guesses it; "
                "docs/conventions.md lists the frames of common sources), its camera (a "
                "perspective map needs its own K, in pixels: --K or --fov) and its encoding"
                + units)
    from .problem import BACKFACING_FRAME_HINT, BLURRED_PRIOR_WEIGHT

    if (info.get("input") or {}).get("facing_away", 0.0) > BACKFACING_FRAME_HINT:
        return None  # (the facing-away warning asks about the frame or BGR order, which
        # explains the deviation: a BGR map was also told to keep jumps, an audit)
    # (with a dense prior its own noise bends the surface alike: a fresh user's sensor depth,
    # 1 mm of noise at weight 0.5, deviated 11 deg, and only the jumps were named)
    # (with --prior-blur given, not that again: an audit)
    # (a tenth of the weight used: "e.g. 0.01" was named to a run at 0.01, an audit; with a
    # blur, its sigma too, which a coarse map's misjudged size bends the surface with)
    blurred = bool(info.get("prior_blur"))
    given = getattr(job, "prior_weight", None)
    weight = float(given) if given is not None else (BLURRED_PRIOR_WEIGHT if blurred else 1.0)
    lower = f"a lower --prior-weight, e.g. {weight / 10:.3g}"
    also = ("" if not dense else
            f" (or the dense prior's own noise or blur: {lower}, or another --prior-blur: about "
            "1.1 times the factor a coarse map was enlarged by; docs/fusion.md)" if blurred else
            f" (or the dense prior's own noise: {lower}, or --prior-blur; docs/fusion.md)")
    # (a method that cannot keep jumps: the one that can, named; poisson and the others at
    # the same deviation got no word, a user's check)
    # ("cannot" was wrong for alpha_surface, whose graph cuts itself, and best on the bear: a
    # reproduction)
    keep = ("--discontinuities keeps them" if method.discontinuities else
            f"--method dgp --discontinuities keeps them ({method.name!r} takes no "
            "--discontinuities)")
    if frame is None:
        hint = (f"{head}, as where a smooth surface bends across depth jumps: {keep} "
                f"(slower; docs/perspective.md){also}")
    else:
        hint = (f"{head}{frame}. If the frame is right, a smooth surface bent across depth "
                f"jumps does this too: {keep} (slower; docs/perspective.md){also}")
    return hint


#: Share of the mask's pixels that the pieces a dense prior's cuts add must pass (and
#: :data:`TORN_MIN` pieces) for :func:`torn_hint`: the DiLiGenT bear with a sensor's 1 mm of
#: noise at weight 0.01 and 0.1 had 138 and 243 pieces (0.3 and 0.6 % of its 40,670 pixels,
#: errors 0.050 and 0.132 mm), with 3 mm at 0.1 8,757 (21 %, 1.575 mm; docs/fusion.md); an
#: audit's 960 x 540 room with a monocular disparity fitted and given pixel by pixel 21,808
#: (5 %), the same prior blurred (--prior-blur 3) 817.
TORN_SHARE = 0.02
TORN_MIN = 200


def torn_hint(job, info: dict) -> str | None:
    """The hint where --discontinuities with a dense prior given pixel by
    pixel tore the mesh into many pieces (:data:`TORN_SHARE`): the prior's noise, or a
    network's blur at the silhouettes, cut as depth jumps; the summary said only how many
    pieces (an audit: 21,808 without a word). None otherwise."""
    cut = info.get("cut_pieces") or 0
    prior = info.get("prior")
    if info.get("solver") != "discontinuous" or not isinstance(prior, dict):
        return None
    pixels = int((info.get("input") or {}).get("pixels") or 0)
    usable = max(int((info.get("input") or {}).get("usable") or 1), 1)
    dense = (prior.get("samples") or 0) > 0.25 * usable
    if not dense or info.get("prior_blur") or cut < max(TORN_MIN, TORN_SHARE * pixels):
        return None
    hint = (f"the cuts split the mesh into {cut} more pieces ({cut / max(pixels, 1):.1%} of the "
            "mask's pixels): a dense prior given pixel by pixel is cut where its noise or its "
            "blur disagrees with the normals. A coarse or blurred map (a monocular network's) "
            "wants --prior-blur SIGMA (its weight then 0.003), a noisy sensor a lower "
            "--prior-weight (0.001-0.01), and a band of foreground and background blended at "
            "the silhouette zero weight (--prior-weight-map); docs/fusion.md")
    from .problem import relief_says_relative

    if (info.get("projection") == "perspective" and not prior.get("fit")
            and relief_says_relative(prior.get("relief_ratio"))):
        # (a review: a monocular network's 0..1 depth given with --fov, torn into 8,167 pieces)
        hint += (". A relative depth (a monocular network's 0..1 map, a disparity) needs "
                 "--prior-fit affine or disparity")
    return hint


def frame_first(job, ic: dict, field: bool = False) -> str | None:
    """:func:`jump_hint`'s words on the frame where the field's relative curls `ic`
    (``info["integrability"]``) say it is more integrable flipped (:data:`JUMP_FRAME_RATIO`),
    naming the flag to try as the frame check does (:func:`facetlift.frames.flip_advice`);
    None otherwise."""
    from . import frames

    if ic.get("other_layout"):  # (the layout warning's advice stands alone: frames.read_in)
        return None
    own = ic["curl"]
    if ic.get("curl_y_flipped") is None or ic.get("curl_x_flipped") is None:
        return None  # (not measured: no flip to name)
    a, b = frames.flip_order(ic)
    flipped = ic[f"curl_{a}_flipped"]
    if not (own > frames.FLIP_MIN_CURL and flipped < JUMP_FRAME_RATIO * own):
        return None
    # (`field`: the record's gradient_field, a .mat of p and q too, whose field was told to
    # try --normal-frame directx, which a gradient field refuses, an audit)
    read = frames.GRADIENT_FIELD if field or getattr(job, "gradients", None) else getattr(
        job, "normal_frame", None)
    try_ = frames.flip_advice(read, a)
    if not frames.flip_decided(ic) and read != frames.GRADIENT_FIELD:
        try_ = (f"{try_} (or {frames.flip_advice(read, b)}: the two flips give surfaces "
                "inside-out from each other; keep the one that bulges where the object does)")
    field = read == frames.GRADIENT_FIELD
    like = (", as a map whose y runs down (DirectX's, most game engines') read as y up does"
            if a == "y" and not field else "")
    return (f", and the {'field' if field else 'map'} is more integrable with {a} flipped "
            f"(relative curl {own:.2f} as given, {flipped:.2f} flipped; short of the frame "
            f"warning's margin): check its frame first{like}: try {try_}; docs/conventions.md "
            "lists the frames of common sources")
