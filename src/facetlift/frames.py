"""Normal-map frames and encodings: what the numbers in a normal map mean, and the checks that
catch a map whose meaning was guessed wrong.

facetlift's own frame is x right, y up, z toward the viewer (:mod:`facetlift.conventions`).
Other sources store normals in other frames; a *frame* names the source's axes in facetlift
terms, either by one of the names in :data:`FRAMES` or as an axis string:

``"x,-y,-z"``
    facetlift x = the source's x, facetlift y = minus the source's y, facetlift z = minus the
    source's z, where the source's x, y, z are its first, second and third channels (R, G, B)
    after decoding. A string may also permute the channels (``"y,-x,z"``: facetlift x is the
    source's second channel). Every axis appears once.

=====================  ============  ===============================================
name                   axis string   the source stores
=====================  ============  ===============================================
``opengl`` (default)   ``x,y,z``     x right, y up, z toward the viewer (DiLiGenT, BiNI)
``directx``/``y_down`` ``x,-y,z``    x right, y down, z toward the viewer
``opencv``             ``x,-y,-z``   x right, y down, z away from the viewer (camera frame)
=====================  ============  ===============================================

docs/conventions.md maps common sources (Blender, Unreal, DSINE, Omnidata, Marigold, ...) to
these flags.

Encodings
    Integer normal maps (uint8, uint16) store ``v = (n + 1) / 2 * max``; :func:`decode` inverts
    that (``n = v / max * 2 - 1``) and marks pixels whose decoded length lies outside
    :data:`ENCODED_LENGTH_RANGE` (background fill) as NaN. :func:`checked` does the same for
    arrays handed to :func:`facetlift.integrate`, with a warning, and refuses float maps that
    look [0, 1]-encoded (every component in [0, 1] and lengths that are not 1) or that face away
    from the viewer, naming the fix. Only pixels inside the mask are inspected. The encodings
    are checked first, on the values as given (before the frame is applied, which negates
    axes): a [0, 1]-encoded map read in a camera frame faces away, and the frame was blamed.

    A float map that stores ``(n + 1) / 2`` in [0, 1] (as many renderers and networks write
    EXR, float TIFF or .npy) is read with the range ``"unsigned"`` of :data:`NORMAL_RANGES`
    (``--normal-range unsigned``): :func:`decode_unsigned` decodes it as ``2 v - 1`` before
    anything else, and refuses an integer map or one with negative components.

    A two-channel map (BC5, "RG", the ``"xy"`` of :data:`NORMAL_ENCODINGS`) stores x and y
    alone; :func:`decode_xy` reads them and rebuilds z facing the viewer. Read as an ``"xyz"``
    map, its one-valued blue channel is refused or warned about, naming the encoding
    (:func:`z_not_stored`).

After a solve, :func:`flip_check` compares how integrable the field is as given and with y or x
flipped, and warns when a flip is far more consistent; at an object's silhouette
(:func:`silhouette`) it also tells which axis is wrong, and an inside-out map (both axes
negated: integrable, so no curl can tell) by the normals pointing into the object there.
"""

from __future__ import annotations

import contextlib
import contextvars
import re

import numpy as np

from ._warnings import warn
from .errors import FrameHint, FrameWarning

#: Named frames -> axis strings (see the module docstring).
FRAMES = {
    "opengl": "x,y,z",
    "directx": "x,-y,z",
    "dx": "x,-y,z",
    "unreal": "x,-y,z",
    "y_down": "x,-y,z",
    "y-down": "x,-y,z",
    "gl": "x,y,z",
    "opencv": "x,-y,-z",
}

#: Decoded integer pixels whose vector length lies outside this range are not normals (NaN).
ENCODED_LENGTH_RANGE = (0.5, 1.5)

#: A decoded 8/16-bit normal is unit length to within its quantisation (8 bits: 0.7 %); a
#: warning where more than :data:`UNIT_SHARE` of them are off by more than this.
UNIT_TOLERANCE, UNIT_SHARE = 0.03, 0.01

#: Integer pixel types decoded as ``v / max * 2 - 1``.
ENCODED_DTYPES = (np.uint8, np.uint16)

#: A float map with at least this many pixels in the mask is checked for a [0, 1] encoding.
ENCODING_CHECK_PIXELS = 64

#: A far more integrable flipped field: its relative curl below this fraction of the field's
#: (the warning says the frame is probably wrong).
FLIP_RATIO = 0.5
#: Between :data:`FLIP_RATIO` and this fraction the warning is a hint to check the surface
#: (added 2026-12-03). A user's y-down render of an object with many occlusions had 0.84 as
#: read and 0.52 flipped (0.62) and drew nothing; on the discontinuity benchmark's 187 renders
#: read with y flipped (exact, 8-bit, 3-deg white noise), half caught 102 and three quarters
#: 142. In their right frame those renders never came below 0.93, nor did the three real maps
#: of ``shared/data`` (1.0-3.5); but a review found right-frame maps that do: nearly flat
#: views with strongly correlated normal errors (a plane with 10-deg noise smoothed over 64
#: px: 0.61-0.74 on 2 of 3 seeds at 512^2), the errors a network estimator makes. Such a map
#: gets the hint, not the claim.
FLIP_HINT = 0.75
#: :data:`FLIP_RATIO` for a gradient field's other layout (:func:`layout_check`).
LAYOUT_RATIO = 0.5
#: ... and the field's own relative curl above this (a clean field is left alone).
FLIP_MIN_CURL = 0.4

_AXIS = re.compile(r"^\s*([+-]?)\s*([xyz])\s*$")


def parse(frame, name: str = "normal_frame") -> tuple[tuple[int, int, int], np.ndarray]:
    """``(channels, signs)`` of a frame: facetlift axis ``i`` = ``signs[i] * source[channels[i]]``.

    Parameters
    ----------
    frame : str or None
        A name in :data:`FRAMES` (case-insensitive), an axis string such as ``"x,-y,-z"``, or
        None for the facetlift frame.
    name : str
        The argument that gave it, for the error.

    Raises
    ------
    ValueError
        Neither a known name nor three comma-separated axes using each of x, y, z once.
    """
    text = "x,y,z" if frame is None else frame
    if not isinstance(text, str):
        raise ValueError(f"`{name}` must be a frame name or an axis string; got {frame!r}")
    text = FRAMES.get(text.strip().lower(), text)
    parts = [_AXIS.match(t) for t in text.lower().split(",")]
    if len(parts) != 3 or not all(parts) or {p.group(2) for p in parts} != {"x", "y", "z"}:
        raise ValueError(
            f"`{name}` must be one of {sorted(FRAMES)} or an axis string such as "
            f"'x,-y,-z' (each of x, y, z once, optionally negated); got {frame!r}"
        )
    channels = tuple("xyz".index(p.group(2)) for p in parts)
    signs = np.array([-1.0 if p.group(1) == "-" else 1.0 for p in parts])
    return channels, signs


def axis_string(frame) -> str:
    """The axis string of `frame`, e.g. ``"x,-y,-z"`` for ``"opencv"``."""
    return _axes(*parse(frame))


def _axes(channels, signs) -> str:
    """The axis string of a parsed frame (:func:`parse`)."""
    return ",".join(("-" if s < 0 else "") + "xyz"[c]
                    for c, s in zip(channels, signs, strict=True))


def is_identity(frame, name: str = "normal_frame") -> bool:
    """True when `frame` is the facetlift frame (nothing to convert)."""
    channels, signs = parse(frame, name)
    return channels == (0, 1, 2) and bool((signs > 0).all())


def negated(frame, axes: str) -> str:
    """The frame that reads a source as `frame` does and then negates the facetlift `axes`
    (e.g. ``"yz"``): its name where one has that axis string, else the axis string. What to
    suggest when a map read in `frame` comes out flipped."""
    channels, signs = parse(frame)
    for a in axes:  # (parse returns a new array)
        signs["xyz".index(a)] *= -1
    text = _axes(channels, signs)
    for name in ("opengl", "directx", "opencv"):
        if FRAMES[name] == text:
            return name
    return text


def flag(frame) -> str:
    """How to ask for `frame` on the command line and in the API, for a message: the default
    frame is asked for by giving none."""
    if is_identity(frame):
        return "the default frame (no --normal-frame, normal_frame=None)"
    text = frame if frame in FRAMES else axis_string(frame)
    sep = "=" if text.startswith("-") else " "
    return f"--normal-frame{sep}{text} (normal_frame='{text}')"


#: The frame normals handed to :func:`checked` in facetlift's frame were read from
#: (:func:`read_in`): only for the hints of its messages; :data:`GRADIENT_FIELD` when they
#: were made from a gradient field.
_READ_IN: contextvars.ContextVar = contextvars.ContextVar("facetlift_read_in", default=None)


#: The `normal_range` (:data:`NORMAL_RANGES`) a job read the normals handed to :func:`checked`
#: with (:func:`read_in`): a map that looks [0, 1]-encoded is then told of the job's option
#: (--normal-range); None for arrays from Python, which are told to decode them.
_RANGE_READ: contextvars.ContextVar = contextvars.ContextVar("facetlift_range", default=None)


#: :func:`read_in`'s mark for normals made from a gradient field (p, q): no normal frame
#: applies, the hints name the slopes instead.
GRADIENT_FIELD = "gradient field"


#: The other gradient layout :func:`layout_check` named for the field being integrated
#: (:func:`read_in`'s `layout`), None where it named none.
_LAYOUT_NAMED: contextvars.ContextVar = contextvars.ContextVar("facetlift_layout",
                                                               default=None)


@contextlib.contextmanager
def read_in(frame, *, layout: str | None = None, normal_range: str | None = None):
    """Within it, normals given to :func:`checked` were converted already from a source in
    `frame` (e.g. by a reader): a map that faces away gets a hint relative to `frame`, not a
    suggestion of the frame the user already gave. `layout`: for a gradient field
    (:data:`GRADIENT_FIELD`), the other layout :func:`layout_check` named (its ``"suggested"``):
    :func:`flip_check` then stays silent (a field turned by 90 degrees is not mended by a
    slope's sign, and a run told both "try --gradient-frame rowcol" and "negate q" was told two
    contradictory things, a review). `normal_range`: the range a job read the map with
    (:data:`NORMAL_RANGES`), whose option a [0, 1]-encoded map is told of; None leaves the
    enclosing one (none: arrays from Python)."""
    token = _READ_IN.set(frame)
    named = _LAYOUT_NAMED.set(layout)
    ranged = None if normal_range is None else _RANGE_READ.set(normal_range)
    try:
        yield
    finally:
        if ranged is not None:
            _RANGE_READ.reset(ranged)
        _LAYOUT_NAMED.reset(named)
        _READ_IN.reset(token)


def reading() -> str | None:
    """The frame given to the enclosing :func:`read_in` (:data:`GRADIENT_FIELD` for normals
    made from a gradient field), None outside one."""
    return _READ_IN.get()


def to_facetlift(normals: np.ndarray, frame) -> np.ndarray:
    """(..., 3) normals in `frame` -> the facetlift frame (a new array unless the identity)."""
    if is_identity(frame):
        return normals
    channels, signs = parse(frame)
    return normals[..., list(channels)] * signs


def from_facetlift(normals: np.ndarray, frame, name: str = "normal_frame") -> np.ndarray:
    """(..., 3) facetlift normals (or points) -> `frame`: the inverse of
    :func:`to_facetlift`."""
    if is_identity(frame, name):
        return normals
    channels, signs = parse(frame, name)
    out = np.empty_like(normals, dtype=np.result_type(normals, float))
    out[..., list(channels)] = normals * signs
    return out


def mirrors(frame, name: str = "frame") -> bool:
    """Whether `frame` is left-handed relative to facetlift's (its axis map's determinant is
    -1: ``directx``, one axis negated): a mesh written in it needs its faces reversed to keep
    them facing the viewer."""
    channels, signs = parse(frame, name)
    odd = sum(channels[i] > channels[j] for i in range(3) for j in range(i + 1, 3)) % 2
    return bool((np.prod(signs) < 0) != bool(odd))


def resolve(frame, y_down: bool, name: str = "frame") -> str | None:
    """One frame from a `frame` argument (called `name` in the message) and the older
    ``y_down`` flag (its alias)."""
    if not isinstance(y_down, (bool, np.bool_)):  # ("yes" was taken as True, a review)
        raise ValueError(f"`y_down` must be True or False; got {y_down!r}")
    if not y_down or frame is None:
        return "directx" if y_down else frame
    (ch, sg), (ch_dx, sg_dx) = parse(frame, name), parse("directx")
    if ch == ch_dx and (sg == sg_dx).all():
        return frame
    raise ValueError(
        f"`y_down` (the frame 'directx') conflicts with `{name}` {frame!r}: give one of them"
    )


# --------------------------------------------------------------------------------------------
# normals given in world space: a rotation into the camera frame

#: How far ``R R^T`` may be from the identity (largest entry) for `R` to count as a rotation
#: (:func:`check_rotation`): a matrix written out to 6 decimals is orthonormal to about 1e-6.
ROTATION_TOLERANCE = 1e-3


