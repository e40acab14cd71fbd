"""``slamkit config …``: configuration files. The main app adds :data:`config_app` as
``config``.

``slamkit config show ESTIMATOR`` prints the estimator's settings with their defaults and
documentation as a TOML file (:func:`slamkit.app.runconfig.defaults_toml`): redirect it into
a file, edit it and pass it to ``slamkit run ESTIMATOR --config FILE``.
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
            help="Also write the [dataset] table of this data set with its options.",
            show_default=False,
        ),
    ] = None,
    data_root: DataRootOption = None,
) -> None:
    """Print ESTIMATOR's settings, their defaults and documentation, as a TOML config file
    (with --data, the data set's table first, so the file runs as it is)."""
    from slamkit.app.runconfig import dataset_toml, defaults_toml
    from slamkit.pipeline import get_estimator_entry

    entry = get_estimator_entry(estimator)
    title = (
        f"slamkit run {entry.name} --config FILE: the defaults of {entry.name} "
        f"({entry.description}).\n# A preset (slamkit/app/presets.py) may change some of them "
        "on its data set; a setting written here wins over the preset."
    )
    text = defaults_toml(entry.config_type(), "estimator", title)
    if data is not None:
        from slamkit.datasets.files import load_data

        dataset = load_data(data, data_root=data_root)
        table = dataset_toml(data, dataset.metadata.get("config", {}))
        head, _, rest = text.partition("\n[estimator]")
        text = f"{head}\n{table}\n[estimator]{rest}"
    typer.echo(text, nl=False)
