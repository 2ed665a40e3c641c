"""Processing hooks used by the tests (``process=tests.hooks:NAME``)."""

import os
import time

import cv2
import numpy as np

from fxis_shm.formats.stamp import read_stamp, write_stamp


def half_size(image):
    """A new layout: half the size, with the frame id stamped again."""
    frame_id = read_stamp(image)
    small = np.ascontiguousarray(cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2)))
    write_stamp(small, frame_id)
    return small


def even_frames_only(image):
    return image if read_stamp(image) % 2 == 0 else None


def fail_every_third(image):
    if read_stamp(image) % 3 == 0:
        raise RuntimeError("this hook fails on every third frame")
    return image


def slow_60ms(image):
    """Slower than a 20 fps frame period (50 ms): needs 2 processes."""
    time.sleep(0.06)
    return image


PID_ROW = 24  # slow_60ms_pid writes its process id here: between the stamp's first and last row


def slow_60ms_pid(image):
    """slow_60ms, and the id of the process that ran it written into row PID_ROW (4 bytes)."""
    time.sleep(0.06)
    out = image.copy()
    out[PID_ROW, :4] = np.frombuffer(os.getpid().to_bytes(4, "little"), np.uint8)
    return out


def pid_of(image) -> int:
    return int.from_bytes(bytes(image[PID_ROW, :4]), "little")
