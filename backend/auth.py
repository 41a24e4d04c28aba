"""The API token: from settings, or generated once and kept in the data directory."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

TOKEN_FILE = "api_token"


def load_or_create_token(data_dir: Path, configured: str | None) -> tuple[str, bool]:
    """Return (token, created). A configured token wins; otherwise the one stored in
    ``data_dir/api_token`` (created with mode 0600 on first start)."""
    if configured:
        return configured, False
    path = data_dir / TOKEN_FILE
    if path.exists():
        token = path.read_text().strip()
        if token:
            return token, False
    token = secrets.token_urlsafe(32)
    data_dir.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as fh:
        fh.write(token + "\n")
    return token, True


def token_matches(expected: str, given: str | None) -> bool:
    return given is not None and secrets.compare_digest(expected.encode(), given.encode())
