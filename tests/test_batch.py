"""facetlift.batch and 'facetlift batch': items, isolated failures, the log, resume, and the
same results on the Dask local scheduler and on a real dask.distributed LocalCluster as in
this process."""

from __future__ import annotations

import contextlib
import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import facetlift
from facetlift import batch as fb
from facetlift import io
from facetlift.cli import main
from facetlift.jobs import Job


def maps(folder, n=4, H=16, W=18):
    """`n` normal maps of tilted waves as 16-bit PNGs, and their in-process depths."""
    folder.mkdir(parents=True, exist_ok=True)
    depths = {}
    for i in range(n):
        r, c = np.indices((H, W)) + 0.5
        p = 0.3 * np.cos(c / 3 + i)
        q = 0.2 * np.sin(r / 4 - i)
        path = io.write_normals(folder / f"m{i}.png", facetlift.normals_from_gradients(p, q))
        decoded, _ = io.read_normals(path)
        depths[f"m{i}"] = facetlift.integrate(decoded).depth
    return depths


def test_items_from_globs_folders_lists_and_masks(tmp_path):
    maps(tmp_path / "a", n=2)
    maps(tmp_path / "b", n=1)
    io.write_mask(tmp_path / "a" / "m0_mask.png", np.ones((16, 18)))
    ds = tmp_path / "ds" / "bear"
    ds.mkdir(parents=True)
    (ds / "normal_map.png").write_bytes((tmp_path / "b" / "m0.png").read_bytes())
    (tmp_path / "list.txt").write_text("# one per line\nb/m0.png\n\nds/bear  # a dataset\n")
    found = fb.items([tmp_path / "a", str(tmp_path / "b" / "*.png")],
                     list_file=tmp_path / "list.txt")
    assert [it.name for it in found] == ["m0", "m1", "m0-2", "bear"]
    assert found[0].mask.endswith("m0_mask.png") and found[1].mask is None
    assert [it.name for it in fb.items([tmp_path / "ds"])] == ["bear"]
    # a '#' inside a name is no comment (a user's 'obj#3.png' was cut to 'obj')
    (tmp_path / "b" / "obj#3.png").write_bytes((tmp_path / "b" / "m0.png").read_bytes())
    (tmp_path / "list2.txt").write_text("b/obj#3.png\t# the third\n  #b/m0.png\n")
    assert [it.name for it in fb.items([], list_file=tmp_path / "list2.txt")] == ["obj#3"]


def test_items_skip_lone_masks_and_say_what_a_folder_left_out(tmp_path):
    """A user's check: obj_normal.png + obj_mask.png ran the mask as a map (and failed) and
    the map without it; a folder of day folders ran nothing of them, without a word."""
    maps(tmp_path / "d", n=1)
    (tmp_path / "d" / "m0.png").rename(tmp_path / "d" / "obj_normal.png")
    io.write_mask(tmp_path / "d" / "obj_mask.png", np.ones((16, 18)))
    with pytest.warns(UserWarning, match=r"obj_mask.png\).*rename.*obj_normal_mask.png"):
        found = fb.items([tmp_path / "d"])
    assert [it.name for it in found] == ["obj_normal"]
    # named on its own, it is an item
    assert [it.name for it in fb.items([tmp_path / "d" / "obj_mask.png"])] == ["obj_mask"]
    maps(tmp_path / "days" / "day1", n=1)
    maps(tmp_path / "days" / "day2", n=1)
    (tmp_path / "days" / "stray.png").write_bytes((tmp_path / "days" / "day1" / "m0.png")
                                                   .read_bytes())
    with pytest.warns(UserWarning, match=r"skipped 2 subfolder\(s\).*day1, day2.*one level"):
        found = fb.items([tmp_path / "days"])
    assert [it.name for it in found] == ["stray"]
    # not for hidden folders, integrate's output folders or an unreadable one (a review)
    import shutil
    import warnings

    for name in (".ipynb_checkpoints", "stray_facetlift"):
        shutil.copytree(tmp_path / "days" / "day1", tmp_path / "days2" / name)
    (tmp_path / "days2" / "s.png").write_bytes((tmp_path / "days" / "stray.png").read_bytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [it.name for it in fb.items([tmp_path / "days2"])] == ["s"]


@pytest.mark.parametrize("inputs, message", [
    (["nothing/*.png"], "matches nothing"), (["missing.png"], "does not exist"),
])
def test_items_refusals(tmp_path, inputs, message):
    with pytest.raises(ValueError, match=message):
        fb.items([str(tmp_path / i) for i in inputs])
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no normal map found"):
        fb.items([tmp_path / "empty"])


def test_in_process_batch_isolates_failures_and_logs_each_item(tmp_path):
    depths = maps(tmp_path / "in", n=3)
    (tmp_path / "in" / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n cut")
    out = tmp_path / "out"
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), progress=False)
    status = {r["name"]: r["status"] for r in recs}
    assert status == {"broken": "error", "m0": "ok", "m1": "ok", "m2": "ok"}
    assert "not a readable PNG" in recs[0]["error"] and recs[0]["exit"] == 1
    for name, depth in depths.items():
        np.testing.assert_allclose(np.load(out / name / "depth.npy"), depth, atol=1e-12)
    log = [json.loads(line) for line in (out / fb.LOG_NAME).read_text().splitlines()]
    assert sorted(r["name"] for r in log) == sorted(status)
    assert all(r["mean_deviation"] is not None and r["seconds"] > 0
               for r in log if r["status"] == "ok")
    # (which mask each item used, as integrate --json says: a user asked)
    assert all(r["mask_source"] for r in log if r["status"] == "ok")
    assert not (out / "broken").exists()


def test_the_log_counts_each_item_s_missing_and_unusable_normals(tmp_path):
    """A photometric-stereo user's check: an item's 197 shadowed (NaN) normals were nowhere in
    batch.jsonl (missing normals are no warning)."""
    (tmp_path / "in").mkdir()
    r, c = np.indices((16, 18)) + 0.5
    n = facetlift.normals_from_gradients(0.3 * np.cos(c / 3), 0.2 * np.sin(r / 4))
    n[2:4, 5:8] = np.nan  # 6 missing
    n[9, 9] = 0.0  # 1 zero-length
    np.save(tmp_path / "in" / "a.npy", n)
    io.write_mask(tmp_path / "in" / "a_mask.png", np.ones((16, 18), bool))
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), progress=False)
    log = [json.loads(line) for line in (out / fb.LOG_NAME).read_text().splitlines()]
    counts = log[0]["normals"]
    assert counts["pixels"] == 288 and counts["missing"] == 6 and counts["zero-length"] == 1
    assert counts["usable"] == 288 - 7 and "zero_confidence" not in counts


def test_resume_skips_finished_items_and_retries_failed_ones(tmp_path, monkeypatch):
    maps(tmp_path / "in", n=3)
    out = tmp_path / "out"
    facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",))
    (out / "m1" / "depth.npy").unlink()  # an output lost since
    ran = []
    real = fb.run_item
    monkeypatch.setattr(fb, "run_item", lambda job: ran.append(job.normals) or real(job))
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)
    assert [r.get("resumed", False) for r in recs] == [True, False, True]
    assert len(ran) == 1 and ran[0].endswith("m1.png")
    assert (out / "m1" / "depth.npy").is_file()
    # other outputs, or another method, asked for now: every item runs again (they were all
    # skipped, and the batch reported success without the outputs asked for)
    for change in ({"save": ("npy", "obj")}, {"save": ("npy",), "method": "poisson"}):
        ran.clear()
        recs = facetlift.batch([tmp_path / "in"], out, workers=1, resume=True, **change)
        assert not any(r.get("resumed") for r in recs) and len(ran) == 3
        assert all(r["status"] == "ok" for r in recs)
    assert all((out / f"m{i}" / "mesh.obj").is_file() for i in range(3))
    ran.clear()  # (the same as the last run: nothing to do)
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, resume=True, save=("npy",),
                           method="poisson")
    assert all(r.get("resumed") for r in recs) and not ran
    # nor with the outputs in another order, or another memory limit (retrying the items
    # that failed for memory with a larger one ran every finished item again; review)
    facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy", "png"), method="poisson")
    ran.clear()
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, resume=True, method="poisson",
                           save=("png", "npy", "npy"), options={"max_memory": "64G"})
    assert all(r.get("resumed") for r in recs) and not ran


def test_every_kind_of_failure_is_a_record(tmp_path, monkeypatch):
    import importlib

    from facetlift.errors import MemoryLimitError, SolverError

    maps(tmp_path / "in", n=1)
    dgp = importlib.import_module("facetlift.methods.dgp")
    for exc, status, code in ((SolverError("singular"), "solver", 2),
                              (MemoryLimitError("needs 9 GiB"), "memory", 1),
                              (KeyError("x"), "bug", 3)):
        def fail(*a, _exc=exc, **k):
            raise _exc

        monkeypatch.setattr(dgp, "run", fail)
        (rec,) = facetlift.batch([tmp_path / "in"], tmp_path / status, workers=1)
        assert (rec["status"], rec["exit"]) == (status, code)
    # a failed item keeps the warnings it gave before failing (they may say why)
    import warnings

    def warn_then_fail(*a, **k):
        warnings.warn("a hint about the input", UserWarning, stacklevel=1)
        raise SolverError("singular")

    monkeypatch.setattr(dgp, "run", warn_then_fail)
    (rec,) = facetlift.batch([tmp_path / "in"], tmp_path / "w", workers=1)
    assert rec["status"] == "solver" and rec["warnings"] == ["a hint about the input"]


def test_bad_arguments(tmp_path):
    maps(tmp_path / "in", n=1)
    with pytest.raises(ValueError, match="`workers` must be a positive integer"):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=0)
    with pytest.raises(ValueError, match="give `job` or job options"):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", job=Job(), method="dgp")


