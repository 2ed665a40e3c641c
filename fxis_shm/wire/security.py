"""CurveZMQ authentication and encryption, and the loopback-only default.

Keys are pyzmq/ZeroMQ certificate files: ``NAME.key`` holds a public key,
``NAME.key_secret`` the public and secret key. ``fxis keys`` makes them. A
service given a secret key and a folder of client public keys accepts only
those clients; every socket of it (requests, publish, events) is a CURVE
server. Clients (Client, Subscriber, EventPublisher) take the server's public
key and their own key pair.
"""

from __future__ import annotations

import ipaddress
import os
import shutil
from dataclasses import dataclass
from urllib.parse import urlsplit

import zmq
import zmq.auth

from fxis_shm.errors import ConfigError


def create_keys(folder: str, name: str, *, force: bool = False) -> tuple[str, str]:
    """Write NAME.key and NAME.key_secret into ``folder`` (0700); returns their paths. A pair
    already there is replaced only with ``force``: every copy of it handed out would stop working."""
    if not name or name in (".", "..") or "/" in name or "\0" in name or len(name.encode()) > 200:
        raise ConfigError(f"--name {name!r}: a key pair's name is a file name (no '/', at most 200 bytes)")
    paths = [os.path.join(folder, f"{name}.key{suffix}") for suffix in ("", "_secret")]
    there = [p for p in paths if os.path.lexists(p)]
    if there and not force:
        raise ConfigError(
            f"{' and '.join(there)} exist: replacing them locks out every side that holds them; "
            "give another --name, or --force to replace them"
        )
    made = not os.path.exists(folder)
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
        public, secret = zmq.auth.create_certificates(folder, name)
        os.chmod(secret, 0o600)
    except OSError as exc:
        if made:  # a folder this call made stays only with the pair in it
            shutil.rmtree(folder, ignore_errors=True)
        raise ConfigError(
            f"cannot write keys into {folder}: {exc.strerror}; give a folder this user can write to"
        ) from None
    return public, secret


def _certificate(path: str) -> tuple[bytes, bytes | None]:
    try:
        return zmq.auth.load_certificate(path)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cannot read the key file {path}: {exc}") from None


def load_public(path: str) -> bytes:
    public, _ = _certificate(path)
    return public


def load_pair(path: str) -> tuple[bytes, bytes]:
    """(public, secret) from a NAME.key_secret file."""
    public, secret = _certificate(path)
    if secret is None:
        raise ConfigError(f"{path} holds no secret key (use the .key_secret file)")
    return public, secret


@dataclass(frozen=True)
class ClientKeys:
    """What a client needs for a CURVE service: the server's public key and its own pair."""

    server_public: bytes
    public: bytes
    secret: bytes

    @classmethod
    def from_files(cls, server_key: str, client_secret: str) -> ClientKeys:
        return cls(load_public(server_key), *load_pair(client_secret))

    def apply(self, sock: zmq.Socket[bytes]) -> None:
        sock.curve_serverkey = self.server_public
        sock.curve_publickey = self.public
        sock.curve_secretkey = self.secret


def make_server(sock: zmq.Socket[bytes], public: bytes, secret: bytes) -> None:
    sock.curve_server = True
    sock.curve_publickey = public
    sock.curve_secretkey = secret


def is_loopback(endpoint: str) -> bool:
    """True for ipc:// endpoints and tcp:// endpoints on a loopback address."""
    if endpoint.startswith("ipc://"):
        return True
    host = urlsplit(endpoint.replace("tcp://", "tcp://", 1)).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # an interface name or a hostname: assume it is reachable from outside
