"""Running a sweep on ``dask.distributed``: every point is :func:`slamkit.app.run_job`.

The driver (:func:`run_sweep`) keys every point (:mod:`slamkit.sweep.keys`), skips those
whose ``DIR/runs/<key>/metrics.json`` exists (run folders are written atomically, so one
that exists is complete) or whose failure is recorded in ``DIR/failures/<key>.json``, and
submits the rest to a Dask cluster: a :class:`~distributed.LocalCluster` of worker processes
with one thread (and one BLAS thread) each, or the scheduler at an address. A worker thread
hands its task to a job process of its own (:mod:`slamkit.sweep.job_process`), where the job
runs as fast as in a plain ``slamkit run``. Each task catches its own errors and returns
them as a failed outcome, so a failing run stops no other; a worker that dies has its task
re-run elsewhere by the scheduler (Dask's ``distributed.scheduler.allowed-failures``, 3 by
default; past that the run is recorded as failed). The results table is rewritten as results
arrive, from what is on disk, so an interrupted sweep loses nothing that finished.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slamkit.errors import ConfigError, InputError
from slamkit.sweep.keys import run_key, slamkit_version
from slamkit.sweep.spec import SweepPoint, SweepSpec, load_spec, parse_spec
from slamkit.sweep.table import flatten_metrics, write_table

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "RunOutcome",
    "RunTask",
    "SweepProgress",
    "SweepResult",
    "execute_in_process",
    "execute_task",
    "local_cluster",
    "plan_sweep",
    "run_sweep",
]

logger = logging.getLogger(__name__)
logger.addHandler(logging.NullHandler())

BLAS_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
"""The environment of each local worker process: one BLAS thread, as the worker has one
task thread (N processes on N cores, not N × cores threads fighting). This is about
process-level parallelism, so it stays an environment (inherited by the worker's job
process) rather than :func:`slamkit.runtime.blas_threads`: it holds every step of a job to
its core (loading, scoring, plots), not only the estimator's run, which the library policy
already limits; and a thread count set in the environment is one the policy respects."""

RUNS = "runs"
FAILURES = "failures"
TABLE_INTERVAL_S = 1.0
"""The table is rewritten at most this often while results arrive (and at the end)."""


@dataclass(frozen=True)
class RunTask:
    """What a worker is sent: one point, its key and where to write."""

    key: str
    point: SweepPoint
    out_dir: str
    plots: bool = False
    preset: str | None = "auto"
    data_root: str | None = None


@dataclass(frozen=True)
class RunOutcome:
    """What a worker sends back: the metrics (``metrics.json``) or the one-line error."""

    key: str
    ok: bool
    metrics: Mapping[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0
    worker_pid: int = 0


def one_line(exc: BaseException) -> str:
    """``TypeName: first line of the message``."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


def execute_task(task: RunTask) -> RunOutcome:
    """Run one point exactly as ``slamkit run`` does, in this thread's job process
    (:mod:`slamkit.sweep.job_process`: a Dask worker thread runs a job measurably slower than a
    plain process does). Any exception of the run, and the job process's death, becomes a
    failed outcome; a job process that cannot be started raises (Dask then records the
    task's error)."""
    from slamkit.sweep.job_process import JobProcessDied, run_in_job_process

    start = time.perf_counter()
    try:
        outcome: RunOutcome = run_in_job_process(execute_in_process, task)
    except JobProcessDied as exc:  # the run took its process down: a result, like any failure
        return RunOutcome(
            task.key,
            False,
            error=one_line(exc),
            seconds=time.perf_counter() - start,
            worker_pid=os.getpid(),
        )
    return outcome


