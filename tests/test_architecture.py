"""A lower package never imports a higher one (checked on the source, with ast)."""

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ALLOWED = {
    "albedo_model": {"albedo_model"},
    "proposals": {"albedo_model", "proposals"},
    "pipeline": {"albedo_model", "pipeline"},
    "mcmcfit": {"albedo_model", "proposals", "pipeline", "mcmcfit"},
}


def imported_project_packages(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names & set(ALLOWED)


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_dependency_direction(package):
    bad = {}
    for path in (REPO / package).rglob("*.py"):
        extra = imported_project_packages(path) - ALLOWED[package]
        if extra:
            bad[str(path.relative_to(REPO))] = sorted(extra)
    assert not bad, f"forbidden imports: {bad}"
