"""Format a :class:`~slamkit.optim.data.GraphData` as the text of a graph file.

The graph is validated first (it may have been built in memory): shapes, finite numbers,
integer ids, symmetric positive definite information, unit quaternions (within
:data:`~slamkit.io.graphfiles.families.QUAT_NORM_TOL`), a valid ``edge_order``, and that the
family can hold everything the graph has — nothing is dropped silently.

Layout: pose vertices, landmark vertices, ``FIX`` lines, edges (in ``edge_order``, else set
after set), ``EQUIV`` lines. Numbers are written with Python's ``repr`` (the shortest text
that reads back to the same float), so a file that needs no conversion round-trips bit for
bit.
"""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import CovarianceError, InputError, NonFiniteError, ShapeError
from slamkit.io.graphfiles.families import (
    FAMILIES,
    PD_RTOL,
    PRIOR_KINDS,
    QUAT_NORM_TOL,
    FamilySpec,
)
from slamkit.optim.data import EdgeSet, GraphData, GraphFamily, IntArray

__all__ = ["format_graph_text"]

_MEASUREMENT = {
    "se2": 3,
    "se3": 7,
    "se2_prior": 3,
    "se3_prior": 7,
    "se2_xy": 2,
    "range_bearing": 2,
    "range": 1,
    "bearing": 1,
}
_RANK = {"se2": 3, "se3": 6, "se2_prior": 3, "se3_prior": 6, "se2_xy": 2, "range_bearing": 2}
_RANK |= {"range": 1, "bearing": 1}


def format_graph_text(graph: GraphData, family: GraphFamily) -> str:
    """The text of ``graph`` as a file of ``family`` (validated; see the module docstring)."""
    if family not in FAMILIES:
        raise InputError(
            f"family: expected one of {', '.join(FAMILIES)}, got {family!r} "
            "(a graph built in memory needs a file family to be written)"
        )
    spec = FAMILIES[family]
    if graph.dim not in (2, 3):
        raise InputError(f"graph.dim: expected 2 or 3, got {graph.dim!r}")
    out: list[str] = []
    out += _vertex_lines(graph, spec)
    out += _fix_lines(graph, spec)
    out += _edge_lines(graph, spec)
    out += _equiv_lines(graph, spec)
    return "\n".join(out) + "\n" if out else ""


# ------------------------------------------------------------------------------ checks


def _ids(values: object, name: str, shape: tuple[int | None, ...]) -> IntArray:
    a = np.asarray(values)
    if a.dtype.kind not in "iu" and not (a.size == 0 and a.dtype.kind == "f"):
        raise ShapeError(f"{name}: expected integer ids, got dtype {a.dtype}")
    if a.ndim != len(shape) or any(
        s is not None and s != d for s, d in zip(shape, a.shape, strict=True)
    ):
        raise ShapeError(f"{name}: expected shape {shape}, got {a.shape}")
    return a.astype(np.int64)


def _floats(values: object, name: str, shape: tuple[int, ...]) -> FloatArray:
    a = np.asarray(values, dtype=np.float64)
    if a.shape != shape:
        raise ShapeError(f"{name}: expected shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise NonFiniteError(f"{name}: expected finite numbers, got NaN/inf")
    return a


def _nonnegative(ids: IntArray, name: str) -> None:
    if ids.size and ids.min() < 0:
        raise InputError(f"{name}: expected non-negative ids, got {int(ids.min())}")


def _check_quaternions(q: FloatArray, name: str) -> None:
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        r = int(bad[0])
        raise InputError(f"{name}[{r}]: quaternion norm {norm[r]:.6g}, expected 1")


def _check_information(info: FloatArray, name: str) -> None:
    scale = np.maximum(np.abs(info).max(axis=(1, 2)), 1e-300)
    asym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2)) > 1e-12 * scale
    if asym.any():
        r = int(np.flatnonzero(asym)[0])
        raise CovarianceError(f"{name}[{r}]: expected a symmetric information matrix")
    if len(info):
        eig = np.linalg.eigvalsh(info)
        bad = ~(eig[:, 0] > PD_RTOL * eig[:, -1])
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise CovarianceError(
                f"{name}[{r}]: expected a positive definite information matrix, eigenvalues "
                f"from {eig[r, 0]:.3g} to {eig[r, -1]:.3g}"
            )


# ----------------------------------------------------------------------------- writing


def _rows(tag: str, ids: IntArray, values: FloatArray) -> list[str]:
    """``TAG id… v…`` lines; ``repr`` gives the shortest text that reads back exactly."""
    id_text = [" ".join(map(str, r)) for r in ids.tolist()]
    value_text = [" ".join(map(repr, r)) for r in values.tolist()]
    return [
        f"{tag} {a} {b}" if b else f"{tag} {a}" for a, b in zip(id_text, value_text, strict=True)
    ]


