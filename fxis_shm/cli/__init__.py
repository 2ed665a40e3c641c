"""The ``fxis`` command, a module per group of commands (run, query, record, snapshot, local; options
for those that talk to a service). The top layer: may import every layer below."""

from fxis_shm.cli.main import main, parser

__all__ = ["main", "parser"]
