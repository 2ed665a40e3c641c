#!/usr/bin/env bash
# Runs the ring's memory-ordering tests on an emulated aarch64 (ARM64) CPU, where the
# seqlock needs the fences of fxis_shm/shm/_ordered.c (docs/design.md, "Memory ordering").
# The emulated run is not part of `make test` (about 25 minutes; root for apt, mounts, chroot);
# its --quick mode below is.
#
# How: Debian's qemu-user-static runs aarch64 binaries through binfmt_misc; mmdebstrap
# makes a Debian arm64 root (python3, gcc) in $FXIS_AARCH64_ROOT, kept between runs;
# PyPI's aarch64 wheels go into a venv there; this tree is copied in and installed,
# which compiles the helper for aarch64. No foreign architecture is added to this
# machine's dpkg. Remove the root with `rm -rf` (nothing stays mounted after a run).
#
# Usage: scripts/test-aarch64.sh [--quick] [pytest arguments]  (default: the tests below)
#   --quick: the same checks on this machine's own CPU with this checkout's .venv, without
#   qemu and without root, in seconds; `make test` runs it, so that the script cannot rot
#   unnoticed between the runs on the emulated CPU (tests/unit/test_scripts.py checks the
#   modules its Python imports and the test files it names).
set -euo pipefail

ROOT=${FXIS_AARCH64_ROOT:-/var/tmp/fxis-aarch64-root}
SRC=$(cd "$(dirname "$0")/.." && pwd)
QUICK=0
if [ "${1:-}" = --quick ]; then QUICK=1; shift; fi

# The ring tests, the stamp that detects torn frames, the local path (clients copying from
# the rings under the seqlock), the slot records' reads and the compiled read of the common
# requests. Not run: the torn-read stress, whose frames-served floor (> 1000 in 8 x 150 tries
# against a 500 fps writer) an emulated CPU does not reach; run it with
# `scripts/test-aarch64.sh tests/integration/test_faults.py -k torn`.
TESTS=(tests/unit/test_ordering.py tests/integration/test_ring.py tests/unit/test_stamp.py
       tests/integration/test_localpath.py tests/unit/test_slotio.py tests/integration/test_compiledread.py)
[ $# -eq 0 ] || TESTS=("$@")

step() { echo "== $*"; }

# The machine is the one expected ($1), the helper's fences are in use, and asking for plain
# accesses (FXIS_PLAIN_ORDERING=1) gives $2: plain ones only where they are correct (x86),
# the fences still elsewhere. The rest of the arguments: how to run python there.
check_ordering() {
  local machine=$1 plain=$2
  shift 2
  "$@" python -c '
import platform, subprocess, sys
from fxis_shm.shm import ordering
machine, expected_plain = sys.argv[1:]
plain = subprocess.run([sys.executable, "-c", "from fxis_shm.shm import ordering; print(ordering.MODE)"],
                       env={"FXIS_PLAIN_ORDERING": "1"}, capture_output=True, text=True, check=True).stdout.strip()
print(f"machine={platform.machine()} python={platform.python_version()} MODE={ordering.MODE} "
      f"MODE with FXIS_PLAIN_ORDERING=1: {plain}")
assert platform.machine() == machine and ordering.MODE == "fenced" and plain == expected_plain' "$machine" "$plain"
}

run_tests() {  # the arguments: how to run python in the tree
  step "pytest ${TESTS[*]}"
  "$@" python -m pytest -p no:cacheprovider "${TESTS[@]}"
}

if [ "$QUICK" -eq 1 ]; then
  here() { (cd "$SRC" && PATH="$SRC/.venv/bin:$PATH" "$@"); }
  case $(uname -m) in x86_64 | amd64 | i386 | i686) plain=x86-tso ;; *) plain=fenced ;; esac
  step "quick: the ordering mode and the tests on this machine's CPU, $(uname -m) (no qemu)"
  check_ordering "$(uname -m)" "$plain" here
  run_tests here
  exit 0
fi

[ "$(id -u)" -eq 0 ] || { echo "scripts/test-aarch64.sh: run as root (apt, mounts, chroot)" >&2; exit 2; }

