"""Every ```python block of README.md and docs/*.md runs as written (a user's complaint: docs
examples that no longer ran, after renamed arguments, changed return types, removed functions).

Each block is found by the heading of the section it sits in (and, where a section holds
several, by a line of its own), not by its index, and executed verbatim in a fresh folder with
small stand-ins for the files, arrays and modules it takes from the reader (``normals``,
``K``, ``diligent/bear/``, Blender's ``bpy``); where the text around it says something
checkable (files written, shapes, a value range, an equality), that is checked too. A block
that cannot run as written is in :data:`SKIPPED` with the reason and the text that stops it.
:func:`test_every_python_block_of_the_docs_is_run_or_skipped` fails on a block that is in
neither list (a new example needs a test here) and on an entry whose block is gone.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
import sys
import textwrap
import types
import warnings
from pathlib import Path

import imagecodecs
import numpy as np
import pytest

import facetlift
from facetlift import io, synthetic

ROOT = Path(__file__).resolve().parents[1]
DOCS = ["README.md", *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md"))]


def python_blocks(doc: str) -> list[tuple[str, str]]:
    """``(heading, code)`` of each ```python block of `doc`: the last heading line above it
    (``## ...``, outside code) and its code, dedented (blocks in list items are indented)."""
    blocks, heading, fence = [], None, None
    for line in (ROOT / doc).read_text().splitlines(keepends=True):
        bare = line.strip()
        if fence is None:
            if bare.startswith("```"):
                fence = (bare[3:].strip(), [])
            elif line.startswith("#"):
                heading = line.rstrip("\n")
        elif bare == "```":
            if fence[0] == "python":
                blocks.append((heading, textwrap.dedent("".join(fence[1]))))
            fence = None
        else:
            fence[1].append(line)
    return blocks


def block(doc: str, heading: str, line: str | None = None) -> str:
    """The one ```python block of `doc` under `heading` (that holds `line`, where given)."""
    found = [code for h, code in python_blocks(doc)
             if h == heading and (line is None or line in code)]
    assert len(found) == 1, (f"{doc}: {len(found)} python blocks under {heading!r}"
                             + (f" holding {line!r}" if line else ""))
    return found[0]


def run(entry, **names) -> dict:
    """Execute `entry`'s block in the current folder with `names` defined; its scope after."""
    doc, heading, _ = entry
    scope = {"__name__": "__docs__", **names}
    code = compile(block(*entry), f"{doc} ({heading})", "exec")
    exec(code, scope)  # noqa: S102 - the docs' own code
    return scope


# The blocks, by (document, heading, a line of the block where its section holds several).
README_QUICK_START = ("README.md", "## Python quick start", None)  # tests/test_readme.py
README_PERSPECTIVE = ("README.md", "## Perspective cameras and depth discontinuities", None)
PERSPECTIVE = ("docs/perspective.md",
               "# Perspective cameras and depth discontinuities (method `dgp`)", None)
CONVENTIONS_FOV = ("docs/conventions.md", "## Perspective cameras: `K`", None)
ARCH_METHOD = ("docs/architecture.md", "## Adding a method", "OPTIONS = (")
ARCH_REGISTER = ("docs/architecture.md", "## Adding a method", "register(MethodInfo(")
METHODS_CALL = ("docs/methods.md", "# Integration methods", None)
METHODS_GRAPH = ("docs/methods.md",
                 "## The pixel graph (poisson, alpha_surface, m_estimator, regularization, "
                 "diffusion)", None)
METHODS_FOURIER = ("docs/methods.md", "## Measurements (frankot_chellappa and kernel)", None)
RECIPE_DILIGENT = ("docs/recipes.md", "## A DiLiGenT or BiNI folder", None)
RECIPE_ESTIMATOR = ("docs/recipes.md", "## A neural estimator's PNG", None)
RECIPE_BLENDER = ("docs/recipes.md", "## A Blender render as OpenEXR", None)
RECIPE_TEXTURE = ("docs/recipes.md",
                  "## A material texture (a tangent-space map of a flat surface)",
                  "imagecodecs.png_encode")
RECIPE_TWO_CHANNEL = ("docs/recipes.md",
                      "## A material texture (a tangent-space map of a flat surface)",
                      'encoding="xy"')
RECIPE_QUEAU = ("docs/recipes.md", "## A gradient field from Quéau's toolbox (`.mat`)",
                "loadmat")
RECIPE_QUEAU_H5 = ("docs/recipes.md", "## A gradient field from Quéau's toolbox (`.mat`)",
                   "h5py")