def execute_in_process(task: RunTask) -> RunOutcome:
    """:func:`execute_task` in this process and thread."""
    from slamkit.app.jobs import RunRequest, run_job

    start = time.perf_counter()
    p = task.point
    done = Path(task.out_dir) / "metrics.json"
    metrics, error = None, None
    if done.is_file():
        # An earlier attempt finished but its result was lost with its worker (the scheduler
        # recomputes lost results); the key names the run, so the folder on disk is this run.
        metrics = _read_json(done)
    else:
        try:
            metrics = run_job(
                RunRequest(
                    estimator=p.estimator,
                    dataset=p.dataset,
                    out_dir=Path(task.out_dir),
                    seed=p.seed,
                    estimator_config=p.settings,
                    dataset_options=p.dataset_options,
                    data_root=None if task.data_root is None else Path(task.data_root),
                    plots=task.plots,
                    preset=task.preset,
                )
            ).metrics
        except Exception as exc:  # a failed run is a result, not the end of the sweep
            error = one_line(exc)
    return RunOutcome(
        task.key,
        error is None,
        metrics=metrics,
        error=error,
        seconds=time.perf_counter() - start,
        worker_pid=os.getpid(),
    )


@dataclass(frozen=True)
class SweepProgress:
    """Counts for a progress bar: of ``total`` runs, ``done`` finished (this time or
    before, failed included), ``failed`` of them failed, ``running`` on the workers now."""

    total: int
    done: int
    running: int
    failed: int
    skipped: int


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did: counts, the rows of the table and the files written."""

    out_dir: Path
    total: int
    executed: int
    """Runs done by this invocation (the others were finished before: ``skipped``)."""
    skipped: int
    failed: int
    rows: list[dict[str, Any]] = field(default_factory=list)
    files: tuple[Path, ...] = ()


def _row(
    point: SweepPoint, key: str, metrics: Mapping[str, Any] | None, error: str | None
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "key": key,
        "status": "ok" if error is None else "failed",
        "error": error,
        "estimator": point.estimator,
        "dataset": point.dataset,
        "seed": point.seed,
    }
    row.update(point.swept)
    if metrics is not None:
        row.update(flatten_metrics(metrics))
    return row


def _read_json(path: Path) -> Any:
    with path.open(encoding="utf-8") as fh:
        return json.load(fh)


def _write_json(path: Path, value: Any) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    tmp.write_text(json.dumps(value, indent=2, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def plan_sweep(spec: SweepSpec) -> list[tuple[str, SweepPoint]]:
    """Every distinct run of ``spec`` with its key (points that resolve to the same run,
    such as a swept value equal to the preset's, are kept once)."""
    seen: dict[str, SweepPoint] = {}
    for point in spec.points():
        seen.setdefault(run_key(point, spec.preset), point)
    return list(seen.items())


def local_cluster(workers: int | None = None) -> Any:
    """A :class:`~distributed.LocalCluster` of ``workers`` processes (default: the CPU
    count), one thread and one BLAS thread each, without a dashboard."""
    from distributed import LocalCluster

    n = (os.cpu_count() or 1) if workers is None else workers
    if n < 1:
        raise InputError(f"workers: expected >= 1, got {n}")
    return LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.ERROR,
        env=dict(BLAS_ENV),
    )


def _as_spec(spec: SweepSpec | Mapping[str, Any] | str | Path) -> SweepSpec:
    if isinstance(spec, SweepSpec):
        return spec
    if isinstance(spec, Mapping):
        return parse_spec(spec)
    return load_spec(spec)


