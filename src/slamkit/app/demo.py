"""What ``make demo`` / ``slamkit demo`` runs: the main job on the built-in simulated world.

Graph-based laser SLAM (``graph-slam``) round the simulated ring of corridors
(``corridor-loop-laser``): noisy odometry, a 180° laser, a loop that must be closed — the
run writes the map, the trajectory against the truth, the pose graph and the metrics in
seconds. Later estimators replace the default here, in one place.
"""

DEMO_ESTIMATOR = "graph-slam"
DEMO_DATASET = "corridor-loop-laser"
