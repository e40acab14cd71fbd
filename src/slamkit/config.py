"""Configuration is data: frozen dataclasses with documented units and defaults.

Algorithms take config objects, never files or environment variables. This module turns plain
mappings (from a TOML/JSON file or the command line) into those objects, rejecting unknown
keys and wrong types with a :class:`~slamkit.errors.ConfigError`, and turns them back into
JSON-able dictionaries that are written next to every result.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from slamkit.errors import ConfigError

__all__ = ["config_from_mapping", "config_to_dict", "load_config_file"]

C = TypeVar("C")


def _coerce(value: Any, annotation: Any, where: str) -> Any:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if annotation is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: expected one of {list(args)}, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        if not math.isfinite(float(value)) and value != math.inf:
            raise ConfigError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if dataclasses.is_dataclass(annotation) and isinstance(annotation, type):
        if isinstance(value, annotation):  # an already built section
            return value
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table of settings, got {value!r}")
        return config_from_mapping(annotation, value, where)
    return value


RENAMED: dict[str, str] = {
    "measurement_noise_scale": "now measurement_cov_scale, a factor on the covariance; "
    "FastSLAM and MCL scaled standard deviations: square the old value",
    "motion_noise_scale": "now motion_cov_scale, a factor on the covariance",
    "noise_scale": "now motion_cov_scale (dead reckoning, least squares) or "
    "measurement_cov_scale (EKF mapping), factors on the covariance",
    "method": "now solver",
    "pose_time_tolerance": "no longer used: known poses arrive through the stream",
}
"""Settings that were renamed, with what to write instead (named in the error)."""


def config_from_mapping(cls: type[C], values: Mapping[str, Any] | None, where: str = "") -> C:
    """Build the frozen dataclass ``cls`` from ``values``; missing keys keep their defaults.

    A field typed as a dataclass (a config *section*, such as ``OptimizerConfig.lm``) takes a
    nested mapping (a ``[optimizer.lm]`` table in TOML, a nested object in JSON), read by the
    same rules with its own defaults for missing keys (unknown keys and wrong types are
    reported as ``where.section.key``); an instance of the section's class is taken as it is.
    :func:`config_to_dict` writes sections back as nested dicts, so the two round-trip.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"{cls!r} is not a dataclass type")
    values = dict(values or {})
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(values) - set(fields))
    label = where or cls.__name__
    if unknown:
        named = ", ".join(k + (f" ({RENAMED[k]})" if k in RENAMED else "") for k in unknown)
        known = ", ".join(sorted(fields))
        raise ConfigError(f"{label}: unknown setting(s) {named}; known: {known}")
    kwargs = {
        name: _coerce(value, hints[name], f"{label}.{name}") for name, value in values.items()
    }
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{label}: {exc}") from exc


def _jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def config_to_dict(config: Any) -> Any:
    """A JSON-able view of a config dataclass (nested dataclasses become dicts)."""
    return _jsonable(config)


def load_config_file(path: str | Path) -> dict[str, Any]:
    """Read a TOML (``.toml``) or JSON (``.json``) configuration file into a dict."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the configuration file ({exc.strerror})") from exc
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{p}: not valid {p.suffix.lstrip('.') or 'TOML'}: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a table of settings at the top level")
    return data
