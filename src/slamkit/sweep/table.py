"""The results table of a sweep: one row per run, in ``DIR/results.parquet`` and
``DIR/results.csv``.

A row holds the run's key, status (``"ok"`` or ``"failed"``) and one-line error, its
estimator, data set and seed, the swept settings under their dotted names
(``estimator.motion_cov_scale``, ``dataset.laps``) and every scalar of its ``metrics.json``
flattened the same way (``ate.rmse``, ``nees.mean``, ``nis.mean_nis_per_dof``,
``runtime.total_seconds``, ``diagnostics.…``; a metric that did not apply is
``<name>.skipped`` with the reason). Short lists of numbers become ``name.0``, ``name.1``…;
longer lists are left out (they stay in the run's ``metrics.json``).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from slamkit.errors import DataNotFoundError, InputError

__all__ = [
    "CSV_NAME",
    "PARQUET_NAME",
    "ROW_FIELDS",
    "flatten_metrics",
    "read_table",
    "table_columns",
    "write_table",
]

PARQUET_NAME = "results.parquet"
CSV_NAME = "results.csv"
ROW_FIELDS = ("key", "status", "error", "estimator", "dataset", "seed")
"""The leading columns of every row."""

_SHORT_LIST = 4
_DROPPED = {"estimator", "dataset", "seed"}  # already leading columns


def flatten_metrics(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """``metrics.json`` (nested) → flat dotted names of scalar values."""
    out: dict[str, Any] = {}

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, Mapping):
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        elif isinstance(value, list | tuple):
            if len(value) <= _SHORT_LIST and all(
                isinstance(v, int | float | str | bool) for v in value
            ):
                for i, v in enumerate(value):
                    out[f"{prefix}.{i}"] = v
        elif value is None or isinstance(value, int | float | str | bool):
            out[prefix] = value

    for key, value in metrics.items():
        if key not in _DROPPED:
            walk(key, value)
    return out


def table_columns(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The columns of ``rows``: :data:`ROW_FIELDS`, the swept settings, then the metrics in
    the order they first appear."""
    seen: dict[str, None] = dict.fromkeys(ROW_FIELDS)
    settings = [c for r in rows for c in r if c.startswith(("estimator.", "dataset."))]
    seen.update(dict.fromkeys(settings))
    for r in rows:
        seen.update(dict.fromkeys(r))
    return list(seen)


def _column(values: list[Any]) -> Any:
    import pyarrow as pa

    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed kinds (a number and a string)
        return pa.array([None if v is None else str(v) for v in values], type=pa.string())


def _clean(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else value
    return value


def write_table(out_dir: str | Path, rows: Sequence[Mapping[str, Any]]) -> tuple[Path, Path]:
    """Write ``rows`` as ``results.parquet`` and ``results.csv`` in ``out_dir``, each
    replacing the old file in one rename (a reader never sees half a table)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    folder = Path(out_dir)
    columns = table_columns(rows)
    table = pa.table({c: _column([_clean(r.get(c)) for r in rows]) for c in columns})
    paths = (folder / PARQUET_NAME, folder / CSV_NAME)
    for path in paths:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=folder)
        os.close(fd)
        try:
            if path.suffix == ".parquet":
                pq.write_table(table, tmp)
            else:
                pcsv.write_csv(table, tmp)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return paths


def read_table(out_dir: str | Path) -> list[dict[str, Any]]:
    """The rows of a sweep folder's ``results.parquet``."""
    import pyarrow.parquet as pq

    path = Path(out_dir) / PARQUET_NAME
    if not path.is_file():
        raise DataNotFoundError(f"{path}: no results table (run `slamkit sweep SPEC` first)")
    try:
        rows: list[dict[str, Any]] = pq.read_table(path).to_pylist()
    except Exception as exc:  # pyarrow's own error types vary by version
        raise InputError(f"{path}: not a readable Parquet table ({exc})") from exc
    return rows
