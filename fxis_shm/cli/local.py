"""``fxis keys``, ``fxis cameras`` and ``fxis clean``: this host only, no service asked."""

from __future__ import annotations

import json
import subprocess
import sys

from fxis_shm.cli.options import timeout_seconds
from fxis_shm.cli.table import aligned
from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.shm import naming
from fxis_shm.wire import defaults


class LookFailed(FxisError):
    """The backends' look for cameras failed or took too long (exit code 4)."""


def checked_name(name: str) -> str:
    """``--name`` as ``run`` and ``clean`` take it: a file or object name, never a path."""
    try:
        return naming.check_name("service", name)
    except ValueError as exc:
        raise ConfigError(f"--name: {exc}") from None


def keys_command(args) -> int:
    from fxis_shm.wire.security import create_keys

    checked_name(args.name)
    public, secret = create_keys(args.out, args.name, force=args.force)
    print(f"wrote {public} (public: give it to the other side) and {secret} (secret: keep it)")
    return 0


def cameras_command(args) -> int:
    from fxis_shm.service.camerakinds import DISCOVERY_MODULE

    try:
        child = subprocess.run(
            [sys.executable, "-m", DISCOVERY_MODULE],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=args.timeout,
        )
    except subprocess.TimeoutExpired:
        raise LookFailed(
            f"the backends did not finish looking within {args.timeout:g} s (give a longer --timeout)"
        ) from None
    if child.returncode != 0:
        last = (child.stderr.strip().splitlines() or ["no message"])[-1]
        raise LookFailed(f"looking for cameras failed (exit code {child.returncode}): {last}")
    listing = json.loads(child.stdout)
    found, unavailable = listing["cameras"], listing["unavailable"]
    if args.json:
        print(json.dumps(listing, indent=2))
        return 0
    if found:
        rows = [["kind", "id (device=...)", "model", "format"]] + [
            [c["kind"], str(c["id"]), str(c.get("model", "-")), str(c.get("format", "-"))] for c in found
        ]
        print("\n".join(aligned(rows)))
    else:
        print("no cameras found")
    for kind, why in unavailable.items():
        print(f"({kind}: not available: {why})")
    return 0


def clean_command(args) -> int:
    from fxis_shm.service.servicelock import service_running

    checked_name(args.name)
    if service_running(args.name):
        raise ConfigError(f"service {args.name!r} is running: stop it first (its shared memory is in use)")
    removed = naming.remove_leftovers(args.name)
    for path in removed:
        print(f"removed {path}")
    if not removed:
        print(f"nothing of service {args.name!r} left in {naming.SHM_DIR}")
    return 0


def add_parsers(sub) -> None:
    keys = sub.add_parser("keys", help="make a CurveZMQ key pair (for a service or a client)")
    keys.add_argument("--out", required=True, metavar="DIR", help="folder to write NAME.key and NAME.key_secret into")
    keys.add_argument("--name", default=defaults.SERVICE, help=f"file name of the pair (default {defaults.SERVICE})")
    keys.add_argument(
        "--force", action="store_true", help="replace a pair of that name already there (its holders are locked out)"
    )
    keys.set_defaults(func=keys_command)

    cameras = sub.add_parser("cameras", help="list the cameras the installed backends can reach")
    cameras.add_argument("--json", action="store_true", help="print the list as JSON")
    cameras.add_argument(
        "--timeout", type=timeout_seconds, default=30.0, help="seconds the backends may take to look (default 30)"
    )
    cameras.set_defaults(func=cameras_command)

    clean = sub.add_parser("clean", help="remove shared memory left by a crashed service")
    clean.add_argument("--name", default=defaults.SERVICE, help=f"service name (default {defaults.SERVICE})")
    clean.set_defaults(func=clean_command)
