"""The graph data model shared by the readers/writers (:mod:`slamkit.io.posegraph`) and the
optimiser (:mod:`slamkit.optim`).

A :class:`GraphData` is what a graph file *says*, converted to slamkit's conventions at load
time, independent of the file family it came from:

* 2D poses are ``(x, y, θ)`` rows; 3D poses are ``(x, y, z, qw, qx, qy, qz)`` rows (unit
  quaternion, ``wxyz`` as everywhere in slamkit); 2D landmarks are ``(x, y)`` rows.
* Every edge set stores its measurement in the same parameterisation as the variables, and its
  weight as a full symmetric **information** matrix in slamkit's tangent order:
  2D ``(x, y, θ)``; 3D ``(x, y, z, rx, ry, rz)`` (translation first, as g2o).  TORO's order,
  iSAM's square-root information and GTSAM's covariances are converted by the readers.
* Ids are the file's integer ids; ``pose_ids``/``landmark_ids`` keep file order so a writer
  can reproduce the file.  ``lines`` keeps the 1-based source line of each edge for error
  messages (0 when the graph was built in memory).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

EdgeKind = Literal[
    "se2",  # relative pose Z = X_i⁻¹ X_j, measurement (E, 3) (x, y, θ); information (E, 3, 3)
    "se3",  # relative pose, measurement (E, 7) (x, y, z, qw, qx, qy, qz); information (E, 6, 6)
    "se2_prior",  # absolute pose prior on i (j = -1), measurement (E, 3)
    "se3_prior",  # absolute pose prior on i (j = -1), measurement (E, 7)
    "se2_xy",  # landmark j in the frame of pose i, measurement (E, 2); information (E, 2, 2)
    "range_bearing",  # (range, bearing) of landmark j from pose i; information (E, 2, 2)
    "range",  # range from pose i to landmark j, measurement (E, 1); information (E, 1, 1)
    "bearing",  # bearing of landmark j from pose i, measurement (E, 1); information (E, 1, 1)
    "gps",  # fix (x, y) of the antenna at lever arm j (a 2D point) of pose i; info (E, 2, 2)
]

GraphFamily = Literal["g2o", "toro", "isam", "gtsam", "memory"]


@dataclass(frozen=True)
class EdgeSet:
    """All edges of one kind, as arrays (edge ``k`` connects ``i[k]`` → ``j[k]``)."""

    kind: EdgeKind
    i: IntArray  # (E,) file id of the first (pose) variable
    j: IntArray  # (E,) file id of the second variable, -1 for unary edges
    measurement: FloatArray  # (E, m)
    information: FloatArray  # (E, r, r), symmetric positive definite
    lines: IntArray  # (E,) 1-based source line, 0 when built in memory

    def __len__(self) -> int:
        return int(self.i.shape[0])


@dataclass(frozen=True)
class GraphData:
    """Variables, edges and provenance of one graph file.

    ``poses`` may be empty when the file has no vertex lines (``CSAIL.g2o``, iSAM files):
    the optimiser then initialises by chaining odometry or by a chordal relaxation.
    ``edge_order`` records, for a writer, the interleaving of edge sets in the file as
    ``(edge set index, row)`` pairs; ``None`` means sets in order.
    """

    dim: Literal[2, 3]
    pose_ids: IntArray  # (N,)
    poses: FloatArray  # (N, 3) or (N, 7); (0, 3|7) when the file has no vertices
    landmark_ids: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    landmarks: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    edges: tuple[EdgeSet, ...] = ()
    fixed_ids: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    equivalences: IntArray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    family: GraphFamily = "memory"
    source: str = ""
    edge_order: IntArray | None = None

    def edges_of(self, kind: EdgeKind) -> EdgeSet | None:
        """The edge set of ``kind``, or ``None`` when the graph has none."""
        for e in self.edges:
            if e.kind == kind:
                return e
        return None

    @property
    def n_edges(self) -> int:
        return sum(len(e) for e in self.edges)


def loop_closures(graph: GraphData, min_gap: int = 2) -> IntArray:
    """The pose-to-pose edges of ``graph`` between poses at least ``min_gap`` apart in the
    graph's order (the loop closures; 2: every edge but the consecutive ones), as ``(E, 2)``
    rows into ``graph.poses``; ``min_gap=1``: every pose-to-pose edge."""
    row = {int(pid): k for k, pid in enumerate(graph.pose_ids)}
    pairs = []
    for edges in graph.edges:
        if edges.kind not in ("se2", "se3"):
            continue
        for i, j in zip(edges.i, edges.j, strict=True):
            a, b = row.get(int(i)), row.get(int(j))
            if a is not None and b is not None and abs(a - b) >= min_gap:
                pairs.append((a, b))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)
