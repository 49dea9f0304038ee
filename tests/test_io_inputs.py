"""Readers of issue 12/11: palette and sub-8-bit PNGs, integer EXR channels, gradient files,
.mat files; and output sets (facetlift.io.OutputSet, sweep)."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from scipy import io as sio

import facetlift
from facetlift import io
from facetlift.io import atomic
from facetlift.io.gradients import read_gradient, read_gradients, read_mat


def png(path, pixels: np.ndarray, colour: int, depth: int, palette: bytes | None = None):
    """A minimal PNG written by hand (imagecodecs cannot write palette or 1-bit files)."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    H, W = pixels.shape[:2]
    if depth < 8:
        rows = [np.packbits(row.astype(np.uint8)).tobytes() for row in pixels]
    else:
        rows = [row.astype(np.uint8).tobytes() for row in pixels]
    raw = b"".join(b"\0" + r for r in rows)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, depth, colour,
                                                             0, 0, 0))
    if palette is not None:
        data += chunk(b"PLTE", palette)
    data += chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    path.write_bytes(data)
    return path


def test_palette_png_is_refused_as_normals(tmp_path):
    pal = bytes([128, 128, 255, 200, 128, 200])
    path = png(tmp_path / "p.png", np.zeros((4, 5), np.uint8), colour=3, depth=8, palette=pal)
    with pytest.raises(ValueError, match=r"p.png is a palette \(indexed colour\) PNG"):
        io.read_normals(path)


def test_one_bit_png_is_refused_as_normals_but_read_as_a_mask(tmp_path):
    bits = np.zeros((4, 8), bool)
    bits[1:3, 2:6] = True
    path = png(tmp_path / "b.png", bits, colour=0, depth=1)
    with pytest.raises(ValueError, match="b.png is a 1-bit PNG"):
        io.read_normals(path)
    np.testing.assert_array_equal(io.read_mask(path), bits)


def test_integer_exr_channels_are_refused(tmp_path):
    import OpenEXR

    ch = {c: np.full((4, 5), 7, np.uint32) for c in "RGB"}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, ch) as f:
        f.write(str(tmp_path / "u.exr"))
    with pytest.raises(ValueError, match=r"integer \(UINT\) channel\(s\) \['R', 'G', 'B'\]"):
        io.read_normals(tmp_path / "u.exr")


def test_values_outside_the_mask_are_never_inspected(tmp_path):
    n = np.zeros((12, 12, 3))
    n[..., 2] = 1
    mask = np.zeros((12, 12), bool)
    mask[2:10, 2:10] = True
    n[~mask] = [np.inf, -np.inf, np.nan]
    n[0, 0] = [0.5, 0.5, 0.5]
    s = facetlift.integrate(n, mask)
    assert np.isfinite(s.depth[mask]).all() and s.info["input"]["usable"] == mask.sum()


@pytest.mark.parametrize("ext", [".npy", ".exr", ".tif"])
def test_gradient_files_round_trip(tmp_path, ext):
    rng = np.random.default_rng(5)
    p, q = rng.normal(size=(2, 6, 7)).astype(np.float32)
    for name, a in (("p", p), ("q", q)):
        io.write_depth(tmp_path / f"{name}{ext}", a)  # one float channel, as a gradient file
    g = read_gradients(tmp_path / f"p{ext}", tmp_path / f"q{ext}")
    np.testing.assert_allclose(g["p"], p)
    np.testing.assert_allclose(g["q"], q)
    assert g["mask"] is None