RECIPE_PHOTOMETRIC = ("docs/recipes.md", "## A photometric-stereo pipeline in Python",
                      "photometric.fit")  # tests/test_readme.py
RECIPE_WARNINGS = ("docs/recipes.md", "## A photometric-stereo pipeline in Python",
                   "FrameWarning")
RECIPE_FROM_DEPTH = ("docs/recipes.md",
                     "## A depth map from elsewhere, and a saved result, as a Surface", None)
RECIPE_CLUSTER = ("docs/recipes.md", "## A batch on a cluster", None)
RECIPE_PIECES = ("docs/recipes.md",
                 "## Parts the normals cannot place: one depth sample each", None)
FUSION_INTRO = ("docs/fusion.md", "# Fusing normals with depth", None)
FUSION_SFM = ("docs/fusion.md", "### Sparse SfM points projected with K", None)
FUSION_MONO = ("docs/fusion.md", "### A monocular depth map", None)
FUSION_MANUAL = ("docs/fusion.md", "#### Metric points, and the manual alignment", None)
FUSION_COARSE = ("docs/fusion.md", "### A depth map of lower resolution", None)
FUSION_BLURRED = ("docs/fusion.md", "## Blurred priors", None)
FUSION_SETTINGS = ("docs/fusion.md", "## Results", None)

#: Blocks run as written, here or in tests/test_readme.py (METHODS_GRAPH: -m slow).
RUN = [README_QUICK_START, README_PERSPECTIVE, PERSPECTIVE, CONVENTIONS_FOV, ARCH_METHOD,
       ARCH_REGISTER, METHODS_CALL, METHODS_GRAPH, METHODS_FOURIER, RECIPE_DILIGENT,
       RECIPE_ESTIMATOR, RECIPE_BLENDER, RECIPE_TEXTURE, RECIPE_TWO_CHANNEL, RECIPE_QUEAU,
       RECIPE_QUEAU_H5,
       RECIPE_PHOTOMETRIC, RECIPE_WARNINGS, RECIPE_FROM_DEPTH, RECIPE_PIECES, FUSION_INTRO,
       FUSION_SFM,
       FUSION_MONO, FUSION_MANUAL, FUSION_COARSE, FUSION_BLURRED, FUSION_SETTINGS]

#: Blocks that cannot run as written: the reason, and the placeholders that stop them (each
#: must still be in the block: one that is gone may have made it runnable, so move it to RUN).
#: Those here are run with their placeholders replaced, by the test named.
SKIPPED = {
    RECIPE_CLUSTER: (
        "a Dask cluster of the reader's own (its scheduler's address) whose workers share a "
        "file system (/shared): run by test_the_cluster_recipe_runs_on_a_local_client with an "
        "in-process dask.distributed Client and a temporary folder in their place",
        ('Client("tcp://head:8786")', "/shared/")),
}


def test_every_python_block_of_the_docs_is_run_or_skipped():
    entries = RUN + list(SKIPPED)
    assert len(set(entries)) == len(entries)
    for entry in entries:
        block(*entry)  # (each names exactly one block)
    unlisted = []
    for doc in DOCS:
        for heading, code in python_blocks(doc):
            n = sum(d == doc and h == heading and (line is None or line in code)
                    for d, h, line in entries)
            if n != 1:
                unlisted.append(f"{doc}, {heading!r}, {n} entries: {code[:60]!r}")
    assert not unlisted, ("give each docs block a test here, or a reason in SKIPPED:\n"
                          + "\n".join(unlisted))
    assert sum(len(python_blocks(doc)) for doc in DOCS) == len(entries)


@pytest.mark.parametrize("entry", list(SKIPPED))
def test_skipped_blocks_still_hold_what_stops_them(entry):
    reason, placeholders = SKIPPED[entry]
    code = block(*entry)
    compile(code, entry[0], "exec")  # (no syntax error, at least)
    assert reason and placeholders
    for text in placeholders:
        assert text in code, f"{text!r} is gone: does the block run now? move it to RUN"


# ---------------------------------------------------------------------------------------------
# stand-ins


