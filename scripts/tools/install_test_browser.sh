#!/usr/bin/env bash
# Install the browser that the live view's browser test drives: Debian's Chromium, run
# headless (test/integration/test_live_view_browser.py). Does nothing when `chromium` is
# already on PATH. Needs root (or sudo) and Debian's package archive.
#
#   scripts/tools/install_test_browser.sh
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
  exit 0
fi
SUDO=""
if [[ "$(id -u)" != 0 ]]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO="sudo -n"
  else
    echo "install_test_browser: chromium is missing and this user cannot install packages" >&2
    exit 1
  fi
fi
echo "[install_test_browser] apt-get install chromium"
export DEBIAN_FRONTEND=noninteractive
timeout 600 $SUDO apt-get update -qq
timeout 900 $SUDO apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null
command -v chromium >/dev/null 2>&1 || { echo "install_test_browser: chromium still missing" >&2; exit 1; }
chromium --version
