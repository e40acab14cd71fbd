"""Shared fixtures: seeded generators and the real-data folder (skip when absent)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import ENV_VAR, find_data_root


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
