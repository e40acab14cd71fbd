"""A sweep's specification: estimators × data sets × seeds × settings, read from TOML.

The spec file::

    [sweep]
    name = "five-features-consistency"   # optional label
    estimators = ["ekf-localization", "ukf-localization"]
    datasets = ["five-features"]          # registered names or data file paths (a log, a bag)
    seeds = {start = 0, count = 1000}     # or a list [0, 1, 2], or a count: seeds = 10
    samples = 20        # random draws of the ranged settings (needed when there are ranges)
    sample_seed = 0     # the generator of those draws
    plots = false       # write each run's PNGs (as `slamkit run` does); off by default
    preset = "auto"     # "auto", "none" or a preset's name, as `slamkit run --preset`

    [estimator]         # settings of every estimator named above
    gate_probability = 0.999                   # a single value: fixed
    motion_cov_scale = [0.5, 1.0, 2.0]         # a list: one axis of the full grid
    measurement_cov_scale = {low = 4.0, high = 64.0, log = true}   # a range: sampled
    n_particles = {low = 50, high = 200, integer = true}

    [dataset]           # options of every data set named above, the same forms
    laps = [1, 2]

A table whose keys are ``values`` or ``low``/``high`` (with ``log``, ``integer``) is an axis;
any other table is a nested config section (``[estimator.lm]``) whose keys take the same
forms, named ``lm.key``. ``{values = [...]}`` is the way to give a list-valued setting's
choices. Points are the full grid of the list axes × ``samples`` joint draws of the ranged
axes × seeds × data sets × estimators.

:func:`parse_spec` validates everything before any run: unknown estimators and data sets
(a file is named by its absolute path from then on), options a data set's reader does not
have, settings an estimator does not have (its registry entry's ``make_config``, with the preset it
would run under), empty lists and ranges, missing ``samples``. Each error is a
:class:`~slamkit.errors.ConfigError` naming the key.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.config import load_config_file
from slamkit.errors import ConfigError, SlamkitError

__all__ = [
    "GridAxis",
    "RangeAxis",
    "SweepPoint",
    "SweepSpec",
    "load_spec",
    "parse_spec",
]

_SWEEP_KEYS = {
    "name",
    "estimators",
    "datasets",
    "seeds",
    "samples",
    "sample_seed",
    "plots",
    "preset",
}
_TOP_KEYS = {"sweep", "estimator", "dataset"}
_AXIS_KEYS = {"values", "low", "high", "log", "integer"}


@dataclass(frozen=True)
class GridAxis:
    """A setting taking each of ``values`` in turn (one axis of the full grid)."""

    name: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class RangeAxis:
    """A setting drawn uniformly from ``[low, high]`` (log-uniformly when ``log``; whole
    numbers when ``integer``, both ends included)."""

    name: str
    low: float
    high: float
    log: bool = False
    integer: bool = False

    def draw(self, rng: np.random.Generator) -> float | int:
        if self.integer:
            if self.log:
                value = math.exp(rng.uniform(math.log(self.low), math.log(self.high + 1)))
                return int(min(math.floor(value), self.high))
            return int(rng.integers(int(self.low), int(self.high) + 1))
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))
        return float(rng.uniform(self.low, self.high))


Axis = GridAxis | RangeAxis


@dataclass(frozen=True)
class SweepPoint:
    """One run of a sweep: what ``slamkit run`` is given. ``settings`` and
    ``dataset_options`` are nested mappings as in a config file; ``swept`` holds the values
    of the spec's axes at this point under their dotted names (``estimator.x``,
    ``dataset.y``)."""

    estimator: str
    dataset: str
    seed: int
    settings: Mapping[str, Any]
    dataset_options: Mapping[str, Any]
    swept: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep specification (see the module docstring for the file format)."""

    estimators: tuple[str, ...]
    datasets: tuple[str, ...]
    seeds: tuple[int, ...]
    estimator_axes: tuple[Axis, ...] = ()
    dataset_axes: tuple[Axis, ...] = ()
    estimator_fixed: Mapping[str, Any] = field(default_factory=dict)
    """Fixed settings under their dotted names."""
    dataset_fixed: Mapping[str, Any] = field(default_factory=dict)
    samples: int | None = None
    sample_seed: int = 0
    plots: bool = False
    preset: str | None = "auto"
    name: str = "sweep"

    def points(self) -> list[SweepPoint]:
        """Every run, in a fixed order: estimators, data sets, setting combinations, seeds."""
        combos = list(_combinations(self))
        out = []
        for est in self.estimators:
            for ds in self.datasets:
                for est_values, ds_values in combos:
                    for seed in self.seeds:
                        swept = {f"estimator.{k}": v for k, v in est_values.items()}
                        swept.update({f"dataset.{k}": v for k, v in ds_values.items()})
                        out.append(
                            SweepPoint(
                                est,
                                ds,
                                seed,
                                _nest({**self.estimator_fixed, **est_values}),
                                _nest({**self.dataset_fixed, **ds_values}),
                                swept,
                            )
                        )
        return out

    @property
    def swept_names(self) -> tuple[str, ...]:
        """The dotted names of the axes (``estimator.x``, ``dataset.y``)."""
        return tuple(f"estimator.{a.name}" for a in self.estimator_axes) + tuple(
            f"dataset.{a.name}" for a in self.dataset_axes
        )


