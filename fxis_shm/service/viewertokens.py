"""Who may look at the viewers (the dashboard, the Foxglove server) and who may change through
them: the access a viewer process is given, and the token and TLS files behind it, read and
checked here for ``fxis run`` (fxis_shm.service.config) and ``fxis dashboard`` alike."""

from __future__ import annotations

import json
import os
import re
import secrets
import ssl
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

from fxis_shm.errors import ConfigError

VIEWER_ACCESS_ENV = "FXIS_VIEWER_ACCESS"  # how a viewer process learns its token (not argv: ps shows that)
TOKEN_BYTES = 32  # of a random viewer token (secrets.token_urlsafe: 43 characters)
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9._~-]{16,}")  # fits a URL and a cookie as it is


@dataclass(frozen=True)
class ViewerAccess:
    """What a viewer process (dashboard, Foxglove server) is told of who may look: the token
    it requires (None: none) and its TLS certificate and key (None: plain http and ws). It
    travels in the child's environment (VIEWER_ACCESS_ENV), which only its user can read."""

    token: str | None = field(default=None, repr=False)
    tls_cert: str | None = None
    tls_key: str | None = None
    # who may change camera settings through it (service.changers): with an operator token, who
    # sends it; else nobody where read_only (--curve-operators named), else whoever may look
    operator_token: str | None = field(default=None, repr=False)
    read_only: bool = False

    def environment(self) -> dict[str, str]:
        return {VIEWER_ACCESS_ENV: json.dumps(asdict(self))}

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] | None = None) -> ViewerAccess:
        """The access the supervisor gave; ConfigError if it gave none (another install's supervisor)."""
        text = (os.environ if environ is None else environ).get(VIEWER_ACCESS_ENV)
        try:
            return cls(**json.loads(text or ""))
        except (TypeError, ValueError):
            raise ConfigError(f"a viewer needs {VIEWER_ACCESS_ENV} from its supervisor, got {text!r}") from None


def new_token() -> str:
    return secrets.token_urlsafe(TOKEN_BYTES)


def read_token_file(path: str, setting: str = "viewer_token_file") -> str:
    """The token a file holds (surrounding white space dropped); ConfigError unless it is at
    least 16 characters of A-Z a-z 0-9 . _ ~ - (what a URL and a cookie carry as they are)."""
    try:
        with open(path) as f:
            token = f.read().strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{setting} {path}: {getattr(exc, 'strerror', None) or exc}") from None
    if not TOKEN_PATTERN.fullmatch(token):
        raise ConfigError(
            f"{setting} {path}: a token must be at least 16 characters of A-Z a-z 0-9 . _ ~ - "
            f"(make one: python3 -c 'import secrets; print(secrets.token_urlsafe({TOKEN_BYTES}))' > {path})"
        )
    return token


def check_tls_files(cert: str, key: str) -> None:
    """ConfigError unless the certificate and key (PEM) load and match."""
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        context.load_cert_chain(cert, key, password=lambda: b"")  # a key with a passphrase fails, never prompts
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"viewer_tls_cert {cert}, viewer_tls_key {key}: {exc}") from None


def check_viewer_files(token_file: str | None, cert: str | None, key: str | None) -> None:
    """ConfigError unless the token file holds a token and the TLS certificate and key come
    together and load (``fxis run``'s viewers and ``fxis dashboard`` alike)."""
    if token_file:
        read_token_file(token_file)
    if bool(cert) != bool(key):
        raise ConfigError("viewer_tls_cert and viewer_tls_key go together: the certificate (PEM) and its key")
    if cert and key:
        check_tls_files(cert, key)


def viewer_token(token_file: str | None) -> str:
    """The token viewers require: the token file's, else a new random one."""
    return read_token_file(token_file) if token_file else new_token()
