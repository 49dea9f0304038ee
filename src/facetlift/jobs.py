"""One integration job from files to files: read the input, integrate, write every output as one
set. ``facetlift integrate`` runs one :class:`Job`; ``facetlift batch`` (:mod:`facetlift.batch`)
runs many, on Dask. No click here: the command line only parses flags into a :class:`Job`.

The steps, in order: the output folder is created and checked for writability and no output may
overwrite an input (:class:`facetlift.io.OutputSet`); the input is read (a normal map, a
dataset folder, a gradient field, or a ``.mat`` file); :func:`facetlift.integrate` runs; every
output is written into the set's staging folder and the set is moved into place only when all
of them succeeded.
"""

from __future__ import annotations

import contextlib
import os
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ._progress import announce
from ._warnings import recording, reemit, renamed, said_if_raised, warn
from .errors import CameraWarning

#: Output kinds (``--save``) -> file names written into the output folder.
OUTPUTS = {
    "npy": "depth.npy",
    "exr": "depth.exr",
    "tif": "depth.tif",
    "npz": "surface.npz",
    "ply": "mesh.ply",
    "obj": "mesh.obj",
    "stl": "mesh.stl",
    "png": "preview.png",
    "report": "report.png",
    "discontinuities": "discontinuities.png",
    "height": "height.png",
    "height-exr": "height.exr",
    "points": "points.ply",
    "normals": "result_normals.png",
}
DEFAULT_SAVE = ("npy", "ply", "png")
#: The outputs that an image's colours paint (``Job.colors``, --colors).
COLOURED = frozenset({"ply", "obj", "points"})
#: The file stems of :data:`OUTPUTS` ("depth", "mesh", ...): files by these names in a folder
#: are facetlift's results, not inputs.
OUTPUT_STEMS = frozenset(Path(name).stem for name in OUTPUTS.values())


@dataclass(frozen=True)
class Job:
    """What to integrate, how, and where to write it.

    Give `normals` (a normal-map file, a dataset folder, or a ``.mat`` file) or `gradients`
    (two files p, q). `options` are method options; `save` the output kinds of
    :data:`OUTPUTS`; `triangles` None keeps each format's default (PLY quads, OBJ triangles;
    STL holds triangles only, whatever it says).
    """

    normals: str | None = None
    gradients: tuple | None = None
    mask: str | None = None
    #: A K file (facetlift.io.read_K), or its numbers typed inline: "fx fy cx cy" or the
    #: matrix's nine row by row (facetlift.io.dataset.inline_K; the command line's is an
    #: io.dataset.InlineK, the text with its numbers parsed once).
    K: str | None = None
    #: Horizontal field of view in degrees: a pinhole K with the principal point at the
    #: centre (facetlift.camera.K_from_fov), instead of a K file.
    fov: float | None = None
    orthographic: bool = False
    normal_frame: str | None = None
    #: Normals in world space: a file of the rotation from world to the camera frame named
    #: by `normal_frame` (``world_to_camera``, --world-to-camera), or of the camera's pose,
    #: camera to world (``camera_to_world``, --camera-to-world: Blender's matrix_world),
    #: transposed (facetlift.io.read_rotation); one of them. A dataset folder's
    #: world_to_camera.* or camera_to_world.* is used where neither is given.
    world_to_camera: str | None = None
    camera_to_world: str | None = None
    #: How the normal map stores its normals: "xyz" (R, G, B) or "xy" (a two-channel map,
    #: BC5 or RG: z rebuilt; facetlift.frames.NORMAL_ENCODINGS).
    normal_encoding: str = "xyz"
    #: The range of a float map's components: "signed" (in [-1, 1]) or "unsigned" ((n + 1) / 2
    #: in [0, 1], decoded as 2 v - 1 on reading; facetlift.frames.NORMAL_RANGES).
    normal_range: str = "signed"
    gradient_frame: str = "xy"
    mat_keys: tuple | None = None
    method: str = "dgp"
    pixel_size: float = 1.0
    backfacing: str = "missing"
    outlier_eps: float | None = None
    options: dict = field(default_factory=dict)
    save: tuple = DEFAULT_SAVE
    triangles: bool | None = None
    #: The heights written as 0 and 65535 in height.png, ``(low, high)`` in the depth's units
    #: (facetlift.io.write_height); None: each map's own lowest and highest.
    height_range: tuple | None = None
    #: Frame of the mesh's and the point cloud's coordinates (and the points' normals):
    #: None for facetlift's (x right, y up, z toward the viewer), "opencv" for the camera
    #: frame of OpenCV and COLMAP, or any frame a normal map may be in (facetlift.frames).
    output_frame: str | None = None
    #: An image of the object (the photograph, an albedo) whose colours are painted on the
    #: ply, obj and points outputs (facetlift.io.read_colors; resampled where it is the same
    #: picture at another size).
    colors: str | None = None
    outdir: str | None = None
    #: Depth prior file (docs/fusion.md), its scale (16-bit PNG), weight or weight map file,
    #: and the normals' confidence file; a dataset folder's prior_depth.* / confidence.* are
    #: used when these are not given.
    prior: str | None = None
    prior_scale: float | None = None
    #: None: the default (1, or facetlift.problem.BLURRED_PRIOR_WEIGHT with prior_blur).
    prior_weight: float | None = None
    prior_weight_map: str | None = None
    confidence: str | None = None
    #: Standard deviation (pixels) of the prior's blur (``prior_blur``, docs/fusion.md).
    prior_blur: float | None = None
    #: What to do with a sparse prior's outlier samples ("remove" or "keep"; None: the
    #: default, remove; facetlift.prior_outliers).
    prior_outliers: str | None = None
    #: What the prior is known up to: "none" (None: the default), "affine", "scale",
    #: "disparity" (facetlift.prior_fit).
    prior_fit: str | None = None
    #: Whether a dataset folder's prior_depth.* and confidence.* files are used.
    dataset_prior: bool = True
    dataset_confidence: bool = True
    #: Fail where the input's frame looks wrong (a :class:`facetlift.FrameWarning`), before
    #: any output is written, instead of warning.
    strict: bool = False
    #: Warn about the files beside a plain map file that the job does not read (``mask.*``,
    #: ``NAME_mask.*``, ``K.txt``); a batch names them once per folder instead (False for
    #: its items).
    unread_beside: bool = True
    #: A batch item whose batch gives the prior's settings (``prior_fit``, ``prior_blur``, ...)
    #: while some of its maps have no prior of their own: where this one has none, it is
    #: integrated from its normals alone, with a warning naming the settings left unused,
    #: instead of refused (False: refused, as a single job is).
    prior_optional: bool = False
    #: Which of ``prior``, ``confidence`` and ``colors`` a batch found beside the map, as
    #: ``NAME_prior_depth.*`` and ``NAME_confidence.*`` (not given by the user): their
    #: errors name the file and what leaves it unread (``dataset_prior=False``, --no-prior).
    beside: tuple = ()
    #: A file whose existence cancels the job: checked before it starts and again before its
    #: outputs are moved into place (nothing is then written). A batch on a cluster gives its
    #: items one and writes it when interrupted: a task already running on a worker cannot
    #: be stopped, and such tasks wrote their outputs after the command had exited, over a
    #: later run's (a review).
    cancel_mark: str | None = None

    def with_input(self, path, outdir) -> Job:
        """The same job on another normal-map input (a batch item)."""
        return replace(self, normals=str(path), gradients=None, outdir=str(outdir))

    @property
    def source(self) -> Path:
        """The main input path (the normal map, dataset folder, .mat file, or p)."""
        if self.normals is None and not self.gradients:
            raise ValueError("give a normal map (NORMALS) or a gradient field (--gradients P Q)")
        if self.normals is not None and self.gradients:
            raise ValueError("give either a normal map (NORMALS) or --gradients P Q, not both")
        return Path(self.normals if self.normals is not None else self.gradients[0])


