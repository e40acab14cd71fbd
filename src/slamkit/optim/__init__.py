"""Graph optimisation (the GraphSLAM back-end): sparse nonlinear least squares over SE(2) poses
and 2D landmarks, and over SE(3) poses.

* :mod:`~slamkit.optim.data`: the graph data model shared with :mod:`slamkit.io.posegraph`.
* :mod:`~slamkit.optim.factors`: residuals and analytic Jacobians of every 2D edge kind;
  :mod:`~slamkit.optim.factors3d`: the SE(3) relative-pose and prior edges.
* :mod:`~slamkit.optim.graph`: validation, variable indexing, gauge, vectorised linearisation.
* :mod:`~slamkit.optim.sparse`: the fixed normal-matrix pattern and the Cholesky back-ends.
* :mod:`~slamkit.optim.settings`: :class:`OptimizerConfig` and its sections (stopping rule,
  LM, dogleg, robust kernel, grown start).
* :mod:`~slamkit.optim.loop`: the one nonlinear least-squares loop (linearise, step,
  accept/reject, stop) and its per-iteration record.
* :mod:`~slamkit.optim.steps`: its step strategies: Gauss-Newton, Levenberg-Marquardt,
  Powell's dogleg, and backtracking Gauss-Newton (the incremental batch step).
* :mod:`~slamkit.optim.mlr`: multilevel relaxation and block Gauss-Seidel, the Gauss-Newton
  step of a 2D pose graph without a factorisation.
* :mod:`~slamkit.optim.solvers`: :func:`optimize` and the grown-prefix start of long
  landmark graphs.
* :mod:`~slamkit.optim.init`: odometry spanning tree and chordal initialisation.
* :mod:`~slamkit.optim.objectives`: the g2o χ² and SE-Sync's ``F`` of any solution.
* :mod:`~slamkit.optim.certificate`: SE-Sync's certificate of global optimality (2D, 3D) and the
  lower bound on ``F*`` it gives.
* :mod:`~slamkit.optim.staircase`: the Riemannian staircase, SE-Sync's certified global optimum
  from any start (a refused local minimum included).
* :mod:`~slamkit.optim.robust`: Huber, Cauchy, Geman-McClure and DCS kernels (IRLS).
* :mod:`~slamkit.optim.marginals`: marginal covariances from the factorisation.
* :mod:`~slamkit.optim.incremental`: poses and edges added in time order, window steps
  between periodic batch steps (iSAM-style), equal to batch at the end.
* :mod:`~slamkit.optim.fixed_lag`: the fixed-lag (sliding-window) smoother, older poses
  marginalised into a prior (:mod:`~slamkit.optim.marginal_prior`); every step costs the same.
"""

from slamkit.optim.certificate import Certificate, certify
from slamkit.optim.data import EdgeKind, EdgeSet, GraphData
from slamkit.optim.fixed_lag import (
    FixedLagConfig,
    FixedLagResult,
    FixedLagSmoother,
    smooth_fixed_lag,
)
from slamkit.optim.graph import GraphProblem
from slamkit.optim.incremental import (
    GraphUpdate,
    IncrementalConfig,
    IncrementalOptimizer,
    IncrementalResult,
    UpdateInfo,
    time_ordered_updates,
)
from slamkit.optim.init import (
    chordal_initialization,
    initial_values,
    spanning_tree_initialization,
)
from slamkit.optim.linearization import Linearization
from slamkit.optim.loop import IterationInfo
from slamkit.optim.marginals import Marginals, marginal_covariances
from slamkit.optim.objectives import g2o_chi2, sesync_objective
from slamkit.optim.robust import RobustKernel, robust_rho_and_weight
from slamkit.optim.settings import (
    DoglegConfig,
    GrowConfig,
    LmConfig,
    OptimizerConfig,
    RelaxationConfig,
    RobustConfig,
    StoppingConfig,
)
from slamkit.optim.solvers import (
    OptimizeResult,
    StartChoice,
    choose_start,
    grow_initialization,
    optimize,
)
from slamkit.optim.sparse import cholmod_available
from slamkit.optim.staircase import StaircaseConfig, StaircaseResult, riemannian_staircase

__all__ = [
    "Certificate",
    "DoglegConfig",
    "EdgeKind",
    "EdgeSet",
    "FixedLagConfig",
    "FixedLagResult",
    "FixedLagSmoother",
    "GraphData",
    "GraphProblem",
    "GraphUpdate",
    "GrowConfig",
    "IncrementalConfig",
    "IncrementalOptimizer",
    "IncrementalResult",
    "IterationInfo",
    "Linearization",
    "LmConfig",
    "Marginals",
    "OptimizeResult",
    "OptimizerConfig",
    "RelaxationConfig",
    "RobustConfig",
    "RobustKernel",
    "StaircaseConfig",
    "StaircaseResult",
    "StartChoice",
    "StoppingConfig",
    "UpdateInfo",
    "certify",
    "cholmod_available",
    "choose_start",
    "chordal_initialization",
    "g2o_chi2",
    "grow_initialization",
    "initial_values",
    "marginal_covariances",
    "optimize",
    "riemannian_staircase",
    "robust_rho_and_weight",
    "sesync_objective",
    "smooth_fixed_lag",
    "spanning_tree_initialization",
    "time_ordered_updates",
]