@pytest.mark.parametrize("template, message", [
    ({"normal_frame": "bogus"}, "`normal_frame` must be one of"),
    ({"method": "nope"}, "`method` must be one of"),
    ({"save": ("npy", "xyz")}, r"`save`: unknown output\(s\) \['xyz'\]"),
    ({"options": {"foo": 1}}, r"unknown option\(s\) \['foo'\] for method 'dgp'"),
    ({"options": {"solver": "iterative", "tol": "x"}}, "`tol` must be a number"),
    ({"options": {"max_iter": 5}}, "`max_iter` applies only with solver='iterative'"),
    ({"options": {"max_memory": "lots"}}, "`max_memory` must be a number of bytes"),
    ({"gradient_frame": "zz"}, "`gradient_frame` must be one of"),
])
def test_a_bad_template_is_refused_once_before_any_item(tmp_path, template, message):
    """As the docstring says: a ValueError, not one error record per item; nothing is
    created or logged."""
    maps(tmp_path / "in", n=2)
    with pytest.raises(ValueError, match=message):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=1, **template)
    with pytest.raises(ValueError, match=message):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=1, job=Job(**template))
    assert not (tmp_path / "o").exists()


def test_cli_batch_with_a_bad_template_is_one_line(tmp_path, capsys):
    maps(tmp_path / "in", n=2)
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "--workers", "1",
                 "--option", "foo=1"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "unknown option(s) [--option foo]" in err
    assert not (tmp_path / "o").exists()


def test_dead_worker_processes_are_a_documented_error(tmp_path, capsys, monkeypatch):
    """The local pool breaking (a worker killed or out of memory) is WorkersDied (a
    RuntimeError) in the API and one line with exit 1 on the command line, not a bug."""
    dask = pytest.importorskip("dask")
    from concurrent.futures.process import BrokenProcessPool

    from facetlift.errors import WorkersDied

    def broken(*a, **k):
        raise BrokenProcessPool("A process in the process pool was terminated abruptly")

    monkeypatch.setattr(dask, "compute", broken)
    maps(tmp_path / "in", n=2)
    with pytest.raises(WorkersDied, match="worker processes died before finishing"):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=2, save=("npy",))
    assert issubclass(WorkersDied, RuntimeError)
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "p"), "--workers", "2",
                 "-s", "npy", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("facetlift: error: the batch's worker")
    assert "--resume" in lines[0] and "--workers 1" in lines[0] and "bug" not in lines[0]


def test_cli_batch_exit_codes_and_count(tmp_path, capsys):
    maps(tmp_path / "in", n=2)
    code = main(["batch", str(tmp_path / "in" / "*.png"), "-o", str(tmp_path / "o"),
                 "--workers", "1", "--save", "npy", "--no-progress"])
    out, _ = capsys.readouterr()
    assert code == 0 and "batch: 2 of 2 succeeded" in out
    (tmp_path / "in" / "z.png").write_bytes(b"bad")
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "--workers", "1",
                 "--resume", "--save", "npy", "--json"])
    out, err = capsys.readouterr()
    assert code == 1 and "batch: 2 of 3 succeeded (2 from an earlier run), 1 failed" in err
    assert "facetlift: error: z (error):" in err
    assert callable(fb) and fb.items is fb.__dict__["items"]
    recs = [json.loads(line) for line in out.splitlines()]
    assert [r["name"] for r in recs] == ["m0", "m1", "z"]
    # one record shape, the log's, for resumed and new items alike (the new ones printed
    # their whole record, info included)
    assert [r.get("resumed", False) for r in recs] == [True, True, False]
    assert "info" not in recs[2] and {"status", "error", "exit", "warnings"} <= set(recs[2])
    assert set(recs[0]) - {"resumed"} <= set(recs[2]) | {"outputs", "mean_deviation",
                                                         "shape", "facets", "converged",
                                                         "mask_source", "perspective",
                                                         "camera", "depth_range", "normals",
                                                         "evaluation", "prior_file",
                                                         "confidence_file", "colors_file",
                                                         "normal_rotation", "output_bytes"}
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "p"), "--workers", "1",
                 "-s", "npy", "--progress"])
    assert code == 1 and "batch:" in capsys.readouterr().err  # the bar, on stderr
    code = main(["batch", "-o", str(tmp_path / "o")])
    assert code == 1 and "give inputs" in capsys.readouterr().err


def test_a_missing_input_is_a_failed_item_not_the_end_of_the_batch(tmp_path, capsys):
    """A user's list of 40 maps with one stale line stopped before any item ran: a missing
    file or an empty pattern is now a failed record, the others run (only nothing found at
    all is refused)."""
    maps(tmp_path / "in", n=1)
    (tmp_path / "maps.txt").write_text("in/m0.png\nin/gone.png\n")
    out = tmp_path / "o"
    recs = facetlift.batch([str(tmp_path / "none" / "*.png")], out, workers=1, save=("npy",),
                           list_file=tmp_path / "maps.txt", progress=False)
    assert [(r["name"], r["status"]) for r in recs] == [
        ("m0", "ok"), ("pattern", "error"), ("gone.png", "error")]
    assert "matches nothing" in recs[1]["error"] and "gone.png does not exist" in recs[2]["error"]
    assert recs[1]["exit"] == recs[2]["exit"] == 1 and (out / "m0" / "depth.npy").is_file()
    assert not (out / "gone.png").exists()
    log = [json.loads(line) for line in (out / fb.LOG_NAME).read_text().splitlines()]
    assert sorted(r["status"] for r in log) == ["error", "error", "ok"]
    # the command line: the count says so, exit 1; --resume runs the map once it is there
    code = main(["batch", "--list", str(tmp_path / "maps.txt"), "-o", str(tmp_path / "p"),
                 "--workers", "1", "-s", "npy", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 1 and "batch: 1 of 2 succeeded" in out and "gone.png does not exist" in err
    maps(tmp_path / "more", n=1)
    (tmp_path / "more" / "m0.png").rename(tmp_path / "in" / "gone.png")
    code = main(["batch", "--list", str(tmp_path / "maps.txt"), "-o", str(tmp_path / "p"),
                 "--workers", "1", "-s", "npy", "--no-progress", "--resume"])
    out, _ = capsys.readouterr()
    assert code == 0 and "batch: 2 of 2 succeeded (1 from an earlier run)" in out


def test_one_input_as_a_str_or_a_path(tmp_path):
    """A Python user's batch('maps/sphere.npy', ...) was read letter by letter (each letter a
    missing input, '.' the working folder); a Path raised a bare TypeError."""
    maps(tmp_path / "in", n=1)
    one = tmp_path / "in" / "m0.png"
    for given in (str(one), one):
        recs = facetlift.batch(given, tmp_path / "o", workers=1, save=("npy",), progress=False)
        assert [(r["name"], r["status"]) for r in recs] == [("m0", "ok")]


def test_fov_and_output_frame_in_templates_and_resume_settings(tmp_path):
    """A bad fov, or one with K or orthographic, is refused once for the template, not per
    item; the resume settings leave unset new fields out (older logs stay complete) and read
    an output frame's spellings alike (a review)."""
    from facetlift.jobs import read

    for job, match in ((Job(fov=200.0), "`fov` must be a horizontal field of view"),
                       (Job(fov=60.0, orthographic=True), "`fov` 60 and `orthographic`"),
                       (Job(fov=60.0, K="K.txt"), "`fov` 60 and `K` contradict")):
        with pytest.raises(ValueError, match=match):
            fb.check_template(job)
    maps(tmp_path / "in", n=1)
    np.savetxt(tmp_path / "K.txt", np.diag([50.0, 50.0, 1.0]) + [[0, 0, 8.5], [0, 0, 7.5],
                                                                  [0, 0, 0]])
    with pytest.raises(ValueError, match="`fov` 60 and `K` contradict"):
        read(Job(normals=str(tmp_path / "in" / "m0.png"), K=str(tmp_path / "K.txt"), fov=60.0))
    plain = fb.settings(Job())
    assert "fov" not in plain and "output_frame" not in plain and "height_range" not in plain
    assert fb.settings(Job(height_range=(-1, 2)))["height_range"] == [-1, 2]
    assert "normal_encoding" not in plain
    assert fb.settings(Job(normal_encoding="xy"))["normal_encoding"] == "xy"
    with pytest.raises(ValueError, match="`normal_encoding` must be one of"):
        fb.check_template(Job(normal_encoding="rg"))
    assert "normal_range" not in plain
    assert fb.settings(Job(normal_range="unsigned"))["normal_range"] == "unsigned"
    with pytest.raises(ValueError, match="`normal_range` must be one of"):
        fb.check_template(Job(normal_range="01"))
    with pytest.raises(ValueError, match="`height_range` must be two finite numbers"):
        fb.check_template(Job(height_range=(2, -1)))
    a, b, c = (fb.settings(Job(output_frame=f)) for f in ("opencv", "OpenCV", "x,-y,-z"))
    assert a == b == c and a["output_frame"] == "x,-y,-z"
    assert fb.settings(Job(output_frame="opengl")) == plain
    # the weight's default recorded as the result takes it (logs before it was None said 1;
    # a review: every item of an old log ran again), --strict off left out as before it was
    assert plain["prior_weight"] == 1.0 and "strict" not in plain
    assert fb.settings(Job(prior_weight=1.0)) == plain
    assert fb.settings(Job(prior_blur=4.0))["prior_weight"] == 0.003
    assert fb.settings(Job(strict=True))["strict"] is True


def test_the_default_workers_without_dask_run_in_this_process(tmp_path, monkeypatch):
    """Without the batch extra the default is one worker (it was the CPU count, which then
    failed for want of Dask); an explicit workers=2 still names the extra."""
    import builtins

    real_import = builtins.__import__

    def no_dask(name, *a, **k):
        if name == "dask" or name.startswith("dask."):
            raise ImportError("No module named 'dask'")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    monkeypatch.setattr(fb.os, "cpu_count", lambda: 4)  # (on one CPU the default was 1 anyway)
    maps(tmp_path / "in", n=2)
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "o", save=("npy",))
    assert [r["status"] for r in recs] == ["ok", "ok"]
    with pytest.raises(ImportError, match=r"facetlift\[batch\]"):
        facetlift.batch([tmp_path / "in"], tmp_path / "p", workers=2, save=("npy",))


def _sleep_forever():  # (a worker task that never ends by itself)
    import time

    time.sleep(600)


def test_an_interrupted_pool_is_stopped_at_once():
    """_stop terminates the pool's workers (a Ctrl-C used to wait for the running items, or
    hang at exit), and leaves the host's own child processes alone."""
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    base = multiprocessing.get_context("spawn")
    host = base.Process(target=_sleep_forever, daemon=True)  # a process of the caller's
    ctx = fb._Recording(base)
    pool = ProcessPoolExecutor(2, mp_context=ctx, initializer=fb._worker_start)
    try:
        futures = [pool.submit(_sleep_forever) for _ in range(2)]
        host.start()  # (started while the batch runs: still not ours)
        deadline = time.monotonic() + 60
        while len(pool._processes) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = list(pool._processes.values())
        assert sorted(p.pid for p in workers) == sorted(p.pid for p in ctx.started)
        t0 = time.monotonic()
        fb._stop(pool, ctx.started)
        assert time.monotonic() - t0 < fb.STOP_GRACE + 1
        assert workers and not any(p.is_alive() for p in workers)
        assert all(f.cancelled() or f.done() for f in futures)
        assert host.is_alive()  # not ours
    finally:
        host.kill()


def test_cli_batch_shows_each_items_warnings(tmp_path, capsys):
    """A warning of one item (here: a y-flipped map) is shown on stderr with the item's name,
    as integrate shows it; it was only in the log."""
    folder = tmp_path / "in"
    folder.mkdir()
    r, c = np.indices((30, 36)) + 0.5  # z = 4 sin(c / 4) cos(r / 5): y up is minus the row
    n = facetlift.normals_from_gradients(np.cos(c / 4) * np.cos(r / 5),
                                         0.8 * np.sin(c / 4) * np.sin(r / 5))
    io.write_normals(folder / "flipped.png", n * [1, -1, 1])
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1", "-s", "npy",
                 "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0 and "facetlift: warning: flipped: the normals are far more integrable " \
        "with x or y flipped" in err  # (a map filling its image: no silhouette)


def test_dask_local_processes_equal_in_process(tmp_path, monkeypatch):
    dask = pytest.importorskip("dask")
    depths = maps(tmp_path / "in", n=4)
    asked = []
    real = dask.compute

    def spy(*a, **k):
        asked.append(k)
        return real(*a, **k)

    monkeypatch.setattr(dask, "compute", spy)
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=2, save=("npy",))
    assert [r["status"] for r in recs] == ["ok"] * 4
    # every item dispatched alone (Dask's default chunk of 6 ran these 4 in one worker, one
    # after another, and logged none of them before all had finished)
    assert [k.get("chunksize") for k in asked] == [1]
    for name, depth in depths.items():
        np.testing.assert_allclose(np.load(tmp_path / "o" / name / "depth.npy"), depth,
                                   atol=1e-12)


