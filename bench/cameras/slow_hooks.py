"""Processing hooks of known cost for bench/cameras/gige.py (``process=slow_hooks:sleep_10ms``) and
bench/cameras/hook_rate.py (``sleep_60ms_pid``); the benchmarks put bench/ on the camera workers' PYTHONPATH."""

import os
import time

COST_S = 0.010


def sleep_10ms(image):
    """Costs 10 ms of wall time (and no CPU) per frame, returns the frame unchanged."""
    time.sleep(COST_S)
    return image


def sleep_60ms_pid(image):
    """Costs 60 ms of wall time (and no CPU) per frame, more than a 20 fps frame period; returns
    a copy with the id of the process that ran it in row 24 (4 bytes, little-endian)."""
    time.sleep(0.060)
    out = image.copy()
    out[24, :4] = list(os.getpid().to_bytes(4, "little"))
    return out
