"""The ``slamkit`` command line (typer + rich): a thin shell over :mod:`slamkit.app`."""
