"""The local fast path: clients on the service's kernel copy frames out of the rings.

Torn copies on this path are covered by tests/integration/test_faults.py
(test_torn_reads_never_reach_a_client[require]).
"""

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from fxis_shm import Client, LocalPathUnavailable, read_stamp
from fxis_shm.errors import FxisError

from ..conftest import wait_until
from .conftest import SMALL
from .frozen import frozen

pytestmark = pytest.mark.integration


def test_a_local_client_copies_the_frames_the_service_would_send(two_cameras):
    with Client(two_cameras.endpoint, local="auto") as local, Client(two_cameras.endpoint, local="off") as remote:
        wait_until(lambda: local.status()["cameras"]["cam1"].get("frames_stored", 0) > 3)
        # the workers stopped for the two requests: a frame a held-up worker stored between them
        # (make test: frame 10 after 9) would be nearer to t* for the second only
        with frozen(local, "cam0", "cam1"):
            by_ring = local.tuple()
            t_star = by_ring.t_request
            by_wire = remote.tuple(at=t_star)
    assert by_ring.path == "local" and by_wire.path == "network"
    assert local.paths["local"] == 1 and local.local_unavailable is None
    for cam in ("cam0", "cam1"):
        assert by_ring[cam].path == "local"
        assert by_ring[cam].frame_id == by_wire[cam].frame_id  # the same selection for the same t*
        assert read_stamp(by_ring[cam].image) == by_ring[cam].frame_id
        np.testing.assert_array_equal(by_ring[cam].image, by_wire[cam].image)
        assert by_ring[cam].image.flags.writeable  # a copy of its own
        assert by_ring[cam].still_valid()


def test_every_frame_op_takes_the_local_path(two_cameras):
    with Client(two_cameras.endpoint, local="require") as client:
        frame = client.image("cam0")
        latest = client.latest()
        seq = client.sequence("consecutive", camera="cam1", count=3)
    assert frame.path == "local" and read_stamp(frame.image) == frame.frame_id
    assert latest.path == "local" and set(latest) == {"cam0", "cam1"}
    assert [f.path for f in seq] == ["local"] * 3
    assert [f.frame_id for f in seq] == list(range(seq[0].frame_id, seq[0].frame_id + 3))
    assert all(read_stamp(f.image) == f.frame_id for f in seq)


def test_every_local_request_is_validated_like_the_services(two_cameras):
    """The local path validates each form of request once, then only its times: a value equal
    to an accepted one but of another type (1 for True) is still refused, as are bad times."""
    with Client(two_cameras.endpoint, local="require") as client:
        assert client.tuple(partial=True).path == "local"
        with pytest.raises(FxisError, match="partial"):
            client._read_locally("tuple", 0.0, True, {"partial": 1})
        with pytest.raises(FxisError, match="at"):
            client._read_locally("tuple", 0.0, True, {"at": "soon"})
        with pytest.raises(FxisError, match="sync"):
            client.tuple(sync="bogus")
        assert client.tuple(at=client.time() - 50_000_000, partial=True).path == "local"


def test_arrays_handed_out_are_never_reused_while_held(two_cameras):
    """The client recycles its buffers only once the caller dropped them."""
    with Client(two_cameras.endpoint, local="require") as client:
        held = [client.image("cam0") for _ in range(30)]
        wait_until(lambda: client.image("cam0").frame_id > held[-1].frame_id + 2)
        for _ in range(30):
            client.image("cam0")  # recycles only the buffers of the dropped frames
    assert all(read_stamp(f.image) == f.frame_id for f in held)
    assert len({f.image.ctypes.data for f in held}) == len(held)


def test_a_zero_copy_view_says_when_the_ring_overwrote_it(start_service):
    svc = start_service("--slots", "3", "--camera", f"fast=synthetic:fps=200,{SMALL}")
    with svc.client() as client:
        wait_until(lambda: client.status()["cameras"]["fast"].get("frames_stored", 0) > 3)
    with Client(svc.endpoint, local="require") as client:
        copied = client.image("fast")
        view = client.image("fast", copy=False)
        assert view.path == "local" and not view.image.flags.writeable
        assert read_stamp(view.image) == view.frame_id or not view.still_valid()
        wait_until(lambda: not view.still_valid(), timeout=5, what="the slot to be overwritten")
        assert copied.still_valid()  # a copy is the caller's for ever
        assert read_stamp(copied.image) == copied.frame_id