def _combinations(spec: SweepSpec) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """The setting values of every point: grid × joint draws of the ranges."""
    axes = [("e", a) for a in spec.estimator_axes] + [("d", a) for a in spec.dataset_axes]
    grid = [(side, a) for side, a in axes if isinstance(a, GridAxis)]
    ranges = [(side, a) for side, a in axes if isinstance(a, RangeAxis)]
    draws: list[list[Any]] = [[]]
    if ranges:
        assert spec.samples is not None  # checked by parse_spec
        rng = np.random.default_rng(spec.sample_seed)
        draws = [[a.draw(rng) for _, a in ranges] for _ in range(spec.samples)]
    for values in itertools.product(*(a.values for _, a in grid)):
        for drawn in draws:
            est: dict[str, Any] = {}
            ds: dict[str, Any] = {}
            named: list[tuple[str, Axis]] = [*grid, *ranges]
            for (side, axis), v in zip(named, [*values, *drawn], strict=True):
                (est if side == "e" else ds)[axis.name] = v
            yield est, ds


def _nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted names → nested tables (``lm.damping`` → ``{"lm": {"damping": ...}}``)."""
    out: dict[str, Any] = {}
    for name, value in flat.items():
        *sections, key = name.split(".")
        table = out
        for s in sections:
            table = table.setdefault(s, {})
        table[key] = value
    return out


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _axis(name: str, table: Mapping[str, Any], where: str) -> Axis:
    unknown = sorted(set(table) - _AXIS_KEYS)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)}; expected values or low/high"
        )
    if "values" in table:
        if set(table) != {"values"}:
            raise ConfigError(f"{where}: give either values or low/high, not both")
        return _grid(name, table["values"], where)
    if "low" not in table or "high" not in table:
        raise ConfigError(f"{where}: a range needs both low and high")
    low, high = _number(table["low"], f"{where}.low"), _number(table["high"], f"{where}.high")
    log, integer = table.get("log", False), table.get("integer", False)
    for flag, value in (("log", log), ("integer", integer)):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}.{flag}: expected true or false, got {value!r}")
    if integer and (low != int(low) or high != int(high)):
        raise ConfigError(f"{where}: an integer range needs whole-number ends, got {low}..{high}")
    if not low <= high:
        raise ConfigError(f"{where}: empty range, low {low:g} > high {high:g}")
    if log and low <= 0:
        raise ConfigError(f"{where}: a log range needs low > 0, got {low:g}")
    return RangeAxis(name, low, high, log, integer)


def _grid(name: str, values: Any, where: str) -> GridAxis:
    if not isinstance(values, list):
        raise ConfigError(f"{where}: expected a list of values, got {values!r}")
    if not values:
        raise ConfigError(f"{where}: empty list of values")
    return GridAxis(name, tuple(values))


def _settings(table: Any, where: str, prefix: str = "") -> tuple[list[Axis], dict[str, Any]]:
    """Axes and fixed values of a ``[estimator]`` or ``[dataset]`` table (dotted names)."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: expected a table of settings, got {table!r}")
    axes: list[Axis] = []
    fixed: dict[str, Any] = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        here = f"{where}.{key}"
        if isinstance(value, list):
            axes.append(_grid(name, value, here))
        elif isinstance(value, Mapping) and value and set(value) <= _AXIS_KEYS:
            axes.append(_axis(name, value, here))
        elif isinstance(value, Mapping):
            sub_axes, sub_fixed = _settings(value, here, f"{name}.")
            axes += sub_axes
            fixed.update(sub_fixed)
        else:
            fixed[name] = value
    return axes, fixed


