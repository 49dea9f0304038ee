"""The command line through main([...]): files, exit codes, messages."""

import functools
import importlib
import json
import re

import numpy as np
import pytest

import facetlift
from facetlift import io, linalg
from facetlift.cli import main
from facetlift.methods import REGISTRY


def write_input(folder, H=20, W=26, *, alpha=False, name="normals.png"):
    """A 16-bit normal map of a tilted roof with a ridge, and a mask with a hole (as a
    dataset folder's files with ``name="normal_map.png"``)."""
    r, c = np.mgrid[0:H, 0:W] + 0.5
    p = np.where(c < W / 2, 0.4, -0.4)
    q = np.full((H, W), 0.1)
    n = facetlift.normals_from_gradients(p, q)
    mask = np.ones((H, W), bool)
    mask[6:10, 4:8] = False
    # (not normal_map.png: a map of that name beside mask.png is warned about as a dataset
    # folder's, integrated without its mask; and a mask.png beside any other map is warned
    # about as unread: the mask of such a map lies in a folder of its own)
    npath = io.write_normals(folder / name, n, mask if alpha else None)
    where = folder if name == "normal_map.png" else folder / "masks"
    where.mkdir(exist_ok=True)
    mpath = io.write_mask(where / "mask.png", mask)
    return npath, mpath, mask


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_integrate_end_to_end(tmp_path, capsys):
    npath, mpath, mask = write_input(tmp_path)
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "integrate", npath, "--mask", mpath, "-o", out)
    assert code == 0, err
    for name in ("depth.npy", "mesh.ply", "preview.png"):
        assert (out / name).is_file() and f"wrote {out / name}" in stdout
    assert "20x26 pixels" in stdout and "method dgp" in stdout
    n, _ = io.read_normals(npath)
    expected = facetlift.integrate(n, mask)
    depth = np.load(out / "depth.npy")
    np.testing.assert_array_equal(np.isnan(depth), ~mask)
    np.testing.assert_allclose(depth[mask], expected.depth[mask], atol=1e-9)


def test_a_map_inside_a_dataset_folder_names_the_folder_files_it_leaves_unread(tmp_path,
                                                                               capsys):
    """An audit: `integrate bear/normal_map.png` ran orthographically on the valid normals,
    without the folder's K.txt and mask.png, and said nothing; the folder itself reads them."""
    npath, mpath, mask = write_input(tmp_path, name="normal_map.png")
    (tmp_path / "K.txt").write_text("600 0 13\n0 600 10\n0 0 1\n")
    code, _, err = run(capsys, "integrate", npath, "-s", "npy", "-o", tmp_path / "a")
    assert code == 0, err
    assert re.search(r"lies in a dataset folder whose K.txt .* and mask.png .* does not read",
                     err) and f"facetlift integrate {tmp_path}" in err
    code, out, err = run(capsys, "integrate", npath, "--K", tmp_path / "K.txt", "--mask", mpath,
                         "-s", "npy", "-o", tmp_path / "b")
    assert code == 0 and "dataset folder" not in err
    # (the summary names the camera's file, not "K", a user's check)
    assert f"perspective (--K {tmp_path / 'K.txt'})" in out + err, out + err
    code, _, err = run(capsys, "integrate", npath, "--orthographic", "-s", "npy", "-o",
                       tmp_path / "c")  # (orthographic asked for: only the mask is named)
    assert code == 0 and "mask.png (its mask)" in err and "K.txt (its camera" not in err
    code, _, err = run(capsys, "integrate", tmp_path, "-s", "npy", "-o", tmp_path / "d")
    assert code == 0 and "dataset folder" not in err


def test_default_outdir_and_alpha_mask(tmp_path, capsys):
    npath, _, mask = write_input(tmp_path, alpha=True)
    code, stdout, err = run(capsys, "integrate", npath, "--save", "npz")
    assert code == 0, err
    out = tmp_path / "normals_facetlift"
    assert [p.name for p in out.iterdir()] == ["surface.npz"]
    assert "mask: alpha channel" in stdout
    with np.load(out / "surface.npz") as z:
        np.testing.assert_array_equal(z["mask"], mask)


def test_an_alpha_mask_in_several_components_is_named_in_the_summary(tmp_path, capsys):
    """A second audit: a height packed in the alpha (0 in the grooves) split the mask into one
    component per brick, each integrated at mean depth 0 (12.5 % RMS against 0.5 % with a
    mask), and the summary said "mask: alpha channel" alone. Where the alpha makes a mask of
    several components the summary counts them; one component, or a --mask, as before."""
    import imagecodecs

    px = np.zeros((32, 32, 4), np.uint8)
    px[..., :3] = (128, 128, 255)
    px[2:14, 2:14, 3] = px[18:30, 2:14, 3] = px[2:30, 18:30, 3] = 255
    (tmp_path / "three.png").write_bytes(imagecodecs.png_encode(px))
    px[..., 3] = 0
    px[2:30, 2:30, 3] = 255
    (tmp_path / "one.png").write_bytes(imagecodecs.png_encode(px))
    code, out, err = run(capsys, "integrate", tmp_path / "three.png", "-s", "npy",
                         "-o", tmp_path / "a")
    assert code == 0, err
    # (a 0/255 alpha of separate pieces, an atlas's, is a mask: counted, no question; a
    # review)
    assert "(mask: alpha channel, 3 components integrated apart, their depths unrelated)" in out
    code, out, err = run(capsys, "integrate", tmp_path / "one.png", "-s", "npy",
                         "-o", tmp_path / "b")
    assert code == 0 and "(mask: alpha channel)" in out
    io.write_mask(tmp_path / "m.png", px[..., 3] > 0)
    code, out, err = run(capsys, "integrate", tmp_path / "three.png", "--mask",
                         tmp_path / "m.png", "-s", "npy", "-o", tmp_path / "c")
    assert code == 0 and "components" not in out
    # an alpha with a height's levels (the alpha check warned): asked
    r, c = np.mgrid[0:32, 0:32]
    px[..., 3] = np.where((r % 16 < 2) | (c % 16 < 2), 0,
                          np.clip(np.minimum(r % 16, c % 16) * 40, 0, 255)).astype(np.uint8)
    (tmp_path / "height.png").write_bytes(imagecodecs.png_encode(px))
    code, out, err = run(capsys, "integrate", tmp_path / "height.png", "-s", "npy",
                         "-o", tmp_path / "d")
    assert code == 0 and "its alpha channel holds" in err, err
    assert "their depths unrelated: a height packed in the alpha? --mask replaces it" in out


def test_default_outdir_is_beside_a_link_not_its_target(tmp_path, capsys):
    """The default <input>_facetlift/ was made beside a symbolic link's target (a shared
    dataset's folder) instead of beside the name the user gave."""
    real, view = tmp_path / "real", tmp_path / "view"
    real.mkdir()
    view.mkdir()
    npath, _, _ = write_input(real, name="normal_map.png")
    (view / "data").symlink_to(real, target_is_directory=True)
    (view / "n.png").symlink_to(npath)
    for given, out in ((view / "data", view / "data_facetlift"),
                       (view / "n.png", view / "n_facetlift")):
        code, _, err = run(capsys, "integrate", given, "-s", "npy")
        assert code == 0, err
        assert (out / "depth.npy").is_file()
    assert not list(tmp_path.glob("*_facetlift")) and not list(real.glob("*_facetlift"))


def test_dataset_folder_and_formats(tmp_path, capsys):
    write_input(tmp_path, name="normal_map.png")
    out = tmp_path / "o"
    code, _, err = run(capsys, "integrate", tmp_path, "-o", out, "-s", "exr", "-s", "tif",
                       "--format", "obj", "--triangles", "--pixel-size", "0.5")
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["depth.exr", "depth.tif", "mesh.obj"]
    assert "f " in (out / "mesh.obj").read_text() and len(
        (out / "mesh.obj").read_text().split("\nf ")[1].split()) == 3


def test_stl_output(tmp_path, capsys):
    """-s stl writes mesh.stl, named in the output and the record: the PLY's mesh as two
    triangles per pixel, facing the viewer; --quads is for the others (said where alone)."""
    import meshio

    npath, mpath, mask = write_input(tmp_path)
    out = tmp_path / "o"
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", out, "-s", "stl",
                            "-s", "ply", "--quads")
    assert code == 0 and err == "", err
    assert f"wrote {out / 'mesh.stl'}" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["mesh.ply", "mesh.stl"]
    stl, ply = (meshio.read(out / n) for n in ("mesh.stl", "mesh.ply"))
    assert ply.cells[0].type == "quad" and len(ply.cells[0].data) == mask.sum()
    assert stl.cells[0].type == "triangle" and len(stl.cells[0].data) == 2 * mask.sum()
    np.testing.assert_allclose(np.unique(stl.points, axis=0),
                               np.unique(np.float32(ply.points), axis=0))
    rec = np.fromfile(out / "mesh.stl", [("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")],
                      offset=84)
    assert (rec["n"][:, 2] > 0).all()
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "j",
                            "-s", "stl", "--quads", "--json")
    assert code == 0 and json.loads(stdout)["outputs"] == {"stl": str(tmp_path / "j" /
                                                                      "mesh.stl")}
    assert "quad faces (--quads; `triangles` False) apply to the ply and obj meshes" in err
    code, _, err = run(capsys, "integrate", npath, "-o", tmp_path / "mesh.stl", "-s", "stl")
    assert code == 1 and re.search(r"-o .*mesh -s stl to write .*mesh/mesh\.stl", err), err
    code, _, err = run(capsys, "batch", npath, "-m", mpath, "-o", tmp_path / "b", "-s", "stl",
                       "--workers", "1")
    assert code == 0 and (tmp_path / "b" / "normals" / "mesh.stl").read_bytes() == (
        out / "mesh.stl").read_bytes(), err


def test_json_output(tmp_path, capsys):
    npath, mpath, mask = write_input(tmp_path)
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "j",
                            "--json", "--solver", "iterative", "--tol", "1e-6")
    assert code == 0, err
    rec = json.loads(stdout)
    assert rec["shape"] == [20, 26] and rec["facets"] == int(mask.sum())
    assert rec["info"]["method"] == "dgp" and rec["info"]["solver"] == "iterative"
    assert rec["info"]["converged"] is True and rec["info"]["iterations"] >= 1
    assert set(rec["outputs"]) == {"npy", "ply", "png"}
    assert all(tmp_path.joinpath(p).is_file() for p in rec["outputs"].values())
    assert rec["timings"]["total"] >= rec["timings"]["integrate"] > 0
    assert rec["warnings"] == [] and rec["hints"] == []


def test_json_output_carries_the_warnings_and_hints(tmp_path, capsys):
    """An audit: the frame warning went to stderr only, while batch records keep warnings;
    a script reading --json can act on them now (with the command line's flag names)."""
    npath, mpath, mask = write_input(tmp_path)
    n, _ = io.read_normals(npath)
    n[2, 3] *= -1.0  # (two normals facing away: missing samples, warned about)
    n[15, 20] *= -1.0
    npath = io.write_normals(tmp_path / "away.png", n)
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "j",
                            "--json")
    assert code == 0, err
    rec = json.loads(stdout)
    printed = [line[len("facetlift: warning: "):] for line in err.splitlines()
               if line.startswith("facetlift: warning: ")]
    assert rec["warnings"] == printed and len(printed) >= 1
    assert any("2 normal(s) inside the mask cannot be used" in w for w in rec["warnings"])
    assert rec["hints"] == [line[len("hint: "):] for line in err.splitlines()
                            if line.startswith("hint: ")]
    # a map whose smooth surface bends across a jump gets the hint, in the object too
    gt = facetlift.synthetic.analytic("occluder", 64)
    np.save(tmp_path / "occ.npy", gt.normals)
    code, stdout, err = run(capsys, "integrate", tmp_path / "occ.npy", "-o", tmp_path / "k",
                            "--json", "-s", "npy")
    assert code == 0, err
    rec = json.loads(stdout)
    said = [line[len("hint: "):] for line in err.splitlines() if line.startswith("hint: ")]
    assert len(said) == 1 and rec["hints"] == said and "--discontinuities" in said[0]


