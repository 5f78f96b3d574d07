#!/usr/bin/env bash
# Installs Debian's chromium for the web panel's browser tests (Playwright drives /usr/bin/chromium;
# Playwright's own browser download cannot work without internet). Idempotent; needs root or sudo.
set -euo pipefail
if [ -x /usr/bin/chromium ]; then exit 0; fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo -n"
command -v apt-get >/dev/null || { echo "install_browser: no apt-get; install chromium yourself (web panel browser tests need /usr/bin/chromium)" >&2; exit 1; }
echo "[bootstrap] installing Debian's chromium for the browser tests"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
