"""``calibration_job``: a data set's odometry and laser calibrated from its own data
(:func:`slamkit.calibration.calibrate`), in one folder written completely or not at all.

Files written (``OUT`` the output folder):

* ``calibration.json`` — the data set, the systematic fit (scales, the laser's mounting,
  the wheel-radius and wheel-base errors, each with its standard deviation, and the
  covariance), the learned noise under both models with standard deviations, the pairs used,
  trimmed and dropped, and the settings;
* ``run_config.json`` — a run configuration whose ``[dataset]`` table is the data set's
  with the learned per-step noise as its ``odometry_sigma_trans`` and
  ``odometry_sigma_rot_deg`` (``slamkit run ESTIMATOR --config OUT/run_config.json``): the
  learned noise fed back.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slamkit.calibration import CalibrationResult, CalibrationSettings, calibrate
from slamkit.datasets.files import load_data
from slamkit.io import atomic_folder, write_json

__all__ = ["CalibrationReport", "CalibrationRequest", "calibration_job"]

NOISE_OPTIONS = ("odometry_sigma_trans", "odometry_sigma_rot_deg")
"""The loader options the learned noise is fed back through (the raw loaders')."""


@dataclass(frozen=True)
class CalibrationRequest:
    """The options of one ``slamkit calibrate`` run."""

    data: str
    out_dir: Path
    options: Mapping[str, Any] = field(default_factory=dict)
    settings: CalibrationSettings = field(default_factory=CalibrationSettings)
    seed: int = 0
    overwrite: bool = False
    data_root: Path | None = None


@dataclass(frozen=True)
class CalibrationReport:
    """What :func:`calibration_job` learned and wrote."""

    result: CalibrationResult
    out_dir: Path
    files: tuple[str, ...]
    fed_back: bool
    """Whether ``run_config.json`` carries the learned noise (the data set's loader takes
    the raw loaders' noise options)."""


def calibration_job(
    request: CalibrationRequest, progress: Callable[[int, int], None] | None = None
) -> CalibrationReport:
    """Load ``request.data``, calibrate it, write the folder (see the module docstring)."""
    from slamkit.app.runconfig import dataset_table

    dataset = load_data(
        request.data, seed=request.seed, options=request.options, data_root=request.data_root
    )
    result = calibrate(dataset, request.settings, progress)
    table = dataset_table(dataset, request.options)
    fed_back = all(key in table for key in NOISE_OPTIONS)
    if fed_back:
        table.update(result.dataset_options())
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        write_json(tmp / "calibration.json", {
            "data": request.data, "seed": request.seed, **result.as_dict(),
        })  # fmt: skip
        write_json(tmp / "run_config.json", {"seed": request.seed, "dataset": table})
    return CalibrationReport(
        result, request.out_dir, ("calibration.json", "run_config.json"), fed_back
    )
