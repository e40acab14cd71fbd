"""Configuration is data: frozen dataclasses with documented units and defaults.

Algorithms take config objects, never files or environment variables. This module turns plain
mappings (from a TOML/JSON file or the command line) into those objects, rejecting unknown
keys and wrong types with a :class:`~slamkit.errors.ConfigError`, and turns them back into
JSON-able dictionaries that are written next to every result.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import itertools
import json
import math
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import field
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np

from slamkit.errors import ConfigError

__all__ = [
    "Check",
    "Section",
    "SettingDoc",
    "config_from_mapping",
    "config_to_dict",
    "describe_settings",
    "finite_above",
    "finite_at_least",
    "fraction",
    "int_at_least",
    "load_config_file",
    "optional",
    "setting",
]

C = TypeVar("C")

# -- declarative validation of config sections ----------------------------------------------

Check = Callable[[Any], bool]
"""A field's range test: true when the value is allowed."""


def setting(default: Any, check: Check, expected: str) -> Any:
    """A dataclass field with ``default`` whose value must pass ``check`` (``expected`` says
    what is allowed, for the error message)."""
    return field(default=default, metadata={"check": check, "expected": expected})


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def int_at_least(low: int) -> Check:
    """An integer ``>= low``."""
    return lambda v: _is_int(v) and v >= low


def finite_at_least(low: float) -> Check:
    """A finite number ``>= low``."""
    return lambda v: _is_number(v) and v >= low


def finite_above(low: float) -> Check:
    """A finite number ``> low``."""
    return lambda v: _is_number(v) and v > low


class Section:
    """Base of config sections (frozen dataclasses that inherit it): ``__post_init__``
    checks every field declared with :func:`setting` and every ``Literal``-typed field,
    naming ``SECTION.field`` on failure."""

    SECTION: ClassVar[str] = ""
    _literal_cache: ClassVar[dict[type, dict[str, tuple[Any, ...]]]] = {}

    @classmethod
    def _literals(cls) -> dict[str, tuple[Any, ...]]:
        """The choices of each ``Literal``-typed field (resolved once per class)."""
        cached = Section._literal_cache.get(cls)
        if cached is None:
            cached = {}
            for name, hint in typing.get_type_hints(cls).items():
                if typing.get_origin(hint) is Literal:
                    cached[name] = typing.get_args(hint)
            Section._literal_cache[cls] = cached
        return cached

    def __post_init__(self) -> None:
        prefix = f"{self.SECTION}." if self.SECTION else ""
        choices = self._literals()
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if f.name in choices and value not in choices[f.name]:
                allowed = ", ".join(repr(c) for c in choices[f.name])
                raise ConfigError(f"{prefix}{f.name}: expected one of {allowed}, got {value!r}")
            section = f.default_factory if f.default_factory is not dataclasses.MISSING else None
            if isinstance(section, type) and issubclass(section, Section):
                if not isinstance(value, section):
                    raise ConfigError(
                        f"{prefix}{f.name}: expected a {section.__name__} (a table of "
                        f"settings), got {value!r}"
                    )
                continue
            check = f.metadata.get("check")
            if check is not None and not check(value):
                raise ConfigError(
                    f"{prefix}{f.name}: expected {f.metadata['expected']}, got {value!r}"
                )


def optional(check: Check) -> Check:
    """``None``, or a value passing ``check``."""
    return lambda v: v is None or check(v)


def fraction(*, open_low: bool = False, open_high: bool = False) -> Check:
    """A number in ``[0, 1]`` (``open_low``/``open_high``: excluding that end)."""

    def check(v: Any) -> bool:
        if not _is_number(v):
            return False
        low_ok = v > 0 if open_low else v >= 0
        high_ok = v < 1 if open_high else v <= 1
        return bool(low_ok and high_ok)

    return check


