"""The loader kit's rules, held by walking the source (beside ``test_private_names.py``).

* Every function of ``src/slamkit/datasets`` and ``src/slamkit/io`` (the file readers and
  writers, the g2o/TORO/iSAM graph files among them) is at most :data:`MAX_CODE_LINES`
  lines of code (docstring, comments and blank lines not counted): a reader is parse,
  check, convert and assemble, each its own small function (``datasets/assemble.py``).
* No reader builds events itself: outside ``stream.py`` (the event types) and
  ``assemble.py`` (the kit), ``src/slamkit/datasets`` calls no event constructor, and a
  ``Dataset``'s ``events`` come from :func:`~slamkit.datasets.assemble.assemble_events`
  (or from another data set's, unchanged) — no stream merge is written by hand.
* ``app/`` and ``cli/`` read no ``Dataset.metadata``: where a data set came from is its
  typed ``provenance``.
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "slamkit"
DATASETS = sorted((SRC / "datasets").rglob("*.py"))
READERS = sorted([*DATASETS, *(SRC / "io").rglob("*.py")])
MAX_CODE_LINES = 60
EVENT_TYPES = {"Control", "Odometry", "KnownPose", "LandmarkReadings", "LaserScan"}
KIT = {"stream.py", "assemble.py"}


def _code_lines(source: str) -> set[int]:
    """The lines that hold a token other than a comment or a line break."""
    skip = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT}
    lines: set[int] = set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type not in skip and tok.type != tokenize.ENDMARKER:
            lines.update(range(tok.start[0], tok.end[0] + 1))
    return lines


def _docstring_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> set[int]:
    first = node.body[0]
    if (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        return set(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    return set()


def function_lengths(path: Path) -> list[tuple[str, int, int]]:
    """``(name, first line, code lines)`` of every function (and method) in ``path``."""
    source = path.read_text(encoding="utf-8")
    code = _code_lines(source)
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            span = range(node.lineno, (node.end_lineno or node.lineno) + 1)
            doc = _docstring_lines(node)
            out.append((node.name, node.lineno, sum(1 for n in span if n in code - doc)))
    return out


def test_the_line_count_skips_docstrings_comments_and_blank_lines(tmp_path: Path) -> None:
    source = '''def f(x):
    """Doc.

    More doc."""
    # a comment

    y = (x +
         1)  # two lines of code
    return y
'''
    path = tmp_path / "probe.py"
    path.write_text(source, encoding="utf-8")
    assert function_lengths(path) == [("f", 1, 4)]  # def, two lines of y, return


@pytest.mark.parametrize("path", READERS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_function_of_a_reader_runs_over_60_code_lines(path: Path) -> None:
    long = [
        f"{path.relative_to(ROOT)}:{line}: {name} has {n} code lines"
        for name, line, n in function_lengths(path)
        if n > MAX_CODE_LINES
    ]
    assert not long, "\n".join(long)


def _assembled_names(fn: ast.AST) -> set[str]:
    """Names bound in ``fn`` to a call of ``assemble_events``."""
    names = set()
    for node in ast.walk(fn):
        if (
            isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Call)
            and _called(node.value) == "assemble_events"
        ):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _called(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def hand_made_streams(path: Path) -> list[str]:
    """Event constructors called outside the kit, and ``events=`` given to a data set from
    anything but ``assemble_events`` (or another data set's ``.events``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for fn in ast.walk(tree):
        if not isinstance(fn, ast.FunctionDef):
            continue
        assembled = _assembled_names(fn)
        for node in ast.walk(fn):
            if not isinstance(node, ast.Call):
                continue
            if _called(node) in EVENT_TYPES:
                found.append(f"{path.name}:{node.lineno}: {fn.name} builds {_called(node)}")
            for kw in node.keywords:
                if kw.arg != "events":
                    continue
                v = kw.value
                ok = (
                    (isinstance(v, ast.Call) and _called(v) == "assemble_events")
                    or (isinstance(v, ast.Name) and v.id in assembled)
                    or (isinstance(v, ast.Attribute) and v.attr == "events")
                )
                if not ok:
                    found.append(f"{path.name}:{node.lineno}: {fn.name} passes events by hand")
    return sorted(found, key=lambda f: int(f.split(":")[1]))


@pytest.mark.parametrize("path", [p for p in DATASETS if p.name not in KIT], ids=lambda p: p.name)
def test_readers_assemble_their_streams_with_the_kit(path: Path) -> None:
    found = hand_made_streams(path)
    assert not found, "\n".join(found)


def test_the_stream_rule_sees_a_hand_merge(tmp_path: Path) -> None:
    source = """
def load(t, u, z):
    events = []
    for k in range(len(t)):
        events.append(Control(t[k], u[k], 0.1))
    return Dataset(name="x", events=tuple(events))
"""
    path = tmp_path / "probe.py"
    path.write_text(source, encoding="utf-8")
    assert hand_made_streams(path) == [
        "probe.py:5: load builds Control",
        "probe.py:6: load passes events by hand",
    ]


@pytest.mark.parametrize(
    "path",
    sorted([*(SRC / "app").rglob("*.py"), *(SRC / "cli").rglob("*.py")]),
    ids=lambda p: f"{p.parent.name}/{p.name}",
)
def test_the_app_layer_reads_no_metadata_keys(path: Path) -> None:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    reads = [
        f"{path.relative_to(ROOT)}:{node.lineno}: .metadata"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr == "metadata"
    ]
    assert not reads, "\n".join(reads) + "\n(read Dataset.provenance instead)"
