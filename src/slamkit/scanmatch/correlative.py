"""Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009).

The matcher looks for the pose ``T_ref_cur = (x, y, θ)`` that maximises the log-likelihood
of the current scan's points ``q_p`` against a reference (a scan or a map):

    S(x, y, θ) = sum_p L( R(θ) q_p + (x, y) ),

where ``L`` is the smeared log-likelihood table of :mod:`slamkit.scanmatch.lookup` (a
Gaussian of the range noise around every reference point, floored by a constant miss
likelihood). The search space is a grid around the initial guess ``(x0, y0, θ0)``:

    x = x0 + j·res,  y = y0 + i·res,  |i|, |j| <= n = ceil(window_xy / res),
    θ = θ0 + k·Δθ,   |k| <= m = ceil(window_theta / Δθ).

Translations are whole cells, so after rotating the scan once per ``θ`` and finding each
point's cell, every translation is an integer offset of the cell indices: the score of all
``(i, j)`` is a gather from the table and a sum, with no trigonometry. The default angular
step ``Δθ = res / r_max`` (``r_max`` the farthest point) moves no point by more than one cell
between neighbouring rotations.

**Branch and bound.** A node ``(k, i, j)`` at level ``h`` stands for the ``2^h × 2^h``
translations ``[i, i + 2^h) × [j, j + 2^h)`` at rotation ``k``; its bound
``sum_p M_h[cell_p + (i, j)]`` (the max tables of the lookup grid) is at least the score of
each of them. The best leaf starts as the initial guess's; since every table value is
``<= 0`` a node's partial sum only falls, so its sum stops as soon as it drops below the
best leaf (the node would be dropped anyway). A leaf that is dropped had an ancestor bound
below a score already reached, so the optimum found equals the exhaustive search over the
same fine grid (``config.search = "exhaustive"``; ties go to the smallest ``(k, i, j)`` in
both), whatever order the nodes are taken in. Two orders are implemented:

* *compiled* (numba and the lookup's integer tables, the default): the top-level nodes are
  bounded by groups of ``2 _SPREAD + 1`` rotations first (at the default angular step a
  point moves at most a cell per rotation, so the top table dilated by ``_SPREAD`` cells,
  summed at the group's middle rotation, bounds all of them; :func:`compiled.group_bounds`),
  and the search goes depth first from the groups, best bound first at every split
  (:func:`compiled.depth_first`): every node is scored against the best leaf reached by
  then, so after the first descents most nodes are scored against the optimum itself;
* *NumPy* (the twin without numba, and float tables): all top-level nodes of all rotations
  are scored and taken in rounds, those of the best bounds first (a few, then more, then
  all that are left whose bound still reaches the best leaf so far). Within a round it
  finds a good leaf by greedy descent from the best node, then goes down level by level:
  nodes whose bound is below the best leaf so far are dropped, the others split into four,
  and the best leaf is tightened by another greedy descent (one vectorised gather per
  level instead of a call per node).

**Covariance** (Olson, section IV). Treating ``exp(S)`` as the (unnormalised) likelihood of
each fine pose, the poses ``x_u`` of a window around the optimum get ``p_u ∝ exp(S_u)`` and

    Σ = sum_u p_u (x_u - μ)(x_u - μ)ᵀ + diag(res², res², Δθ²) / 12,    μ = sum_u p_u x_u,

the second term being the variance of a uniform error within one grid step. A response that
is flat along some direction (a featureless corridor) spreads ``p`` over the whole window; the
matcher then raises :class:`~slamkit.errors.MatchError` ``"degenerate"`` (see
``CorrelativeConfig.max_flatness``). The score reported is ``1 - S / (N log f)`` in
``[0, 1]``: 1 when every point sits on the reference, 0 when every point is a miss.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.backend import SEAM
from slamkit.errors import ConfigError, InputError, MatchError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.maps import FREE_THRESHOLD, OCCUPIED_THRESHOLD, OccupancyGrid
from slamkit.maps.likelihood_field import LikelihoodField
from slamkit.scanmatch import compiled
from slamkit.scanmatch.lookup import (
    QUANTUM,
    LookupGrid,
    log_likelihood_of_distance,
    lookup_from_log_table,
    lookup_from_points,
)
from slamkit.scanmatch.node_scores import Cells, level_values, node_scores, quanta_below
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = ["CorrelativeConfig", "CorrelativeReference", "correlative_match", "correlative_rival"]

IntArray = NDArray[np.int64]

# The NumPy branch and bound searches the top nodes in rounds of at most these many (best
# bounds first), then all that are left: on loop-closure searches of Intel, 1.3x faster
# than one round, within 15 % of a search that knew the optimum's score from the start.
_ROUNDS = (8, 128, 2048)

# The compiled branch and bound bounds the top-level nodes by groups of 2 * _SPREAD + 1
# rotations first (compiled.group_bounds).
_SPREAD = 4

# Fields that shape the lookup grid: a prepared reference fixes them.
_GRID_FIELDS = ("resolution", "sigma", "floor_likelihood", "join_gap", "levels")


@dataclass(frozen=True)
class CorrelativeConfig:
    """Settings of :func:`correlative_match` (metres and radians)."""

    window_xy: float = 0.5
    """Half-width of the translation window around the initial guess [m], in x and in y."""
    window_theta: float = math.radians(20.0)
    """Half-width of the rotation window around the initial guess [rad]."""
    angular_step: float | None = None
    """Rotation step [rad]; ``None``: ``resolution / r_max`` with ``r_max`` the distance of
    the current scan's farthest point (no point moves more than a cell per step)."""
    resolution: float = 0.05
    """Cell side of the lookup grid of a reference built from points [m]. References built
    from an occupancy grid or a likelihood field use the grid's own resolution."""
    sigma: float = 0.05
    """Standard deviation of the Gaussian smear [m]: range noise plus the reference's own
    discretisation (not used with a likelihood field, which has its ``sigma_hit``)."""
    floor_likelihood: float = 0.1
    """Likelihood of a point far from the reference, relative to a perfect hit, in (0, 1)."""
    join_gap: float | None = 0.3
    """Reference points (in scan order) closer than this to the next one are joined by a
    segment before smearing [m] (walls become polylines, see
    :func:`~slamkit.scanmatch.lookup.join_consecutive`); ``None`` keeps bare points."""
    levels: int = 4
    """Resolution levels: the coarsest node covers ``2^(levels-1)`` fine cells per axis;
    1 means an exhaustive search."""
    search: Literal["branch_and_bound", "exhaustive"] = "branch_and_bound"
    """``exhaustive`` scores every fine pose (the reference for branch and bound)."""
    cov_window_xy: float = 0.15
    """Half-width of the fine window around the optimum over which the covariance is
    computed [m]."""
    cov_window_theta: float = math.radians(3.0)
    """Half-width of that window in rotation [rad]."""
    max_flatness: float | None = 0.5
    """Raise ``MatchError("degenerate")`` when, along some direction of (x, y) or in θ, the
    response's standard deviation over the covariance window exceeds this fraction of that
    of a perfectly flat response over the same window (about ``window / sqrt(3)``).
    ``None`` never raises (the covariance then shows the elongation)."""
    min_points: int = 10
    """Fewest valid current points accepted (else ``MatchError("too_few_points")``)."""
    min_score: float = 0.0
    """Raise ``MatchError("low_score")`` below this normalised score, in [0, 1]."""

    def __post_init__(self) -> None:
        for name in ("window_xy", "window_theta", "cov_window_xy", "cov_window_theta"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a number >= 0, got {v!r}")
        if self.join_gap is not None and not (math.isfinite(self.join_gap) and self.join_gap > 0):
            raise ConfigError(f"join_gap: expected None or > 0, got {self.join_gap!r}")
        for name in ("resolution", "sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a number > 0, got {v!r}")
        if self.angular_step is not None and not (
            math.isfinite(self.angular_step) and self.angular_step > 0
        ):
            raise ConfigError(f"angular_step: expected None or > 0, got {self.angular_step!r}")
        if not (0.0 < self.floor_likelihood < 1.0):
            raise ConfigError(
                f"floor_likelihood: expected a number in (0, 1), got {self.floor_likelihood!r}"
            )
        if int(self.levels) != self.levels or not (1 <= self.levels <= 12):
            raise ConfigError(f"levels: expected an integer in [1, 12], got {self.levels!r}")
        if self.search not in ("branch_and_bound", "exhaustive"):
            raise ConfigError(
                f"search: expected 'branch_and_bound' or 'exhaustive', got {self.search!r}"
            )
        if self.max_flatness is not None and not (
            math.isfinite(self.max_flatness) and self.max_flatness > 0
        ):
            raise ConfigError(f"max_flatness: expected None or > 0, got {self.max_flatness!r}")
        if int(self.min_points) != self.min_points or self.min_points < 1:
            raise ConfigError(f"min_points: expected an integer >= 1, got {self.min_points!r}")
        if not (0.0 <= self.min_score <= 1.0):
            raise ConfigError(f"min_score: expected a number in [0, 1], got {self.min_score!r}")


def _pad_cells(config: CorrelativeConfig) -> int:
    """Padding of the lookup tables: the coarsest block and one cell (reads outside the
    tables are misses, see :meth:`LookupGrid.cells`), whatever the window searched."""
    return (1 << (config.levels - 1)) + 1


def _cells(length: float, step: float) -> int:
    """``ceil(length / step)``, robust to ``length`` being a whole multiple of ``step``."""
    return math.ceil(length / step - 1e-9)


@dataclass(frozen=True, eq=False)
class CorrelativeReference:
    """A reference prepared for correlative matching: the lookup grid and the config it was
    built for. Build it once and match many scans against it (scan-to-map localisation,
    loop-closure candidates, the scans of one particle's map).

    A match may use a different config as long as it keeps the grid fields
    (``resolution``, ``sigma``, ``floor_likelihood``, ``levels``); its window may be any
    size (the tables do not depend on it).
    """

    lookup: LookupGrid
    config: CorrelativeConfig

    @classmethod
    def from_points(
        cls, points: ArrayLike, config: CorrelativeConfig | None = None
    ) -> CorrelativeReference:
        """From a reference scan's points ``(M, 2)`` in the reference frame, in scan order
        (consecutive points may be joined, see ``config.join_gap``)."""
        cfg = _as_config(config)
        pts = as_array(points, "reference points", (None, 2))
        lookup = lookup_from_points(
            pts,
            cfg.resolution,
            cfg.sigma,
            cfg.floor_likelihood,
            levels=cfg.levels,
            pad=_pad_cells(cfg),
            join_gap=cfg.join_gap,
        )
        return cls(lookup, cfg)

    @classmethod
    def from_grid(
        cls,
        grid: OccupancyGrid,
        config: CorrelativeConfig | None = None,
        *,
        occupied_threshold: float = OCCUPIED_THRESHOLD,
        free_threshold: float = FREE_THRESHOLD,
    ) -> CorrelativeReference:
        """From an occupancy grid, at the grid's resolution: the distances are those of
        :meth:`LikelihoodField.from_grid` (unknown cells count as far from everything), the
        table is ``L(d)`` with ``config.sigma`` and ``config.floor_likelihood``."""
        cfg = _as_config(config)
        dist = LikelihoodField.from_grid(
            grid,
            cfg.sigma,
            occupied_threshold=occupied_threshold,
            free_threshold=free_threshold,
        ).distances
        table = log_likelihood_of_distance(dist, cfg.sigma, cfg.floor_likelihood)
        inlier = float(
            log_likelihood_of_distance(np.array(3.0 * cfg.sigma), cfg.sigma, cfg.floor_likelihood)
        )
        lookup = lookup_from_log_table(
            table,
            grid.origin_xy,
            grid.resolution,
            floor=float(np.log(cfg.floor_likelihood)),
            inlier_log=inlier,
            levels=cfg.levels,
            pad=_pad_cells(cfg),
        )
        return cls(lookup, cfg)

    @classmethod
    def from_likelihood_field(
        cls, field: LikelihoodField, config: CorrelativeConfig | None = None
    ) -> CorrelativeReference:
        """From MCL's likelihood field, with its own beam model: ``L = log p(d) - log p(0)``
        of :meth:`LikelihoodField.log_p` (``config.sigma`` and ``floor_likelihood`` are
        not used). Points outside the grid read the field's "outside" value."""
        if not isinstance(field, LikelihoodField):
            raise InputError(f"field: expected a LikelihoodField, got {type(field).__name__}")
        cfg = _as_config(config)
        top = float(field.log_p(0.0))
        table = field.log_p(field.distances) - top
        floor = float(field.log_p(field.outside_distance)) - top
        inlier = float(field.log_p(3.0 * field.sigma_hit)) - top
        lookup = lookup_from_log_table(
            table,
            field.grid.origin_xy,
            field.grid.resolution,
            floor=floor,
            inlier_log=max(inlier, floor),
            levels=cfg.levels,
            pad=_pad_cells(cfg),
        )
        return cls(lookup, cfg)


def _as_config(config: CorrelativeConfig | None) -> CorrelativeConfig:
    if config is None:
        return CorrelativeConfig()
    if not isinstance(config, CorrelativeConfig):
        raise InputError(f"config: expected a CorrelativeConfig, got {type(config).__name__}")
    return config


def _prepare(
    reference: CorrelativeReference | OccupancyGrid | LikelihoodField | ArrayLike,
    config: CorrelativeConfig | None,
) -> tuple[CorrelativeReference, CorrelativeConfig]:
    if isinstance(reference, CorrelativeReference):
        cfg = reference.config if config is None else _as_config(config)
        for name in _GRID_FIELDS:
            if getattr(cfg, name) != getattr(reference.config, name):
                raise InputError(
                    f"config.{name}: the reference was built with {name}="
                    f"{getattr(reference.config, name)!r}, the match asks for "
                    f"{getattr(cfg, name)!r}; rebuild the reference"
                )
        return reference, cfg
    cfg = _as_config(config)
    if isinstance(reference, OccupancyGrid):
        return CorrelativeReference.from_grid(reference, cfg), cfg
    if isinstance(reference, LikelihoodField):
        return CorrelativeReference.from_likelihood_field(reference, cfg), cfg
    return CorrelativeReference.from_points(reference, cfg), cfg


def _rotated_cells(
    lookup: LookupGrid, points: FloatArray, xy: FloatArray, thetas: FloatArray
) -> Cells:
    """Cell rows and columns ``(K, N)`` of the points rotated by each ``θ_k`` and moved by
    ``xy``: one rotation of the scan per angle."""
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    world = np.empty((thetas.size, points.shape[0], 2))
    world[..., 0] = c * points[:, 0] - s * points[:, 1] + xy[0]
    world[..., 1] = s * points[:, 0] + c * points[:, 1] + xy[1]
    return lookup.cells(world)


def _score(
    lookup: LookupGrid,
    level: int,
    cells: Cells,
    k: IntArray,
    i: IntArray,
    j: IntArray,
    threshold: float = -np.inf,
) -> FloatArray:
    """``sum_p T[row_p + i_u, col_p + j_u]`` at rotation ``k_u`` for every node ``u``, with
    ``T = lookup.tables[level]`` and reads outside it ``lookup.floor``; ``-inf`` for a node
    whose sum is below ``threshold`` (which needs every table value ``<= 0``: the compiled
    sum stops early): :func:`~slamkit.scanmatch.node_scores.node_scores`."""
    table = lookup.tables[level]
    assert table[0, 0] == lookup.floor  # the padding's corner: compiled reads outside
    return node_scores(lookup, level, cells, k, i, j, threshold)


def _first_best(scores: FloatArray, k: IntArray, i: IntArray, j: IntArray) -> int:
    """Index of the highest score; ties go to the smallest ``(k, i, j)``."""
    top = np.flatnonzero(scores == scores.max())
    order = np.lexsort((j[top], i[top], k[top]))
    return int(top[order[0]])


@dataclass(frozen=True)
class _Optimum:
    k: int
    i: int
    j: int
    score: float
    levels: int


Box = tuple[int, int, int, int]
"""Translations ``[i0, i1] × [j0, j1]`` (cell offsets, inclusive) left out of a search."""

_NO_BOX: Box = (1, 0, 1, 0)


def _outside(i: IntArray, j: IntArray, side: int, box: Box) -> NDArray[np.bool_]:
    """Whether each node of side ``side`` at ``(i, j)`` has a translation outside ``box``."""
    i0, i1, j0, j1 = box
    out: NDArray[np.bool_] = ~((i >= i0) & (i + side - 1 <= i1) & (j >= j0) & (j + side - 1 <= j1))
    return out


def _exhaustive(lookup: LookupGrid, cells: Cells, n: int, box: Box = _NO_BOX) -> _Optimum:
    ks, ii, jj = np.meshgrid(
        np.arange(cells[0].shape[0]), np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij"
    )
    k, i, j = ks.ravel(), ii.ravel(), jj.ravel()
    s = np.where(_outside(i, j, 1, box), _score(lookup, 0, cells, k, i, j), -np.inf)
    u = _first_best(s, k, i, j)
    return _Optimum(int(k[u]), int(i[u]), int(j[u]), float(s[u]), 1)


def _children(
    k: IntArray, i: IntArray, j: IntArray, half: int, n: int
) -> tuple[IntArray, IntArray, IntArray]:
    """The four sub-blocks (offset ``half``) of each node that start inside the window."""
    di = np.array([0, 0, half, half])
    dj = np.array([0, half, 0, half])
    ck = np.repeat(k, 4)
    ci = (i[:, None] + di).ravel()
    cj = (j[:, None] + dj).ravel()
    ok = (ci <= n) & (cj <= n)
    return ck[ok], ci[ok], cj[ok]


def _descend(
    lookup: LookupGrid, cells: Cells, node: tuple[int, int, int], level: int, n: int, box: Box
) -> float:
    """Score of the leaf reached by always taking the child with the best bound (``-inf``
    when every way down ends in ``box``)."""
    ka, ia, ja = np.array([node[0]]), np.array([node[1]]), np.array([node[2]])
    score = -np.inf
    while level > 0:
        ka, ia, ja = _children(ka, ia, ja, 1 << (level - 1), n)
        level -= 1
        s = _score(lookup, level, cells, ka, ia, ja)
        s[~_outside(ia, ja, 1 << level, box)] = -np.inf
        u = int(np.argmax(s))
        if s[u] == -np.inf:
            return -np.inf
        ka, ia, ja, score = ka[u : u + 1], ia[u : u + 1], ja[u : u + 1], float(s[u])
    return score


def _branch_and_bound(
    lookup: LookupGrid, cells: Cells, n: int, start: _Optimum | None = None, box: Box = _NO_BOX
) -> _Optimum:
    """The best leaf of the window outside ``box`` that beats ``start`` (None: the initial
    guess's leaf), ``start`` itself when none does."""
    level = lookup.levels - 1
    starts = np.arange(-n, n + 1, 1 << level)
    n_k = cells[0].shape[0]
    # The best leaf so far starts as the initial guess's (the middle rotation, no shift). A
    # node whose bound falls below it is scored -inf, its sum cut short: with every table
    # value <= 0 a partial sum only falls. Those nodes are dropped below anyway, and a node
    # that may hold the best leaf is always scored in full, so the search reaches the same
    # optimum as without the cut (and as the exhaustive search).
    cut = float(lookup.tables[-1].max()) <= 0.0  # the top table's max is every table's
    zero = np.zeros(1, dtype=np.int64)
    mid = n_k // 2
    best = start or _Optimum(
        mid, 0, 0, float(_score(lookup, 0, cells, zero + mid, zero, zero)[0]), 0
    )
    return _top_search(lookup, cells, n, starts, best, cut, box)


def _search_compiled(
    lookup: LookupGrid, cells: Cells, n: int, starts: IntArray, best: _Optimum, cut: bool,
    box: Box,
) -> _Optimum:  # fmt: skip
    """The search below the top level: :func:`_depth_first` on integer tables when the sums
    may be cut short, else :func:`_search_rounds`."""
    if cut and lookup.counts is not None:
        return _depth_first(lookup, cells, n, starts, best, box)
    return _search_rounds(lookup, cells, n, starts, best, cut, box)


def _search_rounds(
    lookup: LookupGrid, cells: Cells, n: int, starts: IntArray, best: _Optimum, cut: bool,
    box: Box,
) -> _Optimum:  # fmt: skip
    """The search below the top level in NumPy: the top nodes in rounds, best bounds first,
    each round's blocks searched down to the leaves (the path without numba and the oracle
    of :func:`_search_compiled`: the same optimum)."""
    level = lookup.levels - 1
    n_k = cells[0].shape[0]
    ks, ii, jj = np.meshgrid(np.arange(n_k), starts, starts, indexing="ij")
    k, i, j = ks.ravel(), ii.ravel(), jj.ravel()
    bound = _score(lookup, level, cells, k, i, j, best.score if cut else -np.inf)
    bound[~_outside(i, j, 1 << level, box)] = -np.inf
    left = bound.copy()
    # The top nodes in rounds, best bounds first: the first round's leaves give the later
    # rounds a threshold near the optimum. A node left when its bound is below the best leaf
    # holds no leaf as good.
    for size in (*_ROUNDS, None):
        open_ = np.flatnonzero(left >= best.score)
        if open_.size == 0:
            break
        if size is not None and open_.size > size:
            open_ = open_[np.argpartition(-left[open_], size - 1)[:size]]
        left[open_] = -np.inf
        nodes = (k[open_], i[open_], j[open_])
        found = _search_blocks(lookup, cells, nodes, bound[open_], level, n, best, cut, box)
        if found is not None and _better(found, best):
            best = found
    return _Optimum(best.k, best.i, best.j, best.score, lookup.levels)


_top_search = SEAM.pair(compiled=_search_compiled, oracle=_search_rounds)
"""The search from the top level, depth first compiled under numba, else in rounds
(:mod:`slamkit.backend`)."""


def _depth_first(
    lookup: LookupGrid, cells: Cells, n: int, starts: IntArray, start: _Optimum, box: Box
) -> _Optimum:
    """The compiled search (integer tables): the top-level nodes bounded by groups of ``2
    _SPREAD + 1`` rotations (:func:`compiled.group_bounds`, where :func:`_near_groups`
    allows), then :func:`compiled.depth_first` from those groups, best bounds first, with
    ``start`` as the first best leaf."""
    rows, cols = cells
    assert lookup.counts is not None
    level = lookup.levels - 1
    near = _near_groups(cells)
    threshold = quanta_below(start.score)  # the score's own count: a multiple of QUANTUM
    bounds = np.empty(near.size * starts.size**2, dtype=np.int64)
    compiled.group_bounds(
        lookup.dilated_counts(level, _SPREAD), _SPREAD, near, rows, cols, starts, starts,
        threshold, bounds,
    )  # fmt: skip
    best = np.array([threshold, start.k, start.i, start.j], dtype=np.int64)
    compiled.depth_first(
        lookup.counts, rows, cols, n, _SPREAD, bounds, starts, best, np.array(box, np.int64)
    )
    k, i, j = (int(v) for v in best[1:])
    return _Optimum(k, i, j, float(best[0]) * QUANTUM, lookup.levels)


def _near_groups(cells: Cells) -> NDArray[np.bool_]:
    """Whether each group of ``2 _SPREAD + 1`` rotations (the last may be smaller) keeps
    every point's cell within ``_SPREAD`` cells per axis of its cell at the group's middle
    rotation ``(groups,)``: where it does, the dilated table bounds the whole group
    (:func:`compiled.group_bounds`)."""
    rows, cols = cells
    n_k, size = rows.shape[0], 2 * _SPREAD + 1
    k0 = np.arange(n_k) // size * size
    mid = (k0 + np.minimum(k0 + size, n_k) - 1) // 2
    moved = np.maximum(np.abs(rows - rows[mid]).max(axis=1), np.abs(cols - cols[mid]).max(axis=1))
    out: NDArray[np.bool_] = np.maximum.reduceat(moved, np.arange(0, n_k, size)) <= _SPREAD
    return out


def _better(a: _Optimum, b: _Optimum) -> bool:
    """Whether leaf ``a`` beats leaf ``b``: a higher score, or the same and a smaller
    ``(k, i, j)`` (the exhaustive search's tie rule)."""
    return a.score > b.score or (a.score == b.score and (a.k, a.i, a.j) < (b.k, b.i, b.j))


def _search_blocks(
    lookup: LookupGrid,
    cells: Cells,
    nodes: tuple[IntArray, IntArray, IntArray],
    bound: FloatArray,
    level: int,
    n: int,
    incumbent: _Optimum,
    cut: bool,
    box: Box,
) -> _Optimum | None:
    """Branch and bound below ``nodes`` (at ``level``, with their ``bound``): the first best
    leaf (ties to the smallest ``(k, i, j)``) of those scoring at least ``incumbent``'s
    score, None when there is none."""
    k, i, j = nodes
    best = incumbent.score
    while level > 0:
        if k.size == 0:
            return None
        u = int(np.argmax(bound))
        node = (int(k[u]), int(i[u]), int(j[u]))
        best = max(best, _descend(lookup, cells, node, level, n, box))
        # A node whose bound is below a leaf already reached cannot hold the optimum.
        keep = bound >= best
        k, i, j = _children(k[keep], i[keep], j[keep], 1 << (level - 1), n)
        level -= 1
        bound = _score(lookup, level, cells, k, i, j, best if cut else -np.inf)
        bound[~_outside(i, j, 1 << level, box)] = -np.inf
    if k.size == 0 or not bound.max() >= incumbent.score:
        return None
    u = _first_best(bound, k, i, j)
    return _Optimum(int(k[u]), int(i[u]), int(j[u]), float(bound[u]), 0)


def _response_covariance(
    lookup: LookupGrid,
    points: FloatArray,
    pose: FloatArray,
    dtheta: float,
    config: CorrelativeConfig,
) -> tuple[FloatArray, float, float]:
    """Olson's covariance over the fine window around ``pose``, and the flatness ratios
    (response std over flat-response std) in (x, y) and in θ."""
    res = lookup.resolution
    c = _cells(config.cov_window_xy, res)
    ct = _cells(config.cov_window_theta, dtheta)
    dk = np.arange(-ct, ct + 1)
    cells = _rotated_cells(lookup, points, pose[:2], pose[2] + dk * dtheta)
    ks, ii, jj = np.meshgrid(
        np.arange(dk.size), np.arange(-c, c + 1), np.arange(-c, c + 1), indexing="ij"
    )
    k, i, j = ks.ravel(), ii.ravel(), jj.ravel()
    s = _score(lookup, 0, cells, k, i, j)
    p = np.exp(s - s.max())  # p_u ∝ exp(S_u); the shift only rescales
    p /= p.sum()
    x = np.column_stack([j * res, i * res, dk[k] * dtheta])
    mu = p @ x
    d = x - mu
    resp = (d * p[:, None]).T @ d
    cov = resp + np.diag([res**2, res**2, dtheta**2]) / 12.0
    cov = 0.5 * (cov + cov.T)
    # A flat response over 2c+1 equally spaced values has variance step² ((2c+1)² - 1) / 12.
    flat_xy = res * math.sqrt(((2 * c + 1) ** 2 - 1) / 12.0)
    flat_t = dtheta * math.sqrt(((2 * ct + 1) ** 2 - 1) / 12.0)
    lam = float(np.linalg.eigvalsh(resp[:2, :2])[-1])
    ratio_xy = math.sqrt(max(lam, 0.0)) / flat_xy if c > 0 else 0.0
    ratio_t = math.sqrt(max(float(resp[2, 2]), 0.0)) / flat_t if ct > 0 else 0.0
    return cov, ratio_xy, ratio_t


@dataclass(frozen=True)
class _Window:
    """One search: the prepared reference's lookup, the config, the current points, the
    initial guess, the half-window ``n`` in cells, the rotations and every point's cell at
    each rotation."""

    lookup: LookupGrid
    config: CorrelativeConfig
    points: FloatArray
    guess: FloatArray
    n: int
    thetas: FloatArray
    dtheta: float
    cells: Cells

    @classmethod
    def of(
        cls,
        reference: CorrelativeReference | OccupancyGrid | LikelihoodField | ArrayLike,
        current_points: ArrayLike,
        initial: ArrayLike,
        config: CorrelativeConfig | None,
    ) -> _Window:
        ref, cfg = _prepare(reference, config)
        lookup = ref.lookup
        pts = require_points(
            as_array(current_points, "current points", (None, 2)), cfg.min_points, "current"
        )
        guess = as_array(initial, "initial pose", (3,))
        res = lookup.resolution
        if cfg.angular_step is not None:
            dtheta = cfg.angular_step
        else:
            r_max = max(float(np.sqrt((pts**2).sum(axis=1)).max()), res)
            dtheta = res / r_max
        m = _cells(cfg.window_theta, dtheta)
        thetas = guess[2] + np.arange(-m, m + 1) * dtheta
        cells = _rotated_cells(lookup, pts, guess[:2], thetas)
        return cls(lookup, cfg, pts, guess, _cells(cfg.window_xy, res), thetas, dtheta, cells)

    def normalised(self, total: float) -> float:
        """The score ``1 - S / (N log f)`` in ``[0, 1]`` of a sum ``S``."""
        floor, n_pts = self.lookup.floor, self.points.shape[0]
        score = 1.0 - total / (n_pts * floor) if floor < 0 else 1.0
        return min(max(score, 0.0), 1.0)


def correlative_rival(
    reference: CorrelativeReference | OccupancyGrid | LikelihoodField | ArrayLike,
    current_points: ArrayLike,
    initial: ArrayLike,
    match: MatchResult,
    separation: float,
    ratio: float,
    config: CorrelativeConfig | None = None,
) -> float | None:
    """The best score, over the window of :func:`correlative_match` (same arguments), of a
    pose whose translation lies more than ``separation`` [m] from ``match``'s along x or y
    (any rotation), when it reaches ``ratio · match.score`` and is a peak of its own; None
    when no pose does. A best pose outside that lies on the left-out square's edge is the
    optimum's own peak, broad along some direction; the square is then doubled and the
    search repeated, while it fits in the window.

    A match is unique in its window when it has no rival: in a corridor of identical doors
    or a row of look-alike rooms the true place and its aliases score alike, and whichever
    wins depends on noise. The search is the same branch and bound with the translations
    near ``match`` left out and the bar set at ``ratio · match.score`` from the start, so
    most nodes are cut at the top level when there is no rival."""
    w = _Window.of(reference, current_points, initial, config)
    res = w.lookup.resolution
    if not w.lookup.floor < 0:
        return None  # a table without misses scores every pose alike
    bi = round((float(match.pose[1]) - w.guess[1]) / res)
    bj = round((float(match.pose[0]) - w.guess[0]) / res)
    # The sum S of a pose scoring exactly the bar: 1 - S / (N log f) = ratio · score.
    bar = (1.0 - ratio * match.score) * w.points.shape[0] * w.lookup.floor
    n_k = w.thetas.size
    start = _Optimum(n_k, w.n + 1, w.n + 1, bar, 0)  # past every leaf: a tie goes to a leaf
    c = _cells(separation, res)
    while c <= w.n:
        box: Box = (bi - c, bi + c, bj - c, bj + c)
        if w.config.search == "exhaustive" or w.lookup.levels == 1:
            opt = _exhaustive(w.lookup, w.cells, w.n, box)
            if opt.score < bar:
                return None
        else:
            opt = _branch_and_bound(w.lookup, w.cells, w.n, start, box)
            if opt.k == n_k:
                return None
        if max(abs(opt.i - bi), abs(opt.j - bj)) > c + 1:
            return w.normalised(opt.score)
        # On the box's edge: the optimum's own peak, broad along some direction (a
        # corridor), not a peak of its own. Look farther out.
        c *= 2
    return None


def correlative_match(
    reference: CorrelativeReference | OccupancyGrid | LikelihoodField | ArrayLike,
    current_points: ArrayLike,
    initial: ArrayLike,
    config: CorrelativeConfig | None = None,
) -> MatchResult:
    """Register ``current_points (N, 2)`` (current sensor frame) to ``reference`` by
    correlative search around ``initial = T_ref_cur (3,)`` (see the module docstring).

    ``reference`` is a :class:`CorrelativeReference` (prepared once, matched many times),
    or reference points ``(M, 2)``, an :class:`OccupancyGrid` or a :class:`LikelihoodField`
    (each built into one with ``config`` for this call). ``config`` defaults to the
    prepared reference's config, else :class:`CorrelativeConfig()`.

    Returns the best fine-grid pose, Olson's covariance, the normalised score, the fraction
    of points within the inlier distance (``3 sigma``) and ``iterations`` = levels searched.
    Raises :class:`MatchError` with reason ``"too_few_points"`` (fewer than
    ``config.min_points`` current points), ``"degenerate"`` (a flat response, see
    ``max_flatness``) or ``"low_score"`` (below ``min_score``).
    """
    win = _Window.of(reference, current_points, initial, config)
    lookup, cfg, pts, guess, cells = win.lookup, win.config, win.points, win.guess, win.cells
    res, thetas, dtheta = lookup.resolution, win.thetas, win.dtheta
    if cfg.search == "exhaustive" or lookup.levels == 1:
        opt = _exhaustive(lookup, cells, win.n)
    else:
        opt = _branch_and_bound(lookup, cells, win.n)

    pose = np.array(
        [
            guess[0] + opt.j * res,
            guess[1] + opt.i * res,
            wrap_angle_float(float(thetas[opt.k])),
        ]
    )
    values = level_values(
        lookup.tables[0], lookup.floor, cells[0][opt.k] + opt.i, cells[1][opt.k] + opt.j
    )
    n_pts = pts.shape[0]
    score = win.normalised(opt.score)
    inliers = float(np.count_nonzero(values >= lookup.inlier_log)) / n_pts
    if score < cfg.min_score:
        raise MatchError(
            f"correlative match score {score:.3f} is below min_score {cfg.min_score}",
            "low_score",
        )
    cov, ratio_xy, ratio_t = _response_covariance(lookup, pts, pose, dtheta, cfg)
    if cfg.max_flatness is not None and max(ratio_xy, ratio_t) > cfg.max_flatness:
        w, v = np.linalg.eigh(cov[:2, :2])
        which = (
            f"translation along ({v[0, -1]:+.2f}, {v[1, -1]:+.2f}), std {math.sqrt(w[-1]):.3f} m"
            if ratio_xy >= ratio_t
            else f"rotation, std {math.sqrt(cov[2, 2]):.4f} rad"
        )
        raise MatchError(
            f"correlative response is flat in {which}: {max(ratio_xy, ratio_t):.2f} of a flat "
            f"response's spread, above max_flatness {cfg.max_flatness}",
            "degenerate",
        )
    return MatchResult(
        pose=pose,
        cov=cov,
        score=score,
        inlier_fraction=inliers,
        iterations=opt.levels,
        method="correlative",
    )