def test_cli_batch_says_an_items_error_when_it_is_done(tmp_path, capsys, monkeypatch):
    """A user's check: errors and warnings came after the last item (and never for a batch
    stopped before its end); the summary counted an item whose frame was wrong as a plain
    success."""
    import sys

    from facetlift import jobs

    maps(tmp_path / "in", n=1)
    (tmp_path / "in" / "a.png").write_bytes(b"bad")  # (sorted before m0.png)
    real = jobs.run

    def run(job, **kw):
        sys.stderr.write(f"RUNNING {Path(job.normals).name}\n")
        return real(job, **kw)

    monkeypatch.setattr(jobs, "run", run)
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "--workers", "1",
                 "--save", "npy", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 1
    assert err.index("facetlift: error: a (error):") < err.index("RUNNING m0.png"), err
    assert "batch: 1 of 2 succeeded, 1 failed" in out
    # an item that succeeded with a warning is counted as such (here a normal facing away)
    n = io.read_normals(tmp_path / "in" / "m0.png")[0]
    n[5, 6] = [0.0, 0.6, -0.8]
    (tmp_path / "in2").mkdir()
    io.write_normals(tmp_path / "in2" / "odd.png", n)
    code = main(["batch", str(tmp_path / "in2"), "-o", str(tmp_path / "o2"), "--no-progress",
                 "--save", "npy"])
    out, err = capsys.readouterr()
    assert code == 0 and "warning: odd:" in err
    assert "batch: 1 of 1 succeeded (1 with warnings)" in out
    # ... and so is one from an earlier run (a user's resumed batch hid its wrong-frame
    # warning): the summary says that its warnings are in the log
    code = main(["batch", str(tmp_path / "in2"), "-o", str(tmp_path / "o2"), "--no-progress",
                 "--save", "npy", "--resume"])
    out, err = capsys.readouterr()
    assert code == 0 and "warning: odd:" not in err
    assert ("batch: 1 of 1 succeeded (1 from an earlier run; 1 with warnings, 1 of those in "
            "the log only)") in out


def test_batch_warns_of_a_camera_file_beside_plain_maps(tmp_path):
    """A user's rig folder (maps, masks and K.txt, no normal_map.*) was integrated
    orthographically without a word; the records did not say whether a camera was used."""
    maps(tmp_path / "rig", n=1)
    (tmp_path / "rig" / "K.txt").write_text("600 0 9\n0 600 8\n0 0 1\n")
    with pytest.warns(UserWarning, match=r"holds K.txt beside its normal maps.*--K"):
        recs = facetlift.batch([tmp_path / "rig"], tmp_path / "o", save=("npy",))
    assert recs[0]["status"] == "ok" and recs[0]["perspective"] is False
    assert fb.log_record(recs[0])["perspective"] is False
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (given as --K: no warning)
        recs = facetlift.batch([tmp_path / "rig"], tmp_path / "p", save=("npy",),
                               K=str(tmp_path / "rig" / "K.txt"))
        assert recs[0]["perspective"] is True
        # (nor where orthographic was asked for: a review)
        facetlift.batch([tmp_path / "rig"], tmp_path / "q", save=("npy",), orthographic=True)


def test_abandoned_items_are_swept_also_in_folders_that_existed(tmp_path):
    """A review: workers that die at once on SIGTERM left their staging folders in item
    folders that existed before the batch (only the batch's own folders were swept)."""
    import signal

    from facetlift.io import atomic

    old, new = tmp_path / "old", tmp_path / "new"
    for folder in (old, new):
        (folder / f"{atomic.STAGING_PREFIX}{atomic._host()}-999999-deadbeef").mkdir(parents=True)
    (old / "depth.npy").write_bytes(b"kept")
    fb._clean_abandoned([old, new], {old})
    assert [p.name for p in old.iterdir()] == ["depth.npy"] and not new.exists()
    # a worker's SIGTERM is the default again, whatever the parent had installed (fork)
    before = signal.getsignal(signal.SIGTERM)
    try:
        signal.signal(signal.SIGTERM, atomic._raise_terminated)
        atomic.die_on_sigterm()
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    finally:
        atomic._WORKER = False
        signal.signal(signal.SIGTERM, before)


def test_distributed_local_cluster_with_two_workers_equals_in_process(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    depths = maps(tmp_path / "in", n=4)
    (tmp_path / "in" / "bad.png").write_bytes(b"bad")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert len(cluster.workers) == 2
        code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"),
                     "--scheduler", cluster.scheduler_address, "--save", "npy"])
        with distributed.Client(cluster) as client:  # the API with a Client
            recs = facetlift.batch([tmp_path / "in" / "m0.png"], tmp_path / "api",
                                   scheduler=client, save=("npy",))
    out, err = capsys.readouterr()
    assert code == 1 and "batch: 4 of 5 succeeded, 1 failed" in out
    assert "facetlift: error: bad (error):" in err
    for name, depth in depths.items():
        np.testing.assert_allclose(np.load(tmp_path / "o" / name / "depth.npy"), depth,
                                   atol=1e-12)
    assert recs[0]["status"] == "ok"
    np.testing.assert_allclose(np.load(tmp_path / "api" / "m0" / "depth.npy"), depths["m0"],
                               atol=1e-12)


_STARTED = []  # (the items _slow_item began: in-process cluster workers share it)


def _slow_item(job, *a, **kw):
    import time

    _STARTED.append(job)
    time.sleep(0.4)
    return fb._failed("error", "stub", seconds=0.4)


def test_an_interrupted_cluster_batch_cancels_its_tasks(tmp_path, monkeypatch):
    """Ctrl-C in a batch on a cluster left its submitted tasks running there (a review):
    the futures are cancelled now."""
    distributed = pytest.importorskip("distributed")
    import time

    maps(tmp_path / "in", n=6, H=8, W=8)
    _STARTED.clear()
    monkeypatch.setattr(fb, "run_item", _slow_item)

    def interrupt(rec):
        raise KeyboardInterrupt

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        with pytest.raises(KeyboardInterrupt):
            fb.batch([tmp_path / "in"], tmp_path / "o", scheduler=client, on_record=interrupt)
        time.sleep(1.5)  # (time for four more items, had they not been cancelled)
        assert len(_STARTED) <= 2, len(_STARTED)
        assert not client.futures


def test_an_interrupted_batch_leaves_no_empty_folder_of_an_abandoned_item(tmp_path,
                                                                          monkeypatch):
    """A worker stopped mid-item cannot clean up: an interrupted batch left an empty folder
    for each running item (a fresh-user check). Folders that were there before stay."""
    maps(tmp_path / "in", n=3)
    out = tmp_path / "out"
    (out / "m2").mkdir(parents=True)  # (there before the batch: kept)
    real = fb.run_item

    def interrupted(job, threads=None):
        if job.normals.endswith("m1.png"):
            Path(job.outdir).mkdir(parents=True)  # (as OutputSet does first)
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(fb, "run_item", interrupted)
    with pytest.raises(KeyboardInterrupt):
        facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",))
    assert (out / "m0" / "depth.npy").is_file()  # (finished before the interrupt)
    assert not (out / "m1").exists() and (out / "m2").is_dir()


def test_on_record_gets_each_record_as_it_is_known(tmp_path):
    maps(tmp_path / "in", n=2)
    seen = []
    recs = fb.batch([str(tmp_path / "in")], tmp_path / "o", workers=1, save=("npy",),
                    on_record=lambda r: seen.append((r["name"], r["status"],
                                                     (tmp_path / "o" / fb.LOG_NAME).read_text()
                                                     .count("\n"))))
    # each after its log line, so an interrupt loses nothing a caller was shown
    assert [s[:2] for s in seen] == [("m0", "ok"), ("m1", "ok")] and [s[2] for s in seen] == [1, 2]
    seen.clear()
    fb.batch([str(tmp_path / "in")], tmp_path / "o", workers=1, save=("npy",), resume=True,
             on_record=lambda r: seen.append((r["name"], r.get("resumed"))))
    assert seen == [("m0", True), ("m1", True)] and len(recs) == 2


