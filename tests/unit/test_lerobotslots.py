"""The slot grid of ``fxis export --lerobot`` (fxis_shm.record.lerobotslots), in virtual time:
capture times in, kept and dropped slots out."""

from fxis_shm.record.lerobotslots import slot_grid, typical_period_ns

MS = 1_000_000
PERIOD = 33 * MS


def frames(start_ms: float, count: int, skip: range = range(0)) -> list[int]:
    return [round(start_ms * MS) + i * PERIOD for i in range(count) if i not in skip]


def test_every_slot_of_cameras_in_step_is_kept_with_the_joint_tuple():
    grid = slot_grid({"a": frames(0, 30), "b": frames(5, 30)}, 1e9 / PERIOD, 10 * MS)
    assert grid.dropped == 0 and grid.total == len(grid.slots) == 29  # b starts 5 ms late: slot 0 at b's first
    for n, slot in enumerate(grid.slots):
        assert slot.k == n and slot.index == {"a": n, "b": n} and slot.skew_ns == 5 * MS


def test_a_gap_in_one_camera_drops_its_slots_and_never_reuses_an_old_frame():
    grid = slot_grid({"a": frames(0, 30), "b": frames(2, 30, skip=range(10, 15))}, 1e9 / PERIOD, 10 * MS)
    assert grid.total == 29 and grid.dropped_far == 5 and len(grid.slots) == 24  # slots 10 to 14: b's gap
    assert [s.k for s in grid.slots if 9 <= s.k <= 15] == [9, 15]
    used = [s.index["b"] for s in grid.slots]
    assert len(set(used)) == len(used)


def test_a_tuple_over_the_skew_bound_is_dropped_not_kept():
    grid = slot_grid({"a": frames(0, 10), "b": frames(12, 10)}, 1e9 / PERIOD, 10 * MS)
    assert grid.slots == [] and grid.dropped_skew == grid.total == 9


def test_a_slower_grid_than_the_cameras_keeps_the_nearest_tuple_of_each_slot():
    grid = slot_grid({"a": frames(0, 31), "b": frames(1, 31)}, 1e9 / (3 * PERIOD), 5 * MS)
    assert grid.dropped == 0 and [s.index["a"] for s in grid.slots] == [0, 3, 6, 9, 12, 15, 18, 21, 24, 27]


def test_the_typical_period_is_the_median_gap():
    assert typical_period_ns([0, 10, 20, 100, 110]) == 10
    assert typical_period_ns([5]) == 0
