"""``Client([a, b])`` answers whatever ``Client(a)`` does (issue 21, item 2). The operations
with parameters are written once, in fxis_shm.client.api.ClientApi, and a client class that
redefines one is refused when it is made (issue 37): that is tested first. The method sets and
their parameters are still compared, for what each kind declares itself (status, clocks, ...)."""

import inspect

import pytest

from fxis_shm import Client
from fxis_shm.client.api import SHARED_OPERATIONS, ClientApi
from fxis_shm.client.multiclient import MultiClient
from fxis_shm.client.single import SingleClient

# Where the multi-service client must say more than the one-service one, and why.
EXTRA_PARAMETERS = {"clock_estimate": {"service"}}  # which service's clock: there are several


def _public(cls) -> dict:
    return {
        name: member
        for name, member in inspect.getmembers(cls)
        if not name.startswith("_") and (callable(member) or isinstance(member, property))
    }


def test_both_kinds_of_client_take_the_shared_operations_from_one_declaration():
    for name in SHARED_OPERATIONS:
        assert getattr(SingleClient, name) is getattr(MultiClient, name) is getattr(ClientApi, name), name


@pytest.mark.parametrize("name", SHARED_OPERATIONS)
def test_a_client_class_that_redefines_a_shared_operation_is_refused(name):
    with pytest.raises(TypeError, match=f"redefines \\['{name}'\\]"):
        type("Drifting", (MultiClient,), {name: lambda self, extra=None: None})


def test_the_multi_service_client_has_every_public_method_and_property_of_client():
    single, multi = _public(Client), _public(MultiClient)
    assert sorted(set(single) - set(multi)) == []
    assert {n for n, m in single.items() if isinstance(m, property)} <= {
        n for n, m in multi.items() if isinstance(m, property)
    }


def test_each_method_takes_the_same_parameters_in_the_same_order():
    multi = _public(MultiClient)
    for name, method in _public(Client).items():
        if isinstance(method, property):
            continue
        ours = list(inspect.signature(method).parameters)
        theirs = [p for p in inspect.signature(multi[name]).parameters if p not in EXTRA_PARAMETERS.get(name, ())]
        assert ours == theirs, name