# -- mappings to config objects and back ------------------------------------------------------


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
        if isinstance(value, str) and value in ("inf", "-inf"):
            value = float(value)  # how config_to_dict writes an infinite setting in JSON
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
    "near_window": "graph SLAM: removed 2026-12-07; now the constant "
    "slamkit.slam.laser_graph.loops.NEAR_WINDOW (0.3)",
    "ambiguity_ratio": "graph SLAM: removed 2026-12-07; now the constant "
    "slamkit.slam.laser_graph.loops.AMBIGUITY_RATIO (0.95)",
    "neighbour_edges": "graph SLAM: removed 2026-12-07 (off by default; it lost Intel and "
    "Freiburg 079: the matches share their scans with the chain's, so they are not "
    "independent evidence)",
    "fuse_degenerate": "graph SLAM: removed 2026-12-07 (off by default; it lost Intel: 3.71 m "
    "against 0.053 m)",
    "closure_travel": "graph SLAM: removed 2026-12-07 (off by default; its drift bound was "
    "too tight for Intel: 3.1 m against 0.053 m)",
    "frontend.map_keyframes": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.frontend.LOCAL_MAP_KEYFRAMES (20)",
    "frontend.voxel": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.frontend.LOCAL_MAP_VOXEL (0.05 m)",
    "frontend.min_overlap": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.frontend.MIN_OVERLAP (0.6)",
    "frontend.cov_floor_xy": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.frontend.COV_FLOOR_XY (0.01 m)",
    "frontend.cov_floor_deg": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.frontend.COV_FLOOR_DEG (0.25°)",
    "loops.radius": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.SEARCH_RADIUS (0.5 m)",
    "loops.angle_deg": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.SEARCH_ANGLE_DEG (10°)",
    "loops.max_candidates": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.MAX_CANDIDATES (2)",
    "loops.submap_keyframes": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.SUBMAP_KEYFRAMES (11)",
    "loops.resolution": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.GRID_RESOLUTION (0.05 m)",
    "loops.sigma": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.GRID_SIGMA (0.05 m)",
    "loops.min_inliers": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.MIN_INLIERS (0.6)",
    "loops.max_refinement_xy": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.MAX_REFINEMENT_XY (0.25 m)",
    "loops.max_refinement_deg": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.MAX_REFINEMENT_DEG (3°)",
    "loops.pair_keyframes": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.PAIR_KEYFRAMES (10)",
    "loops.pair_xy": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.PAIR_XY (0.1 m)",
    "loops.pair_deg": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.loops.PAIR_DEG (1.5°)",
    "loops.max_chi2": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.backend.MAX_CHI2 (100)",
    "loops.max_edge_chi2": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.backend.MAX_EDGE_CHI2 (100)",
    "loops.cov_scale": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.estimator.CLOSURE_COV_SCALE (4)",
    "loops.optimize_every": "graph SLAM: removed 2026-12-07; now the constant "
    "laser_graph.estimator.OPTIMIZE_EVERY (1)",
    "loops.rejudge": "graph SLAM: removed 2026-12-07 (issue 32's budget of settings); refused "
    "closures are always judged again (it won on ACES; docs/estimators/laser_graph.md)",
    "optimizer": "graph SLAM: removed 2026-12-07 (issue 32's budget of settings); the back end "
    "builds its optimiser inside (slamkit.slam.laser_graph.backend.default_optimizer)",
    "plicp": "graph SLAM and laser odometry: removed 2026-12-07 (issue 32's budget of "
    "settings); now the constants PLICP of slamkit.slam.laser_graph.frontend (PlIcpConfig's "
    "defaults) and of laser odometry (never tuned but for the 60 ICP steps)",
    "normal_icp": "graph SLAM and laser odometry: removed 2026-12-07 (issue 32's budget of "
    "settings); now the constants NORMAL_ICP of slamkit.slam.laser_graph.frontend "
    "(NormalIcpConfig's defaults) and of laser odometry",
    "map": "graph SLAM: removed 2026-12-07 (issue 32's budget of settings); the map's cell is "
    "now map_resolution, the map is always built, its range is the constant "
    "slamkit.slam.laser_graph.estimator.MAP_MAX_RANGE (30 m)",
    "measurement_noise_scale": "now measurement_cov_scale, a factor on the covariance; "
    "FastSLAM and MCL scaled standard deviations: square the old value",
    "motion_noise_scale": "now motion_cov_scale, a factor on the covariance",
    "noise_scale": "now motion_cov_scale (dead reckoning, least squares) or "
    "measurement_cov_scale (EKF mapping), factors on the covariance",
    "method": "now solver",
    "pose_time_tolerance": "no longer used: known poses arrive through the stream",
    "n_particles_global": "MCL: now start.n_particles (a [estimator.start] table)",
    "global_particles_per_m2": "MCL: now start.particles_per_m2 (a [estimator.start] table)",
    "global_start": "MCL: now start.uniform (a [estimator.start] table)",
    "prior_cov_scale": "MCL: now start.prior_cov_scale (a [estimator.start] table)",
    "alpha_slow": "MCL: now augmented.alpha_slow (a [estimator.augmented] table)",
    "alpha_fast": "MCL: now augmented.alpha_fast (a [estimator.augmented] table)",
    "injection_sigmas": "MCL: now augmented.injection_sigmas (a [estimator.augmented] table)",
    "injection_margin": "MCL: now augmented.injection_margin (a [estimator.augmented] table)",
    "kld_epsilon": "MCL: now kld.epsilon (a [estimator.kld] table)",
    "kld_quantile": "MCL: now kld.quantile (a [estimator.kld] table)",
    "kld_bin_xy": "MCL: now kld.bin_xy (a [estimator.kld] table)",
    "kld_bin_theta_deg": "MCL: now kld.bin_theta_deg (a [estimator.kld] table)",
    "kld_min_particles": "MCL: now kld.min_particles (a [estimator.kld] table)",
    "kld_max_particles": "MCL: now kld.max_particles (a [estimator.kld] table)",
    "sigma_hit": "MCL: now laser.sigma_hit (a [estimator.laser] table)",
    "z_hit": "MCL: now laser.z_hit (a [estimator.laser] table)",
    "z_rand": "MCL: now laser.z_rand (a [estimator.laser] table)",
    "laser_independent_beams": "MCL: now laser.independent_beams (a [estimator.laser] table)",
    "laser_offset": "MCL: now laser.offset (a [estimator.laser] table)",
    "snapshot_every": "MCL: now snapshots.every (a [estimator.snapshots] table)",
    "snapshot_times": "MCL: now snapshots.times (a [estimator.snapshots] table)",
    "recovery_fit": "laser odometry: removed; a match that fits the map poorly is now "
    "relocated over every heading and judged against the wheels (scanmatch.relocate)",
    "recovery_span_deg": "laser odometry: removed; the relocation searches every heading",
    "recovery_step_deg": "laser odometry: removed; the relocation searches every heading",
    # laser odometry, 2026-12-07: 45 settings to 15 (docs/estimators/laser_odometry.md).
    "matcher": "laser odometry: removed 2026-12-07; the keyframe reference matches by "
    "point-to-line ICP (point-to-point ICP was never measured better)",
    "odometry_prior": "laser odometry: removed 2026-12-07; the map reference always holds the "
    "match to the odometry's prediction (without it ACES and Freiburg 079 lost: 0.154 m and "
    "1.74 m against 0.106 m and 0.689 m, and the rooms' corridors slid)",
    "icp": "laser odometry: removed 2026-12-07 with point-to-point ICP (never measured better)",
    # grid RBPF, 2026-12-07: 34 settings to 19 (docs/estimators/grid_rbpf.md, "Settings").
    "map_range": "grid RBPF: now max_range, one limit for mapping and matching",
    "match_range": "grid RBPF: now max_range, one limit for mapping and matching",
    "tile_cells": "grid RBPF: removed 2026-12-07; tiles are 64 cells a side (TILE_CELLS)",
    "match_iterations": "grid RBPF: removed 2026-12-07; never tuned, now the constant MATCH",
    "match_tolerance_xy": "grid RBPF: removed 2026-12-07; never tuned, now the constant MATCH",
    "match_tolerance_deg": "grid RBPF: removed 2026-12-07; never tuned, now the constant MATCH",
    "proposal_temperature": "grid RBPF: removed 2026-12-07; the proposal uses the likelihood "
    "untempered (a temperature of 10 there lost on the simulated rooms)",
    "stencil_sigmas": "grid RBPF: removed 2026-12-07; never tuned (STENCIL_SIGMAS = 1.5)",
    "mode_noise_xy": "grid RBPF: removed 2026-12-07; never tuned (MODE_NOISE, 1 cm and 0.3°)",
    "mode_noise_deg": "grid RBPF: removed 2026-12-07; never tuned (MODE_NOISE, 1 cm and 0.3°)",
    "motion_floor_xy": "grid RBPF: removed 2026-12-07; never tuned (MOTION_FLOOR, 1 cm, 0.5°)",
    "motion_floor_deg": "grid RBPF: removed 2026-12-07; never tuned (MOTION_FLOOR, 1 cm, 0.5°)",
    "recovery_window_xy": "grid RBPF: removed 2026-12-07; the recovery searches ±0.5 m, ±30° "
    "(RECOVERY_SEARCH); a larger error is the guard's relocation over every heading",
    "recovery_window_deg": "grid RBPF: removed 2026-12-07; the recovery searches ±0.5 m, ±30° "
    "(RECOVERY_SEARCH); a larger error is the guard's relocation over every heading",
    "resample_threshold": "grid RBPF: removed 2026-12-07; it resamples when N_eff < N/2 "
    "(RESAMPLE_SHARE, Grisetti et al. 2007)",
    "max_updates": "grid RBPF: removed 2026-12-07; never used (cut the data set instead)",
}
"""Settings that were renamed or removed, with what to write instead (named in the error).
A key ``"SECTION.name"`` applies to ``name`` in the sections whose ``SECTION`` is that (so a
common name removed from one estimator's section does not explain it everywhere); a bare
``"name"`` applies anywhere."""