def pinhole_scene(H=48, W=56, f=70.0):
    """A dome (a spherical cap, its rim 60 deg from its axis) before a tilted wall, seen by a
    pinhole camera: exact normals (facetlift frame), mask (all but a 2-pixel border), K,
    z-depth and the dome's pixels. The rim is a depth jump of about 1.5 that the discontinuity
    route cuts; no normal is edge-on (a sphere's rim, where a small image's normals go
    missing and exact prior samples tear the fusion apart)."""
    K = np.array([[f, 0, (W - 1) / 2 + 1.5], [0, f, (H - 1) / 2 - 2.0], [0, 0, 1.0]])
    r, c = np.mgrid[0:H, 0:W].astype(float)
    ray = np.stack([(c - K[0, 2]) / f, (r - K[1, 2]) / f, np.ones_like(r)], -1)  # OpenCV
    wall = np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0])
    t_wall = 10.0 * wall[2] / (ray @ wall)
    centre, radius = np.array([0.4, -0.2, 9.5]), 2.5
    a, b = (ray**2).sum(-1), -2 * (ray @ centre)
    disc = b * b - 4 * a * (centre @ centre - radius**2)
    t_dome = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
    out = (t_dome[..., None] * ray - centre) / radius  # (unit, outward)
    dome = (disc > 0) & (-out[..., 2] > np.cos(np.radians(60.0))) & (t_dome < t_wall)
    z = np.where(dome, t_dome, t_wall)
    m = np.where(dome[..., None], out, wall)
    mask = np.zeros((H, W), bool)
    mask[2:-2, 2:-2] = True
    return m * np.array([1.0, -1.0, -1.0]), mask, K, z, dome


def dataset_folder(folder: Path, normals, mask, K) -> Path:
    """A BiNI / DiLiGenT folder: 16-bit normal_map.png, mask.png, K.txt."""
    folder.mkdir(parents=True)
    io.write_normals(folder / "normal_map.png", normals)
    io.write_mask(folder / "mask.png", mask)
    np.savetxt(folder / "K.txt", K)
    return folder


# ---------------------------------------------------------------------------------------------
# a dataset folder, perspective


@pytest.mark.parametrize("entry, folder", [(README_PERSPECTIVE, "diligent/bear"),
                                           (PERSPECTIVE, "bear"),
                                           (RECIPE_DILIGENT, "diligent/bear")])
def test_a_dataset_folder_integrates_in_perspective(entry, folder, tmp_path, monkeypatch,
                                                    capsys):
    """"positive z-depth along the optical axis, median 1", "(H, W)", "back-projected with K:
    x right, y up, z toward the viewer"; the recipe prints the mean deviation in degrees."""
    n, mask, K, _, _ = pinhole_scene()
    dataset_folder(tmp_path / folder, n, mask, K)
    monkeypatch.chdir(tmp_path)
    scope = run(entry, facetlift=facetlift, io=io)
    s = scope["s"]
    depth = s.depth
    assert depth.shape == mask.shape and np.isnan(depth[~mask]).all()
    assert (depth[mask] > 0).all() and np.median(depth[mask]) == pytest.approx(1.0)
    r, c = np.nonzero(mask)
    d = depth[r, c]
    pts = s.points()
    expected = np.stack([(c - K[0, 2]) / K[0, 0] * d, -(r - K[1, 2]) / K[1, 1] * d, -d], -1)
    np.testing.assert_allclose(pts, expected, rtol=1e-9, atol=1e-12)
    if entry is RECIPE_DILIGENT:
        printed = float(capsys.readouterr().out)
        assert printed == s.info["mean_deviation"] and 0 <= printed < 5


# ---------------------------------------------------------------------------------------------
# conventions, architecture, methods


def test_a_K_from_the_field_of_view_is_K_from_fov_and_a_four_number_K_file(tmp_path,
                                                                         monkeypatch):
    """"which facetlift.camera.K_from_fov((H, W), fov) and the command line's --fov DEG form
    for you"; "integrate(..., K=K); a K file: "fx fy cx cy""."""
    H, W, fov = 36, 50, 60.0
    monkeypatch.chdir(tmp_path)
    K = run(CONVENTIONS_FOV, np=np, H=H, W=W, fov=fov)["K"]
    full = facetlift.camera.K_from_fov((H, W), fov)
    np.testing.assert_allclose(full, [[K[0], 0, K[2]], [0, K[1], K[3]], [0, 0, 1]],
                               rtol=1e-12)
    (tmp_path / "K.txt").write_text(" ".join(str(float(v)) for v in K) + "\n")
    np.testing.assert_allclose(io.read_K(tmp_path / "K.txt"), full, rtol=1e-12)
    n = np.zeros((H, W, 3))
    n[..., 2] = 1.0
    s = facetlift.integrate(n, K=K)
    np.testing.assert_array_equal(s.K, full)


