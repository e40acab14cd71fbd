"""Parse the text of a graph file into a :class:`~slamkit.optim.data.GraphData`.

Three passes, each reporting the *first* offending line (by line number) of its kind of
problem as a :class:`~slamkit.errors.DatasetFormatError`:

1. **lexical**: lines are grouped by tag (one ``str.split`` per line); unknown tags, a
   mixture of 2D and 3D tags, wrong field counts, non-numbers, NaN/inf and non-integer or
   negative ids. The numbers of a whole tag group are converted in one ``np.loadtxt`` call;
   only when that fails is the group searched line by line for the culprit.
2. **per-tag checks** on the raw numbers (quaternion norms, standard deviations,
   covariances), then decoding into slamkit's conventions.
3. **graph checks**: positive definite information, duplicate vertex ids, edges from a
   pose to itself, and references to vertices that have no vertex line — the last only
   when the file has vertex lines of that role at all (iSAM files have none; a TORO ``BR``
   file has pose vertices but no landmark vertices). With ``repair_information="clamp"``
   an information matrix that is not positive definite is repaired by eigenvalue clamping
   (:mod:`slamkit.optim.repair`) and listed in :attr:`ParsedGraph.repaired` instead.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, cast

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.text import MAX_EXACT_INTEGER, text_lines
from slamkit.errors import DatasetFormatError
from slamkit.io.graphfiles.families import (
    FAMILIES,
    LANDMARK_KINDS,
    PD_RTOL,
    POSE_PAIR_KINDS,
    PRIOR_KINDS,
    EdgeSpec,
    FamilySpec,
    VertexSpec,
    detect_family,
)
from slamkit.optim.data import EdgeKind, EdgeSet, GraphData, GraphFamily, IntArray
from slamkit.optim.repair import REPAIR_RTOL, clamp_information, not_positive_definite

__all__ = [
    "MAX_REPORTED_LINES",
    "REPAIR_MODES",
    "ParsedGraph",
    "RepairMode",
    "RepairedEdge",
    "group_lines",
    "parse_graph_text",
]

RepairMode = Literal["none", "clamp"]
REPAIR_MODES: tuple[RepairMode, ...] = ("none", "clamp")

#: How many skipped line numbers a lenient read keeps (the counts are always exact).
MAX_REPORTED_LINES = 20
_MAX_ID = 2.0**53  # ids are read as float64 first: every integer up to here is exact


@dataclass
class _Group:
    """The lines of one tag: the text after the tag, and the 1-based line numbers."""

    rows: list[str] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class RepairedEdge:
    """One edge whose information matrix was repaired: its line, tag and the smallest and
    largest eigenvalue of the matrix as the file gave it (after conversion)."""

    line: int
    tag: str
    eigenvalue_min: float
    eigenvalue_max: float


@dataclass(frozen=True)
class ParsedGraph:
    graph: GraphData
    family: GraphFamily
    skipped_tags: dict[str, int]
    skipped_lines: tuple[int, ...]
    repaired: tuple[RepairedEdge, ...] = ()
    """Every edge whose information was repaired (``repair_information="clamp"``), in line
    order."""


class _Problems:
    """The first problem (smallest line number) seen in one pass."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.best: tuple[int, str] | None = None

    def add(self, line: int, message: str) -> None:
        if self.best is None or line < self.best[0]:
            self.best = (line, message)

    def raise_first(self) -> None:
        if self.best is not None:
            raise DatasetFormatError(self.best[1], self.path, self.best[0])


# ------------------------------------------------------------------------------ pass 1


def group_lines(text: str) -> dict[str, _Group]:
    """Lines grouped by their first word, in order of first appearance; ``#`` starts a
    comment, blank lines are skipped."""
    groups: dict[str, _Group] = {}
    has_comments = "#" in text
    for n, line in enumerate(text_lines(text), start=1):
        if has_comments and "#" in line:
            line = line[: line.index("#")]
        parts = line.split(None, 1)
        if not parts:
            continue
        g = groups.get(parts[0])
        if g is None:
            g = groups[parts[0]] = _Group()
        g.rows.append(parts[1] if len(parts) > 1 else "")
        g.lines.append(n)
    return groups


