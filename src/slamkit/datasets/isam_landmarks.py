"""iSAM 2-D files with landmarks, as a :class:`Dataset` for landmark mapping.

The iSAM text format (one measurement per line, in the order the robot took them; no vertex
lines)::

    EDGE2 i j dx dy dth  s11 s12 s13 s22 s23 s33     (ODOMETRY is a synonym)
    LANDMARK i l x y     s11 s12 s22

``EDGE2`` is the motion of pose ``j`` seen from pose ``i``; ``LANDMARK`` the position of
landmark ``l`` in the frame of pose ``i`` (metres). The ``s`` are the row-major upper
triangle of the square-root information matrix ``R``: information ``Λ = RᵀR`` and covariance
``Λ⁻¹ = R⁻¹R⁻ᵀ`` (computed by two triangular solves, :func:`scipy.linalg.cho_solve` with
``R`` as the Cholesky factor of ``Λ``).

:func:`load_citytrees10000` reads ``isam/cityTrees10000.txt`` (Johannsson & Kaess, simulated:
10000 poses, 100 landmarks, 4443 landmark readings, 9999 odometry edges) and its noise-free
twin ``isam/groundtruth/cityTrees10000_groundtruth.txt``:

* time is synthetic: pose ``k`` is at ``t = k`` seconds (1 s per pose);
* :class:`LandmarkReadings` at ``t = k`` hold every noisy ``LANDMARK k …`` line: kind
  ``"position"`` (``(x, y)`` in the robot frame), ids = landmark ids (or ``-1``, shuffled
  within the scan, with ``identities=False``);
* :class:`Odometry` at every ``t = k``: the NOISY odometry chained from pose 0 at the origin
  (for completeness; mapping with known poses uses the truth);
* truth: the poses from chaining the noise-free odometry from the origin, and each landmark
  at the mean of its noise-free sightings composed with their true poses. The sightings of a
  landmark agree to about 1.5 cm, not exactly: the ground-truth file rounds to six
  significant digits (``-3.14159`` for ``-π``) and the rounding accumulates along the chain.
  The largest spread is stored in ``metadata["truth_landmark_spread_m"]``.
* the file has 8 pairs of landmark ids at exactly the same position, always read together
  (e.g. ids 2 and 34); they are listed in ``metadata["coincident_landmark_ids"]``. With ids
  this does not matter; without, no association can tell the two of a pair apart.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping
from slamkit.datasets.assemble import assemble_events, odometry_events, reading_events
from slamkit.datasets.paths import require_file
from slamkit.datasets.stream import (
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.datasets.text import ascii_fields, integer_values, read_text, text_lines
from slamkit.errors import DatasetFormatError
from slamkit.geometry import pose2, wrap_angle
from slamkit.maps import LandmarkMap
from slamkit.models import OdometryModel

__all__ = [
    "CITYTREES_FILES",
    "CityTreesOptions",
    "IsamLandmarkGraph",
    "load_citytrees10000",
    "read_isam_landmark_graph",
    "sqrt_information_to_covariance",
]

CITYTREES_FILES = (
    "isam/cityTrees10000.txt",
    "isam/groundtruth/cityTrees10000_groundtruth.txt",
)
"""The files :func:`load_citytrees10000` needs under the data root."""

_EDGE_TAGS = ("EDGE2", "ODOMETRY")
_N_FIELDS = {"EDGE2": 12, "ODOMETRY": 12, "LANDMARK": 8}  # tag included


@dataclass(frozen=True, eq=False)
class IsamLandmarkGraph:
    """The measurements of one iSAM 2-D file, in file order.

    ``edges``: ``edge_ids (E, 2)`` pose pairs ``(i, j)``, ``edge_z (E, 3)`` ``(dx, dy, dth)``,
    ``edge_sqrt_info (E, 6)`` and the 1-based file line of each (``edge_lines``).
    ``landmarks``: ``landmark_ids (L, 2)`` ``(pose, landmark)``, ``landmark_z (L, 2)`` robot
    frame ``(x, y)``, ``landmark_sqrt_info (L, 3)`` and ``landmark_lines``.
    """

    path: Path
    edge_ids: np.ndarray
    edge_z: FloatArray
    edge_sqrt_info: FloatArray
    edge_lines: np.ndarray
    landmark_ids: np.ndarray
    landmark_z: FloatArray
    landmark_sqrt_info: FloatArray
    landmark_lines: np.ndarray


def read_isam_landmark_graph(path: str | Path) -> IsamLandmarkGraph:
    """Parse an iSAM 2-D file of ``EDGE2``/``ODOMETRY`` and ``LANDMARK`` lines.

    Blank lines and lines starting with ``#`` are skipped. A line of another type, with the
    wrong number of fields, non-numeric or non-finite values, or a non-integer index raises
    :class:`DatasetFormatError` naming the file and the line.
    """
    p = Path(path)
    text = read_text(p)  # the shared opener: missing file, gzip, UTF-8 with its line
    # One pass over the lines checks tags and field counts and collects the value tokens;
    # each type is then converted by one NumPy call (a bad token is located afterwards).
    tokens: dict[bool, list[str]] = {True: [], False: []}  # is_edge -> flat value tokens
    lines: dict[bool, list[int]] = {True: [], False: []}
    for no, line in enumerate(text_lines(text), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        tag = fields[0]
        if not ascii_fields(fields):
            raise DatasetFormatError("expected ASCII text, got other characters", p, no)
        want = _N_FIELDS.get(tag)
        if want is None:
            raise DatasetFormatError(
                f"unknown line type {tag!r}; expected EDGE2, ODOMETRY or LANDMARK", p, no
            )
        if len(fields) != want:
            raise DatasetFormatError(
                f"{tag}: expected {want - 1} values after the tag, got {len(fields) - 1}", p, no
            )
        is_edge = tag in _EDGE_TAGS
        tokens[is_edge].extend(fields[1:])
        lines[is_edge].append(no)
    e = _to_table(tokens[True], lines[True], 11, "EDGE2", p)
    lm = _to_table(tokens[False], lines[False], 7, "LANDMARK", p)
    for table, at, tag in ((e, lines[True], "EDGE2"), (lm, lines[False], "LANDMARK")):
        for col in (0, 1):
            integer_values(table[:, col], at, f"{tag} index", p)
    return IsamLandmarkGraph(
        path=p,
        edge_ids=e[:, :2].astype(np.int64),
        edge_z=e[:, 2:5],
        edge_sqrt_info=e[:, 5:11],
        edge_lines=np.asarray(lines[True], dtype=np.int64),
        landmark_ids=lm[:, :2].astype(np.int64),
        landmark_z=lm[:, 2:4],
        landmark_sqrt_info=lm[:, 4:7],
        landmark_lines=np.asarray(lines[False], dtype=np.int64),
    )


def _to_table(tokens: list[str], lines: list[int], width: int, tag: str, path: Path) -> FloatArray:
    """``(rows, width)`` floats from the flat value tokens of one line type; errors name the
    line with the first non-numeric, non-finite or bad-index value."""
    try:
        table = np.array(tokens, dtype=np.float64).reshape(-1, width)
    except ValueError:
        for k in range(len(lines)):
            for tok in tokens[k * width : (k + 1) * width]:
                try:
                    float(tok)
                except ValueError:
                    raise DatasetFormatError(
                        f"{tag}: expected numbers, got {tok!r}", path, lines[k]
                    ) from None
        raise  # unreachable: some token failed to convert above
    bad = np.flatnonzero(~np.all(np.isfinite(table), axis=1))
    if bad.size:
        raise DatasetFormatError(f"{tag}: expected finite numbers", path, lines[int(bad[0])])
    idx = table[:, :2]
    bad = np.flatnonzero(np.any((idx != np.round(idx)) | (idx < 0), axis=1))
    if bad.size:
        k = int(bad[0])
        raise DatasetFormatError(
            f"{tag}: expected two non-negative integer indices, got {idx[k, 0]:g} {idx[k, 1]:g}",
            path,
            lines[k],
        )
    return table


def sqrt_information_to_covariance(upper: FloatArray, n: int) -> FloatArray:
    """Covariance ``(n, n)`` from the row-major upper triangle ``(n(n+1)/2,)`` of a
    square-root information matrix ``R``: ``Σ = (RᵀR)⁻¹``, by triangular solves with ``R``
    (which is the upper Cholesky factor of the information ``RᵀR``). Raises
    :class:`ValueError` when a diagonal entry is zero (singular information)."""
    R = np.zeros((n, n))
    R[np.triu_indices(n)] = upper
    if np.any(np.diag(R) == 0):
        raise ValueError("singular square-root information (a zero diagonal entry)")
    cov = cho_solve((R, False), np.eye(n))  # (RᵀR)⁻¹ = R⁻¹ R⁻ᵀ
    return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)


def _uniform_noise(rows: FloatArray, lines: np.ndarray, what: str, path: Path) -> FloatArray:
    """The one square-root information row shared by all lines; error if it varies."""
    if rows.shape[0] == 0:
        raise DatasetFormatError(f"no {what} lines", path)
    differ = np.flatnonzero(np.any(rows != rows[0], axis=1))
    if differ.size:
        raise DatasetFormatError(
            f"{what} noise varies from line to line (line {int(lines[0])} and this one "
            "differ); a landmark data set carries one sensor noise",
            path,
            int(lines[differ[0]]),
        )
    return rows[0]


def _chain(graph: IsamLandmarkGraph, n_poses: int) -> FloatArray:
    """Poses ``(n_poses, 3)`` from composing the odometry edges ``k → k+1`` from the origin:
    ``θ_{k+1} = θ_k + dθ_k`` and ``t_{k+1} = t_k + R(θ_k) (dx_k, dy_k)``, i.e. repeated
    :func:`~slamkit.geometry.pose2.compose`, evaluated with cumulative sums."""
    ids = graph.edge_ids
    bad = np.flatnonzero((ids[:, 0] != np.arange(ids.shape[0])) | (ids[:, 1] != ids[:, 0] + 1))
    if bad.size:
        k = int(bad[0])
        raise DatasetFormatError(
            f"expected the odometry chain k → k+1 in order (edge {k}: {k} → {k + 1}), got "
            f"{ids[k, 0]} → {ids[k, 1]}; loop closures are not supported here",
            graph.path,
            int(graph.edge_lines[k]),
        )
    z = graph.edge_z[: n_poses - 1]
    theta = np.concatenate([[0.0], np.cumsum(z[:, 2])])  # unwrapped headings
    rotation = np.zeros((n_poses - 1, 3))
    rotation[:, 2] = theta[:-1]
    step = pose2.transform_points(rotation, z[:, :2])  # R(θ_k) (dx_k, dy_k)
    poses = np.zeros((n_poses, 3))
    poses[1:, :2] = np.cumsum(step, axis=0)
    poses[:, 2] = wrap_angle(theta)
    return poses


@dataclass(frozen=True)
class CityTreesOptions:
    """Options of the ``citytrees10000`` data set."""

    identities: bool = True
    """Readings carry the landmark ids. False: ids are ``-1`` and each scan's readings are
    shuffled with the seed (for data-association tests)."""


def _same_rows(
    noisy: IsamLandmarkGraph, exact: IsamLandmarkGraph, tag: str, a: np.ndarray, b: np.ndarray
) -> None:
    """The two files must list the same ``tag`` lines (index pairs) in the same order; the
    error names the first line without a partner, in the file that has it, and the other."""
    lines_a = noisy.edge_lines if tag == "EDGE2" else noisy.landmark_lines
    lines_b = exact.edge_lines if tag == "EDGE2" else exact.landmark_lines
    n = min(len(a), len(b))
    differ = np.flatnonzero(np.any(a[:n] != b[:n], axis=1))
    if differ.size:
        k = int(differ[0])
        raise DatasetFormatError(
            f"{tag} {a[k, 0]} {a[k, 1]} here, but {tag} {b[k, 0]} {b[k, 1]} on line "
            f"{lines_b[k]} of {exact.path.name}: the two files must list the same {tag} lines",
            noisy.path,
            int(lines_a[k]),
        )
    if len(a) != len(b):
        longer, other, at = (noisy, exact, lines_a) if len(a) > len(b) else (exact, noisy, lines_b)
        raise DatasetFormatError(
            f"{tag} line {n + 1} of {max(len(a), len(b))} here, but {other.path.name} has only "
            f"{n}: the two files must list the same {tag} lines",
            longer.path,
            int(at[n]),
        )


def load_citytrees10000(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None
) -> Dataset:
    """The cityTrees10000 landmark graph of iSAM as a landmark-mapping data set.

    See the module docstring for the event stream, the synthetic time (t = pose index, 1 s
    per pose) and the truth. Landmark-reading noise comes from the file's square-root
    information (all lines share one: ``R = diag(10, 10)``, i.e. σ = 0.1 m); the odometry noise
    of ``(dx, dy, dth)`` is converted to the ``(rot1, trans, rot2)`` covariance of
    :class:`~slamkit.models.OdometryModel` to first order at a straight step of the median
    step length. ``seed`` only shuffles readings when ``identities`` is False.
    """
    opts = config_from_mapping(CityTreesOptions, options, "dataset citytrees10000")
    noisy_path = require_file(CITYTREES_FILES[0], data_root)
    truth_path = require_file(CITYTREES_FILES[1], data_root)
    noisy = read_isam_landmark_graph(noisy_path)
    exact = read_isam_landmark_graph(truth_path)

    n_poses = noisy.edge_ids.shape[0] + 1
    _same_rows(noisy, exact, "EDGE2", noisy.edge_ids, exact.edge_ids)
    odom = _chain(noisy, n_poses)
    true_poses = _chain(exact, n_poses)
    # Readings: sensor noise, pose indices in range, the same sightings in both files.
    lm_sqrt, lm_cov, edge_sqrt, edge_cov = _noise(noisy)
    _check_pose_refs(noisy, n_poses)
    _same_rows(noisy, exact, "LANDMARK", noisy.landmark_ids, exact.landmark_ids)
    lm_ids, centre, spread, coincident = _true_landmarks(noisy, exact, true_poses)
    rng = np.random.default_rng(seed)
    readings = _readings(noisy, n_poses, opts.identities, rng)
    odometry = odometry_events(np.arange(n_poses, dtype=np.float64), odom)
    return Dataset(
        name="citytrees10000",
        events=assemble_events(odometry, readings),
        motion=MotionSpec(OdometryModel(), _odometry_cov(noisy, edge_cov), source="odometry"),
        landmark_sensor=LandmarkSensorSpec("position", lm_cov, identities=opts.identities),
        initial_pose=np.zeros(3),
        initial_cov=np.zeros((3, 3)),
        truth=GroundTruth(
            times=np.arange(n_poses, dtype=np.float64),
            poses=true_poses,
            landmarks=LandmarkMap(centre, lm_ids.astype(np.int64)),
        ),
        description=(
            "iSAM cityTrees10000 (simulated): 10000 poses, 100 landmarks, 4443 robot-frame "
            "landmark readings, noisy odometry"
        ),
        metadata={
            "kind": "real",
            "format": "isam",
            "files": list(CITYTREES_FILES),
            "time": "synthetic: t = pose index, 1 s per pose",
            "poses": n_poses,
            "landmarks": int(lm_ids.size),
            "landmark_readings": int(noisy.landmark_ids.shape[0]),
            "landmark_sqrt_information": lm_sqrt.tolist(),
            "landmark_noise_cov": lm_cov.tolist(),
            "odometry_sqrt_information": edge_sqrt.tolist(),
            "odometry_noise_cov_dx_dy_dth": edge_cov.tolist(),
            "truth_landmark_spread_m": spread,
            "coincident_landmark_ids": coincident,
            "identities": opts.identities,
        },
    )


def _noise(noisy: IsamLandmarkGraph) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The one square-root information (and covariance) of the readings and of the
    odometry edges of the file."""
    path = noisy.path
    lm_sqrt = _uniform_noise(noisy.landmark_sqrt_info, noisy.landmark_lines, "LANDMARK", path)
    try:
        lm_cov = sqrt_information_to_covariance(lm_sqrt, 2)
        edge_sqrt = _uniform_noise(noisy.edge_sqrt_info, noisy.edge_lines, "EDGE2", path)
        edge_cov = sqrt_information_to_covariance(edge_sqrt, 3)
    except ValueError as exc:
        raise DatasetFormatError(str(exc), path) from None
    return lm_sqrt, lm_cov, edge_sqrt, edge_cov


