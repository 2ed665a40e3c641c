"""``python -m fxis_shm.cli``: the fxis command."""

import sys

from fxis_shm.cli.main import main

sys.exit(main())