def test_a_client_on_another_kernel_gets_the_pixels_in_the_reply(two_cameras):
    """A remote client sends its own kernel's boot id; the service sends pixels then."""
    with Client(two_cameras.endpoint, local="auto") as client:
        client._boot_id = "another-kernel"  # what a client on another host would send
        got = client.tuple()
        assert got.path == "network" and client.paths["network"] == 1
        assert client.local_unavailable == "the service runs on another kernel"
        assert all(read_stamp(f.image) == f.frame_id for f in got.values())
        client._boot_id = "another-kernel"
        client.local = "require"
        client._local_off = None
        with pytest.raises(LocalPathUnavailable, match="another kernel"):
            client.tuple()


# A client in its own mount namespace with a private /dev/shm: same kernel (same
# boot id, so the service replies with ring references), but the rings are not
# there, or a segment of that name is not the service's ring.
_PRIVATE_SHM_CLIENT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from fxis_shm import Client, LocalPathUnavailable, read_stamp
    from fxis_shm.shm.ring import FrameLayout, RingWriter
    endpoint, service, impostor = sys.argv[1], sys.argv[2], sys.argv[3] == "impostor"
    if impostor:  # a ring of the same name, written by someone else
        writer = RingWriter(service, "cam0", FrameLayout(48, 64), 4)
        writer.write(np.zeros((48, 64), np.uint8), 0, 0)
    out = {}
    with Client(endpoint, local="auto") as client:
        t = client.tuple()
        out["path"] = t.path
        out["stamps_ok"] = all(read_stamp(f.image) == f.frame_id for f in t.values())
        out["why"] = client.local_unavailable
        out["second_path"] = client.tuple().path  # stays on the network for a while
    with Client(endpoint, local="require") as client:
        try:
            client.tuple()
            out["require"] = "no error"
        except LocalPathUnavailable as exc:
            out["require"] = str(exc)
    print(json.dumps(out))
""")


@pytest.mark.parametrize("impostor", [False, True], ids=["no-rings", "impostor-ring"])
def test_a_client_that_cannot_read_the_rings_falls_back_to_the_network(two_cameras, impostor):
    shell = 'mount -t tmpfs -o size=16m tmpfs /dev/shm && exec "$0" "$@"'
    done = subprocess.run(
        [
            "unshare",
            "--mount",
            "--propagation",
            "private",
            "sh",
            "-c",
            shell,
            sys.executable,
            "-c",
            _PRIVATE_SHM_CLIENT,
            two_cameras.endpoint,
            two_cameras.name,
            "impostor" if impostor else "-",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr  # as root with util-linux (make test installs it)
    out = json.loads(done.stdout)
    assert out["path"] == "network" and out["second_path"] == "network"
    assert out["stamps_ok"]
    reason = "is not the service's ring" if impostor else "does not exist"
    assert reason in out["why"]
    assert "local fast path cannot be used" in out["require"] and reason in out["require"]


def test_the_service_says_how_its_rings_are_ordered(two_cameras):
    from fxis_shm.shm import ordering

    with Client(two_cameras.endpoint) as client:
        assert client.status()["ring_ordering"] == ordering.MODE == "fenced"  # the install built the helper


def test_a_released_frame_gives_its_buffer_back_and_cannot_be_used_after(two_cameras):
    from fxis_shm import FxisError

    with Client(two_cameras.endpoint, local="require") as client:
        with client.image("cam0") as frame:
            assert read_stamp(frame.image) == frame.frame_id
            address = frame.image.ctypes.data
        with pytest.raises(FxisError, match="was released"):
            _ = frame.image.shape
        held = client.image("cam0")  # held: not released, still referenced
        assert held.image.ctypes.data == address  # the released buffer, reused at once
        with client.tuple() as pair:
            pass
        assert read_stamp(held.image) == held.frame_id  # never overwritten while held
        assert "released" in repr(pair["cam1"].image)
