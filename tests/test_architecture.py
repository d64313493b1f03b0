"""The import rules of docs/architecture.md hold: every module imports only what its floor may import.

The floors table is read from the document itself, so the document and the code cannot drift apart. Imports
are read with `ast` from every module (those inside functions too; those under `if TYPE_CHECKING:` do not run
and do not count).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: folder -> the package it installs as (pyproject's package-dir)
FOLDERS = {"antarium": "antarium", "geometry": "antarium.geometry", "firmware_proto": "antarium.firmware_proto",
           "renderers": "antarium.renderers"}
ROW = re.compile(r"^\|\s*(\d+)\s*\|\s*(.+?)\s*\|\s*(.+?)\s*\|\s*(.*?)\s*\|\s*$")


def floors_table() -> dict[str, tuple[int, set[str]]]:
    """part (a package or module) -> (floor, the parts it may import), from docs/architecture.md."""
    table = {}
    for line in (ROOT / "docs" / "architecture.md").read_text().splitlines():
        m = ROW.match(line)
        if m:
            allowed = set(re.findall(r"`([\w.]+)`", m[4]))
            row = re.findall(r"`([\w.]+)`", m[2])  # the parts of one row may import each other
            for part in row:
                table[part] = (int(m[1]), allowed | set(row))
    return table


TABLE = floors_table()


def part_of(module: str) -> str | None:
    """The table's part that holds `module` (the longest matching prefix), or None for a foreign module."""
    best = None
    for part in TABLE:
        if (module == part or module.startswith(part + ".")) and (best is None or len(part) > len(best)):
            best = part
    return best


def modules() -> dict[str, Path]:
    out = {}
    for folder, package in FOLDERS.items():
        for path in (ROOT / folder).rglob("*.py"):
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join([package, *parts])] = path
    return out


MODULES = modules()


def imports_of(module: str, path: Path) -> set[str]:
    """Our modules that `module` imports (resolved to modules that exist, else their package)."""
    tree = ast.parse(path.read_text())
    not_run = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            not_run |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    base = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if id(node) in not_run:
            continue
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = node.module or ""
            if node.level:
                target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
            names = [f"{target}.{a.name}" if f"{target}.{a.name}" in MODULES else target for a in node.names]
        else:
            continue
        found |= {n for n in names if n == "antarium" or n.startswith("antarium.")}
    return found


def test_the_table_covers_every_module():
    assert TABLE, "docs/architecture.md has no floors table"
    orphans = sorted(m for m in MODULES if part_of(m) is None)
    assert not orphans, f"modules in no row of docs/architecture.md's floors table: {orphans}"
    unknown = sorted({a for _, allowed in TABLE.values() for a in allowed} - set(TABLE))
    assert not unknown, f"the table allows imports of parts it does not list: {unknown}"


def test_floors_only_look_down():
    for part, (floor, allowed) in TABLE.items():
        for other in allowed:
            assert TABLE[other][0] < floor or other in (part, "antarium") or TABLE[other][1] == TABLE[part][1], \
                f"{part} (floor {floor}) may import {other} " \
                f"(floor {TABLE[other][0]}): an import that runs back up"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_follow_the_table(module):
    part = part_of(module)
    allowed = TABLE[part][1] | {part, "antarium"}
    wrong = sorted(i for i in imports_of(module, MODULES[module]) if part_of(i) not in allowed)
    assert not wrong, f"{module} ({part}) imports {wrong}; its floor may import {sorted(allowed)}"
