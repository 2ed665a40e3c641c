import numpy as np

from fxis_shm.shm.bufferpool import BufferPool, release


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


def test_a_view_of_a_dropped_array_keeps_its_buffer_leased():
    pool = BufferPool()
    image = pool.take((4, 8), "uint8")
    row = image[1]
    address = image.ctypes.data
    del image
    assert pool.leased == 1 and pool.take((4, 8), "uint8").ctypes.data != address
    del row
    assert any(pool.take((4, 8), "uint8").ctypes.data == address for _ in range(2))


def test_release_gives_a_buffer_back_at_once_and_only_once():
    pool = BufferPool()
    image = pool.take((4, 8), "uint8")
    assert release(image) is True and pool.leased == 0
    assert release(image) is False  # already back
    again = pool.take((4, 8), "uint8")
    assert again.ctypes.data == image.ctypes.data
    assert release(np.zeros(3)) is False  # not a pool's: nothing to give back


def test_arrays_held_across_many_takes_are_never_handed_out_twice():
    pool = BufferPool()
    held = []
    for n in range(200):
        image = pool.take((16, 16), "uint8")
        image.fill(n % 256)
        if n % 3 == 0:
            held.append((n, image))  # kept; the others are dropped and come back
    assert all(int(image[0, 0]) == n % 256 and (image == image[0, 0]).all() for n, image in held)
    assert len({image.ctypes.data for _, image in held}) == len(held)


def test_an_array_outlives_its_pool():
    pool = BufferPool()
    image = pool.take((4, 8), "uint8")
    image.fill(7)
    del pool
    assert (image == 7).all()
