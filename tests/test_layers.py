"""The dependency rules of ARCHITECTURE.md (section 2, in this repository), checked by reading
the imports."""

from __future__ import annotations

import sys
from pathlib import Path

import networkx as nx
import pytest

from tests.import_graph import ROOT, import_graph, imported_modules, imported_roots, module_name

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
    "pbdag_errors",
    "service",
    "sim",
    "tests",
)


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


def test_the_error_root_imports_only_the_standard_library() -> None:
    """`pbdag_errors` sits below every package, `core` and `pbdag_client` included."""
    modules = sorted((ROOT / "pbdag_errors").rglob("*.py"))
    assert modules
    allowed = set(sys.stdlib_module_names) | {"__future__"}
    outside = {
        str(module.relative_to(ROOT)): imported_roots(module) - allowed for module in modules
    }
    assert {name: extra for name, extra in outside.items() if extra} == {}


def modules_of_tests(root: Path) -> list[Path]:
    """Every test module (test_*.py) under `root`'s tests/."""
    return sorted((root / "tests").rglob("test_*.py"))


def enclosing_test_module(dotted: str) -> str | None:
    """The test module a dotted name is in or is (`tests.a.test_b.helper` -> `tests.a.test_b`)."""
    parts = dotted.split(".")
    for index, part in enumerate(parts):
        if part.startswith("test_"):
            return ".".join(parts[: index + 1]) if parts[0] == "tests" else None
    return None


def imports_of_test_modules(root: Path) -> dict[str, list[str]]:
    """For each test module that imports another test module, the ones it imports: a shared
    helper belongs in a module that is not a test (collecting one test module must not depend
    on collecting another, nor on the optional packages it needs)."""
    found = {}
    for path in modules_of_tests(root):
        name = module_name(path, root)
        imported = sorted(
            {
                tested
                for target in imported_modules(path, name)
                if (tested := enclosing_test_module(target)) is not None
            }
        )
        if imported:
            found[name] = imported
    return found


def test_no_test_module_imports_another() -> None:
    assert modules_of_tests(ROOT), "the checker found no test modules"
    assert imports_of_test_modules(ROOT) == {}


def test_the_test_import_checker_sees_one(tmp_path: Path) -> None:
    tests = tmp_path / "tests"
    (tests / "core").mkdir(parents=True)
    (tests / "core" / "test_a.py").write_text("from tests.core.test_b import helper\n")
    (tests / "core" / "test_b.py").write_text("from tests.core import test_c\n")
    (tests / "core" / "helpers.py").write_text("from tests.core.test_a import x\n")
    assert imports_of_test_modules(tmp_path) == {
        "tests.core.test_a": ["tests.core.test_b"],
        "tests.core.test_b": ["tests.core.test_c"],
    }
