"""The ``fxis`` command's parser and entry point, and the one place its errors become a line
and an exit code (fxis_shm.cli.exitcodes, docs/cli.md): every failure a user can cause is
``fxis COMMAND: what is wrong; what to change`` on stderr, without a traceback unless
``--debug`` or ``FXIS_DEBUG=1`` asks for it."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import traceback
from typing import NoReturn

from fxis_shm.cli import dashboard, exitcodes, export, local, query, record, run, snapshot, syncreport, tune, view

DEBUG_ENV = "FXIS_DEBUG"


class Parser(argparse.ArgumentParser):
    """argparse's parser, with a usage error as one line (``fxis CMD: ...``, code 2) instead of
    the usage block and ``error:``; ``--help`` still shows the usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(exitcodes.USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


def parser() -> argparse.ArgumentParser:
    p = Parser(prog="fxis", description="Multi-camera acquisition service: synchronized images on request.")
    debug_help = f"show the traceback of an error (or set {DEBUG_ENV}=1)"
    p.add_argument("--debug", action="store_true", help=debug_help)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run.add_parser(sub)
    query.add_parsers(sub)
    record.add_parser(sub)
    snapshot.add_parser(sub)
    export.add_parser(sub)
    syncreport.add_parser(sub)
    dashboard.add_parser(sub)
    view.add_parser(sub)
    local.add_parsers(sub)
    tune.add_parsers(sub)
    for command in sub.choices.values():  # --debug after the command too (SUPPRESS: keeps one given before)
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=debug_help)
    return p


def _interrupted(signum, frame) -> NoReturn:
    raise KeyboardInterrupt


def _quiet_stdout() -> None:
    """stdout onto /dev/null: what is still buffered for a reader that left goes nowhere, silently."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def main(argv: list[str] | None = None) -> int:
    top = parser()
    args, extra = top.parse_known_args(argv)
    if extra:  # said by the command's parser: "fxis get: unrecognized arguments ...", as its other usage errors
        (sub,) = [a for a in top._actions if isinstance(a, argparse._SubParsersAction)]
        sub.choices[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    # SIGTERM ends a command as Ctrl-C does (code 130); a command with handlers of its own
    # (fxis run, record) sets them over this one
    in_main = threading.current_thread() is threading.main_thread()  # where Python handles signals
    previous = signal.signal(signal.SIGTERM, _interrupted) if in_main else None
    try:
        code = args.func(args)
        sys.stdout.flush()  # a reader that went away is found here, not in the interpreter's exit
        return code
    except BrokenPipeError:  # the reader of stdout went away (fxis get --json | head -2): not an error
        _quiet_stdout()
        return exitcodes.DONE
    except SystemExit:
        raise
    except BaseException as exc:
        code = exitcodes.for_error(exc)
        if code is None:  # not a failure a user can cause: a bug, with its traceback for the report
            traceback.print_exc()
            print(f"fxis {args.command}: {exitcodes.message(exc)} (a bug: please report it)", file=sys.stderr)
            return exitcodes.FAILED
        if args.debug or os.environ.get(DEBUG_ENV) == "1":
            traceback.print_exc()
        print(f"fxis {args.command}: {exitcodes.message(exc)}", file=sys.stderr)
        return code
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)
