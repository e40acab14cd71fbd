"""Run configuration files: reading one, overriding single settings, choosing the data set,
and writing an estimator's defaults as a commented TOML file.

A configuration file (TOML or JSON) has an ``[estimator]`` table (``[mapping]`` for
``slamkit map occupancy``), a ``[dataset]`` table and top-level ``seed`` and ``preset`` (and,
for a run, ``map``: the saved map it localizes in; for a map, ``poses``: the TUM path it is
built along)::

    seed = 3
    [dataset]
    name = "five-features"       # or path = "my_robot.bag"; the rest are the data set's options
    sigma_v = 0.2
    [estimator]
    motion_cov_scale = 2.0
    [estimator.snapshots]        # a section of the estimator's settings
    every = 50

A run's own ``config.json`` has exactly this shape, so it re-runs that run. The data set named
in the file is the one run; a ``--data`` that names another one is an error
(:func:`resolve_data`). ``--set KEY=VALUE`` (:func:`apply_overrides`) changes one setting:
``KEY`` is dotted into the estimator's sections (``kld.epsilon``), ``dataset.KEY`` is a data
set option, ``seed`` and ``preset`` the top-level keys.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slamkit.config import (
    SettingDoc,
    config_from_mapping,
    config_to_dict,
    describe_settings,
    load_config_file,
)
from slamkit.errors import ConfigError

if TYPE_CHECKING:
    from slamkit.datasets.stream import Dataset

__all__ = [
    "DEFAULT_DATA",
    "RunConfig",
    "apply_overrides",
    "config_toml",
    "dataset_table",
    "dataset_toml",
    "defaults_toml",
    "parse_value",
    "read_run_config",
    "resolve_data",
]

DEFAULT_DATA = "five-features"
"""The data set of a run that names none (neither ``--data`` nor a ``[dataset]`` name)."""


@dataclass(frozen=True)
class RunConfig:
    """A configuration file's content, split into what a run takes."""

    settings: dict[str, Any] = field(default_factory=dict)
    """The ``[estimator]`` (or ``[mapping]``) table, sections as nested dicts."""
    dataset_options: dict[str, Any] = field(default_factory=dict)
    """The ``[dataset]`` table without ``name`` and ``path``: the data set's own options."""
    data: str | None = None
    """The data set the file names: ``[dataset] name`` if registered, else its ``path``."""
    seed: int | None = None
    preset: str | None = None
    """The top-level ``preset`` (``config.json`` writes ``null`` for none: ``"none"`` here)."""
    source: str = "the configuration"
    """Where the settings came from, for messages."""
    known_map: str | None = None
    """The top-level ``map``: a saved ``map_server`` YAML to localize in (``slamkit run
    --map``; ``config.json`` records it as an absolute path)."""
    poses: str | None = None
    """The top-level ``poses`` of a mapping configuration: the TUM path mapped along
    (``slamkit map occupancy --poses FILE``; recorded as an absolute path)."""


