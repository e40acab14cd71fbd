"""``slamkit landmark-graph --data NAME [--gps/--no-gps] [--window L] [--hierarchical P]``: a
landmark data set solved as a factor graph, its GPS fused or not; with ``--window`` smoothed
over a sliding window instead (:mod:`slamkit.app.landmark_smoother`); with ``--hierarchical``
the GPS fused over local maps of ``P`` poses (:mod:`slamkit.slam.landmark_graph.hierarchical`).

Parses the options, calls :func:`slamkit.app.landmark_graph.landmark_graph_job` and prints a
short table (landmarks, lever arm, fixes down-weighted, the held-out GPS error of the graph
without and with the fixes). Known errors become one red line and exit code 1. Heavy imports
happen inside the command.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import DataRootOption, console, known_errors, output_folder

__all__ = ["landmark_graph_command"]


def _table(m: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("without GPS", justify="right")
    table.add_column("with GPS", justify="right")
    un, fu = m["unfused"], m.get("fused", {})

    def add(name: str, a: str, b: str = "—") -> None:
        table.add_row(escape(name), escape(a), escape(b))

    add("poses / landmarks", f"{un['poses']} / {un['landmarks']}",
        f"{fu['poses']} / {fu['landmarks']}" if fu else "—")  # fmt: skip
    add("solve [s] (rounds)", f"{un['solve_seconds']:.2f}",
        f"{fu['solve_seconds']:.2f} ({fu['rounds']})" if fu else "—")  # fmt: skip
    if fu:
        lever = fu["lever_arm"]
        add("lever arm [m]", "—", f"({lever[0]:.2f}, {lever[1]:.2f})")
        add("fixes fused / down-weighted", "—",
            f"{fu['fixes_fused']} / {fu['fixes_down_weighted']}")  # fmt: skip
    if "hierarchy" in m:
        h = m["hierarchy"]
        add("submaps / largest system", "—", f"{h['submaps']} / {h['largest_local_variables']}")
    if "holdout" in un:
        hu, hf = un["holdout"], fu["holdout"]
        add("held-out GPS RMSE, aligned [m]", f"{hu['rmse']:.2f}", f"{hf['rmse']:.2f}")
        add("held-out GPS median, aligned [m]", f"{hu['median']:.2f}", f"{hf['median']:.2f}")
        add("held-out GPS RMSE, direct [m]", "—", f"{hf['direct_rmse']:.2f}")
        add("held-out fixes scored", str(hu["scored"]), str(hf["scored"]))
    return table


def _window_table(m: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column(f"fixed-lag, window {m['window']}", justify="right")
    table.add_column("batch", justify="right")
    sm, ba = m["smoothed"], m["batch"]
    t = sm["step_seconds"]

    def add(name: str, a: str, b: str = "—") -> None:
        table.add_row(escape(name), escape(a), escape(b))

    add("poses / landmarks", f"{sm['poses']} / {sm['landmarks']}",
        f"{ba['poses']} / {ba['landmarks']}")  # fmt: skip
    add("step median / p95 [ms]", f"{1e3 * t['median']:.2f} / {1e3 * t['p95']:.2f}")
    add("total [s]", f"{t['total']:.2f}", f"{ba['solve_seconds']:.2f}")
    add("landmark re-entries", str(sm["reentries"]))
    if sm["gps"] is not None:
        add("GPS RMSE, aligned [m]", f"{sm['gps']['rmse']:.2f}", f"{ba['gps']['rmse']:.2f}")
        add("GPS median, aligned [m]", f"{sm['gps']['median']:.2f}", f"{ba['gps']['median']:.2f}")
    add("against batch RMSE / max [m]",
        f"{m['against_batch']['rmse']:.2f} / {m['against_batch']['max']:.2f}")  # fmt: skip
    return table


@known_errors
def landmark_graph_command(
    data: Annotated[
        str, typer.Option(help="A landmark data set with ids (victoria-park, landmark-loop).")
    ] = "victoria-park",
    gps: Annotated[bool, typer.Option(help="Fuse the data set's GPS track.")] = True,
    weighting: Annotated[
        str,
        typer.Option(
            metavar="none|huber|cauchy|geman-mcclure|dcs|gate",
            help="How GPS fixes are re-weighted against outliers (gate: chi2 gate).",
        ),
    ] = "gate",
    width: Annotated[
        float | None,
        typer.Option(
            help="Kernel width or gate bound (default: the weighting's own).", show_default=False
        ),
    ] = None,
    gps_sigma: Annotated[float, typer.Option(help="GPS standard deviation per axis, m.")] = 1.0,
    holdout: Annotated[
        int, typer.Option(help="Hold every k-th fix out and score on those (0: none).")
    ] = 10,
    max_duration: Annotated[
        float | None,
        typer.Option(help="Use only the first this many seconds.", show_default=False),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output folder (default: a fresh results/landmark-graph-DATA).", show_default=False
        ),
    ] = None,
    window: Annotated[
        int | None,
        typer.Option(
            help="Smooth the graph over this many nodes (fixed-lag) beside batch; the GPS "
            "only scores.",
            show_default=False,
        ),
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write graph.png.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    data_root: DataRootOption = None,
    hierarchical: Annotated[
        int | None,
        typer.Option(
            metavar="SUBMAP_POSES",
            help="Fuse the GPS hierarchically: local maps of this many poses, joined at a top "
            "level of their base frames anchored by the fixes.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Solve a landmark data set as a factor graph (odometry + the readings' ids), with its
    GPS fused (lever arm estimated, fixes re-weighted) or not; score on held-out fixes.
    With --window L: smooth the graph without its GPS over L nodes (a smoothed EKF-SLAM)
    beside batch, both scored on every fix."""
    from slamkit.app.landmark_graph import LandmarkGraphRequest, landmark_graph_job

    target = output_folder(out, f"landmark-graph-{data}")
    request = LandmarkGraphRequest(
        data=data,
        out_dir=target,
        gps=gps,
        weighting=weighting,
        width=width,
        gps_sigma=gps_sigma,
        holdout_every=holdout,
        max_duration_s=max_duration,
        window=window,
        plots=plots,
        overwrite=overwrite,
        data_root=data_root,
        hierarchical=hierarchical,
    )
    with console.status(f"solving the landmark graph of {escape(data)}"):
        report = landmark_graph_job(request)
    console.print(_table(report.metrics) if window is None else _window_table(report.metrics))
    console.print(
        f"wrote {', '.join(report.files)} to [bold]{escape(str(report.out_dir))}[/]",
        soft_wrap=True,
    )