def test_options_are_forwarded(tmp_path, capsys, monkeypatch):
    npath, mpath, _ = write_input(tmp_path)
    K = np.array([[50.0, 0, 13], [0, 50, 10], [0, 0, 1]])
    np.savetxt(tmp_path / "K.txt", K)
    seen = {}

    def spy(normals, mask=None, **kw):
        seen.update(kw)
        raise ValueError("spy stops here")

    monkeypatch.setattr(facetlift, "integrate", spy)
    code, _, err = run(capsys, "integrate", npath, "--K", tmp_path / "K.txt", "--max-iter", 7,
                       "--option", "flat_weight=1e-6", "--option", "mean-subtraction=false",
                       "--option", "name=plain", "--backend", "superlu", "--y-down")
    assert code == 1 and "spy stops here" in err
    np.testing.assert_array_equal(seen.pop("K"), K)
    assert seen == {"method": "dgp", "pixel_size": 1.0, "backfacing": "missing", "max_iter": 7,
                    "outlier_eps": None, "prior": None, "prior_weight": None, "confidence": None,
                    "prior_blur": None, "normal_rotation": None,
                    "flat_weight": 1e-6, "mean_subtraction": False, "name": "plain",
                    "backend": "superlu"}


def test_K_typed_inline_is_forwarded(tmp_path, capsys, monkeypatch):
    """A fresh user's review: --K "3772 3759 305.9 255.1" said "File ... does not exist".
    Four numbers fx fy cx cy, or the matrix's nine row by row, spaces or commas, are taken
    where no such file exists; other text is still a missing file, and numbers that are no
    valid K are refused naming --K."""
    npath, _, _ = write_input(tmp_path)
    K = np.array([[50.0, 0, 13], [0, 52, 10], [0, 0, 1]])
    seen = {}

    def spy(normals, mask=None, **kw):
        seen.update(kw)
        raise ValueError("spy stops here")

    monkeypatch.setattr(facetlift, "integrate", spy)
    for typed in ("50 52 13 10", "50, 52, 13, 10", " 50,0,13, 0,52,10, 0,0,1 ",
                  "50 0 13 0 52 10 0 0 1"):
        seen.clear()
        code, _, err = run(capsys, "integrate", npath, "--K", typed)
        assert code == 1 and "spy stops here" in err, (typed, err)
        np.testing.assert_array_equal(seen["K"], K)
    monkeypatch.undo()
    code, _, err = run(capsys, "integrate", npath, "--K", "50 52 13")  # (named as such, not
    # "File '50 52 13' does not exist": an audit)
    assert code == 1 and "--K: '50 52 13' (typed inline) holds 3 numbers; give four" in err
    code, _, err = run(capsys, "integrate", npath, "--K", "fx 52 13 10")
    assert code == 1 and "does not exist" in err
    code, _, err = run(capsys, "integrate", npath, "--K", "50 -52 13 10", "-o", tmp_path / "o")
    assert code == 1 and "--K: '50 -52 13 10' (typed inline): --K must have positive focal" in err
    # (a file of that name is read as the file)
    (tmp_path / "50 52 13 10").write_text("60 62 13 10\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(facetlift, "integrate", spy)
    assert run(capsys, "integrate", npath, "--K", "50 52 13 10")[0] == 1
    assert seen["K"][0, 0] == 60
    monkeypatch.undo()
    # info and evaluate take it too
    code, out, err = run(capsys, "info", npath, "--K", "50 52 13 10", "--json")
    assert json.loads(out)["K"] == K.tolist(), err
    depth = tmp_path / "depth.npy"
    np.save(depth, np.full((20, 26), 2.0))
    code, out, err = run(capsys, "evaluate", depth, "--gt", depth, "--K", "50 52 13 10")
    assert code == 0 and "perspective (--K 50 52 13 10)" in out, err


def test_K_typed_inline_is_parsed_once(tmp_path, capsys, monkeypatch):
    """--K "fx fy cx cy" was parsed and checked twice, by the option's type and again when the
    job read its camera (once more per item in a batch): now once, kept with the text
    (io.dataset.InlineK), so it costs the checks of a K file with the same numbers (one read
    per item in a batch, the text parsed once for all); the job still holds the text, and a
    pickled copy (a batch worker's) its matrix."""
    import pickle

    from facetlift import camera
    from facetlift.io.dataset import InlineK, inline_value

    npath, _, _ = write_input(tmp_path)
    (tmp_path / "K.txt").write_text("50 52 13 10\n")
    folder = tmp_path / "maps"
    folder.mkdir()
    for name in ("a.png", "b.png"):
        (folder / name).write_bytes(npath.read_bytes())
    calls = []
    check_K = camera.check_K
    monkeypatch.setattr(camera, "check_K", lambda *a, **k: calls.append(1) or check_K(*a, **k))
    counts = {}
    for K in ("50 52 13 10", tmp_path / "K.txt"):
        for command in (("integrate", npath, "-o", tmp_path / f"o{len(counts)}"),
                        ("batch", folder, "-o", tmp_path / f"b{len(counts)}", "--workers",
                         1),  # (in this process, where check_K is counted)
                        ("info", npath)):
            calls.clear()
            code, _, err = run(capsys, *command, "--K", K)
            assert code == 0, err
            counts[command[0], isinstance(K, str)] = len(calls)
    for command, fewer in (("integrate", 0), ("info", 0), ("batch", 1)):
        # (a batch of two reads the file for each item, the text once for both)
        assert counts[command, True] == counts[command, False] - fewer, counts
    typed = inline_value("50 52 13 10")
    assert isinstance(typed, InlineK) and typed == "50 52 13 10" and inline_value(typed) is typed
    again = pickle.loads(pickle.dumps(typed))
    assert again == typed and np.array_equal(again.K, typed.K)


def test_discontinuities_forwarded_or_refused(tmp_path, capsys, monkeypatch):
    npath, _, _ = write_input(tmp_path)
    without = [k for k, v in REGISTRY.items() if not v.discontinuities]
    if without:
        code, _, err = run(capsys, "integrate", npath, "--method", without[0],
                           "--discontinuities")
        assert code == 1 and "does not handle depth discontinuities" in err
    able = [k for k, v in REGISTRY.items() if v.discontinuities]
    if able:
        seen = {}

        def spy(normals, mask=None, **kw):
            seen.update(kw)
            raise ValueError("spy")

        monkeypatch.setattr(facetlift, "integrate", spy)
        assert run(capsys, "integrate", npath, "--method", able[0], "--discontinuities")[0] == 1
        assert seen["discontinuities"] is True


def test_methods_lists_registry(capsys):
    code, stdout, _ = run(capsys, "methods")
    assert code == 0
    assert stdout.startswith("dgp\n") and "solver='direct'" in stdout
    for name in REGISTRY:
        assert f"\n{name}" in "\n" + stdout
    code, stdout, _ = run(capsys, "methods", "--json")
    recs = {r["name"]: r for r in json.loads(stdout)}
    assert recs["dgp"]["available"] and recs["dgp"]["options"]["max_iter"] == 5000
    assert set(recs) == set(REGISTRY)


def test_version_and_help(capsys):
    code, stdout, _ = run(capsys, "--version")
    assert code == 0 and facetlift.__version__ in stdout
    code, stdout, _ = run(capsys, "integrate", "--help")
    assert code == 0 and "Examples:" in stdout and "--mask" in stdout
    code, stdout, _ = run(capsys)
    assert code == 0 and "Usage: facetlift" in stdout and "integrate" in stdout
    # __version__ and pyproject.toml's version are kept by hand: they agree (a review)
    from pathlib import Path

    tomllib = pytest.importorskip("tomllib")  # (Python 3.11)
    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml")
                            .read_text())["project"]
    assert project["version"] == facetlift.__version__


def _one_line_error(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("facetlift: error:"), err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize(
    "make_args, message",
    [
        (lambda t, n, m: [t / "missing.png"], "does not exist"),
        (lambda t, n, m: [n, "--method", "nope"], r"--method must be one of"),
        (lambda t, n, m: [n, "--option", "nope=1"], r"unknown option\(s\) \[--option nope\]"),
        (lambda t, n, m: [n, "--option", "novalue"], "expected KEY=VALUE"),
        (lambda t, n, m: [n, "--bogus"], "No such option"),
        (lambda t, n, m: [n, "--solver", "magic"],
         "--solver must be one of 'direct', 'iterative'; got 'magic'"),
        (lambda t, n, m: [n, "--pixel-size", "-1"], "--pixel-size must be a positive"),
        (lambda t, n, m: [n, "-s", "jpg"], "Invalid value for '-s'"),
        # (another case, a misspelling: the name meant, a review)
        (lambda t, n, m: [n, "--method", "DGP"], r"got 'DGP'; did you mean 'dgp'\? \(method "
         r"names are lower case\)"),
        (lambda t, n, m: [n, "--method", "frankot-chellappa"],
         r"did you mean 'frankot_chellappa'\?"),
        # (-o out.npy made a folder named out.npy, a review)
        (lambda t, n, m: [n, "-o", t / "out.npy"], r"'-o' / '--out': '.*out\.npy' ends like a "
         r"file name, but -o is the output folder.*no option names a single output file.*"
         r"e\.g\. -o .*out -s npy to write .*out/depth\.npy"),
        (lambda t, n, m: [n, "-o", t / "mesh.PLY", "-s", "ply"], r"-o .*mesh -s ply to write "
         r".*mesh/mesh\.ply"),
    ],
)
def test_bad_input_exits_1(tmp_path, capsys, make_args, message):
    npath, mpath, _ = write_input(tmp_path)
    code, _, err = run(capsys, "integrate", *make_args(tmp_path, npath, mpath))
    assert code == 1
    assert re.search(message, _one_line_error(err))
    assert not (tmp_path / "out.npy").exists() and not (tmp_path / "mesh.PLY").exists()


def test_an_existing_folder_with_a_file_ending_is_an_output_folder(tmp_path, capsys):
    """-o refuses a name ending like a file only where no such folder exists (a folder the
    user made so, or an earlier run's, is written into as before); batch's -o alike."""
    npath, mpath, _ = write_input(tmp_path)
    (tmp_path / "scan.tif").mkdir()
    code, _, err = run(capsys, "integrate", npath, "--mask", mpath, "-o", tmp_path / "scan.tif")
    assert code == 0 and (tmp_path / "scan.tif" / "depth.npy").is_file(), err
    code, _, err = run(capsys, "batch", npath, "-o", tmp_path / "all.npz")
    line = _one_line_error(err)
    assert code == 1 and "-o is the output folder" in line
    # (batch writes one folder per item: told so, a review)
    assert re.search(r"-o .*all -s npz to write .*all/<item>/surface\.npz for every item", line)


@pytest.mark.parametrize("flags, message", [
    (["--prior-weight", "-1"], "--prior-weight must be a finite number >= 0; got -1.0"),
    (["--prior-weight", "nan"], "--prior-weight must be a finite number >= 0; got nan"),
    (["--prior-blur", "-2"], "--prior-blur must be a finite number of pixels >= 0"),
    (["--prior-blur", "0.2"], "--prior-blur below half a pixel is no blur"),
])
def test_prior_numbers_are_refused_before_the_input_is_read(tmp_path, capsys, flags, message):
    """--prior-weight -1 was refused after the map was read and its warnings printed (a
    review): the prior's numbers are checked by value first, the one line of the error
    alone."""
    n = facetlift.normals_from_gradients(np.full((12, 14), 0.2), np.zeros((12, 14)))
    n[4, 4] = [1.0, 0.0, 0.0]  # edge-on: a warning once the map is read
    np.save(tmp_path / "n.npy", n)
    np.save(tmp_path / "prior.npy", np.full((12, 14), 5.0))
    code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "--prior",
                       tmp_path / "prior.npy", *flags, "-o", tmp_path / "out")
    assert code == 1 and message in _one_line_error(err)


def test_corrupt_png_exits_1(tmp_path, capsys):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    code, _, err = run(capsys, "integrate", bad)
    assert code == 1 and "bad.png is not a readable PNG" in _one_line_error(err)