def test_the_method_template_declares_its_options_and_result():
    """A method module as docs/architecture.md writes it: its relative imports, Option
    declarations and MethodResult(values=..., info=...) (run()'s body is the template's
    placeholder, `...`, and is not called)."""
    from facetlift import options
    from facetlift.methods import MethodResult

    scope = run(ARCH_METHOD, __package__="facetlift.methods",
                __name__="facetlift.methods.template")
    assert [(o.name, o.default) for o in scope["OPTIONS"]] == [("strength", 1.0),
                                                              ("mode", "fast")]
    assert all(isinstance(o, options.Option) for o in scope["OPTIONS"])
    assert list(inspect.signature(scope["run"]).parameters) == ["problem", "strength", "mode"]
    inspect.signature(MethodResult).bind(values=np.zeros(3), info={"iterations": 1})


def test_the_registry_line_names_capabilities_that_MethodInfo_has():
    """"Add one line to src/facetlift/methods/__init__.py" (such lines are there); the
    capability flags the text names are MethodInfo's."""
    from facetlift.methods import MethodInfo

    registered = []
    run(ARCH_REGISTER, register=registered.append, MethodInfo=MethodInfo)
    (info,) = registered
    assert info.name == "<name>" and info.missing and not info.perspective
    fields = {f.name for f in dataclasses.fields(MethodInfo)}
    flags = {"missing", "perspective", "discontinuities", "prior", "confidence", "prior_blur",
             "jump_map"}
    assert flags <= fields, flags - fields
    assert "register(MethodInfo(" in (ROOT / "src/facetlift/methods/__init__.py").read_text()


def test_a_method_is_called_with_its_options(tmp_path, monkeypatch):
    h = 2 / 32
    gt = synthetic.analytic("saddle", 32, pixel_size=h)
    monkeypatch.chdir(tmp_path)
    scope = run(METHODS_CALL, facetlift=facetlift, normals=gt.normals, mask=gt.mask, h=h)
    s = scope["surface"]
    assert s.info["method"] == "m_estimator"
    e = (s.depth - gt.depth)[gt.mask]
    assert np.abs(e - e.mean()).max() < 0.01 * gt.depth_range


@pytest.mark.slow
def test_the_pixel_graph_measurement_runs_and_gives_its_table(monkeypatch, capsys):
    """docs/methods.md's script as written, from the repository root (it reads tests/): its
    errors are those of the table above it (the times are the machine's)."""
    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(sys, "path", list(sys.path))
    run(METHODS_GRAPH)
    table = {"poisson": (6.8e-14, 4.6e-3, 2.3e-1), "alpha_surface": (3.7e-13, 4.6e-3, 8.7e-4),
             "m_estimator": (6.8e-14, 4.6e-3, 1.4e-1), "regularization": (1.4e-12, 7.1e-5, 2.3e-1),
             "diffusion": (1.1e-13, 4.6e-3, 1.4e-2)}
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == list(table)
    for ln in lines:
        name, *values = ln.split()
        for got, want in zip(map(float, values[:3]), table[name], strict=True):
            if want < 1e-9:  # (exact to rounding)
                assert got < 1e-9, (name, got, want)
            else:
                assert got == pytest.approx(want, rel=0.06), (name, got, want)


def test_the_fourier_measurement_runs_with_the_helpers_it_names(tmp_path, monkeypatch):
    """docs/methods.md's sketch of the Fourier / kernel measurement, with the helpers of
    tests/test_methods_fourier_kernel.py it names, for frankot_chellappa (kernel takes
    seconds at 256²): the annulus' error is the table's, 1.0e-2 (max) / 4.2e-3 (rms)."""
    fk = importlib.import_module("test_methods_fourier_kernel")
    z, p, q, h = fk.wavy(256)
    x, y = fk.centres(256, 256, h, -1.0, 1.0)
    r = np.hypot(x, y)
    mask = (r > 0.3) & (r < 0.95)
    monkeypatch.chdir(tmp_path)
    scope = run(METHODS_FOURIER, np=np, facetlift=facetlift, saddle=fk.saddle,
                normals_from_gradients=fk.normals_from_gradients, m="frankot_chellappa",
                n=fk.normals_from_gradients(p, q), mask=mask)
    e_max, e_rms = fk.err(scope["s"], z)
    span = np.ptp(z[mask])
    assert e_max / span == pytest.approx(1.0e-2, rel=0.06)
    assert e_rms / span == pytest.approx(4.2e-3, rel=0.06)


# ---------------------------------------------------------------------------------------------
# recipes