def test_gradient_file_refusals(tmp_path):
    np.save(tmp_path / "i.npy", np.zeros((3, 3), np.int16))
    with pytest.raises(ValueError, match="pixel type int16; gradients must be floating"):
        read_gradient(tmp_path / "i.npy")
    np.save(tmp_path / "three.npy", np.zeros((3, 3, 2)))
    with pytest.raises(ValueError, match=r"must hold an \(H, W\) gradient map"):
        read_gradient(tmp_path / "three.npy")
    np.save(tmp_path / "a.npy", np.zeros((3, 3)))
    np.save(tmp_path / "b.npy", np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"`q`: .*b.npy has shape \(3, 4\)"):
        read_gradients(tmp_path / "a.npy", tmp_path / "b.npy")
    io.write_normals(tmp_path / "n.exr", np.zeros((3, 3, 3)))
    with pytest.raises(ValueError, match=r"must hold one channel; got channels \['B', 'G', 'R'\]"):
        read_gradient(tmp_path / "n.exr")


def test_mat_files_gradients_normals_and_keys(tmp_path):
    rng = np.random.default_rng(6)
    p, q = rng.normal(size=(2, 5, 6))
    mask = np.ones((5, 6))
    mask[0, 0] = 0
    sio.savemat(tmp_path / "g.mat", {"p": p, "q": q, "mask": mask, "u": p})
    g = read_mat(tmp_path / "g.mat")
    np.testing.assert_array_equal(g["p"], p)
    assert g["mask"].dtype == bool and not g["mask"][0, 0]
    sio.savemat(tmp_path / "renamed.mat", {"gx": p, "gy": q})
    g = read_mat(tmp_path / "renamed.mat", ["gx", "gy"])
    np.testing.assert_array_equal(g["q"], q)
    with pytest.raises(ValueError, match=r"has variables \['gx', 'gy'\]; asked for \['p', 'q'\]"):
        read_mat(tmp_path / "renamed.mat")
    n = rng.normal(size=(5, 6, 3))
    sio.savemat(tmp_path / "n.mat", {"Normal_gt": n})
    np.testing.assert_array_equal(read_mat(tmp_path / "n.mat")["normals"], n)
    with pytest.raises(ValueError, match="a normal map is"):
        read_mat(tmp_path / "n.mat", ["Normal_gt", "Normal_gt", "Normal_gt"])
    sio.savemat(tmp_path / "s.mat", {"p": p, "q": q[:, :3]})
    with pytest.raises(ValueError, match="must be .* arrays of one shape"):
        read_mat(tmp_path / "s.mat")
    # integer slopes (scaled by 1000, say) are refused as a .npy's are: they were read as
    # huge slopes, nearly all grazing (an audit)
    sio.savemat(tmp_path / "i.mat", {"p": (p * 1000).astype(np.int16), "q": q})
    with pytest.raises(ValueError, match=r"variable 'p' of .* has type int16; gradients must "
                       "be floating point"):
        read_mat(tmp_path / "i.mat")
    # a .mat given to --gradients (it holds both): named, not "unsupported format"
    from facetlift.io.gradients import read_gradients

    with pytest.raises(ValueError, match=r"is a MATLAB file, which holds p and q together: "
                       r"give it as the input itself"):
        read_gradients(tmp_path / "g.mat", tmp_path / "g.mat")


def test_mat_v73_and_garbage_are_clear_errors(tmp_path):
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(116) + b"\0" * 8 + b"\x00\x02IM"
    (tmp_path / "h.mat").write_bytes(header + b"\0" * 512)
    with pytest.raises(ValueError, match=r"v7.3 \(HDF5\) file.*-v7.*h5py"):
        read_mat(tmp_path / "h.mat")
    (tmp_path / "x.mat").write_bytes(b"not a mat file at all")
    with pytest.raises(ValueError, match="is not a readable .mat file"):
        read_mat(tmp_path / "x.mat")


# ------------------------------------------------------------------------------ output sets