def test_names_stay_apart_and_resume_sees_changed_inputs(tmp_path):
    """A map added beside another of the same stem never takes its folder, and a map replaced
    under its old name runs again (both reported success over one overwritten folder)."""
    maps(tmp_path / "in", n=2)
    out = tmp_path / "o"
    first = fb.batch([tmp_path / "in"], out, workers=1, save=("npy",))
    assert [r["name"] for r in first] == ["m0", "m1"]
    np.save(tmp_path / "in" / "m0.npy", np.dstack([np.zeros((5, 6, 2)), np.ones((5, 6))]))
    again = fb.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)
    by = {Path(r["item"]).name: r for r in again}
    assert by["m0.png"].get("resumed") and by["m0.png"]["name"] == "m0"
    assert by["m0.npy"]["name"] == "m0_npy" and by["m0.npy"]["shape"] == [5, 6]
    assert np.load(out / "m0" / "depth.npy").shape == (16, 18)  # not overwritten
    # m1.png replaced by another map under its name: run again, not resumed
    (tmp_path / "in" / "m1.png").write_bytes((tmp_path / "in" / "m0.png").read_bytes())
    third = {Path(r["item"]).name: r for r in fb.batch([tmp_path / "in"], out, workers=1,
                                                          save=("npy",), resume=True)}
    assert not third["m1.png"].get("resumed") and third["m0.png"].get("resumed")
    # two extensions from the start: each named by its extension, whatever the order
    assert [it.name for it in fb.items([tmp_path / "in"])] == ["m0_npy", "m0_png", "m1"]
    # one name in three folders, the first kept from an earlier run: the two new ones must
    # not both be renamed onto the same folder
    for sub in ("x", "y", "z"):
        maps(tmp_path / sub, n=1)
    out2 = tmp_path / "o2"
    fb.batch([tmp_path / "x" / "m0.png"], out2, workers=1, save=("npy",))
    recs = fb.batch([tmp_path / s / "m0.png" for s in ("y", "z", "x")], out2, workers=1,
                    save=("npy",), resume=True)
    names = [r["name"] for r in recs]
    assert len(set(names)) == 3 and names[2] == "m0", names


def test_links_and_explicit_mask_named_files_are_items(tmp_path):
    maps(tmp_path / "in", n=1)
    real = tmp_path / "in" / "m0.png"
    (tmp_path / "in" / "l1.png").symlink_to(real)
    (tmp_path / "in" / "l2.png").symlink_to(real)
    assert [it.name for it in fb.items([tmp_path / "in"])] == ["l1", "l2", "m0"]
    # a map whose name ends in _mask with no X beside it is a map; named, always an item
    (tmp_path / "in" / "gas_mask.png").write_bytes(real.read_bytes())
    assert "gas_mask" in [it.name for it in fb.items([tmp_path / "in"])]
    io.write_mask(tmp_path / "in" / "m0_mask.png", np.ones((16, 18)))
    assert "m0_mask" not in [it.name for it in fb.items([tmp_path / "in"])]
    assert [it.name for it in fb.items([tmp_path / "in" / "m0_mask.png"])] == ["m0_mask"]
    # a shell-expanded *.png names the mask with its map: still the map's mask
    listed = sorted((tmp_path / "in").glob("*.png"))
    found = fb.items(listed)
    assert "m0_mask" not in [it.name for it in found]
    assert [it.mask for it in found if it.name == "m0"][0].endswith("m0_mask.png")
    # extensions in capitals
    (tmp_path / "caps").mkdir()
    (tmp_path / "caps" / "A.PNG").write_bytes(real.read_bytes())
    io.write_mask(tmp_path / "caps" / "A_mask.png", np.ones((16, 18)))
    (tmp_path / "caps" / "A_mask.png").rename(tmp_path / "caps" / "A_mask.PNG")
    (only,) = fb.items([tmp_path / "caps"])
    assert only.name == "A" and only.mask.endswith("A_mask.PNG")


def test_bad_pixel_size_is_refused_before_any_item(tmp_path):
    maps(tmp_path / "in", n=1)
    with pytest.raises(ValueError, match="`pixel_size` must be a positive finite number"):
        fb.batch([tmp_path / "in"], tmp_path / "o", workers=1, pixel_size=-1.0)
    assert not (tmp_path / "o").exists()


def _children(pid):
    """PIDs whose parent is `pid` (Linux /proc)."""
    import os

    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_sigterm_stops_a_parallel_batch_and_its_workers(tmp_path):
    """SIGTERM is handled like Ctrl-C: exit 143, the workers stopped (they ran on, orphaned)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    pytest.importorskip("dask")
    maps(tmp_path / "in", n=8, H=120, W=140)
    exe = Path(sys.executable).with_name("facetlift")
    proc = subprocess.Popen([str(exe), "batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"),
                             "--workers", "2", "--discontinuities", "-s", "npy",
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 60
    kids = []
    while time.monotonic() < deadline and len(kids) < 2 and proc.poll() is None:
        kids = _children(proc.pid)
        time.sleep(0.05)
    if proc.poll() is not None:
        pytest.skip("the batch finished before it could be signalled")
    time.sleep(0.3)
    kids = _children(proc.pid)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "terminated (SIGTERM or SIGHUP)" in err and "Traceback" not in err, err
    time.sleep(0.5)
    alive = []
    for pid in kids:
        try:
            os.kill(pid, 0)
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().rsplit(")", 1)[1].split()[0] != "Z":  # (a zombie is gone)
                    alive.append(pid)
        except OSError:
            pass
    assert not alive, f"workers left running: {alive}"


def test_method_options_as_keywords(tmp_path):
    maps(tmp_path / "in", n=1)
    (rec,) = facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=1, save=("npy",),
                             discontinuities=True)
    assert rec["status"] == "ok" and rec["settings"]["options"] == {"discontinuities": True}
    with pytest.raises(ValueError, match="unknown option"):
        facetlift.batch([tmp_path / "in"], tmp_path / "p", workers=1, save=("npy",), nope=1)


def test_mask_rules_with_several_maps_of_one_stem_and_capital_mask(tmp_path):
    maps(tmp_path / "in", n=1)
    d = tmp_path / "in"
    (d / "m0.npy").write_bytes(b"")  # (another map of the stem, not named below)
    io.write_mask(d / "m0_mask.png", np.ones((16, 18)))
    found = fb.items([d / "m0.png", d / "m0_mask.png"])
    assert [it.name for it in found] == ["m0"] and found[0].mask.endswith("m0_mask.png")
    # "_MASK" is not the mask suffix: not dropped in silence (a grey file that pairs with no
    # map: skipped with the warning that names such files; an item where named)
    io.write_mask(d / "x_MASK.png", np.ones((16, 18)))
    with pytest.warns(UserWarning, match=r"skipped 1 one-channel file\(s\).*\(x_MASK.png\)"):
        assert "x_MASK" not in [it.name for it in fb.items([d])]
    assert [it.name for it in fb.items([d / "x_MASK.png"])] == ["x_MASK"]


def test_a_template_takes_progress_true_as_integrate_does():
    """check_template refused progress=True with a message that offered True (a review)."""
    from facetlift.batch import check_template
    from facetlift.jobs import Job

    check_template(Job(normals="x.npy", options={"progress": True}))
    with pytest.raises(ValueError, match=r"`progress` must be True .*; got 'x'"):
        check_template(Job(normals="x.npy", options={"progress": "x"}))


def test_bad_batch_arguments_are_refused_before_any_item_or_folder(tmp_path):
    """An audit: an array K (or mask, prior) reached every item as a path (a 'bug' record
    each), save="npy" was read letter by letter, workers=0 was refused after the output
    folder was made; a single output name is one output."""
    maps(tmp_path / "in", n=2)
    for kw, match in (({"K": np.eye(3)}, r"`K` of a batch is a file path .* got ndarray"),
                      ({"mask": np.ones((4, 4), bool)}, r"`mask` of a batch is a file path"),
                      ({"workers": 0}, r"`workers` must be a positive integer")):
        with pytest.raises(ValueError, match=match):
            facetlift.batch([tmp_path / "in"], tmp_path / "o", **kw)
        assert not (tmp_path / "o").exists()
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "o", save="npy", workers=1)
    assert [r["status"] for r in recs] == ["ok", "ok"]
    assert all(set(r["outputs"]) == {"npy"} for r in recs)
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "d", save=None, workers=1)
    assert [r["status"] for r in recs] == ["ok", "ok"]  # (None: the default outputs)


def test_a_dataset_folders_map_given_as_a_file_is_warned_about_once(tmp_path):
    """The final read: a dataset folder's normal_map.* given by its path was warned about by
    the batch (as maps beside a K.txt) and by its item (jobs._beside_dataset_files, which
    names the mask too); the item's warning alone stays."""
    maps(tmp_path / "ds", n=1)
    (tmp_path / "ds" / "m0.png").rename(tmp_path / "ds" / "normal_map.png")
    (tmp_path / "ds" / "K.txt").write_text("600 0 9\n0 600 8\n0 0 1\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recs = facetlift.batch([tmp_path / "ds" / "normal_map.png"], tmp_path / "o",
                               save=("npy",), workers=1)
    assert not [w for w in caught if "holds K.txt beside its normal maps" in str(w.message)]
    assert any("lies in a dataset folder whose K.txt" in w for w in recs[0]["warnings"])


def test_workers_that_cannot_import_a_stdin_script_are_named(monkeypatch):
    """A batch started from a script read from stdin died with the advice to add a __main__
    guard, which does not help: the workers cannot re-import a script without a file (a
    user's check); it says so now, and nothing for a script file."""
    import sys
    import types

    main = types.ModuleType("__main__")
    main.__file__ = "<stdin>"
    monkeypatch.setitem(sys.modules, "__main__", main)
    assert "read from stdin" in fb._no_script_file()
    main.__file__ = "/tmp/run.py"
    assert fb._no_script_file() is None


