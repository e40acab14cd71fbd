"""Where MCL's particles come from without a prior: random poses over the map.

A :data:`PoseSampler` draws poses uniformly over the free cells of an occupancy grid (laser
worlds) or over the landmarks' bounding box grown by a margin (landmark worlds). The
samplers start a global localization (:func:`initial_poses`) and feed augmented MCL's random
particles (:func:`~slamkit.localization.mcl.core.mcl_resample`,
:func:`~slamkit.localization.mcl.kld.kld_resample_predict`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError
from slamkit.estimation.particles import (
    uniform_particles_in_box,
    uniform_particles_in_free_space,
)
from slamkit.maps import OccupancyGrid

__all__ = [
    "PoseSampler",
    "free_space_sampler",
    "initial_poses",
    "landmark_box_sampler",
    "sample_poses",
]

PoseSampler = Callable[[int, np.random.Generator], FloatArray]
"""``sampler(n, rng) -> poses (n, 3)``: where random (injected) particles come from."""


def sample_poses(sampler: PoseSampler, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` poses ``(n, 3)`` from ``sampler``, checked for their shape."""
    poses = as_array(sampler(n, rng), "sampled poses", (n, 3))
    return poses


def free_space_sampler(grid: OccupancyGrid) -> tuple[PoseSampler, float]:
    """A sampler of poses uniform over the free cells of ``grid``, and their area [m²]."""

    def free_space(n: int, rng: np.random.Generator) -> FloatArray:
        return uniform_particles_in_free_space(grid, n, rng)

    area = float(np.count_nonzero(grid.free())) * grid.resolution**2
    return free_space, area


def landmark_box_sampler(positions: FloatArray, margin: float) -> tuple[PoseSampler, float]:
    """A sampler of poses uniform over the bounding box of the landmark ``positions (M, 2)``
    grown by ``margin`` [m], and the box's area [m²]."""
    pos = positions
    mg = margin
    box = (
        float(pos[:, 0].min()) - mg,
        float(pos[:, 1].min()) - mg,
        float(pos[:, 0].max()) + mg,
        float(pos[:, 1].max()) + mg,
    )
    if not (box[2] > box[0] and box[3] > box[1]):
        raise InputError(
            "mcl: the landmarks' bounding box is degenerate; set augmented.injection_margin > 0"
        )

    def in_box(n: int, rng: np.random.Generator) -> FloatArray:
        return uniform_particles_in_box(box, n, rng)

    return in_box, (box[2] - box[0]) * (box[3] - box[1])


def initial_poses(
    sampler: PoseSampler,
    area: float,
    n_global: int | None,
    per_m2: float,
    rng: np.random.Generator,
) -> FloatArray:
    """A global start: ``n_global`` poses from ``sampler``, or (``None``) ``per_m2`` times
    the ``area`` they are spread over, within [1000, 2·10⁶]."""
    if n_global is None:
        n_global = int(np.clip(np.ceil(per_m2 * area), 1000, 2_000_000))
    return sampler(n_global, rng)