def check_rotation(matrix, name: str = "normal_rotation") -> np.ndarray:
    """`matrix` checked as a rotation: a (3, 3) float array, the upper-left 3x3 of a 3x3, 3x4
    or 4x4 matrix (a camera pose's translation is not needed to turn normals).

    Parameters
    ----------
    matrix : array_like
        A proper rotation, for :func:`facetlift.integrate`'s ``normal_rotation`` the one from
        world to the camera frame the normals are to be read in (``n_cam = R @ n_world``).
    name : str
        The argument (or flag and file) that gave it, for the errors.

    Raises
    ------
    ValueError
        Another shape, non-finite or non-numeric entries, a 4x4 whose bottom row is not
        0 0 0 1 (a pose written column by column: the inverse rotation, said so), a matrix
        that is not orthonormal (within :data:`ROTATION_TOLERANCE`: a scaled camera's pose, a
        projection matrix) or a reflection (determinant -1), each naming `name` and what was
        found.
    """
    try:
        m = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a 3x3 rotation matrix (or a 3x4 / 4x4 pose, of "
                         f"which the upper-left 3x3 is used) of numbers; got "
                         f"{type(matrix).__name__}") from None
    if m.shape not in ((3, 3), (3, 4), (4, 4)):
        raise ValueError(f"`{name}` must be a 3x3 rotation matrix, or a 3x4 or 4x4 pose of "
                         f"which the upper-left 3x3 is used; got shape {m.shape}")
    R = m[:3, :3]
    if not np.isfinite(R).all():
        raise ValueError(f"`{name}` has non-finite entries in its rotation (the upper-left "
                         f"3x3): {R.tolist()}")
    unit = np.array([0.0, 0.0, 0.0, 1.0])
    if m.shape == (4, 4) and not np.allclose(m[3], unit, rtol=0, atol=ROTATION_TOLERANCE):
        # (a pose stored column by column, read row by row: its 3x3 is the inverse rotation,
        # a rotation too, which nothing after this would catch)
        got = ", ".join(f"{v:g}" for v in m[3])
        raise ValueError(
            f"`{name}`: a 4x4 pose's bottom row is 0 0 0 1; got [{got}]: "
            + ("its last column is 0 0 0 1, so the pose was written column by column (as "
               "OpenGL, glm and three.js's matrix.elements store it) and read row by row: "
               "transpose it (its upper-left 3x3 as read is the inverse rotation)"
               if np.allclose(m[:, 3], unit, rtol=0, atol=ROTATION_TOLERANCE) else
               "it is no pose (a projection matrix?): give the camera's rotation, or its "
               "pose with the translation in the last column"))
    off = float(np.abs(R @ R.T - np.eye(3)).max())
    if off > ROTATION_TOLERANCE:
        s = np.linalg.svd(R, compute_uv=False)
        raise ValueError(
            f"`{name}` is not a rotation: R R^T differs from the identity by up to {off:.3g} "
            f"(tolerance {ROTATION_TOLERANCE:g}; R's singular values are {s.min():.4g} to "
            f"{s.max():.4g}, a rotation's are all 1). A scaled camera object's matrix "
            "(Blender's matrix_world with a scale)? Give its rotation alone (in Blender "
            "matrix_world.to_quaternion().to_matrix()); a projection matrix K [R | t] is not a "
            "pose either")
    if np.linalg.det(R) < 0:
        raise ValueError(
            f"`{name}` is a reflection (determinant -1), not a rotation: it flips an odd "
            "number of axes. Give the proper rotation, and name the axes your normals or "
            "camera negate as the frame (normal_frame, --normal-frame: e.g. 'opencv' for y "
            "down and z away, or an axis string such as 'x,-y,z')")
    return R.copy()


def axes_matrix(frame, name: str = "normal_frame") -> np.ndarray:
    """The (3, 3) signed permutation ``P`` with ``to_facetlift(n, frame) = P @ n``."""
    parse(frame, name)
    return np.array(to_facetlift(np.eye(3), frame)).T


def rotation_in_facetlift(R: np.ndarray | None, frame) -> np.ndarray | None:
    """A rotation `R` from world to the camera frame `frame` as the rotation that takes
    normals already converted from `frame` (:func:`to_facetlift`: the world vectors with
    `frame`'s axis map applied, as a reader gives them) to the camera's facetlift frame:
    ``P R P^T``, where ``P`` is `frame`'s axis map (:func:`axes_matrix`); None for None (no
    rotation: camera-frame normals)."""
    if R is None:
        return None
    P = axes_matrix(frame)
    return P @ R @ P.T


def rotate(normals: np.ndarray, R: np.ndarray | None) -> np.ndarray:
    """(..., 3) normals turned by `R` (``R @ n`` at every pixel; a new array; NaN stays NaN,
    a missing sample); unchanged where `R` is None. `R` must be a proper rotation
    (:func:`check_rotation`: a scaled matrix scaled the normals in silence, a review), and
    `normals` end in 3 components."""
    if R is None:
        return normals
    R = check_rotation(R, "R")
    n = np.asarray(normals, dtype=float)
    if n.ndim < 1 or n.shape[-1] != 3:
        raise ValueError(f"`normals` must be (..., 3) vectors; got shape {n.shape}")
    return np.einsum("ij,...j->...i", R, n)


#: Whether :func:`facetlift.integrate` was given a rotation (``normal_rotation``), for the
#: words of the facing-away warnings made where no argument says so (:func:`world_note`).
_ROTATED: contextvars.ContextVar = contextvars.ContextVar("facetlift_rotated", default=False)


@contextlib.contextmanager
def rotation_given(given: bool):
    """Within it, the normals checked were (`given`) or were not turned from world space by a
    rotation: :func:`world_note` words its question so."""
    token = _ROTATED.set(bool(given))
    try:
        yield
    finally:
        _ROTATED.reset(token)


def world_note(rotated: bool | None = None) -> str:
    """The facing-away messages' words on world-space normals: where no rotation was given
    (`rotated` False), that such normals need the camera's
    rotation; where one was, that it may be the wrong one or inverted (:func:`rotation_given`
    says which where `rotated` is None)."""
    rotated = _ROTATED.get() if rotated is None else rotated
    if rotated:
        return ("is the rotation given that of this view, and the right way round "
                "(--world-to-camera, normal_rotation=, takes world to camera; Blender's "
                "matrix_world is camera to world: --camera-to-world)?")
    return ("if the normals are in world space (a Blender Normal pass, a multi-view "
            "pipeline's), give the camera's rotation: --world-to-camera FILE or "
            "--camera-to-world FILE (normal_rotation=R, world to camera, in Python; "
            "docs/conventions.md)")


#: An 8-bit code that decodes next to 0 (127 or 128) is decoded as exactly 0 in the x or y
#: channel where it is a plateau of that channel's histogram (:func:`decode`): at least
#: ZERO_PLATEAU_SHARE of the pixels seen hold it, and at least ZERO_PLATEAU_RATIO times as
#: many as hold each of its two neighbouring codes.
ZERO_PLATEAU_SHARE, ZERO_PLATEAU_RATIO = 0.005, 8


