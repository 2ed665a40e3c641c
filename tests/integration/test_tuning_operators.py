"""Who may change camera settings: with --curve-operators, only the keys in that folder (let in
too); every client the service lets in may read them. Without it, every client may change."""

import pytest

from fxis_shm import Client
from fxis_shm.errors import ServiceError

from ..conftest import fxis
from .conftest import SMALL, client_keys

pytestmark = pytest.mark.integration


def test_only_operators_change_settings_and_everyone_let_in_reads_them(start_service, keys, tmp_path):
    folder, allowed = keys
    assert fxis("keys", "--out", str(folder), "--name", "operator").returncode == 0
    operators = tmp_path / "operators"
    operators.mkdir()
    (operators / "operator.key").write_bytes((folder / "operator.key").read_bytes())
    svc = start_service(
        "--camera",
        f"a=synthetic:fps=50,{SMALL}",
        "--curve-secret",
        str(folder / "server.key_secret"),
        "--curve-clients",
        str(allowed),
        "--curve-operators",
        str(operators),
        client_keys=client_keys(folder, "alice"),
    )
    with (
        Client(svc.endpoint, timeout=15, keys=client_keys(folder, "alice")) as alice,
        Client(svc.endpoint, timeout=15, keys=client_keys(folder, "operator")) as operator,
    ):
        assert alice.settings("a")["values"]["gain"] == 0.0  # reading is open to every client let in
        with pytest.raises(ServiceError) as refused:
            alice.configure("a", gain=6)
        assert refused.value.code == "FORBIDDEN" and "--curve-operators" in refused.value.message
        assert "add this client's public key" in refused.value.message
        assert operator.configure("a", gain=6)["changed"] == {"gain": 6.0}  # an operator, let in by that alone
        assert alice.settings("a")["values"]["gain"] == 6.0
        assert alice.image("a").camera == "a"  # the refusal changed nothing else


def test_operators_need_curvezmq(tmp_path):
    from ..conftest import fxis_run_alone

    (tmp_path / "op.key").write_text("")
    done = fxis_run_alone("--camera", f"a=synthetic:{SMALL}", "--curve-operators", str(tmp_path))
    assert done.returncode != 0 and "curve_operators needs curve_secret and curve_clients" in done.stderr