def _frames(folder, n=2, H=32, W=40):
    """A video's frames as a monocular-depth workflow leaves them: `n` normal maps
    frame_00i.png (16-bit RGB), each with its relative depth frame_00i_prior_depth.png (grey
    16-bit counts, an affine function of the true depth, as a network's) and its
    frame_00i_confidence.png (grey 8-bit); their in-process depths without a prior. (At
    16 x 18 the fit finds no scale and leaves the prior out.)"""
    depths = maps(folder, n=n, H=H, W=W)
    for i in range(n):
        (folder / f"m{i}.png").rename(folder / f"frame_00{i}.png")
        d = depths[f"m{i}"]
        counts = 2000 + 40000 * (d - d.min()) / np.ptp(d)
        _png(folder / f"frame_00{i}_prior_depth.png", counts.astype(np.uint16))
        _png(folder / f"frame_00{i}_confidence.png", np.full((H, W), 200, np.uint8))
    return depths


def _png(path, array):
    import imagecodecs

    Path(path).write_bytes(imagecodecs.png_encode(array))


def test_a_folder_of_frames_pairs_each_map_with_its_own_prior_and_confidence(tmp_path,
                                                                            capsys):
    """An audit of a video workflow (per-frame normals from a network, per-frame monocular
    depth): `facetlift batch FOLDER` ran the grey 16-bit frame_000_prior_depth.png files as
    normal maps ("must be an (H, W, 3) RGB ...", exit 1) and integrated each frame without
    its prior. NAME_prior_depth.* and NAME_confidence.* beside NAME.* are that map's own, as
    NAME_mask.* is (a dataset folder's prior_depth.* and confidence.*), no items; the record
    names them; --prior-fit aligns each frame's own (a 16-bit relative PNG needs no
    --prior-scale with it); --no-prior / --no-confidence leave them unread; --prior given for
    the whole batch takes precedence over them, with one warning."""
    folder = tmp_path / "frames"
    _frames(folder)
    found = fb.items([folder])
    assert [it.name for it in found] == ["frame_000", "frame_001"]
    assert found[0].prior == str(folder / "frame_000_prior_depth.png")
    assert found[1].confidence == str(folder / "frame_001_confidence.png")
    # (a shell-expanded *.png names them with their maps: still theirs)
    assert [it.name for it in fb.items(sorted(folder.glob("*.png")))] == ["frame_000",
                                                                          "frame_001"]
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1",
                 "-s", "npy", "--prior-fit", "affine", "--json", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0, err
    recs = {r["name"]: r for r in map(json.loads, out.splitlines())}
    assert sorted(recs) == ["frame_000", "frame_001"]
    for i in range(2):
        rec = recs[f"frame_00{i}"]
        assert rec["status"] == "ok", rec
        assert rec["prior_file"] == str(folder / f"frame_00{i}_prior_depth.png")
        assert rec["confidence_file"] == str(folder / f"frame_00{i}_confidence.png")
        # (its own files count as its inputs: --resume runs it again where one changed)
        assert [f[0] for f in rec["input_stamp"]] == [
            f"frame_00{i}.png", f"frame_00{i}_prior_depth.png", f"frame_00{i}_confidence.png"]
    # in Python alike, each item's prior fitted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recs = facetlift.batch([folder], tmp_path / "p", workers=1, save=("npy",),
                               prior_fit="affine")
    assert all(r["status"] == "ok" and r["info"]["prior"]["fit"]["used"] and not r["warnings"]
               for r in recs), recs
    # --no-prior / --no-confidence: the normals alone, the files still no items
    code = main(["batch", str(folder), "-o", str(tmp_path / "n"), "--workers", "1",
                 "-s", "npy", "--no-prior", "--no-confidence", "--json", "--no-progress"])
    out, err = capsys.readouterr()
    recs = [json.loads(line) for line in out.splitlines()]
    assert code == 0 and len(recs) == 2, err
    assert all(r["prior_file"] is None and r["confidence_file"] is None for r in recs)
    # one --prior for the whole batch takes precedence, and says so once
    np.save(tmp_path / "scene.npy", np.full((32, 40), 5.0))
    code = main(["batch", str(folder), "-o", str(tmp_path / "s"), "--workers", "1",
                 "-s", "npy", "--prior", str(tmp_path / "scene.npy"), "--json",
                 "--no-progress"])
    out, err = capsys.readouterr()
    recs = [json.loads(line) for line in out.splitlines()]
    assert code == 0, err
    assert all(r["prior_file"] == str(tmp_path / "scene.npy") for r in recs)
    assert all(r["confidence_file"].endswith("_confidence.png") for r in recs)
    said = [line for line in err.splitlines() if "in place of the NAME_prior_depth.*" in line]
    assert len(said) == 1 and "--prior " in said[0] and "2 item(s)" in said[0], err
    assert "leave --prior out" in said[0]


def test_a_frames_own_prior_that_cannot_be_read_names_the_file_and_no_prior(tmp_path, capsys):
    """A frame's own prior refused (a 16-bit PNG without --prior-scale or --prior-fit, or of
    another size) names the file and --no-prior, which the user may not know applies to
    files found beside the maps; two priors beside one map are an error of that item."""
    folder = tmp_path / "frames"
    _frames(folder, n=1)
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1",
                 "-s", "npy", "--no-progress"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 1 and "frame_000_prior_depth.png is a 16-bit PNG" in err, err
    assert "--prior-scale" in err and "--no-prior" in err
    np.save(folder / "frame_000_prior_depth.npy", np.ones((16, 20)))
    (folder / "frame_000_prior_depth.png").unlink()
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1",
                 "-s", "npy", "--no-progress"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 1 and "size 16x20 (HxW) (frame_000_prior_depth.npy) but the normal map is " \
        "32x40" in err and "2x coarser" in err and "--no-prior" in err, err
    _png(folder / "frame_000_prior_depth.png", np.ones((32, 40), np.uint16))
    (only,) = fb.items([folder])
    assert "frame_000_prior_depth.npy and frame_000_prior_depth.png" in only.error

def test_lone_one_channel_files_are_skipped_with_one_warning(tmp_path, capsys):
    """The same audit: a stray depth map and a grey image in a folder of frames ran as
    normal maps, each a failed item ("must be an (H, W, 3) RGB ..."), and the batch exited 1.
    A one-channel image or 2-d array that pairs with no map is skipped now, all named in one
    warning (a prior named after no map too, with its rename); not a two-sample TIFF
    (--normal-encoding xy reads it), and not one named explicitly."""
    import tifffile

    folder = tmp_path / "frames"
    _frames(folder, n=1)
    _png(folder / "stray_depth.png", np.full((16, 18), 7, np.uint16))
    _png(folder / "grey.png", np.full((16, 18), 90, np.uint8))
    np.save(folder / "disparity.npy", np.ones((16, 18)))
    _png(folder / "frame_009_prior_depth.png", np.ones((16, 18), np.uint16))
    n, _ = io.read_normals(folder / "frame_000.png")
    tifffile.imwrite(folder / "rg.tif", n[..., :2].astype(np.float32), photometric="minisblack",
                     planarconfig="contig")
    with pytest.warns(UserWarning, match=r"skipped 4 one-channel file\(s\) that pair with no "
                      r"normal map \(disparity.npy, frame_009_prior_depth.png, grey.png, "
                      r"stray_depth.png\).*frame_009_prior_depth.png has no map frame_009") as w:
        found = fb.items([folder])
    assert len([x for x in w if "one-channel" in str(x.message)]) == 1
    assert [it.name for it in found] == ["frame_000", "rg"]
    assert [it.name for it in fb.items([folder / "grey.png"])] == ["grey"]
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1", "-s", "npy",
                 "--normal-encoding", "xy", "--no-prior", "--no-progress"])
    out, err = capsys.readouterr()
    assert "skipped 4 one-channel file(s)" in err and "must be an (H, W, 3)" not in err, err
    assert code == 0 and "batch: 2 of 2 succeeded" in out, err

def test_a_batch_of_zero_one_float_maps_runs_with_normal_range_unsigned(tmp_path, capsys):
    """Float maps stored as (n + 1) / 2: refused item by item, naming the flag, without
    --normal-range unsigned; with it (and --resume: the failed items run again), each
    integrates to its signed map's depth, and the log records the flag."""
    gt = facetlift.synthetic.analytic("sphere", 32)
    (tmp_path / "in").mkdir()
    for name in ("a", "b"):
        np.save(tmp_path / "in" / f"{name}.npy", np.where(gt.mask[..., None],
                                                          (gt.normals + 1) / 2, 0.0))
    argv = ["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "--workers", "1", "-s",
            "npy", "--no-progress"]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 1 and err.count("--normal-range unsigned") == 2, err
    code = main([*argv, "--normal-range", "unsigned", "--resume"])
    out, err = capsys.readouterr()
    assert code == 0 and "batch: 2 of 2 succeeded" in out, err
    want = facetlift.integrate(gt.normals, gt.mask).depth
    for name in ("a", "b"):
        got = np.load(tmp_path / "o" / name / "depth.npy")
        np.testing.assert_allclose(got[gt.mask], want[gt.mask], atol=1e-9)
    records = [json.loads(line) for line in (tmp_path / "o" / "batch.jsonl").open()]
    assert records[-1]["settings"]["normal_range"] == "unsigned"