def read_run_config(path: str | Path | None, main_table: str = "estimator") -> RunConfig:
    """Read a TOML/JSON configuration file (see the module docstring); ``None``: an empty
    configuration. Unknown top-level keys, a non-table section and a non-integer seed are
    :class:`~slamkit.errors.ConfigError`; ``[estimator] name`` is informational (as
    ``config.json`` writes it) and dropped."""
    if path is None:
        return RunConfig()
    raw = load_config_file(path)
    file_key = {"estimator": "map", "mapping": "poses"}.get(main_table)
    allowed = (main_table, "dataset", "seed", "preset", *([file_key] if file_key else []))
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise ConfigError(
            f"{path}: unknown section(s) {', '.join(unknown)}; expected {', '.join(allowed)}"
        )
    seed = raw.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ConfigError(f"{path}: seed must be an integer, got {seed!r}")
    preset = raw.get("preset", None)
    if "preset" in raw and preset is None:
        preset = "none"  # config.json of a run without a preset
    if preset is not None and not isinstance(preset, str):
        raise ConfigError(f"{path}: preset must be a preset's name or 'none', got {preset!r}")
    tables = []
    for name in (main_table, "dataset"):
        table = raw.get(name, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{path}: [{name}] must be a table of settings")
        tables.append(table)
    settings = {k: v for k, v in tables[0].items() if k != "name"}
    ds = tables[1]
    options = {k: v for k, v in ds.items() if k not in ("name", "path")}
    for key in ("map", "poses"):
        if raw.get(key) is not None and not isinstance(raw[key], str):
            raise ConfigError(f"{path}: {key} must be a file's path, got {raw[key]!r}")
    return RunConfig(
        settings,
        options,
        _named_data(ds, path),
        seed,
        preset,
        str(path),
        raw.get("map"),
        raw.get("poses"),
    )


def _named_data(table: Mapping[str, Any], path: str | Path) -> str | None:
    from slamkit.datasets import DATASETS

    name, file = table.get("name"), table.get("path")
    for key, value in (("name", name), ("path", file)):
        if value is not None and not isinstance(value, str):
            raise ConfigError(f"{path}: [dataset] {key} must be a string, got {value!r}")
    if name is not None and name in DATASETS:
        return str(name)
    if file is not None:
        return str(file)
    if name is not None:  # an unregistered name without a path: let load_data say so
        return str(name)
    return None


def _same_data(a: str, b: str) -> bool:
    if a == b:
        return True
    pa, pb = Path(a).expanduser(), Path(b).expanduser()
    return pa.exists() and pb.exists() and pa.resolve() == pb.resolve()


def resolve_data(
    cli_data: str | None,
    config: RunConfig,
    default: str = DEFAULT_DATA,
    *,
    data_root: str | Path | None = None,
) -> str:
    """The data set a run reads: ``--data`` (``cli_data``), else the file's, else
    ``default``. Both given and different: :class:`~slamkit.errors.ConfigError`
    (a configuration's data set is never silently replaced). A path that is not here but is
    under the data folder (``laser/corrected_carmen/orebro-corrected.log.gz``) becomes that
    file's path (:func:`~slamkit.datasets.paths.find_data_file`)."""
    from slamkit.datasets.paths import find_data_file
    from slamkit.datasets.registry import DATASETS

    if cli_data is not None and config.data is not None and not _same_data(cli_data, config.data):
        raise ConfigError(
            f"--data {cli_data} conflicts with the data set {config.data!r} of "
            f"{config.source}; give one of them (or the same in both)"
        )
    spec = cli_data if cli_data is not None else config.data
    if spec is None:
        return default
    if spec in DATASETS:
        return spec
    found = find_data_file(spec, data_root)
    return spec if found is None or found == Path(spec).expanduser() else str(found)


def dataset_table(dataset: Dataset, options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``[dataset]`` table ``config.json`` writes of a loaded data set: its ``name``; the
    ``path`` and ``reader`` of the file it was read from (so that the file re-runs the run,
    read by the same reader even when the run named another than the content calls for);
    and its resolved options (the loader's record, else ``options``) — all from the data
    set's :class:`~slamkit.datasets.provenance.Provenance`."""
    table: dict[str, Any] = {"name": dataset.name}
    source = dataset.provenance
    if source.path is not None:
        table["path"] = source.path
        table["reader"] = source.reader
    table.update(source.options if source.options is not None else dict(options or {}))
    return table


def parse_value(text: str) -> Any:
    """A ``--set`` value read as a TOML value (``2``, ``0.5``, ``true``, ``[1, 2]``,
    ``"nn"``, ``inf``); anything TOML does not read is taken as a string (``nn``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _set_dotted(table: dict[str, Any], keys: list[str], value: Any, where: str) -> dict[str, Any]:
    out = dict(table)
    head = keys[0]
    if len(keys) == 1:
        out[head] = value
        return out
    inner = out.get(head, {})
    if not isinstance(inner, dict):
        raise ConfigError(f"--set {where}: {head} is a setting, not a section")
    out[head] = _set_dotted(inner, keys[1:], value, where)
    return out


def apply_overrides(config: RunConfig, assignments: Iterable[str], main_table: str) -> RunConfig:
    """``config`` with each ``KEY=VALUE`` of ``assignments`` applied in order (see the module
    docstring; a leading ``estimator.``/``mapping.`` is allowed). A malformed assignment is a
    :class:`~slamkit.errors.ConfigError`; unknown keys are reported when the run builds
    its configuration."""
    for text in assignments:
        key, sep, value_text = text.partition("=")
        key = key.strip()
        keys = key.split(".")
        if not sep or not key or any(not k for k in keys):
            raise ConfigError(f"--set {text!r}: expected KEY=VALUE, e.g. motion_cov_scale=2")
        value = parse_value(value_text.strip())
        if keys == ["seed"]:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"--set seed: expected an integer, got {value_text!r}")
            config = replace(config, seed=value)
        elif keys == ["preset"]:
            config = replace(config, preset=str(value))
        elif keys[0] == "dataset":
            if len(keys) == 1:
                raise ConfigError(f"--set {text!r}: name a data set option (dataset.KEY)")
            if keys[1:] in (["name"], ["path"]):
                config = replace(config, data=str(value))
            else:
                config = replace(
                    config,
                    dataset_options=_set_dotted(config.dataset_options, keys[1:], value, key),
                )
        else:
            if keys[0] == main_table and len(keys) > 1:
                keys = keys[1:]
            config = replace(config, settings=_set_dotted(config.settings, keys, value, key))
    return config


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        if value in ("inf", "-inf"):
            return value
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    return json.dumps(str(value))


def _documented(docs: Iterable[SettingDoc], table: str, first: Iterable[str] = ()) -> list[str]:
    """The ``[table]`` of TOML lines: ``first`` (lines written right under the header), then
    each setting under its documentation (comments), sections as ``[table.section]``
    tables, a setting whose value is ``None`` (unset) commented out."""
    lines = [f"[{table}]", *first]
    current = table
    for doc in docs:
        *sections, name = doc.key.split(".")
        header = ".".join([table, *sections])
        if header != current:
            lines += ["", f"[{header}]"]
            current = header
        lines.append("")
        lines += [f"# {paragraph}" for paragraph in doc.doc.splitlines() if paragraph]
        lines.append(f"# ({doc.type}" + (f"; {doc.expected})" if doc.expected else ")"))
        if doc.default is None:
            lines.append(f"# {name} =   (unset)")
        else:
            lines.append(f"{name} = {_toml_value(doc.default)}")
    return lines


def defaults_toml(config_type: type, table: str, title: str = "") -> str:
    """The defaults of ``config_type`` as a TOML file, each setting under its documentation
    (comments), sections as ``[table.section]`` tables. A setting whose default is ``None``
    (unset: the estimator chooses) is written commented out. The text reads back with
    :func:`read_run_config` to the defaults."""
    lines = [f"# {title}", ""] if title else []
    lines += _documented(describe_settings(config_type), table)
    return "\n".join(lines) + "\n"


def dataset_toml(
    data: str,
    options: Mapping[str, Any] | Any,
    options_type: type | None = None,
    reader: str | None = None,
) -> str:
    """A ``[dataset]`` table naming ``data`` (a registered name, else ``path``) with the data
    set's resolved ``options`` (as ``config.json`` writes them, or the options object).

    With ``options_type`` (the class the data set reads its options into), each option is
    written under its documentation, as :func:`defaults_toml` writes an estimator's. With
    ``reader`` (the reader chosen for a path), the ``reader`` key is documented with its
    allowed values and written commented out, so that the file keeps choosing by content."""
    from slamkit.datasets import DATASETS

    key = "name" if data in DATASETS else "path"
    first = [f"{key} = {_toml_value(data)}"]
    if reader is not None:
        from slamkit.datasets.files import READERS

        first += [
            "",
            f"# The reader of the file, chosen by its content ({reader} for this one); name "
            "one to override the choice.",
            f"# Each reader has options of its own: those below are {reader}'s.",
            "# (one of " + ", ".join(_toml_value(r) for r in READERS) + ")",
            f"# reader = {_toml_value(reader)}",
        ]
    if options_type is not None:
        instance = (
            options
            if isinstance(options, options_type)
            else config_from_mapping(options_type, options, "dataset")
        )
        docs = describe_settings(options_type, instance=instance)
        return "\n".join(_documented(docs, "dataset", first)) + "\n"
    lines = ["[dataset]", *first]
    nested = []
    for name, value in config_to_dict(options).items():
        if value is None:
            lines.append(f"# {name} =   (unset)")
        elif isinstance(value, Mapping):
            nested.append((name, value))
        else:
            lines.append(f"{name} = {_toml_value(value)}")
    for name, value in nested:
        lines.append(f"{name} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def config_toml(
    estimator: str, data: str | None = None, *, data_root: str | Path | None = None
) -> str:
    """``slamkit config show``: ``estimator``'s settings with their defaults and
    documentation as a TOML file; with ``data`` (a registered name or a path) the data set's
    ``[dataset]`` table first, its options documented (:func:`dataset_toml`), so that the
    file runs as it is with ``slamkit run ESTIMATOR --config FILE``.

    A registered data set is loaded for its resolved options (a loader may set its own
    defaults); a path is not read beyond the head its reader is chosen by
    (:func:`slamkit.datasets.files.file_options`), so that a file that does not read yet
    still shows the options that may make it read."""
    from slamkit.pipeline import get_estimator_entry

    entry = get_estimator_entry(estimator)
    title = (
        f"slamkit run {entry.name} --config FILE: the defaults of {entry.name} "
        f"({entry.description}).\n# A preset (slamkit/app/presets.py) may change some of them "
        "on its data set; a setting written here wins over the preset."
    )
    text = defaults_toml(entry.config_type(), "estimator", title)
    if data is None:
        return text
    from slamkit.datasets import DATASETS

    if data in DATASETS:
        from slamkit.datasets.files import load_data

        resolved = load_data(data, data_root=data_root).provenance.options or {}
        table = dataset_toml(data, resolved, DATASETS[data].options_type())
    else:
        from slamkit.datasets.files import file_options

        reader, options, _ = file_options(data, data_root=data_root)
        path = str(Path(data).expanduser().resolve())  # as config.json names it
        table = dataset_toml(path, options, type(options), reader)
    head, _, rest = text.partition("\n[estimator]")
    return f"{head}\n{table}\n[estimator]{rest}"
