"""A finished run as an MCAP file for Foxglove (``pip install 'slamkit[mcap]'``).

Messages are JSON, each channel with a JSON schema of the Foxglove message type it follows
(written here, the fields Foxglove's panels read). The world frame is ``map``; times are the
data set's seconds as nanoseconds (shifted to start at 0 if a data set's times are negative).

========================  =========================  ===========================================
topic                     schema                     messages
========================  =========================  ===========================================
``/scan``                 ``foxglove.LaserScan``     one per laser scan, placed at the sensor's
                                                     pose on the estimated path (robot ⊕ the
                                                     laser's mounting); no-return beams as 0
``/tf``                   ``foxglove.FrameTransform`` one per estimate: ``map`` → ``base_link``
``/path``                 ``foxglove.PosesInFrame``  one: the whole estimated path
``/truth/path``           ``foxglove.PosesInFrame``  one, when the data set has a true path
``/graph``                ``foxglove.SceneUpdate``   one, when the estimator kept a pose graph:
                                                     its edges (grey) and loop closures (red)
``/map``                  ``foxglove.Grid``          one, the occupancy grid the run built or
                                                     localized in: int8 percent, -1 unknown
========================  =========================  ===========================================

The products of the whole run (path, graph, map) are logged once, at the first time stamp, so
that they show for the whole playback. Foxglove's laser scan assumes evenly spaced beams from
``start_angle`` to ``end_angle``: the beams of every slamkit data set are.

The ``mcap`` package is imported only here, and only when a file is written.
"""

from __future__ import annotations

import base64
import json
import os
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.datasets.stream import Dataset, LaserScan
from slamkit.errors import InputError
from slamkit.geometry.pose2 import compose, interpolate_poses
from slamkit.maps import UNKNOWN, OccupancyGrid
from slamkit.optim.data import GraphData, loop_closures
from slamkit.pipeline import Result

__all__ = ["FRAME", "SCHEMAS", "TOPICS", "require_mcap", "write_mcap"]

FRAME = "map"
"""The world frame of every message."""
ROBOT_FRAME = "base_link"

# -- JSON schemas of the Foxglove message types used ----------------------------------------


