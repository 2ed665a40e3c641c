"""ROS 2's rules for topic names and namespaces, as rcl and rmw check them, and the names DDS
gives ROS topics and types.

A name a ROS node would refuse is refused here first, at start-up, with the rule it breaks
(the rules and their order are rmw's ``rmw_validate_full_topic_name`` and
``rmw_validate_namespace``; rcl's ``rcl_validate_topic_name`` adds nothing for the plain names
used here):

* a fully qualified topic name starts with ``/``, does not end with ``/``, holds only ASCII
  letters, digits, ``_`` and ``/``, has no ``//`` and no token that starts with a digit, and is
  at most 247 characters (rmw's ``RMW_TOPIC_MAX_NAME_LENGTH``: an implementation limit of 255,
  less 8 kept for prefixes such as ``rt/``);
* a namespace follows the same rules, at most 245 characters (room for ``/x`` after it);
  ``/`` is the root namespace, given back as ``""`` so that ``namespace + "/cam0"`` works. A
  namespace without its leading ``/`` gets one, as ``rcl_node_init`` does; a trailing ``/`` is
  refused, as rmw refuses it.

The design article's advice against ``__`` and a trailing ``_`` is not enforced by rcl, so not
here either; the ``~`` and ``{}`` substitutions are not supported (refused as characters).
Topics are built with :func:`topic` (relative names in a namespace) or :func:`join` (relative
names under a topic), every part checked.

Pure: strings in, strings out, ``InvalidArgument`` (a ValueError) naming the rule broken.
"""

from __future__ import annotations

import re

from fxis_shm.errors import InvalidArgument

MAX_TOPIC_LENGTH = 255 - 8
MAX_NAMESPACE_LENGTH = MAX_TOPIC_LENGTH - 2
DDS_TOPIC_PREFIX = "rt"  # rmw's prefix for topics ("rq"/"rr" are services' requests and replies)

_NOT_ALLOWED = re.compile(r"[^A-Za-z0-9_/]")
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_NOT_IN_TOKEN = re.compile(r"[^A-Za-z0-9_]")


def _broken(what: str, name: str, rule: str) -> InvalidArgument:
    return InvalidArgument(f"{what} {name!r} {rule}")


def _check_absolute(name: str, what: str, max_length: int) -> str:
    """rmw's checks of a fully qualified name, in rmw's order (the length last)."""
    if not name:
        raise _broken(what, name, "must not be empty")
    if not name.startswith("/"):
        raise _broken(what, name, "must be absolute: start with '/'")
    if name.endswith("/"):
        raise _broken(what, name, "must not end with '/'")
    bad = _NOT_ALLOWED.search(name)
    if bad:
        raise _broken(what, name, f"must hold only letters, digits, '_' and '/': {bad.group()!r} at {bad.start()}")
    repeated = name.find("//")
    if repeated >= 0:
        raise _broken(what, name, f"must not contain repeated '/' (at {repeated})")
    digit = re.search(r"/[0-9]", name)
    if digit:
        raise _broken(what, name, f"must not have a token that starts with a digit (at {digit.start() + 1})")
    if len(name) > max_length:
        raise _broken(what, name, f"must be at most {max_length} characters long, not {len(name)}")
    return name


def check_topic(name: str) -> str:
    """A fully qualified topic name (``/ns/cam0/image_raw``), unchanged if ROS accepts it."""
    return _check_absolute(name, "topic name", MAX_TOPIC_LENGTH)


def check_namespace(namespace: str) -> str:
    """A namespace normalized: ``""`` for the root (``""`` or ``"/"``), else ``/a/b``.

    ``a/b`` is taken as ``/a/b`` (rcl does the same); ``/a/b/`` is refused (rmw refuses it).
    """
    if namespace in ("", "/"):
        return ""
    if not namespace.startswith("/"):
        namespace = "/" + namespace
    return _check_absolute(namespace, "namespace", MAX_NAMESPACE_LENGTH)


def check_token(token: str, what: str = "name") -> str:
    """One token of a name (a camera name, ``image_raw``): a letter or ``_``, then letters, digits
    and ``_``; unchanged if ROS accepts it."""
    if not token:
        raise _broken(what, token, "must not be empty")
    bad = _NOT_IN_TOKEN.search(token)
    if bad:
        raise _broken(what, token, f"must hold only letters, digits and '_': {bad.group()!r} at {bad.start()}")
    if not _TOKEN.fullmatch(token):
        raise _broken(what, token, "must not start with a digit")
    return token


def check_relative(name: str) -> str:
    """A relative name (``cam0``, ``image_raw/compressed``): tokens joined by single ``/``, each
    checked by :func:`check_token`; unchanged if ROS accepts it."""
    tokens = name.split("/")
    for token in tokens:
        check_token(token, "name" if len(tokens) == 1 else f"name {name!r}: token")
    return name


def topic(namespace: str, *names: str) -> str:
    """The fully qualified topic of relative ``names`` in ``namespace`` (``""``, ``/``, ``a/b``
    and ``/a/b`` as :func:`check_namespace` takes them): ``topic("/cell1", "cam0",
    "image_raw")`` is ``/cell1/cam0/image_raw``; a name may hold several tokens."""
    return _under(check_namespace(namespace), names)


def join(base: str, *names: str) -> str:
    """The topic of relative ``names`` under the fully qualified topic ``base``: ``join("/cam0",
    "image_raw", "compressed")`` is ``/cam0/image_raw/compressed``."""
    return _under(check_topic(base), names)


def _under(prefix: str, names: tuple[str, ...]) -> str:
    if not names:
        raise InvalidArgument(f"a topic under {prefix or '/'!r} needs a name")
    return check_topic("/".join((prefix, *map(check_relative, names))))


def dds_topic_name(ros_topic: str) -> str:
    """The DDS topic rmw uses for a ROS topic: ``/cam0/image_raw`` is ``rt/cam0/image_raw``."""
    return DDS_TOPIC_PREFIX + check_topic(ros_topic)


def dds_type_name(ros_type: str) -> str:
    """The DDS type rmw uses for a ROS type: ``sensor_msgs/msg/Image`` is
    ``sensor_msgs::msg::dds_::Image_``."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(_TOKEN.fullmatch(part) for part in parts):
        raise InvalidArgument(f"ROS type {ros_type!r} must be package/msg/Name")
    package, kind, name = parts
    return f"{package}::{kind}::dds_::{name}_"
