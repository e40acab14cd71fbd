"""Named presets: estimator settings measured to suit one data set.

An estimator is built from what an online system knows; settings found by running it on a
data set's whole log (a study over seeds and values) are not part of the data set but a
named preset that the app layer lays under the caller's config, for the estimators and data
sets it was measured on. ``slamkit run`` applies the matching preset unless told otherwise
(``--preset none``) and records its name and settings in ``config.json``. How each preset
was chosen, with the commands that re-measure it: ``docs/presets.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from slamkit.errors import InputError, UnknownNameError

__all__ = ["PRESETS", "Preset", "get_preset", "preset_for", "resolve_preset"]


@dataclass(frozen=True)
class Preset:
    """Settings for the estimators ``estimators`` on the registered data sets ``datasets``."""

    name: str
    estimators: tuple[str, ...]
    datasets: tuple[str, ...]
    settings: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""


PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset(
            "victoria-park-fastslam",
            ("fastslam1", "fastslam2"),
            ("victoria-park",),
            {"measurement_cov_scale": 36.0, "motion_cov_scale": 0.5, "hit_weight": 3},
            "FastSLAM on Victoria Park without ids: 36x the tree-reading covariance (6x the "
            "standard deviations), half the control covariance, hit weight 3 (whole run, "
            "seeds 0-3)",
        ),
    )
}


def get_preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        raise UnknownNameError("preset", name, sorted(PRESETS)) from None


def preset_for(estimator: str, dataset: str) -> Preset | None:
    """The preset measured for ``estimator`` on the registered data set ``dataset``."""
    for p in PRESETS.values():
        if estimator in p.estimators and dataset in p.datasets:
            return p
    return None


def resolve_preset(
    estimator: str, dataset: str, config: Mapping[str, Any], preset: str | None = "auto"
) -> tuple[dict[str, Any], Preset | None]:
    """The config mapping to run with and the preset under it. ``preset``: ``"auto"`` (the
    one measured for this estimator and data set, if any), ``None`` or ``"none"`` (no
    preset), or a preset's name (which must be for ``estimator``). The caller's keys win."""
    if preset is None or preset == "none":
        return dict(config), None
    chosen = preset_for(estimator, dataset) if preset == "auto" else get_preset(preset)
    if chosen is None:
        return dict(config), None
    if estimator not in chosen.estimators:
        raise InputError(
            f"preset {chosen.name!r} is for {', '.join(chosen.estimators)}, not {estimator!r}"
        )
    return {**chosen.settings, **config}, chosen
