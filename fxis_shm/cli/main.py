"""The ``fxis`` command's parser and entry point."""

from __future__ import annotations

import argparse
import sys

from fxis_shm.cli import dashboard, local, query, record, run, snapshot, tune
from fxis_shm.cli.options import EXIT_USAGE
from fxis_shm.errors import ConfigError, FxisError


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="fxis", description="Multi-camera acquisition service: synchronized images on request."
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run.add_parser(sub)
    query.add_parsers(sub)
    record.add_parser(sub)
    snapshot.add_parser(sub)
    dashboard.add_parser(sub)
    local.add_parsers(sub)
    tune.add_parsers(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as exc:  # a bad option, file or key: the user's to fix
        print(f"fxis {args.command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except FxisError as exc:
        print(f"fxis {args.command}: {exc}", file=sys.stderr)
        return 1
