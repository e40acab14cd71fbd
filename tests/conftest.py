"""Shared fixtures: seeded generators and the real-data folder (skip when absent)."""

from __future__ import annotations

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