def test_mask_of_other_size_exits_1(tmp_path, capsys):
    npath, _, _ = write_input(tmp_path)
    io.write_mask(tmp_path / "small.png", np.ones((5, 5)))
    code, _, err = run(capsys, "integrate", npath, "--mask", tmp_path / "small.png")
    assert code == 1 and "size 5x5" in _one_line_error(err)
    assert not (tmp_path / "normals_facetlift").exists()


def test_backfacing_is_a_warning_or_on_request_an_error(tmp_path, capsys):
    n = np.zeros((6, 6, 3))
    n[..., 2] = 1
    n[2, 2] = (0.6, 0, -0.8)
    io.write_normals(tmp_path / "n.npy", n)
    code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "-o", tmp_path / "a")
    assert code == 0, err
    assert "facetlift: warning:" in err and "1 back-facing" in err and "(row 2, col 2)" in err
    code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "-o", tmp_path / "b",
                       "--backfacing", "error")
    assert code == 1 and "back-facing" in err and "--backfacing missing" in _one_line_error(err)


def test_solver_error_exits_2(tmp_path, capsys, monkeypatch):
    npath, _, _ = write_input(tmp_path)

    def fail(*a, **k):
        raise linalg.SolverError("matrix is singular")

    monkeypatch.setattr(importlib.import_module("facetlift.methods.dgp"), "run", fail)
    code, _, err = run(capsys, "integrate", npath, "-o", tmp_path / "o")
    assert code == 2 and "solver failed: matrix is singular" in _one_line_error(err)
    assert not (tmp_path / "o").exists()


def test_no_convergence_exits_2_after_writing(tmp_path, capsys):
    npath, mpath, _ = write_input(tmp_path)
    out = tmp_path / "o"
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", out, "--solver",
                            "iterative", "--max-iter", "1", "--tol", "0", "--no-progress")
    assert code == 2
    assert "did not converge in 1 iterations" in err and "Traceback" not in err
    assert "facetlift: warning:" in err  # the method's own warning, one line
    assert (out / "depth.npy").is_file() and "not converged" in stdout
    # --json: the one object says so too (only converged false did, a user's check)
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "j",
                            "--solver", "iterative", "--max-iter", "1", "--tol", "0",
                            "--no-progress", "--json")
    rec = json.loads(stdout)
    assert code == 2 and rec["status"] == "solver_error" and rec["exit_code"] == 2
    code, stdout, _ = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "k",
                          "--json")
    rec = json.loads(stdout)
    assert code == 0 and rec["status"] == "ok" and rec["exit_code"] == 0


@pytest.mark.parametrize("flag, solver, shown", [
    ("--progress", "iterative", True), ("--no-progress", "iterative", False),
    ("--progress", "direct", True), ("--no-progress", "direct", False),
])
def test_progress_bar_on_stderr(tmp_path, capsys, monkeypatch, flag, solver, shown):
    """The paper's loop reports its iterations, the direct route its CG iterations (the mask
    has a hole: the facet-CG route)."""
    npath, mpath, _ = write_input(tmp_path)
    dgp = importlib.import_module("facetlift.methods.dgp")
    real, calls = dgp.run, []

    @functools.wraps(real)  # keeps the option signature that integrate() checks against
    def spy(problem, **kw):
        if kw.get("progress") is not None:
            bar_update = kw["progress"]

            def progress(it, dev):
                calls.append((it, dev))
                bar_update(it, dev)

            kw["progress"] = progress
        return real(problem, **kw)

    monkeypatch.setattr(dgp, "run", spy)
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "o",
                            "--solver", solver, flag, "--json")
    assert code == 0, err
    json.loads(stdout)  # stdout stays clean JSON
    assert ("integrating" in err) == shown
    assert bool(calls) == shown
    if shown:
        info = json.loads(stdout)["info"]
        its = info["iterations"] if solver == "iterative" else info["cg_iterations"]
        assert calls[0][0] == 1 and calls[-1][0] == its
        assert [it for it, _ in calls] == list(range(1, its + 1))


def test_verbose_logs_to_stderr_for_one_run(tmp_path, capsys):
    npath, _, _ = write_input(tmp_path)
    code, stdout, err = run(capsys, "-v", "integrate", npath, "-o", tmp_path / "a")
    assert code == 0 and "facetlift: dgp:" in err and "facetlift: dgp:" not in stdout
    # readable key=value pairs, not a raw dict
    line = next(ln for ln in err.splitlines() if "facetlift: dgp:" in ln)
    assert "{" not in line and " iterations=" in line and "seconds.total=" in line
    code, _, err = run(capsys, "integrate", npath, "-o", tmp_path / "b")
    assert code == 0 and err == ""
    # a parallel batch's items log in their worker processes: -v says so (it printed
    # nothing and said nothing of it, a CLI audit); with --workers 1 their lines show
    code, _, err = run(capsys, "-v", "batch", npath, "-o", tmp_path / "c", "--workers", "2",
                       "--no-progress")
    assert code == 0 and "give --workers 1 to see their lines" in err, err
    code, _, err = run(capsys, "-v", "batch", npath, "-o", tmp_path / "d", "--workers", "1",
                       "--no-progress")
    assert code == 0 and "worker processes" not in err and "facetlift: dgp:" in err, err


def test_console_script_entry_point():
    from importlib.metadata import entry_points

    from facetlift import _entry

    (ep,) = [e for e in entry_points(group="console_scripts") if e.name == "facetlift"]
    assert ep.load() is _entry.main  # (which runs cli.main, catching an early Ctrl-C)
    assert _entry.main.__module__ == "facetlift._entry" and callable(main)


def test_runs_as_a_program(tmp_path):
    import subprocess
    import sys

    missing = str(tmp_path / "x.png")
    proc = subprocess.run([sys.executable, "-m", "facetlift.cli", "integrate", missing],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and proc.stderr.startswith("facetlift: error:")
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("method, extra", [
    ("m_estimator", ()), ("alpha_surface", ()), ("kernel", ()),
    ("regularization", ("--option", "prior=edge_preserving")),
    ("diffusion", ("--backend", "amg")), ("poisson", ("--backend", "amg")),
])
def test_comparison_methods_show_progress(tmp_path, capsys, method, extra):
    """Reweightings, growing rounds, tile groups and multigrid-CG iterations reach the bar;
    --no-progress keeps stderr quiet."""
    npath, mpath, _ = write_input(tmp_path)
    for flag, shown in (("--progress", True), ("--no-progress", False)):
        code, _, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / flag,
                           "--method", method, *extra, flag, "-s", "npy")
        assert code == 0, err
        assert ("integrating" in err) == shown, err


def test_a_point_cloud_output(tmp_path):
    """-s points: a PLY point cloud, one point per mask pixel (a LiDAR user found no point
    cloud output), with the input normals; a missing normal gets (0, 0, 0)."""
    import meshio

    r, c = np.indices((20, 24))
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 4), 0.1 * np.sin(r / 5))
    n[4, 5] = np.nan
    np.save(tmp_path / "n.npy", n)
    mask = np.ones((20, 24), bool)
    mask[:, :3] = False
    facetlift.io.write_mask(tmp_path / "m.png", mask)
    assert main(["integrate", str(tmp_path / "n.npy"), "--mask", str(tmp_path / "m.png"),
                 "-s", "points", "-o", str(tmp_path / "o")]) == 0
    cloud = meshio.read(tmp_path / "o" / "points.ply")
    s = facetlift.integrate(n, mask)  # (a NaN normal is a missing sample: no warning)
    np.testing.assert_allclose(cloud.points, s.points(), rtol=1e-9, atol=1e-9)
    normals = np.stack([cloud.point_data[k] for k in ("nx", "ny", "nz")], axis=1)
    rr, cc = np.nonzero(mask)
    missing = (rr == 4) & (cc == 5)
    assert (normals[missing] == 0).all()
    np.testing.assert_allclose(normals[~missing], n[rr, cc][~missing], atol=1e-6)


@pytest.mark.parametrize("frame, axes", [("opencv", (1, -1, -1)), ("directx", (1, -1, 1)),
                                          ("z,x,y", None)])
def test_output_frame_for_the_mesh_and_the_point_cloud(tmp_path, frame, axes):
    """--output-frame opencv: the mesh and the points in the camera frame of OpenCV and COLMAP
    (a user fusing them with an SfM cloud flipped y and z by hand); a mirrored frame
    (directx) lists the faces the other way round, so that they still face the viewer."""
    import meshio

    from facetlift import frames

    r, c = np.indices((12, 14))
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 4), 0.1 * np.sin(r / 5))
    np.save(tmp_path / "n.npy", n)
    K = tmp_path / "K.txt"
    np.savetxt(K, [[40.0, 0, 6.5], [0, 40.0, 5.5], [0, 0, 1]])
    for out, extra in (("a", []), ("b", ["--output-frame", frame])):
        assert main(["integrate", str(tmp_path / "n.npy"), "--K", str(K), "-s", "ply", "-s",
                     "points", "-s", "npy", "-o", str(tmp_path / out)]
                    + extra) == 0
    a, b = (meshio.read(tmp_path / o / "mesh.ply") for o in "ab")
    pa, pb = (meshio.read(tmp_path / o / "points.ply") for o in "ab")
    if axes is not None:
        np.testing.assert_allclose(b.points, a.points * axes, rtol=1e-12)
        np.testing.assert_allclose(pb.points, pa.points * axes, rtol=1e-12)
    np.testing.assert_allclose(b.points, frames.from_facetlift(a.points, frame), rtol=1e-12)
    na, nb = (np.stack([p.point_data[k] for k in ("nx", "ny", "nz")], axis=1) for p in (pa, pb))
    np.testing.assert_allclose(nb, frames.from_facetlift(na, frame), atol=1e-6)
    np.testing.assert_array_equal(np.load(tmp_path / "b" / "depth.npy"),
                                  np.load(tmp_path / "a" / "depth.npy"))

    def facing(mesh):  # (each face's normal, in the mesh's own frame)
        q = mesh.cells_dict["quad"]
        v = mesh.points
        return np.cross(v[q[:, 1]] - v[q[:, 0]], v[q[:, 2]] - v[q[:, 0]])

    viewer = frames.from_facetlift(np.array([0.0, 0.0, 1.0]), frame)  # (toward the viewer)
    assert (facing(a) @ [0.0, 0.0, 1.0] > 0).all() and (facing(b) @ viewer > 0).all()
    flipped = frames.mirrors(frame)
    assert flipped == (frame == "directx")
    np.testing.assert_array_equal(b.cells_dict["quad"],
                                  a.cells_dict["quad"][:, ::-1] if flipped
                                  else a.cells_dict["quad"])


def test_a_bad_frame_for_points_and_meshes_names_frame():
    s = facetlift.integrate(np.dstack([np.zeros((4, 4)), np.zeros((4, 4)), np.ones((4, 4))]))
    for call in (lambda: s.points(frame="bogus"), lambda: s.to_mesh(frame="bogus")):
        with pytest.raises(ValueError, match=r"^`frame` must be one of"):
            call()


