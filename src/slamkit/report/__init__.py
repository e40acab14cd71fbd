"""Static HTML report pages of runs (no matplotlib, no server, no template engine)."""

from slamkit.report.html import (
    FIGURE_ORDER,
    RunPage,
    compare_html,
    flatten_metrics,
    order_figures,
    read_run_folder,
    run_html,
    write_compare_page,
    write_run_page,
)

__all__ = [
    "FIGURE_ORDER",
    "RunPage",
    "compare_html",
    "flatten_metrics",
    "order_figures",
    "read_run_folder",
    "run_html",
    "write_compare_page",
    "write_run_page",
]
