"""The ``facetlift`` command line: a thin layer over :func:`facetlift.integrate` and
:mod:`facetlift.io`.

``main(argv)`` returns an exit code: 0 success, 1 bad input (unreadable file, bad option,
input the method cannot take), 2 solver failure (:class:`facetlift.SolverError` or no
convergence), 130 interrupted. Errors are one line on stderr, without a traceback.
See ``docs/cli.md``.
"""

from __future__ import annotations

import json
import logging
import sys
import time
import warnings
from pathlib import Path

import click
import numpy as np

from . import __version__
from . import methods as _methods
from .errors import SolverError

log = logging.getLogger(__name__)

#: ``--save`` choices: extension -> file name written into the output folder.
OUTPUTS = {
    "npy": "depth.npy",
    "exr": "depth.exr",
    "tif": "depth.tif",
    "npz": "surface.npz",
    "ply": "mesh.ply",
    "obj": "mesh.obj",
    "png": "preview.png",
}
DEFAULT_SAVE = ("npy", "ply", "png")

EXIT_OK, EXIT_INPUT, EXIT_SOLVER, EXIT_INTERRUPTED = 0, 1, 2, 130


class SolverFailure(Exception):
    """The method ran but did not converge (outputs were written; exit code 2)."""


CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(context_settings=CONTEXT)
@click.version_option(__version__, "-V", "--version", prog_name="facetlift")
@click.option("-v", "--verbose", count=True,
              help="Log the library's progress on stderr (-vv for debug detail).")
