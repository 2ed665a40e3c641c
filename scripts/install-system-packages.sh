#!/usr/bin/env bash
# System packages the service and its tests need, installed when missing:
# - python3-venv, if this Python cannot make a virtualenv;
# - Aravis (GigE Vision / USB3 Vision) with its GObject introspection data, and
#   the headers PyGObject compiles against (the "aravis" extra);
# - aravis-tools, whose arv-fake-gv-camera-0.8 is the GigE Vision camera
#   emulator the backend tests run against; iproute2 for loopback addresses and the
#   emulated hosts (ip netns, veth links, tc's token bucket: tests/hosts.py);
#   util-linux for unshare (a client in its own mount namespace, test_localpath; the
#   emulated hosts' time and mount namespaces);
#   gcc, which builds the ring's memory-ordering helper (fxis_shm/shm/_ordered.c), its seqlock reads
#   (_slotio.c) and the request engine mypyc compiles (setup.py), and python3-dev (Python.h) for them
#   when this Python has no headers of its own;
# - libturbojpeg0, the TurboJPEG library PyTurboJPEG loads (bench/compare/jpeg.py measures it);
# - ffmpeg, the command line bench/video/anchor.py measures our H.264 encoder against;
# - chromium, the headless browser the dashboard's browser test drives
#   (tests/integration/test_dashboard_browser.py);
# - g++, make, libzmq3-dev (libzmq), cppzmq-dev (its C++ header zmq.hpp) and nlohmann-json3-dev
#   (nlohmann/json.hpp): the C++ client of examples/cpp_client/, which
#   tests/integration/test_cpp_client.py builds and runs against a live service.
# Runs as root (or with sudo); does nothing when everything is present.
set -euo pipefail

wanted=(gir1.2-aravis-0.8 aravis-tools libgirepository1.0-dev libcairo2-dev pkg-config iproute2 util-linux gcc libturbojpeg0 ffmpeg chromium
        g++ make libzmq3-dev cppzmq-dev nlohmann-json3-dev)
python3 -c "import venv, ensurepip" 2>/dev/null || wanted+=(python3-venv)
python3 -c "import os, sysconfig; assert os.path.isfile(os.path.join(sysconfig.get_paths()['include'], 'Python.h'))" \
  2>/dev/null || wanted+=(python3-dev)

missing=()
for pkg in "${wanted[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "installing system packages: ${missing[*]}"
$sudo apt-get -o DPkg::Lock::Timeout=600 update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends "${missing[@]}"
