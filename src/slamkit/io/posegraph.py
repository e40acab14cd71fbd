"""Pose-graph and landmark-graph files: g2o, TORO/hog-man, iSAM and GTSAM's Victoria Park.

:func:`read_graph` turns a file into a :class:`~slamkit.optim.data.GraphData` in slamkit's
conventions (2D poses ``(x, y, θ)``, 3D poses ``(x, y, z, qw, qx, qy, qz)``, full symmetric
*information* matrices in tangent order ``(x, y, θ)`` / ``(x, y, z, rx, ry, rz)``);
:func:`write_graph` writes one back in its family, atomically. The family is detected from
the tags and the file name (:func:`detect_graph_family`) or given as ``family=``.

======  ===========================================================================
family  lines read (→ edge kind) and what their noise fields are
======  ===========================================================================
g2o     ``VERTEX_SE2 id x y θ``; ``VERTEX_XY id x y``; ``VERTEX_SE3:QUAT id x y z qx qy
        qz qw``; ``EDGE_SE2 i j dx dy dθ`` + 6 (→ se2); ``EDGE_SE2_XY i j x y`` + 3 (→
        se2_xy); ``EDGE_PRIOR_SE2 i x y θ`` + 6 (→ se2_prior); ``EDGE_SE3:QUAT i j x y z
        qx qy qz qw`` + 21 (→ se3); ``FIX id …``. Noise: upper triangle of the
        information, row-major, in the order of the measurement's tangent.
toro    ``VERTEX2 id x y θ``; ``EDGE2 i j dx dy dθ Ixx Ixy Iyy Itt Ixt Iyt`` (→ se2;
        TORO's order, converted); ``EQUIV a b``; ``BR pose landmark bearing range
        σ_bearing σ_range`` (→ range_bearing, measurement ``(range, bearing)``,
        information ``diag(1/σ_r², 1/σ_b²)``); hog-man 3D ``VERTEX3 id x y z roll pitch
        yaw`` and ``EDGE3 i j x y z roll pitch yaw`` + 21 information entries (→ se3).
isam    ``EDGE2``/``ODOMETRY i j dx dy dθ`` + 6 (→ se2); ``LANDMARK pose lm x y`` + 3
        (→ se2_xy, the landmark in the robot frame); ``EDGE3 i j x y z roll pitch yaw``
        + 21 (→ se3). Noise: upper-triangular square-root information ``R``,
        information ``RᵀR``. No vertex lines: ``poses`` is empty, and pose ids and
        landmark ids are separate number spaces (edges keep both as written).
gtsam   iSAM's 2D lines (``EDGE2``/``ODOMETRY``, ``LANDMARK``) whose noise fields are
        the upper triangle of the *covariance* (information = its inverse), as in
        GTSAM's ``victoria_park.txt``; also ``BR`` as above.
======  ===========================================================================

Decisions
---------
* **Roll-pitch-yaw** (hog-man and iSAM ``EDGE3``/``VERTEX3``) is ``R = Rz(yaw) Ry(pitch)
  Rx(roll)``: chaining iSAM's noise-free ``sphere2500_groundtruth.txt`` with it closes every
  loop to the printed precision (the reversed order misses by 0.17 rad). The angles are
  stored as a unit quaternion with ``qw >= 0``.
* **iSAM's 3D information order.** iSAM's loader reads ``x y z roll pitch yaw`` and the 21
  square-root entries in that same order (it reorders both to its internal yaw-pitch-roll
  together), so ``RᵀR`` is indexed ``(x, y, z, roll, pitch, yaw)``. slamkit takes that
  matrix as is for ``(x, y, z, rx, ry, rz)`` — roll about x, pitch about y, yaw about z —
  with no Jacobian: for a body-frame rotation error ``δ`` the Euler-angle error is
  ``J δ`` with ``J = I + O(|roll| + |pitch|)`` of the measured rotation, so the identity is
  exact to first order for the small relative roll and pitch of odometry (as on the sphere
  data set), and it keeps reading and writing free of linearisation points. hog-man's
  ``EDGE3`` information is read the same way. The same holds in 2D: files give the noise in
  the parameters of the measurement (``dx dy dθ``), and so does ``GraphData``.
* **Quaternions** of g2o files are kept exactly as written (lossless round trips); their
  norm must be within :data:`~slamkit.io.graphfiles.families.QUAT_NORM_TOL` (1e-3) of one,
  and consumers normalise.
* **Unknown tags** are an error naming the file and line. ``lenient=True`` skips their lines
  and counts them: :func:`read_graph_report` returns the counts per tag; :func:`read_graph`
  drops them. Malformed lines of known tags are errors either way.
* **Information** must be symmetric positive definite after conversion: smallest eigenvalue
  above ``1e-12`` times the largest (:data:`~slamkit.io.graphfiles.families.PD_RTOL`).
  ``repair_information="clamp"`` repairs the matrices that are not instead, never silently:
  each one is clamped to eigenvalues ``≥ 1e-6 λ_max`` (:mod:`slamkit.optim.repair`),
  :func:`read_graph_report` lists every one (line, tag, eigenvalues) and a
  :class:`RepairWarning` gives the count and the first lines.
* **Round trips.** Numbers are written with ``repr``. g2o and TORO data (a permutation)
  round-trip bit for bit. iSAM's ``RᵀR`` is written back as its Cholesky factor, GTSAM's
  covariance as an inverse, ``BR`` as ``1/sqrt``, and Euler angles through the quaternion:
  these come back equal to a few units in the last place (diagonal square-root information
  exactly), and a file's ``R`` with negative diagonal entries comes back with positive ones.
  Measured on the public files: every array comes back bit for bit, except the quaternions
  of iSAM's ``sphere2500.txt`` (Euler angles), which are off by at most one unit in the last
  place.
* **Not read**: iSAM's short ``EDGE3`` (no noise fields), ``POINT3``/stereo lines, g2o's
  parameter-based types (``EDGE_SE3_PRIOR``, ``PARAMS_*``) — unknown tags, see above.
* **Tags written**: the first tag of each kind in the table (iSAM/GTSAM ``ODOMETRY`` lines
  come back as the equivalent ``EDGE2``); vertices first, then ``FIX``, the edges in the
  file's interleaving (``GraphData.edge_order``), then ``EQUIV``.
* **Lossless or nothing.** The writer refuses what a family cannot hold (vertices in an
  iSAM file, ``FIX`` outside g2o, ``EQUIV`` outside TORO, a kind with no tag) instead of
  dropping it.
"""

