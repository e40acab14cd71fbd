"""Fixtures of the SLAM tests: the first seconds of a registered raw Freiburg log."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset

BAGS = {"aces-raw": "aces.bag", "fr079-raw": "fr079.bag", "intel-raw": "intel.bag"}


@pytest.fixture
def raw_log(data_root: Path) -> Callable[..., Dataset]:
    """``raw_log(name, seconds, closed=True)``: the registered raw log ``name`` cut to the
    events within ``seconds`` of its first (``<=``; ``closed=False``: ``<``); skips when
    the ``rosbags`` extra or the bag is missing."""
    pytest.importorskip("rosbags", reason="the laser extra (rosbags) is not installed")

    def cut(name: str, seconds: float, closed: bool = True) -> Dataset:
        bag = f"laser/rosbags/{BAGS[name]}"
        if not (data_root / bag).exists():
            pytest.skip(f"{bag} not under {data_root}")
        data = load_dataset(name, data_root=data_root)
        end = data.events[0].t + seconds
        kept = tuple(e for e in data.events if (e.t <= end if closed else e.t < end))
        return dataclasses.replace(data, events=kept)

    return cut


@pytest.fixture
def slam_gaussian(rng: np.random.Generator) -> Callable[[int], tuple[np.ndarray, np.ndarray]]:
    """``slam_gaussian(L)``: a random SLAM state ``(3 + 2L,)`` (positions ~ N(0, 5²), a
    heading in ``[-π, π)``) and a random positive definite covariance over it."""

    def draw(n_landmarks: int) -> tuple[np.ndarray, np.ndarray]:
        n = 3 + 2 * n_landmarks
        mean = rng.normal(0.0, 5.0, n)
        mean[2] = rng.uniform(-np.pi, np.pi)
        A = rng.normal(size=(n, n))
        return mean, A @ A.T / n + 0.1 * np.eye(n)

    return draw