def test_output_set_commits_all_or_nothing(tmp_path):
    out = tmp_path / "o"
    with atomic.OutputSet(out, ["a.npy", "b.npy"]) as s:
        np.save(s.path("a.npy"), np.zeros(2))
        np.save(s.path("b.npy"), np.ones(2))
        assert sorted(p.name for p in out.iterdir())[0].startswith(atomic.STAGING_PREFIX)
    assert sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy"]
    with pytest.raises(RuntimeError, match="second failed"):
        with atomic.OutputSet(out, ["a.npy", "b.npy"]) as s:
            np.save(s.path("a.npy"), np.full(2, 7.0))
            raise RuntimeError("second failed")
    assert sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy"]
    np.testing.assert_array_equal(np.load(out / "a.npy"), np.zeros(2))


def test_a_failed_output_set_removes_the_folders_it_made(tmp_path):
    """An audit: a failed -o new/sub removed sub/ but left new/, which it had made too; a
    folder that was there before stays."""
    with pytest.raises(RuntimeError, match="failed"):
        with atomic.OutputSet(tmp_path / "new" / "sub" / "o", ["a.npy"]) as s:
            np.save(s.path("a.npy"), np.zeros(2))
            raise RuntimeError("failed")
    assert not (tmp_path / "new").exists()
    (tmp_path / "kept").mkdir()
    with pytest.raises(RuntimeError, match="failed"):
        with atomic.OutputSet(tmp_path / "kept" / "o", ["a.npy"]):
            raise RuntimeError("failed")
    assert (tmp_path / "kept").is_dir() and not (tmp_path / "kept" / "o").exists()


def test_output_set_commit_that_fails_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    """A user's check: a folder named like one output (mkdir out/preview.png) left a new
    depth.npy and mesh.ply beside the staging folder, with a bare '[Errno 21]'."""
    out = tmp_path / "o"
    with atomic.OutputSet(out, ["a.npy", "b.npy"]) as s:
        np.save(s.path("a.npy"), np.zeros(2))
        np.save(s.path("b.npy"), np.zeros(2))
    (out / "c.npy").mkdir()
    with pytest.raises(OSError, match=r"c.npy: a folder of that name is in the way.*-o"):
        with atomic.OutputSet(out, ["a.npy", "b.npy", "c.npy"]) as s:
            for name in ("a.npy", "b.npy", "c.npy"):
                np.save(s.path(name), np.ones(2))
    assert sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy", "c.npy"]
    np.testing.assert_array_equal(np.load(out / "a.npy"), np.zeros(2))
    # a move that fails half-way puts back what the earlier ones replaced
    (out / "c.npy").rmdir()
    real = atomic.os.replace

    def replace(src, dst):  # (the staged b.npy cannot be moved in)
        if Path(dst).name == "b.npy" and Path(src).parent.name.startswith(atomic.STAGING_PREFIX):
            raise OSError(28, "No space left on device", str(dst))
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(OSError, match="left as it was"):
        with atomic.OutputSet(out, ["a.npy", "b.npy", "c.npy"]) as s:
            for name in ("a.npy", "b.npy", "c.npy"):
                np.save(s.path(name), np.ones(2))
    assert sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy"]
    np.testing.assert_array_equal(np.load(out / "a.npy"), np.zeros(2))
    np.testing.assert_array_equal(np.load(out / "b.npy"), np.zeros(2))

    # interrupted between two moves (SIGTERM, Ctrl-C: a review): no target is ever absent
    def interrupted(src, dst):
        if Path(dst).name == "b.npy" and Path(src).parent.name.startswith(atomic.STAGING_PREFIX):
            assert (out / "b.npy").exists()  # (the old one still in place)
            raise KeyboardInterrupt
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        with atomic.OutputSet(out, ["a.npy", "b.npy"]) as s:
            for name in ("a.npy", "b.npy"):
                np.save(s.path(name), np.ones(2))
    assert sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy"]
    np.testing.assert_array_equal(np.load(out / "a.npy"), np.zeros(2))


def test_output_set_removes_a_folder_it_created_on_failure(tmp_path):
    with pytest.raises(ValueError, match="boom"):
        with atomic.OutputSet(tmp_path / "new" / "deep"):
            raise ValueError("boom")
    assert not (tmp_path / "new" / "deep").exists()


