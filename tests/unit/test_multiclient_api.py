"""``Client([a, b])`` answers whatever ``Client(a)`` does (issue 21, item 2): the two method
sets and their parameters are compared here, so they cannot drift apart again."""

import inspect

from fxis_shm import Client
from fxis_shm.client.multiclient import MultiClient

# Where the multi-service client must say more than the one-service one, and why.
EXTRA_PARAMETERS = {"clock_estimate": {"service"}}  # which service's clock: there are several


def _public(cls) -> dict:
    return {
        name: member
        for name, member in inspect.getmembers(cls)
        if not name.startswith("_") and (callable(member) or isinstance(member, property))
    }


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
