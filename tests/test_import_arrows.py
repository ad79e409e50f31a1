"""The import arrows of docs/architecture.md point one way."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
PROJECT = ("algorithms", "scenes", "harness", "reports")


def read_arrows(text: str) -> dict[str, tuple[str, ...]]:
    """The table under "## Import arrows": importer prefix -> project module prefixes it may import.

    A row is ``| `importer` | `a`, `b` (why), ... |``; "nothing" allows only the importer itself.
    """
    section = text.split("## Import arrows", 1)[1].split("\n## ", 1)[0]
    arrows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 2 or not cells[0].startswith("`"):
            continue
        importer = re.findall(r"`([\w.]+)`", cells[0])[0]
        allowed = [n for n in re.findall(r"`([\w.]+)`", cells[1]) if n.split(".")[0] in PROJECT]
        arrows[importer] = tuple(dict.fromkeys([importer, *allowed]))
    return arrows


# module prefix of the importer -> project module prefixes it may import (docs/architecture.md)
ALLOWED = read_arrows(ARCHITECTURE.read_text())


def _rule(module: str) -> tuple[str, ...]:
    for prefix in sorted(ALLOWED, key=len, reverse=True):
        if module == prefix or module.startswith(prefix + "."):
            return ALLOWED[prefix]
    raise AssertionError(f"no import rule for {module}")


def _imports(path: Path, module: str) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # `from pkg import mod` may name a submodule: check pkg.mod too
            found += [(node.lineno, f"{target}.{a.name}") for a in node.names]
    return [(line, name) for line, name in found if name.split(".")[0] in PROJECT]


def _modules():
    for top in PROJECT:
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            yield path, ".".join(parts)


def _allowed(name: str, rule: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") or p.startswith(name + ".") and name in PROJECT
               for p in rule)


def test_every_package_exists_and_has_a_row_in_the_table():
    for top in PROJECT:
        assert (ROOT / top / "__init__.py").is_file(), top
        assert top in ALLOWED, f"docs/architecture.md: no import-arrow row for {top}"


def test_the_table_reads_as_the_page_states_it():
    assert ALLOWED["algorithms"] == ("algorithms",)
    assert ALLOWED["scenes"] == ("scenes", "algorithms.flow")
    assert set(ALLOWED["harness"]) == {"harness", "scenes", "algorithms"}
    assert "reports" in ALLOWED["harness.cli"] and "reports" not in ALLOWED["harness"]
    assert "harness.runner" not in ALLOWED["reports"] and "harness.results" in ALLOWED["reports"]


@pytest.mark.parametrize("path,module", list(_modules()), ids=lambda x: str(x) if isinstance(x, str) else "")
def test_imports_point_one_way(path, module):
    rule = _rule(module)
    bad = [f"{path.relative_to(ROOT)}:{line} imports {name}" for line, name in _imports(path, module)
           if not _allowed(name, rule)]
    assert not bad, "import against the arrows of docs/architecture.md:\n" + "\n".join(bad)


def test_the_checker_catches_a_wrong_arrow(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("from harness.runner import run_suite\nimport scenes.render\n")
    names = [n for _, n in _imports(bad, "algorithms.bad")]
    assert [n for n in names if not _allowed(n, _rule("algorithms.bad"))] == names
    assert _allowed("algorithms.flow.as_gray", _rule("scenes.render"))
    assert not _allowed("scenes.render.x", _rule("reports.html"))
