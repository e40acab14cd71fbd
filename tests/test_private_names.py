"""A name that starts with ``_`` is used only in the module that defines it.

What other modules (and the tests) need has a public name, a docstring and a test. This
test walks every module of ``src/slamkit``, ``tests`` and ``benchmarks`` and fails on

* ``from M import _name`` (a private name of another module), and
* ``obj._name`` where ``obj`` is not ``self``/``cls`` and the module itself does not define
  ``_name`` (as a function, class, attribute or slot): a reach into another module's
  internals, such as a test reading an estimator's private buffer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MODULES = sorted(
    [
        *(ROOT / "src" / "slamkit").rglob("*.py"),
        *(ROOT / "tests").rglob("*.py"),
        *(ROOT / "benchmarks").rglob("*.py"),
    ]
)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _defined(tree: ast.AST) -> set[str]:
    """Every name the module binds: functions, classes, assignments (also to attributes),
    annotated fields and string constants (``__slots__``, ``object.__setattr__``)."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            names.add(node.value)
    return names


def violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    own = _defined(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            found += [
                f"{path.relative_to(ROOT)}:{node.lineno}: imports {node.module}.{a.name}"
                for a in node.names
                if _private(a.name)
            ]
        elif (
            isinstance(node, ast.Attribute)
            and _private(node.attr)
            and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
            and node.attr not in own
        ):
            found.append(f"{path.relative_to(ROOT)}:{node.lineno}: reads .{node.attr}")
    return found


def test_no_module_uses_another_modules_private_names() -> None:
    found = [v for path in MODULES for v in violations(path)]
    assert found == [], "\n".join(found)


def test_the_check_catches_both_kinds(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("from m import _kernel\n\ndef f(est):\n    return est._cov_buf\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert len(violations(bad)) == 2
    finally:
        ROOT = saved


if __name__ == "__main__":  # pragma: no cover - a quick listing while refactoring
    pytest.main([__file__, "-q"])