def test_a_neural_estimators_float_output_in_its_own_frame(tmp_path, monkeypatch):
    """normal_frame="-x,y,z" turns DSINE's frame into facetlift's: the same surface as the
    map in facetlift's frame, with no frame warning."""
    gt = synthetic.analytic("vase", 40)
    n = np.where(gt.mask[..., None], gt.normals, 0.0)
    io.write_normals(tmp_path / "dsine_normal.npy", n, frame="-x,y,z")
    io.write_mask(tmp_path / "mask.png", gt.mask)
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", facetlift.FrameWarning)
        scope = run(RECIPE_ESTIMATOR)
    assert np.load("dsine_normal.npy")[gt.mask][:, 0] == pytest.approx(-n[gt.mask][:, 0])
    same = facetlift.integrate(n, gt.mask)
    np.testing.assert_allclose(scope["s"].depth, same.depth, atol=1e-9 * gt.depth_range)


def test_blenders_matrix_world_is_read_as_the_camera_to_world_pose(tmp_path, monkeypatch):
    """The Blender console's line with a stand-in for bpy (Blender's own module): the file it
    writes is what --camera-to-world reads, the rotation from world to camera its transpose."""
    t = np.radians(30.0)
    pose = np.array([[np.cos(t), 0, np.sin(t), 4.0], [0, 1, 0, -2.0],
                     [-np.sin(t), 0, np.cos(t), 7.5], [0, 0, 0, 1]])
    camera = types.SimpleNamespace(matrix_world=pose.tolist())  # (a mathutils.Matrix)
    bpy = types.SimpleNamespace(context=types.SimpleNamespace(
        scene=types.SimpleNamespace(camera=camera)))
    monkeypatch.chdir(tmp_path)
    run(RECIPE_BLENDER, bpy=bpy)
    R = io.read_rotation(tmp_path / "matrix_world.txt", camera_to_world=True)
    np.testing.assert_allclose(R, pose[:3, :3].T, atol=1e-15)


def test_a_material_texture_gives_a_16_bit_height_map(tmp_path, monkeypatch, capsys,
                                                      brick_texture):
    """A tileable DirectX-frame texture: the printed range is the texture's height range in
    texels, bricks_height.png spans 0..65535, and io.write_height writes "the same"."""
    height, n = brick_texture(64, brick=(32, 16), depth=3.0)
    io.write_normals(tmp_path / "bricks_normal.png", n, frame="directx")
    monkeypatch.chdir(tmp_path)
    scope = run(RECIPE_TEXTURE)
    out = capsys.readouterr().out
    printed = float(re.fullmatch(r"height range in texels: (\S+)\n", out).group(1))
    assert printed == pytest.approx(np.ptp(height), rel=0.02)
    png = imagecodecs.png_decode((tmp_path / "bricks_height.png").read_bytes())
    assert png.dtype == np.uint16 and png.shape == height.shape
    assert png.min() == 0 and png.max() == 65535
    io.write_height(tmp_path / "via_io.png", scope["s"])
    np.testing.assert_array_equal(
        imagecodecs.png_decode((tmp_path / "via_io.png").read_bytes()), png)


def test_a_two_channel_map_integrates_like_its_three_channel_original(tmp_path, monkeypatch,
                                                                      brick_texture):
    """"an 8-bit map with B = 0 then integrates to the height of its three-channel original,
    to within the 8 bits"."""
    _, n = brick_texture(64, brick=(32, 16), depth=3.0)
    io.write_normals(tmp_path / "original.png", n, bits=8, frame="directx")
    rgb = imagecodecs.png_decode((tmp_path / "original.png").read_bytes())
    rgb[..., 2] = 0
    (tmp_path / "bricks_normal.png").write_bytes(imagecodecs.png_encode(rgb))
    monkeypatch.chdir(tmp_path)
    surface = run(RECIPE_TWO_CHANNEL, facetlift=facetlift)["surface"]
    original = facetlift.integrate(io.read_normals("original.png", frame="directx")[0])
    d = surface.depth - original.depth
    assert np.abs(d - d.mean()).max() < 0.02 * np.ptp(original.depth)


def test_a_queau_mat_file_gives_the_height_of_its_slopes(tmp_path, monkeypatch):
    """p down the rows, q along the columns, in pixel units; s.height is "the height whose
    slopes are (p, q)" (up to a constant)."""
    from scipy.io import savemat

    r, c = np.mgrid[0:30, 0:36].astype(float)
    z = 0.02 * (c - 17) ** 2 - 0.03 * (r - 14) * (c - 17) + 0.2 * r
    p, q = -0.03 * (c - 17) + 0.2, 0.04 * (c - 17) - 0.03 * (r - 14)
    mask = (r - 14) ** 2 + (c - 17) ** 2 < 13**2
    savemat(tmp_path / "vase.mat", {"p": p, "q": q, "mask": mask.astype(np.uint8)})
    monkeypatch.chdir(tmp_path)
    s = run(RECIPE_QUEAU)["s"]
    e = (s.height - z)[mask]
    assert np.isnan(s.height[~mask]).all()
    assert np.abs(e - e.mean()).max() < 1e-3 * np.ptp(z[mask])


