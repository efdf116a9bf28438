"""All configuration, from PBDAG_* environment variables; nothing else reads the environment."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from service.security_settings import SecuritySettings, with_database_password


class Settings(SecuritySettings):
    """Service settings (environment prefix PBDAG_; security ones in service/security_settings.py)."""

    model_config = SettingsConfigDict(env_prefix="PBDAG_", extra="ignore")

    data_dir: Path = Field(
        Path("./data"), description="Blobs and the default SQLite database live here."
    )
    database_url: str | None = Field(
        None,
        description="SQLAlchemy URL; default sqlite:///<data_dir>/pbdag.db. PostgreSQL: postgresql+psycopg://...",
    )
    max_body_bytes: int = Field(
        64 * 1024 * 1024, description="Largest accepted request body (413 beyond)."
    )
    lease_seconds: float = Field(
        60.0, description="How long a worker owns a claimed batch before it is requeued."
    )
    max_attempts: int = Field(
        5, description="A batch that fails this many times is parked as dead."
    )
    snapshot_interval: int = Field(
        1000, description="Store a state snapshot every this many events."
    )
    worker_poll_seconds: float = Field(0.05, description="Idle worker polling period.")
    state_cache_scenes: int = Field(
        64, description="Scene states a worker keeps in memory between batches."
    )

    def resolved_database_url(self) -> str:
        """The database URL, defaulting to the SQLite file under the data directory."""
        if self.database_url:
            return with_database_password(self.database_url, self.database_password)
        return f"sqlite:///{(self.data_dir / 'pbdag.db').resolve()}"
