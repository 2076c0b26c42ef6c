#!/usr/bin/env bash
# Installs every Debian package M3DP needs to build, test and run its demos.
# Idempotent: packages already present are skipped by apt. Needs root (or sudo).
set -euo pipefail

packages=(
  build-essential cmake ninja-build ccache pkg-config
  libeigen3-dev libtbb-dev libfmt-dev libspdlog-dev libpugixml-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev
  # Surface reconstruction: OpenVDB sparse grids (its CMake config also needs Boost.Iostreams).
  libopenvdb-dev libboost-iostreams-dev
  # The rigid world: DART with Bullet collision (meshes of printed material) and its URDF loader (robots).
  libdart-dev libdart-collision-bullet-dev libdart-external-ikfast-dev libdart-utils-urdf-dev
  # ParaView's pvpython reads our .pvd/.vtu files back in the end-to-end test.
  paraview python3-paraview python3
)

missing=()
for package in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$package")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} Debian packages already installed"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi

echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
