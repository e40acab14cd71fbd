"""``slamkit eval …``: score a trajectory file. The main app adds :data:`eval_app` as ``eval``.

``slamkit eval ape|rpe REFERENCE ESTIMATE [--align none|se3|sim3|scale|se2] [--max-diff S]
[--offset S] [--delta N] [--delta-unit frames|m] [--all-pairs] [--out DIR]`` compares two
TUM or KITTI files by evo's rules (:func:`slamkit.app.evaluate_files.evaluate_files`) and
prints evo's statistics; as evo, it aligns only when asked and writes files only with
``--out``.

``slamkit eval relations TRAJ.tum RELATIONS [--max-gap S] [--max-duration S] [--json OUT]``
reads a TUM trajectory (:func:`slamkit.io.read_tum`) and a ``*.relations`` file
(:func:`slamkit.datasets.read_relations`), calls :func:`slamkit.eval.relation_errors` and
prints its table (:func:`relations_table`); ``--json`` writes the record. Known errors (a
missing or malformed file, a trajectory that covers no relation) become one red line and exit
code 1. Heavy imports happen inside the command.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import command_group, console, known_errors

if TYPE_CHECKING:
    from slamkit._validation import FloatArray
    from slamkit.eval import RelationError
    from slamkit.eval.pose_error import PoseErrorResult

__all__ = ["eval_app", "pose_error_table", "relations_table"]

eval_app = command_group(
    help="Score trajectory files against reference data.",
)


def relations_table(scores: RelationError) -> Table:
    """The relation metric as a two-column table, in the published tables' units."""
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("value", justify="right")

    def add(name: str, value: str) -> None:  # escape: "[m]" would be read as rich markup
        table.add_row(escape(name), escape(value))

    add("relations scored / given", f"{scores.count} / {scores.total}")
    add("covered [%]", f"{100 * scores.covered_fraction:.1f}")
    add("translational error [m]", f"{scores.translation_mean:.4f} ± {scores.translation_std:.4f}")
    add("rotational error [deg]", f"{scores.rotation_mean_deg:.3f} ± {scores.rotation_std_deg:.3f}")
    add("mean squared translational error [m²]", f"{scores.translation_sq_mean:.6f}")
    add("mean squared rotational error [deg²]", f"{scores.rotation_sq_mean_deg:.4f}")
    add("largest errors", f"{scores.translation_max:.4f} m, {scores.rotation_max_deg:.3f}°")
    if scores.max_duration is not None:
        add("relations up to [s]", f"{scores.max_duration:g}")
    return table


def _read_trajectory(path: Path) -> tuple[FloatArray, FloatArray]:
    from slamkit.errors import DataNotFoundError, DatasetFormatError
    from slamkit.io import read_tum

    if not path.is_file():
        raise DataNotFoundError(f"{path}: not found")
    try:
        return read_tum(path)
    except UnicodeDecodeError:
        raise DatasetFormatError("not a text file (expected a TUM trajectory)", path) from None


@eval_app.command("relations")
@known_errors
def relations_command(
    trajectory: Annotated[
        Path, typer.Argument(help="TUM trajectory: 'time x y z qx qy qz qw' per line.")
    ],
    relations: Annotated[
        Path,
        typer.Argument(
            help="Relations file: 't1 t2 x y z roll pitch yaw' per line (not found here: "
            "looked up under the data folder, e.g. laser/relations/aces.relations)."
        ),
    ],
    max_gap: Annotated[
        float,
        typer.Option(
            help=escape(
                "A stamp between two trajectory samples is interpolated when both lie within "
                "this many seconds of it [s]."
            )
        ),
    ] = 1.0,
    max_duration: Annotated[
        float | None,
        typer.Option(help=escape("Score only relations with |t2 - t1| up to this [s].")),
    ] = None,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the scores to this JSON file.")
    ] = None,
) -> None:
    """Score the trajectory in TRAJECTORY against the reference RELATIONS (the Freiburg
    benchmark's relation metric, Kümmerle et al. 2009)."""
    from slamkit.datasets import read_relations
    from slamkit.datasets.paths import find_data_file
    from slamkit.eval import relation_errors
    from slamkit.io import write_json

    times, poses = _read_trajectory(trajectory)
    reference = read_relations(find_data_file(relations) or relations)
    scores = relation_errors(times, poses, reference, max_gap=max_gap, max_duration=max_duration)
    console.print(f"{escape(trajectory.name)} against {escape(relations.name)}", soft_wrap=True)
    console.print(relations_table(scores))
    if json_out is not None:
        write_json(
            json_out,
            {
                "trajectory": str(trajectory),
                "relations_file": str(relations),
                "relations": scores.as_dict(),
            },
        )
        console.print(f"wrote [bold]{escape(str(json_out))}[/]", soft_wrap=True)


def pose_error_table(result: PoseErrorResult, kind: str) -> Table:
    """APE or RPE statistics (translation [m], rotation [deg]) as evo prints them."""
    if kind == "ape":
        stats = (result.ape, result.ape_rotation_deg)
    else:
        stats = (result.rpe, result.rpe_rotation_deg)
    table = Table(show_header=True, header_style="bold")
    table.add_column("statistic")
    table.add_column(escape(f"{kind.upper()} translation [m]"), justify="right")
    table.add_column(escape(f"{kind.upper()} rotation [deg]"), justify="right")
    for key in ("rmse", "mean", "median", "std", "min", "max", "sse"):
        table.add_row(key, *(f"{getattr(s, key):.6f}" for s in stats))
    table.add_row("pairs", *(str(s.count) for s in stats))
    return table


