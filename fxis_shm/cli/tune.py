"""``fxis get`` and ``fxis set``: read and change a camera's settings while the service runs
(docs/protocol.md 7.8); ``--save`` writes what the camera took into the config file."""

from __future__ import annotations

import json

from fxis_shm.cli import exitcodes
from fxis_shm.cli.options import add_client_options, client_for
from fxis_shm.core.tuning import UNCHANGED, limits_text
from fxis_shm.errors import ConfigError
from fxis_shm.service.configedit import camera_table, save_camera_values


def parse_assignment(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` with VALUE a number, true/false, or else a string."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"expected KEY=VALUE, got {text!r}")
    raw = raw.strip()
    value: object = raw
    if raw.lower() in ("true", "false"):
        value = raw.lower() == "true"
    else:
        for kind in (int, float):
            try:
                value = kind(raw)
                break
            except ValueError:
                continue
    return key.strip(), value


def _limits_line(key: str, value, limits: dict) -> str:
    described = {"value": value, **limits}
    extra = "read-only" if limits["access"] != "rw" else f"{limits['cost']}, {limits_text(described)}"
    return f"  {key:<24} {value!s:<14} ({limits['type']}, {extra})"


def _feature_line(feature: dict) -> str:
    shown = {k: feature[k] for k in ("min", "max", "inc", "choices", "unit") if feature.get(k) is not None}
    limits = limits_text({"type": feature.get("type", ""), **shown}) if shown else ""
    name, kind, access = feature["name"], feature.get("type", ""), feature.get("access", "")
    return f"  {name:<32} {kind:<8} {access:<3} {limits:<28} {feature.get('value', '')}"


def get_command(args) -> int:
    with client_for(args) as client:  # an error: its line and code (fxis_shm.cli.main, ERROR_TABLE)
        answer = client.settings(args.camera, features=args.features)
    keys = args.keys or list(answer["values"])
    unknown = [k for k in keys if k not in answer["values"]]
    if unknown:
        exitcodes.say(
            "get", f"camera {args.camera!r} has no setting {', '.join(unknown)}; it has {', '.join(answer['values'])}"
        )
        return exitcodes.USAGE
    if args.json:
        print(json.dumps({**answer, "values": {k: answer["values"][k] for k in keys}}, indent=2))
        return exitcodes.DONE
    if args.keys and len(keys) == 1 and not args.features:  # one value, for scripts
        print(answer["values"][keys[0]])
        return exitcodes.DONE
    print(f"camera {args.camera!r} (generation {answer['generation']}):")
    for key in keys:
        print(_limits_line(key, answer["values"][key], answer["limits"][key]))
    if args.features:
        print(f"features of its node map ({len(answer.get('features', []))}):")
        for feature in answer.get("features", []):
            print(_feature_line(feature))
    return exitcodes.DONE


def set_command(args) -> int:
    values = dict(parse_assignment(a) for a in args.assignments)
    if args.save and not args.config:
        raise ConfigError("--save writes into the service's config file: give it with --config FILE")
    if args.save:  # before the change: a change that cannot be saved is not made
        camera_table(args.config, args.camera)
    with client_for(args) as client:  # a refused value: SettingRejected, code 2 (ERROR_TABLE)
        answer = client.configure(args.camera, **values)
    if args.save:
        save_camera_values(args.config, args.camera, answer["changed"], given=values)
    if args.json:
        print(json.dumps(answer, indent=2))
        return exitcodes.DONE
    took = " ".join(f"{k}={v}" for k, v in answer["changed"].items())
    how = {"live": "live", UNCHANGED: "unchanged: the camera has these values"}.get(
        answer["cost"], f"the stream restarted, generation {answer['generation']}"
    )
    saved = f"; saved in {args.config}" if args.save else ""
    print(f"camera {args.camera!r}: {took} ({how}){saved}")
    return exitcodes.DONE


def add_parsers(sub) -> None:
    get = sub.add_parser("get", help="show a camera's settings, their limits and what a change costs")
    add_client_options(get)
    get.add_argument("camera", help="the camera")
    get.add_argument("keys", nargs="*", metavar="KEY", help="only these settings (one: its value alone)")
    get.add_argument("--features", action="store_true", help="also list every feature of its GenICam node map")
    get.add_argument("--json", action="store_true", help="print the answer as JSON")
    get.set_defaults(func=get_command)

    set_ = sub.add_parser("set", help="change a camera's settings while it runs (all or none)")
    add_client_options(set_)
    set_.add_argument("camera", help="the camera")
    set_.add_argument("assignments", nargs="+", metavar="KEY=VALUE", help="e.g. exposure_us=2000 gain=6")
    set_.add_argument(
        "--save", action="store_true", help="also write what the camera took into the --config file's [cameras.NAME]"
    )
    set_.add_argument("--json", action="store_true", help="print the answer as JSON")
    set_.set_defaults(func=set_command)