@dataclass
class Input:
    """What :func:`read` returns."""

    normals: np.ndarray
    mask: np.ndarray | None
    K: np.ndarray | None
    mask_source: str
    prior: np.ndarray | None = None
    prior_weight: object = None
    confidence: np.ndarray | None = None
    #: The normals were made from a gradient field (its hints speak of p and q).
    field: bool = False
    #: The other layout the gradient field's layout check named (:func:`facetlift.frames.
    #: layout_check`), None where it named none: the solve's frame check then stays silent.
    layout: str | None = None
    #: The dataset folder's camera file the K came from (K.txt, or DiLiGenT's
    #: Calib_Results.mat, perhaps the parent's), for the summary; None otherwise.
    K_file: str | None = None
    #: Where the prior and the confidence came from, for the summary and the record: the
    #: file given (--prior, --confidence) or "the folder's <name>"; None without one.
    prior_file: str | None = None
    confidence_file: str | None = None
    #: The rotation from world to the camera frame of the job's `normal_frame`, for normals
    #: in world space (None: they are in the camera's frame), the file it came from and the
    #: field that named it ("world_to_camera" or "camera_to_world": which way it was read).
    rotation: np.ndarray | None = None
    rotation_file: str | None = None
    rotation_as: str | None = None
    #: Other tools' camera files beside the input that no K was read from (COLMAP's
    #: cameras.txt, ...; :func:`_unread_camera_files`, which warns of them), for info.
    camera_unread: tuple[str, ...] = ()


def rotation_field(job: Job) -> str | None:
    """The field of `job` that gives its rotation file (:data:`facetlift.io.dataset.
    ROTATION_FIELDS`), or None; a ValueError where it gives both, or something not a path
    (a batch's template reads it for every item)."""
    from .io.dataset import ROTATION_FIELDS

    given = [f for f in ROTATION_FIELDS if getattr(job, f, None) is not None]
    for f in given:
        if not isinstance(getattr(job, f), (str, os.PathLike)):
            raise ValueError(f"`{f}` is a file holding the camera's rotation; got "
                             f"{type(getattr(job, f)).__name__} (an array goes to "
                             "facetlift.integrate(normals, normal_rotation=R))")
    if len(given) > 1:
        raise ValueError("`world_to_camera` and `camera_to_world` give the rotation twice, "
                         "one the other's inverse: give one of them")
    return given[0] if given else None


def read_rotation(job: Job) -> np.ndarray | None:
    """The rotation from world to the camera frame that `job`'s own file gives
    (:func:`rotation_field`, :func:`facetlift.io.read_rotation`), or None."""
    field_ = rotation_field(job)
    if field_ is None:
        return None
    from .io import read_rotation as read

    return read(getattr(job, field_), camera_to_world=field_ == "camera_to_world")


def default_outdir(src: Path) -> Path:
    """``<input>_facetlift/`` next to the input as the user named it: beside a symbolic link,
    not beside its target (which may be a shared or read-only dataset)."""
    src = Path(os.path.abspath(src))  # (absolute, ".." folded, links kept)
    return src.parent / f"{src.stem if src.is_file() else src.name}_facetlift"


def input_paths(job: Job) -> list[Path]:
    """Every file the job reads (a dataset folder's files too): outputs must not be these."""
    paths = [job.source] if job.normals is not None else [Path(p) for p in job.gradients]
    if paths[0].is_dir():  # (the files read_dataset reads, not an earlier run's outputs)
        from .io.dataset import dataset_files

        paths = dataset_files(paths[0], with_prior=job.dataset_prior,
                              with_confidence=job.dataset_confidence)
    paths += [Path(p) for p in (job.mask, job.K, job.prior, job.prior_weight_map,
                                job.confidence, job.world_to_camera, job.camera_to_world,
                                job.colors)
              if p is not None]
    return paths