def test_a_v73_mat_file_read_with_h5py_as_the_recipe_says(tmp_path, monkeypatch):
    """h5py gives MATLAB's arrays transposed (a review: the advice to read a v7.3 file with
    h5py gave a transposed surface, and following the layout warning hid it): the recipe's
    .T gives the height of the slopes. h5py is no dependency: a stand-in serves MATLAB's
    column-major arrays as h5py does."""
    r, c = np.mgrid[0:30, 0:36].astype(float)
    z = 0.02 * (c - 17) ** 2 - 0.03 * (r - 14) * (c - 17) + 0.2 * r
    p, q = -0.03 * (c - 17) + 0.2, 0.04 * (c - 17) - 0.03 * (r - 14)
    mask = (r - 14) ** 2 + (c - 17) ** 2 < 13**2
    stored = {"p": p.T, "q": q.T, "mask": mask.T.astype(float)}  # (as h5py reads them)

    class Dataset:
        def __init__(self, a):
            self.a = a

        def __getitem__(self, key):
            return self.a[key]

    class File(dict):
        def __init__(self, path, mode):
            assert path == "vase.mat" and mode == "r"
            super().__init__((k, Dataset(v)) for k, v in stored.items())

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setitem(sys.modules, "h5py", types.SimpleNamespace(File=File))
    monkeypatch.chdir(tmp_path)
    s = run(RECIPE_QUEAU_H5, facetlift=facetlift)["s"]
    e = (s.height - z)[mask]
    assert s.height.shape == z.shape and np.abs(e - e.mean()).max() < 1e-3 * np.ptp(z[mask])


def test_a_frame_warning_made_an_error_stops_the_job(tmp_path, monkeypatch):
    """"a wrong frame stops the job": the map in its right frame runs, the same map stored y
    down (DirectX) and read as facetlift's raises facetlift.FrameWarning."""
    n, mask, K, _, _ = pinhole_scene()
    monkeypatch.chdir(tmp_path)
    s = run(RECIPE_WARNINGS, facetlift=facetlift, n=n, mask=mask, K=K)["s"]
    assert np.isfinite(s.depth[mask]).all()
    with pytest.raises(facetlift.FrameWarning, match="y flipped"):
        run(RECIPE_WARNINGS, facetlift=facetlift, n=n * [1, -1, 1], mask=mask, K=K)


def test_one_depth_sample_per_piece(capsys):
    """The recipe's bowl: its pieces are what the jump map tints, and one sample in each
    takes the MADE from the guessed inside's 13 mm to under a millimetre, as it says."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (a few grazing normals on the rim)
        scope = run(RECIPE_PIECES)
    before, after = (float(v) for v in capsys.readouterr().out.split())
    assert np.bincount(scope["pieces"][scope["gt"].mask]).size == scope["s"].info["mesh_pieces"]
    assert before > 8.0 and after < 1.0 and np.isfinite(scope["prior"]).sum() >= 3


def test_a_depth_map_and_a_saved_result_as_surfaces(tmp_path, monkeypatch, capsys):
    """from_depth makes a Surface whose mesh saves; a run saved as .npz "loads back with its
    cuts and split mesh"; the printed deviation is metrics.angular_error's."""
    from facetlift import metrics

    n, mask, K, z, _ = pinhole_scene()
    saved = facetlift.integrate(n, mask, K=K, discontinuities=True)
    (tmp_path / "out").mkdir()
    saved.save(tmp_path / "out" / "surface.npz")
    depth_gt = np.where(mask, z, np.nan)
    monkeypatch.chdir(tmp_path)
    scope = run(RECIPE_FROM_DEPTH, depth_gt=depth_gt, mask=mask, K=K, normals=n)
    gt, s = scope["gt"], scope["s"]
    np.testing.assert_array_equal(gt.depth[mask], z[mask])
    assert (tmp_path / "truth.ply").read_bytes().startswith(b"ply")
    np.testing.assert_array_equal(s.depth, saved.depth)
    assert saved.cuts is not None and any(c.any() for c in saved.cuts)
    for a, b in [*zip(s.cuts, saved.cuts, strict=True),
                 *zip(s.to_mesh(), saved.to_mesh(), strict=True)]:
        np.testing.assert_array_equal(a, b)
    assert float(capsys.readouterr().out) == metrics.angular_error(gt, n)[0]