def _check_pose_refs(noisy: IsamLandmarkGraph, n_poses: int) -> None:
    pose_of = noisy.landmark_ids[:, 0]
    if np.any(pose_of >= n_poses):
        k = int(np.flatnonzero(pose_of >= n_poses)[0])
        raise DatasetFormatError(
            f"LANDMARK: pose {pose_of[k]} does not exist (poses 0..{n_poses - 1})",
            noisy.path,
            int(noisy.landmark_lines[k]),
        )


def _true_landmarks(
    noisy: IsamLandmarkGraph, exact: IsamLandmarkGraph, true_poses: FloatArray
) -> tuple[NDArray[np.int64], FloatArray, float, list[list[int]]]:
    """The true landmarks: the mean of each landmark's noise-free sightings in the world
    frame (ids, positions ``(M, 2)``), the largest spread of a sighting from its mean [m],
    and the pairs of ids at one position."""
    seen = pose2.transform_points(true_poses[noisy.landmark_ids[:, 0]], exact.landmark_z)
    lm_ids, inverse = np.unique(noisy.landmark_ids[:, 1], return_inverse=True)
    counts = np.bincount(inverse)
    centre = np.stack(
        [np.bincount(inverse, seen[:, d]) / counts for d in range(2)], axis=-1
    )  # (M, 2)
    spread = float(np.max(np.hypot(*(seen - centre[inverse]).T)))
    # The file holds pairs of landmark ids at one position (read together at every
    # sighting); association cannot tell them apart, so they are listed for the user.
    gap = np.hypot(*(centre[:, None, :] - centre[None, :, :]).transpose(2, 0, 1))
    first, second = np.nonzero(np.triu(gap < 1e-9, k=1))
    coincident = np.column_stack([lm_ids[first], lm_ids[second]]).astype(int).tolist()
    return lm_ids, centre, spread, coincident