def test_an_output_frame_without_a_mesh_or_points_says_so(tmp_path, capsys):
    np.save(tmp_path / "n.npy", np.dstack([np.zeros((4, 4)), np.zeros((4, 4)), np.ones((4, 4))]))
    assert main(["integrate", str(tmp_path / "n.npy"), "--output-frame", "opencv", "-s", "npy",
                 "-o", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "--output-frame 'opencv' applies to the mesh and point outputs" in err, err


def test_a_bad_output_frame_is_refused_before_the_job(tmp_path, capsys):
    np.save(tmp_path / "n.npy", np.dstack([np.zeros((4, 4)), np.zeros((4, 4)), np.ones((4, 4))]))
    code = main(["integrate", str(tmp_path / "n.npy"), "--output-frame", "x,x,z",
                 "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1 and "--output-frame must be one of" in err and not (tmp_path / "o").exists()


def test_python_m_facetlift_runs_the_command_line():
    """A user found only the console script: `python -m facetlift` is the same command."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "facetlift", "--version"], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("facetlift, version")


def test_flags_of_another_input_kind_or_route_say_what_applies(tmp_path, capsys):
    """An audit: --gradient-frame with a normal map was ignored in silence; --max-iter with
    --discontinuities named only the solver, not the reweightings' own cap."""
    npath, mpath, _ = write_input(tmp_path)
    code, _, err = run(capsys, "integrate", npath, "-m", mpath, "--gradient-frame", "rowcol",
                       "-o", tmp_path / "a")
    assert code == 0 and "--gradient-frame 'rowcol' applies to a gradient field" in " ".join(
        err.split()) and "it is ignored here" in " ".join(err.split())
    # (a warning, not an error: a batch may mix gradient fields and maps, a review)
    code, _, err = run(capsys, "integrate", npath, "-m", mpath, "--discontinuities",
                       "--max-iter", "5", "-o", tmp_path / "b")
    assert code == 1 and "--option discontinuity_iter=" in " ".join(err.split())
    code, out, _ = run(capsys, "methods", "--help")
    text = " ".join(out.split())
    assert code == 0 and all(f"{c} (" in text for c in REGISTRY["dgp"].capabilities())


def test_the_recipes_diligent_mat_command_runs_with_its_camera(tmp_path, capsys, monkeypatch):
    """docs/recipes.md's line for DiLiGenT's Normal_gt.mat left out the camera (an audit):
    DiLiGenT is perspective, and a .mat file carries no K. The command as written runs on
    such files, perspective, with the release's Calib_Results.mat (its KK)."""
    import shlex
    from pathlib import Path

    from scipy import io as sio

    text = (Path(__file__).parents[1] / "docs" / "recipes.md").read_text()
    line = next(ln for ln in text.splitlines()
                if ln.startswith("facetlift integrate Normal_gt.mat"))
    argv = shlex.split(line)[1:]
    r, c = np.mgrid[0:24, 0:30]
    n = facetlift.normals_from_gradients(0.02 * (c - 15), 0.01 * (r - 12))
    sio.savemat(tmp_path / "Normal_gt.mat", {"Normal_gt": n})
    io.write_mask(tmp_path / "mask.png", np.ones((24, 30), bool))
    sio.savemat(tmp_path / "Calib_Results.mat", {
        "KK": np.array([[180.0, 0, 14.5], [0, 180.0, 11.5], [0, 0, 1]]), "Rc_1": np.eye(3)})
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, *argv, "--json", "-s", "npy", "-o", tmp_path / "o")
    assert code == 0, err
    assert json.loads(out)["perspective"] is True


def test_a_coarser_prior_is_refused_with_its_remedies(tmp_path, capsys):
    """An audit: a sensor's 128x153 depth beside a 512x612 map was refused ("size 128x153
    (HxW) but the normal map is 512x612") with no remedy. Where the sizes differ by one
    integer factor in both axes (to within a pixel), the command line and integrate name the
    factor, the footprint centres (i + 0.5) * f - 0.5 as point samples and the points file
    that takes them, or upsampling; the points so written run. Other sizes: as before."""
    H, W = 24, 30
    r, c = np.mgrid[0:H, 0:W]
    depth = 10.0 + 0.02 * c + 0.01 * r
    n = facetlift.normals_from_gradients(np.full((H, W), -0.02), np.full((H, W), 0.01))
    np.save(tmp_path / "n.npy", n)
    f = 3
    coarse = depth[1::f, 1::f]  # (8 x 10: each block's centre pixel)
    np.save(tmp_path / "coarse.npy", coarse)
    for size in ((H, W), (H + 1, W - 1)):  # (exact, and one pixel off after rounding)
        np.save(tmp_path / "m.npy", np.resize(n, size + (3,)))
        code, _, err = run(capsys, "integrate", tmp_path / "m.npy", "--prior",
                           tmp_path / "coarse.npy", "-o", tmp_path / "x")
        err = " ".join(err.split())
        assert code == 1 and "--prior: size 8x10 (HxW) but the normal map is " \
            f"{size[0]}x{size[1]}; it is 3x coarser in both axes" in err, err
        assert "row (i + 0.5) * 3 - 0.5, col (j + 0.5) * 3 - 0.5" in err
        assert "--prior points.csv: a header line row,col,depth" in err and "1,1,DEPTH" in err
        assert f"upsample it to {size[0]}x{size[1]} yourself" in err
        with pytest.raises(ValueError, match=r"got shape \(8, 10\); it is 3x coarser.*prior="
                           r"\(rows, cols, depths\)"):
            facetlift.integrate(np.resize(n, size + (3,)), prior=coarse)
    for shape in ((6, 10), (8, 11), (8, 12), (24, 29)):  # (another factor per axis, more
        # than a pixel off, or not coarser)
        np.save(tmp_path / "other.npy", np.ones(shape))
        code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "--prior",
                           tmp_path / "other.npy", "-o", tmp_path / "x")
        assert code == 1 and "but the normal map is 24x30" in err and "coarser" not in err
    # the remedy as the message gives it: the block centres as points
    i, j = np.nonzero(np.isfinite(coarse))
    rows, cols = (i + 0.5) * f - 0.5, (j + 0.5) * f - 0.5
    np.testing.assert_array_equal(depth[rows.astype(int), cols.astype(int)], coarse[i, j])
    lines = ["row,col,depth"] + [f"{a:g},{b:g},{float(d)!r}" for a, b, d in
                                 zip(rows, cols, coarse[i, j], strict=True)]
    (tmp_path / "points.csv").write_text("\n".join(lines) + "\n")
    code, out, err = run(capsys, "integrate", tmp_path / "n.npy", "--prior",
                         tmp_path / "points.csv", "-s", "npy", "-o", tmp_path / "p")
    assert code == 0, err
    np.testing.assert_allclose(np.load(tmp_path / "p" / "depth.npy"), depth, atol=1e-6)


def test_a_prior_of_another_size_is_told_to_be_resized_and_declared_blurred(tmp_path, capsys):
    """An audit of a video workflow: Depth Anything's 518 x 518 depth beside a 540 x 960
    frame got only "size 518x518 (HxW) but the normal map is 540x960". A size that is no
    whole factor of the map's is told what to do: resize it to the map's size, --prior-blur
    about 1.1 x the factor it was enlarged by (docs/fusion.md), its aspect's resize undone,
    and --prior-fit for a network's relative depth; in Python and for a dataset folder's
    prior_depth.* alike. One made smaller gets no blur to declare."""
    H, W = 54, 96  # (540 x 960 / 10: the same ratios, a small file)
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    np.save(tmp_path / "n.npy", n)
    np.save(tmp_path / "mono.npy", np.ones((52, 52)))
    code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "--prior", tmp_path / "mono.npy",
                       "-o", tmp_path / "x")
    err = " ".join(err.split())
    assert code == 1 and "--prior: size 52x52 (HxW) but the normal map is 54x96; a depth " \
        "sensor's map belongs in the normal map's camera: reproject its points with the " \
        "sensor's own K and pose" in err, err
    assert "resize it to 54x96, the normal map's size, with any image tool" in err, err
    assert "--prior-blur / prior_blur about 2 to say it is blurred (1.1 x the 1.8x" in err
    assert "its width/height (1) is not the map's (1.78): undo the resize" in err
    assert "--prior-fit affine or disparity" in err and "'A monocular depth map'" in err
    assert "coarser" not in err
    with pytest.raises(ValueError, match=r"got shape \(52, 52\); a depth sensor's map .* "
                       r"resize it to 54x96"):
        facetlift.integrate(n, prior=np.ones((52, 52)))
    with pytest.raises(ValueError, match=r"resize it to 54x96, the normal map's size, with any "
                       r"image tool \(bilinear\); a monocular"):  # (made smaller: no blur)
        facetlift.integrate(n, prior=np.ones((108, 192)))
    # (a VGA sensor's 480 x 640 beside 512 x 612: taller but narrower, so not "enlarged")
    with pytest.raises(ValueError, match=r"image tool \(bilinear\); its width/height"):
        facetlift.integrate(np.dstack([np.zeros((51, 61, 2)), np.ones((51, 61))]),
                            prior=np.ones((48, 64)))
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    np.save(folder / "prior_depth.npy", np.ones((52, 52)))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 1 and "resize it to 54x96" in err and "--no-prior" in err, err


def test_a_dataset_folders_coarser_prior_depth_gets_the_same_remedy(tmp_path, capsys):
    """A review: a folder's 8x10 prior_depth.npy beside its 24x30 normal_map.npy was refused
    by the folder's own size check, which named no factor, while --prior did; it says the
    factor and the remedy now, and still how to leave the file unread. A confidence map of
    that size is no prior: no such hint."""
    H, W = 24, 30
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    np.save(folder / "prior_depth.npy", np.full((8, 10), 10.0))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 1 and "is 8x10 (HxW) but the normal map is 24x30; it is 3x coarser in both " \
        "axes" in err, err
    assert "row (i + 0.5) * 3 - 0.5" in err and "--no-prior" in err, err
    (folder / "prior_depth.npy").unlink()
    np.save(folder / "confidence.npy", np.ones((8, 10)))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "o")
    assert code == 1 and "but the normal map is 24x30" in err and "3x coarser" not in err, err


def test_info_and_integrate_count_the_same_holes(tmp_path, capsys):
    """A review: on an 8-bit map with a 100-pixel and a 9-pixel black hole inside the object,
    info said "holes: 109" (its own 4-connected fill, any size) where integrate counted and
    warned 9 (8-connected gaps of at most HOLE_PIXELS). Both come from problem.enclosed_gaps
    now: the small ones as holes, warned by integrate, the larger ones apart, no warning; the
    job record (batch.jsonl, integrate --json) keeps both."""
    from facetlift.problem import HOLE_PIXELS

    H, W = 40, 50
    r, c = np.mgrid[0:H, 0:W] + 0.5
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 8), 0.1 * np.sin(r / 9))
    n[5:15, 5:15] = np.nan  # 100 pixels: a real hole, taken for one
    n[25:28, 30:33] = np.nan  # 9 pixels: black fill inside the object
    assert 9 <= HOLE_PIXELS < 100
    path = io.write_normals(tmp_path / "holes.png", n, bits=8)
    code, out, _ = run(capsys, "info", path, "--json")
    rec = json.loads(out)
    assert code == 0 and rec["holes"] == 9 and rec["larger_holes"] == 100, rec
    assert rec["counts"]["holes"] == 9 and rec["counts"]["larger_holes"] == 100
    code, out, _ = run(capsys, "info", path)
    assert "holes: 9 pixels enclosed by the object" in out, out
    assert "larger holes: 100 pixels" in out, out
    code, out, err = run(capsys, "integrate", path, "--json", "-s", "npy", "-o", tmp_path / "o")
    got = json.loads(out)
    assert code == 0 and got["info"]["input"]["holes"] == 9, err
    assert got["info"]["input"]["larger_holes"] == 100
    assert got["normals"]["holes"] == 9 and got["normals"]["larger_holes"] == 100
    err = " ".join(err.split())
    assert "9 pixel(s) enclosed by the object hold no normal" in err and "109" not in err, err


def _flat_map_and_box(H, W):
    """A flat normal map (every normal (0, 0, 1)) and a box mask inside it, rows 4-15 and
    columns 5-19."""
    mask = np.zeros((H, W), bool)
    mask[4:16, 5:20] = True
    return np.dstack([np.zeros((H, W, 2)), np.ones((H, W))]), mask


