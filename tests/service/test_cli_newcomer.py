"""`pbdag` as a newcomer meets it (issue 29): --version, one-line configuration errors, the
database named and never created by accident, a closed pipe, help on every option, what
`migrate` did, a busy port."""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path

import pytest

from service.cli import build_parser, main, pages
from service.settings import Settings

REPO = Path(__file__).resolve().parents[2]


def pbdag(
    *arguments: str, cwd: Path, stdout: int | None = subprocess.PIPE, **env: str
) -> subprocess.CompletedProcess[str]:
    """`python -m service.cli ARGUMENTS` in `cwd` with only these PBDAG_* variables."""
    environment = {k: v for k, v in os.environ.items() if not k.startswith("PBDAG_")}
    environment["PYTHONPATH"] = str(REPO)
    environment.update(env)
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *arguments],
        cwd=cwd,
        env=environment,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
    )


@pytest.fixture
def elsewhere(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A directory without data/, as the working directory, and no PBDAG_* variable."""
    for name in list(os.environ):
        if name.startswith("PBDAG_"):
            monkeypatch.delenv(name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_version_prints_the_installed_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out == f"pbdag {version('pbdag')}\n"


def test_an_unknown_blob_backend_is_one_line_naming_the_variable(tmp_path: Path) -> None:
    done = pbdag("gc", cwd=tmp_path, PBDAG_BLOB_BACKEND="s3")
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith("pbdag: PBDAG_BLOB_BACKEND='s3': input should be 'auto'")
    assert "unset it (default: auto)" in done.stderr
    assert "blob_backend" not in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("variable", "value", "expected"),
    [
        ("PBDAG_PORT", "eighty", "PBDAG_PORT='eighty': input should be a valid integer"),
        ("PBDAG_LOG_LEVEL", "LOUD", "PBDAG_LOG_LEVEL='LOUD': input should be 'DEBUG'"),
        ("PBDAG_RAW_RETENTION", "soon", "PBDAG_RAW_RETENTION='soon': value error"),
        ("PBDAG_TRUSTED_PROXIES", "proxy.lan", "PBDAG_TRUSTED_PROXIES='proxy.lan': value error"),
        ("PBDAG_MAX_BODY_BYTES", "10", "PBDAG_MAX_BODY_BYTES='10': input should be greater"),
    ],
)
def test_every_setting_error_names_its_variable(
    elsewhere: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    variable: str,
    value: str,
    expected: str,
) -> None:
    monkeypatch.setenv(variable, value)
    assert main(["token", "list"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pbdag: {expected}"), err
    assert err.count("\n") == 1 and f"set {variable} to a valid value" in err


def test_postgres_scheme_means_psycopg_3() -> None:
    settings = Settings(database_url="postgres://robot@db.lan:5432/memory")
    assert settings.resolved_database_url() == "postgresql+psycopg://robot@db.lan:5432/memory"
    assert Settings(database_url="postgresql://h/d").database_url == "postgresql+psycopg://h/d"


def test_a_server_that_does_not_answer_is_one_line_without_the_password(tmp_path: Path) -> None:
    url = "postgres://robot:hunter2@127.0.0.1:1/memory"
    done = pbdag("token", "list", cwd=tmp_path, PBDAG_DATABASE_URL=url)
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert lines == [
        "pbdag: database postgresql+psycopg://robot:***@127.0.0.1:1/memory",
        "pbdag: PBDAG_DATABASE_URL='postgresql+psycopg://robot:***@127.0.0.1:1/memory': the "
        'database cannot be opened: connection failed: connection to server at "127.0.0.1", '
        "port 1 failed: Connection refused; check the host, port, database name and credentials",
    ]
    assert "hunter2" not in done.stderr + done.stdout


def test_a_missing_postgres_database_is_one_line_with_the_servers_reason(
    tmp_path: Path,
) -> None:
    url = "postgresql+psycopg://postgres:secret@127.0.0.1:5432/pbdag_no_such_database"
    done = pbdag("migrate", cwd=tmp_path, PBDAG_DATABASE_URL=url)
    assert done.returncode == 2
    last = done.stderr.splitlines()[-1]
    assert len(done.stderr.splitlines()) == 2, done.stderr
    assert last.startswith("pbdag: PBDAG_DATABASE_URL='postgresql+psycopg://postgres:***@")
    assert 'database "pbdag_no_such_database" does not exist' in last
    assert "secret" not in done.stderr


def test_a_url_without_a_driver_is_one_line(
    elsewhere: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PBDAG_DATABASE_URL", "mysql://robot:pw@db/memory")
    assert main(["gc"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith("pbdag: PBDAG_DATABASE_URL='mysql://robot:***@db/memory': no driver")
    assert "use postgresql+psycopg://" in err[-1]


COMMANDS_ON_AN_EXISTING_DATABASE = [
    ["token", "list"],
    ["token", "create", "--name", "robot", "--scope", "read"],
    ["token", "revoke", "000000000000"],
    ["gc", "--dry-run"],
    ["export", "scn-000001"],
    ["rebuild"],
    ["requeue", "--scene", "scn-000001", "--all-dead"],
    ["repair", "scn-000001"],
    ["worker", "--drain"],
    ["blobs", "migrate", "--to", "folder"],
]


@pytest.mark.parametrize("command", COMMANDS_ON_AN_EXISTING_DATABASE, ids=" ".join)
def test_a_missing_database_file_is_refused_not_created(
    elsewhere: Path, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    assert main(command) == 2
    err = capsys.readouterr().err
    expected = elsewhere / "data" / "pbdag.db"
    assert err.startswith(f"pbdag: no database file {expected} (PBDAG_DATABASE_URL is unset"), err
    assert "PBDAG_DATABASE_URL=sqlite:////" in err and "pbdag migrate" in err
    assert err.count("\n") == 1
    assert list(elsewhere.iterdir()) == []  # neither data/ nor a database file


def test_migrate_creates_then_says_up_to_date_and_commands_name_the_database(
    elsewhere: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    database = f"sqlite:///{elsewhere / 'data' / 'pbdag.db'}"
    assert main(["migrate"]) == 0
    out, err = capsys.readouterr()
    assert err == f"pbdag: database {database}\n"
    assert out.startswith(f"pbdag: migrated an empty database {database} to revision ")
    assert main(["migrate"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"pbdag: schema of {database} is up to date (revision ")
    assert err == f"pbdag: database {database}\n"
    assert main(["token", "list"]) == 0
    out, err = capsys.readouterr()
    assert err == f"pbdag: database {database}\n"  # once
    assert out.startswith("no tokens")


@pytest.fixture
def closed_pipe() -> Iterator[int]:
    """The write end of a pipe whose reader has already gone."""
    read, write = os.pipe()
    os.close(read)
    yield write
    os.close(write)


def test_a_closed_stdout_ends_quietly_with_141(tmp_path: Path, closed_pipe: int) -> None:
    assert pbdag("migrate", cwd=tmp_path).returncode == 0
    done = pbdag("gc", "--dry-run", cwd=tmp_path, stdout=closed_pipe, PBDAG_RAW_RETENTION="1d")
    assert done.returncode == 141, done.stderr
    assert done.stderr.splitlines() == [f"pbdag: database sqlite:///{tmp_path / 'data/pbdag.db'}"]
    helped = pbdag("--help", cwd=tmp_path, stdout=closed_pipe)
    assert (helped.returncode, helped.stderr) == (0, "")  # argparse itself ignores the error


def every_argument(
    parser: argparse.ArgumentParser, path: str = "pbdag"
) -> Iterator[tuple[str, argparse.Action]]:
    """(command path, action) of every option, positional and subcommand group in the tree."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield path, action
            for name, sub in action.choices.items():
                yield from every_argument(sub, f"{path} {name}")
        elif not isinstance(action, argparse._HelpAction):
            yield path, action


def test_every_option_and_positional_has_help() -> None:
    arguments = list(every_argument(build_parser()))
    assert len(arguments) > 60  # the walk reached the subcommands, the plugins' included
    missing = [
        f"{path} {'/'.join(action.option_strings) or action.dest}"
        for path, action in arguments
        if not (action.help or "").strip() or action.help == argparse.SUPPRESS
    ]
    assert missing == []


def test_help_says_what_the_commands_do_and_no_worker_what_it_does(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    top = capsys.readouterr().out
    assert ".py" not in top and "scene-graph memory" in top and "token" in top
    with pytest.raises(SystemExit):
        main(["serve", "--help"])
    serve = " ".join(capsys.readouterr().out.split())
    no_worker = serve[serve.index("--no-worker API only") :][:200]
    assert "no worker in this process" in no_worker and "default: true" not in no_worker


def test_serve_on_a_busy_port_fails_before_announcing_the_api(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = pbdag("serve", "--port", str(port), cwd=tmp_path)
    assert done.returncode == 3
    assert "API on" not in done.stdout
    assert done.stderr.splitlines()[-1].startswith(
        f"pbdag serve: cannot listen on 127.0.0.1:{port}: Address already in use; choose "
        "another with --port or PBDAG_PORT"
    )


def test_the_banner_says_whether_a_browser_may_open_the_docs() -> None:
    locked, open_locally = Settings(), Settings(allow_anonymous_local=True)
    assert "PBDAG_ALLOW_ANONYMOUS_LOCAL=true" in pages(locked)
    assert pages(open_locally) == "docs at /docs, metrics at /metrics"