def cli(verbose):
    """facetlift: turn a normal map into a depth map and a mesh (normal integration).

    \b
    Examples:
      facetlift integrate normal_map.png --mask mask.png
      facetlift integrate data/bear/ -o bear_out --save exr --save ply
      facetlift methods
      facetlift bench --quick -o bench_out

    Run 'facetlift COMMAND --help' for the options of a command.
    """
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
    """Logs to whatever ``sys.stderr`` is when a record is emitted."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


def _parse_option(text: str) -> tuple[str, object]:
    if "=" not in text:
        raise click.BadParameter(f"expected KEY=VALUE; got {text!r}", param_hint="--option")
    key, value = text.split("=", 1)
    key = key.strip().replace("-", "_")
    if not key.isidentifier():
        raise click.BadParameter(f"{key!r} is not an option name", param_hint="--option")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value  # a bare string such as solver=iterative


def _default_outdir(src: Path) -> Path:
    src = src.resolve()
    return src.parent / f"{src.stem if src.is_file() else src.name}_facetlift"


def _read_input(normals: Path, mask: Path | None, K: Path | None, y_down: bool,
                orthographic: bool):
    """-> (normals, mask or None, K or None, mask source) from a file or a dataset folder."""
    from . import io

    if normals.is_dir():
        ds = io.read_dataset(normals, y_down=y_down)
        n, m, Kmat = ds["normals"], ds["mask"], ds["K"]
        source = "dataset mask" if m is not None else "valid normals"
    else:
        n, m = io.read_normals(normals, y_down=y_down)
        Kmat = None
        source = "alpha channel" if m is not None else "valid normals"
    if mask is not None:
        m = io.read_mask(mask, n.shape[:2])
        source = str(mask)
    if K is not None:
        Kmat = io.read_K(K)
    if orthographic:
        Kmat = None
    return n, m, Kmat, source


def _progress_bar(total: int | None):
    """(bar, update): a tqdm bar on stderr that appears at the first update (a route that
    never reports progress shows nothing); ``bar.close()`` is safe either way."""
    from tqdm import tqdm

    state = {}

    class _Bar:
        def close(self):
            if "bar" in state:
                state["bar"].close()

    def update(iteration, value):
        if "bar" not in state:
            state["bar"] = tqdm(total=total, desc="integrating", unit="it", file=sys.stderr,
                                leave=False)
        bar = state["bar"]
        bar.update(iteration - bar.n)
        bar.set_postfix_str(f"{value:.4g}", refresh=False)

    return _Bar(), update


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    return repr(obj)


@cli.command(context_settings=CONTEXT)
@click.argument("normals", type=click.Path(exists=True, path_type=Path))
@click.option("-m", "--mask", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Mask image (PNG/TIFF/npy, nonzero = integrate). Default: the dataset's "
              "mask.png, else the alpha channel, else every pixel with a valid normal.")
@click.option("--method", default="dgp", show_default=True,
              help="Integration method; 'facetlift methods' lists them.")
@click.option("--pixel-size", type=float, default=1.0, show_default=True,
              help="Pixel width in world units (orthographic): scales depth with x and y.")
@click.option("--y-down", is_flag=True,
              help="The normal map stores y pointing down (DirectX/OpenCV style).")
@click.option("--K", "K", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Perspective intrinsics, a 3x3 text file (OpenCV layout). A dataset "
              "folder's K.txt is used automatically.")
@click.option("--orthographic", is_flag=True,
              help="Ignore K (e.g. a dataset's K.txt) and integrate orthographically.")
@click.option("--backfacing", type=click.Choice(["missing", "error", "outlier"]),
              default="missing", show_default=True,
              help="Normals facing away from the camera inside the mask: treat them as missing "
              "samples (counted and reported; 'outlier' is an alias), or stop with an error.")
@click.option("--outlier-eps", type=float, default=None,
              help="Grazing threshold on the view cosine below which a normal is a missing "
              "sample (default: cos 85 deg orthographic, 1/255 perspective).")
@click.option("--solver", help="The method's solver, where it has one (dgp: 'direct' solves "
              "the fixed point at once, the default; 'iterative' runs the paper's loop).")
@click.option("--max-iter", type=int, help="Iteration limit (methods with `max_iter`).")
@click.option("--tol", type=float, help="Convergence tolerance (methods with `tol`).")
@click.option("--backend", help="Sparse linear solver backend (methods with `backend`): "
              "auto, pcg, pardiso, superlu, amg.")
@click.option("--discontinuities", is_flag=True,
              help="Allow depth jumps (methods that handle discontinuities: 'facetlift methods').")
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE",
              help="Any other method option, repeatable; VALUE is read as JSON when it "
              "parses (1e-4, true, [1,2]) and as a string otherwise.")
@click.option("-o", "--out", "outdir", type=click.Path(file_okay=False, path_type=Path),
              help="Output folder. Default: <input>_facetlift/ next to the input.")
@click.option("-s", "--save", "--format", "save", multiple=True,
              type=click.Choice(list(OUTPUTS)),
              help="What to write, repeatable: npy/exr/tif = depth map, npz = depth + vertex "
              "depth + mask, ply/obj = mesh, png = shaded preview. Default: npy, ply, png.")
@click.option("--triangles", is_flag=True, help="Write triangle meshes instead of quads.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object (outputs, diagnostics, timings) instead of text.")
@click.option("--progress/--no-progress", default=None,
              help="Progress bar on stderr for iterative solvers. Default: when stderr is a "
              "terminal.")
@click.option("--max-memory", default=None, metavar="SIZE",
              help="Refuse the job if its estimated peak memory exceeds SIZE (bytes, or 8G, "
              "512M). Default: the available memory minus a margin, ulimit -v honoured.")
def integrate(normals, mask, method, pixel_size, y_down, K, orthographic, backfacing,
              outlier_eps, solver, max_iter, tol, backend, discontinuities, options, outdir,
              save, triangles, as_json, progress, max_memory):
    """Integrate a normal map NORMALS into a depth map, a mesh and a preview.

    NORMALS is a normal-map file (PNG 8/16 bit, TIFF, EXR or .npy; x right, y up, z toward
    the viewer, 8/16-bit values v decoded as v/max*2-1) or a dataset folder holding
    normal_map.png, mask.png and, for a perspective camera, K.txt.

    \b
    Examples:
      facetlift integrate normal_map.png --mask mask.png
      facetlift integrate scan.exr --pixel-size 0.5 -o out --save exr --save obj
      facetlift integrate data/tent/ --solver iterative --tol 1e-4 --progress
      facetlift integrate n.png --solver iterative --option mean_subtraction=false --json
    """
    import facetlift

    info = _methods.get(method)
    t0 = time.perf_counter()
    n, m, Kmat, mask_source = _read_input(normals, mask, K, y_down, orthographic)
    t_read = time.perf_counter() - t0

    opts = dict(_parse_option(o) for o in options)
    for key, value in (("solver", solver), ("max_iter", max_iter), ("tol", tol),
                       ("backend", backend), ("max_memory", max_memory)):
        if value is not None:
            opts[key] = value
    if discontinuities:
        opts["discontinuities"] = True

    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    if show and "progress" in info.options() and "progress" not in opts:
        bar, opts["progress"] = _progress_bar(opts.get("max_iter"))

    t1 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            surface = facetlift.integrate(
                n, m, method=method, pixel_size=pixel_size, K=Kmat, backfacing=backfacing,
                outlier_eps=outlier_eps, **opts,
            )
    except ValueError as e:  # name the command-line flag where the library names a keyword
        raise ValueError(
            str(e).replace("pass backfacing='missing'", "pass --backfacing missing")
        ) from None
    finally:
        if bar is not None:
            bar.close()
    for w in caught:
        click.echo(f"facetlift: warning: {w.message}", err=True)
    t_integrate = time.perf_counter() - t1

    t2 = time.perf_counter()
    outdir = _default_outdir(normals) if outdir is None else outdir
    outdir.mkdir(parents=True, exist_ok=True)
    written = {}
    for ext in dict.fromkeys(save or DEFAULT_SAVE):  # keep order, drop repeats
        kw = {"triangles": True} if triangles and ext in ("ply", "obj") else {}
        written[ext] = str(surface.save(outdir / OUTPUTS[ext], **kw))
    t_write = time.perf_counter() - t2

    sinfo = surface.info
    converged = sinfo.get("converged", True)
    H, W = surface.shape
    if as_json:
        record = {
            "input": str(normals),
            "outputs": written,
            "shape": [H, W],
            "facets": int(surface.mask.sum()),
            "mask_source": mask_source,
            "perspective": surface.K is not None,
            "info": _jsonable(sinfo),
            "timings": {"read": t_read, "integrate": t_integrate, "write": t_write,
                        "total": time.perf_counter() - t0},
        }
        click.echo(json.dumps(record))
    else:
        for path in written.values():
            click.echo(f"wrote {path}")
        it = sinfo.get("iterations")
        parts = [
            f"{H}x{W} pixels, {int(surface.mask.sum())} facets (mask: {mask_source})",
            f"method {sinfo.get('method', method)}"
            + (f" ({sinfo['solver']})" if "solver" in sinfo else ""),
        ]
        if it is not None:
            parts.append(f"{it} iteration{'s' if it != 1 else ''}"
                         + ("" if converged else " (not converged)"))
        parts.append(f"{t_integrate:.2f} s")
        click.echo(", ".join(parts))
    if not converged and sinfo.get("solver") == "discontinuous":
        # a fixed budget of reweightings by design: the surface is usable, say so and go on
        click.echo(
            f"note: the discontinuity reweighting used all {sinfo.get('iterations')} "
            "iterations before its weights settled; more may sharpen long jumps "
            "(--option discontinuity_iter=N)",
            err=True,
        )
    elif not converged:
        raise SolverFailure(
            f"method {method!r} did not converge in {sinfo.get('iterations')} iterations "
            "(outputs were written); raise --max-iter or --tol"
        )
    return EXIT_OK


@cli.command(context_settings=CONTEXT)
@click.option("--json", "as_json", is_flag=True, help="Print the registry as JSON.")
@click.option("--markdown", is_flag=True,
              help="Print the capability and option tables in Markdown (docs/methods.md).")
def methods(as_json, markdown):
    """List the integration methods, what they can take, and their options.

    Capabilities: masks (any domain shape), missing (NaN normals inside the mask),
    perspective (a camera K), discontinuities (depth jumps). Options are passed with
    --solver/--max-iter/--tol/--backend or '--option KEY=VALUE'.
    """
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
        click.echo(json.dumps(_jsonable(records)))
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


@cli.command("bench", context_settings=CONTEXT)
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder for tables (CSV, Markdown) and figures (PNG).")
@click.option("--quick", is_flag=True, help="Small sizes and few models (a smoke test).")
@click.option("--methods", default=None, help="Comma-separated method names.")
@click.option("--models", default=None, help="Comma-separated Fig. 9 model names.")
@click.option("--experiments", default=None,  # facetlift.bench.EXPERIMENTS (a test checks)
              help="Comma-separated subset of: table1, fig4, fig5, maps, fig9, fig10, bear.")
@click.option("--mesh", "meshes", multiple=True, type=click.Path(exists=True, dir_okay=False),
              help="Add a mesh to the Fig. 9 models (repeatable).")
@click.option("--normal-map", "normal_maps", multiple=True,
              type=click.Path(exists=True, file_okay=False),
              help="Add a data folder (normal_map.png, mask.png[, K.txt]) to Fig. 10.")
@click.option("--data", "data_dir", default=None, type=click.Path(exists=True, file_okay=False),
              help="Data folder with meshes/ and normal_maps/ (default: $FACETLIFT_DATA).")
@click.option("--no-progress", is_flag=True, help="No progress bars.")
def bench(out, quick, methods, models, experiments, meshes, normal_maps, data_dir, no_progress):
    """Reproduce the paper's experiments (Table 1, Figs. 4-10) into a folder."""
    from .bench import run_bench

    try:
        path = run_bench(out, quick=quick, methods=_split(methods), models=_split(models),
                         experiments=_split(experiments), extra_meshes=meshes,
                         extra_normal_maps=normal_maps, data_dir=data_dir,
                         progress=not no_progress)
    except ValueError as e:
        raise click.UsageError(str(e)) from None
    click.echo(f"wrote {path / 'report.md'}")


