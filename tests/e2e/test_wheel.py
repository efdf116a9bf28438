"""The built wheel, installed outside the source tree, holds everything its commands read: the
shipped active worlds `pbdag eval active` runs by default, the demo scenario, the migrations,
the viewer and the OpenAPI document. The wheel is built with `python -m build` from a copy of
the sources (the clone stays clean); its dependencies are this environment's, put on the new
environment's path, so the test needs no network and checks only the wheel's own files."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

from tests.e2e.fault_run import free_port
from tests.import_graph import ROOT

pytestmark = pytest.mark.slow


def sources(destination: Path) -> Path:
    """The clone's files as git sees them (tracked and untracked, not ignored), copied."""
    listed = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout.decode()
    for name in filter(None, listed.split("\0")):
        source = ROOT / name
        if source.is_file():
            target = destination / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
    return destination


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new environment with the wheel installed; returns its bin folder."""
    work = tmp_path_factory.mktemp("wheel")
    tree = sources(work / "src")
    subprocess.run(
        [sys.executable, "-m", "build", "--wheel", "--outdir", str(work / "dist"), str(tree)],
        capture_output=True,
        check=True,
    )
    (wheel,) = (work / "dist").glob("pbdag-*.whl")
    environment = work / "env"
    venv.EnvBuilder(with_pip=True).create(environment)
    purelib = Path(sysconfig.get_paths(vars={"base": str(environment)})["purelib"])
    # The dependencies from here; a .pth line adds the folder only (its own .pth files, this
    # clone's editable install among them, are not run).
    (purelib / "zz_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    bin_dir = environment / "bin"
    subprocess.run(
        [
            str(bin_dir / "python"),
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-index",
            str(wheel),
        ],
        capture_output=True,
        check=True,
    )
    return bin_dir


def run(bin_dir: Path, cwd: Path, *command: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(bin_dir / command[0]), *command[1:]],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PATH": f"{bin_dir}:/usr/bin:/bin", "HOME": str(cwd), "MPLBACKEND": "Agg"},
    )


def test_the_wheel_holds_the_data_files_its_commands_read(installed: Path) -> None:
    wheel = next((installed.parent.parent / "dist").glob("pbdag-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {
        str(path.relative_to(ROOT))
        for pattern in ("sim/scenarios/**/*.yaml", "service/static/viewer/*")
        for path in ROOT.glob(pattern)
    }
    assert shipped - names == set()
    assert {"api_schema/openapi.json", "migrations/script.py.mako"} <= names
    assert any(name.startswith("migrations/versions/") for name in names)


def test_the_installed_code_is_the_wheels_not_the_clones(installed: Path, tmp_path: Path) -> None:
    where = run(installed, tmp_path, "python", "-c", "import core, sim; print(sim.__file__)")
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(installed.parent)
    version = run(installed, tmp_path, "pbdag", "--version")
    assert version.returncode == 0 and version.stdout.startswith("pbdag "), version


def test_pbdag_eval_active_runs_the_shipped_worlds_from_the_wheel(
    installed: Path, tmp_path: Path
) -> None:
    out = tmp_path / "active"
    result = run(
        installed, tmp_path, "pbdag", "eval", "active", "--seeds", "7", "--orders", "pbdag",
        "--budgets", "2", "--keyframes", "20", "--out", str(out), "--quiet",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "leaving out" not in result.stderr
    results = json.loads((out / "results.json").read_text())
    worlds = {Path(run["scenario_file"]).name for run in results["runs"]}
    assert worlds == {path.name for path in (ROOT / "sim/scenarios/active").glob("*.yaml")}
    assert all(
        Path(run["scenario_file"]).is_relative_to(installed.parent) for run in results["runs"]
    )


def test_the_demo_runs_from_the_wheel(installed: Path, tmp_path: Path) -> None:
    port = free_port()
    result = run(
        installed, tmp_path, "python", "-m", "sim.demo_service", "--frames", "6", "--pace", "0",
        "--exit", "--port", str(port),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert f"http://127.0.0.1:{port}/viewer?scene=scn-" in result.stdout
    assert (tmp_path / "data").is_dir()  # the SQLite default, in the folder it was run from
