"""The optimiser's settings: frozen sections with the defaults of the flat config they
replaced, each validating its own fields (errors name ``section.field``), round-tripping
through :func:`config_from_mapping` / :func:`config_to_dict` as nested tables; and the one
loop: every solver is a step strategy of :func:`run_least_squares`."""

from __future__ import annotations

import itertools
import json
import tomllib
from dataclasses import replace

import numpy as np
import pytest

from slamkit.config import config_from_mapping, config_to_dict
from slamkit.errors import ConfigError
from slamkit.optim import (
    DoglegConfig,
    EdgeSet,
    GraphData,
    GraphProblem,
    GrowConfig,
    IncrementalConfig,
    LmConfig,
    OptimizerConfig,
    RobustConfig,
    StoppingConfig,
    optimize,
)
from slamkit.optim.loop import SolverContext, run_least_squares
from slamkit.optim.sparse import make_factorizer
from slamkit.optim.steps import (
    BacktrackingGaussNewtonStep,
    DoglegStep,
    GaussNewtonStep,
    LevenbergMarquardtStep,
)


def test_defaults_are_those_of_the_flat_config() -> None:
    cfg = OptimizerConfig()
    assert (cfg.solver, cfg.objective, cfg.initialization, cfg.gauge, cfg.linear_solver) == (
        "lm",
        "g2o",
        "auto",
        "anchor_first",
        "auto",
    )
    assert cfg.stopping == StoppingConfig(100, 1e-6, 1e-9, 0.0, 1e-12)
    assert cfg.lm == LmConfig(1e-5, 10.0, 1e10, "hessian", "gain_ratio")
    assert cfg.dogleg == DoglegConfig(1.0, 1e-12)
    assert cfg.grow == GrowConfig(250, 1500, 1e-3)
    assert cfg.robust == RobustConfig("none", None)
    assert RobustConfig("huber").resolve().width == 3.0
    assert OptimizerConfig(robust=RobustConfig("cauchy", 2.0)).kernel.width == 2.0


def test_round_trip_through_nested_dicts_json_and_toml() -> None:
    cfg = OptimizerConfig(
        solver="dogleg",
        initialization="grow",
        stopping=StoppingConfig(max_iterations=7, relative_tolerance=1e-8),
        lm=LmConfig(damping="marquardt"),
        dogleg=DoglegConfig(trust_radius_initial=0.5),
        robust=RobustConfig(kernel="cauchy", width=2.0),
        grow=GrowConfig(initial_poses=10),
    )
    d = config_to_dict(cfg)
    assert d["stopping"]["max_iterations"] == 7 and d["robust"] == {
        "kernel": "cauchy",
        "width": 2.0,
    }
    assert config_from_mapping(OptimizerConfig, d) == cfg
    assert config_from_mapping(OptimizerConfig, json.loads(json.dumps(d))) == cfg
    text = """
[optimizer]
solver = "dogleg"
initialization = "grow"

[optimizer.stopping]
max_iterations = 7
relative_tolerance = 1e-8

[optimizer.lm]
damping = "marquardt"

[optimizer.dogleg]
trust_radius_initial = 0.5

[optimizer.robust]
kernel = "cauchy"
width = 2.0

[optimizer.grow]
initial_poses = 10
"""
    assert config_from_mapping(OptimizerConfig, tomllib.loads(text)["optimizer"]) == cfg
    # A partial table keeps the other defaults; a built section is taken as it is.
    part = config_from_mapping(OptimizerConfig, {"lm": {"lambda_factor": 5.0}})
    assert part == OptimizerConfig(lm=LmConfig(lambda_factor=5.0))
    assert (
        config_from_mapping(OptimizerConfig, {"lm": LmConfig(lambda_max=1.0)}).lm.lambda_max == 1.0
    )


def test_flat_configs_read_as_before() -> None:
    inc = config_from_mapping(IncrementalConfig, {"relinearize_every": 5})
    assert inc == IncrementalConfig(relinearize_every=5)
    assert config_to_dict(inc)["relinearize_every"] == 5


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda: StoppingConfig(max_iterations=-1),
            r"stopping\.max_iterations: expected an integer >= 0",
        ),
        (
            lambda: StoppingConfig(max_iterations=2.0),
            r"stopping\.max_iterations: expected an integer",
        ),
        (
            lambda: StoppingConfig(relative_tolerance=-1e-3),
            r"stopping\.relative_tolerance: expected a finite",
        ),
        (lambda: StoppingConfig(step_tolerance=float("nan")), r"stopping\.step_tolerance"),
        (lambda: LmConfig(lambda_factor=1.0), r"lm\.lambda_factor: expected a finite number > 1"),
        (lambda: LmConfig(lambda_initial=0.0), r"lm\.lambda_initial: expected a finite number > 0"),
        (
            lambda: LmConfig(damping="x"),
            r"lm\.damping: expected one of 'hessian', 'levenberg', 'marquardt'",
        ),
        (lambda: DoglegConfig(trust_radius_initial=-1.0), r"dogleg\.trust_radius_initial"),
        (lambda: GrowConfig(max_step=0), r"grow\.max_step: expected an integer >= 1"),
        (lambda: RobustConfig(kernel="tukey"), r"robust\.kernel: expected one of"),
        (
            lambda: RobustConfig(kernel="huber", width=-1.0),
            r"robust kernel width: expected a number > 0",
        ),
        (
            lambda: OptimizerConfig(solver="newton"),
            r"^solver: expected one of 'lm', 'gn', 'dogleg'",
        ),
        (lambda: OptimizerConfig(linear_solver="lapack"), r"^linear_solver: expected one of"),
        (lambda: OptimizerConfig(stopping=LmConfig()), r"^stopping: expected a StoppingConfig"),
    ],
)
def test_each_section_validates_its_fields(build, message) -> None:
    with pytest.raises(ConfigError, match=message):
        build()