def _numbers(tag: str, g: _Group, n_fields: int, problems: _Problems) -> FloatArray | None:
    """The ``(len, n_fields)`` finite numbers of a tag group, or ``None`` after recording
    the first bad line."""
    if all(g.rows):  # np.loadtxt would silently drop an empty row
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data"
                a = np.loadtxt(g.rows, dtype=np.float64, ndmin=2, comments=None)
            if a.shape == (len(g.rows), n_fields) and np.isfinite(a).all():
                return a
        except ValueError:
            pass
    # Slow path: find the first line that np.loadtxt rejects, and say why.
    for row, line in zip(g.rows, g.lines, strict=True):
        why = _row_problem(row.split(), n_fields)
        if why is None:
            try:
                np.loadtxt([row], dtype=np.float64, ndmin=2, comments=None)
            except ValueError:
                why = "expected numbers"
        if why is not None:
            problems.add(line, f"{tag}: {why}")
            return None
    raise AssertionError("np.loadtxt failed on a group whose every line it reads")


def _row_problem(fields: list[str], n_fields: int) -> str | None:
    """Why the fields after a tag are not ``n_fields`` finite numbers (``None`` if they are)."""
    if len(fields) != n_fields:
        return f"expected {n_fields} fields after the tag, got {len(fields)}"
    for k, f in enumerate(fields, start=1):
        try:
            # np.loadtxt reads ASCII numbers without digit separators; float() is laxer.
            value = float(f) if f.isascii() and "_" not in f else None
        except ValueError:
            value = None
        if value is None:
            return f"field {k} after the tag: expected a number, got {f!r}"
        if not np.isfinite(value):
            return f"field {k} after the tag: expected a finite number, got {f!r}"
    return None


def _ids(tag: str, values: FloatArray, lines: list[int], problems: _Problems) -> IntArray | None:
    """The leading id columns as int64, or ``None`` after recording the first bad one."""
    ok = (values == np.floor(values)) & (values >= 0) & (values < _MAX_ID)
    if ok.all():
        return values.astype(np.int64)
    r, c = np.argwhere(~ok)[0]
    got = float(values[r, c])
    problems.add(
        lines[int(r)], f"{tag}: id field {int(c) + 1}: expected a non-negative integer, got {got!r}"
    )
    return None


def _fix_ids(tag: str, g: _Group, problems: _Problems) -> tuple[IntArray, IntArray]:
    """``FIX id [id …]``: the ids and, for each, its line."""
    ids: list[int] = []
    lines: list[int] = []
    for row, line in zip(g.rows, g.lines, strict=True):
        fields = row.split()
        if not fields:
            problems.add(line, f"{tag}: expected at least one vertex id after the tag")
        for f in fields:
            # ASCII digits only, and an id that the other tags' ids can equal (int64, exact);
            # the length first, as int() refuses more than 4,300 digits with a ValueError.
            digits = f.isascii() and f.isdigit() and len(f) <= len(str(MAX_EXACT_INTEGER))
            value = int(f) if digits else -1
            if not 0 <= value <= MAX_EXACT_INTEGER:
                problems.add(
                    line,
                    f"{tag}: expected a non-negative integer id up to 2^53, got {f[:40]!r}",
                )
                continue
            ids.append(value)
            lines.append(line)
    return np.asarray(ids, dtype=np.int64), np.asarray(lines, dtype=np.int64)


# ------------------------------------------------------------------------------ parsing


@dataclass
class _EdgeRows:
    spec: EdgeSpec
    i: IntArray
    j: IntArray
    measurement: FloatArray
    information: FloatArray
    lines: IntArray


@dataclass
class _Lexed:
    """Pass 1's result: the groups of the family's tags, each tag's numbers after its ids
    and its ids, the FIX ids with their lines, the unknown tags a lenient read skipped, and
    the graph's dimension."""

    known: dict[str, _Group]
    raw: dict[str, FloatArray]
    ids_of: dict[str, IntArray]
    fixed: tuple[IntArray, IntArray]
    skipped: dict[str, int]
    skipped_lines: list[int]
    dim: int


@dataclass
class _Decoded:
    """Pass 2's result: vertices by tag (ids, values, lines), edges, and EQUIV pairs."""

    vertex_rows: dict[str, tuple[IntArray, FloatArray, IntArray]]
    edge_rows: list[_EdgeRows]
    equiv: tuple[IntArray, IntArray]


