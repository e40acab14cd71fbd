"""What each line of each graph-file family holds: one spec per tag, and family detection.

A :class:`VertexSpec` or :class:`EdgeSpec` says how many integer ids and numbers follow the
tag and how to turn those numbers into slamkit's variables, measurements and information
matrices (``decode``) and back (``encode``), using the converters of
:mod:`.conventions` only. ``check`` functions look at the raw numbers of a whole tag group
before decoding and return the first bad row with a message (quaternion norms, standard
deviations, covariances); the reader adds the checks every family shares (ids, positive
definite information, references).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal, NamedTuple

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.io.graphfiles import conventions as cv
from slamkit.optim.data import EdgeKind, GraphFamily

__all__ = [
    "FAMILIES",
    "FILE_FAMILIES",
    "LANDMARK_KINDS",
    "PD_RTOL",
    "POSE_PAIR_KINDS",
    "PRIOR_KINDS",
    "QUAT_NORM_TOL",
    "EdgeSpec",
    "FamilySpec",
    "VertexSpec",
    "detect_family",
    "family_for_suffix",
]

QUAT_NORM_TOL = 1e-3
"""How far from one the norm of a file's quaternion may be. Files print 6–7 digits (the
public 3D data sets are within 8e-7 of one); a larger error means a broken line. The values
are kept as written (lossless round trips); consumers normalise."""

FILE_FAMILIES: tuple[GraphFamily, ...] = ("g2o", "toro", "isam", "gtsam")

#: Edge kinds whose ``i`` and ``j`` are both poses.
POSE_PAIR_KINDS: frozenset[str] = frozenset({"se2", "se3"})
#: Unary edge kinds (``j = -1``).
PRIOR_KINDS: frozenset[str] = frozenset({"se2_prior", "se3_prior"})
#: Edge kinds from a pose ``i`` to a landmark ``j``.
LANDMARK_KINDS: frozenset[str] = frozenset({"se2_xy", "range_bearing", "range", "bearing"})

RowProblem = tuple[int, str] | None
Check = Callable[[FloatArray], RowProblem]
Decode = Callable[[FloatArray], tuple[FloatArray, FloatArray]]
Encode = Callable[[FloatArray, FloatArray], FloatArray]

PD_RTOL = 1e-12
"""A matrix counts as positive definite when its smallest eigenvalue exceeds this fraction
of its largest (a condition number below 1e12): exact zeros, negative entries on the
diagonal and rank-deficient matrices are caught, rounding errors are not flagged."""


class Codec(NamedTuple):
    """File numbers of an edge line ↔ (measurement, information)."""

    decode: Decode
    encode: Encode


@dataclass(frozen=True)
class VertexSpec:
    """A vertex line ``TAG id v1 … vn``."""

    tag: str
    role: Literal["pose", "landmark"]
    dim: Literal[2, 3]
    n_values: int
    decode: Callable[[FloatArray], FloatArray]  # (V, n_values) → (V, 3 | 7 | 2)
    encode: Callable[[FloatArray], FloatArray]  # the inverse
    check: Check | None = None


@dataclass(frozen=True)
class EdgeSpec:
    """An edge line ``TAG i [j] v1 … vn`` (``n_ids`` = 1 for unary edges)."""

    tag: str
    kind: EdgeKind
    dim: Literal[2, 3]
    n_ids: Literal[1, 2]
    n_values: int
    noise: str  # what the noise fields are, for messages
    decode: Decode  # values → (measurement, information)
    encode: Encode  # (measurement, information) → values
    check: Check | None = None


@dataclass(frozen=True)
class FamilySpec:
    """The tags a family reads and the ones its writer uses."""

    name: GraphFamily
    title: str
    vertices: Mapping[str, VertexSpec]
    edges: Mapping[str, EdgeSpec]
    fix_tag: str | None = None
    equiv_tag: str | None = None
    write_edge: Mapping[str, EdgeSpec] = field(default_factory=dict)  # kind → spec

    @property
    def known_tags(self) -> frozenset[str]:
        tags = set(self.vertices) | set(self.edges)
        tags |= {t for t in (self.fix_tag, self.equiv_tag) if t is not None}
        return frozenset(tags)

    def pose_vertex(self, dim: int) -> VertexSpec | None:
        for v in self.vertices.values():
            if v.role == "pose" and v.dim == dim:
                return v
        return None

    def landmark_vertex(self) -> VertexSpec | None:
        for v in self.vertices.values():
            if v.role == "landmark":
                return v
        return None


# ------------------------------------------------------------------------------ checks


def _first(bad: np.ndarray | np.bool_, message: Callable[[int], str]) -> RowProblem:
    rows = np.flatnonzero(bad)
    if rows.size == 0:
        return None
    r = int(rows[0])
    return r, message(r)


def _quat_check(start: int) -> Check:
    """Columns ``start:start+4`` hold a quaternion whose norm must be near one."""

    def check(values: FloatArray) -> RowProblem:
        norm = np.linalg.norm(values[:, start : start + 4], axis=1)
        return _first(
            np.abs(norm - 1.0) > QUAT_NORM_TOL,
            lambda r: f"quaternion norm {norm[r]:.6g}, expected 1 (within {QUAT_NORM_TOL:g})",
        )

    return check


def _sigma_check(start: int, names: tuple[str, ...]) -> Check:
    def check(values: FloatArray) -> RowProblem:
        sig = values[:, start : start + len(names)]
        bad = ~(sig > 0.0).all(axis=1)

        def message(r: int) -> str:
            k = int(np.flatnonzero(~(sig[r] > 0.0))[0])
            return f"standard deviation {names[k]} = {float(sig[r, k])!r}, expected > 0"

        return _first(bad, message)

    return check


def _covariance_check(start: int, n: int) -> Check:
    def check(values: FloatArray) -> RowProblem:
        cov = cv.upper_to_symmetric(values[:, start : start + cv.triangle_size(n)], n)
        eig = np.linalg.eigvalsh(cov) if len(cov) else np.zeros((0, n))
        bad = ~(eig[:, 0] > PD_RTOL * eig[:, -1])
        return _first(
            bad,
            lambda r: (
                "covariance is not positive definite "
                f"(eigenvalues from {eig[r, 0]:.3g} to {eig[r, -1]:.3g})"
            ),
        )

    return check


# ------------------------------------------------------------------------ vertex codecs


def _same(v: FloatArray) -> FloatArray:
    return np.ascontiguousarray(v)


def _se3quat_from_file(v: FloatArray) -> FloatArray:
    return np.concatenate([v[:, :3], cv.xyzw_to_wxyz(v[:, 3:7])], axis=1)


def _se3quat_to_file(p: FloatArray) -> FloatArray:
    return np.concatenate([p[:, :3], cv.wxyz_to_xyzw(p[:, 3:7])], axis=1)


def _se3rpy_from_file(v: FloatArray) -> FloatArray:
    return np.concatenate([v[:, :3], cv.rpy_to_quat(v[:, 3:6])], axis=1)


def _se3rpy_to_file(p: FloatArray) -> FloatArray:
    return np.concatenate([p[:, :3], cv.quat_to_rpy(p[:, 3:7])], axis=1)


# -------------------------------------------------------------------------- edge codecs
# Each pair: decode(values) → (measurement, information); encode(measurement, information).


def _info_upper(n: int, m: int) -> Codec:
    """``m`` measurement numbers, then the upper triangle of the ``n × n`` information."""

    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.ascontiguousarray(v[:, :m]), cv.upper_to_symmetric(v[:, m:], n)

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        return np.concatenate([z, cv.symmetric_to_upper(info)], axis=1)

    return Codec(decode, encode)


def _info_toro2d() -> Codec:
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        upper = v[:, 3:][:, cv.UPPER_FROM_TORO2D]
        return np.ascontiguousarray(v[:, :3]), cv.upper_to_symmetric(upper, 3)

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        return np.concatenate([z, cv.symmetric_to_upper(info)[:, cv.TORO2D_FROM_UPPER]], axis=1)

    return Codec(decode, encode)


def _sqrt_info(n: int, m: int) -> Codec:
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.ascontiguousarray(v[:, :m]), cv.sqrt_information_to_information(v[:, m:], n)

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        return np.concatenate([z, cv.information_to_sqrt_information(info)], axis=1)

    return Codec(decode, encode)


def _covariance(n: int, m: int) -> Codec:
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.ascontiguousarray(v[:, :m]), cv.covariance_to_information(v[:, m:], n)

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        return np.concatenate([z, cv.information_to_covariance(info)], axis=1)

    return Codec(decode, encode)


def _se3_quat_edge() -> Codec:
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _se3quat_from_file(v[:, :7]), cv.upper_to_symmetric(v[:, 7:], 6)

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        return np.concatenate([_se3quat_to_file(z), cv.symmetric_to_upper(info)], axis=1)

    return Codec(decode, encode)


def _se3_rpy_edge(sqrt: bool) -> Codec:
    # The 6x6 matrix is in the file's order (x, y, z, roll, pitch, yaw), taken as slamkit's
    # (x, y, z, rx, ry, rz): see the module docstring of slamkit.io.posegraph for why.
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        info = (
            cv.sqrt_information_to_information(v[:, 6:], 6)
            if sqrt
            else cv.upper_to_symmetric(v[:, 6:], 6)
        )
        return _se3rpy_from_file(v[:, :6]), info

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        noise = cv.information_to_sqrt_information(info) if sqrt else cv.symmetric_to_upper(info)
        return np.concatenate([_se3rpy_to_file(z), noise], axis=1)

    return Codec(decode, encode)


def _bearing_range() -> Codec:
    # File: bearing range sigma_bearing sigma_range; slamkit: (range, bearing), diag(1/σ²).
    def decode(v: FloatArray) -> tuple[FloatArray, FloatArray]:
        z = np.ascontiguousarray(v[:, [1, 0]])
        return z, cv.sigmas_to_information(v[:, [3, 2]])

    def encode(z: FloatArray, info: FloatArray) -> FloatArray:
        off = np.abs(info[:, 0, 1]) + np.abs(info[:, 1, 0])
        rows = np.flatnonzero(off != 0.0)
        if rows.size:
            raise InputError(
                f"range_bearing edge {int(rows[0])}: a BR line holds two standard deviations, "
                "so the information must be diagonal"
            )
        sig = cv.information_to_sigmas(info)
        return np.column_stack([z[:, 1], z[:, 0], sig[:, 1], sig[:, 0]])

    return Codec(decode, encode)


def _edge(
    tag: str,
    kind: EdgeKind,
    dim: Literal[2, 3],
    n_values: int,
    noise: str,
    codec: Codec,
    *,
    n_ids: Literal[1, 2] = 2,
    check: Check | None = None,
) -> EdgeSpec:
    return EdgeSpec(tag, kind, dim, n_ids, n_values, noise, codec.decode, codec.encode, check)


# ----------------------------------------------------------------------------- families

_VERTEX_SE2 = VertexSpec("VERTEX_SE2", "pose", 2, 3, _same, _same)
_VERTEX_XY = VertexSpec("VERTEX_XY", "landmark", 2, 2, _same, _same)
_VERTEX_SE3 = VertexSpec(
    "VERTEX_SE3:QUAT", "pose", 3, 7, _se3quat_from_file, _se3quat_to_file, _quat_check(3)
)
_G2O_EDGES = (
    _edge("EDGE_SE2", "se2", 2, 9, "information", _info_upper(3, 3)),
    _edge("EDGE_SE2_XY", "se2_xy", 2, 5, "information", _info_upper(2, 2)),
    _edge("EDGE_PRIOR_SE2", "se2_prior", 2, 9, "information", _info_upper(3, 3), n_ids=1),
    _edge("EDGE_SE3:QUAT", "se3", 3, 28, "information", _se3_quat_edge(), check=_quat_check(3)),
)

_VERTEX2 = VertexSpec("VERTEX2", "pose", 2, 3, _same, _same)
_VERTEX3 = VertexSpec("VERTEX3", "pose", 3, 6, _se3rpy_from_file, _se3rpy_to_file)
_BR = _edge(
    "BR",
    "range_bearing",
    2,
    4,
    "standard deviations",
    _bearing_range(),
    check=_sigma_check(2, ("sigma_bearing", "sigma_range")),
)
_TORO_EDGES = (
    _edge("EDGE2", "se2", 2, 9, "information (TORO order)", _info_toro2d()),
    _edge("EDGE3", "se3", 3, 27, "information", _se3_rpy_edge(sqrt=False)),
    _BR,
)

_ISAM_EDGE2 = _edge("EDGE2", "se2", 2, 9, "square-root information", _sqrt_info(3, 3))
_ISAM_EDGES = (
    _ISAM_EDGE2,
    _edge("ODOMETRY", "se2", 2, 9, "square-root information", _sqrt_info(3, 3)),
    _edge("LANDMARK", "se2_xy", 2, 5, "square-root information", _sqrt_info(2, 2)),
    _edge("EDGE3", "se3", 3, 27, "square-root information", _se3_rpy_edge(sqrt=True)),
)

_GTSAM_EDGES = (
    _edge("EDGE2", "se2", 2, 9, "covariance", _covariance(3, 3), check=_covariance_check(3, 3)),
    _edge("ODOMETRY", "se2", 2, 9, "covariance", _covariance(3, 3), check=_covariance_check(3, 3)),
    _edge(
        "LANDMARK", "se2_xy", 2, 5, "covariance", _covariance(2, 2), check=_covariance_check(2, 2)
    ),
    _BR,
)


def _family(
    name: GraphFamily,
    title: str,
    vertices: tuple[VertexSpec, ...],
    edges: tuple[EdgeSpec, ...],
    *,
    fix_tag: str | None = None,
    equiv_tag: str | None = None,
) -> FamilySpec:
    write_edge: dict[str, EdgeSpec] = {}
    for e in edges:
        write_edge.setdefault(e.kind, e)  # the first tag of a kind is the one written
    return FamilySpec(
        name=name,
        title=title,
        vertices=MappingProxyType({v.tag: v for v in vertices}),
        edges=MappingProxyType({e.tag: e for e in edges}),
        fix_tag=fix_tag,
        equiv_tag=equiv_tag,
        write_edge=MappingProxyType(write_edge),
    )


FAMILIES: Mapping[str, FamilySpec] = MappingProxyType(
    {
        "g2o": _family(
            "g2o", "g2o", (_VERTEX_SE2, _VERTEX_XY, _VERTEX_SE3), _G2O_EDGES, fix_tag="FIX"
        ),
        "toro": _family(
            "toro", "TORO/hog-man", (_VERTEX2, _VERTEX3), _TORO_EDGES, equiv_tag="EQUIV"
        ),
        "isam": _family("isam", "iSAM", (), _ISAM_EDGES),
        "gtsam": _family("gtsam", "GTSAM (covariances)", (), _GTSAM_EDGES),
    }
)

# Tags that only one family uses decide the family; EDGE2/EDGE3 are TORO's and iSAM's.
_DECISIVE: Mapping[str, str] = MappingProxyType(
    {
        **dict.fromkeys(
            ("VERTEX_SE2", "VERTEX_XY", "VERTEX_SE3:QUAT", "EDGE_SE2", "EDGE_SE2_XY"), "g2o"
        ),
        **dict.fromkeys(("EDGE_PRIOR_SE2", "EDGE_SE3:QUAT", "FIX"), "g2o"),
        **dict.fromkeys(("VERTEX2", "VERTEX3", "EQUIV", "BR"), "toro"),
        **dict.fromkeys(("ODOMETRY", "LANDMARK"), "isam"),
    }
)


def family_for_suffix(suffix: str) -> GraphFamily | None:
    """The family a file name suffix names (``.g2o``, ``.graph``), else ``None``."""
    return {".g2o": "g2o", ".graph": "toro"}.get(suffix.lower())  # type: ignore[return-value]


def detect_family(tags_in_order: list[str], suffix: str, stem: str) -> GraphFamily:
    """The family of a file from its tags (in order of first appearance) and its name.

    The first tag that only one family uses decides (``VERTEX_SE2`` → g2o, ``VERTEX2`` →
    TORO, ``ODOMETRY`` → iSAM, …). A file with only ``EDGE2``/``EDGE3`` lines is TORO when
    named ``*.graph`` and iSAM otherwise. iSAM-style files whose name contains ``gtsam`` are
    read as the GTSAM variant (covariances); pass ``family="gtsam"`` for any other name.
    """
    decided: str | None = None
    for tag in tags_in_order:
        if tag in _DECISIVE:
            decided = _DECISIVE[tag]
            break
    if decided is None:
        decided = family_for_suffix(suffix) or "isam"
    if decided == "isam" and "gtsam" in stem.lower():
        decided = "gtsam"
    return decided  # type: ignore[return-value]
