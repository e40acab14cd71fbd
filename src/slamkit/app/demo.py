"""What ``make demo`` / ``slamkit demo`` runs: the main job on the built-in simulated world.

Later estimators replace the default here, in one place.
"""

DEMO_ESTIMATOR = "dead-reckoning"
DEMO_DATASET = "five-features"
