"""``slamkit optimize FILE [--out DIR]``: optimise a pose-graph or landmark-graph file
(``--window L``: stream a 2D pose graph through the fixed-lag smoother, ``fixed_lag_cmd.py``).

Parses the options, calls :func:`slamkit.app.optimize.optimize_graph_job` and prints a short
table of its metrics and where the files are. Known errors
(:class:`~slamkit.errors.SlamkitError`: bad options, a malformed file with its line, a graph
without a gauge, an existing output folder) become one red line and exit code 1. Heavy
imports happen inside the command, so ``slamkit --help`` stays fast.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import console, err_console, known_errors, output_folder, progress_bar

if TYPE_CHECKING:
    from slamkit.optim.loop import IterationInfo

__all__ = ["optimize_command"]


def _table(m: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("value", justify="right")

    def add(name: str, value: str) -> None:  # escape: "[s]" would be read as rich markup
        table.add_row(escape(name), escape(value))

    add("poses / landmarks / edges", f"{m['poses']} / {m['landmarks']} / {m['edges']}")
    add("solver, start", f"{m['solver']}, {m['initialization']} ({m['objective']} objective)")
    add("start chosen because", m["start"]["reason"])
    add("χ² initial", f"{m['chi2_initial']:.6g}")
    add("χ² final", f"{m['chi2_final']:.6g}")
    add("SE-Sync F initial", f"{m['sesync_objective_initial']:.6g}")
    add("SE-Sync F final", f"{m['sesync_objective_final']:.6g}")
    if m["robust_kernel"] != "none":
        add(f"robust cost ({m['robust_kernel']}) final", f"{m['cost_final']:.6g}")
    add("iterations", str(m["iterations"]))
    add("converged", f"{'yes' if m['converged'] else 'no'}: {m['reason']}")
    add("solve time [s]", f"{m['solve_seconds']:.3f}")
    add("linear solver", m["linear_solver"])
    if m.get("linear_iterations"):
        unit = "V-cycles" if m["linear_solver"] == "multigrid" else "sweeps"
        add(f"linear {unit}", str(m["linear_iterations"]))
    cert = m.get("certificate")
    if cert is not None:
        add("certificate", "globally optimal" if cert["certified"] else "not certified")
        add("λ_min(S) / tolerance", f"{cert['lambda_min']:.3g} / {cert['tolerance']:.3g}")
        add("F* ≥ (gap)", f"{cert['lower_bound']:.6g} ({cert['gap']:.3g})")
        add("certificate time [s]", f"{cert['seconds']:.3f}")
    stair = m.get("staircase")
    if stair is not None:
        ranks = " → ".join(str(step["rank"]) for step in stair["steps"])
        add("staircase ranks", f"{ranks} ({stair['ranks_climbed']} climbed)")
        verdict = "globally optimal" if stair["certified"] else "not certified"
        add("staircase F (rounded)", f"{stair['objective']:.6g}: {verdict}")
        bound, gap = stair["certificate"]["lower_bound"], stair["certificate"]["gap"]
        add("staircase F* ≥ (gap)", f"{bound:.6g} ({gap:.3g})")
        add("staircase time [s]", f"{stair['seconds']:.3f}")
    return table


@known_errors
def optimize_command(
    file: Annotated[
        Path, typer.Argument(help="Graph file: g2o, TORO .graph, iSAM/GTSAM .txt (.gz too).")
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output folder (default: a fresh results/optimize-FILE, numbered when taken).",
            show_default=False,
        ),
    ] = None,
    solver: Annotated[
        str,
        typer.Option(
            metavar="lm|gn|dogleg|mlr|gauss-seidel",
            help="lm (Levenberg-Marquardt), gn (Gauss-Newton), dogleg, mlr (multilevel "
            "relaxation, no factorisation; 2D pose graphs) or gauss-seidel.",
        ),
    ] = "lm",
    init: Annotated[
        str | None,
        typer.Option(
            metavar="auto|file|odometry|chordal|grow",
            show_default=False,
            help="Start: file (its vertices), odometry, chordal or grow (solves over growing "
            "prefixes); default auto: for pose graphs the lower-cost of file (odometry when "
            "it has no vertices) and chordal, for landmark graphs file, else grow.",
        ),
    ] = None,
    robust: Annotated[
        str,
        typer.Option(metavar="none|huber|cauchy|geman-mcclure|dcs", help="Robust kernel."),
    ] = "none",
    robust_width: Annotated[
        float | None,
        typer.Option(help="Kernel width, in whitened-error units (default: the kernel's own)."),
    ] = None,
    objective: Annotated[
        str,
        typer.Option(metavar="g2o|sesync", help="g2o (the file's χ²) or sesync (SE-Sync's F)."),
    ] = "g2o",
    max_iterations: Annotated[
        int | None, typer.Option(help="Linearisations at most (default 100).")
    ] = None,
    repair_information: Annotated[
        str,
        typer.Option(
            metavar="none|clamp",
            help="Information matrices that are not positive definite: none (an error naming "
            "the line) or clamp (raise their eigenvalues to 1e-6 of the largest; each "
            "repaired edge is counted in metrics.json and a warning printed).",
        ),
    ] = "none",
    certify: Annotated[
        bool,
        typer.Option(
            help="Certify the solution globally optimal (SE-Sync's certificate; needs "
            "--objective sesync and a graph of relative-pose edges only).",
        ),
    ] = False,
    staircase: Annotated[
        bool,
        typer.Option(
            help="With --certify: when the solution is not certified, run the Riemannian "
            "staircase from it and write its certified global optimum.",
        ),
    ] = False,
    window: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Stream a 2D pose graph through the fixed-lag smoother keeping the last "
            "WINDOW poses (poses in id order, older ones marginalised; loop closures to them "
            "dropped and counted). Writes the online and final-window estimates.",
            show_default=False,
        ),
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write graph.png (before and after).")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    data_root: Annotated[
        Path | None,
        typer.Option(
            help="Data folder a FILE not found here is looked up in (else $SLAMKIT_DATA).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Optimise the pose or landmark graph in FILE and write the results to OUT.

    FILE not found here is looked up under the data folder (posegraph2d/intel.g2o). OUT gets
    the optimised graph in the format of FILE (iSAM and GTSAM files cannot hold vertices:
    g2o), graph.png, metrics.json and config.json. Each iteration's χ² is printed."""
    from slamkit.app.optimize import OptimizeRequest, find_graph_file, optimize_graph_job

    file = find_graph_file(file, data_root)
    stem = Path(file.name.removesuffix(".gz")).stem
    if window is not None:  # the fixed-lag smoother: its own module renders it
        from slamkit.cli.fixed_lag_cmd import check_window_options, run_fixed_lag

        check_window_options({
            "--solver": solver != "lm", "--init": init is not None, "--robust": robust != "none",
            "--robust-width": robust_width is not None, "--objective": objective != "g2o",
            "--max-iterations": max_iterations is not None, "--certify": certify,
            "--staircase": staircase,
            "--repair-information": repair_information != "none",
        })  # fmt: skip
        target = output_folder(out, f"fixed-lag-{stem}")
        run_fixed_lag(file, target, window, plots, overwrite)
        return
    target = output_folder(out, f"optimize-{stem}")
    request = OptimizeRequest(
        path=file,
        out_dir=target,
        solver=solver,
        init=init,
        robust_kernel=robust,
        robust_width=robust_width,
        objective=objective,
        max_iterations=max_iterations,
        repair_information=repair_information,
        certify=certify,
        staircase=staircase,
        plots=plots,
        overwrite=overwrite,
    )

    def show(info: IterationInfo) -> None:  # one line per iteration, as g2o prints them
        err_console.print(
            f"iteration {info.iteration:3d}  χ² {info.chi2:.6g}"
            + ("" if info.cost == info.chi2 else f"  robust cost {info.cost:.6g}")
            + ("" if info.accepted else "  (step rejected)"),
            highlight=False,
        )

    with progress_bar(f"optimising {file.name}", unit="iterations") as progress:
        report = optimize_graph_job(request, progress, show)
    repair = report.metrics["information_repair"]
    if repair["warning"]:
        err_console.print(f"[yellow]warning:[/] {escape(repair['warning'])}", soft_wrap=True)
    console.print(_table(report.metrics))
    for note in report.metrics["output"]["notes"]:
        console.print(f"note: {escape(note)}", soft_wrap=True)
    console.print(
        f"wrote {', '.join(report.files)} to [bold]{escape(str(report.out_dir))}[/]",
        soft_wrap=True,
    )
