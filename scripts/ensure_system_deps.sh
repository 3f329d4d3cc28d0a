#!/usr/bin/env bash
# Debian packages volec needs:
# - libusb-1.0-0: Open3D needs it just to import. Required.
# - chromium: the test that opens report.html in a real browser (tests/test_report.py).
#   Only the tests need it; without it that test is skipped, saying why.
# Installs what is missing when we are root; otherwise says exactly what to install, and fails
# only for what volec itself needs, so the user is not left with an ImportError later.
set -euo pipefail
required=()
for_tests=()
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || required+=(libusb-1.0-0)
command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 \
  || for_tests+=(chromium)
missing=("${required[@]}" "${for_tests[@]}")
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "volec setup: installing Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get install -y -qq "${missing[@]}" >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq "${missing[@]}" >/dev/null; }
elif [ ${#required[@]} -gt 0 ]; then
  echo "volec setup: missing system packages: ${missing[*]}" >&2
  echo "  install them with: sudo apt-get install ${missing[*]}" >&2
  exit 1
else
  echo "volec setup: the browser test will be skipped: install Chromium with" >&2
  echo "  sudo apt-get install ${for_tests[*]}" >&2
fi
