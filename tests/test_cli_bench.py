"""`facetlift bench` through the real command line entry point.

The quick bench itself runs once, in tests/test_bench.py (fixture `quick`)."""

import pytest
from click.testing import CliRunner

from facetlift.bench import EXPERIMENTS
from facetlift.cli import cli, main


def test_bench_bad_method_exits_1(tmp_path, capsys):
    code = main(["bench", "--quick", "-o", str(tmp_path / "b"), "--methods", "nope",
                 "--no-progress"])
    _, err = capsys.readouterr()
    assert code == 1 and "nope" in err


def test_bench_command(tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["bench", "-o", str(tmp_path / "o"), "--quick", "--experiments",
                              "table1,fig4", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "o" / "table1.md").is_file() and (tmp_path / "o" / "fig4.png").is_file()
    assert not (tmp_path / "o" / "fig9.csv").exists()
    res = runner.invoke(cli, ["bench", "-o", str(tmp_path / "o"), "--methods", "nope"])
    assert res.exit_code == 2 and "unknown" in res.output


def test_bench_help_lists_every_experiment():
    res = CliRunner().invoke(cli, ["bench", "--help"])
    assert res.exit_code == 0, res.output
    assert f"subset of: {', '.join(EXPERIMENTS)}." in " ".join(res.output.split())


@pytest.mark.parametrize("flag", ["--experiments", "--models", "--methods", "--conditions"])
def test_an_empty_list_names_nothing(flag, tmp_path, capsys):
    """An empty list ran every experiment, model or method: hours in full mode (an audit and
    a review)."""
    assert main(["bench", "-o", str(tmp_path / "o"), flag, " , "]) == 1
    assert f"{flag} ' , ' names nothing" in capsys.readouterr().err