def _vertex_lines(graph: GraphData, spec: FamilySpec) -> list[str]:
    width = 3 if graph.dim == 2 else 7
    pose_ids = _ids(graph.pose_ids, "pose_ids", (None,))
    poses = _floats(graph.poses, "poses", (pose_ids.size, width))
    lm_ids = _ids(graph.landmark_ids, "landmark_ids", (None,))
    landmarks = _floats(graph.landmarks, "landmarks", (lm_ids.size, 2))
    _nonnegative(pose_ids, "pose_ids")
    _nonnegative(lm_ids, "landmark_ids")
    all_ids = np.concatenate([pose_ids, lm_ids])
    if np.unique(all_ids).size != all_ids.size:
        raise InputError("pose_ids/landmark_ids: expected distinct vertex ids")
    out: list[str] = []
    if pose_ids.size:
        vspec = spec.pose_vertex(graph.dim)
        if vspec is None:
            raise InputError(
                f"a {spec.title} file has no vertex lines for {graph.dim}D poses: write the "
                "graph with family='g2o', or drop the poses"
            )
        if graph.dim == 3:
            _check_quaternions(poses[:, 3:7], "poses")
        out += _rows(vspec.tag, pose_ids[:, None], vspec.encode(poses))
    if lm_ids.size:
        lspec = spec.landmark_vertex()
        if lspec is None or graph.dim != 2:
            raise InputError(
                f"a {spec.title} file has no vertex lines for landmarks: write the graph with "
                "family='g2o', or drop the landmarks"
            )
        out += _rows(lspec.tag, lm_ids[:, None], lspec.encode(landmarks))
    return out


def _fix_lines(graph: GraphData, spec: FamilySpec) -> list[str]:
    fixed = _ids(graph.fixed_ids, "fixed_ids", (None,))
    if not fixed.size:
        return []
    if spec.fix_tag is None:
        raise InputError(f"a {spec.title} file cannot mark fixed vertices (fixed_ids)")
    _nonnegative(fixed, "fixed_ids")
    return [f"{spec.fix_tag} {k}" for k in fixed.tolist()]


def _equiv_lines(graph: GraphData, spec: FamilySpec) -> list[str]:
    eq = _ids(graph.equivalences, "equivalences", (None, 2))
    if not eq.size:
        return []
    if spec.equiv_tag is None:
        raise InputError(f"a {spec.title} file cannot hold equivalences")
    _nonnegative(eq, "equivalences")
    return [f"{spec.equiv_tag} {a} {b}" for a, b in eq.tolist()]


def _edge_set_lines(graph: GraphData, k: int, e: EdgeSet, spec: FamilySpec) -> list[str]:
    name = f"edges[{k}] ({e.kind})"
    espec = spec.write_edge.get(e.kind)
    if espec is None:
        raise InputError(
            f"{name}: a {spec.title} file has no tag for {e.kind!r} edges "
            f"(it writes {', '.join(spec.write_edge) or 'none'})"
        )
    if espec.dim != graph.dim:
        raise InputError(f"{name}: a {e.kind} edge in a {graph.dim}D graph")
    i = _ids(e.i, f"{name}.i", (None,))
    n = i.size
    j = _ids(e.j, f"{name}.j", (n,))
    z = _floats(e.measurement, f"{name}.measurement", (n, _MEASUREMENT[e.kind]))
    r = _RANK[e.kind]
    info = _floats(e.information, f"{name}.information", (n, r, r))
    _nonnegative(i, f"{name}.i")
    if e.kind not in PRIOR_KINDS:
        _nonnegative(j, f"{name}.j")
    if e.kind in ("se3", "se3_prior"):
        _check_quaternions(z[:, 3:7], f"{name}.measurement")
    _check_information(info, f"{name}.information")
    ids = i[:, None] if espec.n_ids == 1 else np.column_stack([i, j])
    return _rows(espec.tag, ids, espec.encode(z, info) if n else np.zeros((0, 0)))


def _edge_lines(graph: GraphData, spec: FamilySpec) -> list[str]:
    per_set = [_edge_set_lines(graph, k, e, spec) for k, e in enumerate(graph.edges)]
    if graph.edge_order is None:
        return [line for lines in per_set for line in lines]
    order = _ids(graph.edge_order, "edge_order", (None, 2))
    sizes = np.array([len(lines) for lines in per_set], dtype=np.int64)
    total = int(sizes.sum())
    ok = order.shape[0] == total
    if ok and total:
        s, r = order[:, 0], order[:, 1]
        ok = bool(((s >= 0) & (s < sizes.size)).all())
        if ok:
            ok = bool(((r >= 0) & (r < sizes[s])).all())
        if ok:
            offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            flat = offsets[s] + r
            ok = np.unique(flat).size == total
    if not ok:
        raise InputError(
            f"edge_order: expected each of the {total} (edge set, row) pairs exactly once"
        )
    return [per_set[s][r] for s, r in order.tolist()]
