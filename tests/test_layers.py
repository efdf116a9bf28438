"""The dependency rules of ARCHITECTURE.md (section 2, in this repository), checked by reading
the imports."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
# What only the server runs on, and the packages above the service.
SERVER = {"service", "sqlalchemy", "fastapi", "starlette", "uvicorn", "alembic", "psycopg"}
ABOVE = {"sim", "evaluation", "bench", "tests"}
FORBIDDEN = {
    "core": {"api_schema", "codec", "httpx", *SERVER, *ABOVE},
    "api_schema": {"core", "codec", "service", "sqlalchemy", *ABOVE},
    # Between the wire models and the core, for the simulator, the evaluation and any client
    # that wants the service's own decoding: it never needs the server to run.
    "codec": {"httpx", *SERVER, *ABOVE},
    "service": ABOVE,
    "migrations": ABOVE,
    # The simulator produces streams and ground truth; the evaluation consumes them, never the
    # other way round, and neither depends on the benchmarks. Both decode with the codec and
    # talk to a running service through the client, never through the service's modules.
    "sim": {"evaluation", "bench", "tests", "service"},
    "evaluation": {"bench", "tests", "service"},
    # The client a robot team installs: the wire models and HTTP only, never the service.
    "pbdag_client": {"core", "codec", "scipy", "open3d", "pycocotools", *SERVER, *ABOVE},
    # Recorded data in, batches out over HTTP: the wire models only, never the service's insides
    # or the method itself (a user's robot has neither).
    "ingest": {"core", "codec", "service", "sqlalchemy", "fastapi", *ABOVE},
}
# Modules that drive the service on purpose: the demo serves it in its own process.
DRIVES_THE_SERVICE = {"sim/demo_service.py": {"service"}}
# Every package of the repository: each one's module graph, and theirs together, stay acyclic.
PACKAGES = (
    "api_schema",
    "bench",
    "codec",
    "core",
    "evaluation",
    "ingest",
    "migrations",
    "pbdag_client",
    "service",
    "sim",
    "tests",
)


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
def test_package_imports_respect_the_layers(package: str) -> None:
    modules = sorted((ROOT / package).rglob("*.py"))
    assert modules, f"{package}/ has no modules"
    violations = {}
    for module in modules:
        name = str(module.relative_to(ROOT))
        allowed = DRIVES_THE_SERVICE.get(name, set())
        violations[name] = sorted(imported_roots(module) & FORBIDDEN[package] - allowed)
    assert {name: bad for name, bad in violations.items() if bad} == {}


def test_the_checker_sees_a_violation(tmp_path: Path) -> None:
    module = tmp_path / "bad.py"
    module.write_text("import sqlalchemy\nfrom service.app import create_app\n")
    assert imported_roots(module) >= {"sqlalchemy", "service"}


def module_name(path: Path, root: Path) -> str:
    """Dotted module name of a file under `root` (a package's __init__ is the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path, name: str) -> set[str]:
    """Dotted names a module imports, relative imports resolved, each `from X import y` also as X.y.

    Every import counts, including those under TYPE_CHECKING and inside functions: a cycle hidden
    there is still a cycle in the design.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found.add(base)
            found |= {f"{base}.{alias.name}" for alias in node.names}
    return found


def import_graph(root: Path, packages: tuple[str, ...]) -> nx.DiGraph:
    """Module -> imported module edges among the modules of `packages` under `root`."""
    files = {
        module_name(path, root): path
        for package in packages
        for path in (root / package).rglob("*.py")
    }
    graph = nx.DiGraph()
    graph.add_nodes_from(files)
    for name, path in files.items():
        graph.add_edges_from(
            (name, target)
            for target in imported_modules(path, name)
            if target in files and target != name
        )
    return graph


def import_cycles(graph: nx.DiGraph) -> list[list[str]]:
    """The strongly connected components of more than one module, each sorted."""
    return sorted(sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1)


def test_every_package_is_guarded() -> None:
    found = {path.parent.name for path in ROOT.glob("*/__init__.py")}
    assert found == set(PACKAGES)
    assert set(FORBIDDEN) <= found


@pytest.mark.parametrize("package", PACKAGES)
def test_the_modules_of_a_package_import_each_other_without_a_cycle(package: str) -> None:
    graph = import_graph(ROOT, (package,))
    assert import_cycles(graph) == []


def test_the_packages_together_import_without_a_cycle() -> None:
    graph = import_graph(ROOT, PACKAGES)
    assert graph.number_of_edges() > 1000, "the checker found too few imports"
    assert import_cycles(graph) == []


def test_the_cycle_checker_sees_a_cycle_hidden_under_type_checking(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from pkg.b import helper\n")
    (package / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import a\n"
    )
    graph = import_graph(tmp_path, ("pkg",))
    assert {("pkg.a", "pkg.b"), ("pkg.b", "pkg.a")} <= set(graph.edges)
    assert import_cycles(graph) == [["pkg.a", "pkg.b"]]


def test_the_cycle_checker_sees_a_cycle_hidden_in_a_function(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("import pkg.b\n")
    (package / "b.py").write_text("import pkg.c\n")
    (package / "c.py").write_text("def late() -> None:\n    from pkg.a import thing\n")
    assert import_cycles(import_graph(tmp_path, ("pkg",))) == [["pkg.a", "pkg.b", "pkg.c"]]