def test_a_mask_beside_a_plain_map_is_named_as_unread(tmp_path, capsys):
    """An audit: mask.png beside a plain map file was ignored without a word (docs/cli.md said
    a folder's mask.png was its mask), while only a dataset folder's files are read. integrate
    names a mask.*, NAME_mask.* or K.txt beside a map file that it does not read, and the
    flag that reads it (recorded in --json); a batch names each folder's once, not per item;
    given with --mask / --K, or for a .mat file with its own mask, nothing is said."""
    from scipy import io as sio

    H, W = 20, 26
    n, mask = _flat_map_and_box(H, W)
    folder = tmp_path / "maps"
    folder.mkdir()
    np.save(folder / "obj.npy", n)
    np.save(folder / "obj2.npy", n)
    io.write_mask(folder / "mask.png", mask)
    code, out, err = run(capsys, "integrate", folder / "obj.npy", "--json", "-s", "npy", "-o",
                         tmp_path / "a")
    said = [w for w in json.loads(out)["warnings"] if "beside it" in w]
    assert code == 0 and len(said) == 1 and err.count("beside it") == 1, err
    assert "obj.npy has mask.png beside it, which this run does not read" in said[0]
    assert "give --mask to use it" in said[0]
    assert json.loads(out)["facets"] == H * W  # (as said: not the mask)
    code, out, err = run(capsys, "integrate", folder / "obj.npy", "--mask", folder / "mask.png",
                         "--json", "-s", "npy", "-o", tmp_path / "b")
    assert code == 0 and "beside it" not in err and json.loads(out)["facets"] == mask.sum()
    # its own NAME_mask and a K.txt: named too (a batch reads the first, a dataset the second)
    (folder / "mask.png").unlink()
    io.write_mask(folder / "obj_mask.png", mask)
    (folder / "K.txt").write_text("40 0 12.5\n0 40 9.5\n0 0 1\n")
    code, _, err = run(capsys, "integrate", folder / "obj.npy", "-s", "npy", "-o", tmp_path / "c")
    err = " ".join(err.split())
    assert code == 0 and "obj.npy has obj_mask.png and K.txt beside it" in err, err
    assert "give --mask / --K to use them (without K.txt's camera the map is integrated " \
           "orthographically)" in err
    code, _, err = run(capsys, "integrate", folder / "obj.npy", "--fov", "60", "--mask",
                       folder / "obj_mask.png", "-s", "npy", "-o", tmp_path / "d")
    assert code == 0 and "beside it" not in err
    # a batch item's own prior and confidence: batch reads them, integrate names them (it
    # said nothing, a review)
    np.save(folder / "obj_prior_depth.npy", np.full((H, W), 5.0))
    np.save(folder / "obj_confidence.npy", np.ones((H, W)))
    code, _, err = run(capsys, "integrate", folder / "obj.npy", "--mask", folder / "obj_mask.png",
                       "--K", folder / "K.txt", "-s", "npy", "-o", tmp_path / "e")
    err = " ".join(err.split())
    assert code == 0 and ("obj.npy has obj_prior_depth.npy and obj_confidence.npy beside "
                          "it") in err, err
    assert "give --prior / --confidence to use them" in err and "facetlift batch pairs" in err
    code, _, err = run(capsys, "integrate", folder / "obj.npy", "--mask", folder / "obj_mask.png",
                       "--K", folder / "K.txt", "--prior", folder / "obj_prior_depth.npy",
                       "--confidence", folder / "obj_confidence.npy", "-s", "npy", "-o",
                       tmp_path / "f")
    assert code == 0 and "beside it" not in err, err
    (folder / "obj_prior_depth.npy").unlink()
    (folder / "obj_confidence.npy").unlink()
    # a batch: once per folder, the mask only where a map has none of its own
    (folder / "K.txt").unlink()
    io.write_mask(folder / "mask.png", mask)
    code, _, err = run(capsys, "batch", folder, "-s", "npy", "-o", tmp_path / "batch")
    assert code == 0 and "beside it," not in err, err
    assert err.count("holds mask.png beside its normal maps, but it is no map's mask") == 1
    assert f"give --mask {folder / 'mask.png'} (mask=) to use it for every map" in err
    # a .mat map: the release's mask.png beside Normal_gt.mat (a DiLiGenT folder, read as
    # one when given as the folder: tests/test_diligent.py), unless the file holds a mask
    sio.savemat(tmp_path / "Normal_gt.mat", {"Normal_gt": n})
    io.write_mask(tmp_path / "mask.png", mask)
    code, _, err = run(capsys, "integrate", tmp_path / "Normal_gt.mat", "-s", "npy", "-o",
                       tmp_path / "e")
    assert code == 0 and "Normal_gt.mat lies in a dataset folder whose mask.png (its mask)" in err
    said = " ".join(err.split())
    assert "only the folder as the input reads it" in said and "or give it with --mask" in said
    assert "--K" not in said  # (no camera file here: only the flag of the file named)
    # (with a normal_map.* beside it the folder reads that one: not told to integrate the
    # folder for this map, a review)
    io.write_normals(tmp_path / "normal_map.png", n)
    code, _, err = run(capsys, "integrate", tmp_path / "Normal_gt.mat", "-s", "npy", "-o",
                       tmp_path / "e1")
    err = " ".join(err.split())
    assert code == 0 and "reads it with its normal_map.png, not this map" in err, err
    (tmp_path / "normal_map.png").unlink()
    sio.savemat(tmp_path / "obj.mat", {"N": n})
    code, _, err = run(capsys, "integrate", tmp_path / "obj.mat", "-s", "npy", "-o",
                       tmp_path / "e2")
    assert code == 0 and "obj.mat has mask.png beside it" in err
    sio.savemat(tmp_path / "Normal_gt.mat", {"Normal_gt": n, "mask": mask.astype(np.uint8)})
    code, _, err = run(capsys, "integrate", tmp_path / "Normal_gt.mat", "-s", "npy", "-o",
                       tmp_path / "f")
    assert code == 0 and "beside it" not in err, err


def test_another_map_in_a_dataset_folder_is_told_it_is_not_the_folders_map(tmp_path, capsys):
    """A review: other.png beside a dataset folder's normal_map.png and mask.png was told "a
    folder is read as a dataset only with normal_map.*", as if integrating the folder would
    read this map with them. In a dataset folder the warning says this file is not the
    folder's normal_map.*; in a folder without one, as before."""
    H, W = 20, 26
    n, mask = _flat_map_and_box(H, W)
    folder = tmp_path / "ds"
    folder.mkdir()
    io.write_normals(folder / "normal_map.png", n)
    io.write_normals(folder / "other.png", n)
    io.write_mask(folder / "mask.png", mask)
    code, _, err = run(capsys, "integrate", folder / "other.png", "-s", "npy", "-o",
                       tmp_path / "a")
    err = " ".join(err.split())
    assert code == 0 and "other.png has mask.png beside it" in err, err
    assert f"(other.png is not this folder's normal_map.png, the map that integrating the " \
           f"folder ({folder}) reads as a dataset)" in err, err
    assert "only with normal_map.*" not in err
    (folder / "normal_map.png").unlink()
    code, _, err = run(capsys, "integrate", folder / "other.png", "-s", "npy", "-o",
                       tmp_path / "b")
    err = " ".join(err.split())
    assert code == 0 and "a folder is read as a dataset only with normal_map.*" in err, err


def test_a_zero_one_map_read_in_a_camera_frame_is_told_of_its_encoding(tmp_path, capsys):
    """An audit: a [0, 1]-encoded float map with --normal-frame opencv was refused as facing
    away, with advice to drop the frame; its encoding is named first (integrate and info)."""
    npath, _, _ = write_input(tmp_path)
    n, _ = io.read_normals(npath)
    np.save(tmp_path / "enc.npy", (n + 1) / 2)
    code, _, err = run(capsys, "integrate", tmp_path / "enc.npy", "--normal-frame", "opencv",
                       "-o", tmp_path / "out")
    line = _one_line_error(err)
    assert code == 1 and r"[0, 1]-encoded" in line and "face away" not in line
    code, out, _ = run(capsys, "info", tmp_path / "enc.npy", "--normal-frame", "opencv")
    assert "likely [0, 1]-encoded floats" in out and "face away" not in out


def _sphere_files(folder):
    """An analytic sphere's signed normals (NaN outside) as .npy, and the same normals stored
    in [0, 1] as a renderer writes them, (n + 1) / 2 on a black background, as .npy and
    float32 EXR; and its mask."""
    import OpenEXR

    gt = facetlift.synthetic.analytic("sphere", 40)
    np.save(folder / "signed.npy", gt.normals)
    v = np.where(gt.mask[..., None], (gt.normals + 1) / 2, 0.0)
    np.save(folder / "n01.npy", v)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: v[..., i].astype(np.float32)
                               for i, k in enumerate("RGB")}) as f:
        f.write(str(folder / "n01.exr"))
    return gt.normals, v, gt.mask


def test_a_zero_one_float_map_integrates_with_normal_range_unsigned(tmp_path, capsys,
                                                                    monkeypatch):
    """A user with a float map stored as (n + 1) / 2 (EXR, .npy) was refused and had to write
    Python: --normal-range unsigned decodes it (2 v - 1, its black background no normal), and
    the depth is the signed map's; without it the refusal names the flag, and the Python
    remedy too. integrate is handed the decoded normals, no new argument."""
    n, _, mask = _sphere_files(tmp_path)
    code, _, err = run(capsys, "integrate", tmp_path / "signed.npy", "-s", "npy", "-o",
                       tmp_path / "s")
    assert code == 0, err
    want = np.load(tmp_path / "s" / "depth.npy")
    seen = {}

    def spy(normals, mask=None, **kw):
        seen.update(kw, normals=normals)
        raise ValueError("spy stops here")

    with monkeypatch.context() as m:
        m.setattr(facetlift, "integrate", spy)
        code, _, err = run(capsys, "integrate", tmp_path / "n01.npy", "--normal-range",
                           "unsigned", "-o", tmp_path / "spy")
    assert code == 1 and "spy stops here" in err and "normal_range" not in seen
    np.testing.assert_allclose(seen["normals"][mask], n[mask], atol=1e-15)
    for name, atol in (("n01.npy", 1e-9), ("n01.exr", 1e-4)):
        out = tmp_path / name.replace(".", "_")
        code, _, err = run(capsys, "integrate", tmp_path / name, "--normal-range", "unsigned",
                           "-s", "npy", "-o", out)
        assert code == 0 and "warning" not in err, err
        got = np.load(out / "depth.npy")
        np.testing.assert_array_equal(np.isnan(got), ~mask)
        np.testing.assert_allclose(got[mask], want[mask], atol=atol * np.ptp(want[mask]))
        code, _, err = run(capsys, "integrate", tmp_path / name, "-o", tmp_path / "no")
        line = _one_line_error(err)
        assert code == 1 and re.search(
            r"looks \[0, 1\]-encoded: .*read it with --normal-range unsigned \(normal_range="
            r"'unsigned' in a facetlift.jobs.Job or facetlift.io.read_normals\), which decodes "
            r"n = 2 \* v - 1, or decode it in Python", line), line
        assert not (tmp_path / "no").exists()


def test_normal_range_unsigned_is_refused_for_integer_and_signed_maps(tmp_path, capsys):
    """--normal-range unsigned applies to float maps: an 8/16-bit PNG (always decoded from its
    integer range) and a map with negative components (signed) are refused naming the flag,
    the latter with the count; as is a gradient field, which stores slopes."""
    import imagecodecs

    n, v, mask = _sphere_files(tmp_path)
    (tmp_path / "n.png").write_bytes(imagecodecs.png_encode(np.round(v * 255).astype(np.uint8)))
    code, _, err = run(capsys, "integrate", tmp_path / "n.png", "--normal-range", "unsigned",
                       "-o", tmp_path / "a")
    assert code == 1 and re.search(r"n.png: --normal-range 'unsigned' applies to float maps "
                                   r"stored in \[0, 1\]; this one is an 8-bit integer map, "
                                   r"always decoded from its integer range", _one_line_error(err))
    k = int(np.count_nonzero(n[mask] < -facetlift.frames.UNSIGNED_SLACK))
    for command in ("integrate", "info"):
        code, _, err = run(capsys, command, tmp_path / "signed.npy", "--normal-range",
                           "unsigned", *(["-o", tmp_path / "b"] if command == "integrate"
                                         else []))
        assert code == 1 and re.search(rf"signed.npy: --normal-range 'unsigned' says the map "
                                       rf"stores \(n \+ 1\) / 2 in \[0, 1\], but {k} of its "
                                       r"\d+ components are negative", _one_line_error(err))
    np.save(tmp_path / "p.npy", np.zeros((8, 9)))
    np.save(tmp_path / "q.npy", np.zeros((8, 9)))
    code, _, err = run(capsys, "integrate", "--gradients", tmp_path / "p.npy",
                       tmp_path / "q.npy", "--normal-range", "unsigned", "-o", tmp_path / "g")
    assert code == 1 and "--normal-range 'unsigned' applies to a normal map" in (
        _one_line_error(err))


