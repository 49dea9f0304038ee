"""The ``facetlift`` command line: a thin layer over :func:`facetlift.integrate` and
:mod:`facetlift.io`.

``main(argv)`` returns an exit code: 0 success, 1 bad input (unreadable file, bad option,
input the method cannot take, unwritable output, memory limit), 2 solver failure
(:class:`facetlift.SolverError` or no convergence), 3 internal error (a bug), 130
interrupted, 143 terminated. Errors are one line on stderr, without a traceback.
See ``docs/cli.md``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import sys
import time
import warnings
from pathlib import Path

import click

from . import __version__
from . import methods as _methods
from ._progress import progress_bar as _progress_bar
from .errors import SolverError
from .hints import jump_hint, torn_hint
from .jobs import DEFAULT_SAVE, OUTPUTS, jsonable

log = logging.getLogger(__name__)

EXIT_OK, EXIT_INPUT, EXIT_SOLVER, EXIT_BUG = 0, 1, 2, 3
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143

#: Set by ``facetlift --debug``: print the traceback of an internal error.
_STATE = {"debug": False}


class SolverFailure(Exception):
    """The method ran but did not converge (outputs were written; exit code 2)."""


CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(context_settings=CONTEXT)
@click.version_option(__version__, "-V", "--version", prog_name="facetlift")
@click.option("-v", "--verbose", count=True,
              help="Log the library's progress on stderr (-vv for debug detail).")
@click.option("--debug", is_flag=True,
              help="On an internal error (a bug), print the full traceback.")
def cli(verbose, debug):
    """facetlift: turn a normal map into a depth map and a mesh (normal integration).

    \b
    Examples:
      facetlift integrate normal_map.png --mask mask.png
      facetlift integrate data/bear/ -o bear_out --save exr --save ply
      facetlift methods
      facetlift evaluate bear_out --gt data/bear/depth_gt.npz --K data/bear/K.txt
      facetlift bench --quick -o bench_out

    Run 'facetlift COMMAND --help' for the options of a command.
    """
    _STATE["debug"] = _STATE["debug"] or debug
    if verbose:
        root = logging.getLogger("facetlift")
        handler, level = _StderrHandler(), root.level
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        root.addHandler(handler)
        root.setLevel(logging.INFO if verbose == 1 else logging.DEBUG)

        def restore():
            root.removeHandler(handler)
            root.setLevel(level)

        click.get_current_context().call_on_close(restore)


class _StderrHandler(logging.StreamHandler):
    """Logs to whatever ``sys.stderr`` is when a record is emitted, through ``tqdm.write``:
    a progress bar in flight is cleared and drawn again below the line (with -v --progress a
    review's log lines were glued to the bar's text)."""

    def emit(self, record):
        try:
            from tqdm import tqdm

            tqdm.write(self.format(record), file=sys.stderr)
        except Exception:  # pragma: no cover - logging's own policy
            self.handleError(record)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


#: integrate's own arguments, which --option cannot carry: the flag that does (they reached
#: integrate twice, an internal error). ("prior" stays: regularization's option of that name.)
RESERVED_OPTIONS = {
    "normals": "the NORMALS argument", "gradients": "--gradients", "mask": "--mask",
    "method": "--method", "pixel_size": "--pixel-size", "K": "--K",
    "known": "NaN normals in the map (missing samples; the command line has no `known`)",
    "backfacing": "--backfacing", "outlier_eps": "--outlier-eps",
    "normal_frame": "--normal-frame", "prior_weight": "--prior-weight",
    "normal_rotation": "--world-to-camera or --camera-to-world",
    "confidence": "--confidence", "prior_blur": "--prior-blur",
    "prior_outliers": "--prior-outliers", "prior_fit": "--prior-fit", "progress": "--progress",
}


def _same_option(key: str, a, b) -> bool:
    """Whether an --option value and a flag's say the same (a memory size in any spelling)."""
    if key == "max_memory":
        from .memory import parse_size

        try:
            return parse_size(a) == parse_size(b)
        except ValueError:
            return False
    return a == b


def _parse_option(text: str) -> tuple[str, object]:
    if "=" not in text:
        raise click.BadParameter(f"expected KEY=VALUE; got {text!r}", param_hint="--option")
    key, value = text.split("=", 1)
    key = key.strip().replace("-", "_")
    if not key.isidentifier():
        raise click.BadParameter(f"{key!r} is not an option name", param_hint="--option")
    if key in RESERVED_OPTIONS:
        raise click.BadParameter(f"{key!r} is not a method option: give "
                                 f"{RESERVED_OPTIONS[key]}", param_hint="--option")
    # (Python's spellings too, as `facetlift methods` prints the defaults: True, None and
    # inf were refused as strings, an audit)
    python = {"True": True, "False": False, "None": None, "inf": float("inf"),
              "-inf": float("-inf")}
    if value.strip() in python:
        return key, python[value.strip()]
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value  # a bare string such as solver=iterative


#: The endings of the files facetlift reads and writes, by the ``-s`` kind that writes one:
#: an ``-o`` ending so names a file, not the folder it is (:func:`_out_dir`).
_FILE_ENDINGS = {".npy": "npy", ".png": "png", ".exr": "exr", ".tif": "tif", ".tiff": "tif",
                 ".ply": "ply", ".obj": "obj", ".stl": "stl", ".npz": "npz"}


def _out_dir(ctx, param, value):
    """``-o``/``--out`` as a Path; an empty one is refused (click would read it as the
    current folder, and write every output there), and so is one ending like a file
    (``-o out.npy`` made a folder named out.npy, a review) unless that folder exists."""
    if value is None:
        return None
    if not str(value).strip():
        raise click.BadParameter("is empty: give a folder")
    path = Path(value)
    kind = _FILE_ENDINGS.get(path.suffix.lower())
    if kind is not None and not path.is_dir():
        raise click.BadParameter(
            f"{value!r} ends like a file name, but -o is the output folder, written with fixed "
            f"names ({', '.join(OUTPUTS[k] for k in DEFAULT_SAVE)} by default; -s picks "
            "which, and no option names a single output file): give a folder, e.g. -o "
            f"{path.with_suffix('')} -s {kind} to write "
            + (f"{path.with_suffix('') / '<item>' / OUTPUTS[kind]} for every item"
               if ctx.info_name == "batch" else f"{path.with_suffix('') / OUTPUTS[kind]}"))
    return path


