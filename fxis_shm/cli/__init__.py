"""The ``fxis`` command: one module per group of commands, ``main`` in fxis_shm.cli.main.

    run                        the service (cli/run.py)
    status, grab               ask a running service (cli/query.py)
    record                     a rosbag2 bag (cli/record.py)
    keys, cameras, clean       this host only (cli/local.py)

Commands that talk to a service share their options (endpoint, timeout, CurveZMQ keys) in
cli/options.py.
"""

from fxis_shm.cli.main import main, parser

__all__ = ["main", "parser"]
