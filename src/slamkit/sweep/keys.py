"""A run's key: the hash of everything that determines its result.

Two points with the same estimator, data set and options, resolved settings (the preset
laid under the spec's values, then the estimator's defaults for the rest), seed and slamkit
version get the same key, so a sweep finds a run another sweep — or an earlier invocation
of the same one — already finished in ``DIR/runs/<key>/``.
"""

from __future__ import annotations

import hashlib
import json
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from slamkit.config import config_to_dict
from slamkit.sweep.spec import SweepPoint

__all__ = ["KEY_LENGTH", "key_payload", "run_key", "slamkit_version"]

KEY_LENGTH = 16
"""Hex digits of the SHA-256 kept in a key (64 bits: no collision in any real sweep)."""


def slamkit_version() -> str:
    """The installed slamkit version (``"unknown"`` when run from a bare source tree)."""
    try:
        return version("slamkit")
    except PackageNotFoundError:
        return "unknown"


def key_payload(point: SweepPoint, preset: str | None = "auto") -> dict[str, Any]:
    """What the key hashes: the estimator, the data set (a file by its absolute path) and
    its options over the registry's defaults, the resolved settings, the seed and the
    slamkit version."""
    from slamkit.app.presets import resolve_preset
    from slamkit.datasets.registry import DATASETS
    from slamkit.pipeline import get_estimator_entry

    entry = get_estimator_entry(point.estimator)
    config, chosen = resolve_preset(entry.name, point.dataset, point.settings, preset)
    settings = config_to_dict(entry.make_config(config))
    registered = DATASETS.get(point.dataset)
    if registered is not None:
        dataset = point.dataset
        options = {**registered.defaults, **point.dataset_options}
    else:
        dataset = str(Path(point.dataset).resolve())
        options = dict(point.dataset_options)
    return {
        "estimator": entry.name,
        "dataset": dataset,
        "dataset_options": options,
        "settings": settings,
        "seed": point.seed,
        "preset": None if chosen is None else chosen.name,
        "slamkit": slamkit_version(),
    }


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)


def run_key(point: SweepPoint, preset: str | None = "auto") -> str:
    """The point's key: :data:`KEY_LENGTH` hex digits of the SHA-256 of
    :func:`key_payload` in canonical JSON (sorted keys; ``1`` and ``1.0`` differ only where
    the config coerces them alike, since the settings are hashed after the config)."""
    return hashlib.sha256(_canonical(key_payload(point, preset)).encode()).hexdigest()[:KEY_LENGTH]