def test_the_cluster_recipe_runs_on_a_local_client(tmp_path, monkeypatch):
    """The cluster recipe with its placeholders replaced (SKIPPED): an in-process Client for
    the scheduler's address, a temporary folder for /shared; each map gets its record and the
    outputs named in save=."""
    distributed = pytest.importorskip("distributed")
    import dask.distributed

    code = block(*RECIPE_CLUSTER)
    for text in SKIPPED[RECIPE_CLUSTER][1]:
        assert text in code
    shared = tmp_path / "shared"
    (shared / "maps").mkdir(parents=True)
    gt = synthetic.analytic("sphere", 24)
    io.write_normals(shared / "maps" / "a.png", gt.normals, gt.mask, frame="opencv")
    (shared / "maps" / "b.png").write_bytes(b"not a png")

    class Local(distributed.Client):
        def __init__(self, address):
            assert address == "tcp://head:8786"
            super().__init__(processes=False, n_workers=1, threads_per_worker=1,
                             dashboard_address=None)

    monkeypatch.setattr(dask.distributed, "Client", Local)
    scope = {"__name__": "__docs__"}
    exec(compile(code.replace("/shared/", f"{shared}/"), "docs/recipes.md", "exec"),  # noqa: S102
         scope)
    records, failed = scope["records"], scope["failed"]
    assert len(records) == 2 and [r["status"] for r in failed] == ["error"]
    assert (shared / "out" / "a" / "depth.npy").is_file()
    assert (shared / "out" / "a" / "mesh.ply").is_file()


# ---------------------------------------------------------------------------------------------
# fusion

#: Exact samples on the dome's rim, where a facet holds both sides of the jump, are named as
#: far from the surface (docs/fusion.md, "samples on a jump's edge ... can be named too"), and
#: the smooth route bends across the jump: not what these tests are about.
FAR = "prior: .* samples lie far from the surface"


def test_fusion_with_a_perspective_prior_is_metric(tmp_path, monkeypatch):
    """docs/fusion.md's opening: with K and a prior, "the result is then metric, not
    median-normalised"; info["prior"] has "samples used (and those outside the mask, unused),
    components fixed by the prior, those that kept the gauge"."""
    n, mask, K, z, _ = pinhole_scene()
    depth = np.full(z.shape, np.nan)
    depth[::4, ::4] = z[::4, ::4]
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", FAR)
        s = run(FUSION_INTRO, facetlift=facetlift, normals=n, mask=mask, K=K, depth=depth)["s"]
    assert np.median(s.depth[mask] / z[mask]) == pytest.approx(1.0, abs=0.01)
    info = s.info["prior"]
    assert info["outside_mask"] == np.isfinite(depth[~mask]).sum() > 0
    assert 0 < info["samples"] <= np.isfinite(depth[mask]).sum()
    assert info["prior_components"] == [1] and info["gauged_components"] == []


def test_sparse_sfm_points_projected_with_K_give_metric_depth(tmp_path, monkeypatch):
    """Points in the camera frame (OpenCV), two of them outside the image and behind the
    camera: those are left out, the rest give metric depth."""
    n, mask, K, z, _ = pinhole_scene()
    H, W = mask.shape
    r, c = np.nonzero(mask)
    pick = np.random.default_rng(0).random(r.size) < 0.05
    r, c = r[pick], c[pick]
    X = np.linalg.solve(K, np.stack([c, r, np.ones_like(c)]).astype(float)).T * z[r, c, None]
    X = np.vstack([X, [[50.0, 0.0, 8.0], [0.0, 0.0, -3.0]]])
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", FAR)
        scope = run(FUSION_SFM, normals=n, mask=mask, K=K, X=X, H=H, W=W)
    assert scope["inside"].sum() == pick.sum()
    assert np.abs(scope["depth_metric"] - z)[mask].mean() < 0.01 * np.median(z)


