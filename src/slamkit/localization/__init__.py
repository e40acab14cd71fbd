"""Localization: Gaussian beliefs, the shared prediction step and dead reckoning."""

from slamkit.localization.belief import GaussianBelief, predict
from slamkit.localization.dead_reckoning import DeadReckoning, DeadReckoningConfig

__all__ = ["DeadReckoning", "DeadReckoningConfig", "GaussianBelief", "predict"]