def test_batch_records_carry_integrate_s_hints_and_the_summary_counts_them(tmp_path, capsys):
    """The same audit: integrate --json has `hints` (the smooth surface bent across depth
    jumps: --discontinuities), a batch's records had none, so a batch of maps with jumps said
    nothing. Each record has integrate's hints now (the same words), and the batch says how
    many items got some and shows the first once, not a line per item."""
    gt = facetlift.synthetic.analytic("occluder", 64)
    (tmp_path / "in").mkdir()
    for name in ("a", "b", "c"):
        np.save(tmp_path / "in" / f"{name}.npy", gt.normals)
    code = main(["integrate", str(tmp_path / "in" / "a.npy"), "-o", str(tmp_path / "one"),
                 "-s", "npy", "--json"])
    want = json.loads(capsys.readouterr().out)["hints"]
    assert code == 0 and len(want) == 1 and "--discontinuities" in want[0]
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "--workers", "1",
                 "-s", "npy", "--json", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0, err
    recs = [json.loads(line) for line in out.splitlines()]
    assert [r["hints"] for r in recs] == [want] * 3
    log = [json.loads(line) for line in (tmp_path / "o" / fb.LOG_NAME).read_text().splitlines()]
    assert [r["hints"] for r in log] == [want] * 3
    shown = [line for line in err.splitlines() if line.startswith("hint: ")]
    assert len(shown) == 1 and "3 item(s) have hints" in shown[0] and want[0] in shown[0], err
    assert "(3 with hints)" in err.splitlines()[-1], err
    # with --discontinuities none applies: no word
    code = main(["batch", str(tmp_path / "in"), "-o", str(tmp_path / "d"), "--workers", "1",
                 "-s", "npy", "--discontinuities", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0 and "hint" not in out + err, out + err
    assert all(json.loads(line)["hints"] == [] for line in
               (tmp_path / "d" / fb.LOG_NAME).read_text().splitlines())


def test_two_priors_beside_a_map_fail_only_where_one_would_be_read(tmp_path):
    """Two NAME_prior_depth.* beside NAME.*: the item fails (which one was meant?), naming
    --no-prior; with --no-prior, or a --prior for every item, neither is read and the item
    runs (it failed all the same, a review); two confidences keep failing it."""
    folder = tmp_path / "frames"
    folder.mkdir()
    n = np.dstack([np.zeros((6, 7, 2)), np.ones((6, 7))])
    np.save(folder / "a.npy", n)
    np.save(folder / "a_prior_depth.npy", np.ones((6, 7)))
    import tifffile

    tifffile.imwrite(folder / "a_prior_depth.tif", np.ones((6, 7), np.float32))
    (it,) = fb.items([folder])
    assert it.error and "keep one" in it.error and "--no-prior" in it.error
    (kept,) = fb._own_files([it], Job(dataset_prior=False))
    assert kept.error is None and kept.prior is None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (given,) = fb._own_files([it], Job(prior=str(folder / "a_prior_depth.npy")))
    assert given.error is None
    np.save(folder / "a_confidence.npy", np.ones((6, 7)))
    tifffile.imwrite(folder / "a_confidence.tif", np.ones((6, 7), np.float32))
    (both,) = fb.items([folder])
    (left,) = fb._own_files([both], Job(dataset_prior=False))
    assert left.error and "its confidence: keep one" in left.error


def test_a_folder_of_another_inputs_results_is_kept(tmp_path):
    """An audit: a batch of b/m0.png into an OUT holding a/m0.png's results wrote over m0/
    without a word, and a later --resume of a/m0.png kept b's results as a's. Now the other
    input gets m0-2/ (with a warning), and resume checks whose results the folder holds."""
    maps(tmp_path / "a", n=1)
    maps(tmp_path / "b", n=2)
    (tmp_path / "b" / "m1.png").replace(tmp_path / "b" / "m0.png")  # (another map, one name)
    a, b, out = tmp_path / "a" / "m0.png", tmp_path / "b" / "m0.png", tmp_path / "out"
    fb.batch([a], out, save=("npy",), workers=1)
    first = np.load(out / "m0" / "depth.npy")
    with pytest.warns(UserWarning, match=r"m0/ holds .*a/m0\.png, so .*b/m0\.png is written "
                                         r"to m0-2/"):
        rec, = fb.batch([b], out, save=("npy",), workers=1)
    assert rec["name"] == "m0-2"
    np.testing.assert_array_equal(np.load(out / "m0" / "depth.npy"), first)
    assert not np.array_equal(np.load(out / "m0-2" / "depth.npy"), first, equal_nan=True)
    rec, = fb.batch([a], out, save=("npy",), workers=1, resume=True)
    assert rec.get("resumed") and rec["name"] == "m0"
    # the same input run again takes its own folder back (no renaming, no warning)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec, = fb.batch([b], out, save=("npy",), workers=1)
    assert rec["name"] == "m0-2"


def test_a_moved_input_keeps_its_folder_and_folders_do_not_swap(tmp_path):
    """A review: after `mv maps maps2` every item got a new folder (ownership compared the
    path's text); a run naming b/m and a/m in the other order than before swapped their
    folders in silence."""
    maps(tmp_path / "maps", n=2)
    out = tmp_path / "out"
    fb.batch([tmp_path / "maps"], out, save=("npy",), workers=1)
    (tmp_path / "maps").rename(tmp_path / "maps2")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        recs = fb.batch([tmp_path / "maps2"], out, save=("npy",), workers=1)
    assert [r["name"] for r in recs] == ["m0", "m1"]
    maps(tmp_path / "a", n=1)
    maps(tmp_path / "b", n=2)
    (tmp_path / "b" / "m1.png").replace(tmp_path / "b" / "m0.png")
    a, b = tmp_path / "a" / "m0.png", tmp_path / "b" / "m0.png"
    out2 = tmp_path / "out2"
    fb.batch([a], out2, save=("npy",), workers=1)
    with pytest.warns(UserWarning, match=r"given new folders"):
        fb.batch([b], out2, save=("npy",), workers=1)
    first = np.load(out2 / "m0" / "depth.npy")
    recs = fb.batch([b, a], out2, save=("npy",), workers=1)
    assert {r["item"]: r["name"] for r in recs} == {str(b): "m0-2", str(a): "m0"}
    np.testing.assert_array_equal(np.load(out2 / "m0" / "depth.npy"), first)


def test_resume_notices_an_edited_mask_given_to_every_item(tmp_path):
    """An audit: --mask's file was compared by its path's text only, so an edited mask
    file left the results of the old one."""
    maps(tmp_path / "in", n=1)
    mask = np.zeros((16, 18), bool)
    mask[2:14, 2:16] = True
    io.write_mask(tmp_path / "sq.png", mask)
    kw = dict(save=("npy",), workers=1, mask=str(tmp_path / "sq.png"))
    fb.batch([tmp_path / "in"], tmp_path / "out", **kw)
    assert fb.batch([tmp_path / "in"], tmp_path / "out", resume=True, **kw)[0].get("resumed")
    mask[2:14, 2:8] = False
    io.write_mask(tmp_path / "sq.png", mask)
    rec, = fb.batch([tmp_path / "in"], tmp_path / "out", resume=True, **kw)
    assert not rec.get("resumed")
    assert np.isfinite(np.load(tmp_path / "out" / "m0" / "depth.npy")).sum() == mask.sum()


def test_dot_and_globbed_folders_and_own_outputs(tmp_path, monkeypatch):
    """An audit: `batch .` wrote into OUT itself (name ""), `batch ..` beside OUT; a glob
    matching plain folders made each a failed item; facetlift's own preview.png in a folder
    of maps ran as a map; a list file's BOM hid its first entry; batch records had no
    camera_warned."""
    maps(tmp_path / "x" / "in", n=2)
    monkeypatch.chdir(tmp_path / "x" / "in")
    assert [it.name for it in fb.items(["."])] == ["m0", "m1"]
    ds = tmp_path / "ds" / "bear"
    ds.mkdir(parents=True)
    (ds / "normal_map.png").write_bytes((tmp_path / "x" / "in" / "m0.png").read_bytes())
    (ds / "sub").mkdir()
    monkeypatch.chdir(ds / "sub")
    assert [it.name for it in fb.items([".."])] == ["bear"]
    monkeypatch.chdir(tmp_path)
    assert sorted(it.name for it in fb.items(["x/*"])) == ["m0", "m1"]
    s = facetlift.integrate(io.read_normals(tmp_path / "x" / "in" / "m0.png")[0])
    s.save(tmp_path / "x" / "in" / "preview.png")
    with pytest.warns(UserWarning, match=r"skipped 1 file\(s\) named like facetlift's outputs"):
        assert [it.name for it in fb.items(["x/in"])] == ["m0", "m1"]
    (tmp_path / "list.txt").write_bytes("\ufeffx/in/m1.png\n".encode())
    assert [it.name for it in fb.items([], list_file=tmp_path / "list.txt")] == ["m1"]
    (tmp_path / "bad.txt").write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(ValueError, match=r"`list_file`: .*bad\.txt is no UTF-8 text"):
        fb.items([], list_file=tmp_path / "bad.txt")
    rec, = fb.batch(["x/in/m0.png"], tmp_path / "out", save=("npy",), workers=1,
                    K="100 100 500 500")
    assert rec["camera_warned"] is True and "camera_warned" in fb.log_record(rec)
    for kw, match in (({"triangles": "yes"}, r"`triangles` must be True or False or None"),
                      ({"backfacing": "maybe"}, r"`backfacing` must be one of"),
                      ({"strict": "no"}, r"`strict` must be True or False"),
                      ({"K": "1 2 3"}, r"`K`: '1 2 3' \(typed inline\) holds 3 numbers"),
                      ({"K": "nofile.txt"}, r"`K`: nofile.txt is no file"),
                      ({"outlier_eps": -3.0}, r"outlier_eps")):
        with pytest.raises(ValueError, match=match):  # (before any item: each failed alone)
            fb.batch(["x/in/m0.png"], tmp_path / "o2", workers=1, **kw)
    assert not (tmp_path / "o2").exists()


def test_a_cluster_without_distributed_names_the_extra(tmp_path, monkeypatch):
    """dask installed without dask.distributed: the cluster route raised a bare
    ModuleNotFoundError (an audit)."""
    import sys

    from facetlift.batch import _connect

    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r"dask\.distributed.*facetlift\[batch\]"):
        _connect("tcp://127.0.0.1:1")


def test_an_unreachable_scheduler_names_the_argument_and_leaves_nothing(tmp_path):
    """No scheduler at the address: a bare "Timed out trying to connect" after 30 s, and an
    empty batch.jsonl in a new output folder (a check). Now an OSError naming `scheduler`,
    and the folder the batch made is gone."""
    pytest.importorskip("distributed")
    import dask

    src = tmp_path / "in"
    maps(src, n=1)
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(OSError, match=r"`scheduler` 'tcp://127\.0\.0\.1:1'.*answered"):
            fb.batch([str(src)], tmp_path / "nest" / "a" / "out",
                     scheduler="tcp://127.0.0.1:1")
    assert not (tmp_path / "nest").exists()  # (nor the parents it made, a review)


def _sleep_forever():  # (a worker that ignores SIGTERM, as one busy in C code may)
    import signal
    import time

    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    while True:
        time.sleep(0.05)


def test_stopped_workers_are_reaped_before_their_folders_are_swept(monkeypatch):
    """A second interrupt cut _stop's wait short: the killed workers were not yet reaped,
    looked alive to the sweep, and their staging folders stayed (an audit)."""
    import multiprocessing as mp

    from facetlift import batch as B

    monkeypatch.setattr(B, "STOP_GRACE", 0.3)
    proc = mp.get_context("fork").Process(target=_sleep_forever)
    proc.start()

    class Pool:
        def shutdown(self, **kw):
            pass

    B._stop(Pool(), [proc])
    assert proc.exitcode is not None  # (reaped: no longer "alive" to os.kill(pid, 0))


def test_a_frame_without_its_prior_runs_from_its_normals_with_a_warning(tmp_path, capsys):
    """`facetlift batch FOLDER --prior-fit affine` on a video whose network skipped a frame's
    depth failed that frame ("--prior-fit='affine' needs a `prior`", exit 1), a user's check:
    the prior's settings apply to the maps with a prior, and one without is integrated from
    its normals alone, with a warning naming the settings not applied. Where no map has a
    prior the settings are a mistake: each map is refused, as a single job is."""
    folder = tmp_path / "frames"
    depths = _frames(folder, n=3)
    (folder / "frame_001_prior_depth.png").unlink()
    code = main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "1",
                 "-s", "npy", "--prior-fit", "affine", "--json", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0, err
    recs = {r["name"]: r for r in map(json.loads, out.splitlines())}
    assert [recs[f"frame_00{i}"]["status"] for i in range(3)] == ["ok"] * 3
    lone = recs["frame_001"]
    assert lone["prior_file"] is None
    assert [w for w in lone["warnings"] if "no depth prior" in w and "--prior-fit affine "
            "not applied" in w], lone["warnings"]
    assert not [w for w in recs["frame_000"]["warnings"] if "no depth prior" in w]
    # its depth is the normals-only one (the in-process depth of _frames, up to its constant)
    got = np.load(tmp_path / "o" / "frame_001" / "depth.npy")
    want = depths["m1"]
    diff = (got - want)[np.isfinite(got) & np.isfinite(want)]
    assert diff.size and np.ptp(diff) < 1e-6
    # no map with a prior: refused, each naming the setting
    for i in (0, 2):
        (folder / f"frame_00{i}_prior_depth.png").unlink()
    code = main(["batch", str(folder), "-o", str(tmp_path / "n"), "--workers", "1",
                 "-s", "npy", "--prior-fit", "affine", "--json", "--no-progress"])
    out, err = capsys.readouterr()
    recs = [json.loads(line) for line in out.splitlines()]
    assert code == 1 and all(r["status"] == "error" and "needs a `prior`" in r["error"]
                             for r in recs), recs
    # dataset folders without a prior_depth.* alike (every folder counted as holding one
    # before, a review); one holding it makes the others optional
    from facetlift import synthetic

    g = synthetic.analytic("sphere", 32)
    for k in (0, 1):
        d = tmp_path / "sets" / f"obj{k}"
        d.mkdir(parents=True)
        io.write_normals(d / "normal_map.png", np.nan_to_num(g.normals))
        io.write_mask(d / "mask.png", g.mask)
    args = ["batch", str(tmp_path / "sets"), "--workers", "1", "-s", "npy", "--prior-fit",
            "affine", "--json", "--no-progress"]
    code = main(args + ["-o", str(tmp_path / "s1")])
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert code == 1 and all("needs a `prior`" in r["error"] for r in recs), recs
    np.save(tmp_path / "sets" / "obj0" / "prior_depth.npy", 2 * g.depth + 3)
    code = main(args + ["-o", str(tmp_path / "s2")])
    recs = {r["name"]: r for r in map(json.loads, capsys.readouterr().out.splitlines())}
    assert code == 0 and any("no depth prior" in w for w in recs["obj1"]["warnings"]), recs


def _worker_hook(tmp_path, code: str) -> str:
    """A PYTHONPATH whose sitecustomize.py runs `code` in every new interpreter (the batch's
    spawned workers), with this facetlift first."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(code)
    return f"{hook}{os.pathsep}{Path(facetlift.__file__).resolve().parents[1]}"


_KILLER = """
import os, signal
if os.environ.get("FACETLIFT_TEST_KILL"):
    import facetlift.jobs as _jobs

    _run = _jobs.run

    def run(job, *a, **k):
        if os.path.basename(str(job.normals)).startswith(os.environ["FACETLIFT_TEST_KILL"]):
            os.kill(os.getpid(), signal.SIGKILL)
        return _run(job, *a, **k)

    _jobs.run = run
"""


def test_a_killed_worker_costs_its_item_alone(tmp_path, monkeypatch):
    """A review: one local worker killed (SIGKILL, the out-of-memory killer) stopped the whole
    batch with WorkersDied and no record of the item that killed it, so every --resume died
    again. The items not started run on a new pool, those running beside it are run again
    alone, and the one whose worker dies again gets a `killed` record (exit 1)."""
    pytest.importorskip("dask")
    monkeypatch.setenv("PYTHONPATH", _worker_hook(tmp_path, _KILLER))
    monkeypatch.setenv("FACETLIFT_TEST_KILL", "m2")
    maps(tmp_path / "in", n=5)
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=2, save=("npy",))
    status = {r["name"]: r["status"] for r in recs}
    assert status == {"m0": "ok", "m1": "ok", "m2": "killed", "m3": "ok", "m4": "ok"}, status
    killed = next(r for r in recs if r["name"] == "m2")
    assert killed["exit"] == 1 and "worker process died" in killed["error"]
    log = [json.loads(line) for line in (tmp_path / "o" / "batch.jsonl").open()]
    assert sorted(r["name"] for r in log) == ["m0", "m1", "m2", "m3", "m4"]
    assert not (tmp_path / "o" / "m2").exists()


def test_recursive_patterns_resume_in_place_and_early_warnings(tmp_path, capsys):
    """A review of batch: 'maps/**/*.png' matched one folder level alone (maps/a.png and
    maps/sub/deeper/d.png skipped without a word); with OUT the folder holding the dataset
    folders, each item's outputs changed its fingerprint and --resume ran everything again;
    warnings of the batch's settings (an --output-frame with no mesh saved) never reached a
    successful item's record."""
    maps(tmp_path / "maps", n=1)
    maps(tmp_path / "maps" / "sub" / "deeper", n=1)
    recs = facetlift.batch([str(tmp_path / "maps" / "**" / "*.png")], tmp_path / "o",
                           workers=1, save=("npy",), output_frame="opencv")
    assert len(recs) == 2 and all(r["status"] == "ok" for r in recs)
    assert all(any("applies to the mesh and point outputs" in w for w in r["warnings"])
               for r in recs)
    # (OUT under the pattern's root: the first run's previews are no maps of the second)
    args = ([str(tmp_path / "maps" / "**" / "*.png")], tmp_path / "maps" / "out")
    first = facetlift.batch(*args, workers=1, save=("npy", "png"))
    again = facetlift.batch(*args, workers=1, save=("npy", "png"), resume=True)
    assert len(first) == len(again) == 2 and all(r.get("resumed") for r in again)
    sets = tmp_path / "sets"
    for name in ("a", "b"):
        maps(sets / name, n=1)
        (sets / name / "m0.png").rename(sets / name / "normal_map.png")
    args = ["batch", str(sets), "-o", str(sets), "-s", "npy", "--resume", "--workers", "1",
            "--no-progress"]
    assert main(args) == 0
    capsys.readouterr()
    assert main(args) == 0
    out = capsys.readouterr()
    assert "2 from an earlier run" in out.out + out.err, out


def test_a_batch_worker_starts_no_threads_of_its_own(monkeypatch):
    """A review: each of a local batch's worker processes (one per core) also ran its
    transforms on every core and kernel's tiles on up to 8 threads. Where _threads.CORES is
    1, as a worker of a parallel batch sets it, the transforms and the split sparse products
    keep to one thread and kernel's memory plan counts one tile."""
    from facetlift import _threads, memory
    from facetlift.linalg import matvec, spectral

    monkeypatch.setattr(_threads, "CORES", 1)
    assert spectral.fft_workers() == 1 and not matvec.free_core()
    one = memory._kernel_tiles({"tile": 64, "margin": 8, "sigma": 2.0}, (512, 512))
    monkeypatch.setattr(_threads, "CORES", 8)
    assert memory._kernel_tiles({"tile": 64, "margin": 8, "sigma": 2.0}, (512, 512)) == 8 * one


def test_a_scheduler_that_is_no_address_is_named(tmp_path):
    """A review: scheduler='threads' (Dask's local scheduler's name, not a cluster's address)
    said "missing port number in address 'threads'" without naming the argument."""
    pytest.importorskip("distributed")
    maps(tmp_path / "in", n=1)
    with pytest.raises(ValueError, match=r"`scheduler` 'threads': .*tcp://host:8786.*"
                       r"workers=N"):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", scheduler="threads")


_SLEEPER = """
import os, time
if os.environ.get("FACETLIFT_TEST_PIDS"):
    import facetlift.jobs as _jobs

    def run(job, *a, **k):
        with open(os.path.join(os.environ["FACETLIFT_TEST_PIDS"], str(os.getpid())), "w"):
            pass
        time.sleep(60)

    _jobs.run = run
"""


def test_workers_of_a_killed_batch_end_themselves(tmp_path):
    """A review: a batch's parent killed with SIGKILL (which no handler sees) left its worker
    processes waiting for more items, orphans, for good. They now check for their parent and
    end when it is gone."""
    import signal
    import subprocess
    import sys
    import time

    pytest.importorskip("dask")
    pids = tmp_path / "pids"
    pids.mkdir()
    maps(tmp_path / "in", n=2)
    env = dict(os.environ, PYTHONPATH=_worker_hook(tmp_path, _SLEEPER),
               FACETLIFT_TEST_PIDS=str(pids))
    parent = subprocess.Popen([sys.executable, "-m", "facetlift", "batch", str(tmp_path / "in"),
                               "-o", str(tmp_path / "o"), "--workers", "2", "-s", "npy",
                               "--no-progress"], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while len(list(pids.iterdir())) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        workers = [int(p.name) for p in pids.iterdir()]
        assert len(workers) == 2
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()

    def alive(pid):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    deadline = time.monotonic() + 10 * fb.ORPHAN_CHECK + 5
    while any(alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    try:
        assert not any(alive(p) for p in workers)
    finally:
        for p in workers:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p, signal.SIGKILL)


_TIGHT = """
import os
if os.environ.get("FACETLIFT_TEST_AVAIL"):
    import facetlift.jobs as _jobs
    import facetlift.memory as _memory
    from facetlift import _threads

    _memory._meminfo = lambda: {"MemTotal": 2**30,
                                "MemAvailable": int(os.environ["FACETLIFT_TEST_AVAIL"])}
    _memory._cgroup_headroom = lambda: None
    _run = _jobs.run

    def run(job, *a, **k):
        seen = os.path.join(os.environ["FACETLIFT_TEST_SEEN"], str(os.getpid()))
        with open(seen, "w") as f:
            f.write(f"{_threads.CORES} {_memory._SHARE}")
        return _run(job, *a, **k)

    _jobs.run = run
"""


def test_an_item_refused_by_its_workers_share_runs_again_alone(tmp_path, monkeypatch):
    """A review: with each worker planning against 1/N of the free memory, items that fit
    alone were refused in a parallel batch with nothing to say why or retry them. Such an
    item runs again alone, with all of it, after the others. The workers' share and their one
    core are the batch's own wiring, read in the workers here."""
    pytest.importorskip("dask")
    seen = tmp_path / "seen"
    seen.mkdir()
    monkeypatch.setenv("PYTHONPATH", _worker_hook(tmp_path, _TIGHT))
    # (about 21 MiB above the planner's margin: a 256^2 map's ~13 MiB fit alone, not in half)
    monkeypatch.setenv("FACETLIFT_TEST_AVAIL", str(277 * 2**20))
    monkeypatch.setenv("FACETLIFT_TEST_SEEN", str(seen))
    maps(tmp_path / "in", n=2, H=256, W=256)
    recs = facetlift.batch([tmp_path / "in"], tmp_path / "o", workers=2, save=("npy",))
    assert [r["status"] for r in recs] == ["ok", "ok"], [r.get("error") for r in recs]
    states = {p.read_text() for p in seen.iterdir()}
    assert "1 2" in states and "None 1" in states, states  # (shared, then alone)


def test_workers_beside_a_scheduler_are_said_to_go_unused(tmp_path):
    """A review: --workers beside --scheduler was ignored without a word."""
    pytest.importorskip("distributed")
    maps(tmp_path / "in", n=1)
    with pytest.warns(UserWarning, match=r"`workers` 2 is not used with a `scheduler`"), \
            pytest.raises(ValueError, match="`scheduler` 'threads'"):
        facetlift.batch([tmp_path / "in"], tmp_path / "o", scheduler="threads", workers=2)


def test_resume_rolls_back_an_unfinished_commit_before_keeping_an_item(tmp_path):
    """A review: a run killed (kill -9) while it moved its outputs in left depth.npy new and
    the rest old; --resume kept the item as done by its earlier ok record. The dead run's
    commit is rolled back first (the set is the earlier one again); one of another host's
    runs the item again."""
    from facetlift.io import atomic

    maps(tmp_path / "in", n=1)
    out = tmp_path / "out"
    first = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",))[0]
    depth = Path(first["outputs"]["npy"])
    before = np.load(depth)
    # (a later run, killed after it moved its depth.npy in: the old one kept aside)
    staging = out / "m0" / f"{atomic.STAGING_PREFIX}{atomic._host()}-999999-0badc0de"
    (staging / ".replaced").mkdir(parents=True)
    os.link(depth, staging / ".replaced" / "depth.npy")
    np.save(staging / "new.npy", 2 * before)
    os.replace(staging / "new.npy", depth)
    st = os.lstat(depth)
    (staging / atomic.MOVING).write_text(json.dumps(
        ["depth.npy", st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns]) + "\n")
    again = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)[0]
    assert again.get("resumed") and np.array_equal(np.load(depth), before)
    assert not staging.exists()
    # another host's unfinished commit cannot be rolled back here: the item runs again
    other = out / "m0" / f"{atomic.STAGING_PREFIX}otherhost-12-0badc0de"
    other.mkdir()
    (other / atomic.MOVING).write_text("")
    rerun = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)[0]
    assert not rerun.get("resumed") and rerun["status"] == "ok"
    # ... once: the set committed since supersedes it (it ran again on every resume, a review)
    kept = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)[0]
    assert kept.get("resumed")


