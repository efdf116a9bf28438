"""The security part of the settings (PBDAG_*), and secret files (Docker secrets) as a source.

`service.settings.Settings` inherits these fields: there is still one settings class.
"""

from __future__ import annotations

import ipaddress
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import (
    BaseSettings,
    NoDecode,
    PydanticBaseSettingsSource,
    SecretsSettingsSource,
    SettingsConfigDict,
)

# Docker and Compose mount secrets here; a file named like the variable (pbdag_database_url,
# pbdag_database_password, ...) sets that setting. Environment variables take precedence.
SECRETS_DIR = Path("/run/secrets")
LOOPBACK_HOSTS = ("localhost", "127.0.0.1", "::1")


class SecuritySettings(BaseSettings):
    """Authentication, allowed Host names, CORS, rate limits, secrets (environment prefix PBDAG_)."""

    model_config = SettingsConfigDict(secrets_dir=SECRETS_DIR)

    allow_anonymous_local: bool = Field(
        False,
        description=(
            "Requests from a loopback address (127.0.0.0/8, ::1) need no token and may read and "
            "write (never admin). Never enable it behind a reverse proxy on the same host."
        ),
    )
    allowed_hosts: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: list(LOOPBACK_HOSTS),
        description=(
            "Host header names accepted (comma-separated; `*.example.org` and `*` allowed); "
            "others get a 400. `pbdag serve --host H` adds H."
        ),
    )
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="Browser origins allowed to call the API (comma-separated); none by default.",
    )
    trusted_proxies: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description=(
            "Reverse proxies (IP addresses or CIDR networks, comma-separated) whose "
            "X-Forwarded-For names the client; none by default: the client is the socket's peer."
        ),
    )
    rate_limit_per_minute: int = Field(
        1200,
        ge=0,
        description="Requests per minute per token (per address when anonymous), per process; 0 is no limit.",
    )
    rate_limit_burst: int = Field(
        200, ge=1, description="Requests a client may send at once before the rate applies."
    )
    database_password: SecretStr | None = Field(
        None,
        description="Password put into PBDAG_DATABASE_URL when the URL has none (e.g. a Docker secret).",
    )

    @field_validator("allowed_hosts", "cors_origins", "trusted_proxies", mode="before")
    @classmethod
    def _comma_separated(cls, value: object) -> object:
        """Accept `a,b` (and a JSON list) from the environment."""
        if isinstance(value, str):
            text = value.strip()
            if text.startswith("["):
                return json.loads(text)
            return [item.strip() for item in text.split(",") if item.strip()]
        return value

    @field_validator("trusted_proxies")
    @classmethod
    def _addresses_or_networks(cls, value: list[str]) -> list[str]:
        """Each entry an IP address or a network (host bits allowed: `10.1.2.3/8` is
        `10.0.0.0/8`), in canonical form; a name or `*` is an error, not a proxy trusted."""
        canonical = []
        for entry in value:
            try:
                if "/" in entry:
                    canonical.append(str(ipaddress.ip_network(entry, strict=False)))
                else:
                    canonical.append(str(ipaddress.ip_address(entry)))
            except ValueError:
                raise ValueError(f"{entry!r} is not an IP address or a CIDR network") from None
        return canonical

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        """The default sources, reading only secret directories that exist (outside Docker
        /run/secrets usually does not, and pydantic-settings would warn about it)."""
        if isinstance(file_secret_settings, SecretsSettingsSource):
            file_secret_settings.secrets_dir = _existing_directories(
                file_secret_settings.secrets_dir
            )
        return init_settings, env_settings, dotenv_settings, file_secret_settings


def _existing_directories(
    configured: str | Path | Sequence[str | Path] | None,
) -> list[Path] | None:
    if configured is None:
        return None
    candidates = [configured] if isinstance(configured, (str, Path)) else list(configured)
    existing = [Path(path) for path in candidates if Path(path).expanduser().is_dir()]
    return existing or None


def with_database_password(url: str, password: SecretStr | None) -> str:
    """`url` with `password` filled in, unless it is unset or the URL already carries one."""
    if password is None:
        return url
    from sqlalchemy import make_url  # here: reading settings should not import SQLAlchemy

    parsed = make_url(url)
    if parsed.password is not None or parsed.drivername.startswith("sqlite"):
        return url
    return parsed.set(password=password.get_secret_value()).render_as_string(hide_password=False)
