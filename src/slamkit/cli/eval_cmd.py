"""``slamkit eval …``: score a trajectory file. The main app adds :data:`eval_app` as ``eval``.

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

from slamkit.cli._common import console, known_errors

if TYPE_CHECKING:
    from slamkit._validation import FloatArray
    from slamkit.eval import RelationError

__all__ = ["eval_app", "relations_table"]

eval_app = typer.Typer(
    help="Score trajectory files against reference data.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
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
        Path, typer.Argument(help="Relations file: 't1 t2 x y z roll pitch yaw' per line.")
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
    from slamkit.eval import relation_errors
    from slamkit.io import write_json

    times, poses = _read_trajectory(trajectory)
    reference = read_relations(relations)
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
