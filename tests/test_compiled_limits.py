"""Every compiled function (``@jit`` from :mod:`slamkit.backend`, under any alias) stays
small: at most :data:`MAX_CODE_LINES` code lines (no blank, comment or docstring lines) and
:data:`MAX_PARAMETERS` parameters; the arguments of a longer list travel as small typed
records (named tuples of arrays and numbers, as numba takes them). And only
:mod:`slamkit.backend` reads which backend is active: no other module names ``_active``,
``backend`` of the seam, or a flag of numba's presence."""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "slamkit"
MAX_CODE_LINES = 80
MAX_PARAMETERS = 10
JIT_NAMES = {"jit", "_jit"}


def _is_jit(decorator: ast.expr) -> bool:
    """``@jit``, ``@_jit``, ``@module.jit``."""
    if isinstance(decorator, ast.Name):
        return decorator.id in JIT_NAMES
    return isinstance(decorator, ast.Attribute) and decorator.attr in JIT_NAMES


def _code_lines(source: str, fn: ast.FunctionDef) -> int:
    """Lines of ``fn`` (signature included) holding code: no blank, comment-only or
    docstring lines."""
    doc = fn.body[0] if fn.body and isinstance(fn.body[0], ast.Expr) else None
    doc_lines: set[int] = set()
    if doc is not None and isinstance(doc.value, ast.Constant) and isinstance(doc.value.value, str):
        doc_lines = set(range(doc.lineno, (doc.end_lineno or doc.lineno) + 1))
    first = min([fn.lineno] + [d.lineno for d in fn.decorator_list])
    lines = source.splitlines()[first - 1 : fn.end_lineno]
    code: set[int] = set()
    tokens = tokenize.generate_tokens(io.StringIO("\n".join(lines) + "\n").readline)
    skip = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT}
    for tok in tokens:
        if tok.type in skip or tok.type == tokenize.ENDMARKER:
            continue
        for row in range(tok.start[0], tok.end[0] + 1):
            code.add(row + first - 1)
    return len(code - doc_lines - {d.lineno for d in fn.decorator_list})


def compiled_functions() -> list[tuple[str, int, int]]:
    """``(module:function, code lines, parameters)`` of every compiled function."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        source = path.read_text(encoding="utf-8")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.FunctionDef) and any(map(_is_jit, node.decorator_list)):
                a = node.args
                n_params = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                name = f"{path.relative_to(SRC)}:{node.name}"
                found.append((name, _code_lines(source, node), n_params))
    return found


def test_the_walk_finds_the_compiled_kernels() -> None:
    names = {name for name, _, _ in compiled_functions()}
    assert "scanmatch/kernels.py:plicp_loop" in names
    assert "scanmatch/compiled.py:depth_first" in names
    assert "scanmatch/nearest.py:grid_nearest" in names
    assert "optim/compiled2d.py:_edge_terms" in names
    assert len(names) >= 35


def test_no_compiled_function_is_long_or_takes_many_parameters() -> None:
    too_long = [(n, lines) for n, lines, _ in compiled_functions() if lines > MAX_CODE_LINES]
    too_many = [(n, p) for n, _, p in compiled_functions() if p > MAX_PARAMETERS]
    assert too_long == [] and too_many == []


def test_the_code_line_count_leaves_out_docstrings_comments_and_blanks() -> None:
    source = (
        '@jit\ndef f(a, b):\n    """Doc\n    more."""\n\n    # note\n'
        "    x = (a +\n         b)\n    return x\n"
    )
    fn = ast.parse(source).body[0]
    assert isinstance(fn, ast.FunctionDef)
    assert _code_lines(source, fn) == 4  # the signature, two lines of x, the return


def _reads_the_choice(node: ast.AST) -> bool:
    """``AVAILABLE``, ``SEAM.backend`` / ``.default`` / ``.use`` or ``Backend.NUMBA`` /
    ``.NUMPY`` in code (docstrings may name them)."""
    if isinstance(node, ast.Name) and node.id == "AVAILABLE":
        return True
    if isinstance(node, ast.alias) and node.name == "AVAILABLE":  # imported by name
        return True
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
        owner, attr = node.value.id, node.attr
        return (owner == "SEAM" and attr in {"backend", "default", "use"}) or (
            owner == "Backend" and attr in {"NUMBA", "NUMPY"}
        )
    return False


def test_only_the_backend_module_reads_the_choice() -> None:
    readers = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "backend.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        found = [n for n in ast.walk(tree) if _reads_the_choice(n)]
        readers += [f"{path.relative_to(SRC)}: {ast.unparse(n)}" for n in found]
    assert readers == []
    # ... while the test suite reads it (the walk would see it).
    here = ast.parse(Path(__file__).with_name("test_backend.py").read_text(encoding="utf-8"))
    assert any(_reads_the_choice(n) for n in ast.walk(here))
