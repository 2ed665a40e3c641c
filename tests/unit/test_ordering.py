import mmap
import platform
import subprocess
import sys

import pytest

from fxis_shm.shm import ordering


@pytest.mark.parametrize(
    "machine,built,plain,expected",
    [
        ("x86_64", True, False, "fenced"),
        ("x86_64", False, False, "x86-tso"),
        ("x86_64", True, True, "x86-tso"),
        ("aarch64", True, False, "fenced"),
        ("aarch64", True, True, "fenced"),  # never plain on a weak CPU
        ("aarch64", False, False, None),
        ("armv7l", False, True, None),
    ],
)
def test_plain_accesses_only_where_the_cpu_orders_them(machine, built, plain, expected):
    assert ordering.choose_mode(built, machine, plain) == expected


def test_words_round_trip_through_a_shared_mapping():
    mm = mmap.mmap(-1, 4096)
    try:
        for value, offset in ((0, 0), (1, 8), (2**64 - 1, 1024), (123456789012345, 4088)):
            ordering.store_release(mm, offset, value)
            assert ordering.load_acquire(mm, offset) == value
            assert int.from_bytes(mm[offset : offset + 8], "little") == value
        ordering.fence_acquire()
        ordering.fence_release()
    finally:
        mm.close()


@pytest.mark.skipif(ordering.MODE != "fenced", reason="the helper is not built here")
def test_the_helper_refuses_unaligned_or_outside_words():
    from fxis_shm.shm import _ordered

    mm = mmap.mmap(-1, 64)
    try:
        for offset in (-8, 3, 60, 64):
            with pytest.raises(ValueError, match="aligned 8-byte word"):
                _ordered.load_acquire(mm, offset)
        ro = mmap.mmap(-1, 64, prot=mmap.PROT_READ)
        with pytest.raises(BufferError):
            _ordered.store_release(ro, 0, 1)  # a reader's mapping cannot be written
        ro.close()
    finally:
        mm.close()


def test_plain_accesses_can_be_chosen_to_measure_them_on_x86_only():
    out = subprocess.run(
        [sys.executable, "-c", "from fxis_shm.shm import ordering; print(ordering.MODE)"],
        capture_output=True,
        text=True,
        env={"FXIS_PLAIN_ORDERING": "1", "PATH": ""},
        check=True,
    )
    # x86-64 orders plain accesses itself; elsewhere (scripts/test-aarch64.sh) asking for them changes nothing
    expected = "x86-tso" if platform.machine() in ("x86_64", "AMD64") else "fenced"
    assert out.stdout.strip() == expected