def _error(message: str) -> None:
    click.echo(f"facetlift: error: {message}", err=True)


def main(argv: list[str] | None = None) -> int:
    """Run the command line with `argv` (default ``sys.argv[1:]``); returns the exit code."""
    args = sys.argv[1:] if argv is None else list(argv)
    if not args:
        args = ["--help"]
    try:
        rv = cli.main(args=args, prog_name="facetlift", standalone_mode=False)
    except click.exceptions.Exit as e:  # pragma: no cover - returned, not raised, by click 8
        return e.exit_code
    except click.exceptions.Abort:
        _error("aborted")
        return EXIT_INTERRUPTED
    except click.ClickException as e:  # usage errors, bad parameters, unreadable files
        msg = e.format_message()
        ctx = getattr(e, "ctx", None)
        if isinstance(e, click.UsageError) and ctx is not None:
            msg += f" (see '{ctx.command_path} --help')"
        _error(msg)
        return EXIT_INPUT
    except (ValueError, OSError) as e:
        _error(str(e))
        return EXIT_INPUT
    except SolverError as e:
        _error(f"solver failed: {e}")
        return EXIT_SOLVER
    except SolverFailure as e:
        _error(str(e))
        return EXIT_SOLVER
    except KeyboardInterrupt:
        _error("interrupted")
        return EXIT_INTERRUPTED
    return rv if isinstance(rv, int) else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
