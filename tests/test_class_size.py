"""No class in pyrt is longer than a reader can hold: at most 500 lines, each."""

from __future__ import annotations

import ast
from pathlib import Path

import pyrt

PACKAGE = Path(pyrt.__file__).parent
MAX_LINES = 500


def _classes() -> list[tuple[int, str]]:
    """(lines, module:Class) of every class in the package, decorators included."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                rel = path.relative_to(PACKAGE.parent)
                found.append((node.end_lineno - first + 1, f"{rel}:{node.name}"))  # type: ignore[operator]
    return found


def test_the_class_census_sees_the_package():
    """The census finds the classes it must judge (the loop, the ready queue, the controllers)."""
    names = {name.split(":")[1] for _, name in _classes()}
    assert {"Loop", "ReadyQueue", "PolyAxis", "GripperController", "Station"} <= names


def test_no_class_in_pyrt_is_over_500_lines():
    """Every class in pyrt/ is at most 500 lines long; a longer one holds more than one concept."""
    long = sorted((n, name) for n, name in _classes() if n > MAX_LINES)
    assert not long, "classes over 500 lines: " + ", ".join(f"{name} ({n})" for n, name in long)
