"""The thread policy (slamkit.runtime): ``slamkit run``, ``slamkit.pipeline.run`` and
``slamkit.optim.optimize`` hold BLAS to one thread with no environment variable set; an
explicit count or one set in the environment wins; the counts are restored afterwards.

BLAS reads its environment when it is loaded, so the tests set the counts at hand with
threadpoolctl (two threads before each run), clear the variables, and read the counts that
threadpoolctl reports inside the run, through a probe on the estimator's ``estimate``."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from threadpoolctl import threadpool_limits
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import load_dataset
from slamkit.errors import InputError
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph
from slamkit.localization.dead_reckoning import DeadReckoning
from slamkit.optim import optimize
from slamkit.pipeline import run
from slamkit.runtime import BLAS_ENV_VARS, DEFAULT_BLAS_THREADS, blas_thread_counts, blas_threads


def _counts() -> set[int]:
    return set(blas_thread_counts().values())


@pytest.fixture
def two_threads(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """No BLAS variable in the environment, and every BLAS at two threads (whatever it read
    at load time, e.g. a Makefile's ``OPENBLAS_NUM_THREADS=1``)."""
    for name in BLAS_ENV_VARS:
        monkeypatch.delenv(name, raising=False)
    with threadpool_limits(limits=2, user_api="blas"):
        if _counts() != {2}:
            pytest.skip(f"this BLAS cannot be set to two threads: {blas_thread_counts()}")
        yield


@pytest.fixture
def seen(monkeypatch: pytest.MonkeyPatch) -> list[set[int]]:
    """The BLAS thread counts at every ``estimate()`` of dead reckoning (once after its
    creation and once per step of a run)."""
    counts: list[set[int]] = []
    original = DeadReckoning.estimate

    def probe(self: DeadReckoning):
        counts.append(_counts())
        return original(self)

    monkeypatch.setattr(DeadReckoning, "estimate", probe)
    return counts


def test_run_holds_blas_to_one_thread_and_restores_the_count(two_threads, seen):
    ds = load_dataset("five-features", seed=0)
    res = run("dead-reckoning", ds)
    assert len(res.times) > 10 and len(seen) >= len(res.times)
    assert all(c == {DEFAULT_BLAS_THREADS} for c in seen)
    assert _counts() == {2}


def test_slamkit_run_command_holds_blas_to_one_thread(two_threads, seen, tmp_path):
    out = tmp_path / "run"
    res = CliRunner().invoke(
        app, ["run", "dead-reckoning", "--data", "five-features", "--out", str(out), "--no-plots"]
    )
    assert res.exit_code == 0, res.output
    assert (out / "trajectory.tum").is_file()
    assert len(seen) > 10 and all(c == {1} for c in seen)
    assert _counts() == {2}


def test_an_explicit_count_and_the_environment_win(two_threads, seen, monkeypatch):
    ds = load_dataset("five-features", seed=0)
    with blas_threads():  # an enclosing policy does not stop an explicit count
        run("dead-reckoning", ds, blas_threads=2)
        assert _counts() == {1}
    assert seen and all(c == {2} for c in seen)

    seen.clear()
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")  # the user's choice: left alone
    run("dead-reckoning", ds)
    assert seen and all(c == {2} for c in seen)

    seen.clear()
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "")  # empty: not a choice
    run("dead-reckoning", ds)
    assert seen and all(c == {1} for c in seen)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_a_bad_thread_count_is_refused(bad):
    with pytest.raises(InputError, match="blas_threads: expected an integer >= 1 or None"):
        run("dead-reckoning", load_dataset("five-features", seed=0), blas_threads=bad)


SQUARE = """\
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1.2 -0.1 1.4
VERTEX_SE2 2 0.9 1.2 3.0
VERTEX_SE2 3 -0.1 0.8 -1.7
EDGE_SE2 0 1 1 0 1.5707963267948966 100 0 0 100 0 1000
EDGE_SE2 1 2 1 0 1.5707963267948966 100 0 0 100 0 1000
EDGE_SE2 2 3 1 0 1.5707963267948966 100 0 0 100 0 1000
EDGE_SE2 3 0 1 0 1.5707963267948966 100 0 0 100 0 1000
"""


def test_optimize_holds_blas_to_one_thread_unless_wrapped(two_threads, tmp_path):
    path = tmp_path / "square.g2o"
    path.write_text(SQUARE)
    graph = read_graph(path)
    counts: list[set[int]] = []

    def record(info: object) -> bool:
        counts.append(_counts())
        return False  # go on

    res = optimize(graph, callback=record)
    # the unit square, driven counter-clockwise from the origin
    square = np.array([[0, 0, 0], [1, 0, math.pi / 2], [1, 1, math.pi], [0, 1, -math.pi / 2]])
    error = pose2.between(square, res.poses)
    assert np.abs(error).max() < 1e-6
    assert counts and all(c == {1} for c in counts)
    assert _counts() == {2}

    counts.clear()
    with blas_threads(2):  # a caller's choice around it is kept
        optimize(graph, callback=record)
    assert counts and all(c == {2} for c in counts)
