"""`slamkit run --svg` and `slamkit compare DIR...`: the files, the page, the errors."""

from __future__ import annotations

from typer.testing import CliRunner

from slamkit.cli.main import app

runner = CliRunner()


def test_run_then_compare_two_runs(tmp_path):
    for seed in ("0", "1"):
        res = runner.invoke(
            app,
            [
                "run",
                "dead-reckoning",
                "--seed",
                seed,
                "--svg",
                "--out",
                str(tmp_path / f"dr{seed}"),
            ],
        )
        assert res.exit_code == 0, res.output
        assert "report.html" in res.output
    run0 = tmp_path / "dr0"
    for name in ("trajectory", "errors", "nees"):
        assert (run0 / f"{name}.svg").read_bytes().lstrip()[:5] in (b"<?xml", b"<svg ")
    page = (run0 / "report.html").read_text()
    assert page.count("<img ") == 3  # the PNGs; the SVG copies are in the file list
    assert 'href="trajectory.svg"' in page
    res = runner.invoke(
        app, ["compare", str(run0), str(tmp_path / "dr1"), "--out", str(tmp_path / "cmp")]
    )
    assert res.exit_code == 0, res.output
    text = (tmp_path / "cmp" / "compare.html").read_text()
    assert text.count("<img ") == 6
    assert 'src="../dr1/errors.png"' in text


def test_compare_of_a_folder_that_is_not_a_run_is_one_line(tmp_path):
    res = runner.invoke(app, ["compare", str(tmp_path), "--out", str(tmp_path / "cmp")])
    assert res.exit_code == 1
    assert "no metrics.json" in res.output
    assert "Traceback" not in res.output
