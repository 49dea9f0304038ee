"""`facetlift bench --quick -o DIR` through the real command line entry point."""

from facetlift.cli import main


def test_bench_quick_through_main(tmp_path, capsys):
    out = tmp_path / "bench"
    code = main(["bench", "--quick", "-o", str(out), "--no-progress"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert f"wrote {out / 'report.md'}" in stdout
    for name in ["table1.md", "fig4.png", "fig5.csv", "fig9.md", "report.md"]:
        assert (out / name).is_file(), name
    table1 = (out / "table1.md").read_text()
    assert "factorization_ms" in table1 and "spectral" in table1  # timed rows, not a header


def test_bench_bad_method_exits_1(tmp_path, capsys):
    code = main(["bench", "--quick", "-o", str(tmp_path / "b"), "--methods", "nope",
                 "--no-progress"])
    _, err = capsys.readouterr()
    assert code == 1 and "nope" in err
