"""CLI faults end as one line and exit code 1, checked before any work is done."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app

runner = CliRunner()


def _one_line_error(args: list[str], expected: str) -> None:
    res = runner.invoke(app, args)
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expected in lines[0], lines


def test_an_impossible_or_unwritable_out_is_refused(tmp_path: Path) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    _one_line_error(["run", "dead-reckoning", "--out", str(afile / "sub")], "cannot create")
    _one_line_error(["run", "dead-reckoning", "--out", "/proc/x"], "cannot write in /proc")
    _one_line_error(["run", "dead-reckoning", "--out", str(afile)], "not a folder")


def test_a_full_out_folder_is_refused_before_the_run(tmp_path: Path, monkeypatch) -> None:
    """The folder is checked first: the estimator is never built (it would fail loudly)."""
    import slamkit.app.jobs as jobs

    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("x")

    def never(*args, **kwargs):
        raise AssertionError("the run started although the output folder is full")

    monkeypatch.setattr(jobs, "run", never)
    _one_line_error(["run", "dead-reckoning", "--out", str(full)], "not empty")


@pytest.mark.parametrize("how", ["option", "config"])
def test_a_negative_seed_is_refused(tmp_path: Path, how: str) -> None:
    args = ["run", "dead-reckoning", "--out", str(tmp_path / "r")]
    if how == "option":
        args += ["--seed", "-1"]
    else:
        (tmp_path / "c.toml").write_text("seed = -1\n")
        args += ["--config", str(tmp_path / "c.toml")]
    _one_line_error(args, "seed: expected an integer >= 0")


def test_a_binary_config_file_and_a_data_root_that_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "bin.toml").write_bytes(b"\x00\x01\xff\xfe")
    _one_line_error(
        [
            "run",
            "dead-reckoning",
            "--config",
            str(tmp_path / "bin.toml"),
            "--out",
            str(tmp_path / "a"),
        ],
        "not a text file",
    )
    (tmp_path / "root").write_text("x")
    _one_line_error(
        ["run", "dead-reckoning", "--data", "plaza1", "--data-root", str(tmp_path / "root"),
         "--out", str(tmp_path / "b")],
        "(which is not a folder)",
    )  # fmt: skip


@pytest.mark.parametrize(
    ("table", "expected"),
    [
        ("initial_sigma_xy = inf", "initial_sigma_xy: expected a finite number"),
        ("laps = 100000000", "above the limit of 2,000,000 (set max_steps"),
        ("dt = 1e-7", "above the limit of 2,000,000 (set max_steps"),
    ],
)
def test_simulator_settings_that_would_hang_or_exhaust_memory(tmp_path, table, expected):
    (tmp_path / "c.toml").write_text(f"[dataset]\n{table}\n")
    args = ["run", "dead-reckoning", "--config", str(tmp_path / "c.toml")]
    _one_line_error([*args, "--out", str(tmp_path / "r")], expected)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "code", "word"), [("INT", 130, "interrupted"), ("TERM", 143, "terminated")]
)
def test_an_interrupted_run_says_so_and_leaves_nothing_behind(tmp_path, sig, code, word):
    import os
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "long.toml").write_text("[dataset]\nlaps = 400\n")
    out = tmp_path / "runs" / "r"
    # A test run started in the background by a shell without job control inherits SIGINT
    # ignored (POSIX), and Python then installs no handler for it: the user's terminal is
    # what is tested here, so the run gets the default disposition back.
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamkit.cli.main", "run", "fastslam2", "--config",
         str(tmp_path / "long.toml"), "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while not (tmp_path / "runs").exists() and time.monotonic() < deadline:
        time.sleep(0.1)  # the output folder's parent is made before the work starts
    time.sleep(2.0)
    proc.send_signal(getattr(signal, f"SIG{sig}"))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1] == f"{word}; nothing was written"
    assert not out.exists() and os.listdir(tmp_path / "runs") == []


def test_stale_partial_folders_of_a_killed_run_are_removed(tmp_path):
    from slamkit.io import atomic_folder

    dead = tmp_path / ".r.999999999.abcd.partial"  # no such process
    dead.mkdir()
    (dead / "metrics.json").write_text("{}")
    mine = tmp_path / ".other.999999999.x.partial"  # another target's: left alone
    mine.mkdir()
    with atomic_folder(tmp_path / "r") as tmp:
        (tmp / "a.txt").write_text("a")
    assert not dead.exists() and mine.exists() and (tmp_path / "r" / "a.txt").exists()
