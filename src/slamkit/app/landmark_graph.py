"""``landmark_graph_job``: a landmark data set → its factor graph solved, with the data set's
GPS fused or not, in one folder written completely or not at all.

The readings are given their landmark ids (the data set's ``identities`` option: Victoria
Park's feature index, a scenario's true association): the graph takes the association as
given (:mod:`slamkit.slam.landmark_graph`). The GPS is the data set's position track
(``truth.position_times`` / ``positions``: Victoria Park's receiver); with ``gps`` every
``holdout_every``-th fix is held out and the estimates are scored on those
(:func:`slamkit.eval.gps_holdout.holdout_gps_error`).

Files written (``OUT`` the output folder):

* ``trajectory.tum`` — the poses at the graph's nodes (fused when ``gps``; with
  ``hierarchical``, the hierarchy's placed local maps);
  ``trajectory_unfused.tum`` — the graph solved without the fixes (with ``gps``);
* ``landmarks.csv`` — the landmark map (``id,x,y``) of the same solution;
* ``graph.png`` — the path(s), the map and the fixes (fused and held out);
* ``metrics.json`` — counts, times, the lever arm, the fixes' weights (how many were
  down-weighted), and the held-out scores of both solutions (aligned and direct); with
  ``hierarchical``, the hierarchy's sizes and times under ``hierarchy``;
* ``config.json`` — the request, to re-run it.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING, Any

from slamkit.app.landmark_graph_types import LandmarkGraphReport, LandmarkGraphRequest
from slamkit.datasets import get_dataset_entry, load_dataset
from slamkit.errors import ConfigError
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.io import atomic_folder, write_json
from slamkit.io.landmarks import write_landmarks_csv
from slamkit.io.tum import write_tum
from slamkit.maps import LandmarkMap
from slamkit.optim.gps import GpsWeighting
from slamkit.slam.landmark_graph import (
    GpsFixes,
    GraphSolution,
    LandmarkGraphConfig,
    build_landmark_graph,
    fused_start,
    solve_fused,
    solve_hierarchical,
    solve_unfused,
)

if TYPE_CHECKING:
    from slamkit.viz.plots import Figure  # app never imports matplotlib itself

__all__ = ["LandmarkGraphReport", "LandmarkGraphRequest", "landmark_graph_job"]

WEIGHTINGS = ("none", "huber", "cauchy", "geman_mcclure", "dcs", "gate")


def _weighting(request: LandmarkGraphRequest) -> GpsWeighting:
    from slamkit.optim.robust import DEFAULT_WIDTHS

    name = request.weighting.replace("-", "_")
    if name not in WEIGHTINGS:
        raise ConfigError(
            f"weighting: expected one of {', '.join(WEIGHTINGS)}, got {request.weighting!r}"
        )
    width = request.width
    if width is None:
        width = 9.21 if name == "gate" else DEFAULT_WIDTHS.get(name, 1.0)
    return GpsWeighting(name, width)  # type: ignore[arg-type]


def _options(request: LandmarkGraphRequest) -> dict[str, Any]:
    cls = get_dataset_entry(request.data).options_type()
    names = {f.name for f in dataclasses.fields(cls)} if cls is not None else set()
    if "identities" not in names:
        raise ConfigError(
            f"{request.data}: its readings cannot be given landmark ids (no 'identities' "
            "option); the landmark graph takes the association as given"
        )
    opts: dict[str, Any] = {"identities": True}
    if request.max_duration_s is not None:
        if "max_duration_s" not in names:
            raise ConfigError(f"{request.data}: takes no max_duration_s")
        opts["max_duration_s"] = request.max_duration_s
    return opts


def _solution_metrics(sol: GraphSolution) -> dict[str, Any]:
    out: dict[str, Any] = {
        "poses": int(sol.poses.shape[0]),
        "landmarks": int(sol.landmark_ids.shape[0]),
        "chi2": sol.chi2,
        "iterations": sol.iterations,
        "rounds": sol.rounds,
        "converged": sol.converged,
        "solve_seconds": sol.seconds,
    }
    if sol.lever_arm is not None and sol.weights is not None:
        out["lever_arm"] = [float(v) for v in sol.lever_arm]
        out["fixes_fused"] = int(sol.weights.shape[0])
        out["fixes_down_weighted"] = int((sol.weights < 0.1).sum())
    return out


def landmark_graph_job(request: LandmarkGraphRequest) -> LandmarkGraphReport:
    """Build, solve and write (module docstring). Raises :class:`~slamkit.errors.ConfigError`
    for bad options or a data set without ids or without GPS."""
    weighting = _weighting(request)
    ds = load_dataset(
        request.data, seed=request.seed, options=_options(request), data_root=request.data_root
    )
    if request.hierarchical is not None and (request.window is not None or not request.gps):
        raise ConfigError("hierarchical: fuses the GPS in batch (needs gps, not window)")
    if request.window is not None:  # the fixed-lag back end: its own job and files
        from slamkit.app.landmark_smoother import smoothed_landmark_graph_job

        return smoothed_landmark_graph_job(request, ds)
    track_t, track_xy = ds.truth.position_times, ds.truth.positions
    gps: GpsFixes | None = None
    if request.gps:
        if track_t is None or track_xy is None:
            raise ConfigError(f"{request.data}: the data set has no GPS track to fuse")
        gps = GpsFixes(track_t, track_xy, request.gps_sigma, request.holdout_every)
    cfg = LandmarkGraphConfig(weighting=weighting)
    t0 = time.perf_counter()
    built = build_landmark_graph(ds, gps=gps)
    build_s = time.perf_counter() - t0
    unfused = solve_unfused(built, cfg)
    metrics: dict[str, Any] = {
        "data": request.data,
        "build_seconds": build_s,
        "unfused": _solution_metrics(unfused),
    }
    final = unfused
    if gps is not None:
        if request.hierarchical is None:
            final = solve_fused(built, *fused_start(built, unfused), cfg)
        else:
            hier = solve_hierarchical(built, request.hierarchical, cfg)
            final = hier.solution
            metrics["hierarchy"] = {
                "submap_poses": request.hierarchical,
                "submaps": hier.submaps,
                "largest_local_variables": hier.largest_local,
                "top_variables": hier.top_variables,
                "flat_variables": hier.flat_variables,
                "local_seconds": hier.local_seconds,
                "top_seconds": hier.top_seconds,
            }
        metrics["fused"] = _solution_metrics(final)
        metrics["weighting"] = {"name": weighting.name, "width": weighting.width}
        metrics["fixes"] = int(gps.times.shape[0])
        if request.holdout_every:
            for key, sol in (("unfused", unfused), ("fused", final)):
                lever = (0.0, 0.0) if sol.lever_arm is None else sol.lever_arm
                score = holdout_gps_error(
                    sol.times, sol.poses, gps.times, gps.positions, gps.held_out, lever
                )
                metrics[key]["holdout"] = score.as_dict()
    figure = _figure(final, gps) if request.plots else None
    config = {**dataclasses.asdict(request), "out_dir": str(request.out_dir)}
    config["data_root"] = None if request.data_root is None else str(request.data_root)
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        write_tum(tmp / "trajectory.tum", final.times, final.poses)
        files = ["trajectory.tum"]
        if gps is not None:
            write_tum(tmp / "trajectory_unfused.tum", unfused.times, unfused.poses)
            files.append("trajectory_unfused.tum")
        write_landmarks_csv(tmp / "landmarks.csv", LandmarkMap(final.landmarks, final.landmark_ids))
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "config.json", config)
        files += ["landmarks.csv", "metrics.json", "config.json"]
        if figure is not None:
            from slamkit.viz.plots import save_figure

            save_figure(figure, tmp / "graph.png", dpi=120)
            files.append("graph.png")
    return LandmarkGraphReport(request.out_dir, tuple(files), metrics)


def _figure(final: GraphSolution, gps: GpsFixes | None) -> Figure:
    from slamkit.viz.gps_fusion import plot_gps_fusion
    from slamkit.viz.plots import new_figure

    fig = new_figure(figsize=(8.0, 7.0))
    plot_gps_fusion(
        fig.add_subplot(),
        final.poses,
        final.landmarks,
        None if gps is None else gps.positions,
        None if gps is None else gps.held_out,
        label="graph + GPS" if gps is not None else "graph",
    )
    return fig
