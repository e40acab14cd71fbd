"""Static HTML report pages of runs (no matplotlib, no server, no template engine), and saved
runs as a table (console, CSV)."""

from slamkit.report.html import (
    FIGURE_CAPTIONS,
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
from slamkit.report.table import (
    ComparisonTable,
    comparison_table,
    format_comparison_csv,
    scalar_metrics,
    write_comparison_csv,
)

__all__ = [
    "FIGURE_CAPTIONS",
    "FIGURE_ORDER",
    "ComparisonTable",
    "RunPage",
    "compare_html",
    "comparison_table",
    "flatten_metrics",
    "format_comparison_csv",
    "order_figures",
    "read_run_folder",
    "run_html",
    "scalar_metrics",
    "write_compare_page",
    "write_comparison_csv",
    "write_run_page",
]
