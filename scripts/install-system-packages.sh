#!/usr/bin/env bash
# System packages the service and its tests need, installed when missing.
# Runs as root (or with sudo); does nothing when everything is present.
set -euo pipefail

packages=()
python3 -c "import venv, ensurepip" 2>/dev/null || packages+=(python3-venv)

if [ ${#packages[@]} -eq 0 ]; then
  exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "installing system packages: ${packages[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${packages[@]}"
