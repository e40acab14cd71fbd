"""Settings of the batch optimiser (:func:`~slamkit.optim.optimize`) as frozen sections.

``OptimizerConfig`` holds the choices (solver, objective, start, gauge, linear back-end) and
one section per concern::

    OptimizerConfig(
        solver="lm",
        stopping=StoppingConfig(max_iterations=100, relative_tolerance=1e-6),
        lm=LmConfig(lambda_initial=1e-5),    # read only by solver="lm"
        dogleg=DoglegConfig(),               # read only by solver="dogleg"
        relaxation=RelaxationConfig(),       # read only by solver="mlr" / "gauss_seidel"
        robust=RobustConfig(kernel="cauchy"),
        grow=GrowConfig(),                   # read only by initialization="grow"
    )

In a TOML file the sections are nested tables (``[optimizer.lm]``), in JSON nested objects;
:func:`~slamkit.config.config_from_mapping` and :func:`~slamkit.config.config_to_dict` read
and write them.

**Validation is declarative** (:class:`slamkit.config.Section`): each field that needs a
range says so where it is declared, ``setting(default, check, expected)``, and a ``Literal``
annotation is its own list of choices; errors name the field as ``section.field``.

Units: ``f`` is the cost ``Σ ρ(‖U e‖²)`` (χ² without a robust kernel, no factor ½),
dimensionless; steps ``δ`` are tangent vectors of the free variables (metres and radians for
poses, metres for landmarks). An *iteration* is one linearisation; LM may factor several
damped systems and dogleg try several radii inside one iteration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slamkit.config import Section, finite_above, finite_at_least, int_at_least, setting
from slamkit.errors import ConfigError
from slamkit.optim.graph import GaugeMode, ObjectiveName
from slamkit.optim.robust import DEFAULT_WIDTHS, KernelName, RobustKernel
from slamkit.optim.sparse import LinearSolverName

__all__ = [
    "DoglegConfig",
    "GrowConfig",
    "InitName",
    "LmConfig",
    "MethodName",
    "OptimizerConfig",
    "RelaxationConfig",
    "RobustConfig",
    "StoppingConfig",
]

MethodName = Literal["lm", "gn", "dogleg", "mlr", "gauss_seidel"]
InitName = Literal["auto", "vertices", "odometry", "chordal", "grow"]


@dataclass(frozen=True)
class StoppingConfig(Section):
    """When the nonlinear least-squares loop stops. Before solving iteration ``k`` it stops
    (converged) when ``max |g| ≤ gradient_tolerance``; after an accepted step from ``f_old``
    to ``f_new`` of size ``max |δ|`` it stops (converged) when the first of
    ``|f_old - f_new| ≤ absolute_tolerance``, ``|f_old - f_new| ≤ relative_tolerance · |f_old|``
    or ``max |δ| ≤ step_tolerance`` holds; after ``max_iterations`` linearisations it stops
    with ``converged = False``."""

    SECTION: ClassVar[str] = "stopping"

    max_iterations: int = setting(100, int_at_least(0), "an integer >= 0")
    """Stop after this many linearisations (``converged = False``)."""
    relative_tolerance: float = setting(1e-6, finite_at_least(0.0), "a finite number >= 0")
    """Stop (converged) after a step when ``|f_old - f_new| ≤ relative_tolerance · |f_old|``
    (dimensionless)."""
    absolute_tolerance: float = setting(1e-9, finite_at_least(0.0), "a finite number >= 0")
    """Stop (converged) after a step when ``|f_old - f_new| ≤ absolute_tolerance`` (cost
    units: χ²)."""
    gradient_tolerance: float = setting(0.0, finite_at_least(0.0), "a finite number >= 0")
    """Stop (converged) before solving when ``max |g| ≤ gradient_tolerance`` (``g = JᵀWr``,
    cost per tangent unit)."""
    step_tolerance: float = setting(1e-12, finite_at_least(0.0), "a finite number >= 0")
    """Stop (converged) after a step when ``max |δ| ≤ step_tolerance`` (tangent units: metres,
    radians)."""


@dataclass(frozen=True)
class LmConfig(Section):
    """Levenberg-Marquardt: solve ``(H + λD) δ = -g`` and accept when ``f`` decreases; ``λ``
    moves by ``schedule`` (the gain-ratio rule of :mod:`slamkit.optim.steps` by default)."""

    SECTION: ClassVar[str] = "lm"

    lambda_initial: float = setting(1e-5, finite_above(0.0), "a finite number > 0")
    """The first damping ``λ`` (``damping="levenberg"``: cost per squared tangent unit;
    ``"marquardt"`` and ``"hessian"``: dimensionless)."""
    lambda_factor: float = setting(10.0, finite_above(1.0), "a finite number > 1")
    """``schedule="fixed"`` only: ``λ`` is divided by this after an accepted step and
    multiplied after a rejected one."""
    lambda_max: float = setting(1e10, finite_above(0.0), "a finite number > 0")
    """Stop (``converged = False``) when ``λ`` exceeds this without finding a decrease."""
    damping: Literal["hessian", "levenberg", "marquardt"] = "hessian"
    """The damping matrix ``D``: ``"hessian"`` (``D = H``: the Gauss-Newton step shortened
    to ``δ_gn / (1 + λ)``, one factorisation per iteration; a singular ``H`` falls back to
    ``D = I`` for that iteration), ``"levenberg"`` (``D = I``, GTSAM's default) or
    ``"marquardt"`` (``D = diag(H)``). Why ``"hessian"`` is the default: the measurements in
    ``docs/estimators/optim.md``."""
    schedule: Literal["gain_ratio", "fixed"] = "gain_ratio"
    """How ``λ`` moves. ``"gain_ratio"`` (Nielsen 1999): with ``ϱ`` the actual over the
    predicted cost reduction, on an accepted step (``ϱ > 0``)
    ``λ ← max(λ · max(1/3, 1 - (2ϱ - 1)³), 1e-20)`` and ``ν ← 2``; on a rejected one
    ``λ ← λ · ν`` and ``ν ← 2ν`` (``ν`` starts at 2). ``"fixed"``: ``λ ← max(λ /
    lambda_factor, 1e-20)`` on accept, ``λ ← λ · lambda_factor`` on reject."""


@dataclass(frozen=True)
class DoglegConfig(Section):
    """Powell's dogleg: a trust region of Euclidean radius ``Δ`` (tangent units) around the
    current estimate, grown to ``max(Δ, 3‖δ‖)`` when the gain ratio exceeds 0.75 and halved
    when it is below 0.25."""

    SECTION: ClassVar[str] = "dogleg"

    trust_radius_initial: float = setting(1.0, finite_above(0.0), "a finite number > 0")
    """The least first trust-region radius (Euclidean norm of ``δ``, tangent units): the
    first region is ``max(trust_radius_initial, ‖δ_gn‖)``, so that it holds the first
    Gauss-Newton step and shrinks only when that step fails."""
    trust_radius_min: float = setting(1e-12, finite_at_least(0.0), "a finite number >= 0")
    """Stop (``converged = False``) when ``Δ`` shrinks below this without finding a
    decrease."""


@dataclass(frozen=True)
class RelaxationConfig(Section):
    """Multilevel relaxation (``solver="mlr"``) and block Gauss-Seidel
    (``solver="gauss_seidel"``): per linearisation, ``H δ = -g`` is solved from ``δ = 0`` by
    V-cycles (MLR) or sweeps (Gauss-Seidel) until ``‖H δ + g‖ ≤ linear_tolerance · ‖g‖`` or
    the budget is spent (:mod:`slamkit.optim.mlr`). A step whose solve missed the tolerance
    is not taken as evidence of convergence by the stopping rule."""

    SECTION: ClassVar[str] = "relaxation"

    linear_tolerance: float = setting(1e-2, finite_above(0.0), "a finite number > 0")
    """Relative residual ``‖H δ + g‖ / ‖g‖`` at which the linear solve stops
    (dimensionless)."""
    sweeps: int = setting(2, int_at_least(1), "an integer >= 1")
    """MLR: forward Gauss-Seidel sweeps before, and backward sweeps after, the coarse
    correction on every level of a V-cycle."""
    max_cycles: int = setting(10, int_at_least(1), "an integer >= 1")
    """MLR: at most this many V-cycles per linearisation."""
    max_sweeps: int = setting(200, int_at_least(1), "an integer >= 1")
    """Gauss-Seidel: at most this many sweeps (alternately forward and backward) per
    linearisation."""


@dataclass(frozen=True)
class RobustConfig(Section):
    """The robust kernel ``ρ`` applied to every edge's ``‖U e‖²`` (IRLS weights)."""

    SECTION: ClassVar[str] = "robust"

    kernel: KernelName = "none"
    """``"none"``, ``"huber"``, ``"cauchy"``, ``"geman_mcclure"`` or ``"dcs"`` (all edges)."""
    width: float | None = None
    """Kernel width (δ, c or φ; see :mod:`slamkit.optim.robust`); ``None``: the kernel's
    default, :data:`~slamkit.optim.robust.DEFAULT_WIDTHS`."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _ = self.resolve()  # validates the width

    def resolve(self) -> RobustKernel:
        """The kernel with its width resolved (``width`` or the kernel's default)."""
        width = self.width
        if width is None:
            width = DEFAULT_WIDTHS.get(self.kernel, 1.0)
        return RobustKernel(self.kernel, width)


@dataclass(frozen=True)
class GrowConfig(Section):
    """``initialization="grow"``: batch solves over growing time-ordered prefixes (see
    :func:`~slamkit.optim.grow_initialization`)."""

    SECTION: ClassVar[str] = "grow"

    initial_poses: int = setting(250, int_at_least(1), "an integer >= 1")
    """Poses (rows in ``pose_ids`` order, i.e. time order) in the first prefix."""
    max_step: int = setting(1500, int_at_least(1), "an integer >= 1")
    """Each prefix doubles, adding at most this many poses."""
    relative_tolerance: float = setting(1e-3, finite_above(0.0), "a finite number > 0")
    """The ``stopping.relative_tolerance`` of the prefix solves (the larger of the two is
    used; the last, full solve uses ``stopping``'s); they only need to land in the right
    basin."""


@dataclass(frozen=True)
class OptimizerConfig(Section):
    """Settings of :func:`~slamkit.optim.optimize` (see the module docstring for the units)."""

    solver: MethodName = "lm"
    """``"lm"`` (Levenberg-Marquardt), ``"gn"`` (Gauss-Newton), ``"dogleg"`` (Powell),
    ``"mlr"`` (multilevel relaxation: Gauss-Newton steps solved by V-cycles, no
    factorisation; 2D pose graphs) or ``"gauss_seidel"`` (the same with plain block
    Gauss-Seidel sweeps)."""
    objective: ObjectiveName = "g2o"
    """``"g2o"``: ``Σ eᵀ Ω e`` with g2o's SE(2) error; ``"sesync"``: SE-Sync's ``F`` for the
    relative-pose edges (other edge kinds keep their g2o error)."""
    initialization: InitName = "auto"
    """``"vertices"``, ``"odometry"`` (spanning tree), ``"chordal"``, ``"grow"`` (batch solves
    over growing time-ordered prefixes, settings in ``grow``), or ``"auto"``: on a pose graph
    the lower-cost of the file's vertices (odometry when it has none) and the chordal start;
    on a landmark graph the vertices, else ``"grow"`` (:func:`~slamkit.optim.choose_start`).
    Ignored when initial values are passed."""
    gauge: GaugeMode = "anchor_first"
    """``"anchor_first"``: with no fixed pose and no prior, hold the first pose fixed;
    ``"none"``: raise :class:`~slamkit.errors.GeometryError` in that case."""
    linear_solver: LinearSolverName = "auto"
    """Sparse Cholesky back-end: ``"cholmod"`` (needs cvxopt), ``"superlu"``, ``"dense"``;
    ``"auto"`` is CHOLMOD when available, else SuperLU."""
    stopping: StoppingConfig = field(default_factory=StoppingConfig)
    """The stopping rule of every solver."""
    lm: LmConfig = field(default_factory=LmConfig)
    """Levenberg-Marquardt's damping (``solver="lm"``)."""
    dogleg: DoglegConfig = field(default_factory=DoglegConfig)
    """Dogleg's trust region (``solver="dogleg"``)."""
    relaxation: RelaxationConfig = field(default_factory=RelaxationConfig)
    """The linear solve of ``solver="mlr"`` and ``solver="gauss_seidel"``."""
    robust: RobustConfig = field(default_factory=RobustConfig)
    """The robust kernel (all solvers)."""
    grow: GrowConfig = field(default_factory=GrowConfig)
    """The grown-prefix start (``initialization="grow"``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, kind in (
            ("stopping", StoppingConfig),
            ("lm", LmConfig),
            ("dogleg", DoglegConfig),
            ("relaxation", RelaxationConfig),
            ("robust", RobustConfig),
            ("grow", GrowConfig),
        ):
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(
                    f"{name}: expected a {kind.__name__}, got {getattr(self, name)!r}"
                )

    @property
    def kernel(self) -> RobustKernel:
        """The robust kernel with its width resolved (``robust.width`` or the default)."""
        return self.robust.resolve()