def test_a_cut_log_line_and_defaults_spelt_out_do_not_rerun_items(tmp_path):
    """A review: a log line cut short glued the next record onto it (that item ran a third
    time, the log kept an invalid line); an option given at its default, or the default
    frame spelt out, ran every item again on --resume."""
    maps(tmp_path / "in", n=2)
    out = tmp_path / "out"
    facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",))
    log = out / fb.LOG_NAME
    with open(log, "a", encoding="utf-8") as f:
        f.write('{"item": "cut sh')
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True,
                           normal_frame="gl", options={"solver": "direct"})
    assert all(r.get("resumed") for r in recs)
    recs = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy", "ply"), resume=True)
    assert not any(r.get("resumed") for r in recs)  # (other outputs: run again)
    lines = log.read_text().splitlines()
    assert sum(1 for ln in lines if ln.startswith('{"item": "cut sh')) == 1
    assert all(json.loads(ln) for ln in lines if not ln.startswith('{"item": "cut sh'))


def test_an_unreadable_folder_is_a_failed_item_not_the_end_of_the_batch(tmp_path, monkeypatch):
    """A review: a folder that cannot be listed stopped the whole batch with a bare
    '[Errno 13] Permission denied' and no log; now it is a failed item and the others run.
    (Run as root, permissions are not enforced: the listing's error is simulated.)"""
    maps(tmp_path / "ok", n=1)
    locked = tmp_path / "locked"
    maps(locked, n=1)
    real = fb._folder_items

    def listing(p):
        if Path(p) == locked:
            raise PermissionError(13, "Permission denied", str(p))
        return real(p)

    monkeypatch.setattr(fb, "_folder_items", listing)
    recs = facetlift.batch([locked, tmp_path / "ok"], tmp_path / "out", workers=1,
                           save=("npy",))
    by = {Path(r["item"]).name: r for r in recs}
    assert by["m0.png"]["status"] == "ok"
    assert by["locked"]["status"] == "error"
    assert "cannot be read (Permission denied" in by["locked"]["error"]