def read(job: Job) -> Input:
    """Read the job's input into facetlift-frame normals, mask and K.

    Raises
    ------
    ValueError
        Unreadable or inconsistent input (the message names the file and the argument).
    """
    from . import frames, io
    from .io.dataset import DILIGENT_NORMALS
    from .io.gradients import is_mat, read_gradients, read_mat

    src = job.source
    K = prior = conf = K_file = None
    rotation = rotation_file = rotation_as = layout = None
    given_rotation = rotation_field(job)
    files = {"prior": None, "confidence": None}
    field_input = bool(job.gradients)
    folder = not field_input and src.is_dir()  # (a dataset folder may hold its own prior)
    if job.prior is None and not folder:  # (the prior's own flags refused before the map is
        _no_prior_checks(job)  # read; a folder's, once it is read)
    encoding = frames.normal_encoding(job.normal_encoding, "normal_encoding")
    signs = frames.normal_range(job.normal_range)
    if job.gradients and encoding != "xyz":
        raise ValueError(f"`normal_encoding` {encoding!r} applies to a normal map; a gradient "
                         "field (--gradients P Q) stores slopes: leave it out")
    if job.gradients and signs != "signed":
        raise ValueError(f"`normal_range` {signs!r} applies to a normal map; a gradient "
                         "field (--gradients P Q) stores slopes: leave it out")
    # (read before the map, its size checked after: an "unsigned" map's signs are counted
    # inside it, and a fill outside it was refused as signed normals, a review)
    given = None if job.mask is None else io.read_mask(job.mask)
    if job.gradients:
        g = read_gradients(*job.gradients)
        (n, layout), m, source = _normals_from_field(g, job), g["mask"], "valid gradients"
    elif is_mat(src):
        g = read_mat(src, job.mat_keys)
        field_input = "p" in g
        for key, value, default in (("normal_encoding", encoding, "xyz"),
                                    ("normal_range", signs, "signed")):
            if field_input and value != default:
                raise ValueError(f"`{key}` {value!r} applies to a normal map; {src} holds a "
                                 "gradient field (p, q), which stores slopes: leave it out")
        if field_input:
            n, layout = _normals_from_field(g, job)
        else:
            n = g["normals"]
            if signs == "unsigned":  # (its signs counted where a map's are: images._counted)
                from .io.images import _counted

                n = frames.decode_unsigned(n, f"`path`: {src}",
                                           _counted(given, g["mask"], n.shape[:2]),
                                           2 if encoding == "xy" else 3)
            if encoding == "xy":
                n = frames.decode_xy(n, frame=job.normal_frame)
            n = frames.to_facetlift(n, job.normal_frame)
        m = g["mask"]
        if m is not None and given is None and not np.asarray(m).any():
            # (named: "`mask` is empty" did not say it was the file's, a gradients audit)
            raise ValueError(f"`path`: {src} holds a mask with no pixel set: nothing to "
                             "integrate (--mat-keys names another variable; --mask gives one)")
        source = (f"{src.name} mask" if m is not None else
                  "valid gradients" if field_input else "valid normals")
        if not field_input and src.name == DILIGENT_NORMALS:  # (its folder's files)
            _beside_dataset_files(src, job, own_mask=m is not None)
        elif not field_input and job.unread_beside:
            _unread_beside(src, job, own_mask=m is not None)
    elif src.is_dir():
        ds = io.read_dataset(src, frame=job.normal_frame,
                             prior_scale=None if job.prior else _prior_scale(job),
                             with_prior=job.dataset_prior and job.prior is None,
                             with_confidence=job.dataset_confidence and job.confidence is None,
                             with_rotation=given_rotation is None, encoding=encoding,
                             normal_range=signs, mask=given,
                             prior_zero_unknown=_zero_unknown(job))
        n, m, K = ds["normals"], ds["mask"], ds["K"]
        if ds["rotation"] is not None:
            rotation, rotation_file = ds["rotation"], f"the folder's {ds['rotation_file'].name}"
            rotation_as = ds["rotation_file"].stem
        prior, conf = ds["prior"], ds["confidence"]
        K_file = ds["K_file"]
        for name in files:  # (named in the summary: a stray confidence.npy changed results
            # unsaid, an audit)
            if ds.get(f"{name}_file") is not None:
                files[name] = f"the folder's {Path(ds[f'{name}_file']).name}"
        source = "dataset mask" if m is not None else "valid normals"
    else:
        # (no word on an alpha that --mask replaces)
        n, m = io.read_normals(src, frame=job.normal_frame, check_alpha=job.mask is None,
                               encoding=encoding, normal_range=signs, mask=given)
        source = "alpha channel" if m is not None else "valid normals"
        _beside_dataset_files(src, job)
        if job.unread_beside and src.stem.lower() != "normal_map":
            _unread_beside(src, job)
    if field_input and job.K is not None:
        raise ValueError("`K`: a gradient field is orthographic; --K does not apply")
    if given_rotation is not None:
        if field_input:
            raise ValueError(f"`{given_rotation}`: a gradient field's slopes are of the height "
                             "over the image plane, with no world frame to turn from; it does "
                             "not apply")
        rotation, rotation_file = read_rotation(job), str(getattr(job, given_rotation))
        rotation_as = given_rotation
    if not field_input and job.gradient_frame != Job.gradient_frame:  # (ignored silently: an
        # audit; a warning, not an error: a batch may mix fields and maps, a review)
        warn(f"`gradient_frame` {job.gradient_frame!r} applies to a gradient field "
             f"(--gradients P Q, or a .mat file holding p and q); {src.name} is a normal map, "
             "whose frame is --normal-frame: it is ignored here")
    if job.mat_keys and not is_mat(src):  # (ignored silently, a CLI audit)
        warn(f"`mat_keys` {','.join(job.mat_keys)} name a MATLAB file's variables; {src.name} "
             "is no .mat file: they are ignored here")
    if given is not None:
        from .io.images import check_mask_size

        m = check_mask_size(given, Path(job.mask), n.shape[:2],
                            of="the gradient field" if field_input else "the normal map")
        source = str(job.mask)
    if job.K is not None:  # (a file, or fx fy cx cy typed inline)
        from .io.dataset import camera_of

        # (a calibration of another size refused: a 1224 x 1024 one on a 612 x 512 map was
        # caught only by chance, a fresh user's review)
        folder_K, K = K, camera_of(job.K, n.shape[:2])
        if folder_K is not None and not np.allclose(folder_K, K, rtol=1e-6, atol=1e-9):
            # (replaced in silence where --fov warns: an audit)
            name = "K.txt" if K_file is None else _camera_name(K_file, src)
            warn(f"`K` {job.K} replaces the K of the dataset folder's {name} (fx "
                 f"{folder_K[0, 0]:g}, fy {folder_K[1, 1]:g}, cx {folder_K[0, 2]:g}, cy "
                 f"{folder_K[1, 2]:g}), which differs (fx {K[0, 0]:g}, fy {K[1, 1]:g}, cx "
                 f"{K[0, 2]:g}, cy {K[1, 2]:g}); leave --K out to use the folder's")
    if job.fov is not None:
        check_fov(job)
        if field_input:
            raise ValueError("`fov`: a gradient field is orthographic; --fov does not apply")
        from .camera import K_from_fov

        if K is not None:  # (documented, but replaced in silence: an audit)
            name = "K.txt" if K_file is None else _camera_name(K_file, src)
            warn(f"`fov` {float(job.fov):g} deg replaces the K of the dataset folder's {name} "
                 f"(fx {K[0, 0]:g}, cx {K[0, 2]:g}, cy {K[1, 2]:g}); leave --fov out to use it")

        K = K_from_fov(n.shape[:2], job.fov)
    if job.orthographic:
        K = None
    unread_cameras = () if K is not None or field_input or not camera_unset(job) else tuple(
        _unread_camera_files(src, job))
    if job.prior is not None:
        with _beside_file(job, "prior"):
            prior = io.read_prior(job.prior, _prior_scale(job), zero_unknown=_zero_unknown(job))
        files["prior"] = str(job.prior)
    elif prior is None and folder:
        _no_prior_checks(job)
    if job.confidence is not None:
        with _beside_file(job, "confidence"):
            conf = io.read_weights(job.confidence, arg="confidence")
        files["confidence"] = str(job.confidence)
    weight = job.prior_weight
    if job.prior_weight_map is not None:  # (times --prior-weight: an 8-bit map reaches 100)
        # (its values are checked where the prior has a sample, as integrate's prior_weight:
        # a sentinel elsewhere is no error; the command line names the map in the message)
        from .problem import default_prior_weight

        weight = default_prior_weight(job.prior_weight, job.prior_blur) * io.read_weights(
            job.prior_weight_map, arg="prior_weight_map")
    for name, arr in (("prior", prior), ("confidence", conf), ("prior_weight_map", weight)):
        if isinstance(arr, np.ndarray) and arr.shape != n.shape[:2]:
            from .problem import coarse_prior_hint

            # (a sensor's depth of lower resolution was refused with no remedy, an audit)
            hint = coarse_prior_hint(arr.shape, n.shape[:2]) if name == "prior" else ""
            # (a batch's NAME_prior_depth.*: the file named, and how to leave it unread)
            own = f" ({Path(getattr(job, name)).name})" if name in job.beside else ""
            of = "the gradient field" if field_input else "the normal map"
            raise ValueError(f"`{name}`: size {arr.shape[0]}x{arr.shape[1]} (HxW){own} but "
                             f"{of} is {n.shape[0]}x{n.shape[1]}{hint}"
                             f"{_beside_tail(job, name)}")
    return Input(normals=n, mask=m, K=K, mask_source=source, prior=prior, prior_weight=weight,
                 confidence=conf, field=bool(field_input), layout=layout,
                 K_file=None if K_file is None or job.K is not None or job.fov is not None
                 else _camera_name(K_file, src),
                 prior_file=files["prior"] if prior is not None else None,
                 confidence_file=files["confidence"] if conf is not None else None,
                 rotation=rotation, rotation_file=rotation_file, rotation_as=rotation_as,
                 camera_unread=unread_cameras)


def _unread_camera_files(src: Path, job: Job) -> list[str]:
    """Warn where a job without a camera (no K read, none given) has beside its input other
    tools' camera files (:data:`facetlift.io.dataset.OTHER_CAMERA_FILES`: COLMAP's
    cameras.txt, OpenCV's calib.yml, a transforms.json, K.npy, ...), which only --K reads: the
    map is integrated orthographically (a folder holding cameras.txt did so without a word, a
    review). Looked for in a dataset folder given as the input, and beside a map file given
    by its path (not in a batch's items, whose folders the batch names once,
    :func:`facetlift.batch._unused_folder_files`). Returns the files' paths, for info."""
    from .io.dataset import unread_camera_advice, unread_camera_files

    if src.is_dir():
        folder = src
    elif job.unread_beside:
        folder = src.parent
    else:
        return []
    found = unread_camera_files(folder)
    if not found:
        return []
    names = " and ".join(p.name for p in found)
    where = (f"the dataset folder {src} holds {names}" if folder == src
             else f"{src.name} has {names} beside it")
    warn(f"{where}: {unread_camera_advice(found)}", UserWarning)
    return [str(p) for p in found]