def test_mapping_errors_name_the_nested_key() -> None:
    with pytest.raises(ConfigError, match=r"optimize\.lm: unknown setting\(s\) lambda"):
        config_from_mapping(OptimizerConfig, {"lm": {"lambda": 1.0}}, "optimize")
    with pytest.raises(
        ConfigError, match=r"optimize\.stopping\.max_iterations: expected an integer"
    ):
        config_from_mapping(OptimizerConfig, {"stopping": {"max_iterations": "many"}}, "optimize")
    with pytest.raises(ConfigError, match=r"optimize\.stopping: expected a table"):
        config_from_mapping(OptimizerConfig, {"stopping": 3}, "optimize")


def _loop_graph() -> GraphData:
    """Eight poses on a noisy square loop (odometry plus one closure), file vertices off."""
    rng = np.random.default_rng(4)
    n = 8
    z = np.tile([1.0, 0.0, np.pi / 4], (n, 1)) + 0.05 * rng.standard_normal((n, 3))
    i = np.arange(n)
    info = np.broadcast_to(np.diag([50.0, 50.0, 200.0]), (n, 3, 3)).copy()
    es = EdgeSet("se2", i, (i + 1) % n, z, info, np.zeros(n, dtype=np.int64))
    poses = np.cumsum(np.tile([0.7, 0.3, 0.8], (n, 1)), axis=0)
    return GraphData(dim=2, pose_ids=i, poses=poses, edges=(es,))


@pytest.mark.parametrize("solver", ["gn", "lm", "dogleg"])
def test_every_solver_is_the_one_loop_with_its_step_strategy(solver: str) -> None:
    """optimize() equals run_least_squares with the solver's strategy, iterate for iterate."""
    data = _loop_graph()
    cfg = OptimizerConfig(solver=solver, initialization="vertices")  # type: ignore[arg-type]
    res = optimize(data, cfg)
    problem = GraphProblem.from_data(data)
    ctx = SolverContext(problem, cfg.kernel, make_factorizer("auto", problem.pattern))
    strategy = {
        "gn": GaussNewtonStep(),
        "lm": LevenbergMarquardtStep(cfg.lm),
        "dogleg": DoglegStep(cfg.dogleg),
    }[solver]
    history: list = []
    out = run_least_squares(
        ctx, ctx.linearize(data.poses.copy(), np.zeros((0, 2))), strategy, cfg.stopping, history
    )
    assert out.iterations == res.iterations and out.reason == res.reason and res.converged
    assert np.array_equal(out.estimate.poses, res.poses)
    assert [h.cost for h in history] == [h.cost for h in res.history]
    assert res.history[-1].cost < res.initial_cost


def test_stopping_rule_max_iterations_and_callback() -> None:
    data = _loop_graph()
    base = OptimizerConfig(solver="gn", initialization="vertices")
    res = optimize(data, replace(base, stopping=StoppingConfig(max_iterations=1)))
    assert (res.iterations, res.converged, res.reason) == (1, False, "max_iterations reached")
    res = optimize(data, base, callback=lambda info: True)
    assert (res.iterations, res.converged, res.reason) == (1, False, "stopped by the callback")
    res = optimize(data, replace(base, stopping=StoppingConfig(gradient_tolerance=1e12)))
    assert res.iterations == 0 and res.converged and res.reason.startswith("gradient")


def test_backtracking_gauss_newton_reaches_the_batch_optimum() -> None:
    """The incremental batch step's strategy: same optimum as LM, cost never rising."""
    data = _loop_graph()
    problem = GraphProblem.from_data(data)
    ctx = SolverContext(problem, OptimizerConfig().kernel, make_factorizer("auto", problem.pattern))
    rule = StoppingConfig(relative_tolerance=1e-12, absolute_tolerance=0.0)
    history: list = []
    start = ctx.linearize(data.poses.copy(), np.zeros((0, 2)))
    out = run_least_squares(
        ctx, start, BacktrackingGaussNewtonStep(1e-12, 0), rule, history, check_gradient=False
    )
    costs = [start.lin.cost] + [h.cost for h in history if h.accepted]
    assert all(b <= a for a, b in itertools.pairwise(costs))
    tight = OptimizerConfig(
        initialization="vertices", stopping=StoppingConfig(relative_tolerance=1e-12)
    )
    ref = optimize(data, tight)
    assert out.converged and out.estimate.lin.cost == pytest.approx(ref.cost, rel=1e-9)
    np.testing.assert_allclose(out.estimate.poses, ref.poses, atol=1e-6)
