"""``slamkit config …``: configuration files. The main app adds :data:`config_app` as
``config``.

``slamkit config show ESTIMATOR [--data NAME|PATH]`` prints the estimator's settings (and the
data set's options) with their defaults and documentation as a TOML file
(:func:`slamkit.app.runconfig.config_toml`): redirect it into a file, edit it and pass it to
``slamkit run ESTIMATOR --config FILE``.
"""

from __future__ import annotations

from typing import Annotated

import typer

from slamkit.cli._common import DataRootOption, command_group, known_errors

__all__ = ["config_app"]

config_app = command_group(
    help="Configuration files: the settings of an estimator with their documentation.",
)


@config_app.command("show")
@known_errors
def show_command(
    estimator: Annotated[str, typer.Argument(help="Estimator name (see `slamkit estimators`).")],
    data: Annotated[
        str | None,
        typer.Option(
            "--data",
            "-d",
            metavar="NAME|PATH",
            help=r"Also write the \[dataset] table of this data set (a name, or a file: the "
            "options of the reader chosen for it) with its options documented.",
            show_default=False,
        ),
    ] = None,
    data_root: DataRootOption = None,
) -> None:
    """Print ESTIMATOR's settings, their defaults and documentation, as a TOML config file
    (with --data, the data set's table first, its options documented, so the file runs as
    it is)."""
    from slamkit.app.runconfig import config_toml

    typer.echo(config_toml(estimator, data, data_root=data_root), nl=False)