def _odometry_cov(noisy: IsamLandmarkGraph, edge_cov: FloatArray) -> FloatArray:
    """Odometry noise ``(dx, dy, dth)`` → ``(rot1, trans, rot2)`` at a straight step of the
    median length d: rot1 ≈ dy/d, trans ≈ dx, rot2 = dth − rot1."""
    d = float(np.median(np.hypot(noisy.edge_z[:, 0], noisy.edge_z[:, 1])))
    J = np.array([[0.0, 1.0 / d, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0 / d, 1.0]])
    out: FloatArray = J @ edge_cov @ J.T
    return out


def _readings(
    noisy: IsamLandmarkGraph, n_poses: int, identities: bool, rng: np.random.Generator
) -> list[LandmarkReadings]:
    """The readings of each pose at its stamp (t = pose index); without ``identities``
    each pose's readings shuffled by ``rng`` (pose by pose) and their ids -1."""
    pose_of = noisy.landmark_ids[:, 0]
    order = np.argsort(pose_of, kind="stable")
    if not identities:
        starts = np.searchsorted(pose_of[order], np.arange(n_poses + 1))
        for k in range(n_poses):
            if starts[k + 1] > starts[k]:
                rows = order[starts[k] : starts[k + 1]]
                order[starts[k] : starts[k + 1]] = rows[rng.permutation(rows.size)]
    ids = noisy.landmark_ids[order, 1] if identities else np.full(order.size, -1, np.int64)
    return reading_events(pose_of[order].astype(np.float64), noisy.landmark_z[order], ids)