def run_sweep(
    spec: SweepSpec | Mapping[str, Any] | str | Path,
    out_dir: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    client: Client | None = None,
    data_root: str | Path | None = None,
    retry_failed: bool = False,
    progress: Callable[[SweepProgress], None] | None = None,
) -> SweepResult:
    """Run every point of ``spec`` (a :class:`SweepSpec`, a spec mapping, or a TOML file)
    not finished before, each into ``out_dir/runs/<key>/``, and write the results table.

    The cluster: ``client`` if given (left open), else the scheduler at ``scheduler``
    (``tcp://host:8786``), else a :func:`local_cluster` of ``workers`` processes (closed at
    the end). ``data_root`` is passed to every run (it must be a path on the workers);
    by default each worker reads its own ``SLAMKIT_DATA``. Failed runs recorded before are
    skipped unless ``retry_failed``. ``progress`` is called after each result.
    """
    sweep = _as_spec(spec)  # every spec error before anything starts
    if scheduler is not None and client is not None:
        raise InputError("give a scheduler address or a client, not both")
    root = Path(out_dir)
    if root.exists() and not root.is_dir():
        raise InputError(f"{root}: the sweep folder is a file")
    runs, failures = root / RUNS, root / FAILURES
    runs.mkdir(parents=True, exist_ok=True)
    failures.mkdir(exist_ok=True)
    plan = plan_sweep(sweep)
    _write_json(
        root / "sweep.json",
        {
            "name": sweep.name,
            "runs": len(plan),
            "swept": list(sweep.swept_names),
            "slamkit": slamkit_version(),
        },
    )
    rows: dict[str, dict[str, Any]] = {}
    pending: list[tuple[str, SweepPoint]] = []
    failed = 0
    for key, point in plan:
        metrics_file, failure_file = runs / key / "metrics.json", failures / f"{key}.json"
        if metrics_file.is_file():
            rows[key] = _row(point, key, _read_json(metrics_file), None)
        elif failure_file.is_file() and not retry_failed:
            rows[key] = _row(point, key, None, _read_json(failure_file)["error"])
            failed += 1
        else:
            pending.append((key, point))
    skipped = len(rows)

    def table_rows() -> list[dict[str, Any]]:
        return [rows[k] for k, _ in plan if k in rows]

    files = write_table(root, table_rows())
    report = progress or (lambda _: None)
    report(SweepProgress(len(plan), len(rows), 0, failed, skipped))
    if pending:
        failed += _execute(
            sweep,
            pending,
            root,
            rows,
            table_rows,
            report,
            len(plan),
            skipped,
            failed,
            scheduler=scheduler,
            workers=workers,
            client=client,
            data_root=data_root,
        )
        files = write_table(root, table_rows())
    return SweepResult(root, len(plan), len(pending), skipped, failed, table_rows(), files)


def _execute(
    sweep: SweepSpec,
    pending: Sequence[tuple[str, SweepPoint]],
    root: Path,
    rows: dict[str, dict[str, Any]],
    table_rows: Callable[[], list[dict[str, Any]]],
    report: Callable[[SweepProgress], None],
    total: int,
    skipped: int,
    failed_before: int,
    *,
    scheduler: str | None,
    workers: int | None,
    client: Client | None,
    data_root: str | Path | None,
) -> int:
    """Submit ``pending``, collect outcomes into ``rows`` as they arrive; returns how many
    failed."""
    from distributed import Client, as_completed

    owned: list[Any] = []
    if client is None:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout="30s")
            except OSError as exc:
                raise ConfigError(f"scheduler {scheduler}: cannot connect ({exc})") from None
        else:
            cluster = local_cluster(workers)
            owned.append(cluster)
            client = Client(cluster)
        owned.insert(0, client)
    points = dict(pending)
    failed = 0
    try:
        futures = [
            client.submit(
                execute_task,
                RunTask(
                    key,
                    point,
                    str(root / RUNS / key),
                    sweep.plots,
                    sweep.preset,
                    None if data_root is None else str(data_root),
                ),
                key=f"slamkit-run-{key}",
                pure=False,
            )
            for key, point in pending
        ]
        names = {f.key: k for f, (k, _) in zip(futures, pending, strict=True)}
        left = len(futures)
        last_write = time.monotonic()
        for future in as_completed(futures):
            key = names[future.key]
            try:
                outcome: RunOutcome = future.result()
                metrics, error = outcome.metrics, outcome.error
            except Exception as exc:  # KilledWorker: the run killed its workers too often
                metrics, error = None, one_line(exc)
            if error is not None:
                failed += 1
                _write_json(root / FAILURES / f"{key}.json", {"key": key, "error": error})
                logger.info("run %s failed: %s", key, error)
            rows[key] = _row(points[key], key, metrics, error)
            left -= 1
            if time.monotonic() - last_write >= TABLE_INTERVAL_S or left == 0:
                write_table(root, table_rows())
                last_write = time.monotonic()
            threads = sum(client.nthreads().values()) if left else 0
            report(
                SweepProgress(total, len(rows), min(left, threads), failed_before + failed, skipped)
            )
    finally:
        write_table(root, table_rows())  # also when interrupted: what finished is kept
        for thing in owned:
            thing.close()
    return failed