from __future__ import annotations

import gzip
import os
import tempfile
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from slamkit.datasets.text import read_text
from slamkit.errors import InputError
from slamkit.io.graphfiles.families import FILE_FAMILIES, detect_family, family_for_suffix
from slamkit.io.graphfiles.reader import (
    RepairedEdge,
    RepairMode,
    group_lines,
    parse_graph_text,
)
from slamkit.io.graphfiles.writer import format_graph_text
from slamkit.optim.data import GraphData, GraphFamily

__all__ = [
    "GraphReadReport",
    "RepairWarning",
    "RepairedEdge",
    "detect_graph_family",
    "format_graph",
    "read_graph",
    "read_graph_report",
    "repair_summary",
    "write_graph",
]


@dataclass(frozen=True)
class GraphReadReport:
    """A graph file as read, and what a lenient read skipped."""

    graph: GraphData
    family: GraphFamily
    skipped_tags: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    """How many lines of each unknown tag were skipped (empty for a strict read)."""
    skipped_lines: tuple[int, ...] = ()
    """The first 20 skipped line numbers."""
    repaired: tuple[RepairedEdge, ...] = ()
    """Every edge whose information matrix was repaired (``repair_information="clamp"``),
    in line order."""

    @property
    def skipped(self) -> int:
        """How many lines were skipped in all."""
        return sum(self.skipped_tags.values())


class RepairWarning(UserWarning):
    """Information matrices of a graph file were repaired (``repair_information="clamp"``)."""


def repair_summary(path: Path | str, repaired: tuple[RepairedEdge, ...], first: int = 5) -> str:
    """One sentence: how many information matrices of ``path`` were repaired, and the first
    ``first`` of them as ``file:line`` with their smallest eigenvalue."""
    shown = ", ".join(
        f"{path}:{r.line} ({r.tag}, smallest eigenvalue {r.eigenvalue_min:.3g})"
        for r in repaired[:first]
    )
    more = f" and {len(repaired) - first} more" if len(repaired) > first else ""
    return (
        f"{len(repaired)} information matrices were not positive definite and were "
        f"repaired by eigenvalue clamping: {shown}{more}"
    )


