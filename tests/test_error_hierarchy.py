"""One error hierarchy across the packages (ARCHITECTURE.md, section 4), checked by reading the
class definitions: every exception the project defines derives from `pbdag_errors.PbdagError`,
and no two packages define an exception of the same name."""

from __future__ import annotations

import ast
import builtins
from collections import defaultdict
from pathlib import Path

from tests.import_graph import ROOT

PACKAGES = (
    "pbdag_errors",
    "core",
    "api_schema",
    "codec",
    "pbdag_client",
    "service",
    "migrations",
    "sim",
    "evaluation",
    "bench",
    "ingest",
)
# Exceptions that stay outside on purpose, with the reason.
OUTSIDE = {
    "SkipFrame": "a signal from a detector to its frame source, counted there; never an error",
}
BUILTIN_EXCEPTIONS = frozenset(
    name
    for name, value in vars(builtins).items()
    if isinstance(value, type) and issubclass(value, BaseException)
)


def base_names(node: ast.ClassDef) -> list[str]:
    """The names of a class's bases as written (`errors.Refused` -> `Refused`)."""
    names = []
    for base in node.bases:
        if isinstance(base, ast.Name):
            names.append(base.id)
        elif isinstance(base, ast.Attribute):
            names.append(base.attr)
    return names


def exception_classes(root: Path, packages: tuple[str, ...]) -> dict[str, list[tuple[str, str]]]:
    """Every exception class defined under `packages`: name -> [(module path, root name)] per
    definition, the root being "PbdagError" when the class derives from `pbdag_errors`'s, else
    the builtin exception it derives from. A base is found by its name."""
    definitions: dict[str, list[tuple[str, list[str]]]] = defaultdict(list)
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ClassDef):
                    module = path.relative_to(root).as_posix()
                    definitions[node.name].append((module, base_names(node)))

    def root_of(module: str, name: str, bases: list[str], seen: frozenset[str]) -> str | None:
        if name == "PbdagError" and module == "pbdag_errors/__init__.py":
            return "PbdagError"
        found = [root_of_name(base, seen | {name}) for base in bases if base not in seen]
        known = [found_root for found_root in found if found_root is not None]
        return "PbdagError" if "PbdagError" in known else (known[0] if known else None)

    def root_of_name(name: str, seen: frozenset[str]) -> str | None:
        if name in BUILTIN_EXCEPTIONS and name not in definitions:
            return name
        roots = [root_of(module, name, bases, seen) for module, bases in definitions.get(name, [])]
        known = [found_root for found_root in roots if found_root is not None]
        return "PbdagError" if "PbdagError" in known else (known[0] if known else None)

    classes: dict[str, list[tuple[str, str]]] = {}
    for name, where in definitions.items():
        roots = [(module, root_of(module, name, bases, frozenset())) for module, bases in where]
        if any(found_root is not None for _, found_root in roots):
            classes[name] = [(module, found_root or "?") for module, found_root in roots]
    return classes


def test_every_exception_derives_from_the_one_root() -> None:
    classes = exception_classes(ROOT, PACKAGES)
    assert len(classes) > 40, "the checker found too few exception classes"
    outside = {
        name: [module for module, _ in where]
        for name, where in classes.items()
        if any(found_root != "PbdagError" for _, found_root in where)
    }
    assert outside == {name: outside.get(name) for name in OUTSIDE}
    assert all(outside[name] for name in OUTSIDE), "an exception listed outside is gone"


def test_no_exception_name_is_defined_twice() -> None:
    """The client mirrors the hierarchy without redefining its names (`ApiError`, not a second
    `PbdagError`; `ResourceNotFound`, not a second `NotFound`)."""
    twice = {
        name: [module for module, _ in where]
        for name, where in exception_classes(ROOT, PACKAGES).items()
        if len(where) > 1
    }
    assert twice == {}


def test_the_checker_sees_an_outsider_and_a_name_defined_twice(tmp_path: Path) -> None:
    (tmp_path / "pbdag_errors").mkdir()
    (tmp_path / "pbdag_errors" / "__init__.py").write_text(
        "class PbdagError(Exception): ...\nclass Refused(PbdagError): ...\n"
    )
    (tmp_path / "one").mkdir()
    (tmp_path / "one" / "a.py").write_text(
        "import pbdag_errors\n"
        "class NotFound(pbdag_errors.Refused): ...\n"
        "class Stray(KeyError): ...\n"
        "class Helper: ...\n"
    )
    (tmp_path / "one" / "b.py").write_text("class NotFound(Exception): ...\n")
    classes = exception_classes(tmp_path, ("pbdag_errors", "one"))
    assert "Helper" not in classes
    assert classes["Stray"] == [("one/a.py", "KeyError")]
    assert sorted(classes["NotFound"]) == [("one/a.py", "PbdagError"), ("one/b.py", "Exception")]
