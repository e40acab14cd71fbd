"""``run_job``: data set → estimator → result → metrics → output folder (with plots)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slamkit.app.mapping import USABLE_RANGE_ESTIMATORS, with_usable_range
from slamkit.app.outputs import check_formats, write_result_files
from slamkit.app.presets import resolve_preset
from slamkit.app.runconfig import dataset_table
from slamkit.datasets.files import load_data
from slamkit.datasets.reading import ReadingSummary
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError, InputError
from slamkit.eval.records import RunScores
from slamkit.io import atomic_folder, write_json, write_tum
from slamkit.io.folders import check_output_folder
from slamkit.io.rosmap_read import RosMapReading, read_ros_map_reading
from slamkit.pipeline import Progress, Result, Stage, get_estimator_entry, run, work_measure
from slamkit.pipeline.eta import Pace
from slamkit.pipeline.evaluate import evaluate

__all__ = ["ANIMATION_FRAMES", "KNOWN_MAP_ESTIMATORS", "RunReport", "RunRequest", "run_job"]

ANIMATION_FRAMES = 120
"""Frames of the GIF that ``animate`` writes (about 15 s at 8 frames per second)."""

KNOWN_MAP_ESTIMATORS = ("mcl",)
"""The registered estimators that localize in a known occupancy grid, so take
:attr:`RunRequest.known_map`."""


@dataclass(frozen=True)
class RunRequest:
    """Everything one run needs. ``estimator_config`` and ``dataset_options`` are plain
    mappings (from a config file's ``[estimator]`` and ``[dataset]`` tables)."""

    estimator: str
    dataset: str | Dataset
    """A registered data set's name, the path of a file (:func:`slamkit.datasets.files.
    load_data`), or a :class:`~slamkit.datasets.Dataset` built in Python (its
    ``dataset_options`` and ``seed`` then do not apply to it; ``config.json`` names it)."""
    out_dir: Path
    seed: int = 0
    estimator_config: Mapping[str, Any] = field(default_factory=dict)
    dataset_options: Mapping[str, Any] = field(default_factory=dict)
    data_root: Path | None = None
    plots: bool = True
    overwrite: bool = False
    svg: bool = False
    """Also write every figure as SVG (beside its PNG)."""
    animate: bool = False
    """Also write ``animation.gif``: the estimate over time (:data:`ANIMATION_FRAMES` frames)."""
    preset: str | None = "auto"
    """Settings measured for this estimator on this data set (:mod:`slamkit.app.presets`),
    laid under ``estimator_config``: ``"auto"`` the matching preset if there is one, a
    preset's name, or ``None`` for none."""
    formats: tuple[str, ...] = ()
    """Trajectory formats besides TUM (``"kitti"``: :mod:`slamkit.app.outputs`)."""
    rerun: str | None = None
    """Also record the run for rerun (:mod:`slamkit.app.recording`): ``"spawn"`` a viewer,
    a relative ``.rrd`` name inside the output folder, or an absolute path."""
    known_map: Path | None = None
    """A saved ROS ``map_server`` map (its YAML, :mod:`slamkit.io.rosmap_read`) to localize
    in: it replaces the data set's known grid (estimators of :data:`KNOWN_MAP_ESTIMATORS`)."""
    mcap: Path | None = None
    """Also write the run as an MCAP file for Foxglove (:mod:`slamkit.app.foxglove`): a
    relative name inside the output folder, or an absolute path."""


@dataclass(frozen=True)
class RunReport:
    """What a run wrote and measured."""

    out_dir: Path
    files: tuple[str, ...]
    scores: RunScores
    result: Result
    preset: str | None = None
    """The preset the run used, if any."""
    preset_settings: dict[str, Any] = field(default_factory=dict)
    """The preset's settings the run used (those the config left unset)."""
    reading: ReadingSummary | None = None
    """What reading the data file dropped and repaired (None: simulated data)."""
    map_notes: tuple[str, ...] = ()
    """What reading :attr:`RunRequest.known_map` read past (an origin's yaw, unknown keys)."""

    @property
    def metrics(self) -> dict[str, Any]:
        """The scores as written to ``metrics.json``."""
        return run_metrics(self.scores, self.reading)


def run_metrics(scores: RunScores, reading: ReadingSummary | None) -> dict[str, Any]:
    """``metrics.json``: the scores, and under ``"reading"`` what reading the file did."""
    metrics = scores.as_dict()
    if reading is not None:
        metrics["reading"] = reading.to_dict()
    return metrics


def run_job(
    request: RunRequest,
    progress: Progress | None = None,
    stage: Stage | None = None,
    counting: Callable[[str, Pace], None] | None = None,
) -> RunReport:
    """Load the data set, run the estimator, evaluate, and write into ``request.out_dir``:
    ``trajectory.tum``, ``metrics.json``, ``config.json`` (the resolved configuration),
    the files of :func:`slamkit.app.outputs.write_result_files` (``landmarks.csv``,
    ``groundtruth.tum``, ``graph.g2o``, ``map.pgm`` + ``map.yaml``, KITTI on request), PNG
    plots and ``report.html`` (the page of the run: :mod:`slamkit.report`). The folder is
    written completely or not at all.

    ``counting(unit, pace)`` is told once, before the first ``progress(done, total)``, what
    the progress counts (``"scans"``, ``"readings"``, ``"events"``:
    :func:`slamkit.pipeline.work_measure`) and how its time per unit behaves (``"steady"``
    or ``"growing"``: :class:`slamkit.pipeline.eta.TimeLeft`). ``stage(text)`` is told of
    each step without a count, in order: the estimator's last step, scoring, drawing the
    plots, writing the result files (the map among them), writing the plots, the animation,
    the rerun and MCAP recordings, the report page; they take long on big data sets."""
    say = stage if stage is not None else (lambda text: None)
    entry = get_estimator_entry(request.estimator)
    given = request.dataset if isinstance(request.dataset, Dataset) else None
    config, preset = resolve_preset(
        entry.name,
        given.name if given is not None else str(request.dataset),
        request.estimator_config,
        request.preset,
    )
    if entry.name in USABLE_RANGE_ESTIMATORS:  # the same map as `slamkit map occupancy`
        config = with_usable_range(config)
    entry.make_config(config)  # fail on bad config before loading
    if isinstance(request.seed, bool) or not isinstance(request.seed, int) or request.seed < 0:
        raise ConfigError(f"seed: expected an integer >= 0, got {request.seed!r}")
    check_formats(request.formats)
    if request.rerun is not None:
        from slamkit.app.recording import require_rerun

        require_rerun()  # before the work
    if request.mcap is not None:
        from slamkit.app.foxglove import require_mcap

        require_mcap()
    check_output_folder(request.out_dir, overwrite=request.overwrite)  # before the work
    known_map = _read_known_map(entry.name, request.known_map)  # a broken map before the data
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    dataset = given or load_data(
        str(request.dataset),
        seed=request.seed,
        options=request.dataset_options,
        data_root=request.data_root,
    )
    if known_map is not None:  # the saved map replaces the data set's own, if it has one
        if dataset.laser is None:
            raise InputError(
                f"--map: data set {dataset.name!r} has no laser scans to localize with in "
                "an occupancy map"
            )
        dataset = dataclasses.replace(dataset, known_grid=known_map.grid)
    timings["load the data set"] = time.perf_counter() - clock
    if counting is not None:
        measure = work_measure(entry, dataset)
        counting(measure.unit, measure.pace)
    # twice the GIF's frames, from which it picks those where the robot moves
    frames = 2 * ANIMATION_FRAMES if request.animate else 0
    clock = time.perf_counter()
    result = run(
        entry,
        dataset,
        config=config,
        seed=request.seed,
        progress=progress,
        frames=frames,
        stage=say,
    )
    timings["run the estimator"] = time.perf_counter() - clock
    clock = time.perf_counter()
    say("scoring the run")
    evaluation = evaluate(result, dataset)
    timings["evaluate"] = time.perf_counter() - clock
    figures = {}
    clock = time.perf_counter()
    if request.plots:
        from slamkit.viz.report import run_figures  # plotting only when asked for

        say("drawing the plots")
        figures = run_figures(result, dataset, evaluation)
    resolved = {
        "estimator": {"name": entry.name, **result.config},
        "dataset": dataset_table(dataset),
        "seed": request.seed,
        "preset": None if preset is None else preset.name,
    }
    if request.known_map is not None:  # re-run from config.json in any folder
        resolved["map"] = str(Path(request.known_map).resolve())
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        say("writing the result files")
        write_tum(tmp / "trajectory.tum", result.times, result.poses)
        write_json(tmp / "metrics.json", run_metrics(evaluation.scores, dataset.reading))
        write_json(tmp / "config.json", resolved)
        write_result_files(tmp, result, dataset, request.formats)  # landmarks, truth, graph
        if figures:
            from slamkit.viz import save_figure
            from slamkit.viz.report import FIGURE_DPI

            say(f"writing {len(figures)} plots")

            for name, fig in figures.items():
                save_figure(fig, tmp / name, dpi=FIGURE_DPI)
                if request.svg:
                    save_figure(fig, (tmp / name).with_suffix(".svg"))
        if request.animate:
            from slamkit.viz.animation import save_animation

            say(f"writing animation.gif ({ANIMATION_FRAMES} frames)")
            from slamkit.viz.report import gps_alignment

            save_animation(
                result,
                dataset,
                tmp / "animation.gif",
                gps_alignment=gps_alignment(evaluation),
                max_frames=ANIMATION_FRAMES,
            )
        if request.rerun is not None:
            from slamkit.app.recording import record_run

            say("recording the run for rerun")
            where = Path(request.rerun)
            spawn = request.rerun == "spawn"
            record_run(
                result, dataset, "spawn" if spawn else where if where.is_absolute() else tmp / where
            )
        if request.mcap is not None:
            from slamkit.app.foxglove import write_mcap

            say("writing the MCAP file")
            mcap = Path(request.mcap)
            write_mcap(result, dataset, mcap if mcap.is_absolute() else tmp / mcap)
        timings["figures and files"] = time.perf_counter() - clock
        say("writing the report page")
        _write_report(tmp, entry.description, dataset.description, timings)
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    settings = {} if preset is None else dict(preset.settings)
    used = {k: v for k, v in settings.items() if k not in request.estimator_config}
    return RunReport(
        Path(request.out_dir),
        files,
        evaluation.scores,
        result,
        None if preset is None else preset.name,
        used,
        dataset.reading,
        () if known_map is None else known_map.notes,
    )


def _read_known_map(estimator: str, path: Path | None) -> RosMapReading | None:
    """The saved map of :attr:`RunRequest.known_map`, for an estimator that can use one."""
    if path is None:
        return None
    if estimator not in KNOWN_MAP_ESTIMATORS:
        raise ConfigError(
            f"--map: {estimator} does not localize in a known map; "
            f"{', '.join(KNOWN_MAP_ESTIMATORS)} does"
        )
    return read_ros_map_reading(path)


def _write_report(folder: Path, estimator: str, dataset: str, timings: Mapping[str, float]) -> None:
    """``report.html`` from what the folder holds (written last, so it lists every file)."""
    from slamkit.report import read_run_folder, write_run_page

    page = read_run_folder(
        folder, estimator_description=estimator, dataset_description=dataset, timings=timings
    )
    names = (*page.files, "report.html")
    write_run_page(dataclasses.replace(page, files=tuple(sorted(names))))