def _check_family(family: str | None) -> GraphFamily | None:
    if family is not None and family not in FILE_FAMILIES:
        raise InputError(f"family: expected one of {', '.join(FILE_FAMILIES)}, got {family!r}")
    return family


def read_graph_report(
    path: str | os.PathLike[str],
    *,
    family: GraphFamily | None = None,
    lenient: bool = False,
    repair_information: RepairMode = "none",
) -> GraphReadReport:
    """Read a graph file (``.gz``: gzip) and report what a lenient read skipped and what
    ``repair_information="clamp"`` repaired (then also a :class:`RepairWarning`).

    Raises :class:`~slamkit.errors.DatasetFormatError` naming the file and the first bad line,
    :class:`~slamkit.errors.DataNotFoundError` when the file is missing.
    """
    fam = _check_family(family)
    p = Path(path)
    parsed = parse_graph_text(
        read_text(p), p, family=fam, lenient=lenient, repair_information=repair_information
    )
    if parsed.repaired:
        warnings.warn(repair_summary(p, parsed.repaired), RepairWarning, stacklevel=2)
    return GraphReadReport(
        parsed.graph,
        parsed.family,
        MappingProxyType(parsed.skipped_tags),
        parsed.skipped_lines,
        parsed.repaired,
    )


def read_graph(
    path: str | os.PathLike[str],
    *,
    family: GraphFamily | None = None,
    lenient: bool = False,
    repair_information: RepairMode = "none",
) -> GraphData:
    """Read a graph file into slamkit's conventions (see the module docstring);
    ``repair_information="clamp"`` repairs information matrices that are not positive
    definite (with a :class:`RepairWarning`; :func:`read_graph_report` lists them)."""
    return read_graph_report(
        path, family=family, lenient=lenient, repair_information=repair_information
    ).graph


def detect_graph_family(path: str | os.PathLike[str]) -> GraphFamily:
    """The family :func:`read_graph` would read ``path`` as (from its tags and its name)."""
    p = Path(path)
    base = p.with_suffix("") if p.suffix == ".gz" else p
    return detect_family(list(group_lines(read_text(p))), base.suffix, base.stem)


def _write_family(graph: GraphData, path: Path | None, family: str | None) -> GraphFamily:
    fam = _check_family(family)
    if fam is not None:
        return fam
    if graph.family in FILE_FAMILIES:
        return graph.family
    if path is not None:
        base = path.with_suffix("") if path.suffix == ".gz" else path
        by_name = family_for_suffix(base.suffix) or (
            "isam" if base.suffix.lower() == ".txt" else None
        )
        if by_name is not None:
            return by_name
    raise InputError(
        f"a graph of family {graph.family!r} needs family= (one of {', '.join(FILE_FAMILIES)})"
        + ("" if path is None else " or a file name ending in .g2o, .graph or .txt")
    )


def format_graph(graph: GraphData, *, family: GraphFamily | None = None) -> str:
    """The text of ``graph`` in ``family`` (default: the family it was read from)."""
    return format_graph_text(graph, _write_family(graph, None, family))


def _new_file_mode(path: Path) -> int:
    """The mode a plainly created file would get (mkstemp makes 0600)."""
    try:
        return path.stat().st_mode & 0o777
    except FileNotFoundError:
        umask = os.umask(0o022)
        os.umask(umask)
        return 0o666 & ~umask


def write_graph(
    graph: GraphData,
    path: str | os.PathLike[str],
    *,
    family: GraphFamily | None = None,
) -> Path:
    """Write ``graph`` to ``path`` (``.gz``: gzip) and return the path.

    The family is ``family``, else the one the graph was read from, else the one the file
    name names (``.g2o``, ``.graph``, ``.txt`` → iSAM). The text is formatted and validated
    completely first, written to a temporary file beside ``path`` and renamed over it, so
    ``path`` is never left partly written.
    """
    p = Path(path)
    text = format_graph_text(graph, _write_family(graph, p, family))
    data = text.encode("utf-8")
    if p.suffix == ".gz":
        data = gzip.compress(data, mtime=0)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".partial", dir=p.parent)
    try:
        os.chmod(tmp, _new_file_mode(p))
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p
