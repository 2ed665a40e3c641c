"""Drawing free TCP ports (fxis_shm.service.launch): each process its own part of the span, and
no port it drew lately drawn again, so launchers in processes running at once never draw the
same port (a drawn port stays free until its service binds it)."""

import pytest

from fxis_shm.service import launch


@pytest.fixture
def part():
    """Restores this process's part (the suite's conftest chose it) and its recent draws."""
    before, recent = launch._part, list(launch._recent)
    yield
    launch._part = before
    launch._recent.clear()
    launch._recent.extend(recent)


def test_each_part_draws_only_its_own_ports_and_the_parts_do_not_overlap(part):
    drawn = {}
    for index in range(8):
        launch.draw_from_part(index, 8)
        drawn[index] = {launch.free_tcp_port() for _ in range(50)}
    for index, ports in drawn.items():
        launch.draw_from_part(index, 8)
        low, high = launch._part_bounds()
        assert all(low <= port < high for port in ports)
        assert high <= launch._ephemeral_start()  # never a port the kernel gives outgoing connections
    assert all(drawn[a].isdisjoint(drawn[b]) for a in drawn for b in drawn if a < b)


def test_a_port_drawn_lately_is_not_drawn_again(part):
    launch.draw_from_part(3, 8)
    ports = [launch.free_tcp_port() for _ in range(200)]
    assert len(set(ports)) == 200  # free all along (none bound), and yet never drawn twice


@pytest.mark.parametrize("index, parts", [(8, 8), (-1, 8), (0, 0)])
def test_a_part_outside_the_span_is_refused(part, index, parts):
    with pytest.raises(ValueError, match="expected 0 <= index < parts"):
        launch.draw_from_part(index, parts)
