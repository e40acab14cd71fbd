"""Application layer: whole jobs that combine the pipeline, result files and plots.

The CLI is a thin shell over these functions; notebooks and scripts can call them too.
Unlike the numerical packages, this layer may import :mod:`slamkit.viz` (lazily).
"""

from slamkit.app.jobs import RunReport, RunRequest, run_job
from slamkit.app.optimize import OptimizeReport, OptimizeRequest, optimize_graph_job

__all__ = [
    "OptimizeReport",
    "OptimizeRequest",
    "RunReport",
    "RunRequest",
    "optimize_graph_job",
    "run_job",
]