def test_a_cluster_batch_makes_its_files_absolute_and_cancels_running_items(tmp_path,
                                                                           monkeypatch):
    """A review: on a cluster, a relative --K, --mask or --prior failed every item with
    "does not exist" (the workers run in another folder), and items running when the batch
    was interrupted wrote their outputs after it had exited, over a later run's. The files
    are made absolute for the workers (the log's settings keep them as given), and an
    interrupt writes a cancel mark that a running item finds before it commits."""
    from facetlift.io import atomic

    maps(tmp_path / "in", n=1)
    np.savetxt(tmp_path / "K.txt", [[30.0, 0, 9], [0, 30.0, 8], [0, 0, 1]])
    monkeypatch.chdir(tmp_path)
    template = Job(K="K.txt", save=("npy",))
    item = fb.items([tmp_path / "in"])[0]
    (tmp_path / "o").mkdir()  # (the batch's OUT, made before its items run)
    jobs = fb._for_cluster([(item, template.with_input(item.path, tmp_path / "o" / "m0"))],
                           template, tmp_path / "o")
    j = jobs[0][1]
    assert j.K == str(tmp_path / "K.txt") and atomic.CANCEL_PREFIX in j.cancel_mark
    assert fb.settings(template) == fb.settings(Job(K="K.txt", save=("npy",)))

    class Client:
        cancelled = None

        def submit(self, fn, *args, pure=True):
            return object()

        def cancel(self, futures):
            Client.cancelled = futures

    def interrupted(futures, done):
        raise KeyboardInterrupt

    monkeypatch.setattr(fb, "_collect", interrupted)
    with pytest.raises(KeyboardInterrupt):
        fb._on_cluster(jobs, Client(), lambda it, rec: None)
    assert Path(j.cancel_mark).is_file() and len(Client.cancelled) == 1
    # the running item finds the mark: nothing is written, and its record says why
    rec = fb.run_item(j)
    assert rec["status"] == "cancelled" and not (tmp_path / "o" / "m0" / "depth.npy").exists()
    with atomic.OutputSet(tmp_path / "o2", ["a.npy"]) as out:  # (no mark: written)
        np.save(out.path("a.npy"), np.zeros(2))
    assert (tmp_path / "o2" / "a.npy").is_file()
    out = atomic.OutputSet(tmp_path / "o3", ["a.npy"], cancel=tmp_path / "mark")
    np.save(out.path("a.npy"), np.zeros(2))
    (tmp_path / "mark").touch()  # (the batch interrupted while the item ran)
    with pytest.raises(atomic.Cancelled):
        out.commit()
    assert not (tmp_path / "o3" / "a.npy").exists()


def test_a_list_file_expands_the_home_folder(tmp_path, monkeypatch):
    """'~/maps/m0.png' in a --list file was a folder named '~' beside the list (a review)."""
    maps(tmp_path / "home" / "maps", n=1)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "list.txt").write_text("~/maps/m0.png\n")
    found = fb.items([], list_file=tmp_path / "list.txt")
    assert [it.error for it in found] == [None]
    assert found[0].path == str(tmp_path / "home" / "maps" / "m0.png")


def test_resume_runs_again_an_item_whose_output_was_cut_short(tmp_path):
    """--resume checked only that the outputs exist: a depth.npy truncated to 100 bytes was
    taken as done (a review). The record keeps each output's size (output_bytes)."""
    maps(tmp_path / "in", n=2)
    out = tmp_path / "out"
    first = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",))
    depth = Path(first[0]["outputs"]["npy"])
    assert first[0]["output_bytes"]["npy"] == depth.stat().st_size
    depth.write_bytes(depth.read_bytes()[:100])
    again = facetlift.batch([tmp_path / "in"], out, workers=1, save=("npy",), resume=True)
    assert [bool(r.get("resumed")) for r in again] == [False, True]
    assert np.load(depth).shape == (16, 18)
    logged = [json.loads(ln) for ln in (out / fb.LOG_NAME).read_text().splitlines()]
    assert all("output_bytes" in rec for rec in logged)