def test_a_monocular_depth_with_an_affine_fit(tmp_path, monkeypatch):
    """A network's relative depth (the fusion benchmark's coarse prior, 8 x 8 blocks, blurred
    and upsampled, made affine; at 48 x 56 the fit, rightly, finds no scale in it):
    info["prior"]["fit"] holds "method, scale, shift, scale_error"; info["prior"]["left_out"]."""
    from facetlift.bench.fusion import coarse_prior

    n, mask, K, z, _ = pinhole_scene(96, 112, 140.0)
    truth = synthetic.GroundTruth(depth=np.where(mask, z, np.nan), normals=n, mask=mask, K=K)
    mono = 0.5 * coarse_prior(truth) + 3.0
    monkeypatch.chdir(tmp_path)
    s = run(FUSION_MONO, facetlift=facetlift, normals=n, mask=mask, K=K, mono=mono)["s"]
    fit = s.info["prior"]["fit"]
    assert {"method", "scale", "shift", "scale_error"} <= set(fit) and fit["kind"] == "affine"
    assert fit["used"] and s.info["prior"]["left_out"] is False
    assert np.isfinite(s.depth[mask]).all()


def test_the_manual_alignment_on_one_continuous_region(tmp_path, monkeypatch):
    """The wall, a region the dome's jump does not cross, eroded by 12 pixels: "Fitted to the
    normals-only depth (median 1) the result keeps its unknown scale"."""
    n, mask, K, z, dome = pinhole_scene(96, 112, 140.0)
    mono = 0.5 * z + 3.0
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", FAR)
        scope = run(FUSION_MANUAL, np=np, facetlift=facetlift, normals=n, mask=mask, K=K,
                    region=mask & ~dome, mono=mono)
    s, s0 = scope["s"], scope["s0"]
    assert scope["inner"].sum() > 500 and not (scope["inner"] & dome).any()
    assert np.median(s0.depth[mask]) == pytest.approx(1.0)
    assert np.median(s.depth[mask]) == pytest.approx(1.0, abs=0.02)


def test_a_coarse_depth_map_as_samples_at_its_footprints(tmp_path, monkeypatch):
    """A 4x coarser map (block means, known where a block lies on one side of the jump and
    inside the mask) as point samples at their footprints' centres: metric depth (the smooth
    route bends across the jump, so not exact)."""
    n, mask, K, z, dome = pinhole_scene()
    H, W = z.shape

    def blocks(a):
        return a.reshape(H // 4, 4, W // 4, 4)

    known = blocks(mask).all(axis=(1, 3)) & (blocks(dome).all(axis=(1, 3))
                                            | ~blocks(dome).any(axis=(1, 3)))
    coarse = np.where(known, blocks(z).mean(axis=(1, 3)), np.nan)
    monkeypatch.chdir(tmp_path)
    s = run(FUSION_COARSE, np=np, facetlift=facetlift, normals=n, mask=mask, K=K,
            coarse=coarse)["s"]
    assert s.info["prior"]["samples"] == known.sum()
    assert np.median(s.depth[mask] / z[mask]) == pytest.approx(1.0, abs=0.02)


def test_a_blurred_prior_reports_its_blur(tmp_path, monkeypatch):
    """info["prior_blur"]: "{'sigma': 8.9, 'updates': ..., 'mismatch': ..., 'converged': True,
    ...}" (8.9 about 1.1 times the 8x upsampling's factor, since an audit: 4 left the bear
    worse than without the prior)."""
    from scipy import ndimage

    n, mask, K, z, _ = pinhole_scene()
    H, W = z.shape
    coarse = z.reshape(H // 8, 8, W // 8, 8).mean(axis=(1, 3))
    depth_up = ndimage.zoom(coarse, 8, order=1, mode="nearest", grid_mode=True)
    assert depth_up.shape == (H, W)
    monkeypatch.chdir(tmp_path)
    s = run(FUSION_BLURRED, facetlift=facetlift, normals=n, mask=mask, K=K,
            depth_up=depth_up)["s"]
    blur = s.info["prior_blur"]
    assert {"sigma", "updates", "mismatch", "converged"} <= set(blur)
    assert blur["sigma"] == 8.9 and blur["converged"] is True


def test_the_fusion_results_settings_are_bench_settings(tmp_path, monkeypatch):
    """The settings the results were measured with, and those the comment names, are
    facetlift.bench's (Settings fields; models=, run_bench's)."""
    from facetlift.bench import Settings, run_bench

    monkeypatch.chdir(tmp_path)
    s = run(FUSION_SETTINGS, Settings=Settings)["s"]
    assert s.disc_views == ("front",) and s.disc_wide_views == ()
    fields = {f.name for f in dataclasses.fields(Settings)}
    assert {"disc_views", "disc_wide_views", "disc_meshes", "disc_analytic"} <= fields
    assert "models" in inspect.signature(run_bench).parameters
