#!/usr/bin/env bash
# Install the Debian/Ubuntu packages gesture_sim needs, when they are missing.
# Usage: tools/install_system_deps.sh PKG...
# As root, missing packages are installed with apt-get; otherwise the exact command is printed
# and the script fails, so that `make` stops with a clear message.
set -euo pipefail
missing=()
for pkg in "$@"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "gesture_sim: missing system packages (${missing[*]}) and no apt-get here; install their equivalents by hand." >&2
    exit 1
fi
if [ "$(id -u)" -eq 0 ]; then
    echo "gesture_sim: installing system packages: ${missing[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
    echo "gesture_sim: missing system packages. Run:  sudo apt-get install -y ${missing[*]}" >&2
    exit 1
fi