def _beside_tail(job: Job, name: str) -> str:
    """The tail of a message on `name` ("prior", "confidence") where a batch found it beside
    the map (``NAME_prior_depth.*``, ``NAME_confidence.*``; ``job.beside``): what leaves such
    files unread, as a dataset folder's message says it; "" otherwise."""
    if name not in job.beside:
        return ""
    stem = "prior_depth" if name == "prior" else "confidence"
    return (f"; or leave the maps' NAME_{stem}.* files unread with --no-{name} "
            f"(dataset_{name}=False in Python)")


@contextlib.contextmanager
def _beside_file(job: Job, name: str):
    """A ValueError of its block with :func:`_beside_tail` added, where a batch found the
    file `name` beside the map: the user gave no such flag, and the message names the file
    (:func:`facetlift.io.read_prior` and ``read_weights`` do) but not the way out."""
    try:
        yield
    except ValueError as e:
        tail = _beside_tail(job, name)
        if not tail:
            raise
        raise ValueError(f"{e}{tail}") from None


def rotation_record(job: Job, inp: Input) -> dict | None:
    """The record's ``normal_rotation``: the rotation from world to the camera frame the
    normals were read in (``frame``, an axis string), the file it came from (``file``: the
    path given, or "the folder's NAME") and which way the file held it (``given_as``:
    "world_to_camera", or "camera_to_world" transposed); None without one."""
    if inp.rotation is None:
        return None
    from . import frames

    return {"world_to_camera": np.asarray(inp.rotation).tolist(),
            "frame": frames.axis_string(job.normal_frame), "file": inp.rotation_file,
            "given_as": inp.rotation_as}


def camera_source(job: Job, inp: Input) -> str:
    """Where the camera of `job` read as `inp` (:func:`read`) came from, as the summaries
    name it: "orthographic" without one, "K" (given), "fov D deg", or "the folder's K.txt"
    (a DiLiGenT folder's "../Calib_Results.mat"); integrate's and info's alike."""
    if inp.K is None:
        return "orthographic"
    if job.fov is not None:
        return f"fov {float(job.fov):g} deg"
    return "K" if job.K is not None else f"the folder's {inp.K_file or 'K.txt'}"


def _camera_name(path: Path, folder: Path) -> str:
    """A dataset folder's camera file as the summary names it: ``K.txt``, or
    ``../Calib_Results.mat`` where it is the parent's."""
    return path.name if path.parent == folder else f"../{path.name}"


def _beside_dataset_files(src: Path, job: Job, own_mask: bool = False) -> None:
    """Warn where a normal map given by its path lies in a dataset folder (``normal_map.*``
    beside ``K.txt``, ``mask.*`` or a rotation file, or DiLiGenT's ``Normal_gt.mat`` beside
    ``mask.png`` and with a camera file there or in its parent) whose files the job does not
    use: only the folder as the input reads them (a user's ``integrate bear/normal_map.png``
    ran orthographically on the valid normals, without the folder's K and mask, and no word;
    an audit). Not the mask where the map has its own (`own_mask`: a .mat file's)."""
    from .io.dataset import DILIGENT_NORMALS, _find, camera_files
    from .io.images import MASK_FORMATS

    folder = src.parent
    if src.stem.lower() != "normal_map" and src.name != DILIGENT_NORMALS:
        return
    unused = []
    try:
        cameras = camera_files(folder)
    except ValueError:  # (a folder named K.txt: the folder's own reading would say so)
        cameras = []
    camera = camera_unset(job) and bool(cameras)
    if camera:
        unused.append(f"{_camera_name(cameras[0], folder)} (its camera: the map is integrated "
                      "orthographically)")
    mpath = None
    if job.mask is None and not own_mask:
        try:
            mpath = _find(folder, "mask", MASK_FORMATS)
        except ValueError:  # (several mask files: the folder's own reading would say so)
            pass
    if mpath is not None:
        unused.append(f"{mpath.name} (its mask)")
    turns = rotation_files(unread_files(folder, None, mask=False, camera=False,
                                        rotation=rotation_field(job) is None))
    if turns:
        unused.append(f"{turns[0]} (its rotation: the world-space normals are read as the "
                      "camera's)")
    if unused:
        from .io.dataset import normals_file

        try:
            own = normals_file(folder)
        except ValueError:  # (the folder's own reading would say what is wrong with it)
            own = None
        # (a folder holding both normal_map.* and Normal_gt.mat reads the first: told to
        # integrate the folder, this map's user would get the other, a review)
        them = "them" if len(unused) > 1 else "it"
        how = (f"only the folder as the input reads {them} (facetlift integrate {folder})"
               if own is None or own.name == src.name else
               f"the folder as the input reads {them} with its {own.name}, not this map")
        # (the flags of the files named only: '--K / --mask' for a lone mask.png, a user's
        # check)
        flags = " / ".join(flag for flag, given in (
            ("--K", camera), ("--mask", mpath is not None),
            (rotation_flag(turns[0]) if turns else "", bool(turns)))
            if given)
        warn(f"{src} lies in a dataset folder whose {' and '.join(unused)} this run does not "
             f"read: {how}; or give {them} with {flags}", UserWarning)


def camera_unset(job: Job) -> bool:
    """Whether `job` leaves the camera unset (no --K, no --fov, no --orthographic), so that
    a ``K.txt`` beside its map, which only a dataset folder's reading takes, is one it misses
    (the one condition of the warnings on unread files, which wrote it out three times)."""
    return job.K is None and job.fov is None and not job.orthographic


def unread_files(folder: Path, stem: str | None, *, mask: bool, camera: bool,
                 prior: bool = False, confidence: bool = False,
                 rotation: bool = False) -> list[str]:
    """The names of the files in `folder` that a plain map file named `stem` (None: any map
    of the folder) would be read with if its folder were a dataset, or if it were a batch
    item, but that ``integrate`` does not read: ``mask.*`` and ``NAME_mask.*`` where
    `mask`, ``K.txt`` where `camera`, a batch item's ``NAME_prior_depth.*`` and
    ``NAME_confidence.*`` where `prior` and `confidence`, a dataset folder's rotation file
    (``world_to_camera.*``, ``camera_to_world.*``) where `rotation` (each only where the
    flags do not give one)."""
    from .batch import companions
    from .io.dataset import _find
    from .io.images import MASK_FORMATS

    found = []
    wanted = {"prior": prior, "confidence": confidence}
    for kind, suffix, formats in (companions() if stem is not None else ()):
        if not wanted.get(kind, False):  # (a batch's NAME_colors.*: cosmetic, not warned of)
            continue
        try:
            p = _find(folder, f"{stem}{suffix}", formats)
        except ValueError:  # (several of them: none is read, batch says so)
            p = None
        if p is not None:
            found.append(p.name)
    if mask:
        for name in ("mask",) + (() if stem is None else (f"{stem}_mask",)):
            try:
                p = _find(folder, name, MASK_FORMATS)
            except ValueError:  # (several of them, or a folder by that name: none is read)
                p = None
            if p is not None:
                found.append(p.name)
    if camera:  # (K.TXT too, as a dataset folder's is read, a review)
        from .io.dataset import _named

        try:
            k = _named(folder, "K.txt")
        except ValueError:
            k = None
        if k is not None and k.is_file():
            found.append("K.txt")  # (the name the advice below keys on)
    if rotation:
        from .io.dataset import ROTATION_FIELDS, ROTATION_FORMATS

        found += [f"{name}{ext}" for name in ROTATION_FIELDS for ext in ROTATION_FORMATS
                  if (folder / f"{name}{ext}").is_file()]
    return found


def rotation_files(names) -> list[str]:
    """The rotation files (``world_to_camera.*``, ``camera_to_world.*``) among the file
    `names` (:func:`unread_files`)."""
    from .io.dataset import ROTATION_FIELDS

    return [n for n in names if Path(n).stem in ROTATION_FIELDS]


