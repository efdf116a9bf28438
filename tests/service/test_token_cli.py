"""`pbdag token create|list|revoke` and the refusal of `pbdag serve` on the LAN without a token."""

from __future__ import annotations

import hashlib
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.auth import create_token, revoke_token, verify_token
from service.auth_cli import access_summary, serve_refusal
from service.bootstrap import build_container
from service.cli import main
from service.settings import Settings
from service.store.tables import api_tokens

REPO = Path(__file__).resolve().parents[2]
TOKEN_LINE = re.compile(r"^pbdag_([0-9a-f]{12})_[A-Za-z0-9_-]{43}$")


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """`pbdag` commands in this test use a fresh SQLite database under a temp dir (created by
    `pbdag migrate`: the token commands refuse a database file that does not exist)."""
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    assert main(["migrate"]) == 0
    return tmp_path


def test_create_list_revoke_round_trip(data_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["token", "create", "--name", "robot-1", "--scope", "read", "--scope", "write"]) == 0
    )
    out, err = capsys.readouterr()
    token = out.strip()
    match = TOKEN_LINE.fullmatch(token)
    assert match, out
    token_id = match.group(1)
    assert "cannot be shown again" in err and "Authorization: Bearer" in err

    engine = build_container(Settings()).engine
    record = verify_token(engine, token)
    assert record is not None and record.scopes == ("read", "write") and record.active

    assert main(["token", "list"]) == 0
    listing = capsys.readouterr().out
    row = next(line for line in listing.splitlines() if line.startswith(token_id))
    assert "robot-1" in row and "read,write" in row and row.rstrip().endswith("-")
    assert token not in listing
    assert hashlib.sha256(token.encode()).hexdigest() not in listing

    assert main(["token", "revoke", token_id]) == 0
    assert "revoked" in capsys.readouterr().out
    assert main(["token", "list"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith(token_id))
    assert re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\s*$", row), row
    record = verify_token(engine, token)
    assert record is not None and not record.active

    assert main(["token", "revoke", "000000000000"]) == 1
    assert "no token" in capsys.readouterr().err


def test_create_needs_a_known_scope(data_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["token", "create", "--name", "x", "--scope", "root"]) == 2
    assert "unknown scopes" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["token", "create", "--name", "x"])  # --scope is required
    engine = build_container(Settings()).engine
    with engine.connect() as connection:
        assert connection.execute(sa.select(sa.func.count()).select_from(api_tokens)).scalar() == 0


def test_list_without_tokens_says_how_to_create_one(
    data_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["token", "list"]) == 0
    assert "pbdag token create" in capsys.readouterr().out


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_serve_on_the_lan_without_a_token_exits_with_instructions(tmp_path: Path) -> None:
    env = {**os.environ, "PBDAG_DATA_DIR": str(tmp_path)}
    env.pop("PBDAG_DATABASE_URL", None)
    port = free_port()
    done = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--host", "0.0.0.0", "--port", str(port)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,  # a server that started would never return: the timeout fails the test
    )
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "refusing to listen on 0.0.0.0" in done.stderr
    assert "pbdag token create --name" in done.stderr
    assert "Authorization: Bearer <token>" in done.stderr
    assert "API on" not in done.stdout  # it stopped before starting the server


def test_serve_refusal_decides_by_loopback_and_active_tokens(tmp_path: Path) -> None:
    engine = build_container(Settings(data_dir=tmp_path)).engine
    for host in ("127.0.0.1", "localhost", "::1"):
        assert serve_refusal(host, engine) is None, host
    for host in ("0.0.0.0", "192.168.1.20", "robot.lan"):
        assert serve_refusal(host, engine) is not None, host
    new = create_token(engine, "robot-1", ["read"])
    assert serve_refusal("0.0.0.0", engine) is None
    revoke_token(engine, new.record.id)
    assert serve_refusal("0.0.0.0", engine) is not None  # only active tokens count


def test_serve_says_when_nobody_could_use_the_api(tmp_path: Path) -> None:
    engine = build_container(Settings(data_dir=tmp_path)).engine
    assert "every request but /healthz will get a 401" in access_summary(engine, False)
    assert "401" not in access_summary(engine, True)
    create_token(engine, "robot-1", ["read"])
    summary = access_summary(engine, False)
    assert "1 active API token(s)" in summary and "401" not in summary
