"""``fxis cameras`` runs this as a child process: it asks every backend which
cameras it reaches and prints ``{"cameras": [...], "unavailable": {...}}`` as
JSON. A child, so that the camera SDKs load (and may misbehave) outside the CLI."""

from __future__ import annotations

import json

from .backends import discover_all


def main() -> None:
    found, unavailable = discover_all()
    print(json.dumps({"cameras": found, "unavailable": unavailable}))


if __name__ == "__main__":
    main()