def rotation_flag(name) -> str:
    """The flag that reads the rotation file `name` (:func:`rotation_files`):
    ``--world-to-camera`` or ``--camera-to-world``."""
    return f"--{Path(name).stem.replace('_', '-')}"


def _unread_beside(src: Path, job: Job, own_mask: bool = False) -> None:
    """Warn where a plain map file (not a dataset folder's ``normal_map.*``) has beside it a
    ``mask.*``, its ``NAME_mask.*`` or a ``K.txt`` that the job does not read: only --mask and
    --K give a plain map its mask and camera (a fresh user's mask.png beside the map was
    ignored without a word, while docs/cli.md said a folder's mask.png was its mask; an
    audit). Not for a mask where the map has its own (`own_mask`: a .mat file's)."""
    from .io.images import NORMAL_READ_FORMATS

    unread = unread_files(src.parent, src.stem, mask=job.mask is None and not own_mask,
                          camera=camera_unset(job), prior=job.prior is None,
                          confidence=job.confidence is None,
                          rotation=rotation_field(job) is None)
    if not unread:
        return
    turns = rotation_files(unread)
    # (a batch item's own prior and confidence, read by batch, not by integrate: a review)
    from .batch import companions

    stems = {f"{src.stem}{suffix}": f"--{kind}" for kind, suffix, _ in companions()}
    paired = {n: stems[Path(n).stem] for n in unread if Path(n).stem in stems}
    flags = " / ".join(f for f, given in (
        ("--mask", any(n != "K.txt" and n not in paired and n not in turns for n in unread)),
        ("--K", "K.txt" in unread), ("--prior", "--prior" in paired.values()),
        ("--confidence", "--confidence" in paired.values()),
        (rotation_flag(turns[0]) if turns else "", bool(turns))) if given)
    folder = src.parent
    own = [folder / f"normal_map{ext}" for ext in NORMAL_READ_FORMATS
           if (folder / f"normal_map{ext}").is_file()]
    # (in a dataset folder, "only with normal_map.*" read as if integrating the folder would
    # read this map with them: it reads the folder's normal_map.*, a review)
    why = (f"{src.name} is not this folder's {own[0].name}, the map that integrating the "
           f"folder ({folder}) reads as a dataset" if own and own[0].name != src.name
           else "a folder is read as a dataset only with normal_map.* or Normal_gt.mat")
    own_mask_file = any(Path(n).stem == f"{src.stem}_mask" for n in unread)
    warn(f"{src.name} has {' and '.join(unread)} beside it, which this run does not read: a "
         f"normal-map file's mask and camera come only from --mask and --K"
         + (", its prior and confidence from --prior and --confidence (facetlift batch "
            "pairs NAME_prior_depth.* and NAME_confidence.* with NAME.*)" if paired else "")
         + (", the rotation of world-space normals from --world-to-camera or "
            "--camera-to-world" if turns else "")
         + f" ({why}); give "
         f"{flags} to use "
         f"{'it' if len(unread) == 1 else 'them'}"
         + (" (without K.txt's camera the map is integrated orthographically)"
            if "K.txt" in unread else "")
         + (f" (without {turns[0]} its normals are read as the camera's)" if turns else "")
         + ("; facetlift batch reads NAME_mask.* beside NAME.* as its mask"
            if own_mask_file else ""),
         UserWarning)


def _from_folder(message: str, job: Job, inp: Input) -> str:
    """`message` with the dataset folder's files named where a method refused a prior or a
    confidence that the folder gave (a batch user's `--method bini` was refused a
    `confidence` it had not asked for, without the file or the flag that leaves it out); every
    such file the method does not take, so that one run says all (a review)."""
    from . import methods

    if not any(f"does not take a `{w}`" in message for w in ("prior", "confidence")):
        return _folder_named(message, job, inp)
    try:
        able = methods.get(job.method)
    except (KeyError, ValueError):
        return message
    # (a batch's NAME_prior_depth.* beside the map alike: --no-prior leaves those out too)
    own = [w for w in ("prior", "confidence") if w in job.beside]
    files = [(what, stem, flag) for what, given, stem, flag in (
        ("prior", (job.prior is None or "prior" in own) and inp.prior is not None,
         "prior_depth", "--no-prior"),
        ("confidence", (job.confidence is None or "confidence" in own)
         and inp.confidence is not None, "confidence", "--no-confidence"))
        if given and not getattr(able, what, True)]
    if not files:
        return message
    plural = "s" if len(files) > 1 else ""
    if own:
        what = (" and ".join(f"NAME_{stem}.*" for _, stem, _ in files)
                + f" file{plural} beside the map")
    else:
        what = ("the dataset folder's " + " and ".join(f"{stem}.*" for _, stem, _ in files)
                + f" file{plural}")
    flags = " ".join(flag for *_, flag in files)
    # (and the Python switches: facetlift.batch's user was named the flags only, a review)
    python = ", ".join(f"dataset_{name}=False" for name, _, _ in files)
    return (f"{message} ({what}, "
            f"which this method does not take: {flags} leave{'s' if len(files) == 1 else ''} "
            f"{'it' if len(files) == 1 else 'them'} out, {python} in Python)")


def _folder_named(message: str, job: Job, inp: Input, warning: bool = False) -> str:
    """`message` about the `prior` or `confidence` that a dataset folder gave (no such flag:
    ``facetlift.cli`` leaves the Python name, which pointed nowhere, a user's check) with the
    file named and the flag that leaves it unread (a `warning`'s: that it can be)."""
    for name, flag in (("prior", "--no-prior"), ("confidence", "--no-confidence")):
        if not message.startswith(f"`{name}`"):
            continue
        rest = message[len(name) + 2:]
        if name in job.beside:  # (a batch's NAME_prior_depth.* beside the map, a review)
            tail = _beside_tail(job, name)
            return (f"`{name}` ({Path(getattr(job, name)).name}){rest}"
                    + (f" ({tail[len('; or '):]})" if warning else tail))
        file = getattr(inp, f"{name}_file")
        if getattr(job, name) is None and file:
            python = f"dataset_{name}=False in Python"
            tail = (f" ({flag} leaves it unread, {python})" if warning
                    else f"; or leave it unread with {flag} ({python})")
            return f"`{name}` ({file}){rest}{tail}"
    return message


def check_fov(job: Job) -> None:
    """A job's `fov` checked: a field of view (:func:`facetlift.camera.K_from_fov`) and not
    with `K` or `orthographic`, which it contradicts (ValueError naming them)."""
    if job.fov is None:
        return
    from .camera import fov_degrees

    fov_degrees(job.fov)  # (no warning: K_from_fov gives its own once, with the map's size)
    clash = "K" if job.K is not None else ("orthographic" if job.orthographic else None)
    if clash:
        raise ValueError(f"`fov` {float(job.fov):g} and `{clash}` contradict each other; "
                         "give one")


def _no_prior_checks(job: Job) -> None:
    """Refuse the prior's own settings in a job without a prior (ValueError naming each);
    in a batch item of :attr:`Job.prior_optional`, warn that they are not applied."""
    if job.prior_optional:
        _unused_prior_settings(job)
        return
    if job.prior_scale is not None:
        raise ValueError("`prior_scale` applies only with a prior (a dataset folder's "
                         "prior_depth file, or integrate's --prior)")
    for name, given in (("prior_weight_map", job.prior_weight_map is not None),
                        ("prior_weight", job.prior_weight not in (None, 1.0))):
        if given:
            raise ValueError(f"`{name}` applies only with a prior (--prior or a dataset's "
                             "prior_depth file)")
    if job.prior_blur is not None:  # (its value's own errors first, then the missing prior)
        from .problem import check_prior_blur

        check_prior_blur(job.prior_blur, has_prior=False)
    if job.prior_outliers is not None:
        from .problem import check_prior_outliers

        check_prior_outliers(job.prior_outliers, has_prior=False)
    if job.prior_fit not in (None, "none"):
        from .prior_fit import check

        check(job.prior_fit, has_prior=False, perspective=True)


