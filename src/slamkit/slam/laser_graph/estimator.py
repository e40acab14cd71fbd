"""Graph-based 2D laser SLAM on the estimator shell (registered as ``graph-slam``).

Front end (:mod:`~slamkit.slam.laser_graph.frontend`): scans tracked against the local map
of the last keyframes by point-to-normal ICP with the wheels' offset as a prior (or against
the current keyframe by point-to-line ICP); keyframes every ``keyframe_distance`` /
``keyframe_angle_deg``; an edge to the previous keyframe. Loops
(:mod:`~slamkit.slam.laser_graph.loops`): candidates in a search region grown with the path
travelled, correlative matching against the candidate's submap, verification, refinement
and pairwise consistency. Back end (:mod:`~slamkit.slam.laser_graph.backend`): the pose
graph, optimised (Levenberg-Marquardt, plain least squares, warm start) after each keyframe
that brings closures and once more at the end; closures that raise the graph's χ² too much
or tear its edges are removed, and refused ones judged again once they outnumber the
closures that refused them.

Every time stamp is held as *(keyframe, offset from it)*, so the path at the end is each
keyframe's optimised pose composed with the offset (:attr:`EstimatorOutput.trajectory`,
which the runner reports); the map is the occupancy grid of the keyframes' scans at their
optimised poses, the graph is :attr:`EstimatorOutput.graph`.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, LaserScan
from slamkit.errors import InputError, MatchError
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate, SmoothedTrajectory
from slamkit.estimation.health import (
    UnmatchedStretch,
    override_rows,
    still_odometry_warning,
    usable_motion,
)
from slamkit.estimation.shell import EstimatorShell
from slamkit.geometry.pose2 import between, compose, transform_points
from slamkit.mapping.inverse_model import InverseSensorModel
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.mapper import OccupancyMapper
from slamkit.models.laser import scan_points
from slamkit.scanmatch.icp import prepare_scan
from slamkit.scanmatch.normal_icp import NormalCloud
from slamkit.scanmatch.point_map import ScanNormals, scan_normals
from slamkit.scanmatch.transient import ScanView
from slamkit.slam.laser_graph.backend import (
    MAX_CHI2,
    MAX_EDGE_CHI2,
    PoseGraph,
    RefusedClosure,
    default_optimizer,
    optimize_consistent,
    rejudge,
    restore_consistent,
    retract_inconsistent,
)
from slamkit.slam.laser_graph.config import LaserGraphConfig
from slamkit.slam.laser_graph.freespace import (
    MAX_CONTRADICTION,
    NEIGHBOURHOOD_KEYFRAMES,
    FreeSpace,
    contradiction,
    neighbourhood,
    neighbourhood_scans,
    revisit_contradictions,
)
from slamkit.slam.laser_graph.frontend import (
    LOCAL_MAP_KEYFRAMES,
    NORMAL_ICP,
    Keyframe,
    Tracker,
    floored_information,
    local_map,
)
from slamkit.slam.laser_graph.health import laser_unusable, run_warnings
from slamkit.slam.laser_graph.loops import (
    PAIR_KEYFRAMES,
    SUBMAP_KEYFRAMES,
    LoopMatch,
    SubmapCache,
    consistent_partners,
    loop_candidates,
    search_window,
    verify_closure,
)
from slamkit.slam.laser_graph.places import WINDOW_DEG, WINDOW_XY, PlaceIndex, signature

__all__ = ["NO_ODOMETRY", "LaserGraphSlam"]

NO_ODOMETRY = "none: scan matching alone (constant-velocity prediction)"
"""What the diagnostics say of a run on a log without odometry."""

# Constants that were settings until 2026-12-07 (docs/estimators/laser_graph.md, "Settings").
# A closure's (floored) match covariance is multiplied by this: its reference is a submap of
# several keyframes whose relative poses carry errors of their own.
CLOSURE_COV_SCALE = 4.0
# The graph is optimised after the keyframe that brings new closures, at most every this many
# keyframes (closures wait in between).
OPTIMIZE_EVERY = 1
# Place recognition (slam.laser_graph.places) runs at every this many keyframes and offers the
# verification this many candidates beyond the local search's.
GLOBAL_EVERY = 5
GLOBAL_CANDIDATES = 2
# The occupancy map of the optimised keyframes leaves out readings beyond this [m] (long rays
# through doors and windows fill a grid with free space that a short-range view does not
# contradict).
MAP_MAX_RANGE = 30.0
# A keyframe whose points the recent keyframes saw through by more than this fraction keeps
# them all (_clear_transient): people walk through a few of a scan's beams, not most.
MAX_TRANSIENT = 0.25
# ... judged by the keyframes at most this far back along the path [m]: farther ones see the
# place from other sides, through the errors of a longer stretch of the chain.
TRANSIENT_TRAVEL = 3.0


class LaserGraphSlam(EstimatorShell):
    """Graph-based laser SLAM (see the module docstring). Needs a laser; without odometry
    (no motion model) the scans are tracked by scan matching alone from a constant-velocity
    prediction, and the diagnostics say so (``"odometry"``)."""

    name = "graph SLAM"

    def __init__(self, dataset: Dataset, config: LaserGraphConfig, rng: np.random.Generator):
        if dataset.laser is None:
            raise InputError(f"graph SLAM needs laser scans; {dataset.name!r} has none")
        super().__init__()
        self._cfg = config
        self._laser = dataset.laser
        self._max_range = dataset.laser.max_range if config.max_range is None else config.max_range
        mounting = config.mounting if config.mounting is not None else dataset.laser.mounting
        self._mounting = np.asarray(mounting, dtype=np.float64)
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._start: FloatArray = np.array(start, dtype=np.float64)
        # Odometry that never moves says nothing: the laser alone then, and the run says so.
        motion, self._no_motion = usable_motion(dataset)
        self._tracker = Tracker(
            None if motion is None else motion.model,
            None if motion is None else motion.noise_cov,
            config.frontend,
        )
        reference = config.frontend.reference
        if reference == "auto":
            reference = "keyframe" if motion is None else "map"
        self._reference = reference  # what the front end tracks against (resolved)
        self._local: NormalCloud | None = None  # the local map in the keyframe's frame
        self._graph = PoseGraph(default_optimizer())
        self._keys: list[Keyframe] = []
        self._ranges: list[FloatArray] = []
        self._normals: dict[int, ScanNormals] = {}  # each keyframe's, once in a submap
        self._views: dict[int, ScanView] = {}  # the recent keyframes' free space
        self._submaps = SubmapCache(config.loops, self._scan_normals)
        self._places = PlaceIndex()
        self._counts: Counter[str] = Counter()
        self._pending = 0  # closures added since the last optimisation
        self._waiting: list[tuple[int, int, LoopMatch]] = []  # verified, no partner yet
        self._confirmed: list[tuple[int, int, LoopMatch]] = []  # recent ones in the graph
        self._doubted = np.zeros(0, dtype=bool)  # per keyframe: its chain edge doubted
        self._refused: list[RefusedClosure] = []  # by the Δχ² check, recently
        self._dropped: dict[tuple[int, int], RefusedClosure] = {}  # by it, ever
        self._last_solve = 0  # the keyframe count at the last optimisation
        # (stamp, keyframe index or -1 for the start pose, offset) of every time stamp.
        self._stamps: list[float] = [float(dataset.start_time)]
        self._last_scan: float | None = None  # stamp of the last scan (for coasting)
        self._anchors: list[int] = [-1]
        self._offsets: list[FloatArray] = [np.zeros(3)]
        self._overrides: list[tuple[float, FloatArray]] = []  # (stamp, T_wheels_laser)
        self._stretch = UnmatchedStretch()  # the longest run of unmatched scans
        self._last_offset = np.zeros(3)  # the wheels' offset at the last scan

    # -- the Estimator protocol ---------------------------------------------------------

    def handle(self, event: Event) -> None:
        super().handle(event)
        anchor = len(self._keys) - 1
        offset = self._tracker.offset.copy()
        if event.t == self._stamps[-1]:  # the latest event of this stamp holds
            self._anchors[-1], self._offsets[-1] = anchor, offset
        else:
            self._stamps.append(float(event.t))
            self._anchors.append(anchor)
            self._offsets.append(offset)

    def on_control(self, u: FloatArray, dt: float) -> None:
        if self._tracker.model is not None:  # (None: the data set's motion said nothing)
            self._tracker.predict(u, dt)

    def on_scan(self, event: LaserScan) -> None:
        self._counts["scans"] += 1
        points = scan_points(
            event.ranges, self._laser.beam_angles, self._max_range, min_range=self._cfg.min_range
        )
        if any(self._mounting):
            points = transform_points(self._mounting, points)
        last, self._last_scan = self._last_scan, float(event.t)
        if not self._keys:
            self._add_keyframe(event, points)
            return
        if last is not None:
            self._tracker.coast(event.t - last)  # only without odometry
        reference = self._local if self._local is not None else self._keys[-1].reference
        before = self._last_offset
        since = 0.0 if last is None else float(event.t) - last
        matched = self._tracker.match(reference, points, since)
        moved = between(before, self._tracker.odometry_offset)
        self._stretch.add(event.t, matched, math.hypot(moved[0], moved[1]))
        if self._tracker.last_override is not None:
            self._overrides.append((event.t, self._tracker.last_override))
        if self._tracker.keyframe_due():
            self._add_keyframe(event, points)
        self._last_offset = self._tracker.odometry_offset.copy()  # (reset at a keyframe)

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(compose(self._base(), self._tracker.offset))

    def finish(self) -> EstimatorOutput:
        never_matched = self._counts["scans"] > 1 and not self._tracker.counts["matched"]
        if not self._keys or never_matched:
            raise MatchError(laser_unusable(self._counts, self._tracker.counts), "laser_unusable")
        if len(self._graph) > 1:
            self._optimize()
            # Every closure judged once more with all the others in view, and the refused
            # ones offered again by the same statistic (backend).
            retracted = retract_inconsistent(self._graph, PAIR_KEYFRAMES)
            judged = {*self._graph.loop_pairs(), *retracted}
            pool = [c for ends, c in self._dropped.items() if ends not in judged]
            restored = restore_consistent(self._graph, pool, PAIR_KEYFRAMES)
            if restored:
                retracted += retract_inconsistent(self._graph, PAIR_KEYFRAMES)
            kept = set(self._graph.loop_pairs())
            back = sum((c.i, c.j) in kept for c in restored)
            self._counts["loops_retracted"] += len(retracted) - (len(restored) - back)
            self._counts["loops_restored"] += back
        poses = self._graph.poses
        anchors = np.asarray(self._anchors)
        offsets = np.asarray(self._offsets, dtype=np.float64).reshape(-1, 3)
        bases = np.broadcast_to(self._start, offsets.shape)
        if len(self._graph):
            bases = np.where((anchors >= 0)[:, None], poses[np.maximum(anchors, 0)], bases)
        path = SmoothedTrajectory(np.asarray(self._stamps), compose(bases, offsets))
        grid = None
        diagnostics = self._diagnostics()
        if len(self._graph):
            mapper = OccupancyMapper(
                self._laser,
                OccupancyMappingConfig(
                    resolution=self._cfg.map_resolution,
                    bounds="grow",
                    model=InverseSensorModel(max_range=MAP_MAX_RANGE),
                ),
                None,
            )
            mapper.integrate_many(compose(poses, self._mounting), np.asarray(self._ranges))
            grid = mapper.occupancy_grid()
            diagnostics["mapping"] = mapper.stats.as_dict()
        revisits = (0, 0)
        if len(self._graph) and self._cfg.loops.enabled:
            travelled = np.array([kf.travelled for kf in self._keys])
            checked, bad = revisit_contradictions(
                poses, [kf.points for kf in self._keys], self._mounting, travelled,
                self._cfg.loops.min_travel,
            )  # fmt: skip
            revisits = (checked, len(bad))
            diagnostics["revisits_checked"] = checked
            diagnostics["revisits_contradicting"] = len(bad)
        warnings = run_warnings(
            {**diagnostics, "loops_refused": self._counts["loop_rejected:chi2"]},
            self._overrides,
            self._stretch,
            self._graph.loop_chi2(),
            revisits,
        )
        if self._no_motion is not None:
            warnings = (still_odometry_warning(self._no_motion), *warnings)
        return EstimatorOutput(
            grid=grid,
            diagnostics=diagnostics,
            trajectory=path,
            graph=self._graph.graph_data() if len(self._graph) else None,
            warnings=warnings,
        )

    # -- views for tests and plots --------------------------------------------------------

    @property
    def graph(self) -> PoseGraph:
        """The pose graph so far."""
        return self._graph

    @property
    def keyframes(self) -> tuple[Keyframe, ...]:
        """The keyframes so far, in the graph's order."""
        return tuple(self._keys)

    @property
    def keyframe_times(self) -> FloatArray:
        """The stamp of every keyframe ``(K,)`` [s]."""
        return np.array([k.t for k in self._keys], dtype=np.float64)

    def loop_closures(self) -> list[tuple[int, int]]:
        """The accepted closures ``(j, k)`` (keyframe indices, ``j < k``) in the graph."""
        return self._graph.loop_pairs()

    # -- steps ----------------------------------------------------------------------------

    def _base(self) -> FloatArray:
        return self._graph.pose(len(self._keys) - 1) if self._keys else self._start

    def _add_keyframe(self, event: LaserScan, points: FloatArray) -> None:
        try:
            reference = prepare_scan(points)
        except MatchError as exc:  # too few points to be a keyframe: keep tracking the old
            self._counts[f"keyframe_refused:{exc.reason}"] += 1
            return
        pose = compose(self._base(), self._tracker.offset)
        k = self._graph.add_pose(pose)
        travelled = 0.0
        if k > 0:
            z, info, matched = self._tracker.edge()
            self._graph.add_edge(k - 1, k, z, info, "odometry")
            if self._tracker.doubt > 0.0:
                self._doubted = np.append(self._doubted, np.zeros(k + 1 - self._doubted.size, bool))
                self._doubted[k] = True
            self._counts["odometry_edges" if not matched else "matched_edges"] += 1
            travelled = self._keys[-1].travelled + math.hypot(z[0], z[1])
        self._keys.append(Keyframe(event.t, points, reference, travelled))
        self._ranges.append(np.asarray(event.ranges, dtype=np.float64))
        self._tracker.reset()
        self._clear_transient(k)
        if self._cfg.loops.enabled:
            self._add_signature(k)
        if self._cfg.loops.enabled and k > 0:
            self._close_loops(k)
        if self._pending and k - self._last_solve >= OPTIMIZE_EVERY:
            self._optimize()
        if self._reference == "map":
            self._local = local_map(
                self._graph.poses, [kf.points for kf in self._keys], k,
                scan_normals=self._scan_normals,
            )  # fmt: skip

    def _clear_transient(self, k: int) -> None:
        """Take out of keyframe ``k`` the points the recent keyframes (within
        :data:`TRANSIENT_TRAVEL` of path) saw through, and out of theirs the points ``k`` saw
        through: people walking, doors that opened
        (:mod:`slamkit.scanmatch.transient`). A keyframe that would lose more than
        :data:`MAX_TRANSIENT` of its points keeps them all (the poses, not the world, are
        then in doubt)."""
        self._views[k] = ScanView(
            self._ranges[k], self._laser.beam_angles, self._max_range, self._cfg.min_range,
            self._mounting,
        )  # fmt: skip
        self._views.pop(k - LOCAL_MAP_KEYFRAMES, None)
        here = self._keys[k].travelled
        recent = [
            j
            for j in range(max(k - LOCAL_MAP_KEYFRAMES + 1, 0), k)
            if here - self._keys[j].travelled <= TRANSIENT_TRAVEL
        ]
        if not recent:
            return
        pose_k = self._graph.pose(k)  # (the recent poses alone: not a copy of them all)
        near = {j: self._graph.pose(j) for j in recent}
        points = self._keys[k].points
        gone = np.zeros(points.shape[0], dtype=bool)
        for j in recent:
            gone |= self._views[j].seen_through_from(between(near[j], pose_k), points)
        self._drop_points(k, gone)
        for j in recent:
            seen = self._views[k].seen_through_from(between(pose_k, near[j]), self._keys[j].points)
            self._drop_points(j, seen)

    def _drop_points(self, k: int, gone: np.ndarray) -> None:
        n = int(gone.sum())
        if n == 0 or n > MAX_TRANSIENT * gone.size:
            return
        self._keys[k] = dataclasses.replace(self._keys[k], points=self._keys[k].points[~gone])
        self._normals.pop(k, None)
        self._counts["transient_points"] += n

    def _close_loops(self, k: int) -> None:
        s = self._cfg.loops
        poses = self._graph.poses
        travelled = np.array([kf.travelled for kf in self._keys])
        points = [kf.points for kf in self._keys]
        local = loop_candidates(poses[:, :2], travelled, k, s)
        tries = [(j, between(poses[j], poses[k]), search_window(travelled[k] - travelled[j], s))
                 for j in local]  # fmt: skip
        self._counts["loop_candidates"] += len(tries)
        if k % GLOBAL_EVERY == 0:
            far = travelled[k] - travelled >= s.min_travel
            for c in local:  # the local search has these places already
                far[max(c - SUBMAP_KEYFRAMES, 0) : c + SUBMAP_KEYFRAMES] = False
            found = self._places.candidates(k, far, GLOBAL_CANDIDATES)
            window = (WINDOW_XY, math.radians(WINDOW_DEG))
            tries += [(j, np.array([0.0, 0.0, turn]), window) for j, turn in found]
            self._counts["place_candidates"] += len(found)
        recent: FreeSpace | None = None  # keyframe k's neighbourhood, once a closure needs it
        for n, (j, initial, window) in enumerate(tries):
            ref_points, cloud, reference = self._submaps.get(poses, points, j)
            match = verify_closure(
                ref_points, cloud, self._keys[k].points, initial, window, s, NORMAL_ICP,
                reference=reference,
            )  # fmt: skip
            if isinstance(match, str):
                self._counts[f"loop_rejected:{match}"] += 1
                continue
            if recent is None:
                recent = neighbourhood(
                    poses, points, self._mounting, k, k - NEIGHBOURHOOD_KEYFRAMES + 1, k + 1
                )
            place = self._submaps.free_space(poses, points, j, self._mounting)
            if contradiction(place, recent, match.pose) > MAX_CONTRADICTION:
                self._counts["loop_rejected:free_space"] += 1
                continue
            self._counts["loops_verified"] += 1
            self._counts["places_verified"] += int(n >= len(local))  # beyond the local ones
            self._confirm(poses, (j, k, match))
        self._submaps.advance()

    def _add_signature(self, k: int) -> None:
        """Keyframe ``k``'s place signature (:mod:`~slamkit.slam.laser_graph.places`)."""
        _, clouds = neighbourhood_scans(
            self._graph.poses, [kf.points for kf in self._keys], self._mounting, k,
            k - NEIGHBOURHOOD_KEYFRAMES + 1, k + 1,
        )  # fmt: skip
        self._places.add(signature(np.concatenate(clouds)))

    def _scan_normals(self, i: int) -> ScanNormals:
        """Keyframe ``i``'s normals in its own frame (computed once)."""
        if i not in self._normals:
            self._normals[i] = scan_normals(self._keys[i].points)
        return self._normals[i]

    def _confirm(self, poses: FloatArray, new: tuple[int, int, LoopMatch]) -> None:
        """Add ``new`` and its waiting partners once one agrees with it (pairwise
        consistency, :func:`~slamkit.slam.laser_graph.loops.pair_consistent`)."""
        j, k, found = new
        self._waiting = [w for w in self._waiting if k - w[1] <= PAIR_KEYFRAMES]
        near = [
            w
            for w in [*self._waiting, *self._confirmed]
            if abs(w[0] - j) <= PAIR_KEYFRAMES
            and 0 < k - w[1] <= PAIR_KEYFRAMES
            and not self._doubt_between(w[0], j)
            and not self._doubt_between(w[1], k)
        ]
        agree = consistent_partners(
            poses, (j, k, found.pose), [(w[0], w[1], w[2].pose) for w in near]
        )
        partners = [w for w, ok in zip(near, agree, strict=True) if ok]
        if not partners:
            self._waiting.append(new)
            return
        for w in [*partners, new]:
            if w in self._confirmed:
                continue
            info = floored_information(w[2].cov, scale=CLOSURE_COV_SCALE)
            self._graph.add_edge(w[0], w[1], w[2].pose, info, "loop")
            self._counts["loops_added"] += 1
            self._pending += 1
            if w in self._waiting:
                self._waiting.remove(w)
        self._confirmed = [*self._confirmed[-4 * PAIR_KEYFRAMES :], *partners, new]

    def _doubt_between(self, a: int, b: int) -> bool:
        """Whether a chain edge between keyframes ``a`` and ``b`` was doubted (a standstill
        the laser could not confirm, :attr:`Tracker.doubt`): a cycle through it agrees with
        a closure shifted along the robot's way, so it confirms nothing."""
        lo, hi = min(a, b) + 1, max(a, b) + 1
        return bool(self._doubted[lo:hi].any())

    def _optimize(self) -> None:
        kinds = self._graph.edge_kinds()
        pending = [e for e in range(len(kinds)) if kinds[e] == "loop"][-self._pending :]
        if not self._pending:
            pending = []
        # The pending closures as they are, for re-judging (the check removes refused ones).
        offered: dict[int, RefusedClosure] = {}
        if pending:
            i, j, z, info = self._graph.edges()
            offered = {e: RefusedClosure(int(i[e]), int(j[e]), z[e], info[e]) for e in pending}
        removed = optimize_consistent(self._graph, pending, MAX_CHI2, MAX_EDGE_CHI2)
        self._counts["loop_rejected:chi2"] += len(removed)
        self._counts["solves"] += 1
        self._pending = 0
        self._last_solve = len(self._graph)
        if removed and offered:
            # Refused closures wait, while their newer end is recent, for a majority
            # against the closures that refused them (backend.rejudge).
            window = 2 * PAIR_KEYFRAMES
            newest = len(self._graph) - 1
            self._refused = [c for c in self._refused if newest - c.j <= window]
            self._refused += [offered[e] for e in removed]
            self._refused, readmitted, reversed_ = rejudge(
                self._graph, self._refused, window, MAX_CHI2, MAX_EDGE_CHI2
            )
            self._counts["loops_readmitted"] += readmitted
            self._dropped.update(((c.i, c.j), c) for c in self._refused)
            self._counts["loops_reversed"] += reversed_

    def _diagnostics(self) -> dict[str, object]:
        c = self._counts + self._tracker.counts
        solves = self._graph.solves
        # Without odometry: the scans matched with the prediction along a corridor, and the
        # matched speeds not believed (frontend.Tracker.match).
        coasting = ("degenerate_fused", "speed_not_believed")
        no_odometry = {k: c[k] for k in coasting} if self._tracker.velocity is not None else {}
        return {
            **no_odometry,
            "odometry": "wheels" if self._tracker.velocity is None else NO_ODOMETRY,
            "frontend_reference": self._reference,
            "scans": c["scans"],
            "keyframes": len(self._keys),
            "matched": c["matched"],
            "unmatched": {k[len("failed:") :]: v for k, v in c.items() if k.startswith("failed:")},
            "gated": c["gated"],
            "relocation_tried": c["relocation_tried"],
            "relocated": c["relocated"],
            "odometry_overridden": len(self._overrides),
            "odometry_overrides": override_rows(self._overrides),
            "odometry_stalls": c["stalled"],
            "standstills_doubted": c["standstill_doubted"],
            "lost": c["lost"],
            "transient_points": c["transient_points"],
            "odometry_edges": c["odometry_edges"],
            "loop_candidates": c["loop_candidates"],
            "place_candidates": c["place_candidates"],
            "places_verified": c["places_verified"],
            "loops_verified": c["loops_verified"],
            "loops_added": c["loops_added"],
            "loops_unconfirmed": c["loops_verified"] - c["loops_added"],
            "loops_kept": len(self.loop_closures()),
            "loops_readmitted": c["loops_readmitted"],
            "loops_reversed": c["loops_reversed"],
            "loops_retracted": c["loops_retracted"],
            "loops_restored": c["loops_restored"],
            "loops_rejected": {
                k[len("loop_rejected:") :]: v
                for k, v in c.items()
                if k.startswith("loop_rejected:")
            },
            "keyframes_refused": sum(v for k, v in c.items() if k.startswith("keyframe_refused:")),
            "optimizations": len(solves),
            "optimizations_not_converged": sum(1 for r in solves if not r.converged),
            "optimization_start": (
                "the current estimate (the last optimum extended by the front end)"
                if all(r.start == "given" for r in solves)
                else sorted({r.start for r in solves})
            ),
            "optimization_seconds": float(sum(r.seconds for r in solves)),
            "final_cost": solves[-1].cost if solves else None,
        }