def _object(title: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": properties}


_NUMBER = {"type": "number"}
_INT = {"type": "integer"}
_STRING = {"type": "string"}
_TIME = _object("time", {"sec": _INT, "nsec": _INT})
_VECTOR3 = _object("foxglove.Vector3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_POINT3 = _object("foxglove.Point3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_QUATERNION = _object(
    "foxglove.Quaternion", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER, "w": _NUMBER}
)
_POSE = _object("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_COLOR = _object("foxglove.Color", {"r": _NUMBER, "g": _NUMBER, "b": _NUMBER, "a": _NUMBER})


def _array(items: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": items}


_LINE = _object(
    "foxglove.LinePrimitive",
    {
        "type": {"type": "integer", "description": "0 line strip, 1 line loop, 2 line list"},
        "pose": _POSE,
        "thickness": _NUMBER,
        "scale_invariant": {"type": "boolean"},
        "points": _array(_POINT3),
        "color": _COLOR,
        "colors": _array(_COLOR),
        "indices": _array(_INT),
    },
)
_ENTITY = _object(
    "foxglove.SceneEntity",
    {
        "timestamp": _TIME,
        "frame_id": _STRING,
        "id": _STRING,
        "lifetime": _TIME,
        "frame_locked": {"type": "boolean"},
        "metadata": _array(_object("foxglove.KeyValuePair", {"key": _STRING, "value": _STRING})),
        "lines": _array(_LINE),
        **{
            name: _array({"type": "object"})
            for name in ("arrows", "cubes", "spheres", "cylinders", "triangles", "texts", "models")
        },
    },
)

SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.LaserScan": _object(
        "foxglove.LaserScan",
        {
            "timestamp": _TIME,
            "frame_id": _STRING,
            "pose": _POSE,
            "start_angle": _NUMBER,
            "end_angle": _NUMBER,
            "ranges": _array(_NUMBER),
            "intensities": _array(_NUMBER),
        },
    ),
    "foxglove.FrameTransform": _object(
        "foxglove.FrameTransform",
        {
            "timestamp": _TIME,
            "parent_frame_id": _STRING,
            "child_frame_id": _STRING,
            "translation": _VECTOR3,
            "rotation": _QUATERNION,
        },
    ),
    "foxglove.PosesInFrame": _object(
        "foxglove.PosesInFrame",
        {"timestamp": _TIME, "frame_id": _STRING, "poses": _array(_POSE)},
    ),
    "foxglove.SceneUpdate": _object(
        "foxglove.SceneUpdate",
        {
            "deletions": _array(
                _object(
                    "foxglove.SceneEntityDeletion",
                    {"timestamp": _TIME, "type": _INT, "id": _STRING},
                )
            ),
            "entities": _array(_ENTITY),
        },
    ),
    "foxglove.Grid": _object(
        "foxglove.Grid",
        {
            "timestamp": _TIME,
            "frame_id": _STRING,
            "pose": _POSE,
            "column_count": _INT,
            "cell_size": _object("foxglove.Vector2", {"x": _NUMBER, "y": _NUMBER}),
            "row_stride": _INT,
            "cell_stride": _INT,
            "fields": _array(
                _object(
                    "foxglove.PackedElementField",
                    {
                        "name": _STRING,
                        "offset": _INT,
                        "type": {"type": "integer", "description": "2 = INT8"},
                    },
                )
            ),
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    ),
}

TOPICS: dict[str, str] = {
    "/scan": "foxglove.LaserScan",
    "/tf": "foxglove.FrameTransform",
    "/path": "foxglove.PosesInFrame",
    "/truth/path": "foxglove.PosesInFrame",
    "/graph": "foxglove.SceneUpdate",
    "/map": "foxglove.Grid",
}
"""Every topic the file may hold and its schema's name (module docstring)."""

_INT8 = 2  # foxglove.NumericType.INT8
_LINE_LIST = 2  # foxglove.LineType.LINE_LIST
_EDGE_GREY = {"r": 0.55, "g": 0.55, "b": 0.55, "a": 1.0}
_CLOSURE_RED = {"r": 0.85, "g": 0.1, "b": 0.1, "a": 1.0}


def require_mcap() -> Any:
    """The ``mcap.writer`` module, or an :class:`InputError` saying how to install it."""
    try:
        import mcap.writer
    except ImportError as exc:
        raise InputError(
            "an MCAP file needs the mcap package: pip install 'slamkit[mcap]'"
        ) from exc
    return mcap.writer


# -- messages -------------------------------------------------------------------------------


def _stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _pose(x: float, y: float, theta: float, z: float = 0.0) -> dict[str, Any]:
    # a rotation by theta about z: q = (0, 0, sin(θ/2), cos(θ/2))
    return {
        "position": {"x": x, "y": y, "z": z},
        "orientation": {
            "x": 0.0,
            "y": 0.0,
            "z": float(np.sin(theta / 2)),
            "w": float(np.cos(theta / 2)),
        },
    }


def _poses_in_frame(ns: int, poses: np.ndarray) -> dict[str, Any]:
    return {
        "timestamp": _stamp(ns),
        "frame_id": FRAME,
        "poses": [_pose(float(x), float(y), float(t)) for x, y, t in poses[:, :3]],
    }


def grid_message(ns: int, grid: OccupancyGrid) -> dict[str, Any]:
    """A ``foxglove.Grid`` of ``grid``: one int8 per cell, the occupancy in percent (-1 for a
    cell at :data:`~slamkit.maps.UNKNOWN`), rows from the grid's bottom (y = origin) up, as
    slamkit's rows run."""
    percent = np.rint(100.0 * grid.prob).astype(np.int8)
    percent[grid.prob == UNKNOWN] = -1
    cols = grid.shape[1]
    x0, y0 = (float(v) for v in grid.origin_xy)
    return {
        "timestamp": _stamp(ns),
        "frame_id": FRAME,
        "pose": _pose(x0, y0, 0.0),
        "column_count": cols,
        "cell_size": {"x": grid.resolution, "y": grid.resolution},
        "row_stride": cols,
        "cell_stride": 1,
        "fields": [{"name": "occupancy", "offset": 0, "type": _INT8}],
        "data": base64.b64encode(np.ascontiguousarray(percent).tobytes()).decode("ascii"),
    }


def graph_message(ns: int, graph: GraphData) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` of the pose graph: two line lists, ``graph/edges`` (the
    edges between consecutive poses) and ``graph/closures`` (:func:`~slamkit.optim.data.
    loop_closures`)."""
    xyz = np.zeros((graph.poses.shape[0], 3))
    xyz[:, : 2 if graph.dim == 2 else 3] = graph.poses[:, : 2 if graph.dim == 2 else 3]
    every = loop_closures(graph, min_gap=1)
    far = np.abs(every[:, 0] - every[:, 1]) >= 2
    entities = []
    for name, pairs, color in (
        ("graph/edges", every[~far], _EDGE_GREY),
        ("graph/closures", every[far], _CLOSURE_RED),
    ):
        points = [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in xyz[pairs.ravel()]]
        line = {
            "type": _LINE_LIST,
            "pose": _pose(0.0, 0.0, 0.0),
            "thickness": 2.0,
            "scale_invariant": True,
            "points": points,
            "color": color,
            "colors": [],
            "indices": [],
        }
        entities.append(
            {
                "timestamp": _stamp(ns),
                "frame_id": FRAME,
                "id": name,
                "lifetime": _stamp(0),  # 0: until replaced
                "frame_locked": False,
                "metadata": [{"key": "count", "value": str(len(pairs))}],
                "lines": [line],
                **{
                    k: []
                    for k in (
                        "arrows",
                        "cubes",
                        "spheres",
                        "cylinders",
                        "triangles",
                        "texts",
                        "models",
                    )
                },
            }
        )
    return {"deletions": [], "entities": entities}


def _scan_messages(
    result: Result, dataset: Dataset, to_ns: Any
) -> Iterator[tuple[int, dict[str, Any]]]:
    laser = dataset.laser
    scans = [e for e in dataset.events if isinstance(e, LaserScan)]
    if laser is None or not scans or not len(result.poses):
        return
    times = np.array([s.t for s in scans])
    robot = interpolate_poses(np.asarray(result.times), np.asarray(result.poses), times)
    sensor = compose(robot, np.asarray(laser.mounting, dtype=np.float64))
    start, end = float(laser.beam_angles[0]), float(laser.beam_angles[-1])
    for scan, pose in zip(scans, sensor, strict=True):
        ranges = np.where(scan.ranges >= laser.max_range, 0.0, np.round(scan.ranges, 4))
        ns = to_ns(scan.t)
        yield (
            ns,
            {
                "timestamp": _stamp(ns),
                "frame_id": FRAME,
                "pose": _pose(float(pose[0]), float(pose[1]), float(pose[2])),
                "start_angle": start,
                "end_angle": end,
                "ranges": ranges.tolist(),
                "intensities": [],
            },
        )


def _messages(result: Result, dataset: Dataset) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """``(topic, time [ns], message)`` in time order per topic."""
    times = np.asarray(result.times, dtype=np.float64)
    poses = np.asarray(result.poses, dtype=np.float64)
    first = [float(times[0])] if times.size else []
    stamps = [*first, dataset.start_time]
    shift = max(0.0, -min(stamps))

    def to_ns(t: float) -> int:
        return round((t + shift) * 1e9)

    t0 = to_ns(min(stamps))
    if len(poses):
        yield "/path", t0, _poses_in_frame(t0, poses)
    truth = dataset.truth
    if truth.poses is not None and len(truth.poses):
        yield "/truth/path", t0, _poses_in_frame(t0, truth.poses)
    if result.output.graph is not None and len(result.output.graph.poses):
        yield "/graph", t0, graph_message(t0, result.output.graph)
    grid = result.output.grid if result.output.grid is not None else dataset.known_grid
    if grid is not None:
        yield "/map", t0, grid_message(t0, grid)
    for t, (x, y, th) in zip(times, poses, strict=True):
        ns = to_ns(float(t))
        yield (
            "/tf",
            ns,
            {
                "timestamp": _stamp(ns),
                "parent_frame_id": FRAME,
                "child_frame_id": ROBOT_FRAME,
                "translation": {"x": float(x), "y": float(y), "z": 0.0},
                "rotation": _pose(0.0, 0.0, float(th))["orientation"],
            },
        )
    for ns, msg in _scan_messages(result, dataset, to_ns):
        yield "/scan", ns, msg


def write_mcap(result: Result, dataset: Dataset, path: str | Path) -> dict[str, int]:
    """Write ``result`` (a run on ``dataset``) to ``path`` as MCAP (module docstring),
    atomically; returns the number of messages per topic."""
    writer_module = require_mcap()
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
    counts: dict[str, int] = {}
    try:
        with tmp.open("wb") as stream:
            writer = writer_module.Writer(stream)
            writer.start(profile="", library="slamkit")
            channels: dict[str, int] = {}
            schema_ids: dict[str, int] = {}
            for topic, ns, message in _messages(result, dataset):
                if topic not in channels:
                    name = TOPICS[topic]
                    if name not in schema_ids:
                        data = json.dumps(SCHEMAS[name]).encode()
                        schema_ids[name] = writer.register_schema(name, "jsonschema", data)
                    channels[topic] = writer.register_channel(topic, "json", schema_ids[name])
                    counts[topic] = 0
                data = json.dumps(message, allow_nan=False, separators=(",", ":")).encode()
                writer.add_message(channels[topic], log_time=ns, data=data, publish_time=ns)
                counts[topic] += 1
            writer.add_metadata(
                "slamkit", {"estimator": result.estimator, "dataset": result.dataset}
            )
            writer.finish()
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return counts