def _unused_prior_settings(job: Job) -> None:
    """Check the values of the prior's settings of a batch item without a prior, and warn
    that they are not applied (nothing where none is given)."""
    from .prior_fit import check
    from .problem import check_prior_blur, check_prior_outliers

    given = []
    if job.prior_scale is not None:
        given.append(f"--prior-scale {job.prior_scale:g}")
    if job.prior_weight not in (None, 1.0):
        given.append(f"--prior-weight {job.prior_weight:g}")
    if job.prior_weight_map is not None:
        given.append(f"--prior-weight-map {job.prior_weight_map}")
    if job.prior_blur is not None:
        check_prior_blur(job.prior_blur, has_prior=True)
        given.append(f"--prior-blur {job.prior_blur:g}")
    if job.prior_outliers is not None:
        check_prior_outliers(job.prior_outliers, has_prior=True)
        given.append(f"--prior-outliers {job.prior_outliers}")
    if job.prior_fit not in (None, "none"):
        check(job.prior_fit, has_prior=True, perspective=True)
        given.append(f"--prior-fit {job.prior_fit}")
    if given:
        warn(f"no depth prior for this map (NAME_prior_depth.* beside it, or a dataset "
             f"folder's prior_depth.*): integrated from its normals alone; "
             f"{', '.join(given)} not applied")


def _normals_from_field(g: dict, job: Job) -> tuple[np.ndarray, str | None]:
    """The normals made from the field `g`, and the other layout its layout check named
    (None where none: :attr:`Input.layout`)."""
    from . import frames
    from .problem import normals_from_gradients

    if job.normal_frame is not None:
        # (--y-down sets it too, and was named `normal_frame`, an audit)
        raise ValueError("a normal frame (normal_frame=; --normal-frame or --y-down) does not "
                         "apply to a gradient field; use --gradient-frame")
    layout = frames.layout_check(g["p"], g["q"], job.gradient_frame, g.get("mask"))["suggested"]
    return normals_from_gradients(*frames.gradients_to_facetlift(g["p"], g["q"],
                                                                 job.gradient_frame)), layout


@contextlib.contextmanager
def recorded_warnings(on_warning=None):
    """The warnings of its block, recorded (for the job's record); if the block raises, they
    are given again on the way out, so that a caller's own record (a failed batch item's)
    keeps them: they may say why it failed. `on_warning` (callable(message)), where given,
    also hears each as it is raised (a command line's progress bar shows them then, not
    after the run)."""
    kept: list = []
    try:
        with recording(on_warning=on_warning) as caught:
            kept = caught
            yield caught
    except BaseException:
        if on_warning is None:  # (a caller that heard them as they came has them already)
            for w in kept:
                reemit(w)
        raise


def _check_outputs(save, job: Job, local: bool = True) -> None:
    """Refuse outputs the job cannot produce before it runs: the report without matplotlib
    (where it is drawn here: `local`), the discontinuity map without ``discontinuities`` (the
    method's value, given or default) or from a method that makes none.

    Raises
    ------
    ImportError, ValueError
    """
    if "report" in save and local:
        try:
            import matplotlib.figure  # noqa: F401
        except ImportError as e:
            raise ImportError(
                "the report (--save report) needs matplotlib, which comes with the plot "
                "extra: pip install 'facetlift[plot]'"
            ) from e
    if "discontinuities" in save:
        from . import methods
        from .options import validate

        info = methods.get(job.method)
        if not info.jump_map:
            able = sorted(k for k, v in methods.REGISTRY.items() if v.jump_map)
            raise ValueError(
                "`save`: 'discontinuities' (discontinuities.png, the map of depth jumps) comes "
                f"only from {able} with --discontinuities; method {job.method!r} gives none"
            )
        opts = {k: v for k, v in dict(job.options).items() if k != "max_memory"}
        # (every option checked: a misspelt one is named as such, not taken as absent)
        if not validate(info.specs(), opts, job.method)["discontinuities"]:
            raise ValueError(
                "`save`: 'discontinuities' (discontinuities.png, the map of depth jumps) needs "
                "a surface with jumps: add --discontinuities (discontinuities=True)"
            )


def check_height_range(job: Job, save=None) -> None:
    """A job's `height_range` checked (:func:`facetlift.io.preview.check_height_range`,
    ValueError naming it), and a warning where `save` (default the job's) writes no height
    PNG for it to apply to."""
    if job.height_range is None:
        return
    from .io.preview import check_height_range as check

    check(job.height_range)
    save = job.save or DEFAULT_SAVE if save is None else save
    if "height" not in save:  # (accepted and ignored: as output_frame without a mesh)
        warn(f"`height_range` {list(job.height_range)} applies to height.png (save "
             "'height'), which is not saved: "
             + ("height.exr holds the heights themselves" if "height-exr" in save
                else "nothing is scaled by it"))


