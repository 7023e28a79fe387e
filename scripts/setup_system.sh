#!/usr/bin/env bash
# Debian packages SAPIEN needs to render on the CPU (see docs/platform.md):
# Mesa >= 25 lavapipe from bookworm-backports (Debian 12's 22.3 lacks
# descriptorBindingPartiallyBound), the Vulkan loader, and libusb for open3d.
# Idempotent: does nothing when the packages are already installed.
set -euo pipefail
need=()
dpkg-query -W -f='${Status}' libvulkan1 2>/dev/null | grep -q "ok installed" || need+=(libvulkan1)
dpkg-query -W -f='${Status}' libusb-1.0-0 2>/dev/null | grep -q "ok installed" || need+=(libusb-1.0-0)
mesa_ok=0
if dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null | grep -q "bpo"; then mesa_ok=1; fi
if [ ${#need[@]} -eq 0 ] && [ $mesa_ok -eq 1 ]; then
  echo "system packages: already installed"
  exit 0
fi
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
list=/etc/apt/sources.list.d/backports.list
if [ ! -f "$list" ]; then
  echo "deb http://deb.debian.org/debian bookworm-backports main" | $SUDO tee "$list" >/dev/null
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
if [ $mesa_ok -eq 0 ]; then
  $SUDO apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers
fi
if [ ${#need[@]} -gt 0 ]; then
  $SUDO apt-get install -y -qq "${need[@]}"
fi
