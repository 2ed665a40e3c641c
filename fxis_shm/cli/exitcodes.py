"""The exit codes every ``fxis`` command follows (docs/cli.md, "Exit codes").

A script can tell from the code alone what happened and whether anything was kept.
"""

from __future__ import annotations

DONE = 0  # the command did all it was asked
MISSING = 1  # done, but some of what was asked is missing (frames gone, a camera down)
USAGE = 2  # bad usage or settings (a flag, a path, a key file, a config): change the command
NO_SERVICE = 3  # a service did not answer (down, wrong endpoint, wrong keys)
FAILED = 4  # anything else went wrong at run time (a full disk, a refusal by the service)
INTERRUPTED = 130  # Ctrl-C or SIGTERM: stopped, with what was kept said on screen (128 + SIGINT)