def run(job: Job, *, progress=None, on_warning=None) -> dict:
    """Run `job`: outputs written as one set; returns its record.

    Parameters
    ----------
    job : Job
    progress : callable(iteration, value), optional
        Passed to methods that report progress; with a ``stage`` attribute it also hears
        the job's steps start ("reading", "integrating", "writing outputs" and the method's
        own: :mod:`facetlift._progress`).
    on_warning : callable(message), optional
        Hears each warning as it is raised (they are in the record's ``warnings`` too).

    Returns
    -------
    dict
        ``input``, ``outputs`` (kind -> path), ``shape``, ``facets``, ``components`` (the
        mask's connected components), ``mask_source``,
        ``perspective``, ``mean_deviation`` (degrees), ``converged``, ``warnings`` (messages),
        ``info`` (JSON-ready ``Surface.info``) and ``timings`` (seconds per phase).

    Raises
    ------
    ValueError, OSError
        Bad input, or an output folder that cannot be written.
    facetlift.SolverError, facetlift.MemoryLimitError
        As :func:`facetlift.integrate`.
    """
    import facetlift

    from . import frames, io, methods

    t0 = time.perf_counter()
    info = methods.get(job.method)
    save = tuple(dict.fromkeys(job.save or DEFAULT_SAVE))
    unknown = [s for s in save if s not in OUTPUTS]
    if unknown:
        raise ValueError(f"`save`: unknown output(s) {unknown}; valid: {sorted(OUTPUTS)}")
    _check_outputs(save, job)  # (before any reading or solving: not after the whole job)
    # (said again in the job's record below: a batch item's record, which is that record,
    # lost them, a review; said before an error of these checks goes on, as before)
    with said_if_raised() as early:
        if job.output_frame is not None:
            frames.parse(job.output_frame, "output_frame")
            if not set(save) & {"ply", "obj", "stl", "points"}:  # (accepted and ignored)
                warn(f"`output_frame` {job.output_frame!r} applies to the mesh and point "
                     "outputs (ply, obj, stl, points), none of which is saved: depth maps "
                     "stay in facetlift's convention (depth along the viewing axis)")
        if job.colors is not None and not set(save) & COLOURED and "colors" not in job.beside:
            warn(f"`colors` {job.colors} paints only the ply, obj and points outputs, none of "
                 "which is saved: add -s ply, -s obj or -s points")
        if job.triangles is False and "stl" in save and not set(save) & {"ply", "obj"}:
            warn("quad faces (--quads; `triangles` False) apply to the ply and obj meshes, "
                 "neither of which is saved: mesh.stl holds triangles (STL has no quads)")
        elif job.triangles is not None and not set(save) & {"ply", "obj", "stl"}:
            # (accepted and ignored before, where --colors and --output-frame warn, a review)
            which = ("triangles (--triangles, triangles=True in Python)" if job.triangles
                     else "quads (--quads, triangles=False in Python)")
            warn(f"mesh faces as {which} apply to the ply and obj meshes, neither of which is "
                 "saved: add -s ply or -s obj")
        check_height_range(job, save)
    src = job.source
    outdir = default_outdir(src) if job.outdir is None else Path(job.outdir)
    names = [OUTPUTS[s] for s in save]
    # (one record of the whole job's warnings, the gradient layout's, ...: given again if any
    # phase fails, a write or the outputs' commit too)
    with recorded_warnings(on_warning) as caught, \
            io.OutputSet(outdir, names, inputs=input_paths(job),
                         cancel=job.cancel_mark) as out:
        for w in early:
            reemit(w)
        announce(progress, "reading")
        inp = read(job)
        # (before the solve: a wrong image fails the job at once)
        rgb = None
        if job.colors is not None and set(save) & COLOURED:
            try:
                rgb = io.read_colors(job.colors, inp.normals.shape[:2])
            except ValueError as e:  # (a batch's NAME_colors.*: which file, and the way out)
                if "colors" not in job.beside:
                    raise
                raise ValueError(f"{e} (the map's NAME_colors file beside it, which a batch "
                                 "paints its meshes with: rename it to leave it unread)"
                                 ) from None
        t_read = time.perf_counter() - t0
        opts = dict(job.options)
        if progress is not None and "progress" in info.options() and "progress" not in opts:
            opts["progress"] = progress
        if isinstance(opts.get("prior"), str) and inp.prior is not None:
            raise ValueError("`prior`: a depth prior (--prior or prior_depth file) and the "
                             f"method option prior={opts['prior']!r} were both given")
        depth_prior = opts.pop("prior", None) if inp.prior is None else inp.prior
        t1 = time.perf_counter()
        announce(progress, "integrating")
        # (the normals were read in the job's frame already: the rotation goes from world
        # to that frame, and is given to integrate as one to facetlift's)
        turn = frames.rotation_in_facetlift(inp.rotation, job.normal_frame)
        with frames.read_in(frames.GRADIENT_FIELD if inp.field else job.normal_frame,
                            layout=inp.layout,
                            normal_range=frames.normal_range(job.normal_range)):
            try:
                with renamed(lambda m: _folder_named(m, job, inp, warning=True)):
                    surface = facetlift.integrate(
                        inp.normals, inp.mask, method=job.method, pixel_size=job.pixel_size,
                        K=inp.K, backfacing=job.backfacing, outlier_eps=job.outlier_eps,
                        normal_rotation=turn,
                        prior=depth_prior,
                        prior_weight=inp.prior_weight if inp.prior is not None else None,
                        confidence=inp.confidence,
                        prior_blur=job.prior_blur if inp.prior is not None else None,
                        **({} if job.prior_outliers is None or inp.prior is None
                           else {"prior_outliers": job.prior_outliers}),
                        **({} if job.prior_fit is None or inp.prior is None
                           else {"prior_fit": job.prior_fit}), **opts,
                    )
            except ValueError as e:
                said = _from_folder(str(e), job, inp)
                if said == str(e):
                    raise
                raise ValueError(said) from None
        t_integrate = time.perf_counter() - t1
        if not inp.field and not frames.is_identity(job.normal_frame):
            # (the frame the map was read in: the result's normals are written in it, also
            # from its surface.npz, as --save normals writes them, a review)
            surface.info["input_frame"] = frames.axis_string(job.normal_frame)
        if job.strict:  # (before the outputs: nothing is written)
            _strict_check(caught, surface)
        t2 = time.perf_counter()
        announce(progress, "writing outputs")
        # (the normals as integrate was given them: Surface.save turns them by the rotation
        # it records, so the points' normals and the report's deviation are of the camera
        # frame's, not of world-space ones as read)
        for kind, name in zip(save, names, strict=True):
            try:
                _write(surface, kind, out.path(name), inp.normals, job.triangles,
                       job.output_frame, job.height_range, rgb)
            except OSError as e:  # (say which and where: the file written is a staging one)
                if e.errno is None:
                    raise
                raise OSError(e.errno, f"{e.strerror} (writing {name} for {outdir}; nothing "
                                       "was written there)") from e
            except MemoryError as e:  # (after a whole solve: said which output, a review's
                # 4096^2 job that fit died here with "try a crop, a smaller map")
                from .errors import OutputMemoryError

                raise OutputMemoryError(f"{e}, writing {name} after the solve had finished; "
                                        f"nothing was written to {outdir}: save fewer or "
                                        "smaller outputs (-s), or free memory") from e
        # (a dataset folder's depth_gt.*, as BiNI's DiLiGenT folders hold it: scored by
        # facetlift evaluate's measures, so a batch over such folders compares methods; here,
        # where its warning is the record's)
        evaluation = _evaluate_against_gt(src, surface)
        stale = [n for n in OUTPUTS.values() if n not in names and (outdir / n).is_file()]
        if stale:  # (left as they are: the folder is the user's; said, so none is mistaken)
            warnings.warn(f"the output folder {outdir} also holds {', '.join(stale)} from an "
                          "earlier run, not written now: they are not of this result",
                          stacklevel=2)
    written = {kind: str(outdir / name) for kind, name in zip(save, names, strict=True)}
    sinfo = surface.info
    H, W = surface.shape
    return {
        "input": str(src),
        "outputs": written,
        "shape": [H, W],
        "facets": int(surface.mask.sum()),
        # (its connected components, each with a constant of its own: an alpha holding a
        # height splits into one per brick, all at mean depth 0, a second audit)
        "components": _components(surface.mask),
        "mask_source": inp.mask_source,
        # (the input was a gradient field, not a normal map: the summary counts its samples)
        "gradient_field": inp.field,
        "perspective": surface.K is not None,
        # (where the camera came from, for the summary: K, a field of view, a dataset's K.txt)
        "camera": camera_source(job, inp) if surface.K is not None else "orthographic",
        # (the files the prior and the confidence came from: a dataset folder's are read
        # without asking)
        "prior_file": inp.prior_file,
        "confidence_file": inp.confidence_file,
        # (the image that painted the meshes and points, --colors; none where none was)
        "colors_file": job.colors if rgb is not None else None,
        # (normals in world space: the rotation to the camera frame of --normal-frame, and
        # its file; None for camera-frame normals)
        "normal_rotation": rotation_record(job, inp),
        # (the depth of height.png's 0 and 65535, as io.write_height scales it)
        "depth_range": _depth_range(surface, job.height_range if "height" in save else None),
        "mean_deviation": jsonable(sinfo.get("mean_deviation")),
        "evaluation": evaluation,
        "converged": bool(sinfo.get("converged", True)),
        # (how many mask pixels had no usable normal, by reason: a batch's missing normals
        # were nowhere in batch.jsonl, a photometric-stereo user's check)
        "normals": _normal_counts(sinfo),
        "warnings": [str(w.message) for w in caught],
        # (whether one of them says the camera looks wrong: the jump hint then points at it)
        "camera_warned": any(issubclass(w.category, CameraWarning) for w in caught),
        "info": jsonable(sinfo),
        "timings": {"read": t_read, "integrate": t_integrate,
                    "write": time.perf_counter() - t2, "total": time.perf_counter() - t0},
    }


#: Ground-truth depth files a dataset folder may hold (BiNI's DiLiGenT folders:
#: ``depth_gt.npz`` with the array ``depth_gt``), scored in the job's record.
GT_NAMES = ("depth_gt.npz", "depth_gt.npy", "depth_gt.exr", "depth_gt.tif", "depth_gt.tiff")

