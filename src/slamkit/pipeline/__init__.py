"""The pipeline: the estimator contract, the estimator registry, the runner, evaluation.

Data flows ``Dataset → run(estimator) → Result → evaluate → metrics``; ``slamkit.io`` writes
results and ``slamkit.viz`` draws them.
"""

from slamkit.estimation.contract import (
    Estimator,
    EstimatorOutput,
    InnovationLog,
    LandmarkEstimate,
    ParticleSnapshot,
    PoseEstimate,
)
from slamkit.pipeline.registry import (
    ESTIMATORS,
    EstimatorEntry,
    get_estimator_entry,
    list_estimators,
)
from slamkit.pipeline.runner import Progress, Result, Stage, run
from slamkit.pipeline.work import WorkMeasure, work_measure

__all__ = [
    "ESTIMATORS",
    "Estimator",
    "EstimatorEntry",
    "EstimatorOutput",
    "InnovationLog",
    "LandmarkEstimate",
    "ParticleSnapshot",
    "PoseEstimate",
    "Progress",
    "Result",
    "Stage",
    "WorkMeasure",
    "get_estimator_entry",
    "list_estimators",
    "run",
    "work_measure",
]
