"""Features extracted from raw sensor data: tree trunks and poles from laser scans
(:mod:`slamkit.features.trees`)."""

from slamkit.features.trees import TreeDetections, TreeExtractorConfig, extract_trees

__all__ = ["TreeDetections", "TreeExtractorConfig", "extract_trees"]