def parse_graph_text(
    text: str,
    path: Path,
    *,
    family: GraphFamily | None = None,
    lenient: bool = False,
    repair_information: RepairMode = "none",
) -> ParsedGraph:
    """Parse ``text`` (the content of ``path``, named in errors) as a graph file;
    ``repair_information="clamp"`` repairs information matrices that are not positive
    definite (module docstring) instead of refusing them."""
    if repair_information not in REPAIR_MODES:
        raise DatasetFormatError(
            f"repair_information: expected one of {', '.join(REPAIR_MODES)}, "
            f"got {repair_information!r}",
            path,
        )
    groups = group_lines(text)
    if family is None:
        base = path.with_suffix("") if path.suffix == ".gz" else path
        family = detect_family(list(groups), base.suffix, base.stem)
    spec = FAMILIES[family]
    lexed = _lexical(groups, spec, lenient, path)
    decoded = _decode(lexed, spec, path)
    pose_ids, poses, lm_ids, landmarks, repaired = _graph_checks(
        decoded, lexed, spec, repair_information, path
    )
    if not decoded.edge_rows and not pose_ids.size and not lm_ids.size:
        raise DatasetFormatError(f"no vertex or edge lines of a {spec.title} file", path)
    edges, order = _edge_sets(decoded.edge_rows)
    graph = GraphData(
        dim=cast(Literal[2, 3], lexed.dim),
        pose_ids=pose_ids,
        poses=poses,
        landmark_ids=lm_ids,
        landmarks=landmarks,
        edges=edges,
        fixed_ids=lexed.fixed[0],
        equivalences=decoded.equiv[0],
        family=family,
        source=str(path),
        edge_order=order,
    )
    skipped_lines = sorted(lexed.skipped_lines)
    return ParsedGraph(
        graph,
        family,
        lexed.skipped,
        tuple(skipped_lines[:MAX_REPORTED_LINES]),
        tuple(sorted(repaired, key=lambda r: r.line)),
    )


def _lexical(groups: dict[str, _Group], spec: FamilySpec, lenient: bool, path: Path) -> _Lexed:
    """Pass 1: the family's tags (others refused, or skipped and counted when
    ``lenient``), the dimension, and every known tag's numbers and ids."""
    problems = _Problems(path)
    skipped: dict[str, int] = {}
    skipped_lines: list[int] = []
    known: dict[str, _Group] = {}
    for tag, g in groups.items():
        if tag in spec.known_tags:
            known[tag] = g
        elif lenient:
            skipped[tag] = len(g.lines)
            skipped_lines.extend(g.lines)
        else:
            problems.add(
                g.lines[0],
                f"unknown tag {tag!r} for a {spec.title} file (tags read: "
                f"{', '.join(sorted(spec.known_tags))}; lenient=True skips unknown lines)",
            )
    dim = _graph_dim(known, spec, problems)
    fixed = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    raw: dict[str, FloatArray] = {}
    ids_of: dict[str, IntArray] = {}
    for tag, g in known.items():
        if tag == spec.fix_tag:
            fixed = _fix_ids(tag, g, problems)
            continue
        if tag == spec.equiv_tag:
            n_ids, n_values = 2, 0
        else:
            s = _tag_spec(spec, tag)
            n_ids, n_values = _n_ids(s), s.n_values
        values = _numbers(tag, g, n_ids + n_values, problems)
        if values is None:
            continue
        ids = _ids(tag, values[:, :n_ids], g.lines, problems)
        if ids is None:
            continue
        raw[tag] = values[:, n_ids:]
        ids_of[tag] = ids
    problems.raise_first()
    return _Lexed(known, raw, ids_of, fixed, skipped, skipped_lines, dim)


def _decode(lexed: _Lexed, spec: FamilySpec, path: Path) -> _Decoded:
    """Pass 2: each tag's checks on its raw numbers, then its decoding into slamkit's
    conventions."""
    problems = _Problems(path)
    out = _Decoded({}, [], (np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)))
    for tag, values in lexed.raw.items():
        lines = np.asarray(lexed.known[tag].lines, dtype=np.int64)
        ids = lexed.ids_of[tag]
        if tag == spec.equiv_tag:
            out.equiv = (ids, lines)
            continue
        s = _tag_spec(spec, tag)
        if s.check is not None:
            bad = s.check(values)
            if bad is not None:
                problems.add(int(lines[bad[0]]), f"{tag}: {bad[1]}")
                continue
        if isinstance(s, VertexSpec):
            out.vertex_rows[tag] = (ids[:, 0], s.decode(values), lines)
        else:
            z, info = s.decode(values)
            j = ids[:, 1] if s.n_ids == 2 else np.full(len(ids), -1, dtype=np.int64)
            out.edge_rows.append(_EdgeRows(s, ids[:, 0], j, z, info, lines))
    problems.raise_first()
    return out


