"""Processing hooks of known cost for bench/gige.py (``process=gige_hooks:sleep_10ms``;
the benchmark puts bench/ on the camera workers' PYTHONPATH)."""

import time

COST_S = 0.010


def sleep_10ms(image):
    """Costs 10 ms of wall time (and no CPU) per frame, returns the frame unchanged."""
    time.sleep(COST_S)
    return image