def test_normal_range_unsigned_in_info_a_folder_and_with_encoding_xy(tmp_path, capsys):
    """info reads the map as integrate does (its encoding line says so) and points to the flag
    without it; a dataset folder's normal_map.exr is read so too; with --normal-encoding xy,
    x and y are decoded before z is rebuilt."""
    import OpenEXR

    _, v, mask = _sphere_files(tmp_path)
    code, out, err = run(capsys, "info", tmp_path / "n01.exr", "--normal-range", "unsigned")
    assert code == 0 and "encoding: 2 v - 1 (unsigned: stored in [0, 1])" in out, out + err
    code, out, _ = run(capsys, "info", tmp_path / "n01.exr")
    assert code == 1 and "likely [0, 1]-encoded floats: read with --normal-range unsigned" in (
        out)
    code, _, err = run(capsys, "integrate", tmp_path / "signed.npy", "-s", "npy", "-o",
                       tmp_path / "s")
    assert code == 0, err
    want = np.load(tmp_path / "s" / "depth.npy")
    folder = tmp_path / "set"
    folder.mkdir()
    (tmp_path / "n01.exr").rename(folder / "normal_map.exr")
    io.write_mask(folder / "mask.png", mask)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: v[..., i].astype(np.float32)
                               for i, k in enumerate("RG")}) as f:
        f.write(str(tmp_path / "xy.exr"))
    for args in ((folder,), (tmp_path / "xy.exr", "--normal-encoding", "xy")):
        out = tmp_path / f"o{len(args)}"
        code, _, err = run(capsys, "integrate", *args, "--normal-range", "unsigned", "-s",
                           "npy", "-o", out)
        assert code == 0, err
        got = np.load(out / "depth.npy")
        np.testing.assert_array_equal(np.isnan(got), ~mask)
        np.testing.assert_allclose(got[mask], want[mask], atol=1e-4 * np.ptp(want[mask]))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "no")
    assert code == 1 and "--normal-range unsigned" in _one_line_error(err)


def test_normal_range_unsigned_reads_a_mat_normal_map(tmp_path, capsys):
    """A .mat file's normal map (--mat-keys N,mask) is decoded as a file's is; its signs are
    counted inside its own mask."""
    import scipy.io

    n, v, mask = _sphere_files(tmp_path)
    scipy.io.savemat(tmp_path / "u.mat", {"N": v, "mask": mask.astype(float)})
    scipy.io.savemat(tmp_path / "s.mat", {"N": np.nan_to_num(n), "mask": mask.astype(float)})
    code, _, err = run(capsys, "integrate", tmp_path / "u.mat", "--mat-keys", "N,mask",
                       "--normal-range", "unsigned", "-s", "npy", "-o", tmp_path / "u")
    assert code == 0, err
    want = facetlift.integrate(n, mask).depth
    np.testing.assert_allclose(np.load(tmp_path / "u" / "depth.npy")[mask], want[mask],
                               atol=1e-9)
    k = int(np.count_nonzero(n[mask] < -facetlift.frames.UNSIGNED_SLACK))
    code, _, err = run(capsys, "integrate", tmp_path / "s.mat", "--mat-keys", "N,mask",
                       "--normal-range", "unsigned", "-o", tmp_path / "s")
    assert code == 1 and f"but {k} of its {3 * mask.sum()} components" in _one_line_error(err)


def test_normal_range_unsigned_counts_signs_inside_a_separate_mask(tmp_path, capsys):
    """A [0, 1] map whose background outside its mask file holds -1 (a signed fill) was
    refused as signed normals with --normal-range unsigned: --mask, a dataset folder's
    mask.png and batch's NAME_mask.png were read after the map, so the fill's signs were
    counted (its own alpha and a .mat file's mask already bounded them). Now only the pixels
    inside the mask count, for a .npy, an EXR and a .mat map; negatives inside are still
    refused, counted there; a mask of another size still gets its own refusal."""
    import OpenEXR
    import scipy.io

    n, v, mask = _sphere_files(tmp_path)
    want = facetlift.integrate(n, mask).depth
    filled = np.where(mask[..., None], v, -1.0)
    np.save(tmp_path / "fill.npy", filled)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: filled[..., i].astype(np.float32)
                               for i, k in enumerate("RGB")}) as f:
        f.write(str(tmp_path / "fill.exr"))
    scipy.io.savemat(tmp_path / "fill.mat", {"N": filled})
    io.write_mask(tmp_path / "m.png", mask)
    folder = tmp_path / "set"
    folder.mkdir()
    np.save(folder / "normal_map.npy", filled)
    io.write_mask(folder / "mask.png", mask)
    unsigned = ("--normal-range", "unsigned")
    for i, args in enumerate(((tmp_path / "fill.npy", "--mask", tmp_path / "m.png"),
                              (tmp_path / "fill.exr", "--mask", tmp_path / "m.png"),
                              (tmp_path / "fill.mat", "--mat-keys", "N", "--mask",
                               tmp_path / "m.png"),
                              (folder,))):
        code, _, err = run(capsys, "integrate", *args, *unsigned, "-s", "npy", "-o",
                           tmp_path / f"o{i}")
        assert code == 0, err
        got = np.load(tmp_path / f"o{i}" / "depth.npy")
        np.testing.assert_allclose(got[mask], want[mask], atol=1e-4 * np.ptp(want[mask]))
        code, out, err = run(capsys, "info", *args, *unsigned)
        assert code == 0 and "unusable normals: none" in out, out + err
    # without the mask every component counts: the fill's
    code, _, err = run(capsys, "integrate", tmp_path / "fill.npy", *unsigned, "-o",
                       tmp_path / "no")
    assert code == 1 and f"but {3 * (~mask).sum()} of its {3 * mask.size} components are " \
        "negative" in _one_line_error(err)
    # a negative inside the mask is still refused, counted among the mask's components
    inside = filled.copy()
    inside[mask.nonzero()[0][0], mask.nonzero()[1][0], 0] = -0.5
    np.save(tmp_path / "inside.npy", inside)
    code, _, err = run(capsys, "integrate", tmp_path / "inside.npy", "--mask",
                       tmp_path / "m.png", *unsigned, "-o", tmp_path / "no")
    assert code == 1 and f"but 1 of its {3 * mask.sum()} components are negative (down to " \
        "-0.5)" in _one_line_error(err)
    io.write_mask(tmp_path / "small.png", mask[:-2])
    code, _, err = run(capsys, "integrate", tmp_path / "fill.npy", "--mask",
                       tmp_path / "small.png", *unsigned, "-o", tmp_path / "no")
    assert code == 1 and re.search(r"small.png has size 38x40 \(HxW\) but the normal map is "
                                   r"40x40", _one_line_error(err))
    assert not (tmp_path / "no").exists()


def test_a_two_channel_map_with_blue_0_is_told_to_rebuild_z(tmp_path, capsys):
    """An audit: a BC5 map (B = 0) was told '100 % ... face away ... try --normal-frame
    opencv' after a warning that z is not stored; integrate and info say z is not stored."""
    import imagecodecs

    npath, _, _ = write_input(tmp_path)
    n, _ = io.read_normals(npath)
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    v[..., 2] = 0
    (tmp_path / "bc5.png").write_bytes(imagecodecs.png_encode(v))
    code, _, err = run(capsys, "integrate", tmp_path / "bc5.png", "-o", tmp_path / "out")
    line = [ln for ln in err.splitlines() if ln.startswith("facetlift: error:")]
    assert code == 1 and len(line) == 1 and "is z stored" in line[0]
    assert "sqrt(1 - x^2 - y^2)" in line[0] and "normal-frame" not in line[0]
    assert "--normal-encoding xy" in line[0]  # (the flag that reads it, a texture audit)
    code, out, _ = run(capsys, "info", tmp_path / "bc5.png")
    assert "likely z not stored" in out and "normal-frame" not in out
    assert "--normal-encoding xy" in out


def test_a_two_channel_map_integrates_with_normal_encoding_xy(tmp_path, capsys):
    """A texture artist's BC5 map (x, y in R, G; B = 0) was refused with a recipe in Python
    only: --normal-encoding xy reads R, G as x, y and rebuilds z, and the height is that of
    the three-channel original to within the 8 bits; info reads it so too."""
    import imagecodecs

    r, c = np.mgrid[0:40, 0:48] + 0.5
    # (h = 2 sin(c / 4) cos(r / 6), y up: an integrable field, so both give one height)
    p = 0.5 * np.cos(c / 4) * np.cos(r / 6)
    q = (2 / 6) * np.sin(c / 4) * np.sin(r / 6)
    n = facetlift.normals_from_gradients(p, q)
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    (tmp_path / "full.png").write_bytes(imagecodecs.png_encode(v))
    v[..., 2] = 0
    (tmp_path / "bc5.png").write_bytes(imagecodecs.png_encode(v))
    code, _, err = run(capsys, "integrate", tmp_path / "full.png", "-s", "npy", "-o",
                       tmp_path / "full")
    assert code == 0, err
    code, _, err = run(capsys, "integrate", tmp_path / "bc5.png", "-s", "npy", "-o",
                       tmp_path / "xy", "--normal-encoding", "xy")
    assert code == 0 and "warning" not in err, err
    a, b = np.load(tmp_path / "full" / "depth.npy"), np.load(tmp_path / "xy" / "depth.npy")
    assert np.isfinite(b).all() and np.abs(a - b).max() < 0.005 * np.ptp(a)
    # without the flag: refused, the flag named (test above)
    code, _, err = run(capsys, "integrate", tmp_path / "bc5.png", "-o", tmp_path / "no")
    line = [ln for ln in err.splitlines() if ln.startswith("facetlift: error:")]
    assert code == 1 and len(line) == 1 and "--normal-encoding xy" in line[0]
    code, out, _ = run(capsys, "info", tmp_path / "bc5.png", "--normal-encoding", "xy")
    assert code == 0 and "z = sqrt(1 - x^2 - y^2)" in out and "z not stored" not in out
    # a gradient field stores slopes: the encoding does not apply
    np.save(tmp_path / "p.npy", p)
    np.save(tmp_path / "q.npy", q)
    code, _, err = run(capsys, "integrate", "--gradients", tmp_path / "p.npy",
                       tmp_path / "q.npy", "--normal-encoding", "xy", "-o", tmp_path / "g")
    assert code == 1 and "--normal-encoding 'xy' applies to a normal map" in (
        _one_line_error(err))


def test_black_pixels_inside_the_object_are_reported(tmp_path, capsys):
    """An audit: `integrate map.png` with 39 black (0, 0, 0) pixels left NaN holes in the depth
    and the mesh, and only `info` spoke of holes; integrate says how many and where."""
    import imagecodecs

    npath, _, _ = write_input(tmp_path)
    n, _ = io.read_normals(npath)
    v = np.round((n + 1) / 2 * 255).astype(np.uint8)
    v[3, 5] = v[12, 20] = v[15, 2] = 0
    (tmp_path / "black.png").write_bytes(imagecodecs.png_encode(v))
    code, _, err = run(capsys, "integrate", tmp_path / "black.png", "-s", "npy", "-o",
                       tmp_path / "out")
    assert code == 0
    said = [ln for ln in err.splitlines() if "enclosed by the object" in ln]
    assert len(said) == 1 and "3 pixel(s)" in said[0] and "(row 3, col 5)" in said[0]
    assert np.isnan(np.load(tmp_path / "out" / "depth.npy")[[3, 12, 15], [5, 20, 2]]).all()


