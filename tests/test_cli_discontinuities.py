"""The CLI treats the discontinuity reweighting's fixed budget as a note, not a failure."""

import functools
import importlib

from test_cli import run, write_input


def test_discontinuity_budget_is_a_note_not_exit_2(tmp_path, capsys, monkeypatch):
    dgp = importlib.import_module("facetlift.methods.dgp")
    real = dgp.run

    @functools.wraps(real)  # keeps the option signature that integrate() checks
    def budget_used(problem, **kw):
        result = real(problem, **kw)
        assert result.info["solver"] == "discontinuous"
        result.info["converged"] = False  # as when the weights have not settled yet
        return result

    monkeypatch.setattr(dgp, "run", budget_used)
    npath, mpath, _ = write_input(tmp_path)
    out = tmp_path / "o"
    code, stdout, err = run(capsys, "integrate", npath, "-m", mpath, "-o", out,
                            "--discontinuities", "--option", "discontinuity_iter=1")
    assert code == 0, err
    assert (out / "depth.npy").is_file() and "not converged" in stdout
    assert "discontinuity_iter" in err


def test_iterative_non_convergence_still_exits_2(tmp_path, capsys):
    npath, mpath, _ = write_input(tmp_path)
    code, _, err = run(capsys, "integrate", npath, "-m", mpath, "-o", tmp_path / "o",
                       "--solver", "iterative", "--max-iter", "1", "--tol", "0",
                       "--no-progress")
    assert code == 2 and "did not converge" in err
