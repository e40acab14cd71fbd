"""Sweeps: Monte Carlo and parameter studies over estimators × data sets × seeds × settings,
run on ``dask.distributed`` (a local cluster of processes, or a cluster by address).

Each point is exactly :func:`slamkit.app.run_job` (what ``slamkit run`` does) writing its
folder under ``DIR/runs/<key>/``; the key hashes what determines the result, so a re-run
skips what finished. One table (``results.parquet`` + ``results.csv``) collects settings
and metrics; :func:`write_report` summarises it. Needs the ``sweep`` extra
(``dask[distributed]``, ``pyarrow``), imported only when a sweep runs or a table is written.

* :mod:`~slamkit.sweep.spec` — the spec file, its validation and its points
* :mod:`~slamkit.sweep.keys` — run keys
* :mod:`~slamkit.sweep.execute` — the driver and the worker task
* :mod:`~slamkit.sweep.table` — the results table
* :mod:`~slamkit.sweep.report` — summaries (NEES/NIS over seeds, best settings, failures)
"""

from slamkit.sweep.execute import SweepProgress, SweepResult, local_cluster, run_sweep
from slamkit.sweep.keys import key_payload, run_key
from slamkit.sweep.report import (
    ConsistencyOverSeeds,
    SweepReport,
    best_settings,
    consistency_over_seeds,
    summarize,
    write_report,
)
from slamkit.sweep.spec import GridAxis, RangeAxis, SweepPoint, SweepSpec, load_spec, parse_spec
from slamkit.sweep.table import read_table, write_table

__all__ = [
    "ConsistencyOverSeeds",
    "GridAxis",
    "RangeAxis",
    "SweepPoint",
    "SweepProgress",
    "SweepReport",
    "SweepResult",
    "SweepSpec",
    "best_settings",
    "consistency_over_seeds",
    "key_payload",
    "load_spec",
    "local_cluster",
    "parse_spec",
    "read_table",
    "run_key",
    "run_sweep",
    "summarize",
    "write_report",
    "write_table",
]