#: The arrays of a ground truth's ``.npz`` looked for, in order (BiNI's ``depth_gt``; a
#: :meth:`facetlift.Surface.save` archive's ``depth``): ``facetlift evaluate --gt`` too.
GT_NPZ_NAMES = ("depth_gt", "depth")


def _evaluate_against_gt(src: Path, surface) -> dict | None:
    """The record's ``evaluation``: :func:`facetlift.metrics.evaluate` of `surface` against
    the first of :data:`GT_NAMES` in the dataset folder `src` (``gt``: its name), or None
    where `src` is no folder or holds none. A ground truth that cannot be scored (another
    size, unreadable) is warned about and gives None: it never fails the job."""
    if not Path(src).is_dir():
        return None
    gt = next((Path(src) / n for n in GT_NAMES if (Path(src) / n).is_file()), None)
    if gt is None:
        return None
    from . import io, metrics

    try:
        truth = io.read_depth(gt, npz_names=GT_NPZ_NAMES, arg="ground truth")
        if truth.shape != surface.depth.shape:  # (said in the command line's words, not
            # evaluate's `truth` and `estimate`, a user's check)
            raise ValueError(f"it is {truth.shape[0]}x{truth.shape[1]} (HxW), the normal map "
                             f"{surface.depth.shape[0]}x{surface.depth.shape[1]}")
        # (its warnings, e.g. an orthographic result's range unlike the truth's: --pixel-size,
        # are the job's too)
        # (run from the command line or Python: its warnings name both)
        scores = metrics._evaluate(surface, truth, surface.mask, None, "both")
    except ValueError as e:
        warn(f"{gt.name} in {src}: not scored ({e})")
        return None
    keep = ("pixels", "uncovered", "perspective", "made", "scale", "rmse_scaled", "mae",
            "normalized_error")
    return {"gt": gt.name, **{k: jsonable(scores.get(k)) for k in keep}}


def _components(mask) -> int:
    """The connected components of `mask`, as the integration's domain counts them (facets
    sharing a corner: 8-connected), by one labelling (a whole Domain was built for it, 0.22 s
    and 90 MB at 4096^2, a review)."""
    from scipy import ndimage

    from .domain import _EIGHT

    return int(ndimage.label(mask, structure=_EIGHT)[1])


def _zero_unknown(job) -> bool:
    """Whether an integer prior file's 0 marks an unknown depth (a sensor's): not for a prior
    aligned by ``prior_fit``, a network's relative depth or disparity scaled to start at 0
    (:func:`facetlift.io.read_prior`)."""
    return job.prior_fit in (None, "none")


def _prior_scale(job: Job) -> float | None:
    """The depth units per count of a 16-bit PNG prior: ``--prior-scale``, or 1 where
    ``--prior-fit`` aligns the prior (affine, scale, disparity), whose scale the fit takes
    whatever it is (a monocular network's 16-bit disparity PNG was refused for want of a
    --prior-scale that cannot matter, an audit)."""
    if job.prior_scale is None and job.prior_fit not in (None, "none"):
        return 1.0
    return job.prior_scale


def _strict_check(caught, surface) -> None:
    """``strict``: a ValueError where the input's frame looks wrong: a
    :class:`facetlift.FrameWarning` that is no :class:`facetlift.errors.FrameHint` (which
    right inputs give too), or many normals facing away (the unusable-normals warning's
    question about another frame or BGR order). Its first clause says why; the warning
    itself, printed before, the rest."""
    from .errors import FrameHint, FrameWarning
    from .problem import BACKFACING_FRAME_HINT

    why = [str(w.message).split(": ", 1)[0] for w in caught
           if issubclass(w.category, FrameWarning) and not issubclass(w.category, FrameHint)]
    away = surface.info.get("input", {}).get("facing_away", 0.0)
    if not why and away > BACKFACING_FRAME_HINT:
        why = [f"{away:.0%} of the normals face away from the camera"]
    if why:
        raise ValueError(f"`strict`: the input's frame looks wrong ({why[0]}; the warning "
                         "above says what to try); nothing was written")


#: The counts of info["input"] a job record keeps (``normals``: batch.jsonl and
#: ``integrate --json``), in this order. ``holes`` and ``larger_holes`` (without a mask, the
#: pixels enclosed by the object without a valid normal, :func:`facetlift.problem.
#: enclosed_gaps`) lie outside the mask and are not among its ``pixels``: they are there so a
#: batch's log says where its depths have holes, as ``info`` and integrate's warning do.
NORMAL_COUNTS = ("pixels", "usable", "missing", "non-finite", "zero-length", "back-facing",
                 "grazing", "isolated", "zero_confidence", "holes", "larger_holes")


def _normal_counts(info: dict) -> dict:
    """Pixels of the mask and how many had a usable normal or none, by reason, and the
    enclosed holes outside it (those of :data:`NORMAL_COUNTS` that the method's info has)."""
    counts = info.get("input") or {}
    return {k: int(counts[k]) for k in NORMAL_COUNTS
            if isinstance(counts.get(k), (int, np.integer))}


def _depth_range(surface, height_range=None) -> list | None:
    """The depth of height.png's 0 and 65535: ``[largest, smallest]`` finite depth (None
    without one), or those of `height_range`'s heights."""
    if height_range is not None:  # ("0.0 -": a height of 0 is depth 0.0, not -0.0)
        return [0.0 - float(height_range[0]), 0.0 - float(height_range[1])]
    d = np.asarray(surface.depth, dtype=float)
    ok = np.isfinite(d)
    return [float(d[ok].max()), float(d[ok].min())] if ok.any() else None


def _write(surface, kind: str, path: Path, normals, triangles, frame=None,
           height_range=None, colors=None) -> None:
    """Output `kind` at `path` (named :data:`OUTPUTS`' `kind`): by :meth:`Surface.save`,
    which writes the command line's file names as ``--save`` does (one writer for both: its
    points.ply was a mesh, a review). `colors`: the (H, W, 3) image painted on the kinds of
    :data:`COLOURED`. The result's normals are written in the frame the input was read in,
    which the surface records (``info["input_frame"]``)."""
    if Path(path).name != OUTPUTS[kind]:  # pragma: no cover - a caller's bug
        raise ValueError(f"{kind} output must be named {OUTPUTS[kind]}; got {path}")
    if kind in ("ply", "obj"):
        kw = {"frame": frame, **({} if triangles is None else {"triangles": triangles})}
    elif kind == "stl":  # (triangles only: --quads is for the others, warned where alone)
        kw = {"frame": frame}
    else:
        kw = {"report": {"normals": normals}, "points": {"normals": normals, "frame": frame},
              "height": {"height_range": height_range}}.get(kind, {})
    if colors is not None and kind in COLOURED:
        kw["colors"] = colors
    surface.save(path, **kw)


def finished_unconverged(info: dict) -> bool:
    """Whether a result reported ``converged=False`` is nevertheless a finished, usable
    surface: the discontinuity reweighting stopped by its cap (a budget), BiNI's reweighting
    by its ``max_iter`` (as BiNI's own code stops and returns its surface; a BiNI user's run
    exited 2, an audit), or the blurred prior's corrections by their cap (a safety net). The
    command line notes these with exit 0 and a batch records them as ok; any other
    unconverged result is a solver failure."""
    return info.get("solver") == "discontinuous" or info.get("method") == "bini" or bool(
        (info.get("prior_blur") or {}).get("capped"))


def jsonable(obj):
    """`obj` with numpy values, tuples and non-finite floats turned into JSON (None for NaN)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    return repr(obj)
