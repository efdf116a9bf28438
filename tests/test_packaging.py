"""The service installs slim: the evaluation stack is the `eval` extra, which the service's
packages never import, and `pbdag eval` says so in one line when the extra is missing."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from evaluation import cli as evaluation_cli
from ingest import cli as ingest_cli
from service.cli import main
from tests.import_graph import ROOT, imported_roots

SERVICE_PACKAGES = ("core", "codec", "service", "api_schema", "migrations")
# Distributions whose import name differs from their own.
IMPORT_NAMES = {"open3d-cpu": "open3d", "pyyaml": "yaml", "pillow": "PIL"}


def distribution(requirement: str) -> str:
    """`name[extra]==1.0` -> name, lower case."""
    match = re.match(r"[A-Za-z0-9._-]+", requirement)
    assert match is not None, requirement
    return match.group(0).lower()


def project() -> dict[str, object]:
    with (ROOT / "pyproject.toml").open("rb") as file:
        document = tomllib.load(file)
    table: dict[str, object] = document["project"]
    return table


def extra_only_modules(extra_name: str = "eval") -> set[str]:
    """Import names of an extra's distributions that the service does not depend on."""
    table = project()
    runtime = {distribution(r) for r in table["dependencies"]}  # type: ignore[attr-defined]
    extra = {distribution(r) for r in table["optional-dependencies"][extra_name]}  # type: ignore[index]
    return {IMPORT_NAMES.get(name, name) for name in extra - runtime}


def eval_only_modules() -> set[str]:
    """Import names of the `eval` extra's distributions that the service does not depend on."""
    return extra_only_modules("eval")


def test_the_eval_extra_holds_the_evaluation_stack_and_the_service_none_of_it() -> None:
    table = project()
    runtime = {distribution(r) for r in table["dependencies"]}  # type: ignore[attr-defined]
    assert {"open3d-cpu", "matplotlib", "pandas", "motmetrics", "tqdm"}.isdisjoint(runtime)
    assert {"open3d", "matplotlib", "pandas", "motmetrics", "tqdm", "pycocotools", "yaml"} <= (
        eval_only_modules()
    )
    # `pbdag eval` checks the same list it asks the user to install.
    assert set(evaluation_cli.EVAL_EXTRA) == eval_only_modules()


def test_pbdag_ingest_checks_the_extra_it_asks_for() -> None:
    assert (
        set(ingest_cli.INGEST_EXTRA) == extra_only_modules("ingest") == {"rosbags", "yaml", "tqdm"}
    )


@pytest.mark.parametrize("package", SERVICE_PACKAGES)
def test_service_packages_import_no_eval_only_distribution(package: str) -> None:
    forbidden = eval_only_modules() | extra_only_modules("ingest")
    modules = sorted((ROOT / package).rglob("*.py"))
    assert modules
    found = {
        str(module.relative_to(ROOT)): sorted(imported_roots(module) & forbidden)
        for module in modules
    }
    assert {name: bad for name, bad in found.items() if bad} == {}


def test_pbdag_eval_without_the_extra_fails_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(evaluation_cli.EVAL_EXTRA, "no_such_module_pbdag", "matplotlib")
    assert main(["eval", "dynamic", "--frames", "2", "--out", "unused"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and "install pbdag[eval]" in lines[0] and "matplotlib" in lines[0]
    assert not Path("unused").exists()


def test_pbdag_ingest_without_the_extra_fails_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    monkeypatch.setitem(ingest_cli.INGEST_EXTRA, "no_such_module_pbdag", "rosbags")
    assert main(["ingest", "folder", str(tmp_path), "--scene", "s"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and "pbdag[ingest]" in lines[0] and "rosbags" in lines[0]
