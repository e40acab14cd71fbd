"""Shared fixtures: seeded generators, the real-data folder (skip when absent), small
CARMEN logs and wheel glitches put into a data set."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import ENV_VAR, find_data_root
from slamkit.datasets.stream import Control, Dataset


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def data_root() -> Path:
    root = find_data_root()
    if root is None:
        pytest.skip(f"real data not found: set {ENV_VAR} to the shared data folder")
    return root


@pytest.fixture
def carmen_log(tmp_path: Path) -> Callable[..., Path]:
    """A writer of small CARMEN logs in ``tmp_path``: ``carmen_log(name, corrected=True,
    scans=6)`` writes ``scans`` FLASER lines of 180 beams driving 0.1 m a second along x,
    each followed by the ``NEFF`` line of a corrected log when ``corrected`` (so the reader
    is chosen by the content: corrected or raw), and returns the path."""

    def write(name: str = "run.log", *, corrected: bool = True, scans: int = 6) -> Path:
        ranges = " ".join(f"{1.0 + 0.01 * i:g}" for i in range(180))
        lines = []
        for k in range(scans):
            x, t = 0.1 * k, 1.0 + k
            lines.append(f"FLASER 180 {ranges} {x:g} 0 0 {x:g} 0 0 {t:g} host {t:g}")
            if corrected:
                lines.append("NEFF 30")
        path = tmp_path / name
        path.write_text("\n".join(lines) + "\n")
        return path

    return write


def _with_heading_jump(data: Dataset, jump: float, at: float) -> tuple[Dataset, float]:
    """``data`` whose wheels report a turn of ``jump`` [rad] too much in one control at the
    fraction ``at`` of the drive (a gyro or encoder spike: ``ω += jump / dt``), so the
    prediction carries the wrong heading from then on, and the stamp of the glitch."""
    controls = [k for k, e in enumerate(data.events) if isinstance(e, Control)]
    k = controls[int(at * len(controls))]
    e = data.events[k]
    assert isinstance(e, Control) and e.dt > 0
    u = np.array(e.u, dtype=np.float64)
    u[1] += jump / e.dt
    events = list(data.events)
    events[k] = dataclasses.replace(e, u=u)
    return dataclasses.replace(data, events=tuple(events)), e.t


@pytest.fixture
def heading_jump() -> Callable[[Dataset, float, float], tuple[Dataset, float]]:
    """``heading_jump(data, jump, at)``: ``data`` with one wheel glitch of ``jump`` [rad] at
    the fraction ``at`` of its controls, and the glitch's stamp."""
    return _with_heading_jump