wanted=(qemu-user-static binfmt-support mmdebstrap arch-test)
missing=()
for pkg in "${wanted[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  step "installing ${missing[*]}"
  apt-get -o DPkg::Lock::Timeout=600 update -qq
  DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends "${missing[@]}"
fi

# Containers often start without binfmt_misc mounted; the F flag of Debian's entry
# lets the emulator run binaries inside the chroot.
mountpoint -q /proc/sys/fs/binfmt_misc || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
update-binfmts --enable qemu-aarch64 >/dev/null 2>&1 || true
arch-test arm64 >/dev/null || { echo "aarch64 binaries cannot be run here (binfmt_misc/qemu)" >&2; exit 1; }

in_root() { chroot "$ROOT" env -i PATH=/opt/venv/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root \
  PIP_DISABLE_PIP_VERSION_CHECK=1 "$@"; }

# mount: test_localpath gives a client its own /dev/shm (mount in a private namespace).
root_packages=(python3 python3-venv python3-dev gcc libc6-dev ca-certificates mount)
if [ ! -x "$ROOT/usr/bin/python3" ]; then
  step "making a Debian arm64 root in $ROOT"
  sources=()  # this machine's Debian mirror; mmdebstrap's default otherwise
  for f in /etc/apt/sources.list.d/debian.sources /etc/apt/sources.list; do
    [ -s "$f" ] && { sources=("$f"); break; }
  done
  rm -rf "$ROOT"
  mmdebstrap --arch=arm64 --variant=apt --include="$(IFS=,; echo "${root_packages[*]}")" \
    bookworm "$ROOT" "${sources[@]}" </dev/null
fi
if ! in_root dpkg-query -W "${root_packages[@]}" >/dev/null 2>&1; then  # a root made by an older script
  step "installing ${root_packages[*]} in $ROOT"
  cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
  in_root apt-get update -qq
  in_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${root_packages[@]}"
fi
# Trust what this machine trusts (a proxy's CA, if any) and resolve names the same way.
cp /usr/local/share/ca-certificates/*.crt "$ROOT/usr/local/share/ca-certificates/" 2>/dev/null || true
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
in_root update-ca-certificates >/dev/null

# The root is bound onto itself so that it is a mount point (`unshare --propagation
# private`, used by test_localpath, needs one); /dev/shm is this machine's, so anything a
# test left behind is seen here.
mounted=()
unmount() {  # a service process may still be exiting when pytest returns: wait up to 30 s
  for _ in $(seq 60); do umount "$1" 2>/dev/null && return 0; sleep 0.5; done
  umount "$1"
}
cleanup() { for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do unmount "${mounted[i]}" || true; done; }
trap cleanup EXIT
mount --bind "$ROOT" "$ROOT" && mounted+=("$ROOT")
mount -t proc proc "$ROOT/proc" && mounted+=("$ROOT/proc")
mount --bind /dev "$ROOT/dev" && mounted+=("$ROOT/dev")
mount --bind /dev/shm "$ROOT/dev/shm" && mounted+=("$ROOT/dev/shm")

step "copying $SRC (tracked and new files) to $ROOT/src and installing it with its test extra"
rm -rf "$ROOT/src" && mkdir "$ROOT/src"
git -C "$SRC" ls-files -co --exclude-standard -z | (cd "$SRC" && tar --null -T - -cf -) | tar -xf - -C "$ROOT/src"
[ -x "$ROOT/opt/venv/bin/python" ] || in_root python3 -m venv /opt/venv
in_root sh -c 'cd /src && pip install --quiet -e ".[test]"'

step "the helper's instructions and the ordering mode on the emulated CPU"
in_root sh -c 'objdump -d /src/fxis_shm/shm/_ordered.*.so | grep -E "<(load_acquire|store_release|fence_acquire|fence_release)>:|ldar|stlr|dmb"'
check_ordering aarch64 fenced in_root
in_tree() { in_root sh -c 'cd /src && exec env FXIS_EMULATED_CPU=1 "$@"' sh "$@"; }  # (test_compiledread.py)
run_tests in_tree