def _names(raw: Mapping[str, Any], key: str) -> tuple[str, ...]:
    value = raw.get(key)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"sweep.{key}: expected a non-empty list of names, got {value!r}")
    if len(set(value)) != len(value):
        raise ConfigError(f"sweep.{key}: names repeated in {value!r}")
    return tuple(value)


def _seeds(value: Any) -> tuple[int, ...]:
    def is_int(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    where = "sweep.seeds"
    if value is None:
        return (0,)
    if is_int(value):
        if value < 1:
            raise ConfigError(f"{where}: expected a count >= 1, got {value}")
        return tuple(range(value))
    if isinstance(value, list):
        if not value:
            raise ConfigError(f"{where}: empty list of seeds")
        if not all(is_int(v) and v >= 0 for v in value):
            raise ConfigError(f"{where}: expected integers >= 0, got {value!r}")
        if len(set(value)) != len(value):
            raise ConfigError(f"{where}: seeds repeated in {value!r}")
        return tuple(value)
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {"start", "count"})
        start, count = value.get("start", 0), value.get("count")
        if unknown or not is_int(start) or not is_int(count) or start < 0:
            raise ConfigError(f"{where}: expected {{start = N >= 0, count = M}}, got {value!r}")
        assert isinstance(count, int) and isinstance(start, int)
        if count < 1:
            raise ConfigError(f"{where}.count: empty range of seeds (count {count})")
        return tuple(range(start, start + count))
    raise ConfigError(f"{where}: expected a count, a list or {{start, count}}, got {value!r}")


def _check_estimator_settings(spec: SweepSpec) -> None:
    """Every estimator accepts every setting: its config built at the first value of each
    axis (and at both ends of each range), under the preset it would run with."""
    from slamkit.app.presets import resolve_preset
    from slamkit.pipeline import get_estimator_entry

    probes: list[dict[str, Any]] = []
    for pick in (0, -1):
        values = dict(spec.estimator_fixed)
        for a in spec.estimator_axes:
            if isinstance(a, GridAxis):
                values[a.name] = a.values[pick]
            else:
                end = a.low if pick == 0 else a.high
                values[a.name] = int(end) if a.integer else end
        probes.append(_nest(values))
    for name in spec.estimators:
        try:
            entry = get_estimator_entry(name)
        except SlamkitError as exc:
            raise ConfigError(f"sweep.estimators: {exc}") from None
        for ds in spec.datasets:
            for probe in probes:
                try:
                    config, _ = resolve_preset(entry.name, ds, probe, spec.preset)
                    entry.make_config(config)
                except SlamkitError as exc:
                    raise ConfigError(f"[estimator] for {name}: {exc}") from None
    for a in spec.estimator_axes:  # every listed value, not only the ends
        if isinstance(a, GridAxis):
            for v in a.values:
                for name in spec.estimators:
                    entry = get_estimator_entry(name)
                    try:
                        entry.make_config(_nest({**spec.estimator_fixed, a.name: v}))
                    except SlamkitError as exc:
                        raise ConfigError(f"estimator.{a.name} for {name}: {exc}") from None


def _datasets(names: Sequence[str]) -> tuple[str, ...]:
    """The spec's data sets: registered names as they are, files by their absolute path
    (``~`` expanded; a relative path is relative to the current folder, as ``--data`` is),
    so that the table names the file and workers on a shared file system find it."""
    from slamkit.datasets.registry import DATASETS

    out = []
    for name in names:
        if name in DATASETS:
            out.append(name)
            continue
        path = Path(name).expanduser()
        if not path.exists():
            known = ", ".join(sorted(DATASETS))
            raise ConfigError(
                f"sweep.datasets: unknown data set {name!r} (not registered and no such file); "
                f"known: {known}"
            )
        out.append(str(path.resolve()))
    if len(set(out)) != len(out):
        raise ConfigError(f"sweep.datasets: the same data set twice in {list(names)!r}")
    return tuple(out)