def _pose_error_command(
    kind: str,
    reference: Path,
    estimate: Path,
    *,
    fmt: str,
    align: str,
    evo_align: bool,
    evo_scale: bool,
    n_align: int | None,
    max_diff: float,
    offset: float,
    delta: float,
    delta_unit: str,
    all_pairs: bool,
    pairs_from_reference: bool,
    out: Path | None,
    plots: bool,
    overwrite: bool,
) -> None:
    from slamkit.app.evaluate_files import EvalFilesRequest, evaluate_files
    from slamkit.errors import ConfigError
    from slamkit.eval.pose_error import alignment_from_evo_flags, describe_alignment

    if evo_align or evo_scale:
        if align != "none":
            raise ConfigError(f"--align {align} and evo's -a/-s: give one of them")
        align = alignment_from_evo_flags(evo_align, evo_scale)

    report = evaluate_files(
        EvalFilesRequest(
            reference, estimate, kind=kind, fmt=fmt, alignment=align,  # type: ignore[arg-type]
            n_align=n_align, max_diff=max_diff, offset=offset, delta=delta,
            delta_unit=delta_unit,  # type: ignore[arg-type]
            all_pairs=all_pairs, pairs_from_reference=pairs_from_reference, out_dir=out,
            plots=plots, overwrite=overwrite,
        )
    )  # fmt: skip
    r = report.result
    console.print(
        f"{escape(estimate.name)} against {escape(reference.name)}: {r.matched} pairs "
        f"(of {r.estimate_poses} estimated, {r.reference_poses} reference poses), "
        f"{describe_alignment(r.alignment)}"
        + (
            f", scale {r.similarity.scale:.6g}"
            if r.similarity is not None and r.alignment in ("sim3", "scale")
            else ""
        )
        + ("" if kind == "ape" else f"; {len(r.rpe_pairs)} pairs {r.delta:g} {r.delta_unit} apart"),
        soft_wrap=True,
    )
    console.print(pose_error_table(r, kind))
    if report.out_dir is not None:
        console.print(
            f"wrote {', '.join(report.files)} to [bold]{escape(str(report.out_dir))}[/]",
            soft_wrap=True,
        )


_REF_HELP = "Reference trajectory (TUM: 'time x y z qx qy qz qw'; KITTI: 12 numbers a line)."
_EST_HELP = "Estimated trajectory, same format."
_FMT = typer.Option(
    "--format",
    metavar="auto|tum|kitti",
    help="File format: auto (KITTI when 12 numbers a line), tum, kitti.",
)
_ALIGN = typer.Option(
    metavar="none|se3|sim3|scale|se2",
    help="Alignment of the estimate, none unless asked (as evo): se3 (Umeyama, evo's -a), "
    "sim3 (with scale, -as), scale (the scale alone, -s), se2 (planar: rotation about z and "
    "x-y translation).",
)
_EVO_A = typer.Option("-a", help="As evo's -a: --align se3 (-as: sim3).", show_default=False)
_EVO_S = typer.Option("-s", help="As evo's -s: --align scale (-as: sim3).", show_default=False)
_N_ALIGN = typer.Option(help="Align on the first N pairs only (default: all).", show_default=False)
_MAX_DIFF = typer.Option(help=escape("Largest stamp difference of a pair [s] (TUM)."))
_OFFSET = typer.Option(help=escape("Added to the estimate's stamps before pairing [s]."))
_DELTA = typer.Option(help="RPE: pairs this far apart (in --delta-unit).")
_DELTA_UNIT = typer.Option(
    metavar="frames|m", help="RPE: delta in poses, or in metres of travelled path."
)
_ALL = typer.Option(help="RPE: every pair i, i+delta (default: i = 0, delta, 2·delta, …).")
_FROM_REF = typer.Option(
    help="RPE in metres: measure the path on the reference (default: on the estimate, as evo)."
)
_OUT = typer.Option(
    help="Also write metrics.json and the plots to this folder (default: print only, as evo).",
    show_default=False,
)


def _make_command(kind: str) -> None:
    @eval_app.command(kind)
    @known_errors
    def command(
        reference: Annotated[Path, typer.Argument(help=_REF_HELP)],
        estimate: Annotated[Path, typer.Argument(help=_EST_HELP)],
        fmt: Annotated[str, _FMT] = "auto",
        align: Annotated[str, _ALIGN] = "none",
        evo_align: Annotated[bool, _EVO_A] = False,
        evo_scale: Annotated[bool, _EVO_S] = False,
        n_align: Annotated[int | None, _N_ALIGN] = None,
        max_diff: Annotated[float, _MAX_DIFF] = 0.01,
        offset: Annotated[float, _OFFSET] = 0.0,
        delta: Annotated[float, _DELTA] = 1,
        delta_unit: Annotated[str, _DELTA_UNIT] = "frames",
        all_pairs: Annotated[bool, _ALL] = False,
        pairs_from_reference: Annotated[bool, _FROM_REF] = False,
        out: Annotated[Path | None, _OUT] = None,
        plots: Annotated[bool, typer.Option(help="With --out: write PNG plots.")] = True,
        overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    ) -> None:
        _pose_error_command(
            kind, reference, estimate, fmt=fmt, align=align, evo_align=evo_align,
            evo_scale=evo_scale, n_align=n_align,
            max_diff=max_diff, offset=offset, delta=delta, delta_unit=delta_unit,
            all_pairs=all_pairs, pairs_from_reference=pairs_from_reference, out=out,
            plots=plots, overwrite=overwrite,
        )  # fmt: skip

    command.__doc__ = (
        f"{'Absolute' if kind == 'ape' else 'Relative'} pose error of ESTIMATE against "
        "REFERENCE, by evo's rules (stamp association; alignment only when asked); prints "
        f"the statistics, and with --out writes metrics.json (APE and RPE), trajectories.png "
        f"and {kind}.png."
    )


_make_command("ape")
_make_command("rpe")
