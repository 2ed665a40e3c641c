import numpy as np

from fxis_shm.bufferpool import BufferPool


def test_a_dropped_buffer_is_handed_out_again():
    pool = BufferPool()
    first = pool.take((4, 8), "uint8")
    address = first.ctypes.data
    del first
    again = pool.take((4, 8), "uint8")
    assert again.ctypes.data == address and pool.kept_bytes == 32


def test_a_buffer_still_referenced_is_never_handed_out():
    pool = BufferPool()
    held = [pool.take((4, 8), "uint8") for _ in range(3)]
    view = held[0][1:]  # a view keeps its base alive too
    addresses = {a.ctypes.data for a in held}
    del held[0]
    fresh = pool.take((4, 8), "uint8")
    assert len(addresses) == 3 and fresh.ctypes.data not in addresses
    assert view.base is not None


def test_buffers_come_in_the_asked_shape_and_type():
    pool = BufferPool()
    image = pool.take((3, 5, 3), "uint8")
    deep = pool.take((2, 4), "uint16")
    assert image.shape == (3, 5, 3) and image.dtype == np.uint8
    assert deep.shape == (2, 4) and deep.dtype == np.uint16


def test_beyond_its_budget_the_pool_keeps_nothing_more():
    pool = BufferPool(max_bytes=64)
    held = [pool.take((32,), "uint8") for _ in range(4)]
    assert pool.kept_bytes == 64  # two kept, two one-off allocations
    assert all(a.nbytes == 32 for a in held)