def test_a_dataset_folders_ground_truth_is_scored(tmp_path, capsys):
    """A dataset folder holding depth_gt.* (BiNI's DiLiGenT folders hold depth_gt.npz) is
    scored with facetlift evaluate's measures: the summary gives BiNI's MADE, --json and
    batch.jsonl the record's evaluation, and a batch its mean over the items that have one,
    so that methods compare on a benchmark's folders in one run. A ground truth that cannot
    be scored (another size) is warned about; the job still succeeds."""
    H, W, f = 40, 48, 200.0
    c = np.mgrid[0:H, 0:W][1].astype(float)
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])
    depth = 10.0 / (1.0 - 2.0 * (c - K[0, 2]) / f)  # (a tilted plane z = 10 + 2 X)
    n = np.dstack([np.full((H, W), -2.0), np.zeros((H, W)), np.ones((H, W))])
    n = n * [1, -1, -1] * -1  # (the plane's normal toward the camera, facetlift frame)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    for name in ("a", "b"):
        d = tmp_path / name
        d.mkdir()
        np.save(d / "normal_map.npy", n)
        np.savetxt(d / "K.txt", K)
    np.savez(tmp_path / "a" / "depth_gt.npz", depth_gt=depth)
    code, out, err = run(capsys, "integrate", tmp_path / "a", "-s", "npy", "--json", "-o",
                         tmp_path / "out_a")
    rec = json.loads(out)
    assert code == 0, err
    ev = rec["evaluation"]
    assert ev["gt"] == "depth_gt.npz" and ev["perspective"] and ev["pixels"] == H * W
    assert ev["made"] < 1e-3 * depth.mean(), ev
    code, out, err = run(capsys, "integrate", tmp_path / "a", "-s", "npy", "-o",
                         tmp_path / "out_a2")
    assert re.search(r"MADE [\d.e-]+ against depth_gt\.npz \(BiNI's: after the median scale",
                     out), out
    np.save(tmp_path / "b" / "depth_gt.npy", depth[:20])  # (another size)
    code, out, err = run(capsys, "batch", tmp_path / "a", tmp_path / "b", "-s", "npy", "-o",
                         tmp_path / "batch")
    said = " ".join((out + err).split())
    assert code == 0 and "depth_gt.npy in" in said and "not scored" in said, said
    assert re.search(r"mean MADE [\d.e-]+ over the 1 with a depth_gt file scored by it",
                     said), said
    logged = [json.loads(line) for line in (tmp_path / "batch" / "batch.jsonl").open()]
    assert sorted(bool(r.get("evaluation")) for r in logged) == [False, True]


def test_normal_range_unsigned_names_a_mat_maps_undecoded_integer_values(tmp_path, capsys):
    """A .mat file's uint8 normal map (read as floats, 0..255) with --normal-range unsigned was
    decoded into fill, and the run said 'no usable normal (all missing)'; it is named as
    undecoded 8-bit values, as a float .npy of them is (a review)."""
    import scipy.io

    n, _, mask = _sphere_files(tmp_path)
    v = np.where(mask[..., None], np.round((n + 1) / 2 * 255), 0).astype(np.uint8)
    scipy.io.savemat(tmp_path / "u8.mat", {"N": v, "mask": mask.astype(np.uint8)})
    np.save(tmp_path / "f255.npy", v.astype(np.float32))
    for args in ((tmp_path / "u8.mat", "--mat-keys", "N,mask"), (tmp_path / "f255.npy",)):
        code, _, err = run(capsys, "integrate", *args, "--normal-range", "unsigned", "-o",
                           tmp_path / "o")
        assert code == 1 and re.search(r"--normal-range 'unsigned' says .* reach 255: they "
                                       r"look like an undecoded 8-bit", _one_line_error(err)), err


def test_info_does_not_advise_normal_range_unsigned_to_a_run_that_gave_it(tmp_path, capsys):
    """A map encoded twice, read with --normal-range unsigned, is still in [0, 1]: info's frame
    line told it to 'read with --normal-range unsigned', the flag it was given; it says the
    decode was applied (as integrate's refusal does), and the refusal's sentence ends once."""
    _, v, mask = _sphere_files(tmp_path)
    np.save(tmp_path / "twice.npy", np.where(mask[..., None], (v + 1) / 2, 0.0))
    code, out, err = run(capsys, "info", tmp_path / "twice.npy", "--normal-range", "unsigned")
    assert code == 1, out + err
    frame = next(line for line in out.splitlines() if line.strip().startswith("frame:"))
    assert "read with --normal-range unsigned" not in frame, frame
    assert "after --normal-range unsigned's decoding" in frame, frame
    assert "?." not in out


def test_info_reads_the_normals_noise_from_their_curl(tmp_path, capsys):
    """info names the normals' angular noise (frames.normal_noise): about 3 deg for a 16-bit
    map with 3 deg of angular noise, about 0 for the same surface's own normals; in the JSON
    record as 'noise' (degrees)."""
    from facetlift import synthetic

    H, W = 60, 70
    r, c = np.mgrid[0:H, 0:W] + 0.5
    n = facetlift.normals_from_gradients(0.2 * np.cos(c / 8), 0.1 * np.sin(r / 9))
    noisy = synthetic.add_angular_noise(n, 3.0, np.random.default_rng(2))
    for name, normals, lo, hi in (("clean", n, 0.0, 0.1), ("noisy", noisy, 2.5, 3.4)):
        path = io.write_normals(tmp_path / f"{name}.png", normals, bits=16)
        code, out, _ = run(capsys, "info", path, "--json")
        assert code == 0 and lo <= json.loads(out)["noise"] < hi, out
        code, out, _ = run(capsys, "info", path)
        line = next(x for x in out.splitlines() if "noise: about" in x)
        assert "read from the normals' curl" in line, out


def test_info_takes_integrates_folder_flags_and_a_given_K_over_the_folders_is_warned(
        tmp_path, capsys):
    """An audit: info told a folder's user to give --no-prior, which it refused (and had no
    --orthographic); --K over a dataset folder's differing K.txt replaced it in silence where
    --fov warns; info's text left out the zero-confidence pixels its JSON counts."""
    ds = tmp_path / "ds"
    ds.mkdir()
    _, _, mask = write_input(ds, name="normal_map.png")
    np.savetxt(ds / "K.txt", [[50.0, 0, 12.5], [0, 50.0, 9.5], [0, 0, 1]])
    conf = np.ones((20, 26))
    conf[0, :5] = 0.0
    np.save(ds / "confidence.npy", conf)
    np.save(ds / "prior_depth.npy", np.full((20, 26), -1.0))  # (refused: not positive)
    code, out, err = run(capsys, "info", ds)
    assert code == 1 and "positive z-depths" in out
    code, out, err = run(capsys, "info", ds, "--no-prior", "--json")
    rec = json.loads(out)
    assert code == 0 and "prior" not in rec and rec["counts"]["zero_confidence"] == 5, err
    code, out, err = run(capsys, "info", ds, "--no-prior")
    assert code == 0 and "5 zero confidence" in out, out
    code, out, err = run(capsys, "info", ds, "--no-prior", "--no-confidence", "--orthographic",
                         "--json")
    rec = json.loads(out)
    assert code == 0 and rec.get("K") is None and "confidence" not in rec, out
    code, _, err = run(capsys, "info", ds, "--orthographic", "--K", "50 50 12.5 9.5")
    assert code == 1 and "contradict" in err
    np.save(ds / "prior_depth.npy", np.full((20, 26), 3.0))
    code, _, err = run(capsys, "integrate", ds, "--K", "60 60 12.5 9.5", "-o", tmp_path / "o")
    assert code == 0 and "--K 60 60 12.5 9.5 replaces the K of the dataset folder's K.txt" in err
    code, _, err = run(capsys, "integrate", ds, "--K", "50 50 12.5 9.5", "-o", tmp_path / "o2")
    assert code == 0 and "replaces the K" not in err  # (the same K: no word)


def test_info_json_words_warnings_as_the_command_line_and_says_camera_warned(tmp_path,
                                                                             capsys):
    """An audit: info --json named `K` in its warnings where integrate --json names --K, and
    had no camera_warned."""
    npath, mpath, _ = write_input(tmp_path)
    code, out, err = run(capsys, "info", npath, "--mask", mpath, "--K", "50 50 25.5 19.5",
                         "--json")
    rec = json.loads(out)
    assert code == 0 and rec["camera_warned"] is True, err
    assert any(w.startswith("--K: the principal point") for w in rec["warnings"]), rec
    code, out, _ = run(capsys, "info", npath, "--mask", mpath, "--json")
    assert json.loads(out)["camera_warned"] is False
    # (the text names the camera as typed, not "K", a review)
    code, out, _ = run(capsys, "info", npath, "--mask", mpath, "--K", "50 50 25.5 19.5")
    assert "camera: perspective (--K 50 50 25.5 19.5), K = " in out, out


def test_methods_refuses_json_with_markdown_and_a_flipped_plane_is_told_its_frame(capsys):
    """A docs audit: `methods --json --markdown` printed Markdown, exit 0; a plane read in a
    z-flipped frame was told "x and y vary" and pointed to --normal-encoding xy."""
    code, out, err = run(capsys, "methods", "--json", "--markdown")
    assert code == 1 and "give --json or --markdown, not both" in err
    n = facetlift.normals_from_gradients(np.full((30, 30), -0.3), np.full((30, 30), -0.2))
    with pytest.raises(ValueError, match=r"face away from the viewer") as got:
        facetlift.integrate(n, normal_frame="opencv")
    assert "x and y vary" not in str(got.value)


def test_a_gradient_field_in_the_other_layout_gets_no_jump_hint(tmp_path, capsys):
    """A gradients audit: a row-down field read as xy got the layout warning and a hint that
    its deviation looked like depth jumps (--discontinuities); the layout is the advice."""
    H, W = 60, 80
    r, c = np.mgrid[0:H, 0:W] + 0.5
    z = 8 * np.exp(-((c - 50) ** 2 + (r - 25) ** 2) / 200) + 0.05 * c
    p = np.gradient(z, axis=1)  # dz/dx (x right)
    q = -np.gradient(z, axis=0)  # dz/dy (y up)
    np.save(tmp_path / "p.npy", -q)  # (rowcol: dz/d(row), dz/d(col))
    np.save(tmp_path / "q.npy", p)
    code, _, err = run(capsys, "integrate", "--gradients", tmp_path / "p.npy",
                       tmp_path / "q.npy", "-o", tmp_path / "o")
    assert code == 0 and "--gradient-frame rowcol" in err, err
    assert "--discontinuities keeps them" not in err


def test_an_all_nan_gradient_file_is_named_as_gradients(tmp_path, capsys):
    """A gradients audit: an all-NaN p was reported as 'NORMALS has no finite, non-zero
    normal'."""
    np.save(tmp_path / "p.npy", np.full((12, 14), np.nan))
    np.save(tmp_path / "q.npy", np.zeros((12, 14)))
    code, _, err = run(capsys, "integrate", "--gradients", tmp_path / "p.npy",
                       tmp_path / "q.npy", "-o", tmp_path / "o")
    assert code == 1 and ("--gradients P and --gradients Q have no pixel where both are "
                          "finite") in err


def test_a_mat_gradient_field_is_hinted_as_a_field_and_its_empty_mask_named(tmp_path, capsys):
    """A gradients audit: a .mat of p and q whose mask is all zeros said only "`mask` is
    empty"; a .mat field's jump hint told it to try --normal-frame directx, which a gradient
    field refuses."""
    from scipy import io as sio

    H, W = 60, 80
    r, c = np.mgrid[0:H, 0:W].astype(float)
    x, y = c, -r
    g = 8 * np.exp(-((x - 55) ** 2 + (y + 20) ** 2) / 150)
    p, q = g * (-2 * (x - 55) / 150) + 0.05, g * (-2 * (y + 20) / 150) - 0.03
    mask = np.ones((H, W), bool)
    mask[:5, :] = False
    mask[:, -3:] = False
    np.save(tmp_path / "mask.npy", mask.astype(np.uint8))
    # (Quéau's layout, p = dz/d(row), q = dz/d(col), read as the default xy)
    sio.savemat(tmp_path / "f.mat", {"p": -q, "q": p, "mask": np.zeros((H, W))})
    code, _, err = run(capsys, "integrate", tmp_path / "f.mat", "-o", tmp_path / "o0")
    assert code == 1 and "f.mat holds a mask with no pixel set" in err
    code, _, err = run(capsys, "integrate", tmp_path / "f.mat", "--mask", tmp_path / "mask.npy",
                       "-o", tmp_path / "o")
    assert code == 0 and "hint:" in err and "--normal-frame" not in err, err