def _graph_checks(
    decoded: _Decoded, lexed: _Lexed, spec: FamilySpec, repair: RepairMode, path: Path
) -> tuple[IntArray, FloatArray, IntArray, FloatArray, list[RepairedEdge]]:
    """Pass 3: the vertices (pose ids and poses, landmark ids and positions), each edge's
    information (repaired with ``repair="clamp"``) and references, duplicate ids, and the
    ids FIX and EQUIV name; returns the vertices and the repaired edges."""
    problems = _Problems(path)
    pose_ids, poses, pose_lines = _vertices(decoded.vertex_rows, "pose", lexed.dim, spec)
    lm_ids, landmarks, lm_lines = _vertices(decoded.vertex_rows, "landmark", lexed.dim, spec)
    repaired: list[RepairedEdge] = []
    for e in decoded.edge_rows:
        if repair == "clamp":
            repaired.extend(_repair_information(e, problems))
        _check_information(e, problems)
        _check_references(e, pose_ids, lm_ids, problems)
    _check_duplicates(
        np.concatenate([pose_ids, lm_ids]), np.concatenate([pose_lines, lm_lines]), problems
    )
    all_ids = np.concatenate([pose_ids, lm_ids])
    fixed, equiv = lexed.fixed, decoded.equiv
    if all_ids.size:
        _check_member(fixed[0], fixed[1], all_ids, "FIX names vertex", problems)
    if pose_ids.size:
        flat = equiv[0].reshape(-1)
        _check_member(flat, np.repeat(equiv[1], 2), pose_ids, "EQUIV names pose", problems)
    problems.raise_first()
    return pose_ids, poses, lm_ids, landmarks, repaired


def _tag_spec(spec: FamilySpec, tag: str) -> VertexSpec | EdgeSpec:
    v = spec.vertices.get(tag)
    return v if v is not None else spec.edges[tag]


def _n_ids(s: VertexSpec | EdgeSpec) -> int:
    return s.n_ids if isinstance(s, EdgeSpec) else 1


def _graph_dim(known: dict[str, _Group], spec: FamilySpec, problems: _Problems) -> int:
    """2 or 3 from the tags; a tag of the other dimension is an error at its first line."""
    dims: list[tuple[int, int, str]] = []  # (first line, dim, tag)
    for tag, g in known.items():
        if tag in spec.vertices or tag in spec.edges:
            dims.append((g.lines[0], _tag_spec(spec, tag).dim, tag))
    if not dims:
        return 2
    dims.sort()
    dim = dims[0][1]
    for line, d, tag in dims:
        if d != dim:
            problems.add(
                line,
                f"{tag} is a {d}D tag, but the graph is {dim}D ({dims[0][2]} on line {dims[0][0]})",
            )
    return dim


def _vertices(
    rows: dict[str, tuple[IntArray, FloatArray, IntArray]],
    role: str,
    dim: int,
    spec: FamilySpec,
) -> tuple[IntArray, FloatArray, IntArray]:
    width = {"pose": 3 if dim == 2 else 7, "landmark": 2}[role]
    parts = [r for tag, r in rows.items() if spec.vertices[tag].role == role]
    if not parts:
        return (
            np.zeros(0, dtype=np.int64),
            np.zeros((0, width)),
            np.zeros(0, dtype=np.int64),
        )
    ids = np.concatenate([p[0] for p in parts])
    values = np.concatenate([p[1] for p in parts])
    lines = np.concatenate([p[2] for p in parts])
    order = np.argsort(lines, kind="stable")
    return ids[order], np.ascontiguousarray(values[order]), lines[order]


def _check_information(e: _EdgeRows, problems: _Problems) -> None:
    info = e.information
    finite = np.isfinite(info).all(axis=(1, 2))
    if not finite.all():
        r = int(np.flatnonzero(~finite)[0])
        problems.add(
            int(e.lines[r]), f"{e.spec.tag}: the {e.spec.noise} gives a non-finite information"
        )
        return
    eig = np.linalg.eigvalsh(info)
    ok = eig[:, 0] > PD_RTOL * eig[:, -1]
    if not ok.all():
        r = int(np.flatnonzero(~ok)[0])
        problems.add(
            int(e.lines[r]),
            f"{e.spec.tag}: the {e.spec.noise} gives an information matrix that is not "
            f"positive definite (eigenvalues from {eig[r, 0]:.3g} to {eig[r, -1]:.3g}); "
            "repair_information='clamp' (slamkit optimize --repair-information clamp) "
            "repairs such matrices by eigenvalue clamping and reports each one",
        )