class _CameraFile(click.Path):
    """A --K value: a K file, or where no such path exists the intrinsics typed inline, four
    numbers fx fy cx cy or the nine of the matrix row by row (spaces or commas), kept as the
    text with its numbers parsed once (:class:`facetlift.io.dataset.InlineK`: numbers that
    are no valid K are refused when the job reads its camera, as a file's are); anything else
    is a missing file, as before (``--K "3772 3759 305.9 255.1"`` said "File ... does not
    exist", a fresh user's review)."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and not os.path.exists(value):
            from .io.dataset import inline_value

            inline = inline_value(value)
            if inline is not None:
                return inline
            # (what --K takes, where it is neither: "--K 420" and "--K 'fx=420 ...'" were
            # told "File '420' does not exist" alone, a review)
            self.fail(f"File {value!r} does not exist, and it is no K typed inline: --K takes "
                      "a K file (text, JSON, .npy, .mat, or a calibration tool's: OpenCV "
                      ".yml/.xml, ROS camera_info, COLMAP cameras.txt/.bin, transforms.json), "
                      "or four numbers fx fy cx cy (--K \"420 420 319.5 239.5\"), or the "
                      "matrix's nine row by row, as numbers alone (no names, no '='); for a "
                      "field of view, --fov DEG", param, ctx)
        return super().convert(value, param, ctx)


#: --K's type, for integrate, batch, info and evaluate alike.
CAMERA_FILE = _CameraFile(exists=True, dir_okay=False, path_type=Path)

#: The options ``integrate`` and ``batch`` share: what to read and how to integrate it.
_JOB_OPTIONS = [
    click.option("-m", "--mask", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                 help="Mask image (PNG/TIFF/npy/PFM, nonzero = integrate). Default: the dataset's "
                 "mask.png, else the alpha channel, else every pixel with a valid normal."),
    click.option("--normal-frame", "normal_frame", metavar="FRAME",
                 help="Frame of the normal map: opengl (default: x right, y up, z toward the "
                 "viewer; alias gl), directx (y down; aliases dx, unreal), opencv (y down, z "
                 "away), or an axis string such "
                 "as 'x,-y,-z' (docs/conventions.md lists common sources)."),
    click.option("--y-down", is_flag=True, help="Alias of --normal-frame directx."),
    click.option("--world-to-camera", "world_to_camera", metavar="FILE",
                 type=click.Path(exists=True, dir_okay=False, path_type=Path),
                 help="Normals in world space (a multi-view pipeline's; COLMAP's R with "
                 "--normal-frame opencv): the rotation from world to the camera frame of "
                 "--normal-frame, as text (3x3, or a 3x4 / 4x4 pose: its upper-left 3x3; "
                 "spaces or commas, # comments), .npy or JSON (a list, or an object with one "
                 "matrix such as \"R\"). A dataset folder's world_to_camera.txt is used "
                 "automatically. docs/conventions.md."),
    click.option("--camera-to-world", "camera_to_world", metavar="FILE",
                 type=click.Path(exists=True, dir_okay=False, path_type=Path),
                 help="Instead of --world-to-camera: the camera's pose, camera to world "
                 "(Blender's camera.matrix_world, for its world-space Normal pass), "
                 "transposed; files as for --world-to-camera. A dataset folder's "
                 "camera_to_world.txt is used automatically."),
    click.option("--normal-encoding", "normal_encoding", type=click.Choice(["xyz", "xy"]),
                 default="xyz", show_default=True,
                 help="How the map stores its normals: xyz = x, y, z in R, G, B; xy = a "
                 "two-channel map (BC5, RG, as game engines compress normal maps): x and y in "
                 "R and G, z rebuilt as sqrt(1 - x^2 - y^2) facing the viewer, B ignored; "
                 "from RGB(A) PNG/TIFF/npy, two-channel TIFF/npy (H, W, 2) or EXR R, G (a "
                 "two-channel PNG is grey + alpha)."),
    click.option("--normal-range", "normal_range", type=click.Choice(["signed", "unsigned"]),
                 default="signed", show_default=True,
                 help="The range of a float map's components: signed = n itself, in [-1, 1]; "
                 "unsigned = (n + 1) / 2 in [0, 1], as many renderers and networks write EXR, "
                 "float TIFF or .npy maps, decoded as 2 v - 1 first (x and y alone with "
                 "--normal-encoding xy). 8/16-bit PNG/TIFF maps are always decoded from their "
                 "integer range and refuse unsigned."),
    click.option("--gradient-frame", default="xy", show_default=True,
                 help="Layout of a gradient field: xy (p = dz/dx right, q = dz/dy up), "
                 "rowcol (aliases queau, numpy: p = dz/d(row) down, q = dz/d(col)) or image "
                 "(aliases matlab, opencv: p = dz/d(col), q = dz/d(row) down). z is a "
                 "height (larger = nearer): slopes of a depth map are negated. The slopes are "
                 "depth per unit of x and y, a pixel being --pixel-size wide; a gradient field "
                 "is orthographic (--K and --fov do not apply)."),
    click.option("--mat-keys", metavar="P,Q[,MASK] | N[,MASK]",
                 help="Variable names in a .mat input: a gradient field p,q[,mask] or a "
                 "normal map N[,mask]. Default: p,q[,mask], else the only HxWx3 variable."),
    click.option("--method", default="dgp", show_default=True,
                 help="Integration method; 'facetlift methods' lists them."),
    click.option("--pixel-size", type=float, default=1.0, show_default=True,
                 help="Pixel width in world units (orthographic): scales depth with x and y."),
    click.option("--K", "K", type=CAMERA_FILE, metavar="FILE | \"FX FY CX CY\"",
                 help="Perspective intrinsics: a text file of the 3x3 matrix (OpenCV layout) "
                 "or of fx fy cx cy (also under a header naming them), JSON, a (3, 3) "
                 ".npy, or a .mat file's KK (a calibration's Calib_Results.mat) or K; or a "
                 "calibration tool's file: OpenCV FileStorage .yml/.xml (camera_matrix), ROS "
                 "camera_info YAML or a CameraInfo dump (k), COLMAP's cameras.txt or .bin, a "
                 "nerfstudio transforms.json (fl_x; COLMAP's and nerfstudio's cx, cy are "
                 "shifted by -0.5 px); one stating another image size than the map's is "
                 "refused. Or typed inline: four numbers fx fy cx cy, or the matrix's nine "
                 "row by row, separated by spaces or commas (--K \"3772 3759 305.9 255.1\"). "
                 "A dataset folder's K.txt is used automatically."),
    click.option("--fov", type=float, default=None, metavar="DEG",
                 help="Horizontal field of view in degrees (across the width, also for a "
                 "portrait photo), for a camera without a K: fx = fy = (W/2)/tan(fov/2), the "
                 "principal point at the centre. Instead of --K (a dataset's K.txt is then "
                 "not used)."),
    click.option("--orthographic", is_flag=True,
                 help="Ignore K (e.g. a dataset's K.txt) and integrate orthographically."),
    click.option("--backfacing", type=click.Choice(["missing", "error", "outlier"]),
                 default="missing", show_default=True,
                 help="Normals facing away from the camera inside the mask: treat them as "
                 "missing samples (counted and reported; 'outlier' is an alias), or stop with "
                 "an error."),
    click.option("--outlier-eps", type=float, default=None,
                 help="Grazing threshold on the view cosine below which a normal is a missing "
                 "sample (default: cos 85 deg orthographic, 1/255 perspective; cos 87.5 deg for "
                 "both with dgp --discontinuities)."),
    click.option("--solver", help="The method's solver, where it has one (dgp: 'direct' "
                 "solves the fixed point at once, the default; 'iterative' runs the paper's "
                 "loop)."),
    click.option("--max-iter", type=int, help="Iteration limit (methods with `max_iter`)."),
    click.option("--tol", type=float, help="Convergence tolerance (methods with `tol`)."),
    click.option("--backend", help="Sparse linear solver backend (methods with `backend`): "
                 "auto, pcg, pardiso, superlu, amg."),
    click.option("--discontinuities", is_flag=True,
                 help="Allow depth jumps (methods that handle discontinuities: 'facetlift "
                 "methods'). About 30 reweighted solves: up to 10-20x the time of the smooth "
                 "integration (the DiLiGenT bear's solve about 10x, 0.12 -> 1.2-1.4 s; 0.37 -> "
                 "1.6 s as the summary line counts it, with its checks; 'facetlift info' "
                 "estimates it); the "
                 "cut's sharpness is --option discontinuity_k=K (default 4; --method bini: "
                 "--option k=K, default 2), the jumps' map --save discontinuities."),
    click.option("--prior", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                 help="Depth prior (npy, EXR, TIFF, PFM, MATLAB .mat, an earlier result's npz, or "
                 "16-bit PNG with --prior-scale), NaN where unknown (0 too in integer "
                 "files, but for --prior-fit), or a points file (.csv/.txt: one sample per "
                 "line under a header naming the columns, e.g. u,v,depth: pixels, not a "
                 "cloud's metres), in the output's depth convention "
                 "(metric z-depth with K). "
                 "A dataset folder's prior_depth.* is used automatically. docs/fusion.md."),
    click.option("--prior-scale", type=float, default=None, metavar="S",
                 help="Depth units per count of a 16-bit PNG prior (e.g. 0.001)."),
    click.option("--prior-weight", type=float, default=None, metavar="W",
                 help="Weight of each prior sample relative to one pixel's normal "
                 "[default: 1, or 0.003 with --prior-blur]."),
    click.option("--prior-weight-map", type=click.Path(exists=True, dir_okay=False,
                 path_type=Path), help="Per-pixel prior weights, times --prior-weight (npy, "
                 "EXR, float TIFF, PFM as stored; 8/16-bit PNG or TIFF = v/max)."),
    click.option("--prior-blur", type=float, default=None, metavar="SIGMA",
                 help="The prior is coarse or blurred (a monocular network, a low-resolution "
                 "sensor, a map upsampled from a coarse grid): the standard deviation in "
                 "pixels of its blur, so that only its coarse shape counts (for a map "
                 "upsampled by a factor f from block means or a blurred coarse map, about "
                 "1.1 f); --prior-weight then defaults to 0.003. A map interpolated from "
                 "point samples of a coarse grid is no blurred map: give those samples "
                 "instead (NaN between them, or a points file). docs/fusion.md, 'Blurred "
                 "priors'."),
    click.option("--prior-outliers", type=click.Choice(["remove", "keep"]), default=None,
                 help="remove (the default): samples of a sparse prior that disagree with "
                 "every neighbouring sample along the normals are left out, counted and "
                 "named in a warning (mismatched SfM points, stray sensor returns); keep: "
                 "use every sample. docs/fusion.md, 'Outlier samples'."),
    click.option("--prior-fit", type=click.Choice(["none", "affine", "scale", "disparity"]),
                 default=None,
                 help="What the prior is known up to: none (the default: depth in the "
                 "output's units); affine: depth up to scale and shift (a monocular network's "
                 "affine-invariant depth); scale: up to a scale; disparity (with K): an "
                 "affine-invariant inverse depth (MiDaS, Depth Anything). It is aligned to the "
                 "normals-only surface, piece by piece, then fused; the result keeps the "
                 "normals' units. docs/fusion.md, 'A monocular depth map'."),
    click.option("--confidence", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                 help="Per-pixel weights >= 0 of the normals (npy, EXR, float TIFF, PFM as stored; "
                 "8/16-bit PNG or TIFF = v/max); "
                 "0 = missing normal. A dataset folder's confidence.* is used automatically."),
    click.option("--no-prior", "no_prior", is_flag=True,
                 help="Leave a dataset folder's prior_depth.* file unused (normals only)."),
    click.option("--no-confidence", "no_confidence", is_flag=True,
                 help="Leave a dataset folder's confidence.* file unused."),
    click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
                 help="Any other method option, repeatable; VALUE is read as JSON when it "
                 "parses (1e-4, true, [1,2]) and as a string otherwise."),
    click.option("-s", "--save", "--format", "save", multiple=True,
                 type=click.Choice(list(OUTPUTS)),
                 help="What to write, repeatable: npy/exr/tif = depth map, npz = depth + "
                 "vertex depth + mask, ply/obj/stl = mesh (stl: binary, triangles, for "
                 "slicers and CAD), png = shaded preview, report = one PNG with shading, "
                 "depth, deviation and discontinuity panels (needs "
                 "facetlift[plot]), discontinuities = where the surface is cut by depth jumps "
                 "and the pieces it falls into (with --discontinuities), height = a 16-bit "
                 "grey height map PNG scaled to "
                 "0..1 (alpha only where pixels are outside the mask; its range in the "
                 "summary and --json's depth_range; see --height-range), height-exr = the "
                 "heights themselves as float32 EXR (channel Y), points = a PLY point cloud "
                 "(a point per pixel with the input's normal), normals = the result's own "
                 "normals as a 16-bit PNG normal map in the input's frame. Default: npy, ply, "
                 "png."),
    click.option("--height-range", "height_range", nargs=2, type=float, default=None,
                 metavar="LOW HIGH",
                 help="The heights (in the depth's units: texels with --pixel-size 1) that "
                 "height.png writes as 0 and 65535, the same for every map of a texture set; "
                 "heights outside are clipped, with a warning counting them. Default: each "
                 "map's own lowest and highest."),
    click.option("--quads", is_flag=True,
                 help="Write quad meshes (the PLY default; OBJ defaults to triangles; STL "
                 "holds triangles only)."),
    click.option("--triangles", is_flag=True,
                 help="Write triangle meshes (the OBJ default)."),
    click.option("--output-frame", "output_frame", metavar="FRAME",
                 help="Frame of the mesh's and the point cloud's coordinates (and the points' "
                 "normals): opengl (default: x right, y up, z toward the viewer), opencv (the "
                 "camera frame of OpenCV and COLMAP: y down, z away), directx, or an axis "
                 "string such as 'x,-y,-z', as for --normal-frame. For the ply, obj, stl and "
                 "points outputs; depth maps are unchanged."),
    click.option("--max-memory", default=None, metavar="SIZE",
                 help="Refuse the job if its estimated peak memory, above the prepared "
                 "input (the map as read and checked), exceeds SIZE (bytes, or 8G, 512M); "
                 "optional factorizations then stay within it too; the preparation itself and "
                 "the outputs' writing are not counted. Default: the available memory minus a "
                 "margin, ulimit -v honoured."),
    click.option("--progress/--no-progress", default=None,
                 help="Progress bar on stderr: the iterations of routes that iterate and the "
                 "steps of the job (reading, integrating, writing; for batches, the items). "
                 "Default: when stderr is a terminal."),
    click.option("--strict", is_flag=True,
                 help="Fail (exit 1, nothing written; in a batch, the item) where the input's "
                 "frame looks wrong instead of warning: far more integrable flipped, a "
                 "gradient field in the other layout, many normals facing away (another frame "
                 "or BGR order). Not on the weaker hints that right inputs give too."),
]


def _job_options(f):
    for option in reversed(_JOB_OPTIONS):
        f = option(f)
    return f


def _refuse_contradictions(prior, no_prior, confidence, no_confidence, K, orthographic):
    """The flags of `integrate`, `batch` and `info` that contradict each other, refused."""
    if no_prior and prior is not None:
        raise ValueError(f"--no-prior and --prior {prior} contradict each other; give one")
    if no_confidence and confidence is not None:
        raise ValueError(f"--no-confidence and --confidence {confidence} contradict each "
                         "other; give one")
    if K is not None and orthographic:
        raise ValueError(f"--K {K} and --orthographic contradict each other: --orthographic "
                         "ignores a camera (e.g. a dataset folder's K.txt); give one of them")


def _make_job(*, normals=None, gradients=None, mask=None, normal_frame=None, y_down=False,
              world_to_camera=None, camera_to_world=None, normal_encoding="xyz",
              normal_range="signed", gradient_frame="xy", mat_keys=None, method="dgp",
              pixel_size=1.0, K=None,
              fov=None, orthographic=False, backfacing="missing", outlier_eps=None,
              solver=None,
              max_iter=None, tol=None, backend=None, discontinuities=False, options=(),
              save=(), height_range=None, quads=False, triangles=False, output_frame=None,
              colors=None, outdir=None,
              max_memory=None, prior=None,
              prior_scale=None, prior_weight=None, prior_weight_map=None, confidence=None,
              prior_blur=None, prior_outliers=None, prior_fit=None, no_prior=False,
              no_confidence=False, strict=False):
    """A :class:`facetlift.jobs.Job` from the parsed flags (ValueError on bad values)."""
    from . import frames
    from .io.dataset import K_value
    from .jobs import Job

    _methods.get(method)
    if quads and triangles:
        raise ValueError("give --quads or --triangles, not both")
    _refuse_contradictions(prior, no_prior, confidence, no_confidence, K, orthographic)
    if K is not None and not orthographic and pixel_size != 1.0:  # (also for a batch)
        raise ValueError(f"`pixel_size` {pixel_size!r} applies to orthographic input; --K "
                         f"{K} gives a camera (its scale comes from K): drop --pixel-size, or "
                         "give --orthographic without --K")
    if fov is not None and pixel_size != 1.0:
        raise ValueError(f"`pixel_size` {pixel_size!r} applies to orthographic input; "
                         f"--fov gives a camera: drop --pixel-size")
    opts = dict(_parse_option(o) for o in options)
    for key, value in (("solver", solver), ("max_iter", max_iter), ("tol", tol),
                       ("backend", backend), ("max_memory", max_memory),
                       ("discontinuities", True if discontinuities else None)):
        if value is None:
            continue
        if key in opts and not _same_option(key, opts[key], value):  # (the flag won silently)
            raise ValueError(f"--option {key}={json.dumps(opts[key])} and "
                             f"--{key.replace('_', '-')} contradict each other; give one")
        opts[key] = value
    if opts.get("max_memory") is not None:  # (before the input is read: its warnings came
        from .memory import parse_size  # first; --option max_memory=... as well)

        parse_size(opts["max_memory"])
    # (the prior's numbers by their values alone, before the input is read: --prior-weight -1
    # was refused after the map's warnings, a review; whether a prior is there is the
    # reading's to say, a dataset folder may hold one)
    from .problem import check_prior_blur, prior_weight_value

    if prior_weight is not None:
        prior_weight_value(prior_weight)
    if prior_blur is not None:
        check_prior_blur(prior_blur, has_prior=True)
    frame = frames.resolve(normal_frame, y_down, "normal_frame")
    if frame is not None:
        frames.parse(frame)
    if output_frame is not None:
        frames.parse(output_frame, "output_frame")
    frames.gradient_frame(gradient_frame)
    job = Job(
        normals=None if normals is None else str(normals),
        gradients=tuple(str(g) for g in gradients) if gradients else None,
        mask=None if mask is None else str(mask), K=K_value(K), fov=fov,
        orthographic=orthographic, normal_frame=frame,
        world_to_camera=None if world_to_camera is None else str(world_to_camera),
        camera_to_world=None if camera_to_world is None else str(camera_to_world),
        normal_encoding=normal_encoding, normal_range=normal_range,
        gradient_frame=gradient_frame,
        mat_keys=_split(mat_keys), method=method, pixel_size=pixel_size,
        backfacing=backfacing, outlier_eps=outlier_eps, options=opts,
        save=tuple(save) or DEFAULT_SAVE,
        height_range=None if height_range is None else tuple(height_range),
        triangles=True if triangles else (False if quads else None),
        output_frame=None if output_frame is None or frames.is_identity(output_frame)
        else output_frame,
        colors=None if colors is None else str(colors),
        outdir=None if outdir is None else str(outdir),
        prior=None if prior is None else str(prior), prior_scale=prior_scale,
        prior_weight=prior_weight,
        prior_weight_map=None if prior_weight_map is None else str(prior_weight_map),
        confidence=None if confidence is None else str(confidence), prior_blur=prior_blur,
        prior_outliers=prior_outliers, prior_fit=prior_fit, dataset_prior=not no_prior,
        dataset_confidence=not no_confidence, strict=strict,
    )
    from .jobs import check_fov, read_rotation

    check_fov(job)  # (before the input is read)
    read_rotation(job)  # (its file and the two flags together refused before, too)
    return job


def _show_progress(flag) -> bool:
    return sys.stderr.isatty() if flag is None else bool(flag)


def _progress_total(job) -> int | None:
    """The iteration count a progress bar can expect, where the route has one: the iterative
    loop's ``max_iter`` where given. None for the reweightings of ``discontinuities``, whose
    cap (200) is a safety net they stop far short of (20-40 on the benchmark): the bar then
    counts them, and shows the largest weight change falling toward the tolerance."""
    if job.options.get("discontinuities"):
        return None
    return job.options.get("max_iter")


def _samples(field: bool, count: int = 2) -> str:
    """What a pixel's input value is called in the summary and ``info`` lines: a normal, or
    for a gradient field (`field`) a gradient sample (as :mod:`facetlift.problem`'s warnings
    name them); plural unless `count` is 1."""
    word = "gradient sample" if field else "normal"
    return word if count == 1 else f"{word}s"


def _camera_given(camera: str) -> str:
    """A record's camera as the summary names it: "K", the camera given, as the --K typed
    (its file: a user's check read "perspective (K)" for a DiLiGenT Calib_Results.mat)."""
    if camera != "K":
        return camera
    args = list(_STATE.get("args") or ())
    typed = camera
    for i, a in enumerate(args):  # (the last given: click takes the last, a review)
        if a == "--K" and i + 1 < len(args):
            typed = f"--K {args[i + 1]}"
        elif a.startswith("--K="):
            typed = f"--K {a[len('--K='):]}"
    return typed


def summary(record: dict) -> str:
    """The one-line text summary of a job's record."""
    info = record["info"]
    H, W = record["shape"]
    source = record["mask_source"]
    many = record.get("components") or 1
    if source == "alpha channel" and many > 1:  # (a height in the alpha splits the mask in
        # one piece per brick, each at mean depth 0; the warning may not fire, a second audit)
        source = f"alpha channel, {many} components integrated apart, their depths unrelated"
        if any("its alpha channel holds" in w for w in record.get("warnings", ())):
            # (asked only where the alpha looked like data: a 0/255 alpha of separate pieces,
            # an atlas's or leaf cards', is a mask, a review)
            source += ": a height packed in the alpha? --mask replaces it"
    rotation = record.get("normal_rotation")
    parts = [
        f"{H}x{W} pixels, {record['facets']} facets (mask: {source})",
        (f"perspective ({_camera_given(record.get('camera', 'K'))})"
         if record.get("perspective") else "orthographic"),
        *([f"normals turned from world space ({rotation['file']})"] if rotation else []),
        f"method {info.get('method')}" + (f" ({info['solver']})" if "solver" in info else ""),
    ]
    it = info.get("iterations")
    if it is not None:
        parts.append(f"{it} iteration{'s' if it != 1 else ''}"
                     + ("" if record["converged"] else " (not converged)"))
    prior = info.get("prior")
    fit = prior.get("fit") if isinstance(prior, dict) else None
    if isinstance(prior, dict) and prior.get("left_out"):  # (--prior-fit could not align it)
        parts.append(f"depth prior left out (--prior-fit {fit.get('kind')}: not aligned, "
                     "see the warning)")
    elif isinstance(prior, dict):  # (also a dataset folder's prior_depth file, read silently)
        outside = prior.get("outside_mask") or 0
        named = f" ({record['prior_file']})" if record.get("prior_file") else ""
        count = prior.get("samples")
        parts.append(f"depth prior{named}: {count} sample{'' if count == 1 else 's'} fixing "
                     f"{len(prior.get('prior_components', []))} of "
                     f"{prior.get('components')} components"
                     + (f" ({outside} outside the mask, unused)" if outside else "")
                     # (dgp.lone_samples: the normals' surface moved, not reshaped)
                     + ((", alone in its component: the surface moved to it whole"
                         if count == 1 else
                         ", each alone in its component: the surface moved to them whole")
                        if info.get("prior_one_per_component") else ""))
        removed = (prior.get("outliers") or {}).get("removed") or 0
        if removed:
            parts.append(f"{removed} prior outlier{'s' if removed != 1 else ''} left out")
        if fit:  # (its depth keeps the normals' units: not metric, a user's check)
            units = "gradient field's" if record.get("gradient_field") else "normals'"
            parts.append(f"prior aligned by --prior-fit {fit.get('kind')} ({fit.get('method')}: "
                         f"scale {fit.get('scale'):.4g}, shift {fit.get('shift'):.4g}; the depth "
                         f"keeps the {units} units, not the prior's)")
    cut = info.get("cut_pieces") or 0
    if cut > 0:  # (docs/results.md, "What the remaining error is")
        held = (isinstance(prior, dict) and not prior.get("left_out")
                and (prior.get("samples") or 0) > 0
                and not info.get("prior_one_per_component"))  # (placed as without one)
        # (without a prior the pieces the rule closes come out joined: those counted are
        # mostly ones too far apart to close, methods.dgp.split.TOUCH)
        # (where they are: the jump map tints them, Surface.pieces)
        shown = "discontinuities" in (record.get("outputs") or {})
        parts.append(f"cuts split the mesh into {cut} more piece{'s' if cut != 1 else ''} "
                     + ("(placed by the prior where they hold samples, else the occlusion "
                        "rule)" if held else "(closed by the occlusion rule where they nearly "
                        "touch, else left where the solve put them)")
                     + ("" if shown else "; --save discontinuities tints them"))
    counts = info.get("input") or {}
    missing = counts.get("missing") or 0
    if missing:  # (NaN inside the mask: no warning, being the documented way to say it)
        parts.append(f"{missing} missing {_samples(record.get('gradient_field'), missing)}")
    unusable = sum(counts.get(k) or 0 for k in ("non-finite", "zero-length", "back-facing",
                                                 "grazing", "isolated"))
    if unusable:
        parts.append(f"{unusable} unusable")
    if "zero_confidence" in counts:
        zero = counts.get("zero_confidence") or 0
        named = [record["confidence_file"]] if record.get("confidence_file") else []
        named += [f"{zero} at 0"] if zero else []
        parts.append("confidence map" + (f" ({', '.join(named)})" if named else ""))
    dev = record.get("mean_deviation")
    if dev is not None:
        parts.append(f"mean deviation {dev:.2f} deg")
    span = record.get("depth_range")
    if "height" in record.get("outputs", {}) and span:  # (the displacement scale, without
        # --json: a texture artist's check)
        parts.append(f"height.png 0..65535 = height {0.0 - span[0]:.6g} to {0.0 - span[1]:.6g}")
    ev = record.get("evaluation")
    if ev:  # (a dataset folder's depth_gt.*, scored as facetlift evaluate scores it)
        if ev.get("made") is not None:
            parts.append(f"MADE {ev['made']:.4g} against {ev['gt']} (BiNI's: after the median "
                         f"scale {ev['scale']:.4g})")
        elif ev.get("normalized_error") is not None:
            parts.append(f"normalised error {100 * ev['normalized_error']:.3g} % against "
                         f"{ev['gt']}")
    t = record["timings"]
    # (the integration's time alone read as the run's: a 2048^2 run said 6.34 s where it
    # took 18.7 s with its reading and five outputs' writing, a review)
    parts.append(f"{t['integrate']:.2f} s" + (
        f" ({t['total']:.2f} s with reading and writing)"
        if t.get("total", 0.0) > 1.2 * t["integrate"] + 0.05 else ""))
    return ", ".join(parts)


# (the hints' words and rules are facetlift.hints', shared with a batch's records)
def _jump_hint(job, info: dict, camera_warned: bool = False, field: bool = False) -> str | None:
    """:func:`facetlift.hints.jump_hint`, printed as a ``hint:`` line on stderr."""
    return _echo_hint(jump_hint(job, info, camera_warned, field))


def _torn_hint(job, info: dict) -> str | None:
    """:func:`facetlift.hints.torn_hint`, printed as a ``hint:`` line on stderr."""
    return _echo_hint(torn_hint(job, info))


def _echo_hint(hint: str | None) -> str | None:
    if hint is not None:
        click.echo(f"hint: {hint}", err=True)
    return hint


class _FieldFile(click.Path):
    """A file of --gradients P Q: a value that looks like an option is no file (``--gradients
    p.npy -o out`` said "File '-o' does not exist", a user's check)."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and value.startswith("-") and not os.path.exists(value):
            self.fail(f"takes two files, P and Q; got {value!r} where a file was expected "
                      "(an option? give both files first)", param, ctx)
        return super().convert(value, param, ctx)


@cli.command(context_settings=CONTEXT)
@click.argument("normals", required=False, type=click.Path(exists=True, path_type=Path))
@click.option("--gradients", nargs=2, type=_FieldFile(exists=True, dir_okay=False,
                                                       path_type=Path),
              metavar="P Q", help="Integrate a gradient field instead: two files (npy, EXR, "
              "TIFF, PFM) holding p and q; see --gradient-frame.")
@_job_options
@click.option("-o", "--out", "outdir", type=click.Path(file_okay=False), callback=_out_dir,
              help="Output folder, its files named by -s (depth.npy, ...); a name ending "
              "like a file (.npy, .png, .exr, .tif, .ply, .obj, .stl, .npz) is refused unless "
              "that folder exists. Default: <input>_facetlift/ next to the input.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object (outputs, diagnostics, timings) instead of text.")
@click.option("--colors", "--colours", "colors",
              type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="An image of the object (the photo the normals were estimated from, an "
              "albedo; PNG, JPEG, TIFF, EXR or .npy) whose colours paint the ply, obj and "
              "points outputs: each point its pixel's colour, each mesh vertex the mean of "
              "its facets' (one side's at a jump). The same picture at another size is "
              "resampled.")
def integrate(normals, gradients, progress, as_json, **flags):
    """Integrate a normal map NORMALS into a depth map, a mesh and a preview.

    NORMALS is a normal-map file (PNG 8/16 bit, TIFF, EXR, .npy or .pfm; by default x right,
    y up, z toward the viewer, 8/16-bit values v decoded as v/max*2-1), a dataset folder holding
    normal_map.png, mask.png and, for a perspective camera, K.txt, or a .mat file holding
    gradients p, q or a normal map (--mat-keys). A gradient field in two files is given
    with --gradients P Q instead.

    \b
    Examples:
      facetlift integrate normal_map.png --mask mask.png
      facetlift integrate estimate.png --normal-frame opencv -s report
      facetlift integrate --gradients p.npy q.npy --gradient-frame rowcol
      facetlift integrate vase.mat --mat-keys p,q,mask --gradient-frame queau
      facetlift integrate data/tent/ --solver iterative --tol 1e-4 --progress
    """
    from . import jobs

    job = _make_job(normals=normals, gradients=gradients, **flags)
    bar, update = (None, None)
    if _show_progress(progress) and "progress" in _methods.get(job.method).options():
        bar, update = _progress_bar(_progress_total(job))
    shown = []  # (the warnings printed as they came, above the bar: not again at the end)

    def live(message):
        from tqdm import tqdm

        shown.append(str(message))
        tqdm.write(f"facetlift: warning: {_as_flags(str(message))}", file=sys.stderr)

    try:
        record = jobs.run(job, progress=update, on_warning=None if bar is None else live)
    except ValueError as e:  # name the command-line flag where the library names a keyword
        raise ValueError(
            str(e).replace("pass backfacing='missing'", "pass --backfacing missing")
        ) from None
    finally:
        if bar is not None:
            bar.close()
    for w in record["warnings"]:
        if str(w) in shown:
            shown.remove(str(w))
            continue
        click.echo(f"facetlift: warning: {_as_flags(str(w))}", err=True)
    info = record["info"]
    if not as_json:
        for path in record["outputs"].values():
            click.echo(f"wrote {path}")
        click.echo(summary(record))
    hint = _jump_hint(job, info, record.get("camera_warned", False),
                      bool(record.get("gradient_field")))
    torn = _torn_hint(job, info)
    unconverged = (not record["converged"] and info.get("solver") != "discontinuous"
                   and not jobs.finished_unconverged(info))  # (exit 2, outputs written)
    if as_json:  # (the warnings and hints as printed: a script can act on a wrong frame)
        out = {k: v for k, v in record.items() if k != "warnings"}
        out["warnings"] = [_as_flags(str(w)) for w in record["warnings"]]
        out["hints"] = [h for h in (hint, torn) if h is not None]
        # (as a failed command's object has them: an exit code 2 left only converged false
        # to tell, a user's check)
        out["status"] = "solver_error" if unconverged else "ok"
        out["exit_code"] = EXIT_SOLVER if unconverged else EXIT_OK
        click.echo(json.dumps(out))
        _STATE["printed_json"] = True
    blur = info.get("prior_blur") or {}
    if blur.get("capped"):
        # a safety net, not a setting: the surface is usable (its mismatch is in the info)
        click.echo(
            f"note: the blurred prior's target corrections stopped at their cap of "
            f"{blur.get('cap')} updates before the mismatch levelled off (a safety net; "
            f"mismatch {blur.get('mismatch') or float('nan'):.3g}, first solve's "
            f"{blur.get('mismatch_first') or float('nan'):.3g})",
            err=True,
        )
    if not record["converged"] and info.get("solver") == "discontinuous":
        # a fixed budget of reweightings by design: the surface is usable, say so and go on
        click.echo(
            f"note: the discontinuity reweighting used all {info.get('iterations')} "
            "iterations before its weights settled or its cuts stopped growing; more may "
            "sharpen long jumps "
            "(--option discontinuity_iter=N)",
            err=True,
        )
    elif not record["converged"] and info.get("method") == "bini":
        click.echo(
            f"note: BiNI's reweighting used all {info.get('iterations')} iterations before "
            "its energy settled (as BiNI's own code, the surface is returned); more: "
            "--max-iter N",
            err=True,
        )
    elif unconverged:
        raise SolverFailure(
            f"method {info.get('method')!r} did not converge in {info.get('iterations')} "
            "iterations (outputs were written); raise --max-iter or --tol"
        )
    return EXIT_OK


@cli.command(context_settings=CONTEXT)
@click.argument("normals", required=False, type=click.Path(exists=True, path_type=Path))
@click.option("--gradients", nargs=2, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              metavar="P Q", help="Describe a gradient field instead: two files holding p and "
              "q, as for 'integrate'; see --gradient-frame.")
@click.option("-m", "--mask", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Mask image, as for 'integrate'.")
@click.option("--K", "K", type=CAMERA_FILE, metavar="FILE | \"FX FY CX CY\"",
              help="Perspective intrinsics, a file or typed inline, as for 'integrate'.")
@click.option("--fov", type=float, default=None, metavar="DEG",
              help="Horizontal field of view in degrees instead of --K, as for 'integrate'.")
@click.option("--normal-frame", "normal_frame", metavar="FRAME",
              help="Read the map in this frame (as for 'integrate').")
@click.option("--y-down", is_flag=True, help="Alias of --normal-frame directx.")
@click.option("--world-to-camera", "world_to_camera", metavar="FILE",
              type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Normals in world space: the rotation from world to the camera frame, as "
              "for 'integrate'.")
@click.option("--camera-to-world", "camera_to_world", metavar="FILE",
              type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Instead of --world-to-camera: the camera's pose (Blender's matrix_world), "
              "as for 'integrate'.")
@click.option("--normal-encoding", "normal_encoding", type=click.Choice(["xyz", "xy"]),
              default="xyz", show_default=True,
              help="xy: a two-channel map (BC5, RG), z rebuilt; as for 'integrate'.")
@click.option("--normal-range", "normal_range", type=click.Choice(["signed", "unsigned"]),
              default="signed", show_default=True,
              help="unsigned: a float map stored in [0, 1], decoded as 2 v - 1; as for "
              "'integrate'.")
@click.option("--gradient-frame", "gradient_frame", default="xy", show_default=True,
              help="Layout of a gradient field (--gradients or a .mat input), as for "
              "'integrate'.")
@click.option("--mat-keys", metavar="KEYS", help="Variable names in a .mat input.")
@click.option("--prior", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="A depth prior (map or points file) to check against the map, as for "
              "'integrate'.")
@click.option("--prior-scale", type=float, default=None, metavar="S",
              help="Depth units per count of a 16-bit PNG prior, --prior's or a dataset "
              "folder's prior_depth (as for 'integrate').")
@click.option("--prior-fit", type=click.Choice(["none", "affine", "scale", "disparity"]),
              default=None, help="What the prior is known up to, as for 'integrate': its "
              "values are not checked as depths, and the time estimate allows for two runs.")
@click.option("--prior-blur", "prior_blur", type=float, default=None, metavar="SIGMA",
              help="The prior's blur in pixels, as for 'integrate': its relief is then "
              "checked as a blurred map's (a review: integrate's flag was refused here).")
@click.option("--confidence", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="A confidence map to check against the map, as for 'integrate'.")
@click.option("--no-prior", "no_prior", is_flag=True,
              help="Leave a dataset folder's prior_depth.* file unread, as for 'integrate'.")
@click.option("--no-confidence", "no_confidence", is_flag=True,
              help="Leave a dataset folder's confidence.* file unread, as for 'integrate'.")
@click.option("--orthographic", is_flag=True,
              help="Ignore K (e.g. a dataset's K.txt), as for 'integrate'.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def info(normals, gradients, mask, K, fov, normal_frame, y_down, world_to_camera,
         camera_to_world, normal_encoding, normal_range, gradient_frame, mat_keys, prior,
         prior_scale,
         prior_fit, prior_blur, confidence, no_prior, no_confidence, orthographic, as_json):
    """Describe an input without integrating it: size, pixel type, detected frame and
    encoding, mask and components, unusable normals, K, and the memory planner's estimate of
    the peak memory the default integration would need (the figure --max-memory is checked
    against), with a time range from the benchmarks. Exit status 1 where the input cannot
    be integrated as read (the report says why), 0 otherwise.

    \b
    Examples:
      facetlift info normal_map.png --mask mask.png
      facetlift info data/bear/ --json
      facetlift info --gradients p.npy q.npy --gradient-frame rowcol
    """
    from . import frames
    from .describe import describe

    frames.gradient_frame(gradient_frame)  # (refused as integrate refuses it, on any input)
    # (integrate's flags that info named in its advice and did not take: an audit)
    _refuse_contradictions(prior, no_prior, confidence, no_confidence, K, orthographic)
    if fov is not None:  # (as integrate refuses them)
        from .jobs import Job, check_fov

        check_fov(Job(K=None if K is None else str(K), fov=fov, orthographic=orthographic))
    rec = describe(normals, gradients=gradients, mask=mask, K=K, fov=fov,
                   normal_frame=frames.resolve(normal_frame, y_down, "normal_frame"),
                   normal_encoding=normal_encoding, normal_range=normal_range,
                   mat_keys=_split(mat_keys),
                   gradient_frame=gradient_frame,
                   prior_scale=prior_scale, prior=prior, confidence=confidence,
                   prior_fit=prior_fit, prior_blur=prior_blur,
                   world_to_camera=world_to_camera,
                   camera_to_world=camera_to_world, dataset_prior=not no_prior,
                   dataset_confidence=not no_confidence, orthographic=orthographic)
    # (for preflight scripts: as integrate would fail, on the map or on a folder's files)
    status = EXIT_INPUT if rec.get("problem") or rec.get("refused") else EXIT_OK
    reason = rec.get("problem") or rec.get("refused")
    if status != EXIT_OK and isinstance(reason, str):
        # (exit 1 with nothing on stderr, the reason in the report alone: an audit)
        _error(_as_flags(reason))
    if as_json:
        # (its warnings and problem in the command line's words, as integrate --json's: they
        # named `K` where integrate's name --K, an audit); status and exit_code as every
        # other command's object has them
        rec = dict(rec, warnings=[_as_flags(str(w)) for w in rec.get("warnings", [])],
                   status="ok" if status == EXIT_OK else "error", exit_code=status)
        for key in ("problem", "refused"):
            if isinstance(rec.get(key), str):
                rec[key] = _as_flags(rec[key])
        click.echo(json.dumps(jsonable(rec)))
        _STATE["printed_json"] = True  # (the report is the one object, failed or not)
        return status
    for line in _info_lines(rec):
        click.echo(line)
    return status


def _info_lines(rec: dict) -> list[str]:
    from .problem import HOLE_PIXELS

    H, W = rec["shape"]
    kind = ", ".join(f"{k} {rec[k]}" for k in ("format", "bit_depth", "channels", "dtype")
                     if rec.get(k) is not None)
    lines = [f"{rec['input']}: {H}x{W} pixels ({kind})"]
    if rec.get("encoding"):
        lines.append(f"  encoding: {rec['encoding']}")
    frame = rec.get("frame", {})
    lines.append(f"  frame: read as {frame.get('as_read')}; likely {frame.get('likely', '?')}")
    rotation = rec.get("normal_rotation")
    if rotation:  # (the frame above is that of the normals as turned)
        lines.append(f"  world space: the normals turned into the camera frame by "
                     f"{rotation['file']} ({rotation['given_as'].replace('_', '-')})")
    source = rec.get("camera")
    lines.append(f"  camera: {rec['projection']}"
                 + (f" ({_camera_given(source)})" if rec["K"]
                    and source not in (None, "orthographic") else "")
                 + (f", K = {rec['K']}" if rec["K"] else "")
                 + (f" ({', '.join(Path(f).name for f in unread)} beside it not read: --K "
                    f"{unread[0]} to use it)" if (unread := rec.get("camera_files_unread"))
                    else ""))
    for name, what in (("prior", "depth prior"), ("confidence", "normal confidence")):
        if rec.get(name):  # (--prior / --confidence, or a dataset folder's own files)
            got = rec[name]
            span = (f", {got['range'][0]:.6g} to {got['range'][1]:.6g}" if got["range"]
                    else "")
            inside = got.get("known_in_mask")
            lines.append(f"  {what} ({got.get('source', 'dataset file')}): "
                         f"{got['known_pixels']} known pixels"
                         + (f", {inside} in the mask" if inside is not None else "")
                         + (f"{span} there" if span and inside is not None else span)
                         + (f"; aligned by --prior-fit {got['fit']} (the route runs twice)"
                            if got.get("fit") else ""))
    lines += [f"  warning: {_as_flags(w)}" for w in rec.get("warnings", [])]
    if not rec["usable"]:
        # (named by the flags, as its warnings and integrate's error are: an audit)
        lines.append(f"  cannot be integrated as read: {_as_flags(rec['problem'])}")
        return lines
    c = rec["counts"]
    field = rec.get("gradient_field")
    lines.append(f"  mask: {rec['mask_pixels']} pixels ({rec['mask_source']}), "
                 f"{rec['components']} component(s)")
    # (both as integrate counts them, problem.enclosed_gaps: the small ones are what its
    # warning names, the larger ones taken for real holes; a gradient field's in its words)
    valid = "gradient sample (p or q not finite)" if field else "valid normal"
    if rec.get("holes"):
        lines.append(f"  holes: {rec['holes']} pixels enclosed by the object, in holes of at "
                     f"most {HOLE_PIXELS} pixels, have no {valid} and are left out (NaN / "
                     "background fill inside, or a small real hole: a mask, --mask, integrates "
                     "across those as missing samples)")
    if rec.get("larger_holes"):
        lines.append(f"  larger holes: {rec['larger_holes']} pixels in enclosed regions of more "
                     f"than {HOLE_PIXELS} pixels without a {valid}, left out as real holes "
                     "(a ring's; if they are NaN / background fill inside the object, a mask, "
                     "--mask, integrates across them as missing samples)")
    # (zero confidence too, as the JSON and integrate count it: an audit; isolated: the smooth
    # DGP's lone steep normals, problem.STEEP_ISOLATED)
    bad = ", ".join(f"{c[k]} {k.replace('_', ' ')}" for k in (
        "missing", "non-finite", "zero-length", "back-facing", "grazing", "isolated",
        "zero_confidence") if c.get(k))
    first = rec.get("first_unusable")
    lines.append(f"  unusable {_samples(field)}: {bad or 'none'}"
                 + (f"; first at (row {first[0]}, col {first[1]})" if first else ""))
    if rec.get("noise") is not None:
        lines.append(f"  noise: about {rec['noise']:.1f} deg, read from the {_samples(field)}' "
                     "curl (a surface's own are curl-free: 0 up to detail below the pixel)")
    if rec.get("camera_hint"):
        lines.append(f"  without a camera: {rec['camera_hint']}")
    jg = rec.get("discontinuity_grazing") or {}
    if jg.get("more_grazing"):
        lines.append(f"  with --discontinuities (dgp): {jg['more_grazing']} more grazing (view "
                     f"cosine < {jg['outlier_eps']:.4g}), treated as missing unless "
                     "integrate --outlier-eps says otherwise")
    if jg.get("fewer_grazing"):
        lines.append(f"  with --discontinuities (dgp): {jg['fewer_grazing']} of the grazing ones "
                     f"kept (its rule is a view cosine < {jg['outlier_eps']:.4g})")
    if jg.get("grazing_kept"):
        lines.append(f"  with --discontinuities (dgp): {jg['grazing_kept']} grazing ones kept as "
                     "a surface seen edge-on (more than a tenth of their component, and "
                     "neighbours agree: not a rim)")
    if jg.get("isolated"):
        from .problem import isolated_rule_text

        # (all the route drops: the default's lone steep ones counted above among them,
        # said so, the diff review read them as more)
        steep = (rec.get("counts") or {}).get("isolated") or 0
        among = f", the {steep} above among them" if steep else ""
        lines.append(f"  with --discontinuities (dgp): {jg['isolated']} isolated "
                     f"({isolated_rule_text(jg['isolated_rule'])}{among}), treated as missing")
    for key, what in (("estimate", "default integration"),
                      ("estimate_discontinuities", "with --discontinuities")):
        e = rec.get(key)
        if e is None:
            continue
        fits = "within" if e["fits"] else "more than"
        line = (f"  {what} (estimate): peak about {_mib(e['bytes'])} above the input "
                f"({e['route']} route; {fits} the {_mib(e['limit'])} allowed here)")
        if e["seconds"] is not None:
            lo, hi = e["seconds"]
            line += f", {_seconds(lo)}-{_seconds(hi)} s on the 2-core benchmark machine"
        if e.get("bytes_factorized"):
            what_is = ("its last solve is factorized (when that fits)"
                       if e["route"] == "dgp-discontinuous" else
                       "it factorizes the system instead of iterating (when that fits and is "
                       "modelled faster: many components, scattered missing normals)")
            line += f"; up to about {_mib(e['bytes_factorized'])} where {what_is}"
        lines.append(line)
    return lines


def _mib(b: float) -> str:
    if b >= 2**30:
        return f"{b / 2**30:.1f} GiB"
    if b >= 2**20:
        return f"{b / 2**20:.0f} MiB"
    return f"{b / 1024:.0f} KiB" if b >= 1024 else f"{b:.0f} bytes"  # (not "0 MiB")


def _say_item(r: dict) -> None:
    """A batch item's warnings and error on stderr as soon as the item is done (above the
    progress bar; one line each, as integrate shows them), not after the last item: an
    overnight batch shows its failures as they happen, and a stopped one those it had."""
    from tqdm import tqdm

    for w in r.get("warnings") or ():
        tqdm.write(f"facetlift: warning: {r['name']}: {_as_flags(' '.join(str(w).split()))}",
                   file=sys.stderr)
    if r["status"] != "ok":
        msg = _as_flags(" ".join(str(r["error"]).split()))
        tqdm.write(f"facetlift: error: {r['name']} ({r['status']}): {msg}", file=sys.stderr)


@cli.command("batch", context_settings=CONTEXT)
@click.argument("inputs", nargs=-1)
@click.option("--list", "list_file", type=click.Path(exists=True, dir_okay=False),
              help="A text file with more inputs, one path or glob pattern per line; relative "
              "paths are relative to the file's folder (~ is the home folder), '#' at a "
              "line's start or after a space starts a comment.")
@_job_options
@click.option("-o", "--out", "outdir", required=True,
              type=click.Path(file_okay=False), callback=_out_dir,
              help="Output folder: one subfolder per item, and the log batch.jsonl.")
@click.option("--workers", type=int, help="Local worker processes (default: the CPU count "
              "where Dask, the batch extra, is installed, else 1; 1 runs in this process "
              "without Dask).")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run on a dask.distributed cluster, e.g. tcp://host:8786 (the workers must "
              "see the input and output paths).")
@click.option("--resume", is_flag=True, help="Skip items the log says finished.")
@click.option("--json", "as_json", is_flag=True, help="Print the records as JSON lines.")
@click.option("--colors", "--colours", "colors", hidden=True, expose_value=True,
              help="Refused: one picture would paint every map.")
def batch(inputs, list_file, outdir, workers, scheduler, resume, progress, as_json, colors,
          **flags):
    """Integrate many normal maps: files, dataset folders, folders of them, glob patterns
    (quote them) or a --list file, each into OUT/<name>/. Exit 0 only if every item
    succeeded, else 1 with the count; the log OUT/batch.jsonl has one record per item.

    \b
    Examples:
      facetlift batch 'maps/*.png' -o out --workers 2 --normal-frame opencv
      facetlift batch data/ -o out --save npy --save report --resume
      facetlift batch --list maps.txt -o /shared/out --scheduler tcp://head:8786
    """
    if colors is not None:  # (click's "No such option" offered --solver, a user's check)
        raise ValueError(f"--colors {colors}: a batch takes no colour image for every map (one "
                         "picture would paint them all); name each map's own NAME_colors.* "
                         "beside it (NAME.png and NAME_colors.jpg), or integrate each map with "
                         "facetlift integrate --colors")
    from .batch import LOG_NAME, log_record
    from .batch import batch as run_batch
    from .errors import WorkersDied
    from .io.atomic import Terminated

    if not inputs and list_file is None:
        raise click.UsageError("give inputs (files, folders, patterns) or --list FILE")
    job = _make_job(**flags)
    t0 = time.perf_counter()
    known = []

    def stream(r):  # (each record as it is known: an interrupted batch has shown its part)
        if not r.get("resumed"):  # (a resumed item's warnings were shown by its own run)
            known.append(r["status"])
            _say_item(r)
        if as_json:
            click.echo(json.dumps(log_record(r)))

    log = logging.getLogger("facetlift")
    if workers != 1 and log.isEnabledFor(logging.INFO):  # (-v printed nothing from a
        # parallel batch's items, and said nothing of it, a CLI audit)
        log.info("batch: items that run in worker processes log there, not here: give "
                 "--workers 1 to see their lines")
    try:
        records = run_batch(inputs, outdir, job=job, workers=workers, scheduler=scheduler,
                            resume=resume, progress=_show_progress(progress),
                            list_file=list_file, on_record=stream,
                            wording=lambda m: _as_flags(" ".join(m.split())))
    except (KeyboardInterrupt, click.exceptions.Abort, Terminated, WorkersDied):
        # (stopped from outside, or its workers died: what this run finished is said first)
        if known:
            ok = sum(k == "ok" for k in known)
            click.echo(f"batch: stopped with {len(known)} item(s) done in this run ({ok} ok; "
                       f"log: {outdir / LOG_NAME}); --resume goes on", err=True)
        raise
    failed = [r for r in records if r["status"] != "ok"]
    if as_json:  # (every item's record was printed as it was known)
        _STATE["printed_json"] = True
    resumed = sum(bool(r.get("resumed")) for r in records)
    warned = [bool(r.get("resumed")) for r in records
              if r["status"] == "ok" and r.get("warnings")]
    # (those of an earlier run too, whose warnings this run did not print: a user's resumed
    # batch said nothing of a wrong-frame warning its log held)
    # (one parenthesis: "(2 with warnings, 2 of them from an earlier run, in the log) (2 from
    # an earlier run)" said the earlier run twice, a user's check)
    said = [f"{resumed} from an earlier run"] if resumed else []
    if warned:  # (those earlier ones' warnings were not printed now: in the log)
        said.append(f"{len(warned)} with warnings"
                    + (f", {sum(warned)} of those in the log only" if any(warned) else ""))
    evals = [r["evaluation"] for r in records if r["status"] == "ok" and r.get("evaluation")]
    made = [e["made"] for e in evals if e.get("made") is not None]
    # (an orthographic result is scored by the normalised error where it has no MADE: both
    # means, each over its own items, a user's check of a mixed batch)
    normalised = [e["normalized_error"] for e in evals
                  if e.get("made") is None and e.get("normalized_error") is not None]
    scored = []
    if made:
        scored.append(f"mean MADE {sum(made) / len(made):.4g} over the {len(made)} with a "
                      "depth_gt file scored by it")
    if normalised:
        scored.append(f"mean normalised error {100 * sum(normalised) / len(normalised):.3g} % "
                      f"over the {len(normalised)} orthographic one(s) with a depth_gt file")
    # (integrate's hints, in each record's "hints": counted, and the first shown once, not
    # one line per item of a long batch)
    hinted = [r for r in records if r["status"] == "ok" and r.get("hints")]
    if hinted:
        said.append(f"{len(hinted)} with hints")
        click.echo(f"hint: {len(hinted)} item(s) have hints in their records ({outdir / LOG_NAME}"
                   f', "hints"); {hinted[0]["name"]}\'s: {hinted[0]["hints"][0]}', err=True)
    line = (f"batch: {len(records) - len(failed)} of {len(records)} succeeded"
            + (f" ({'; '.join(said)})" if said else "")
            + (f", {len(failed)} failed" if failed else "")
            # (the items whose dataset folder holds a depth_gt.*: a method compared on a
            # benchmark's folders in one line, as BiNI's evaluation prints it)
            + ("; " + "; ".join(scored) if scored else "")
            + f" (log: {outdir / LOG_NAME}), {time.perf_counter() - t0:.1f} s")
    click.echo(line, err=as_json)
    return EXIT_INPUT if failed else EXIT_OK


@cli.command(context_settings=CONTEXT)
@click.option("--json", "as_json", is_flag=True, help="Print the registry as JSON.")
@click.option("--markdown", is_flag=True,
              help="Print the capability and option tables in Markdown (docs/methods.md).")
def methods(as_json, markdown):
    """List the integration methods, what they can take, and their options.

    Capabilities: masks (any domain shape), missing (NaN normals inside the mask),
    perspective (a camera K), discontinuities (depth jumps), prior (a depth prior: --prior),
    confidence (per-pixel normal weights: --confidence), prior_blur (a prior seen through a
    blur: --prior-blur). Options are passed with --solver/--max-iter/--tol/--backend or
    '--option KEY=VALUE'.
    """
    if markdown and as_json:  # (Markdown was printed, exit 0: an audit)
        raise ValueError("give --json or --markdown, not both")
    if markdown:
        click.echo(_methods.markdown(), nl=False)
        return EXIT_OK
    caps = _methods.CAPABILITIES
    records = []
    for name, info in _methods.REGISTRY.items():
        try:
            specs = info.specs()
            available = True
        except ImportError:
            specs, available = (), False
        records.append({
            "name": name,
            "available": available,
            "summary": info.summary,
            "reference": info.reference,
            "capabilities": info.capabilities(),
            "options": {o.name: o.default for o in specs},
            "option_details": [
                {"name": o.name, "default": o.default, "values": o.expected, "doc": o.doc,
                 "applies": o.when} for o in specs
            ],
        })
    if as_json:
        click.echo(json.dumps(jsonable(records)))
        return EXIT_OK
    for r in records:
        head = f"{r['name']}" + ("" if r["available"] else "  (not available)")
        click.echo(head)
        click.echo(f"    {r['summary']}")
        can = [c for c in caps if r["capabilities"][c]]
        click.echo(f"    handles: {', '.join(can) if can else '-'}")
        for o in r["option_details"]:
            when = "".join(f", with {k}={v!r}" for k, v in o["applies"].items())
            click.echo(f"    --option {o['name']}={o['default']!r}  ({o['values']}{when}): "
                       f"{o['doc']}")
        click.echo(f"    reference: {r['reference']}")
    return EXIT_OK


def _split(text):
    return None if not text else tuple(t.strip() for t in text.split(",") if t.strip())


@cli.command(context_settings=CONTEXT)
@click.argument("result", type=click.Path(exists=True, path_type=Path))
@click.option("--gt", "gt", required=True,
              type=click.Path(exists=True, path_type=Path),
              help="Ground-truth depth map: .npy, .npz (its depth_gt or depth array, or its "
              "only one), .exr (channel Z or its only one), .tif, .pfm, .mat (its depth_gt, "
              "depth or z, or its only map), or a 16-bit PNG with --gt-scale; NaN (0 in a PNG or "
              "an integer TIFF) where undefined. Or a "
              "dataset folder (BiNI's DiLiGenT folders): its depth_gt.*, and its mask.png "
              "and K.txt where --mask and --K are not given and the result keeps no camera.")
@click.option("--gt-scale", "gt_scale", type=float, default=None, metavar="S",
              help="Depth units per count of a 16-bit PNG ground truth (e.g. 0.001 for "
              "millimetres in metres); multiplies other formats too.")
@click.option("-m", "--mask", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="The pixels to score (PNG/TIFF/npy, nonzero = inside). Default: where both "
              "depths are finite.")
@click.option("--K", "K", type=CAMERA_FILE, metavar="FILE | \"FX FY CX CY\"",
              help="The result's camera, as for 'integrate' (a file, or fx fy cx cy typed "
              "inline): score it as a perspective depth "
              "(a surface .npz keeps its own). Without one no camera is given and the result "
              "is scored as orthographic.")
@click.option("--fov", "fov", type=float, default=None, metavar="DEG",
              help="Instead of --K: the horizontal field of view the result was integrated "
              "with (integrate's --fov), for a camera without a K file.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def evaluate(result, gt, mask, K, fov, as_json, gt_scale=None):
    """Score a result RESULT (depth.npy, .exr, .tif or surface.npz, as integrate writes them,
    or integrate's output folder: its surface.npz, else its depth.npy, .exr or .tif; another
    tool's .npy, .npz, .pfm or .mat: its depth or z, or its only map) against
    a ground-truth depth map: MADE (BiNI's: the result times the median of GT /
    RESULT, then the mean absolute error), that scale, the RMSE after it, the mean absolute
    error without a scale (for metric depth, e.g. a result fused with a depth prior) and, for
    an orthographic result, the paper's normalised error (facetlift.metrics.evaluate), which
    needs the result in the ground truth's units: integrate with --pixel-size, the world
    width of a pixel (a warning says where the depth ranges differ).

    \b
    Examples:
      facetlift evaluate out/depth.npy --gt bear/depth_gt.npz -m bear/mask.png --K bear/K.txt
      facetlift evaluate out/surface.npz --gt gt.exr --json
      facetlift evaluate out --gt gt.exr
      facetlift evaluate out/depth.npy --gt depth_gt.npy --fov 60
    """
    import numpy as np

    from . import io, metrics

    if fov is not None and K is not None:
        raise ValueError(f"`fov` {fov:g} and `K` contradict each other; give one")
    if gt_scale is not None and not (np.isfinite(gt_scale) and gt_scale > 0):
        raise ValueError(f"`gt_scale` must be a positive number; got {gt_scale!r}")
    if result.is_dir():  # (integrate's output folder was refused as "is a directory", a review)
        result = _result_in_folder(result)
    est = io.read_depth(result, arg="result")
    folder_notes = []
    # (the camera as the text names it: the flag typed, or the folder's file)
    shown = f"--fov {fov:g} deg" if fov is not None else None if K is None else f"--K {K}"
    if gt.is_dir():  # (a BiNI user's `--gt bear` was refused as a directory, an audit)
        typed = K
        gt, mask, K, folder_notes = _gt_folder(gt, mask, K, fov, result, est)
        if K is not None and typed is None:  # (not typed: as integrate's summary names it)
            shown = f"the folder's {Path(K).name}"
    camera = None
    orthographic = False  # (a surface.npz that records an orthographic camera)
    if result.suffix.lower() == ".npz":  # (a surface's: its camera, NaN when orthographic)
        with np.load(result, allow_pickle=False) as z:
            stored = np.asarray(z["K"], dtype=float) if "K" in z.files else None
        if stored is not None and stored.shape == (3, 3) and np.isfinite(stored).all():
            camera = stored
        orthographic = stored is not None and not np.isfinite(stored).all()
    if K is not None or fov is not None:  # (integrate took --fov too: a fov user had no K file)
        from .camera import K_from_fov
        from .io.dataset import camera_of

        if K is not None:  # (a file stating another image size is refused, as integrate does)
            given = camera_of(K, est.shape, of="the result")
            named, flag = f"`K`: {K}", "--K"
        else:
            given, named, flag = K_from_fov(est.shape, fov), f"`fov` {fov:g}", "--fov"
        if orthographic:  # (as metrics.evaluate refuses a K for an orthographic Surface)
            raise ValueError(f"{named} given for {result}, which was integrated "
                             f"orthographically (its camera is stored): leave {flag} out")
        if camera is not None and not np.allclose(given, camera, rtol=1e-6):
            raise ValueError(f"{named} differs from the camera {result} was integrated with "
                             f"({camera.tolist()}); leave {flag} out to use the surface's own")
        camera = given
    from .jobs import GT_NPZ_NAMES

    if gt.suffix.lower() == ".png":  # (a sensor's or a dataset's 16-bit counts)
        truth = io.read_prior(gt, gt_scale, arg="gt", scale_arg="gt_scale")
    else:
        truth = io.read_depth(gt, npz_names=GT_NPZ_NAMES, arg="gt", zero_unknown=True)
        if gt_scale is not None:
            truth = truth * gt_scale
    if truth.shape != est.shape:
        # (a result stored transposed, (W, H), was told to give another ground truth, a
        # review)
        advice = ("the result's shape is the ground truth's transposed: one of them was "
                  "stored as (W, H)? transpose it" if truth.shape == est.shape[::-1] else
                  "give the ground truth of the same view and crop")
        raise ValueError(f"`gt`: {gt} is {truth.shape[0]}x{truth.shape[1]} (HxW) but `result` "
                         f"{result} is {est.shape[0]}x{est.shape[1]}: {advice}")
    sel = None if mask is None else io.read_mask(mask, est.shape, of=f"the result {result}")
    perspective = camera is not None
    from ._warnings import recording, reemit

    try:
        # (its warnings in the command line's words: --K, not perspective=True, a review;
        # kept for --json too, as integrate's: a unit warning went to stderr alone, an audit)
        with recording() as caught:
            rec = metrics._evaluate(est, truth, sel, perspective, "command line")
    except ValueError as e:  # (the library's arguments, named as the command's)
        raise ValueError(str(e).replace("`estimate`", "`result`").replace("`truth`", "`gt`")
                         ) from None
    for w in caught:
        reemit(w)
    rec["warnings"] = [_as_flags(str(w.message)) for w in caught]
    if (not perspective and rec["scale"] is not None and K is None and not orthographic
            and not (rec["correlation"] is not None
                     and rec["correlation"] < metrics.HEIGHT_CORRELATION)):  # (a positive
        # height was told to give --K, a review: the warning asks whether it is a height)
        rec["notes"].append("the result's depths are all > 0, as a perspective result's are "
                            "(an orthographic one has mean 0): give --K to score it as one "
                            "(or --fov, as integrate took it)")
    rec["notes"][:0] = folder_notes
    rec = {"result": str(result), "gt": str(gt),
           "mask": "where both are finite" if mask is None else str(mask), **rec}
    if as_json:
        click.echo(json.dumps(jsonable(dict(rec, status="ok", exit_code=EXIT_OK))))
        _STATE["printed_json"] = True
        return EXIT_OK
    for line in _evaluate_lines(rec, shown, surface=result.suffix.lower() == ".npz"):
        click.echo(line)
    return EXIT_OK


def _gt_folder(folder: Path, mask, K, fov, result: Path, est):
    """``(gt, mask, K, notes)`` of ``evaluate --gt FOLDER``: the folder's ground truth
    (:data:`facetlift.jobs.GT_NAMES`, the first present), and its ``mask.png`` and ``K.txt``
    where the command was given none and (for K) the result `est` keeps no camera of its own
    (a surface.npz does) and has only positive depths (an orthographic result, integrated
    with --orthographic from such a folder, has mean 0); ``notes`` say which files were taken.
    A ValueError names the files looked for where the folder holds no ground truth."""
    from .jobs import GT_NAMES

    present = [folder / n for n in GT_NAMES if (folder / n).is_file()]
    if not present:
        raise ValueError(f"`gt`: the folder {folder} holds none of {', '.join(GT_NAMES)}: "
                         "give the ground-truth file itself")
    notes = [f"ground truth: {present[0].name} of {folder}"]
    if mask is None and (folder / "mask.png").is_file():
        mask = folder / "mask.png"
        notes.append(f"scored inside {mask} (the folder's mask; --mask overrides it)")
    if (K is None and fov is None and (folder / "K.txt").is_file()
            and result.suffix.lower() != ".npz"):
        import numpy as np

        with np.errstate(invalid="ignore"):
            positive = bool(np.all(est[np.isfinite(est)] > 0))
        if positive:
            K = folder / "K.txt"
            notes.append(f"scored as a perspective depth with {K} (the folder's camera; --K "
                         "overrides it)")
        else:
            notes.append(f"the folder's {folder / 'K.txt'} not used: the result has depths "
                         "<= 0, as an orthographic one has")
    return present[0], mask, K, notes


def _result_in_folder(folder: Path) -> Path:
    """The result ``facetlift evaluate`` scores in integrate's output `folder`: its
    surface.npz (which keeps its camera), else its depth.npy, .exr or .tif; a ValueError
    naming them where it holds none."""
    names = [OUTPUTS[k] for k in ("npz", "npy", "exr", "tif")]
    present = [folder / n for n in names if (folder / n).is_file()]
    if not present:
        raise ValueError(f"`result`: the folder {folder} holds none of {', '.join(names)} "
                         "(integrate writes them with -s npz, npy, exr, tif): give the depth "
                         "file, or the folder of a run that saved one")
    # (of the latest run only: a later integrate -o into the folder without -s npz left an
    # earlier run's surface.npz, which was scored instead of its depth.npy, an audit. One
    # run's outputs are moved into place as one set, within moments: on POSIX systems the
    # move sets st_ctime, while st_mtime is when each was written into staging, seconds
    # apart on large maps, a review; the latest run's are those within STALE_SECONDS of
    # each other, counting from the newest)
    stamp = "st_ctime" if os.name == "posix" else "st_mtime"
    when = {f: getattr(f.stat(), stamp) for f in present}
    order = sorted(present, key=when.get, reverse=True)
    latest = [order[0]]
    for f in order[1:]:
        if when[latest[-1]] - when[f] > STALE_SECONDS:
            break
        latest.append(f)
    found = next(f for f in present if f in latest)
    stale = [f.name for f in present if f not in latest]
    if stale:
        warnings.warn(f"evaluate: {folder} holds {', '.join(stale)} from an earlier run than "
                      f"its {found.name}: scoring {found.name}, the latest (give a file to "
                      "score another)", stacklevel=2)
    return found


#: Outputs of one folder written this many seconds apart come from different runs
#: (:func:`_result_in_folder`): one run writes its set within moments.
STALE_SECONDS = 2.0


def _evaluate_lines(rec: dict, given, surface: bool = False) -> list[str]:
    """``facetlift evaluate``'s text: one line per measure, '-' where it does not apply (the
    notes say why). `given`: the camera as the text names it ("--K FILE", "--fov D deg", "the
    folder's K.txt"; None: none given). `surface`: the result is a surface .npz, which says
    its camera (a depth file without --K says none: not "orthographic", a perspective
    depth.npy was labelled so, an audit)."""
    def num(v):
        return "-" if v is None else f"{v:.6g}"

    camera = ("perspective" + (f" ({given})" if given is not None else " (the surface's camera)")
              if rec["perspective"] else "orthographic (the surface's camera)" if surface
              else "no camera given: scored as orthographic (up to an offset per piece)")
    uncovered = (f"; {rec['uncovered']} mask pixels left out, where a depth is undefined"
                 if rec["uncovered"] else "")
    ne = rec["normalized_error"]
    lines = [f"{rec['result']} against {rec['gt']}: {rec['pixels']} pixels (mask: "
             f"{rec['mask']}{uncovered}), {camera}",
             f"  MADE:              {num(rec['made'])}"
             + (" (the ground truth's units, after the median scale)"
                if rec["made"] is not None else ""),
             f"  scale:             {num(rec['scale'])}"
             + (" (median of GT / RESULT)" if rec["scale"] is not None else ""),
             f"  RMSE after scale:  {num(rec['rmse_scaled'])}"
             + (" (the ground truth's units)" if rec["rmse_scaled"] is not None else ""),
             f"  MAE, no scale:     {num(rec['mae'])}"
             + (" (the ground truth's units, as stored: for metric depth)"
                if rec["mae"] is not None else "")
             + ("; far above MADE: a scale between the two (a result up to scale, or in "
                "other units)"
                if rec["mae"] is not None and rec["made"] is not None
                and rec["mae"] > 10 * max(rec["made"], 1e-300) else ""),
             "  normalised error:  "
             + ("-" if ne is None else f"{100 * ne:.4g} % of the ground truth's depth range "
                "(offset-aligned per piece)")]
    return lines + [f"  note: {n}" for n in rec["notes"]]


@cli.command("bench", context_settings=CONTEXT,
             short_help="Reproduce the paper's experiments and run the benchmarks.")
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder for tables (CSV, Markdown) and figures (PNG).")
@click.option("--quick", is_flag=True, help="Small sizes and few models (a smoke test).")
@click.option("--methods", default=None, help="Comma-separated method names.")
@click.option("--models", default=None,
              help="Comma-separated Fig. 9 model names; for the discontinuity and fusion "
                   "benchmarks also scene names, mesh names or vessel kinds (cup, bowl, "
                   "goblet, vase).")
@click.option("--experiments", default=None,  # facetlift.bench.EXPERIMENTS (a test checks)
              help="Comma-separated subset of: table1, fig4, fig5, maps, fig9, fig10, bear, "
                   "discontinuities, heldout, fusion.")
@click.option("--mesh", "meshes", multiple=True, type=click.Path(exists=True, dir_okay=False),
              help="Add a mesh to the Fig. 9 models (repeatable).")
@click.option("--normal-map", "normal_maps", multiple=True,
              type=click.Path(exists=True, file_okay=False),
              help="Add a data folder (normal_map.png, mask.png[, K.txt]) to Fig. 10.")
@click.option("--data", "data_dir", default=None, type=click.Path(exists=True, file_okay=False),
              help="Data folder with meshes/ and normal_maps/ (default: $FACETLIFT_DATA).")
@click.option("--conditions", default=None,
              help="Comma-separated normal conditions of the discontinuities and heldout "
                   "experiments "
                   "(default exact,16bit,8bit,noise3, with --quick exact,8bit; also noise6: 6 "
                   "degrees of angular noise, smooth3: "
                   "spatially correlated errors of 3 degrees RMS, outliers: 2 % of the "
                   "normals rotated by up to 45 degrees, blur1.5: the normal map blurred by "
                   "a Gaussian of 1.5 px, soft occlusion boundaries; blur3: of 3 px; "
                   "blur0.7: of 0.7 px; resample2, resample4: estimated at half or a "
                   "quarter of the resolution and upsampled bilinearly; ps: "
                   "normals fitted by photometric stereo to simulated images under 20 "
                   "lights, with shadows, highlights and image noise; ps_shiny: the same "
                   "with broader, brighter highlights).")
@click.option("--heldout-seed", "heldout_seed", type=click.IntRange(min=0), default=None,
              metavar="N",
              help="Seed of the heldout experiment's random views (a new one draws a fresh "
                   "test set).")
@click.option("--no-progress", is_flag=True, help="No progress bars.")
def bench(out, quick, methods, models, experiments, meshes, normal_maps, data_dir, conditions,
          no_progress, heldout_seed):
    """Reproduce the paper's experiments (Table 1, Figs. 4-10) and run the discontinuity,
    held-out and fusion benchmarks, into a folder."""
    from .bench import run_bench

    for flag, value in (("--experiments", experiments), ("--models", models),
                        ("--methods", methods), ("--conditions", conditions)):
        if value is not None and not _split(value):  # (an empty list ran them all, hours in
            # full mode, an audit and a review)
            raise click.UsageError(f"{flag} {value!r} names nothing")
    try:
        path = run_bench(out, quick=quick, methods=_split(methods), models=_split(models),
                         experiments=_split(experiments), extra_meshes=meshes,
                         extra_normal_maps=normal_maps, data_dir=data_dir,
                         conditions=_split(conditions),
                         # (bars only on a terminal, as integrate's and batch's: a redirected
                         # log held tqdm's cursor moves, an audit)
                         progress=not no_progress and sys.stderr.isatty(),
                         heldout_seed=heldout_seed)
    except ValueError as e:  # (in the flags' words: `heldout_seed` was named, an audit)
        raise click.UsageError(_as_flags(str(e))) from None
    click.echo(f"wrote {path / 'report.md'}")


def _seconds(t: float) -> str:
    """A time estimate in seconds, two significant digits without an exponent (110, 17, 1.5,
    0.04)."""
    return f"{float(f'{t:.2g}'):g}" if t < 1e5 else f"{t:.0f}"


def _error(message: str) -> None:
    click.echo(f"facetlift: error: {message}", err=True)
    _STATE.setdefault("errors", []).append(message)


def _as_flags(message: str) -> str:
    """The library's messages name Python arguments (`` `prior_weight` must be ...``); on the
    command line those given as flags are named as the flags (``--prior-weight must be
    ...``), and the input as NORMALS. A name whose flag was not given stays as it is: a
    dataset folder's K.txt is no --K, regularization's ``--option prior=`` no --prior."""
    args = _STATE.get("args") or ()
    names = {"path": "NORMALS", "folder": "NORMALS"}
    if "--gradients" in args:
        names.update(p="--gradients P", q="--gradients Q")
    for command in cli.commands.values():
        for param in command.params:
            if param.name in names:
                continue
            if param.param_type_name == "argument":
                names[param.name] = param.name.upper()
            else:  # (the spelling the user typed: -s, --save or --format)
                typed = [o for o in param.opts for a in args if a == o or a.startswith(o + "=")]
                if typed:
                    names[param.name] = typed[0]
    # (a --prior-weight-map's values are checked as integrate's `prior_weight`, and
    # `mat_keys` comes from no file: both were named as Python arguments, a user's check)
    if any(a == "--prior-weight-map" or a.startswith("--prior-weight-map=") for a in args):
        names["prior_weight"] = ("--prior-weight-map" if "prior_weight" not in names
                                 else f"--prior-weight-map (times {names['prior_weight']})")
    names.setdefault("mat_keys", "--mat-keys")
    # (a camera from --fov is integrate's `K`: a method without perspective support named
    # `K` to a user who typed --fov, a review)
    if "K" not in names and any(a == "--fov" or a.startswith("--fov=") for a in args):
        names["K"] = "--fov"
    # (a method option given as --option KEY=VALUE: named so, `k` alone was a name the user
    # had not typed, a user's check)
    given = [b for a, b in zip(args, args[1:], strict=False) if a == "--option"] + [
        a[len("--option="):] for a in args if a.startswith("--option=")]
    for text in given:
        typed = text.split("=", 1)[0].strip()
        key = typed.replace("-", "_")
        # (not "prior": regularization's --option prior= is no depth prior, and a message
        # about the depth prior (integrate's own `prior`) keeps its name, a review)
        if key.isidentifier() and key not in names and key != "prior":
            names[key] = f"--option {typed}"
    # (an option the method lacks, given as a flag: named as typed in the unknown list, not
    # as ['max_iter'], a user's check; the valid list stays the method's option names)
    head = re.match(r"unknown option\(s\) (\[[^\]]*\])", message)
    if head is not None:
        listed = re.sub(r"'(\w+)'", lambda m: names.get(m.group(1), m.group(0)), head.group(1))
        message = message[:head.start(1)] + listed + message[head.end(1):]
    message = re.sub(r"`(\w+)`", lambda m: names.get(m.group(1), m.group(0)), message)
    if "applies only with" not in message:  # (others give both spellings, or quote Python)
        return message
    # (the settings an option needs, as the flags that make them: "set solver='iterative'"
    # was Python on the command line, a fresh user's check)
    message = re.sub(r"\bsolver='(\w+)'", r"--solver \1", message)
    return re.sub(r"\bdiscontinuities=(True|False)\b",
                  lambda m: "--discontinuities" if m.group(1) == "True"
                  else "no --discontinuities", message)


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Every warning the commands do not print themselves (those of a job that failed after
    its reading, numpy's), as ``facetlift: warning: ...`` on stderr: Python's display named
    a line of click's or numpy's source."""
    text = _as_flags(" ".join(str(message).split()))
    _STATE.setdefault("warnings", []).append(text)  # (for a --json failure's object)
    print(f"facetlift: warning: {text}", file=sys.stderr if file is None else file)


def main(argv: list[str] | None = None) -> int:
    """Run the command line with `argv` (default ``sys.argv[1:]``); returns the exit code.

    The one error boundary: a ``ValueError`` or ``OSError`` (bad input, unwritable output) or
    an ``ImportError`` (a missing extra, named in the message) is one line and exit 1; a
    :class:`~facetlift.SolverError` exit 2; a :class:`~facetlift.MemoryLimitError` (or
    MemoryError) or a batch's dead workers (:class:`facetlift.errors.WorkersDied`) exit 1;
    anything else is a bug: one line asking for a report (the traceback
    with ``--debug``), exit 3.

    With ``--json``, a command that fails before printing its object prints
    ``{"status", "exit_code", "error"}`` on stdout instead (the message stays on stderr too).
    """
    if argv is None and os.environ.get("FACETLIFT_RETAIN_MEMORY", "1").strip().lower() not in (
            "0", "false", "no", "off"):
        # a command-line process: keep freed memory warm (facetlift.memory.retain_freed_memory;
        # not for in-process callers such as the tests, whose allocator stays as it was)
        from .memory import retain_freed_memory

        retain_freed_memory()
    args = sys.argv[1:] if argv is None else list(argv)
    if not args:
        args = ["--help"]
    from .io.images import _REDIRECT, protect_stdout

    # (stdout carries the --json object alone: the C readers' prints aside; put back after
    # an in-process call, whose host's stdout is its own)
    protected = _REDIRECT["enabled"]
    protect_stdout()
    _STATE.update(debug=False, errors=[], warnings=[], printed_json=False, args=tuple(args))
    try:
        code = _main(args)
    finally:
        protect_stdout(protected)
    if code != EXIT_OK and "--json" in args and not _STATE["printed_json"]:
        # a script reading --json gets one object on stdout for a failure too
        # (with the warnings printed before the failure, which its error may point to:
        # "the warning above says what to try" had none in the object, an audit)
        click.echo(json.dumps({"status": _STATUS.get(code, "error"), "exit_code": code,
                               "error": "; ".join(_STATE["errors"]) or None,
                               "warnings": list(_STATE.get("warnings") or [])}))
    return code


#: The "status" of the JSON object a failed command prints with --json, by exit code.
_STATUS = {EXIT_INPUT: "error", EXIT_SOLVER: "solver_error", EXIT_BUG: "internal_error",
           EXIT_INTERRUPTED: "interrupted", EXIT_TERMINATED: "terminated"}


#: The commands that write no file.
_READ_ONLY = ("info", "evaluate", "methods")


def _command(args) -> str | None:
    """The command named in a command line's arguments (its first word that is no flag)."""
    return next((a for a in args if not a.startswith("-")), None)


def _stopped(how: str) -> str:
    """What Ctrl-C ("interrupted (Ctrl-C)") or SIGTERM says: the outputs are staged and moved
    in as a set; a batch's finished items are in its log (said by a batch only: a plain
    integrate's message spoke of one, an audit)."""
    command = _command(_STATE.get("args", ()))
    if command == "bench":  # (its files are written experiment by experiment, an audit)
        return (f"{how}; the finished experiments' files are in the output folder, and its "
                "report.md lists them and the one interrupted")
    from .io.atomic import COMMITTED

    if command in _READ_ONLY:  # (they write nothing: no word on partial outputs, a review)
        return how
    if COMMITTED and command != "batch":  # (after the set was moved in: it is complete)
        return (f"{how} after the outputs were written: {COMMITTED[-1]} holds the complete "
                "new set")
    args = _STATE.get("args", ())
    cluster = command == "batch" and any(a == "--scheduler" or str(a).startswith(
        "--scheduler=") for a in args)
    return (f"{how}; nothing partial was written"
            + (" (a batch's finished items are in its log)" if command == "batch" else "")
            # (a cluster's running tasks cannot be stopped: they wrote their outputs after
            # the command had exited, a review; they now find the batch's cancel mark)
            + ("; items already running on the cluster run to their end and then discard "
               "their outputs" if cluster else ""))


def _main(args: list[str]) -> int:
    from .errors import MemoryLimitError, WorkersDied
    from .io.atomic import COMMITTED, Terminated, sigterm_raises

    COMMITTED.clear()  # (this command's commits only: _stopped)
    command = _command(args)
    try:
        # (the commands that write nothing end on SIGTERM with their message too: info died
        # by the signal with none, and no --json object, a review; the others install it
        # around their outputs)
        with warnings.catch_warnings(), (sigterm_raises() if command in _READ_ONLY
                                         else contextlib.nullcontext()):
            warnings.showwarning = _show_warning
            rv = cli.main(args=args, prog_name="facetlift", standalone_mode=False)
    except click.exceptions.Exit as e:  # pragma: no cover - returned, not raised, by click 8
        return e.exit_code
    except click.exceptions.Abort as e:  # click turns Ctrl-C (KeyboardInterrupt) into Abort
        _error(_stopped("interrupted (Ctrl-C)") if isinstance(e.__cause__, KeyboardInterrupt)
               else "aborted")
        return EXIT_INTERRUPTED
    except click.ClickException as e:  # usage errors, bad parameters, unreadable files
        msg = e.format_message()
        ctx = getattr(e, "ctx", None)
        if isinstance(e, click.UsageError) and ctx is not None:
            msg += f" (see '{ctx.command_path} --help')"
        _error(msg)
        return EXIT_INPUT
    except MemoryLimitError as e:
        _error(_as_flags(_one_line(e)))
        return EXIT_INPUT
    except WorkersDied as e:  # a batch's local workers: not a bug in facetlift
        _error(_one_line(e).replace("resume=True", "--resume").replace("workers=1",
                                                                        "--workers 1"))
        return EXIT_INPUT
    except MemoryError as e:
        from .errors import OutputMemoryError

        _error(f"out of memory ({_one_line(e)})" + ("" if isinstance(e, OutputMemoryError)
                                                     else "; try a crop, a smaller map or "
                                                     "another method"))
        return EXIT_INPUT
    except (ValueError, OSError) as e:
        _error(_as_flags(_one_line(e)))
        return EXIT_INPUT
    except ImportError as e:  # an optional extra that is not installed: the message names it
        _error(_one_line(e))
        return EXIT_INPUT
    except SolverError as e:
        _error(f"solver failed: {_one_line(e)}")
        return EXIT_SOLVER
    except SolverFailure as e:
        _error(str(e))
        return EXIT_SOLVER
    except KeyboardInterrupt:
        _error(_stopped("interrupted (Ctrl-C)"))
        return EXIT_INTERRUPTED
    except Terminated:
        _error(_stopped("terminated (SIGTERM or SIGHUP)"))
        return EXIT_TERMINATED
    except Exception as e:
        if _STATE["debug"]:
            import traceback

            traceback.print_exc()
        _error(
            f"internal error ({type(e).__name__}: {_one_line(e)}). This is a bug in facetlift "
            f"{__version__}: please report it with the command line"
            + ("" if _STATE["debug"] else " (run with 'facetlift --debug ...' for the traceback)")
        )
        return EXIT_BUG
    return rv if isinstance(rv, int) else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
