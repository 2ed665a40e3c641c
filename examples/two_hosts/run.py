"""Try the two-host cell on this machine: two emulated camera hosts, each with a clock of its
own, behind 1 Gbit links (tests/hosts.py: network namespaces on TEST-NET-2 addresses, time
namespaces, their own /dev/shm), CurveZMQ keys, and cell.py as the vision node here.

    sudo .venv/bin/python examples/two_hosts/run.py            # needs root (namespaces)
    sudo .venv/bin/python examples/two_hosts/run.py --encoding jpeg -n 10

It prints every command it runs: on real hosts you run the same ones (README.md). Everything
it made (namespaces, links, keys, services) is removed when it ends, also on Ctrl-C.
Exit status: that of cell.py; 1 if the hosts or services could not be started.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))  # the repository: tests.hosts

from fxis_shm.errors import FxisError  # noqa: E402
from fxis_shm.service.launch import ServiceProcess  # noqa: E402
from fxis_shm.wire.security import ClientKeys  # noqa: E402
from tests.hosts import HostsUnavailable, Lab  # noqa: E402

FXIS = [sys.executable, "-m", "fxis_shm.cli"]


def show_and_run(argv: list[str], where: str = "vision node") -> subprocess.CompletedProcess:
    print(f"[{where}] $ {shlex.join(['fxis', *argv[3:]] if argv[:3] == FXIS else argv)}", flush=True)
    return subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", type=int, default=5, help="tuples cell.py requests (default 5)")
    p.add_argument("--encoding", choices=("raw", "jpeg", "png"), default="raw")
    p.add_argument("--width", type=int, default=1360)
    p.add_argument("--height", type=int, default=1024)
    p.add_argument("--rate", default="1gbit", help="link rate, tc's syntax (default 1gbit)")
    args = p.parse_args(argv)

    work = tempfile.mkdtemp(prefix="fxis-two-hosts-")
    services = []
    try:
        with Lab(log_dir=work) as lab:
            keys, allowed = os.path.join(work, "keys"), os.path.join(work, "allowed")
            show_and_run([*FXIS, "keys", "--out", keys, "--name", "server"])
            show_and_run([*FXIS, "keys", "--out", keys, "--name", "vision"])
            os.makedirs(allowed)
            shutil.copy(os.path.join(keys, "vision.key"), allowed)  # copy it to every camera host
            print(f"[vision node] $ cp {keys}/vision.key {allowed}/", flush=True)
            client_keys = ClientKeys.from_files(
                os.path.join(keys, "server.key"), os.path.join(keys, "vision.key_secret")
            )
            endpoints = []
            for label, offset, camera in (("A", 1000, "left"), ("B", 2000, "right")):
                host = lab.host(clock_offset_s=offset, rate=args.rate)
                endpoint, pub, events = host.endpoints(5555)
                run_args = [
                    "--camera",
                    f"{camera}=synthetic:width={args.width},height={args.height}",
                    "--curve-secret",
                    os.path.join(keys, "server.key_secret"),
                    "--curve-clients",
                    allowed,
                ]
                svc = ServiceProcess(
                    run_args,
                    name=f"cell{label}",
                    endpoint=endpoint,
                    pub=pub,
                    events=events,
                    stderr=open(os.path.join(work, f"host{label}.log"), "wb"),
                    client_keys=client_keys,
                    wrapper=host.wrapper(),
                )
                services.append(svc)
                host.services.append(svc)  # the lab stops it before it removes the host
                print(
                    f"[camera host {label}: {host.address}, clock {offset} s ahead, {args.rate}] $ "
                    + shlex.join(["fxis", "run", *svc.args]),
                    flush=True,
                )
                svc.start()
                endpoints.append(endpoint)
            cell = [
                sys.executable,
                str(HERE / "cell.py"),
                *endpoints,
                "--server-key",
                os.path.join(keys, "server.key"),
                "--client-key",
                os.path.join(keys, "vision.key_secret"),
                "-n",
                str(args.n),
                "--encoding",
                args.encoding,
            ]
            print(f"[vision node] $ {shlex.join(['python', 'examples/two_hosts/cell.py', *cell[2:]])}", flush=True)
            return subprocess.run(cell).returncode
    except (HostsUnavailable, FxisError, subprocess.CalledProcessError) as exc:
        print(f"FAIL: {exc}")
        return 1
    except KeyboardInterrupt:
        print("interrupted")
        return 130
    finally:
        for svc in services:
            svc.stderr.close()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
