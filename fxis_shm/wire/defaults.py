"""The defaults of the service and of its clients, written once: the config,
the command line's help, the client and the subscriber refer to these (the
request defaults a config may change are core.requestdefaults)."""

from __future__ import annotations

SERVICE = "fxis"  # names the shared memory, the lock and the key files
ENDPOINT = "tcp://127.0.0.1:5555"  # requests and replies (the coordinator's ROUTER)
PUB = "tcp://127.0.0.1:5556"  # streams and answers to request events (XPUB)
EVENTS = "tcp://127.0.0.1:5557"  # request events (SUB)
SLOTS = 20  # frames held per camera ring
CAMERAS = ("cam0=synthetic", "cam1=synthetic")  # when neither the config nor flags name any
RESTART_LIMIT = 5  # restarts of one process within RESTART_WINDOW_S before the supervisor gives up on it
RESTART_WINDOW_S = 600.0  # the crashes of the last 10 minutes count; older ones are forgiven
LOG_LEVEL = "INFO"
HTTP = "127.0.0.1:8080"  # the live dashboard (fxis_shm.viewers.dashboard)
HTTP_OFF = "off"  # no dashboard