def _renamed(cls: type, key: str) -> str | None:
    """What :data:`RENAMED` says of the unknown ``key`` of the config class ``cls``."""
    section = getattr(cls, "SECTION", "")
    qualified = RENAMED.get(f"{section}.{key}") if section else None
    return qualified if qualified is not None else RENAMED.get(key)


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
        hints = {k: _renamed(cls, k) for k in unknown}
        named = ", ".join(k + (f" ({hints[k]})" if hints[k] else "") for k in unknown)
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
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not a text file (expected UTF-8 TOML or JSON)") from exc
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{p}: not valid {p.suffix.lstrip('.') or 'TOML'}: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a table of settings at the top level")
    return data


# -- documentation of the settings ------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SettingDoc:
    """One setting of a config dataclass: its dotted ``key`` (``"kld.epsilon"`` inside a
    section), its default as written to ``config.json``, its type and the documentation
    (the attribute docstring under the field, ``""`` when it has none)."""

    key: str
    default: Any
    type: str
    doc: str
    expected: str = ""
    """What the setting's check allows (from :func:`setting`), ``""`` when unchecked."""


def _attribute_docs(cls: type) -> dict[str, str]:
    """The attribute docstrings (a string literal right after a field) of ``cls`` and its
    dataclass bases, read from the source (Python keeps no other record of them)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(inspect.getsource(klass))
        except (OSError, TypeError, SyntaxError):  # no source (frozen app, REPL class)
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for node, after in itertools.pairwise(body):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            ):
                docs[node.target.id] = inspect.cleandoc(after.value.value)
    return docs


def _type_name(annotation: Any) -> str:
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation).replace("typing.", "")


def describe_settings(cls: type, prefix: str = "", instance: Any = None) -> list[SettingDoc]:
    """Every setting of the config dataclass ``cls`` with its default (that of ``instance``
    when given) and documentation, in declaration order; the settings of a section follow
    under ``section.`` keys, with the defaults the enclosing config gives that section."""
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"{cls!r} is not a dataclass type")
    docs = _attribute_docs(cls)
    hints = typing.get_type_hints(cls)
    value = cls() if instance is None else instance
    defaults = config_to_dict(value)
    out: list[SettingDoc] = []
    sections: list[tuple[str, type]] = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            sections.append((f.name, hint))
            continue
        out.append(
            SettingDoc(
                f"{prefix}{f.name}",
                defaults[f.name],
                _type_name(hint),
                docs.get(f.name, ""),
                f.metadata.get("expected", ""),
            )
        )
    for name, section in sections:
        out += describe_settings(section, f"{prefix}{name}.", getattr(value, name))
    return out
