"""``slamkit optimize FILE --window L``: the fixed-lag smoother's branch of the optimize
command. Calls :func:`slamkit.app.fixed_lag.fixed_lag_job` and prints a short table of its
metrics and where the files are."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import console, progress_bar
from slamkit.errors import ConfigError

__all__ = ["check_window_options", "run_fixed_lag"]


def check_window_options(given: dict[str, bool]) -> None:
    """Refuse batch-only options (``given``: option name → whether it was set) beside
    ``--window``: the smoother has its own Gauss-Newton and no robust kernel."""
    clash = [name for name, set_ in given.items() if set_]
    if clash:
        raise ConfigError(
            f"--window runs the fixed-lag smoother; {', '.join(clash)} "
            f"{'applies' if len(clash) == 1 else 'apply'} to the batch optimiser only"
        )


def _table(m: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("value", justify="right")

    def add(name: str, value: str) -> None:
        table.add_row(escape(name), escape(value))

    t = m["step_seconds"]
    add("poses / edges", f"{m['poses']} / {m['edges']}")
    add("window [poses]", str(m["window"]))
    add("edges dropped (to marginalised poses)", str(m["dropped_edges"]["count"]))
    add("step time median / p95 / max [ms]",
        f"{1e3 * t['median']:.3f} / {1e3 * t['p95']:.3f} / {1e3 * t['max']:.1f}")  # fmt: skip
    add("steps, total [s]", f"{m['steps']}, {t['total']:.2f}")
    add("Gauss-Newton iterations a step (mean / max)",
        f"{m['iterations']['mean']:.2f} / {m['iterations']['max']}")  # fmt: skip
    if "landmarks" in m:  # a pose-landmark graph
        add("landmarks / re-entries", f"{m['landmarks']} / {m['reentries']}")
        add("largest step system / prior [unknowns]",
            f"{m['max_unknowns']} / {m['max_prior_size']}")  # fmt: skip
    else:
        add("largest marginal prior [poses]", str(m["max_prior_poses"]))
    add("χ² arrival guesses", f"{m['chi2_initial']:.6g}")
    add("χ² smoother estimate", f"{m['chi2_final']:.6g}")
    add("last window converged", "yes" if m["converged"] else "no")
    return table


def run_fixed_lag(file: Path, target: Path, window: int, plots: bool, overwrite: bool) -> None:
    """Run the smoother on ``file`` into ``target`` and print its summary."""
    from slamkit.app.fixed_lag import FixedLagRequest, fixed_lag_job
    from slamkit.optim.fixed_lag import FixedLagConfig

    request = FixedLagRequest(
        path=file,
        out_dir=target,
        config=FixedLagConfig(window=window),
        plots=plots,
        overwrite=overwrite,
    )
    with progress_bar(f"smoothing {file.name}", unit="poses") as progress:
        report = fixed_lag_job(request, progress)
    console.print(_table(report.metrics))
    console.print(
        f"wrote {', '.join(report.files)} to [bold]{escape(str(report.out_dir))}[/]",
        soft_wrap=True,
    )