def _repair_information(e: _EdgeRows, problems: _Problems) -> list[RepairedEdge]:
    """Clamp the eigenvalues of the rows of ``e`` that are not positive definite (in place)
    and return their records; a matrix with no positive eigenvalue stays for
    :func:`_check_information`'s error, and non-finite ones for its own."""
    info = e.information
    if not np.isfinite(info).all():
        return []
    bad = not_positive_definite(info, PD_RTOL)
    if not bad.any():
        return []
    eig = np.linalg.eigvalsh(info[bad])
    rows = np.flatnonzero(bad)
    hopeless = eig[:, -1] <= 0
    if hopeless.any():
        r = int(rows[np.flatnonzero(hopeless)[0]])
        problems.add(
            int(e.lines[r]),
            f"{e.spec.tag}: the {e.spec.noise} gives an information matrix with no positive "
            f"eigenvalue (largest {float(eig[hopeless][0, -1]):.3g}): there is no information "
            "to repair from",
        )
        return []
    e.information = clamp_information(info, rows, REPAIR_RTOL)
    return [
        RepairedEdge(int(e.lines[r]), e.spec.tag, float(lo), float(hi))
        for r, lo, hi in zip(rows.tolist(), eig[:, 0].tolist(), eig[:, -1].tolist(), strict=True)
    ]


def _check_member(
    ids: IntArray, lines: IntArray, known: IntArray, what: str, problems: _Problems
) -> None:
    missing = ~np.isin(ids, known)
    if missing.any():
        r = int(np.flatnonzero(missing)[0])
        problems.add(int(lines[r]), f"{what} {int(ids[r])}, which has no vertex line")


def _check_references(
    e: _EdgeRows, pose_ids: IntArray, lm_ids: IntArray, problems: _Problems
) -> None:
    kind = e.spec.kind
    tag = e.spec.tag
    if kind in POSE_PAIR_KINDS:
        loop = e.i == e.j
        if loop.any():
            r = int(np.flatnonzero(loop)[0])
            problems.add(int(e.lines[r]), f"{tag}: edge from pose {int(e.i[r])} to itself")
    if pose_ids.size:
        _check_member(e.i, e.lines, pose_ids, f"{tag} refers to pose", problems)
        if kind in POSE_PAIR_KINDS:
            _check_member(e.j, e.lines, pose_ids, f"{tag} refers to pose", problems)
    if lm_ids.size and kind in LANDMARK_KINDS:
        _check_member(e.j, e.lines, lm_ids, f"{tag} refers to landmark", problems)
    assert kind in POSE_PAIR_KINDS | PRIOR_KINDS | LANDMARK_KINDS


def _check_duplicates(ids: IntArray, lines: IntArray, problems: _Problems) -> None:
    if ids.size < 2:
        return
    order = np.argsort(lines, kind="stable")
    ids, lines = ids[order], lines[order]
    _, first = np.unique(ids, return_index=True)
    if first.size == ids.size:
        return
    dup = np.ones(ids.size, dtype=bool)
    dup[first] = False
    r = int(np.flatnonzero(dup)[0])
    first_line = int(lines[np.flatnonzero(ids == ids[r])[0]])
    problems.add(int(lines[r]), f"duplicate vertex id {int(ids[r])} (first on line {first_line})")


def _edge_sets(rows: list[_EdgeRows]) -> tuple[tuple[EdgeSet, ...], IntArray | None]:
    """One :class:`EdgeSet` per kind in order of first appearance, rows in file order, and
    the file's interleaving (``None`` when the sets simply follow one another)."""
    by_kind: dict[EdgeKind, list[_EdgeRows]] = {}
    for r in sorted(rows, key=lambda r: int(r.lines[0])):
        by_kind.setdefault(r.spec.kind, []).append(r)
    sets: list[EdgeSet] = []
    for kind, parts in by_kind.items():
        lines = np.concatenate([p.lines for p in parts])
        order = np.argsort(lines, kind="stable")
        sets.append(
            EdgeSet(
                kind=kind,
                i=np.concatenate([p.i for p in parts])[order],
                j=np.concatenate([p.j for p in parts])[order],
                measurement=np.ascontiguousarray(
                    np.concatenate([p.measurement for p in parts])[order]
                ),
                information=np.ascontiguousarray(
                    np.concatenate([p.information for p in parts])[order]
                ),
                lines=lines[order],
            )
        )
    if not sets:
        return (), None
    all_lines = np.concatenate([s.lines for s in sets])
    if np.all(np.diff(all_lines) > 0):
        return tuple(sets), None
    set_index = np.concatenate([np.full(len(s), k, dtype=np.int64) for k, s in enumerate(sets)])
    row = np.concatenate([np.arange(len(s), dtype=np.int64) for s in sets])
    order = np.argsort(all_lines, kind="stable")
    return tuple(sets), np.column_stack([set_index[order], row[order]])
