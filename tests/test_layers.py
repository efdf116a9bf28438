"""The dependency rules of ARCHITECTURE.md section 2, checked by reading the imports."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = {
    "core": {
        "service",
        "api_schema",
        "bench",
        "tests",
        "sqlalchemy",
        "fastapi",
        "httpx",
        "uvicorn",
        "alembic",
        "psycopg",
    },
    "api_schema": {"core", "service", "bench", "tests", "sqlalchemy"},
    "service": {"bench", "tests"},
    "migrations": {"bench", "tests"},
}


def imported_roots(path: Path) -> set[str]:
    """Top-level package names a module imports."""
    roots = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_respect_the_layers(package):
    modules = sorted((ROOT / package).rglob("*.py"))
    assert modules, f"{package}/ has no modules"
    violations = {
        str(module.relative_to(ROOT)): sorted(imported_roots(module) & FORBIDDEN[package])
        for module in modules
    }
    assert {name: bad for name, bad in violations.items() if bad} == {}


def test_the_checker_sees_a_violation(tmp_path):
    module = tmp_path / "bad.py"
    module.write_text("import sqlalchemy\nfrom service.app import create_app\n")
    assert imported_roots(module) >= {"sqlalchemy", "service"}