def decode(pixels: np.ndarray, where=None, frame=None) -> np.ndarray:
    """uint8/uint16 pixels -> float64 normals ``v / max * 2 - 1``; NaN where the decoded
    length is outside :data:`ENCODED_LENGTH_RANGE` (background fill, not a normal). A warning
    where many of them (among `where`, (H, W) bool: the mask or alpha, where known) are
    longer than unit length (:data:`UNIT_TOLERANCE`): z not stored, or an sRGB curve; or,
    where more than :data:`NOISE_SHORT` as many are shorter, noise (lossy compression).

    8-bit flat areas (uint8 only): the component 0 falls exactly between two codes, 127 and
    128 (``0.5 * 255 = 127.5``); encoders write it as round(127.5) = 128 (some truncate to
    127), which decodes to +0.0039 (-0.0039), and every flat area tilts by that: an audit's
    1024^2 brick texture came out with 27 % RMS height error (13.5 % at 512^2) instead of
    about 1 %. A spike in a channel's histogram at one of these codes is a point mass at 0:
    the flat surfaces facing along an axis, which a continuous spread of normals (a sphere)
    never makes. So in the x and y channels, among the pixels seen (valid, inside `where`),
    a code 128 or 127 held by at least :data:`ZERO_PLATEAU_SHARE` of them and by at least
    :data:`ZERO_PLATEAU_RATIO` times as many as each neighbouring code is decoded as exactly
    0. A plateau at 127 says more: the encoder truncates, so every code ``v`` stands for
    ``[v, v + 1)`` and the whole map decodes as ``(v + 0.5) / 255 * 2 - 1`` (its plateau then
    0; with 127 alone read as 0, the sloped texels of a second audit's truncated brick texture
    kept half a code of bias, 2.7 % RMS height error against 0.57 %). Other maps decode bit for
    bit as ``v / 255 * 2 - 1``; 16-bit maps always do (their step, 3e-5, tilts little). The x
    and y channels are those the normals' `frame` (:func:`parse`) reads x and y from (a BGR
    map read with ``z,y,x`` kept its half-code tilt: x is its third channel, an audit)."""
    maxval = float(np.iinfo(pixels.dtype).max)
    n = pixels.astype(np.float64) / maxval * 2.0 - 1.0
    length = np.sqrt(np.einsum("...i,...i->...", n, n))
    lo, hi = ENCODED_LENGTH_RANGE
    bad = (length < lo) | (length > hi)
    seen = _seen(bad, where)
    channels = parse(frame)[0]
    if pixels.dtype == np.uint8:
        _zero_plateaus(n, pixels, seen, channels[:2])
    flat_z = _constant_z(pixels, channels, where)
    if flat_z is not None and np.mean(np.abs(length[_seen(np.zeros_like(bad), where)] - 1.0)
                                      > 2 * UNIT_TOLERANCE) <= FILL_OFF_UNIT:
        flat_z = None  # (unit vectors nearly all: planes of one slope each, a roof's, even
        # anti-aliased along its ridges, a review; a filled channel puts most texels off)
    n[bad] = np.nan
    # (longer only: averaging, resizing and noise shorten vectors, which renormalising fixes)
    off = length[seen] > 1.0 + UNIT_TOLERANCE
    longer = float(off.mean()) if off.size else 0.0
    gamma = blamed = None
    if longer > UNIT_SHARE:
        # (a texture artist's map with the blue channel fixed at 255, as two-channel bakes are
        # often filled, read as 'consistent' and lost 29 % of its height)
        picked = pixels[seen]
        picked = picked[:: max(1, len(picked) // GAMMA_SAMPLE)]  # (6 s at 4096^2: a review)
        gamma = _gamma_hint(picked.astype(np.float64) / maxval, longer)
        short = float(np.mean(length[seen] < 1.0 - UNIT_TOLERANCE))
        # (a stored z or a colour curve makes vectors longer; noise, a JPEG's above all, as
        # many shorter: a JPEG-compressed bear, 8 % longer and 13.5 % shorter, was asked
        # whether z was stored and told of --normal-encoding xy, a review)
        blamed = gamma is not None or short <= NOISE_SHORT * longer
    if flat_z is not None and not blamed:
        # (a two-channel map whose blue fill decodes between 0 and 1: its flat texels too
        # short, left out as fill, the rest bent; 31 % of a texture kept, 29.7 % RMS, and no
        # word, a texture artist's audit; 0 faces away and 255 is too long: said elsewhere)
        warn(f"the map's z channel holds one code, {flat_z}, at "
             "every pixel while x and y vary: is z stored? A two-channel map (BC5, RG) "
             f"stores x and y only, and its filled channel is not z: {REBUILD_Z}", FrameWarning)
    elif blamed:
        warn(f"{longer:.0%} of the decoded normals are longer than unit length (by more "
             f"than {UNIT_TOLERANCE:.0%}, median length {np.median(length[seen]):.3g}): "
             + (gamma or "is z stored (a blue channel fixed at one value, as two-channel maps "
                "are often filled, must be rebuilt as z = sqrt(1 - x^2 - y^2) first: "
                "--normal-encoding xy, encoding='xy' in facetlift.io.read_normals)?")
             + " facetlift renormalises each vector, which is right only where it points the "
             "right way", FrameWarning)
    elif blamed is not None:
        warn(f"the decoded normals' lengths are noisy: {longer:.0%} are longer than unit length "
             f"and {short:.0%} shorter (by more than {UNIT_TOLERANCE:.0%}; median length "
             f"{np.median(length[seen]):.3g}), as lossy compression (a JPEG, or a map once "
             "saved as one) or noise leaves them, not a stored z or a colour curve, which "
             "make them longer. facetlift renormalises each vector, but the directions keep "
             "that noise: read a losslessly saved original (PNG, TIFF, EXR) where there is "
             "one", FrameWarning)
    return n


#: :func:`decode`: the most vectors shorter than unit length, as a share of those longer, for
#: the longer ones to be blamed on a stored z (a filled blue channel: none shorter) rather than
#: on noise, which spreads them both ways (a JPEG's: 1.2-3.6 times as many shorter).
NOISE_SHORT = 0.25


#: How a normal map stores its normals: ``"xyz"`` (the default), x, y, z in its first three
#: channels (R, G, B); ``"xy"``, a two-channel map (BC5, "RG", as game engines compress
#: tangent-space maps), x and y in R and G alone, z rebuilt by :func:`decode_xy` and B, if
#: any, ignored.
NORMAL_ENCODINGS = ("xyz", "xy")


def _one_of(value, choices: tuple[str, ...], name: str, meaning: str) -> str:
    """`value` (None: the first of `choices`) lower-cased and checked against `choices`; a
    ValueError naming `name`, the choices and their `meaning` otherwise."""
    if value is None:
        return choices[0]
    if not isinstance(value, str) or value.strip().lower() not in choices:
        raise ValueError(f"`{name}` must be one of {list(choices)} ({meaning}); got {value!r}")
    return value.strip().lower()


def normal_encoding(encoding, name: str = "encoding") -> str:
    """`encoding` checked against :data:`NORMAL_ENCODINGS` (None: ``"xyz"``); a ValueError
    naming `name` and the choices otherwise."""
    return _one_of(encoding, NORMAL_ENCODINGS, name, "'xyz': x, y, z in R, G, B; 'xy': a "
                   "two-channel map, BC5 or RG, z rebuilt")


#: The range a float normal map's components are stored in: ``"signed"`` (the default), the
#: components themselves, in [-1, 1]; ``"unsigned"``, ``n01 = (n + 1) / 2`` in [0, 1], as many
#: renderers and networks write float maps (EXR, float TIFF, .npy), decoded as ``2 v - 1``
#: before anything else (:func:`decode_unsigned`). An 8/16-bit map is always decoded from its
#: integer range (``v / max * 2 - 1``): ``"unsigned"`` is refused for one.
NORMAL_RANGES = ("signed", "unsigned")


def normal_range(value, name: str = "normal_range") -> str:
    """`value` checked against :data:`NORMAL_RANGES` (None: ``"signed"``); a ValueError
    naming `name` and the choices otherwise."""
    return _one_of(value, NORMAL_RANGES, name, "'signed': components in [-1, 1]; 'unsigned': "
                   "float components stored in [0, 1] as (n + 1) / 2, decoded as 2 v - 1")


#: With ``normal_range="unsigned"``, a stored component below ``-UNSIGNED_SLACK`` is negative:
#: a map that holds any is refused as signed (:func:`decode_unsigned`). Less is rounding, or a
#: network's output not clipped to [0, 1], and decodes to within 2 % of -1.
UNSIGNED_SLACK = 0.01
#: ... unless at most this share of the components is negative, none below
#: ``-UNSIGNED_STRAY``: a [0, 1]-encoded map resampled with a cubic or Lanczos kernel rings a
#: little past 0 and 1 at its edges (an audit: a bicubic half-size map, 28 of 30k components
#: below 0, was refused as signed); a signed map has about half its x and y components
#: negative. The same bounds let :func:`_check_encoding` see such a map as [0, 1]-encoded.
UNSIGNED_STRAYS, UNSIGNED_STRAY = 0.005, 0.1


def decode_unsigned(values: np.ndarray, what: str, where=None, channels: int = 3,
                    name: str = "normal_range") -> np.ndarray:
    """(H, W, `channels`) float64 ``2 v - 1`` from the first `channels` of a float map `values`
    (H, W, C) stored in [0, 1] (:data:`NORMAL_RANGES` ``"unsigned"``), NaN where the decoded
    vector holds no normal, as :func:`decode` and :func:`decode_xy` mark integer pixels: with
    3 channels, a length outside :data:`ENCODED_LENGTH_RANGE` (black, white or mid-grey fill);
    with 2 (x, y alone, z rebuilt after), x, y longer than unit length by more than
    :data:`UNIT_TOLERANCE`. NaN stays NaN. `what` names the input in the messages (a path,
    with its argument), `where` ((H, W) bool: the alpha, or a mask given apart from the map)
    the pixels whose components are checked (every pixel where None; none where of another
    shape: a mask file of another size, which its reader's caller refuses naming the file,
    where a refusal of the fill outside it would mislead).

    Raises
    ------
    ValueError
        An integer map (always decoded from its integer range) or, naming `name` and their
        count, components below ``-UNSIGNED_SLACK`` (a signed map); with 3 channels, an 8/16-bit
        map's values as floats (:func:`encoded_scale`).
    """
    v = np.asarray(values)
    if v.dtype.kind != "f":
        bits = np.iinfo(v.dtype).bits if v.dtype in ENCODED_DTYPES else None
        kind = (f"is {'an' if bits == 8 else 'a'} {bits}-bit integer map, always decoded from "
                "its integer range (v / max * 2 - 1)" if bits is not None
                else f"has pixel type {v.dtype}")
        raise ValueError(f"{what}: `{name}` 'unsigned' applies to float maps stored in [0, 1]; "
                         f"this one {kind}: leave it out")
    v = v[..., :channels]
    w = None if where is None else np.asarray(where)
    inside = (v if w is None else v[w.astype(bool)] if w.shape == v.shape[:2]
              else np.empty((0, v.shape[-1]), v.dtype))
    with np.errstate(invalid="ignore"):
        negative = inside < -UNSIGNED_SLACK
    count = int(np.count_nonzero(negative))
    if count and not _strays(inside):  # (a resampled map's ringing: decoded as it is)
        finite = int(np.count_nonzero(np.isfinite(inside)))
        raise ValueError(
            f"{what}: `{name}` 'unsigned' says the map stores (n + 1) / 2 in [0, 1], but "
            f"{count} of its {finite} components are negative (down to "
            f"{float(np.min(inside[negative])):.3g}): it holds signed normals, n itself in "
            "[-1, 1]; leave the option out (or give 'signed')"
        )
    scale = None
    if v.shape[-1] == 3 and np.max(inside, initial=0.0, where=np.isfinite(inside)) > 1.0:
        rows = inside.reshape(-1, 3)
        rows = rows[np.isfinite(rows).all(axis=1)]
        # (R = G = B: a fill, black, white or grey, outside a mask file's inside)
        rows = rows[(rows[:, 0] != rows[:, 1]) | (rows[:, 1] != rows[:, 2])]
        scale = encoded_scale(rows.astype(np.float64))
    if scale is not None:  # (2 v - 1 of these is all fill, NaN: "no usable normal" said no
        # more; without the option the undecoded-integer check names them, a review)
        bits = 8 if scale == 255 else 16
        raise ValueError(
            f"{what}: `{name}` 'unsigned' says the map stores (n + 1) / 2 in [0, 1], but its "
            f"components reach {float(rows.max()):g}: they look like an undecoded {bits}-bit "
            f"normal map's values as floats (2 * v / {scale} - 1 is of unit length); decode it "
            f"first with n = v / {scale} * 2 - 1 (or pass the {bits}-bit integer image "
            "itself) and leave the option out"
        )
    n = v.astype(np.float64) * 2.0 - 1.0
    with np.errstate(invalid="ignore"):
        length = np.sqrt(np.einsum("...i,...i->...", n, n))
        if channels == 2:
            bad = length > 1.0 + UNIT_TOLERANCE
        else:
            lo, hi = ENCODED_LENGTH_RANGE
            bad = (length < lo) | (length > hi)
    n[bad] = np.nan
    return n


def decode_xy(values: np.ndarray, where=None, frame=None) -> np.ndarray:
    """(H, W, 3) normals in the map's own frame from an (H, W, C) map (C >= 2) that stores x
    and y alone in its first two channels (:data:`NORMAL_ENCODINGS` ``"xy"``), its other
    channels ignored: uint8/uint16 decoded as ``v / max * 2 - 1`` (8-bit zero plateaus as in
    :func:`decode`), floats as stored; z rebuilt as ``sqrt(max(0, 1 - x^2 - y^2))``, with the
    sign that faces the viewer once `frame` is applied (a two-channel map cannot store z's
    sign, and a tangent-space map faces out of its surface). An integer pixel whose x, y are
    longer than unit length (by more than :data:`UNIT_TOLERANCE`: black or white fill, 1.41)
    holds no normal and is NaN. `where` ((H, W) bool, the mask or alpha) selects the pixels
    the zero plateaus are counted on.

    Raises
    ------
    ValueError
        A `frame` that reads facetlift's z from the first or second channel, which hold x
        and y here.
    """
    channels, signs = parse(frame)
    if channels[2] != 2:
        raise ValueError(f"a two-channel ('xy') map stores x and y in its first two channels "
                         f"and z is rebuilt as the third, but the frame {axis_string(frame)!r} "
                         "reads z from the "
                         f"{('first', 'second')[channels[2]]}: give a frame whose z is the "
                         "third channel (e.g. 'y,x,z' swaps x and y)")
    v = np.asarray(values)
    n = np.empty(v.shape[:2] + (3,))
    encoded = v.dtype in ENCODED_DTYPES
    bad = None
    if encoded:
        n[..., :2] = v[..., :2] / float(np.iinfo(v.dtype).max) * 2.0 - 1.0  # (as decode)
        bad = np.einsum("...i,...i->...", n[..., :2], n[..., :2]) > (1.0 + UNIT_TOLERANCE) ** 2
        seen = _seen(bad, where)
        if v.dtype == np.uint8:
            _zero_plateaus(n, v, seen)
    else:
        n[..., :2] = v[..., :2]
    r2 = np.einsum("...i,...i->...", n[..., :2], n[..., :2])
    n[..., 2] = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    n[..., 2] *= signs[2]
    if bad is not None:
        n[bad] = np.nan
    return n


#: Share of a map's texels off unit length (by twice :data:`UNIT_TOLERANCE`) above which a z
#: channel of one code is taken for a two-channel map's fill (:func:`decode`).
FILL_OFF_UNIT = 0.25


def _constant_z(pixels: np.ndarray, channels, where) -> int | None:
    """The one code the z channel of the integer map `pixels` (stored in ``channels[2]``)
    holds at every pixel inside `where` (or at all), above 0 and below the type's largest
    (those decode to a normal facing away or too long, which other checks name), where x and
    y vary; None otherwise."""
    if pixels.ndim != 3 or pixels.shape[-1] < 3 or min(pixels.shape[:2]) < 2:
        return None
    z = pixels[..., channels[2]]
    inside = None if where is None else np.asarray(where)
    if inside is not None and inside.shape == z.shape:
        inside = inside.astype(bool)
        if inside.sum() < ENCODING_CHECK_PIXELS:
            return None
        z = z[inside]
        xy = [pixels[..., ch][inside] for ch in channels[:2]]
    else:
        if z.size < ENCODING_CHECK_PIXELS:
            return None
        xy = [pixels[..., ch] for ch in channels[:2]]
    first = z.flat[0]
    top = np.iinfo(pixels.dtype).max
    if not 0 < int(first) < top or not (z == first).all():
        return None
    return int(first) if any(a.min() != a.max() for a in xy) else None


def _seen(bad: np.ndarray, where) -> np.ndarray:
    """The pixels a decode's checks count: a valid length (not `bad`), inside `where` ((H, W)
    bool, the mask or alpha) where it is given with the map's shape."""
    where = None if where is None else np.asarray(where)
    return ~bad if where is None or where.shape != bad.shape else ~bad & where.astype(bool)


def _zero_plateaus(n: np.ndarray, pixels: np.ndarray, seen: np.ndarray,
                   channels=(0, 1)) -> None:
    """Set the x and y of `n` (the decoded uint8 `pixels`; stored in `channels`) to exactly
    0 where their code is
    a plateau at 128 or 127 among the `seen` pixels, or, where every plateau is at 127, decode
    every channel as a truncating encoder's, ``(v + 0.5) / 255 * 2 - 1`` (:func:`decode`). A
    128 in one channel and a 127 in the other is a rounding encoder's map with one channel
    inverted (OpenGL <-> DirectX by 255 - v): both plateaus are 0, the rest as decoded (read
    as truncated, every flat area tilted by a whole code, a review: 2 % -> 11 % RMS)."""
    k = int(np.count_nonzero(seen))
    if k == 0:
        return
    every = k == seen.size  # (then no mask to apply: a pass less per code)
    plateaus = {}
    for ch in channels:
        codes = pixels[..., ch]
        # (the four codes around 127.5 alone: a histogram of a 4096^2 map took 0.4 s)
        counts = {c: int(np.count_nonzero(codes == c if every else (codes == c) & seen))
                  for c in (126, 127, 128, 129)}
        for code in (128, 127):
            c = counts[code]
            if (c >= ZERO_PLATEAU_SHARE * k
                    and c >= ZERO_PLATEAU_RATIO * max(counts[code - 1], counts[code + 1])):
                plateaus[ch] = code
                break  # (both cannot be: each would hold 8 times the other)
    if plateaus and all(code == 127 for code in plateaus.values()):
        # (a truncating encoder: every code half a step low; in place, no float64 temporary
        # of the map's size)
        c3 = min(n.shape[-1], pixels.shape[-1])
        np.add(pixels[..., :c3], 0.5, out=n[..., :c3])
        n[..., :c3] *= 2.0 / 255.0
        n[..., :c3] -= 1.0
        return
    for ch, code in plateaus.items():
        n[..., ch][pixels[..., ch] == code] = 0.0


def grey_check(values: np.ndarray, where, what: str) -> None:
    """Refuse an (H, W, 3) image whose three channels are equal at every pixel among `where`
    ((H, W) bool: the mask or alpha where known; None: every pixel; non-finite pixels aside),
    with at least two levels: a grey image saved as RGB (a height map, a photo), not a normal
    map. Decoded, R = G = B is a vector along (1, 1, 1) or its opposite, or too short to be a
    normal: an audit's grey height map ran with ~30 % of it facing away and came out as
    garbage. A map where only some pixels are grey (a background fill) passes; so does one
    of a single level (one plane, or a fill that the valid-normals rule handles). `what`
    names the argument (and path) in the message."""
    v = np.asarray(values)
    if v.ndim != 3 or v.shape[-1] != 3 or v.dtype.kind not in "uif" or v.size == 0:
        return
    flat = v.reshape(-1, 3)
    sel, inside = None, " of the image"
    if where is not None:
        w = np.asarray(where)
        if w.shape == v.shape[:2]:
            sel, inside = w.reshape(-1).astype(bool), " inside the mask"
    def pick(rows):  # (the pixels of `rows` that count)
        a, s = flat[rows], None if sel is None else sel[rows]
        if v.dtype.kind == "f":
            fin = np.isfinite(a).all(axis=1)
            s = fin if s is None else s & fin
        return a if s is None else a[s]

    def grey(a):
        return bool(((a[:, 0] == a[:, 1]) & (a[:, 1] == a[:, 2])).all())

    # (a strided sample first: a normal map shows colour at once, and the full pass is made
    # only where every sampled pixel is grey)
    if not grey(pick(slice(None, None, max(1, flat.shape[0] // CHECK_SAMPLE)))):
        return
    picked = pick(slice(None))
    if not picked.size or not grey(picked) or picked[:, 0].min() == picked[:, 0].max():
        return
    raise ValueError(
        f"{what}: R = G = B at every pixel{inside}: a grey image (a "
        "height map?), not a normal map, which stores x, y, z in R, G, B (a flat area facing "
        "the viewer is (128, 128, 255), bluish). Give the normal map: a height or depth map "
        "is what facetlift makes from one"
    )


def _srgb_to_linear(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1.0 / 2.4) - 0.055)


#: The sRGB transfer curves tried on a map whose decoded normals are too long
#: (:func:`_gamma_hint`): (name in the message, function of the stored values in [0, 1], the
#: Python that undoes it).
GAMMAS = (
    ("sRGB-encoded (a colour-managed export, or one saved through a display profile)",
     _srgb_to_linear, "v = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)"),
    ("linearised by an sRGB decode (read as a colour texture)", _linear_to_srgb,
     "v = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)"),
)


#: :func:`_gamma_hint` looks at about this many of the map's pixels (evenly strided).
GAMMA_SAMPLE = 65_536


def _gamma_hint(v: np.ndarray, share: float) -> str | None:
    """The colour transfer that explains too-long normals, as a sentence, or None: the sRGB
    curve one way or the other (:data:`GAMMAS`) applied to the stored values `v` (k, 3) in [0,
    1] leaves at most a fifth of the share `share` too long (an audit: an 8-bit map through
    an sRGB curve, 80 % too long, was blamed on a missing z; 30x the depth error)."""
    for name, fix, code in GAMMAS:
        n = 2.0 * fix(v) - 1.0
        length = np.sqrt(np.einsum("ki,ki->k", n, n))
        if np.mean(length > 1.0 + UNIT_TOLERANCE) <= 0.2 * share:
            return (f"the map looks {name}: with its values v (0..1) first mapped by {code}, "
                    f"{np.mean(np.abs(length - 1.0) <= UNIT_TOLERANCE):.0%} of them decode to "
                    "unit length. Save normal maps without colour management (linear, "
                    "'Non-Color' in Blender), or convert the values so and decode them "
                    "yourself (n = 2 v - 1), passing floats.")
    return None


def checked(normals, mask=None, *, frame=None, name: str = "normals", rotation=None):
    """Normals as :func:`facetlift.integrate` receives them -> float normals in the facetlift
    frame, after the safety nets (see the module docstring).

    `rotation` (3, 3), where given, turns world-space normals into the camera frame `frame`
    (``R @ n``, :func:`check_rotation`): after the encoding checks, which look at the values
    as stored, and before the facing check, which looks at the camera's.

    Arrays that are not (H, W, 3) numbers pass through unchanged, for
    :func:`facetlift.prepare` to refuse with its own message.

    Warns
    -----
    FrameWarning
        uint8/uint16 input, decoded as ``v / max * 2 - 1``.

    Raises
    ------
    ValueError
        Other unsigned integer types; a grey image (R = G = B at every pixel inside the
        mask, :func:`grey_check`); a float map that looks [0, 1]-encoded or like an
        undecoded 8/16-bit image (values up to 255 or 65535); a map whose
        normals mostly face away from the viewer (a camera frame with z pointing away, or
        world-space normals); a bad `frame` or `rotation`.
    """
    parse(frame)
    turn = None if rotation is None else rotation_in_facetlift(check_rotation(rotation), frame)
    normals, hidden = masked_pixels(normals)
    try:
        n = np.asarray(normals)
    except Exception:
        return normals  # prepare() says what is wrong with it
    if n.ndim != 3 or n.shape[-1] != 3 or n.dtype.kind not in "uif" or n.size == 0:
        return normals
    if n.dtype.kind == "i":  # (signed integers are no decoded image's type: checked as the
        # floats they hold. An 8-bit map held as int after img.astype(int) went through as
        # raw 0..255 without a word, 2.0 degrees of mean deviation for a wrong surface, an
        # audit; int8 maps stored as n * 127 pass)
        n = n.astype(float)
    floats = n.dtype.kind == "f"
    grey_check(n, _where(mask, n.shape[:2], hidden), f"`{name}`")  # (before the decode's
    n = as_float_normals(n, name, mask, hidden, frame)  # warning)
    read = _READ_IN.get()
    field = read == GRADIENT_FIELD
    read = None if field else read  # (such normals never face away)
    # (the reader's frame, already applied, to undo for the values as stored; none where
    # `frame` is still to be applied)
    undo = read if is_identity(frame) else None
    read = read if is_identity(frame) else frame  # (the frame the values were stored in)
    # the encodings first, on the values as stored (before `frame`, or the reader's frame, is
    # applied: it negates axes): a [0, 1]-encoded map read with normal_frame='opencv' faced
    # away and was told to drop the frame before its encoding was named (an audit); with
    # 'directx' it was not refused at all
    sample = _inside(n, mask, sample=CHECK_SAMPLE)
    stored = None if sample is None else from_facetlift(sample, undo)
    if stored is not None and len(stored) and stored.min() >= -UNSIGNED_STRAY:  # (only then
        # can the whole map be encoded; a resampled one rings a little below 0)
        if floats:
            _check_encoding(from_facetlift(_inside(n, mask), undo), name)
        else:  # (an 8/16-bit array decoded here)
            check_integer_encoding(from_facetlift(_inside(n, mask), undo), f"`{name}`")
    if floats and mask is None:  # (after the encodings' own words; an 8/16-bit map's fill
        # is dropped by its decoding)
        kept = drop_fill(n, name)
        if kept is not n:
            n, sample = kept, _inside(kept, mask, sample=CHECK_SAMPLE)
    n = to_facetlift(n, frame)
    if mask is None and not field:  # (in the map's own camera frame: the fill is its (0, 0,
        # 1); a gradient field's zero slopes around an object are a height's ground, no fill)
        flat_fill_check(n, name)
    n = rotate(n, turn)
    if sample is not None:
        _check_facing(rotate(to_facetlift(sample, frame), turn), name, read,
                      rotated=turn is not None, decoded=not floats)
    return n


def _mask_pixels(mask, shape) -> np.ndarray | None:
    """(H, W) bool: the pixels of a given `mask` (nonzero and finite), None where it cannot
    be read as one of `shape` (prepare refuses it, with the words). The checks' one reading
    of a mask (:func:`_where` and :func:`_inside` each had a copy)."""
    try:
        m = np.asarray(mask)
    except Exception:
        return None
    if m.shape != shape or m.dtype.kind not in "biuf":
        return None
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(m), m, 0) != 0 if m.dtype.kind == "f" else m != 0


def _where(mask, shape, hidden=None) -> np.ndarray | None:
    """(H, W) bool: inside `mask` (nonzero and finite; None: every pixel) and not `hidden`;
    None where neither is given or the mask cannot be read (prepare refuses it)."""
    m = None if mask is None else _mask_pixels(mask, shape)
    if hidden is not None:
        m = ~hidden if m is None else m & ~hidden
    return m


#: The facing check looks at about this many mask pixels, evenly spaced.
CHECK_SAMPLE = 2**16


def _inside(n: np.ndarray, mask, sample: int | None = None) -> np.ndarray | None:
    """(k, 3) finite normals inside `mask` (None when `mask` cannot be read: prepare refuses),
    every pixel or about `sample` of them, evenly spaced."""
    m = None if mask is None else _mask_pixels(mask, n.shape[:2])
    if mask is not None and m is None:
        return None
    flat = n.reshape(-1, 3)
    if sample is not None and m is None:
        v = flat[:: max(1, flat.shape[0] // sample)]
    elif sample is not None:
        idx = np.flatnonzero(m)
        v = flat[idx[:: max(1, idx.size // sample)]]
    else:
        v = flat if m is None else n[m]
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(v).all(axis=1)
        if m is None:  # (no mask: the default one, finite non-zero normals; a background of
            keep &= (v != 0).any(axis=1)  # zeros must not outvote the object)
        return v[keep]


def encoded_scale(v: np.ndarray) -> int | None:
    """255 or 65535 where (k, 3) finite float vectors look like an 8/16-bit normal map that
    was not decoded (every component in [0, max] and ``2 v / max - 1`` of unit length on
    nine in ten), else None: an image read into floats and passed on as it is."""
    if len(v) < ENCODING_CHECK_PIXELS or v.min() < 0 or not 1 < v.max() <= 65535:
        return None
    scale = 255 if v.max() <= 255 else 65535
    d = v * (2.0 / scale) - 1.0
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    return scale if np.mean(np.abs(length - 1) < 0.05) > 0.9 else None


#: Share of the vectors whose ``2 v - 1`` is of unit length (within 0.05) below which a map
#: whose components lie in [0, 1] is taken for normals not of unit length, not for a [0, 1]
#: encoding (:func:`_check_encoding`): an encoded object covering 14 % of an image on a
#: white background reads 0.14, normals scaled by 1e-3 read 0.
UNSIGNED_UNIT_SHARE = 0.01


def _strays(v: np.ndarray) -> bool:
    """Whether the components `v` lie in [0, 1] but for strays: at most
    :data:`UNSIGNED_STRAYS` of the finite ones beyond ``UNSIGNED_SLACK`` outside it, none
    beyond :data:`UNSIGNED_STRAY` (a [0, 1]-encoded map as stored, or resampled)."""
    with np.errstate(invalid="ignore"):
        finite = v[np.isfinite(v)]
        if not finite.size:
            return False
        if finite.min() < -UNSIGNED_STRAY or finite.max() > 1.0 + UNSIGNED_STRAY:
            return False
        out = np.count_nonzero((finite < -UNSIGNED_SLACK) | (finite > 1.0 + UNSIGNED_SLACK))
    return out <= UNSIGNED_STRAYS * finite.size


def _unsigned_signature(v: np.ndarray) -> bool:
    """Whether the (k, 3) values `v` look [0, 1]-encoded: every component >= 0 (but a few
    strays), not of unit length, and ``2 v - 1`` of unit length for most of them."""
    if len(v) < ENCODING_CHECK_PIXELS or not _strays(v):
        return False
    with np.errstate(over="ignore", invalid="ignore"):
        length = np.sqrt(np.einsum("ij,ij->i", v, v))
        d = 2.0 * v - 1.0
        decoded = np.sqrt(np.einsum("ij,ij->i", d, d))
    if np.mean(np.abs(length - 1) > 0.05) < 0.5:
        return False  # unit normals that all face up and right: a tilted plane, say
    # (nor (n + 1) / 2: normals not of unit length, which prepare normalises; a map scaled by
    # 1e-3, or all components >= 0 at 0.8 of unit length, was refused as [0, 1]-encoded, an
    # audit. Not "half of them": an encoded object on a white or grey background, whose
    # 2 v - 1 is never of unit length, passed so, a review)
    return float(np.mean(np.abs(decoded - 1) < 0.05)) >= UNSIGNED_UNIT_SHARE


def check_integer_encoding(v: np.ndarray, name: str) -> None:
    """Refuse the normals `v` (k, 3) decoded from an 8/16-bit map (``v / max * 2 - 1``) that
    still look [0, 1]-encoded (:func:`_unsigned_signature`): encoded twice, or through a
    colour curve; --normal-range unsigned, the advice for a float map, is refused for them (a
    texture artist's sRGB map was sent from one refusal to the other, an audit)."""
    if _unsigned_signature(v):
        raise ValueError(
            f"{name}: decoded from its 8/16-bit values (v / max * 2 - 1), every component "
            "inside the mask still lies in [0, 1] and the vectors are not unit length: it looks "
            "encoded twice ((n + 1) / 2 stored, then encoded again) or saved through a colour "
            "curve (sRGB: a warning says so where it fits); decode it yourself, undoing that, "
            "and pass floats (--normal-range applies to float maps only)")


def _check_encoding(v: np.ndarray, name: str) -> None:
    scale = encoded_scale(v)
    if scale is not None:
        bits = 8 if scale == 255 else 16
        raise ValueError(
            f"`{name}` looks like an undecoded {bits}-bit normal map: every component inside "
            f"the mask lies in [0, {scale}] as given and 2 * v / {scale} - 1 is of unit "
            f"length; decode it first with n = v / {scale} * 2 - 1 (or pass the {bits}-bit "
            "integer image itself)"
        )
    if not _unsigned_signature(v):
        return
    read = _RANGE_READ.get()
    if read is None:  # (arrays from Python: facetlift.integrate has no option for it)
        fix = ("decode it first with n = 2 * v - 1 (or pass the 8/16-bit integer image itself; "
               "facetlift.io.read_normals(path, normal_range='unsigned') reads a float file "
               "stored so)")
    elif read == "unsigned":  # (2 v - 1 applied already, and still in [0, 1])
        fix = ("and that is after --normal-range unsigned's decoding (2 * v - 1): it may "
               "have been encoded twice")
    else:
        fix = ("if the file stores (n + 1) / 2, read it with --normal-range unsigned "
               "(normal_range='unsigned' in a facetlift.jobs.Job or facetlift.io.read_normals), "
               "which decodes n = 2 * v - 1, or decode it in Python and pass the array (or save "
               "the 8/16-bit integer image instead)")
    raise ValueError(
        f"`{name}` looks [0, 1]-encoded: every component inside the mask lies in [0, 1] as "
        "given (none negative, before any normal frame is applied; or all but a few strays "
        "within 0.1 of it, as a resampled map rings) and the vectors are not "
        f"unit length; {fix}. If these really are normals, normalise them to unit length"
    )


#: A normal counts as facing away (or toward) the viewer in the frame checks only beyond this
#: z component of its unit vector; those within it are edge-on as far as the map can say and
#: count neither way. An 8-bit map stores z = 0 as 128, which decodes to +-1/255: an indoor
#: scene's walls and floor seen by a pinhole camera (53 % of a user's map) made a correct
#: camera-frame map "face away" and refused it.
EDGE_ON = 0.02


def facing_away(v: np.ndarray) -> float | None:
    """The share of the (k, 3) normals `v` that face away from the viewer (``z`` below
    ``-EDGE_ON`` of their length), among those that are not edge-on; None where fewer than
    :data:`ENCODING_CHECK_PIXELS` are not edge-on."""
    with np.errstate(invalid="ignore", divide="ignore"):
        z = v[:, 2] / np.sqrt(np.einsum("ij,ij->i", v, v))
    away, toward = int(np.sum(z < -EDGE_ON)), int(np.sum(z > EDGE_ON))
    if away + toward < ENCODING_CHECK_PIXELS:
        return None
    return away / (away + toward)


def masked_pixels(a):
    """``(data, hidden)``: a numpy masked array's data and its (H, W) pixels with any channel
    masked (missing: NaN once decoded, an audit), or ``(a, None)``."""
    if not np.ma.isMaskedArray(a):
        return a, None
    hidden = np.ma.getmaskarray(a)
    return np.ma.getdata(a), (hidden.any(axis=-1) if hidden.ndim == 3 else None)


def native(a: np.ndarray) -> np.ndarray:
    """`a` in the machine's byte order (a copy only where it was not): big-endian ``>u2``
    compares unequal to uint16, and such a map was refused as "must be uint8 or uint16"
    (an audit)."""
    return a if a.dtype.isnative else a.astype(a.dtype.newbyteorder("="))


def as_float_normals(n: np.ndarray, name: str, mask=None, hidden=None,
                     frame=None) -> np.ndarray:
    """(H, W, 3) normals `n` as floats: a uint8/uint16 map decoded (:func:`decode`, its
    unit-length check inside `mask` and outside `hidden`) with a warning, other unsigned
    types refused; NaN at the `hidden` pixels (:func:`masked_pixels`). Shared by
    :func:`checked` and :func:`facetlift.io.write_normals`."""
    if n.dtype.kind == "u":
        n = native(n)
        if n.dtype not in ENCODED_DTYPES:
            raise ValueError(
                f"`{name}` has integer type {n.dtype}; integer normal maps must be uint8 or "
                "uint16 (decoded as v / max * 2 - 1): decode it yourself and pass floats"
            )
        warn(
            f"`{name}` is {n.dtype}: decoded as v / {np.iinfo(n.dtype).max} * 2 - 1 (the PNG "
            "encoding); pass float normals to silence this", FrameWarning
        )
        where = mask if hidden is None else (
            ~hidden if mask is None else np.asarray(mask).astype(bool) & ~hidden)
        n = decode(n, where=where, frame=frame)
    if hidden is not None and hidden.any():  # (after the decode: an 8-bit masked map, a review)
        n = np.array(n, dtype=float)
        n[hidden] = np.nan
    return n


#: Least share of the pixels one vector must fill, repeated exactly, for :func:`drop_fill` to
#: take it for a float map's background fill.
FILL_SHARE = 0.01


def drop_fill(n: np.ndarray, name: str = "normals") -> np.ndarray:
    """Float normals `n` (H, W, 3) with a background fill left out (NaN), with a warning
    naming it; a copy where anything is dropped. A fill is a vector found at a corner of the
    image that
    - has three equal components (a decoded black, white or mid-grey) or components +-1 (a
      pure colour's decoded codes 0 and max),
    - has a length outside :data:`ENCODED_LENGTH_RANGE` (not 0: a zero vector is a missing
      sample already),
    - is repeated exactly on at least :data:`FILL_SHARE` of the pixels, with as many other
      finite ones (a map of one vector is a plane), and
    - stands beside normals mostly of unit length (a decoded map's; an unnormalised map's
      faces of (-p, -q, 1) are no fill).
    A PNG's fill is dropped by its decoding (:func:`decode`); the same map decoded by the user
    (``v / 65535 * 2 - 1``, as BiNI's loader does) kept its white fill as normals (1, 1, 1):
    the DiLiGenT bear came out joined to a 45-degree plane, 17.6 mm off instead of 0.47, with
    no word but a hint to keep depth jumps (an audit; the rest of the rule from reviews)."""
    H, W = n.shape[:2]
    lo, hi = ENCODED_LENGTH_RANGE
    out, said, tried = n, [], set()
    for v in (n[0, 0], n[0, -1], n[-1, 0], n[-1, -1]):
        key = tuple(float(x) for x in v)
        if key in tried or not np.isfinite(v).all():
            continue
        tried.add(key)
        length = float(np.sqrt(sum(x * x for x in key)))
        grey = key[0] == key[1] == key[2]
        coded = all(abs(x) == 1.0 for x in key)
        if length == 0 or lo <= length <= hi or not (grey or coded):
            continue
        hit = (n[..., 0] == v[0]) & (n[..., 1] == v[1]) & (n[..., 2] == v[2])
        count = int(np.count_nonzero(hit))
        others = np.isfinite(out[..., 0]) & ~hit
        rest = int(np.count_nonzero(others))
        if count < FILL_SHARE * H * W or rest < FILL_SHARE * H * W:
            continue  # (too few; or everything: no normal would be left)
        with np.errstate(invalid="ignore", over="ignore"):
            around = np.sqrt(np.einsum("ij,ij->i", out[others], out[others]))
        if not np.mean((around >= lo) & (around <= hi)) >= 0.5:
            continue  # (the other normals not of unit length either: an unnormalised map)
        if out is n:
            out = np.array(n, dtype=float)
        out[hit] = np.nan
        said.append(f"{count} hold ({', '.join(f'{x:.4g}' for x in key)}), of length "
                    f"{length:.3g}")
    if said:
        warn(f"`{name}`: a background fill, no normals, was left out: of the {H * W} pixels "
             f"{'; '.join(said)} (a repeated vector at the image's corners; a unit normal has "
             "length 1); give a mask to choose the pixels yourself")
    return out


#: :func:`flat_fill_check`: the least share of the image that one flat vector, repeated exactly
#: in regions holding the image's corners, must fill to be asked about; the most that
#: the normals along its edge may face the viewer (median z of the unit normals there).
FLAT_FILL_SHARE, FLAT_FILL_RIM_Z = 0.2, 0.5
#: A flat vector's x and y at most this far from 0: one 8-bit code (128 decodes to +1/255,
#: 127 to -1/255; a 16-bit code's half-step is far below).
FLAT_FILL_XY = 1.0 / 255 + 1e-9
#: The most objects a fill is taken to stand around: at least half of the other normals lie
#: in this many connected pieces (a texture's bricks or rivets on a flat plate are dozens).
FLAT_FILL_PIECES = 4


def flat_fill_check(n: np.ndarray, name: str = "normals") -> None:
    """Warn where normals `n` (H, W, 3), in facetlift's frame and given without a mask, hold
    one and the same flat vector (x, y within :data:`FLAT_FILL_XY` of 0, z > 0: the encoding
    of a normal facing the camera, (128, 128, 255) in 8 bits) at all four corners of the
    image, and in the connected regions of it holding them over more than
    :data:`FLAT_FILL_SHARE` of the image, and the normals next to those regions are steep
    (median z below :data:`FLAT_FILL_RIM_Z`: an object's outline, its rim turning away from
    the viewer). Such a fill is a unit normal, so neither the decoding nor :func:`drop_fill`
    leaves it out, and the bear on a flat-blue background was integrated joined to one large
    plane: MADE 2.82 mm instead of 0.60, with "unusable normals: none" (a review). A surface
    that really faces the camera stays silent where it meets the rest along gentle slopes
    (BiNI's tent, its ground 65 % of the image in one 16-bit code, meets the roof at z 0.71),
    leaves a corner to another surface (a wall above a floor) or carries many raised
    features (a texture's bricks or rivets: fewer than half of the other normals in the
    :data:`FLAT_FILL_PIECES` largest connected pieces); a floor seen from above with a few
    objects standing on it is asked about: the normals cannot tell it from a fill. Not
    dropped, then: the warning names the count and asks for a mask."""
    H, W = n.shape[:2]
    if H < 3 or W < 3:
        return
    corners = [(r, c) for r in (0, H - 1) for c in (0, W - 1)]
    v = tuple(float(x) for x in n[0, 0])
    if not (np.isfinite(v).all() and abs(v[0]) <= FLAT_FILL_XY and abs(v[1]) <= FLAT_FILL_XY
            and v[2] > 0) or any(tuple(n[r, c]) != v for r, c in corners):
        return  # (a background holds every corner: a wall above a floor holds two)
    hit = (n[..., 0] == v[0]) & (n[..., 1] == v[1]) & (n[..., 2] == v[2])
    if np.count_nonzero(hit) <= FLAT_FILL_SHARE * H * W:
        return  # (too few in all: no component of them can be enough)
    from scipy import ndimage

    labels, _ = ndimage.label(hit)
    region = np.zeros((H, W), bool)
    for k in {int(labels[r, c]) for r, c in corners}:
        region |= labels == k
    count = int(np.count_nonzero(region))
    if count <= FLAT_FILL_SHARE * H * W:
        return
    others = ~hit & np.isfinite(n[..., 0]) & np.isfinite(n[..., 1]) & np.isfinite(n[..., 2])
    total = np.count_nonzero(others)
    if total < FILL_SHARE * H * W:
        return  # (a flat image, or nearly: a plane)
    pieces, _ = ndimage.label(others)
    sizes = np.sort(np.bincount(pieces.ravel())[1:])[::-1]
    if sizes[:FLAT_FILL_PIECES].sum() < 0.5 * total:
        return  # (a texture's many raised features on its flat plate: bricks, rivets)
    rim = np.zeros((H, W), bool)  # (the pixels beside the region, across an edge)
    rim[1:] |= region[:-1]
    rim[:-1] |= region[1:]
    rim[:, 1:] |= region[:, :-1]
    rim[:, :-1] |= region[:, 1:]
    rim &= others
    if np.count_nonzero(rim) < ENCODING_CHECK_PIXELS:
        return
    w = n[rim]
    with np.errstate(invalid="ignore", divide="ignore"):
        z = float(np.median(w[:, 2] / np.sqrt(np.einsum("ij,ij->i", w, w))))
    if z < FLAT_FILL_RIM_Z:  # (else gentle slopes meet it: a surface facing the camera)
        warn(f"`{name}`: {count} of the {H * W} pixels ({count / (H * W):.0%}), reaching the "
             f"image's corners, hold one and the same flat normal ({v[0] + 0:.3g}, {v[1] + 0:.3g}, "
             f"{v[2]:.3g}; (128, 128, 255) in 8 bits), and the normals along its edge are "
             f"steep (median z {z:.2f}), as along an object's outline: a background filled "
             "with the flat-normal colour? Without a mask it is integrated as a plane the "
             "object is joined to; give a mask (--mask FILE; mask= in Python) to integrate "
             "the object alone (a floor or wall that really faces the camera may stay)")


def _check_facing(v: np.ndarray, name: str, frame=None, rotated: bool = False,
                  decoded: bool = False) -> None:
    if len(v) < ENCODING_CHECK_PIXELS:
        return
    away = facing_away(v)
    if away is None or away <= 0.5:
        return
    said = (f"{away:.0%} of the normals inside the mask that are not edge-on face away from "
            "the viewer (z < 0)")
    missing = z_not_stored(v)
    if missing is not None:
        # (an audit: a two-channel map with B = 0 was told to try --normal-frame opencv,
        # after the decode's right warning that z is not stored)
        text, decoded = missing
        raise ValueError(
            f"`{name}`: {text}" + ("" if decoded else
                                   f". If z really is that value, {said}: "
                                   f"{facing_hint(frame, v, rotated)}")
        )
    # (a colour texture of a material folder, its albedo, was told to try a camera frame,
    # and written as a height 335 texels tall, a texture artist's audit; asked only of an
    # image read or decoded here: an array of unnormalised normals, albedo times n in a
    # camera frame, wants the frame hint alone, a review)
    colour = ""
    if decoded or reading() is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            median = float(np.nanmedian(np.sqrt(np.einsum("ij,ij->i", v, v))))
        if not 0.9 <= median <= 1.1:
            colour = (f". Or is it a normal map at all? Its vectors' median length is "
                      f"{median:.2g}, a normal map's is 1: a colour texture (an albedo), a "
                      "photo or a mask")
    raise ValueError(
        f"`{name}`: {said}, {facing_hint(frame, v, rotated)}, or see "
        f"docs/conventions.md for the frame of your source{colour}"
    )


#: How to read a map that stores x and y only, in the messages on one read as x, y, z
#: (docs/recipes.md says the same): the encoding's flag and argument, and for an array in
#: Python the rebuild itself.
REBUILD_Z = ("read it with --normal-encoding xy (facetlift.io.read_normals(path, "
             "encoding='xy') in Python), which rebuilds z; for decoded normals n in an array: "
             "n[..., 2] = np.sqrt(np.clip(1 - n[..., 0]**2 - n[..., 1]**2, 0, 1))")


def z_not_stored(v: np.ndarray) -> tuple[str, bool] | None:
    """``(sentence, decoded)`` where the z of the (k, 3) normals `v` (inside the mask, at
    least :data:`ENCODING_CHECK_PIXELS`) is one value while x and y vary: a two-channel map
    (BC5, RG) stores x and y only and fills its blue channel with one value (0 decodes to z =
    -1: every normal faces away), which is not z. The sentence says so and how to rebuild z
    (:data:`REBUILD_Z`). `decoded`: every x and y lies on the 16-bit code grid or its half
    steps (or is 0), as a decoded 8/16-bit map's do, where no other frame is worth naming;
    float normals built as (p, q, -1) also have a constant z, and get the frame hint after.
    None otherwise."""
    if len(v) < ENCODING_CHECK_PIXELS:
        return None
    z = v[:, 2]
    # (x and y each constant, a plane's: not "x and y vary", and no two-channel map; its one
    # normal facing away is a frame's z flipped, which the facing check names, an audit)
    if z.min() != z.max() or (np.ptp(v[:, 0]) == 0 and np.ptp(v[:, 1]) == 0):
        return None
    with np.errstate(invalid="ignore"):
        # (8-bit codes lie on it too: 65535 = 257 * 255; and the half steps, where a map read
        # as a truncating encoder's is decoded at the middle of each step, (v + 0.5) / 255,
        # which was told to try a frame that mends nothing, an audit of the docs' claims)
        f = (v[:, :2] + 1.0) / 2.0 * 131070.0
        decoded = bool(((np.abs(f - np.round(f)) < 1e-6) | (v[:, :2] == 0)).all())
    return (f"z is {float(z[0]):g} at every pixel inside the mask while x and y vary: is z "
            "stored? A two-channel map (BC5, RG) stores x and y only, and a blue channel filled "
            "with one value is not z (0 decodes to z = -1, facing away): z = sqrt(1 - x^2 - "
            f"y^2) must be rebuilt: {REBUILD_Z}", decoded)


#: A map read in some frame with about half its normals facing away has its channels in
#: another order (a flipped z turns nearly all away): between these shares the swapped
#: orders are tried (:func:`facing_hint`), and one is named where it leaves at most
#: SWAP_AWAY of them facing away.
SWAP_RANGE, SWAP_AWAY = (0.2, 0.8), 0.05


def _swapped_orders(frame, v: np.ndarray) -> str | None:
    """For normals `v` (k, 3) read in `frame` (facetlift frame): the frames with the source's
    channels in reverse order (BGR for RGB), with their y and z negated or not, that leave at
    most :data:`SWAP_AWAY` facing away, as a sentence; None where none does."""
    channels, signs = parse(frame)
    raw = from_facetlift(v, frame)
    found = []
    for flip in ("", "yz", "z"):
        cand = _axes(tuple(2 - c for c in channels), signs.copy())
        cand = negated(cand, flip) if flip else cand
        away = facing_away(to_facetlift(raw, cand))
        if away is not None and away <= SWAP_AWAY:
            found.append(f"{flag(cand)} leaves {away:.0%} facing away")
    if not found:
        return None
    return ("about half facing away is the sign of channels in another order, e.g. BGR "
            "(OpenCV's imwrite) rather than RGB: read with their order reversed, "
            + "; ".join(found) + " (the y sign is yours to check: the integrability warning "
            "says if it is wrong)")


#: Where the normals of a map that faces away would still face away by more than this share
#: with z negated (as every frame a hint names for a camera-frame map does; prepare's
#: :data:`facetlift.problem.BACKFACING_FRAME_HINT`), the hint asks about world-space normals
#: (:func:`world_note`); so it does after a channel order that faces them (a world-space map
#: seen along a world axis is one, its channels reversed).
WORLD_AWAY = 0.05


def facing_hint(frame, v: np.ndarray | None = None, rotated: bool = False) -> str:
    """What to try for a map that faces away from the viewer when read in `frame`: relative
    to the frame given (the flag the user gave is never the suggestion). With the normals `v`
    (k, 3) as read, about half of them facing away (:data:`SWAP_RANGE`) is tried against the
    reversed channel order first (an audit: an OpenCV-frame map saved in BGR order and read
    with --normal-frame opencv was offered two frames that both ran at 20 deg off). Where
    `rotated` (the normals were turned from world space) the rotation is asked about too;
    where not, and a channel order faces them or negating z would leave many facing away
    (:data:`WORLD_AWAY`), whether the normals are in world space (:func:`world_note`)."""
    if v is not None:
        away = facing_away(np.asarray(v, float))
        if away is not None and SWAP_RANGE[0] <= away <= SWAP_RANGE[1]:
            swapped = _swapped_orders(frame, np.asarray(v, float))
            if swapped is not None:  # (world-space normals too: a Blender camera looking
                # along world x, z up, faces the viewer with the channels reversed, a review)
                return f"{swapped}; else {facing_hint(frame)}; or {world_note(rotated)}"
        if rotated:
            return f"{facing_hint(frame)}; or {world_note(True)}"
        if away is not None and 1.0 - away > WORLD_AWAY:
            return (f"{facing_hint(frame)}; but with z negated {1.0 - away:.0%} would still "
                    f"face away: {world_note(False)}")
    if is_identity(frame):  # (y down, as OpenCV's, or y up with z alone negated, as
        # Blender's camera space through a Vector Transform node: only opencv was named, and
        # a user's Blender map then got an x-flip hint that turned it inside-out)
        return ("the map is probably in a camera frame with z pointing away: try "
                f"{flag('opencv')} (OpenCV, Omnidata, Metric3D: y down), or "
                f"{flag('x,y,-z')} (y up, as Blender's camera space); the frame check after "
                "the run says if y is wrong")
    # the camera frame's y and z flips, or z alone (the facing says only that z is wrong)
    return (f"as read in the frame {axis_string(frame)}; try that frame with y and z negated, "
            f"as a camera frame has them: {flag(negated(frame, 'yz'))}; or with z alone "
            f"negated: {flag(negated(frame, 'z'))}")


# --------------------------------------------------------------------------------------------
# after the solve: would a flipped field be more integrable?


#: :func:`relative_curl` looks at about this many usable pixels, in strips of two rows. 2^16
#: since 2026-12-03 (2^18 before, counted over the image rather than the object): on 512^2 and
#: 700^2 analytic maps with 1.7 deg of noise the ratios moved by 0.05-0.4 %, far inside the
#: warning's margin (:data:`FLIP_RATIO`), and the check costs a quarter (it was a third of a
#: 512^2 rectangle's run); an object in a larger image is now seen whole up to 2^16 pixels.
CURL_SAMPLE = 2**16


def relative_curl(problem, flip=(1.0, 1.0, 1.0), *, sample: int = CURL_SAMPLE) -> float:
    """Mean |curl| of the grid slopes over 2x2 blocks of usable pixels, relative to the mean
    size of the two cross derivatives: 0 for an integrable field, about 1 for noise; NaN
    without such a block.

    The normals are multiplied by `flip` first. Large objects are sampled: pairs of adjacent
    rows, one at a seeded random place in each run of rows (:func:`_cross_derivatives`), about
    `sample` usable pixels in all (every row pair up to `sample`).
    """
    return _curl_ratio(*_cross_derivatives(problem, flip, sample))


def _curl_ratio(dgx_dy, dgy_dx, sign: float = -1.0) -> float:
    """:func:`relative_curl` of the cross derivatives, the curl ``dgx_dy + sign dgy_dx``."""
    if dgx_dy is None:
        return float("nan")
    total = (np.abs(dgx_dy) + np.abs(dgy_dx)).sum()
    curl = np.abs(dgx_dy + sign * dgy_dx).sum()
    return float(curl / total) if total > 0 else 0.0


#: Seed of :func:`_strided`'s places: the same rows on every call, so a map's curls with and
#: without a flip are of the same pixels, and a run is repeatable.
STRIDE_SEED = 20261206


def _strided(n: int, step: int) -> np.ndarray:
    """Indices into `n` rows: one in each run of `step` (all where `step` is 1), at a seeded
    random place in its run (:data:`STRIDE_SEED`). Every `step`-th row locked onto a texture's
    period: a brick texture 64 rows high (a second audit's y-down map, 512^2, step 8) was seen
    only where its horizontal grooves are flat, where the cross derivatives that tell a flip
    are 0, and read 0.94 as given against 0.74 flipped, no warning; over all its rows, or
    these, 1.00 against 0.04."""
    if step <= 1:
        return np.arange(n)
    starts = np.arange(0, n, step)
    picks = starts + np.random.default_rng(STRIDE_SEED).integers(0, step, starts.size)
    return np.minimum(picks, n - 1)


def _cross_derivatives(problem, flip, sample, cosines: bool = False):
    """The cross derivatives ``d gx / dy`` and ``d gy / dx`` of the grid slopes of the normals
    times `flip` at every vertex between four usable sampled pixels (:func:`relative_curl`),
    or ``(None, None)`` where there is no such vertex; with `cosines`, also the mean squared
    view cosine of each vertex's four pixels (``(None, None, None)`` where none).

    The sample: every row that holds usable pixels, as does the row below it, with that row,
    where the object has at most `sample` usable pixels; else one such row in each run of
    `step` of them, at a seeded random place in its run (:func:`_strided`; a mask's period
    cannot hide the object from rows taken among its own, nor a texture's period from rows not
    evenly spaced). The four pixels of a block are found by their row-major index among the
    kept pixels: memory in proportion to them, not to the object's box."""
    d = problem.domain
    H, W = d.shape
    r, c = d.pixels  # (row-major)
    usable = np.asarray(problem.usable, bool)
    rows = np.unique(r[usable])
    rows = rows[np.isin(rows + 1, rows)]  # (those with a row below: a block's top row)
    none = (None, None, None) if cosines else (None, None)
    if rows.size == 0:
        return none
    used = int(np.count_nonzero(usable))  # (the object's pixels, not the image's)
    step = 1 if used <= sample else max(2, (2 * used) // sample)
    top = np.zeros(H + 1, bool)
    top[rows[_strided(rows.size, step)]] = True
    keep_row = top.copy()
    keep_row[1:] |= top[:-1]  # (each top row with the row below it)
    k = np.flatnonzero(keep_row[r] & usable)
    n = problem.normals[k] * np.asarray(flip, float)
    rk, ck = r[k], c[k]
    with np.errstate(invalid="ignore", divide="ignore"):  # (at the true columns: a pinhole's
        gx, gy = problem.camera.grid_slopes(rk, ck, n)  # slopes depend on them)
    lin = rk.astype(np.int64) * W + ck  # (ascending)
    tl = np.flatnonzero(top[rk] & (ck < W - 1))  # top-left pixels of the blocks

    def find(offset):
        want = lin[tl] + offset
        at = np.minimum(np.searchsorted(lin, want), lin.size - 1)
        return at, lin[at] == want

    (tr, ok1), (bl, ok2), (br, ok3) = find(1), find(W), find(W + 1)
    ok = ok1 & ok2 & ok3
    tl, tr, bl, br = tl[ok], tr[ok], bl[ok], br[ok]
    # at the vertex between four pixels; y points up (toward row 0)
    dgx_dy = (gx[tl] + gx[tr] - gx[bl] - gx[br]) / 2
    dgy_dx = (gy[tr] + gy[br] - gy[tl] - gy[bl]) / 2
    good = np.isfinite(dgx_dy) & np.isfinite(dgy_dx)
    if not good.any():
        return none
    if not cosines:
        return dgx_dy[good], dgy_dx[good]
    c2 = np.square(_slope_cosine(problem.camera, rk, ck, n))
    c2 = (c2[tl] + c2[tr] + c2[bl] + c2[br])[good] / 4
    return dgx_dy[good], dgy_dx[good], c2


def _slope_cosine(camera, rows, cols, n) -> np.ndarray:
    """The cosine ``c`` by whose square and first power an angular error of unit normals `n`
    grows into the error of the grid slopes along and across the tilt (:func:`normal_noise`):
    orthographically the view cosine, ``n_z``; through a pinhole the normal's dot product
    with the viewing ray of unit z, ``m . K^-1 (col, row, 1)`` (the slopes' denominator, the
    view cosine times the ray's length). A plane facing the optical axis has slopes that do
    not grow off the axis (``c`` = 1), where the view cosine there, the ray's angle's
    cosine, made a wide lens' noise read low (f = 60 px on 128^2: 1.25 deg for 2)."""
    c = camera.view_cosine(rows, cols, n, unit=True)
    rays = getattr(camera, "rays", None)
    return c if rays is None else c * np.linalg.norm(rays(rows, cols), axis=-1)


#: Median of the absolute value of a standard normal: :func:`normal_noise`'s median |curl| over
#: it is the spread of the curl's noise.
_HALF_NORMAL_MEDIAN = 0.6745


def normal_noise(problem, *, sample: int = CURL_SAMPLE) -> float:
    """The normals' angular noise in degrees, read from their curl (NaN without a 2x2 block
    of usable pixels).

    A surface's own normals are integrable however detailed, so their curl around every 2x2
    block of pixels is zero up to detail below the pixel; noise is not. A normal tilted from
    the view by an angle of cosine ``c`` turns an angular error along the tilt into a slope
    error ``1 / c^2`` times as large, one across it ``1 / c`` times (through a pinhole,
    ``c`` is the normal's dot product with the unit-z ray, :func:`_slope_cosine`): the
    curl of the slopes per pixel footprint times ``c^2 / sqrt((1 + c^2) / 2)`` (``c^2`` the
    block's mean) has the spread of a front view's, in radians. Its median over the blocks
    (about `sample` usable pixels, :func:`relative_curl`'s sample) over that of a standard
    normal's absolute value estimates the spread. Jumps and creases are lines and barely move a
    median. Measured on angular noise (:func:`facetlift.synthetic.add_angular_noise`,
    tests/test_frames.py): 0.94x the angle's spread on a front view, 0.92-1.01x on a plane seen
    at view cosine 0.5, 0.96-1.07x on the DiLiGenT bear's normals through its camera (its own
    normals 0.4 deg), 0.96-1.04x through a wide lens (f = 60 px on 128^2). On the development
    renders (docs/results.md, "A noise-aware dead zone", before the cross-tilt factor): exact
    normals 0.0-0.85 deg (an orthographic armadillo, detail below its pixels, 2.4), 8-bit about
    0.1 more, 3 deg of angular noise 2.3-3.0, noise smoothed over 8 px 0.2-0.7 (the local
    evidence of jumps is what it measures, and low frequencies do not disturb it).
    """
    return _noise(problem, _cross_derivatives(problem, (1.0, 1.0, 1.0), sample, cosines=True))


def curl_to_angle(c2):
    """The factor ``c^2 / sqrt((1 + c^2) / 2)`` that turns the curl of the slopes per pixel
    footprint around a 2x2 block into radians of the normals' angle (:func:`normal_noise`;
    also :func:`facetlift.methods.dgp.discontinuous.curl_seed`), `c2` the block's mean
    squared cosine: the slope error along the tilt grows as ``1 / c^2``, across it as
    ``1 / c``."""
    return c2 / np.sqrt(0.5 * (1.0 + c2))


def _noise(problem, parts) -> float:
    """:func:`normal_noise` from :func:`_cross_derivatives`' `parts` with their cosines."""
    dgx_dy, dgy_dx, c2 = parts
    if dgx_dy is None:
        return float("nan")
    curl = np.abs(dgx_dy - dgy_dx) * curl_to_angle(c2) / problem.camera.footprint()
    return float(np.degrees(np.median(curl) / _HALF_NORMAL_MEDIAN))


def flip_curls(problem) -> dict:
    """``{"curl", "curl_y_flipped", "curl_x_flipped", "noise"}``: :func:`relative_curl` of
    the field as given and with y and x flipped (for an orthographic camera from one set of
    cross derivatives: flipping y or x negates one slope, and the curl's sign with it), and
    :func:`normal_noise` (from the same cross derivatives as the field's own curl)."""
    from .camera import Orthographic

    parts = _cross_derivatives(problem, (1.0, 1.0, 1.0), CURL_SAMPLE, cosines=True)
    out = {"curl": _curl_ratio(*parts[:2])}
    if not isinstance(problem.camera, Orthographic):  # (a pinhole's are not odd in nx, ny)
        out["curl_y_flipped"] = relative_curl(problem, (1.0, -1.0, 1.0))
        out["curl_x_flipped"] = relative_curl(problem, (-1.0, 1.0, 1.0))
    else:
        out["curl_y_flipped"] = out["curl_x_flipped"] = _curl_ratio(*parts[:2], sign=1.0)
    out["noise"] = _noise(problem, parts)
    return out


def flip_verdict(own: float, flipped: float) -> str | None:
    """"claim" where the flipped field's relative curl `flipped` is below :data:`FLIP_RATIO`
    of the field's own `own`, "hint" where below :data:`FLIP_HINT`, else None (also where
    `own` is at most :data:`FLIP_MIN_CURL`: a clean field is left alone)."""
    if not own > FLIP_MIN_CURL:
        return None
    if flipped < FLIP_RATIO * own:
        return "claim"
    return "hint" if flipped < FLIP_HINT * own else None


#: The silhouette test (:func:`silhouette`): at an occluding contour the normal is edge-on and
#: points out of the object, so along x (y) the pixels on the mask's edge whose neighbour
#: across it lies outside the mask (inside the image: an object cut by the image's border is
#: no contour) and whose normal's x (y) component exceeds SILHOUETTE_TILT in size say which
#: way x (y) points. A share of at least SILHOUETTE_SURE of at least SILHOUETTE_MIN such
#: pixels agreeing with the outward direction says the axis is right, at most 1 -
#: SILHOUETTE_SURE that it is negated; between, nothing. Measured (2026-12-05): the DiLiGenT
#: bear 1.00 / 1.00 (x / y, 530 / 541 pixels), BiNI's human map 0.99 / 0.99 (311 / 361), its
#: tent none (a full-image map); of the discontinuity benchmark's 83 scenes 65 vote outward on both
#: axes, 4 on one (`mountain@oblique` y 0.50, a terrain's cut base: undecided), 14 on neither
#: (masks that fill the image or meet its border), none inward.
SILHOUETTE_TILT, SILHOUETTE_SURE, SILHOUETTE_MIN = 0.3, 0.7, 50
#: The silhouette ranks the two flips only where their relative curls are within this factor
#: of each other (a pinhole camera's differ where the map says which axis is wrong).
SILHOUETTE_TIE = 1.5


def silhouette(problem) -> dict:
    """``{"x": share or None, "y": share or None, "pixels": (nx, ny)}``: per axis, the share of
    the mask's edge pixels whose normal points out of the mask along it
    (:data:`SILHOUETTE_TILT`; None below :data:`SILHOUETTE_MIN` such pixels). Every given,
    front-facing normal counts, grazing ones too (a contour's own); a cropped problem's
    neighbours beyond its box count where they are inside the image (``extras`` "offset" and
    "image_shape", :func:`facetlift.api.crop`)."""
    return silhouette_of(problem.domain, problem.known, problem.normals,
                         offset=problem.extras.get("offset", (0, 0)),
                         image_shape=problem.extras.get("image_shape"))


def silhouette_of(d, known, normals, *, offset=(0, 0), image_shape=None) -> dict:
    """:func:`silhouette` of a domain `d`, its facets' given normals `known` (m,) bool and
    `normals` (m, 3), a box at `offset` in an image of `image_shape` (default: the box)."""
    H, W = d.shape
    r0, c0 = offset
    IH, IW = (H, W) if image_shape is None else image_shape
    m = np.pad(d.mask, 1)
    rr = np.arange(-1, H + 1) + r0
    cc = np.arange(-1, W + 1) + c0
    image = ((rr >= 0) & (rr < IH))[:, None] & ((cc >= 0) & (cc < IW))[None, :]
    out = ~m & image  # (outside the mask, inside the image)
    if not out.any():  # (a mask that fills the image: no edge; 0.1 s at 2048^2 otherwise)
        return {"x": None, "y": None, "pixels": (0, 0)}
    # on the image, then at the mask's edge pixels only (gathering at every pixel took 0.1 s
    # at 2048^2)
    ox = out[1:-1, 2:].astype(np.int8) - out[1:-1, :-2]  # (+1: the mask ends to the right)
    oy = out[:-2, 1:-1].astype(np.int8) - out[2:, 1:-1]  # (+1: it ends above: y up)
    er, ec = np.nonzero(d.mask & ((ox != 0) | (oy != 0)))
    r, c = d.pixels  # (row-major: the facets' order)
    key = r.astype(np.int64) * W + c
    f = np.searchsorted(key, er.astype(np.int64) * W + ec)
    ox, oy = ox[er, ec], oy[er, ec]
    known_all = np.asarray(known, bool)
    known = known_all[f]

    def inward(o, dr, dc):
        """Per edge pixel: its facet, or where it has no normal the facet one step inward
        along the axis (``np.gradient`` of a depth with a NaN background leaves the rim's
        slopes NaN, and a field integrated inside out went unvoted on, a review), with
        whether it has a normal."""
        ir, ic = er - dr * o, ec - dc * o
        inside = (~known) & (o != 0) & (ir >= 0) & (ir < H) & (ic >= 0) & (ic < W)
        g = f.copy()
        if inside.any():
            kk = ir[inside].astype(np.int64) * W + ic[inside]
            pos = np.minimum(np.searchsorted(key, kk), key.size - 1)
            hit = key[pos] == kk
            idx = np.flatnonzero(inside)[hit]
            g[idx] = pos[hit]
        return g, known_all[g]

    res = {}
    counts = []
    # (x: +1 where the mask ends to the right, inward is left; y: +1 where it ends above,
    # inward is a row down)
    for axis, o, col, (dr, dc) in (("x", ox, 0, (0, 1)), ("y", oy, 1, (-1, 0))):
        g, has = inward(o, dr, dc)
        comp = normals[g, col]
        with np.errstate(invalid="ignore"):
            sel = has & (o != 0) & (np.abs(comp) > SILHOUETTE_TILT)
        k = int(sel.sum())
        counts.append(k)
        res[axis] = (float(np.mean(np.sign(comp[sel]) == o[sel])) if k >= SILHOUETTE_MIN
                     else None)
    res["pixels"] = tuple(counts)
    return res


def _silhouette_says(sil: dict, axis: str) -> str | None:
    """"out" where the silhouette says `axis` is right, "in" where it says it is negated."""
    share = sil.get(axis)
    if share is None:
        return None
    return "out" if share >= SILHOUETTE_SURE else "in" if share <= 1 - SILHOUETTE_SURE else None


def flip_order(curls: dict, sil: dict | None = None) -> tuple[str, str]:
    """The axis whose flip a warning names first, and the other: where the two flips are
    about as integrable (within :data:`SILHOUETTE_TIE` of each other: orthographically they
    tie) the one the silhouette says is negated, where it says so of one axis only; else the
    one whose flip is the more integrable (y on a tie)."""
    cy, cx = curls["curl_y_flipped"], curls["curl_x_flipped"]
    if sil is not None and max(cy, cx) <= SILHOUETTE_TIE * min(cy, cx):
        says = {a: _silhouette_says(sil, a) for a in ("x", "y")}
        if says["x"] == "in" and says["y"] != "in":
            return "x", "y"
        if says["y"] == "in" and says["x"] != "in":
            return "y", "x"
    return ("y", "x") if cy <= cx else ("x", "y")


def flip_decided(curls: dict, sil: dict | None = None) -> bool:
    """Whether :func:`flip_order`'s first axis is known: the silhouette named it, or the two
    flips' relative curls differ by more than :data:`SILHOUETTE_TIE`. Else (always without a
    camera and a silhouette) the two flips are about as integrable, give surfaces inside-out
    from each other, and a warning names both alike: with a camera and depth jumps the
    inside-out one even scored lower (a user's DSINE map with K: 0.43 against 0.52, the y flip
    named first and followed, a concave sphere without a word)."""
    cy, cx = curls["curl_y_flipped"], curls["curl_x_flipped"]
    if not max(cy, cx) <= SILHOUETTE_TIE * min(cy, cx):
        return True
    says = {a: _silhouette_says(sil, a) for a in ("x", "y")} if sil is not None else {}
    return (says.get("x") == "in") != (says.get("y") == "in")


def flip_assessment(problem, curls: dict | None = None) -> dict:
    """What the frame check decides from the curls (:func:`flip_curls`, computed where not
    given) and the silhouette, for :func:`flip_check`'s warnings and ``facetlift info``'s
    frame guess alike (they drifted apart once, a review): ``curls``, ``sil``, the axes ``a``
    (named first, :func:`flip_order`) and ``b``, ``says`` (the silhouette's "in" / "out" per
    axis), ``verdict`` (:func:`flip_verdict` on the better flip; None for a hint where many
    normals face away, ``facing_away`` > :data:`facetlift.problem.BACKFACING_FRAME_HINT`:
    another frame or BGR order, which no flip mends), ``decided`` (:func:`flip_decided`),
    ``facing_away`` (the share) and ``inside_out`` (no verdict, not many facing away, and
    both axes pointing into the object: :func:`inside_out_check`)."""
    from .problem import BACKFACING_FRAME_HINT

    curls = flip_curls(problem) if curls is None else curls
    sil = silhouette(problem)
    a, b = flip_order(curls, sil)
    verdict = flip_verdict(curls["curl"], min(curls["curl_y_flipped"], curls["curl_x_flipped"]))
    share = problem.counts.get("facing_away", 0.0)
    away = share > BACKFACING_FRAME_HINT
    if verdict == "hint" and away:
        # (many normals faced away: prepare's warning asks about another frame or BGR order,
        # which no flip of x or y mends, and the hint's small margin says little; a BGR map
        # was also told to try -x,-y,-z, a user's check. A claim stays: an x-flipped map with
        # a camera turns 7 % away and is told so)
        verdict = None
    says = {axis: _silhouette_says(sil, axis) for axis in ("x", "y")}
    if verdict == "hint" and says[a] == "in" and says[b] == "out":
        # (the silhouette's normals point into the object along the axis the curls name and
        # out of it along the other: a review's y-down render, 0.86 as given, 0.48 with y
        # flipped, every one of its 310 edge pixels inward along y, got only the hint, and
        # integrated as given it was 54x the error. Not where the other axis says nothing or
        # "in" too: a room seen from inside has its walls' edges inward along x on a right
        # map, 6 of 6 development rooms)
        verdict = "claim"
    return {"curls": curls, "sil": sil, "a": a, "b": b, "says": says, "verdict": verdict,
            "decided": flip_decided(curls, sil), "facing_away": share,
            "inside_out": verdict is None and not away and says["x"] == says["y"] == "in"}


def flip_advice(frame, axes: str) -> str:
    """What to try where the `axes` ("x", "y" or "xy") of a map read in `frame` are negated:
    that frame's flag, or for a gradient field (:data:`GRADIENT_FIELD`, which has no normal
    frame) the slopes to negate, in the layout read (rowcol's y slope is p)."""
    if frame == GRADIENT_FIELD:
        if len(axes) == 2:
            return "negating both p and q"
        own, other = ("q", "p") if axes == "y" else ("p", "q")
        return f"negating the {axes} slope ({own}; {other} with --gradient-frame rowcol)"
    for a in axes:
        frame = negated(frame, a)
    return flag(frame)


def _silhouette_note(sil: dict | None, a: str) -> str:
    """The warning's words on what the silhouette says of axis `a` (empty where nothing)."""
    if sil is None or _silhouette_says(sil, a) != "in":
        return ""
    k = sil["pixels"][0 if a == "x" else 1]
    return (f" (at the object's silhouette the normals point into it along {a}: "
            f"{100 * (1 - sil[a]):.0f} % of {k} edge pixels)")


def inside_out_check(problem, sil: dict | None = None) -> None:
    """Warn (:class:`facetlift.errors.FrameHint`) where the silhouette (:func:`silhouette`)
    says both x and y are negated: such a map is as integrable as the right one, and the
    surface comes out inside-out (a DSINE map read with y flipped instead of x); a concave
    surface masked alone says so too, hence a hint."""
    sil = silhouette(problem) if sil is None else sil
    if not (_silhouette_says(sil, "x") == "in" and _silhouette_says(sil, "y") == "in"):
        return
    frame = _READ_IN.get()
    field = frame == GRADIENT_FIELD  # (no normal frame to name: a review found a crash)
    fix = ("negate both p and q (or give the height's negative)" if field
           else f"try {flip_advice(frame, 'xy')}")
    read = "" if field or is_identity(frame) else f" (read in the frame {axis_string(frame)})"
    kx, ky = sil["pixels"]
    warn(f"the normals{read} point into the object at its mask's edge along both x and y "
         f"({100 * (1 - sil['x']):.0f} % of {kx} and {100 * (1 - sil['y']):.0f} % of {ky} "
         "edge pixels), where an occluding contour's point out of it: if the mask's edge is "
         "the object's silhouette, the surface came out inside-out (both axes negated, which "
         f"no integrability check can see): {fix}; docs/conventions.md lists the frames of "
         "common sources. A concave surface masked alone (a bowl's inside, a crater, an "
         "engraving) or a region cut out of a larger surface does this too: then all is well",
         FrameHint)


def flip_check(problem) -> dict:
    """Relative curl (:func:`relative_curl`) of the field as given and with y and x flipped;
    warns, naming the flag to try, when a flip is far more integrable (:data:`FLIP_RATIO`),
    and hints at it when it is more integrable by a smaller margin (:data:`FLIP_HINT`).

    Flipping x or y turns the surface inside out relative to the other flip, so the two are
    (almost) equally integrable: the warning names both.

    Returns
    -------
    dict
        ``{"curl": ..., "curl_y_flipped": ..., "curl_x_flipped": ..., "noise": ...}``
        (``noise``: :func:`normal_noise`, degrees); for a gradient
        field whose other layout :func:`layout_check` named (:func:`read_in`'s `layout`),
        also ``"other_layout"``, and no warning: that layout is the advice.
    """
    out = flip_curls(problem)
    layout = _LAYOUT_NAMED.get()
    if layout is not None and _READ_IN.get() == GRADIENT_FIELD:
        # (the layout warning has spoken: a slope's sign is no second cause to name; the
        # field turned by 90 degrees is far from integrable either way)
        out["other_layout"] = layout
        return out
    own = out["curl"]
    # the axis the silhouette says is negated, else the one whose flip is the more integrable,
    # decides and is named first (with a pinhole camera the two flips differ: a review's
    # x-flipped map, 0.65 as given, 0.68 with y and 0.0005 with x flipped, was told to try the
    # y flip); orthographically they tie, and a DSINE map (x flipped) was told y first
    f = flip_assessment(problem, out)
    a, b, sil, verdict, decided = f["a"], f["b"], f["sil"], f["verdict"], f["decided"]
    if f["inside_out"]:
        inside_out_check(problem, sil)
    best = out[f"curl_{a}_flipped"]
    frame = _READ_IN.get()  # (the frame the map was read in: the hint is relative to it)
    flips = f"{best:.2f} with {a} flipped, {out[f'curl_{b}_flipped']:.2f} with {b} flipped"
    slope = {"y": "q", "x": "p"}
    either = ("both flips are about as integrable and give surfaces inside-out from each "
              "other, and no silhouette in view says which axis is wrong: keep the one whose "
              "surface bulges toward the camera where the object does")
    if verdict == "hint":
        try_ = flip_advice(frame, a)
        if not decided and frame != GRADIENT_FIELD:
            try_ = f"{try_} or {flip_advice(frame, b)} ({either})"
        warn(f"the normals are more integrable with {a} flipped (relative curl {own:.2f} as "
             f"given, {flips}), not by the margin that "
             "says the frame is wrong (strongly correlated errors on a nearly flat view do "
             f"this too): if the surface looks bent or inside-out, try {try_}",
             FrameHint)
    elif verdict == "claim" and not decided and frame != GRADIENT_FIELD:
        read = "" if is_identity(frame) else f" (read in the frame {axis_string(frame)})"
        warn(f"the normals are far more integrable with x or y flipped (relative curl "
             f"{own:.2f} as given, {flips}): its frame{read} is probably wrong in x or in y: "
             f"try {flip_advice(frame, a)} or {flip_advice(frame, b)}; {either}. "
             "docs/conventions.md lists the frames of common sources. If the frame is right, "
             "the image itself may be flipped or mirrored (rows or columns reversed by an "
             "export): flip it back instead", FrameWarning)
    elif verdict == "claim":
        if frame == GRADIENT_FIELD:
            # (a field is spoken of as one, and a y slope down the rows, as MATLAB's gradient()
            # and OpenCV's Sobel give it, is named as the frame that reads it: its user was
            # told of normals and to negate q, a review)
            rows = ("; a field whose second slope runs down the rows, as MATLAB's gradient() "
                    "and OpenCV's Sobel give it, is --gradient-frame image" if a == "y" else "")
            warn(f"the gradient field is far more integrable with {a} flipped (relative curl "
                 f"{own:.2f} as given, {flips}): the field's {a} slope probably has the wrong "
                 f"sign: negate {slope[a]} ({'p' if a == 'y' else 'q'} with --gradient-frame "
                 f"rowcol), or the {b} slope instead if the surface then comes out "
                 f"inside-out{rows}", FrameWarning)
        else:
            head = (f"the normals are far more integrable with {a} flipped (relative curl "
                    f"{own:.2f} as given, {flips})")
            read = "" if is_identity(frame) else f" (read in the frame {axis_string(frame)})"
            warn(f"{head}: its frame{read} is probably wrong in {a}{_silhouette_note(sil, a)}: "
                 f"try {flip_advice(frame, a)}, or {flip_advice(frame, b)} if the surface "
                 "then comes out inside-out; docs/conventions.md lists the frames of common "
                 "sources. If the frame is right, the image itself may be flipped or mirrored "
                 "(rows or columns reversed by an export): flip it back instead",
                 FrameWarning)
    return out


# --------------------------------------------------------------------------------------------
# gradient fields

#: Gradient frames -> what (p, q) hold. "xy" is facetlift's; "rowcol" is the layout of Quéau's
#: normal_integration toolbox and of numpy's ``np.gradient(z)`` (rows first); "image" that of
#: MATLAB's ``[FX, FY] = gradient(Z)`` and of OpenCV's Sobel dx, dy (columns first, rows
#: down). ("matlab" meant "rowcol" until 2026-12-07: MATLAB's own gradient() then came out
#: wrong without a word, an audit.)
GRADIENT_FRAMES = {
    "xy": "p = dz/dx (x right), q = dz/dy (y up)",
    "rowcol": "p = dz/d(row) (down the rows), q = dz/d(col) (along the columns)",
    "image": "p = dz/d(col) (along the columns), q = dz/d(row) (down the rows)",
}
_GRADIENT_ALIASES = {"queau": "rowcol", "numpy": "rowcol", "matlab": "image",
                     "opencv": "image", "facetlift": "xy"}


def gradient_frame(name) -> str:
    """The canonical name of a gradient frame (:data:`GRADIENT_FRAMES`, or an alias: ``queau``,
    ``numpy`` = ``rowcol``; ``matlab``, ``opencv`` = ``image``); ValueError otherwise."""
    key = name.strip().lower() if isinstance(name, str) else name
    key = _GRADIENT_ALIASES.get(key, key)
    if key not in GRADIENT_FRAMES:
        raise ValueError(
            f"`gradient_frame` must be one of {sorted(GRADIENT_FRAMES)} (aliases "
            f"{sorted(_GRADIENT_ALIASES)}); got {name!r}"
        )
    return key


#: A gradient field's curl relative to all its first derivatives above which, with the other
#: layout's below :data:`LAYOUT_RATIO` of it, :func:`layout_check` warns (measured: a smooth bump
#: 0.46 in the wrong layout and 0.005 in the right one, the BiNI human map's field 0.56 and
#: 0.16; a saddle's field is about equal in both, noise or not).
LAYOUT_MIN_CURL = 0.3

#: Below :data:`LAYOUT_MIN_CURL`, a curl as read above this still counts where another reading
#: has less than :data:`LAYOUT_STRONG_RATIO` of it (a field all but integrable in the other
#: layout: a nearly symmetric sine surface read in the wrong one had 0.107 against 0.00019).
#: Noise adds curl to every reading alike, so it does not reach the ratio; a separable field
#: (a saddle z = k x y: p of y alone, q of x alone) keeps exactly none in the other readings
#: whatever its quantisation, and is not judged by this rule.
LAYOUT_LOW_CURL = 0.05
LAYOUT_STRONG_RATIO = 0.05
#: The fewest pixels of a field for the rule below :data:`LAYOUT_MIN_CURL` (a 2 x 2 map is
#: one block, whose noise alone reads as a layout).
LAYOUT_LOW_PIXELS = 64


class LayoutWarning(FrameWarning):
    """A gradient field far more integrable in the other layout (:func:`layout_check`);
    `other` names that layout."""

    def __init__(self, message: str, other: str | None = None):
        super().__init__(message)
        self.other = other


#: :func:`layout_curls` looks at about this many pixels of the image (a gradient field's own
#: sample; 2^18 as before :data:`CURL_SAMPLE` became 2^16).
LAYOUT_SAMPLE = 2**18


def layout_curls(gx, gy, mask=None, *, gy_sign: float = 1.0,
                 sample: int = LAYOUT_SAMPLE) -> tuple[float, float, float, float]:
    """``(curl, curl of the other layout, curl with y flipped, curl with gx and gy
    exchanged)`` of a gradient field in
    facetlift's frame (``gx = dz/dx``, ``gy = dz/dy``, y up), each relative to the sum of all
    four first derivatives' magnitudes (a denominator both layouts share), over the 2 x 2
    blocks inside `mask` whose slopes are finite and not grazing (the paper's rule, cos 85
    deg: such huge slopes dominate the sums); NaNs without such a block.

    The other layout (``p = dz/d(row)`` read as ``dz/dx``, or the reverse) turns the field by
    90 degrees, whose curl is the field's divergence: a smooth surface's field has curl 0 and
    a divergence that is not, the turned one the reverse; a saddle's field has neither (no
    layout preferred). `gy` is taken times `gy_sign`. Large fields are sampled in strips of
    two rows (about `sample` pixels), taken before any conversion."""
    from .conventions import OUTLIER_EPS

    nan = (float("nan"),) * 4
    try:
        gx, gy = np.asarray(gx), np.asarray(gy)
    except Exception:
        return nan
    if gx.ndim != 2 or gx.shape != gy.shape or min(gx.shape) < 2:
        return nan
    H, W = gx.shape
    step = 1 if H * W <= sample else max(2, H // max(1, sample // (2 * W)))
    a = _strided(H - 1, step)  # (not every step-th row: a texture's period, :func:`_strided`)
    b = a + 1  # (row a above row b: y up)
    m = None if mask is None else np.asarray(mask)
    with np.errstate(all="ignore"):
        try:
            X = [gx[r].astype(float) for r in (a, b)]
            Y = [gy_sign * gy[r].astype(float) for r in (a, b)]
        except (TypeError, ValueError):
            return nan
        ok = [x * x + y * y < 1.0 / OUTLIER_EPS**2 - 1.0 for x, y in zip(X, Y, strict=True)]
        if m is not None and m.shape == gx.shape:
            ok = [o & (m[r] != 0) for o, r in zip(ok, (a, b), strict=True)]
        good = ok[0][:, :-1] & ok[0][:, 1:] & ok[1][:, :-1] & ok[1][:, 1:]
        if not good.any():
            return nan
        # (differences first: a sum of the four values rounds exact zeros to ~1e-17)
        dgx_dy = ((X[0][:, :-1] - X[1][:, :-1]) + (X[0][:, 1:] - X[1][:, 1:])) / 2
        dgy_dx = ((Y[0][:, 1:] - Y[0][:, :-1]) + (Y[1][:, 1:] - Y[1][:, :-1])) / 2
        dgx_dx = ((X[0][:, 1:] - X[0][:, :-1]) + (X[1][:, 1:] - X[1][:, :-1])) / 2
        dgy_dy = ((Y[0][:, :-1] - Y[1][:, :-1]) + (Y[0][:, 1:] - Y[1][:, 1:])) / 2
        curl = np.abs(dgx_dy - dgy_dx)[good].sum()
        div = np.abs(dgx_dx + dgy_dy)[good].sum()
        flipped = np.abs(dgx_dy + dgy_dx)[good].sum()  # (the field with gy negated)
        total = (np.abs(dgx_dy) + np.abs(dgy_dx) + np.abs(dgx_dx) + np.abs(dgy_dy))[good].sum()
        swapped = np.abs(dgy_dy - dgx_dx)[good].sum()  # (the field with gx and gy exchanged)
    if not np.isfinite(total) or total <= 0:
        return (0.0, 0.0, 0.0, 0.0) if total == 0 else nan
    return (float(curl / total), float(div / total), float(flipped / total),
            float(swapped / total))


def layout_check(p, q, frame: str = "xy", mask=None) -> dict:
    """Relative curl (:func:`layout_curls`) of the gradient field (p, q) read in `frame` and
    in the other layouts; warns when the field as read has a clear curl (above
    :data:`LAYOUT_MIN_CURL`) and another reading less than :data:`LAYOUT_RATIO` of it: the
    other layout of ``xy`` and ``rowcol`` (``p = dz/d(row)`` read as ``dz/dx`` turns the field
    by 90 degrees, which no flip of the normals undoes), naming ``--gradient-frame``; or p and
    q exchanged (two files given the other way round), naming that.

    Returns
    -------
    dict
        ``{"curl": ..., "curl_other_layout": ..., "curl_y_flipped": ..., "curl_swapped": ...,
        "suggested": ...}`` (the third: with one slope's sign flipped, which explains it
        better where it is lowest: no layout is then suggested; the fourth: with p and q
        exchanged; the last: the layout the warning named, ``"swapped"`` for p and q
        exchanged, else None: hand it to :func:`read_in` for the solve, so that
        :func:`flip_check` does not contradict it).
    """
    given = gradient_frame(frame)
    # (rowcol: dz/dx = q, dz/dy = -p; image: dz/dx = p, dz/dy = -q; no converted copy of the
    # whole field is made)
    gx, gy, sign = {"xy": (p, q, 1.0), "image": (p, q, -1.0), "rowcol": (q, p, -1.0)}[given]
    own, alt, flip, swap = layout_curls(gx, gy, mask, gy_sign=sign)
    out = {"curl": own, "curl_other_layout": alt, "curl_y_flipped": flip,
           "curl_swapped": swap, "suggested": None}
    # (the other layout of "image" is no named frame: its exchange is "rowcol"'s, below)
    other = {"xy": "rowcol", "rowcol": "xy"}.get(given)
    # (not where a slope's sign explains it better: flip_check names that after the solve)
    if flip <= min(alt, swap):
        return out
    # (a smaller curl as read counts where another reading is all but integrable: a sine
    # field read in the wrong layout, 0.107 as read and 0.00019 exchanged, came out 31 % of
    # its range wrong without a word, a review)
    # (not where the other reading's curl is exactly 0: a separable field, p of y and q of x
    # as a saddle z = k x y has, is integrable in both layouts, and quantised slopes leave
    # curl in one reading alone, which was told to change its layout, a review; nor on a
    # map of a few pixels)
    # (the ratio itself is the tests below, with the stronger one under the floor)
    if not (own > LAYOUT_MIN_CURL or (own > LAYOUT_LOW_CURL and min(alt, swap) > 0.0
                                      and np.size(p) >= LAYOUT_LOW_PIXELS)):
        return out
    ratio = LAYOUT_RATIO if own > LAYOUT_MIN_CURL else LAYOUT_STRONG_RATIO
    if other is not None and alt < ratio * own and alt <= swap:
        out["suggested"] = other
        meaning = GRADIENT_FRAMES[other]
        warn(
            f"the gradient field is far more integrable in the other layout (relative curl "
            f"{own:.2f} read as {given!r}, {alt:.2f} as {other!r}: {meaning}): try "
            f"--gradient-frame {other} (gradient_frame='{other}')", LayoutWarning, other=other
        )
    elif swap < ratio * own:
        out["suggested"] = "swapped"
        also = (" (or --gradient-frame rowcol: MATLAB's gradient() and OpenCV's Sobel give "
                "columns first, numpy's np.gradient rows first)" if given == "image" else
                " (or --gradient-frame image)" if given == "rowcol" else "")
        warn(
            f"p and q look exchanged: the gradient field is far more integrable with them the "
            f"other way round (relative curl {own:.2f} as given, {swap:.2f} exchanged): give "
            f"them in the other order (--gradients Q P; integrate_gradients(q, p)){also}",
            LayoutWarning, other="swapped"
        )
    return out


def gradients_to_facetlift(p, q, frame: str = "xy"):
    """(p, q) in `frame` -> facetlift's ``(dz/dx, dz/dy)`` with x right and y up.

    ``rowcol``: ``dz/dx = q`` and ``dz/dy = -p`` (a row step goes down, against y);
    ``image``: ``dz/dx = p`` and ``dz/dy = -q``.
    """
    given = gradient_frame(frame)
    if given == "xy":
        return p, q
    if given == "image":
        return p, -np.asarray(q, dtype=float)
    return q, -np.asarray(p, dtype=float)