def test_output_set_refuses_an_output_that_is_an_input(tmp_path):
    np.save(tmp_path / "depth.npy", np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"the output .*depth.npy is the input"):
        atomic.OutputSet(tmp_path, ["depth.npy"], inputs=[tmp_path / "depth.npy"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depth.npy"]


def test_output_set_refuses_a_file_as_folder_and_an_unwritable_one(tmp_path, monkeypatch):
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="exists and is not a directory"):
        atomic.OutputSet(tmp_path / "f")
    with pytest.raises(OSError, match="cannot create the output folder"):
        atomic.OutputSet(tmp_path / "f" / "sub")
    real = type(tmp_path).mkdir

    def refuse(self, *a, **k):
        if self.name.startswith(atomic.STAGING_PREFIX):
            raise PermissionError(13, "Permission denied")
        return real(self, *a, **k)

    monkeypatch.setattr(type(tmp_path), "mkdir", refuse)
    with pytest.raises(OSError, match="is not writable: Permission denied"):
        atomic.OutputSet(tmp_path / "ro")
    assert not (tmp_path / "ro").exists()


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_sweep_removes_what_killed_runs_left_and_keeps_live_ones(tmp_path):
    host, dead, live = atomic._host(), _dead_pid(), os.getpid()
    stale_dir = tmp_path / f"{atomic.STAGING_PREFIX}{host}-{dead}-0123abcd"
    stale_dir.mkdir()
    (stale_dir / "depth.npy").write_bytes(b"x" * 100)
    stale_tmp = tmp_path / f".mesh.ply.{host}.{dead}.89abcdef.tmp"
    stale_tmp.write_bytes(b"partial")
    live_tmp = tmp_path / f".mesh.ply.{host}.{live}.89abcdef.tmp"
    live_tmp.write_bytes(b"writing")
    other_host = tmp_path / f"{atomic.STAGING_PREFIX}otherhost-{dead}-0123abcd"
    other_host.mkdir()
    user = tmp_path / "notes.tmp"
    user.write_text("mine")
    removed = atomic.sweep(tmp_path)
    assert sorted(removed) == sorted([stale_dir, stale_tmp])
    assert live_tmp.exists() and other_host.exists() and user.exists()


def test_integer_npy_maps_decode_like_png_or_are_refused(tmp_path):
    n = np.zeros((4, 5, 3))
    n[..., 2] = 1.0
    png_path = io.write_normals(tmp_path / "n.png", n, bits=8)
    import imagecodecs

    np.save(tmp_path / "u8.npy", imagecodecs.png_decode(png_path.read_bytes()))
    np.testing.assert_array_equal(io.read_normals(tmp_path / "u8.npy")[0],
                                  io.read_normals(png_path)[0])
    np.save(tmp_path / "i64.npy", np.ones((4, 5, 3), np.int64))
    with pytest.raises(ValueError, match="pixel type int64; normal maps must be uint8, uint16"):
        io.read_normals(tmp_path / "i64.npy")


# ------------------------------------------------------------------------- Portable Float Map


def write_pfm(path, a, little=True):
    """A PFM file as MiDaS's and Middlebury's writers make it: rows from the bottom."""
    a = np.asarray(a, np.float32)
    kind = b"PF" if a.ndim == 3 else b"Pf"
    rows = np.ascontiguousarray(a[::-1]).astype("<f4" if little else ">f4")
    head = kind + b"\n%d %d\n%s\n" % (a.shape[1], a.shape[0], b"-1.0" if little else b"1.0")
    Path(path).write_bytes(head + rows.tobytes())
    return Path(path)


@pytest.mark.parametrize("little", [True, False])
def test_pfm_normal_map_is_read_top_row_first(tmp_path, little):
    """A PFM normal map (a renderer's or denoiser's normal AOV) is read as stored, its rows
    turned the right way up (the file keeps them from the bottom) in either byte order."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=(6, 5, 3))
    n[..., 2] = np.abs(n[..., 2]) + 1.0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    got, alpha = io.read_normals(write_pfm(tmp_path / "n.pfm", n, little))
    assert alpha is None
    np.testing.assert_allclose(got, n, atol=1e-6)


def test_pfm_planes_prior_depth_and_gradients(tmp_path):
    """A one-channel PFM is a depth prior (MiDaS writes its output so), a weight map, a
    ground-truth depth and a gradient component; NaN stays unknown."""
    d = np.arange(20, dtype=float).reshape(4, 5) + 1.0
    d[1, 2] = np.nan
    f = write_pfm(tmp_path / "d.pfm", d)
    np.testing.assert_array_equal(io.read_prior(f), d)
    np.testing.assert_array_equal(io.read_depth(f), d)
    np.testing.assert_array_equal(read_gradient(f), d)
    w = write_pfm(tmp_path / "w.pfm", np.full((4, 5), 0.5))
    np.testing.assert_array_equal(io.read_weights(w), np.full((4, 5), 0.5))


@pytest.mark.parametrize("data, words", [
    (b"P6\n2 2\n255\n" + bytes(12), "not a Portable Float Map"),
    (b"PF4\n2 2\n-1.0\n" + bytes(64), "not a Portable Float Map"),
    (b"Pf\n2 2\n0\n" + bytes(16), "must be a non-zero number"),
    (b"Pf\n2 2\n-1.0\n" + bytes(12), "12 bytes of pixels where its header (2 x 2, 1 channel(s)) "
                                     "asks for 16: a truncated file"),
    (b"Pf\n2 2\n-1.0\n" + bytes(17), "17 bytes of pixels where its header (2 x 2, 1 channel(s)) "
                                     "asks for 16: bytes after the pixels"),
    (b"Pf\n0 2\n-1.0\n", "declares an empty image (0 x 2)"),
])
def test_damaged_pfm_files_are_named(tmp_path, data, words):
    p = tmp_path / "bad.pfm"
    p.write_bytes(data)
    with pytest.raises(ValueError, match=re.escape(words)):
        io.read_prior(p)


def test_pfm_header_lines_ended_by_crlf_or_spaces(tmp_path):
    """Line-based readers (MiDaS's, Middlebury's) take a header with CR LF or trailing spaces;
    so does ours (a review: refused as 'truncated')."""
    d = np.arange(20, dtype="<f4").reshape(4, 5)
    for head in (b"Pf\r\n5 4\r\n-1.0\r\n", b"Pf\n5 4\n-1.000000  \n"):
        p = tmp_path / "h.pfm"
        p.write_bytes(head + d[::-1].tobytes())
        np.testing.assert_array_equal(io.read_prior(p), d)


def test_a_colour_pfm_is_no_depth(tmp_path):
    f = write_pfm(tmp_path / "c.pfm", np.ones((3, 4, 3)))
    with pytest.raises(ValueError, match=r"must hold an \(H, W\) depth prior map; got shape "):
        io.read_prior(f)


def test_pfm_masks_and_grey_weights(tmp_path):
    """A PFM mask (a renderer's alpha pass) is read as any float mask; a three-channel PFM of
    equal channels is a grey weight map, as RGB TIFF and PNG are (a review)."""
    m = np.zeros((4, 5))
    m[1:3, 1:4] = 1.0
    np.testing.assert_array_equal(io.read_mask(write_pfm(tmp_path / "m.pfm", m)), m > 0)
    with pytest.raises(ValueError, match="unsupported mask format '.pfm'"):  # (read only)
        io.write_mask(tmp_path / "out.pfm", m)
    w = np.full((4, 5), 0.25)
    w[0, 0] = np.nan
    got = io.read_weights(write_pfm(tmp_path / "w.pfm", np.dstack([w, w, w])))
    np.testing.assert_array_equal(got, w)