def test_a_settings_warning_is_said_before_a_later_checks_error(tmp_path, capsys):
    """A review: --output-frame without a mesh saved was warned about, then the batch's
    records were mended to keep it, which dropped it where a later check of the settings
    (a bad --height-range) failed the job: both are said."""
    n = np.dstack([np.zeros((12, 14, 2)), np.ones((12, 14))])
    np.save(tmp_path / "n.npy", n)
    code = main(["integrate", str(tmp_path / "n.npy"), "-o", str(tmp_path / "o"), "-s", "npy",
                 "--output-frame", "opencv", "--height-range", "1", "0"])
    err = capsys.readouterr().err
    assert code == 1 and "applies to the mesh and point outputs" in err
    assert "--height-range must be two finite numbers" in err


def test_save_normals_writes_the_results_own_normals_in_the_inputs_frame(tmp_path, capsys):
    """--save normals: the result's facet normals (each facet's own corners where split at
    jumps) as a 16-bit PNG normal map, in the frame the input came in, to set beside it."""
    from facetlift import frames, io, metrics, synthetic

    g = synthetic.analytic("steps", 40)
    rng = np.random.default_rng(3)
    noisy = synthetic.add_angular_noise(g.normals, 2.0, rng)
    np.save(tmp_path / "n.npy", frames.from_facetlift(noisy, "opencv"))
    code, _, err = run(capsys, "integrate", tmp_path / "n.npy", "--normal-frame", "opencv",
                       "--discontinuities", "-o", tmp_path / "out", "-s", "normals", "-s", "npz")
    assert code == 0, err
    s = io.load_surface(tmp_path / "out" / "surface.npz")
    want = metrics.surface_normals(s)
    back, _ = io.read_normals(tmp_path / "out" / "result_normals.png", frame="opencv")
    np.testing.assert_allclose(back, want, atol=3e-5)
    # the result's normals are not the input's: the noise is gone
    assert np.nanmean(np.abs(back - noisy)) > 10 * np.nanmean(np.abs(back - want))
    # the reloaded surface writes the same file, in the frame the command line read the map
    # in (it wrote facetlift's, 130 degrees off, a review)
    s.save(tmp_path / "result_normals.png")
    assert (tmp_path / "result_normals.png").read_bytes() == (
        tmp_path / "out" / "result_normals.png").read_bytes()


def test_a_dataset_folders_prior_named_in_value_errors(tmp_path, capsys):
    """A user's check: a folder's prior_depth.npy with no finite sample, or with negative
    depths beside the folder's K.txt, was refused as `prior`, a Python name the user had not
    typed; the message names the file and --no-prior now. A --prior given as a flag keeps
    its flag's name, with no such tail."""
    H, W = 24, 30
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    np.save(folder / "prior_depth.npy", np.full((H, W), np.nan))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 1 and "`prior` (the folder's prior_depth.npy) has no finite depth sample" \
        in err and err.endswith("or leave it unread with --no-prior (dataset_prior=False in "
                                 "Python)"), err
    np.savetxt(folder / "K.txt", [[50.0, 0, 15], [0, 50.0, 12], [0, 0, 1]])
    np.save(folder / "prior_depth.npy", np.full((H, W), -1.0))
    code, _, err = run(capsys, "integrate", folder, "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 1 and "`prior` (the folder's prior_depth.npy) must hold positive z-depths" \
        in err and "write NaN there" in err and "--no-prior" in err, err
    code, _, err = run(capsys, "integrate", folder, "--prior", folder / "prior_depth.npy",
                       "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 1 and "--prior must hold positive z-depths" in err, err
    assert "--no-prior" not in err, err
    assert not (tmp_path / "o").exists()


def test_a_dataset_folders_confidence_named_in_warnings(tmp_path, capsys):
    """A user's check: a warning about a folder's confidence.* (0..255 beside its prior)
    named `confidence`, a Python argument the user had not typed; it names the file and
    --no-confidence now, and a --confidence given as a flag keeps the flag's name."""
    H, W = 24, 30
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    prior = np.full((H, W), np.nan)
    prior[::6, ::6] = 0.0
    np.save(folder / "prior_depth.npy", prior)
    np.save(folder / "confidence.npy", np.full((H, W), 255.0))
    code, out, err = run(capsys, "integrate", folder, "-s", "npy", "-o", tmp_path / "o")
    err = " ".join(err.split())
    assert code == 0, err
    assert "`confidence` (the folder's confidence.npy) reaches 255" in err, err
    assert "(--no-confidence leaves it unread, dataset_confidence=False in Python)" in err
    code, out, err = run(capsys, "integrate", folder, "--confidence", folder / "confidence.npy",
                         "-s", "npy", "-o", tmp_path / "p")
    err = " ".join(err.split())
    assert code == 0 and "--confidence reaches 255" in err and "--no-confidence" not in err, err
    # (the renaming is this job's only: a library call afterwards says `confidence`)
    with pytest.warns(UserWarning, match=r"^`confidence` reaches 255"):
        facetlift.integrate(n, prior=prior, confidence=np.full((H, W), 255.0))


def test_a_batchs_files_beside_the_maps_named_in_messages(tmp_path, capsys):
    """A review: a batch's own NAME_confidence.* (0..255 beside a prior) and NAME_prior_depth.*
    (no finite sample) were refused or warned about as `confidence` and `prior`, the Python
    names; the messages name the file and the flag that leaves such files unread."""
    H, W = 24, 30
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    maps = tmp_path / "maps"
    maps.mkdir()
    prior = np.full((H, W), np.nan)
    prior[::6, ::6] = 0.0
    for name in ("a", "b"):
        np.save(maps / f"{name}.npy", n)
    np.save(maps / "a_prior_depth.npy", prior)
    np.save(maps / "a_confidence.npy", np.full((H, W), 255.0))
    np.save(maps / "b_prior_depth.npy", np.full((H, W), np.nan))
    code, out, err = run(capsys, "batch", str(maps / "[ab].npy"), "-o", tmp_path / "out",
                         "-s", "npy", "--workers", "1")
    err = " ".join(err.split())
    assert "`confidence` (a_confidence.npy) reaches 255" in err, err
    assert "`prior` (b_prior_depth.npy) has no finite depth sample" in err, err
    assert err.count("--no-prior") >= 1 and "--no-confidence" in err, err


def test_info_names_a_dataset_folders_prior_in_its_refusal(tmp_path, capsys):
    """A review: `facetlift info FOLDER` said "cannot be integrated as read: `prior` must
    hold positive z-depths" for the folder's prior_depth.npy, without the file or
    --no-prior, where integrate names both."""
    H, W = 24, 30
    n = np.dstack([np.zeros((H, W, 2)), np.ones((H, W))])
    folder = tmp_path / "ds"
    folder.mkdir()
    np.save(folder / "normal_map.npy", n)
    np.savetxt(folder / "K.txt", [[50.0, 0, 15], [0, 50.0, 12], [0, 0, 1]])
    np.save(folder / "prior_depth.npy", np.full((H, W), -1.0))
    code, out, err = run(capsys, "info", folder)
    text = " ".join((out + err).split())
    assert "cannot be integrated as read: `prior` (the folder's prior_depth.npy) must hold " \
        "positive z-depths" in text, text
    assert "--no-prior" in text


def test_a_camera_from_fov_is_named_as_fov_where_a_method_refuses_it(tmp_path, capsys):
    """A review: `--method kernel --fov 40` was told the method does not support `K`, a name
    the user had not typed."""
    g = facetlift.synthetic.analytic("sphere", 32)
    np.save(tmp_path / "n.npy", np.where(g.mask[..., None], g.normals, np.nan))
    code = main(["integrate", str(tmp_path / "n.npy"), "--method", "kernel", "--fov", "40",
                 "-o", str(tmp_path / "o"), "-s", "npy"])
    err = capsys.readouterr().err
    assert code == 1 and "does not support perspective input (--fov)" in err, err


@pytest.mark.parametrize("flag", ["--quads", "--triangles"])
def test_mesh_faces_without_a_mesh_output_are_warned_about(tmp_path, capsys, flag):
    """A review: --quads / --triangles with no mesh saved were ignored in silence, where
    --colors and --output-frame warn."""
    g = facetlift.synthetic.analytic("sphere", 24)
    np.save(tmp_path / "n.npy", np.where(g.mask[..., None], g.normals, np.nan))
    code = main(["integrate", str(tmp_path / "n.npy"), flag, "-o", str(tmp_path / "o"),
                 "-s", "npy"])
    err = capsys.readouterr().err
    said = (f"mesh faces as {flag[2:]} ({flag}, triangles={flag == '--triangles'} in Python) "
            "apply to the ply and obj meshes, neither of which is saved: add -s ply or -s obj")
    assert code == 0 and said in err, err


def test_info_takes_prior_blur_and_checks_a_blurred_relative_prior(tmp_path, capsys,
                                                                   near_sphere):
    """A review: `info ... --prior-blur 4`, integrate's flag, was refused as unknown; it is
    taken, a blurred prior's relief checked as integrate checks it, and without a prior
    refused as integrate refuses it."""
    n, depth, mask, K = near_sphere
    z = depth[mask]
    np.save(tmp_path / "n.npy", np.where(mask[..., None], n, np.nan))
    np.save(tmp_path / "p.npy", np.where(mask, (depth - z.min()) / np.ptp(z) * 0.99 + 0.01,
                                         np.nan))
    np.savetxt(tmp_path / "K.txt", K)
    args = ["info", str(tmp_path / "n.npy"), "--K", str(tmp_path / "K.txt")]
    code = main(args + ["--prior", str(tmp_path / "p.npy"), "--prior-blur", "4"])
    out = capsys.readouterr().out
    assert code == 0 and "relative relief (of log-depth)" in out, out
    assert "its background is blended in" in out.split("relative relief")[1].split("when")[1]
    code = main(args + ["--prior-blur", "4"])
    err = capsys.readouterr().err
    assert code == 1 and "--prior-blur 4 applies only with a prior" in err, err


def test_out_of_memory_while_writing_says_the_solve_had_finished(tmp_path, capsys,
                                                                  monkeypatch):
    """A review: a 4096^2 job that fit died writing preview.png after a 35 s solve, told to
    try a crop or a smaller map; it now names the output and that the solve had finished."""
    from facetlift import jobs

    def short(surface, kind, *a, **k):
        raise MemoryError("Unable to allocate 384. MiB")

    monkeypatch.setattr(jobs, "_write", short)
    g = facetlift.synthetic.analytic("sphere", 24)
    np.save(tmp_path / "n.npy", np.where(g.mask[..., None], g.normals, np.nan))
    code = main(["integrate", str(tmp_path / "n.npy"), "-o", str(tmp_path / "o"),
                 "-s", "png"])
    err = capsys.readouterr().err
    assert code == 1 and "writing preview.png after the solve had finished" in err, err
    assert "try a crop" not in err and not (tmp_path / "o").exists()


def test_sigterm_during_info_ends_with_its_message_and_no_word_on_outputs(tmp_path, capsys,
                                                                         monkeypatch):
    """A review: SIGTERM during `info` killed it by the signal, with no message and no --json
    object; Ctrl-C there said "nothing partial was written", though info writes nothing."""
    import signal

    from facetlift import describe

    def slow(*a, **k):
        signal.raise_signal(signal.SIGTERM)

    monkeypatch.setattr(describe, "describe", slow)
    g = facetlift.synthetic.analytic("sphere", 16)
    np.save(tmp_path / "n.npy", np.where(g.mask[..., None], g.normals, np.nan))
    code = main(["info", str(tmp_path / "n.npy"), "--json"])
    out, err = capsys.readouterr()
    assert code == 143 and json.loads(out)["status"] == "terminated", (out, err)
    assert "nothing partial" not in err
    assert signal.getsignal(signal.SIGTERM) is not None  # (put back)
