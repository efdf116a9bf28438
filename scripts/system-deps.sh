#!/usr/bin/env bash
# Install the system libraries open3d needs (libusb, libgomp) when they are missing.
set -euo pipefail
missing=()
ldconfig -p | grep -q 'libusb-1.0.so.0' || missing+=(libusb-1.0-0)
ldconfig -p | grep -q 'libgomp.so.1' || missing+=(libgomp1)
[ ${#missing[@]} -eq 0 ] && exit 0
echo "installing system libraries: ${missing[*]}"
sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