def _check_dataset_options(spec: SweepSpec) -> None:
    """Every data set takes every ``[dataset]`` option: a key its options class (a
    registered data set's, or the reader's of a file: :func:`slamkit.datasets.files.
    dataset_options_type`) does not have is an error before any run. Values are checked
    by each run (a failed run is a result of the sweep)."""
    import dataclasses

    from slamkit.datasets.files import dataset_options_type
    from slamkit.datasets.registry import DATASETS

    given = {name.split(".")[0] for name in spec.dataset_fixed}
    given |= {a.name.split(".")[0] for a in spec.dataset_axes}
    reader = spec.dataset_fixed.get("reader")
    if any(a.name == "reader" for a in spec.dataset_axes):
        return  # the options class depends on the point
    for name in spec.datasets:
        try:
            cls = dataset_options_type(name, None if reader is None else {"reader": reader})
        except SlamkitError as exc:
            raise ConfigError(f"[dataset] for {name}: {exc}") from None
        known = {f.name for f in dataclasses.fields(cls)} if cls is not None else set()
        if name not in DATASETS:
            known.add("reader")  # a file's reader, named
        unknown = sorted(given - known)
        if unknown:
            raise ConfigError(
                f"[dataset] for {name}: unknown option(s) {', '.join(unknown)}; known: "
                f"{', '.join(sorted(known)) or 'none'}"
            )


def parse_spec(raw: Mapping[str, Any]) -> SweepSpec:
    """Validate a spec mapping (a parsed TOML file) into a :class:`SweepSpec`."""
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise ConfigError(
            f"unknown table(s) {', '.join(unknown)}; expected sweep, estimator, dataset"
        )
    sweep = raw.get("sweep")
    if not isinstance(sweep, Mapping):
        raise ConfigError("sweep: the spec needs a [sweep] table naming estimators and datasets")
    unknown = sorted(set(sweep) - _SWEEP_KEYS)
    if unknown:
        raise ConfigError(
            f"sweep: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(_SWEEP_KEYS))}"
        )
    est_axes, est_fixed = _settings(raw.get("estimator", {}), "estimator")
    ds_axes, ds_fixed = _settings(raw.get("dataset", {}), "dataset")
    samples = sweep.get("samples")
    has_ranges = any(isinstance(a, RangeAxis) for a in [*est_axes, *ds_axes])
    if samples is not None and (
        isinstance(samples, bool) or not isinstance(samples, int) or samples < 1
    ):
        raise ConfigError(f"sweep.samples: expected an integer >= 1, got {samples!r}")
    if has_ranges and samples is None:
        raise ConfigError("sweep.samples: the spec has ranges; say how many draws to make")
    sample_seed = sweep.get("sample_seed", 0)
    if isinstance(sample_seed, bool) or not isinstance(sample_seed, int) or sample_seed < 0:
        raise ConfigError(f"sweep.sample_seed: expected an integer >= 0, got {sample_seed!r}")
    plots = sweep.get("plots", False)
    if not isinstance(plots, bool):
        raise ConfigError(f"sweep.plots: expected true or false, got {plots!r}")
    preset = sweep.get("preset", "auto")
    if not isinstance(preset, str):
        raise ConfigError(f"sweep.preset: expected 'auto', 'none' or a name, got {preset!r}")
    name = sweep.get("name", "sweep")
    if not isinstance(name, str):
        raise ConfigError(f"sweep.name: expected a string, got {name!r}")
    spec = SweepSpec(
        estimators=_names(sweep, "estimators"),
        datasets=_datasets(_names(sweep, "datasets")),
        seeds=_seeds(sweep.get("seeds")),
        estimator_axes=tuple(est_axes),
        dataset_axes=tuple(ds_axes),
        estimator_fixed=est_fixed,
        dataset_fixed=ds_fixed,
        samples=samples if has_ranges else None,
        sample_seed=sample_seed,
        plots=plots,
        preset=None if preset == "none" else preset,
        name=name,
    )
    _check_dataset_options(spec)
    _check_estimator_settings(spec)
    return spec


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a TOML (or JSON) spec file; errors name the file and the key."""
    raw = load_config_file(path)
    try:
        return parse_spec(raw)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
