"""What ``make demo`` / ``slamkit demo`` runs: the main job on the built-in simulated world.

Graph-based laser SLAM (``graph-slam``) round the simulated ring of corridors
(``corridor-loop-laser``): noisy odometry, a 180° laser, a loop that must be closed — the
run writes the map, the trajectory against the truth, the pose graph with its loop closures,
the metrics and the report page (``report.html``) in well under a minute.
Later estimators replace the default here, in one place.
"""

DEMO_ESTIMATOR = "graph-slam"
DEMO_DATASET = "corridor-loop-laser"

DEMO_LOOK_AT = (
    ("report.html", "the report page: figures, metrics, config, timings (open in a browser)"),
    ("map.png", "the occupancy map SLAM built, with its path against the true one (dashed)"),
    ("loops.png", "the pose graph's keyframes and the loop closures it accepted"),
    ("errors.png", "x, y and heading error against time, after the ATE's alignment"),
    ("metrics.json", "ATE, RPE and the estimator's counts (keyframes, loops, timings)"),
)
"""The demo's files worth opening first, and what each shows."""
