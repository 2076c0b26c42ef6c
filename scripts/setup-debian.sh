#!/usr/bin/env bash
# Installs every Debian package M3DP needs to build, test and run its demos, and keeps the ones
# whose updates change how our files are read at Debian's current version, so that every machine
# (a developer's, CI's, a fresh one) reads files the same way. Needs root (or sudo). Idempotent:
# with everything installed and current it changes nothing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build ccache pkg-config
  libeigen3-dev libtbb-dev libfmt-dev libspdlog-dev libpugixml-dev zlib1g-dev libdeflate-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev
  # Surface reconstruction: OpenVDB sparse grids (its CMake config also needs Boost.Iostreams).
  libopenvdb-dev libboost-iostreams-dev
  # The rigid world: DART with Bullet collision (meshes of printed material) and its URDF loader (robots).
  libdart-dev libdart-collision-bullet-dev libdart-external-ikfast-dev libdart-utils-urdf-dev
  # ParaView's pvpython reads our .pvd/.vtu files back in the end-to-end tests.
  paraview python3-paraview python3
  # Recordings: Foxglove's messages as protobuf (protoc makes the code and the schemas' descriptors),
  # MCAP chunks compressed with zstd; the live stream's WebSocket server (websocketpp on asio).
  protobuf-compiler libprotobuf-dev libzstd-dev libwebsocketpp-dev libasio-dev
  # Node for the readers we did not write (the MCAP reader, the Foxglove schemas; npm ci below).
  nodejs
  # Cameras: Embree ray casting; images as PNG (libpng), read back in the tests by PIL, numpy and
  # ImageMagick's identify.
  libembree-dev libpng-dev python3-pil python3-numpy imagemagick
  # The Python API (import m3dp): pybind11 and numpy; its tests run with pytest.
  pybind11-dev python3-dev python3-pytest
  # The browser viewer's tests: Debian's Chromium, headless (puppeteer-core drives it; npm ci below).
  chromium
  # Real slicers with their printer profiles: the G-code reader's test slices with both.
  prusa-slicer slic3r
  # Plots of studies (scripts/plot_deposition.py, m3dp study) with a real plotting library.
  python3-matplotlib
  # Studies of many runs (m3dp study): Dask's local and remote clusters, SciPy's Latin hypercube and
  # Sobol samples, results in HDF5, and a progress bar.
  python3-dask python3-distributed python3-scipy python3-h5py python3-tqdm
  # The readers fuzzed with libFuzzer under AddressSanitizer and UndefinedBehaviorSanitizer (scripts/fuzz.sh).
  clang libclang-rt-14-dev
)
# Kept at the candidate version: ParaView and the XML parser under its readers. Debian 12's expat
# security update 2.5.0-1+deb12u5 made ParaView 5.11 unable to read raw appended VTK data; a machine
# with an older expat would pass tests that fail on a fresh one.
current=(libexpat1 paraview python3-paraview)

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
export DEBIAN_FRONTEND=noninteractive

# Empty when not installed or unknown (never a failure: the script runs under set -e and pipefail).
installed_version() { { dpkg-query -W -f='${Status} ${Version}' "$1" 2>/dev/null || true; } | sed -n 's/^install ok installed //p'; }
candidate_version() { { apt-cache policy "$1" 2>/dev/null || true; } | sed -n 's/^ *Candidate: //p'; }

# The package lists decide what "current" means: refresh them when they are over a day old.
lists_age_days() {
  local newest
  newest=$({ find /var/lib/apt/lists -maxdepth 1 -name '*Packages*' -printf '%T@\n' 2>/dev/null || true; } | sort -n | tail -n 1)
  if [ -z "$newest" ]; then echo 999; else echo $(( ($(date +%s) - ${newest%.*}) / 86400 )); fi
}
lists_refreshed=false
if [ "$(lists_age_days)" -ge 1 ]; then
  if "${sudo_cmd[@]}" apt-get update -qq; then
    lists_refreshed=true
  else
    echo "setup: warning: apt-get update failed; checking against the package lists this machine has" >&2
  fi
fi

wanted=()
for package in "${packages[@]}"; do
  [ -n "$(installed_version "$package")" ] || wanted+=("$package")
done
for package in "${current[@]}"; do
  have=$(installed_version "$package")
  candidate=$(candidate_version "$package")
  if [ -n "$have" ] && [ -n "$candidate" ] && [ "$candidate" != "(none)" ] && [ "$have" != "$candidate" ]; then
    echo "setup: $package $have is older than Debian's current $candidate: upgrading it"
    wanted+=("$package")
  fi
done

# npm: Debian's package, unless the installed Node brings its own (NodeSource's does, and conflicts with it).
command -v npm > /dev/null || [ -n "$(installed_version npm)" ] || wanted+=(npm)

if [ ${#wanted[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} Debian packages installed, ${current[*]} at Debian's current versions"
else
  echo "setup: installing ${wanted[*]}"
  $lists_refreshed || "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${wanted[@]}"
fi

# The npm packages the tests read our files with, exactly as package-lock.json pins them; again
# only when the lockfile changed since the last install (npm ci removes node_modules first).
cd "$(dirname "$0")/.."
if [ node_modules/.m3dp-installed -nt package-lock.json ]; then
  echo "setup: npm packages installed as package-lock.json pins them"
else
  npm ci --no-audit --no-fund --loglevel=error
  touch node_modules/.m3dp-installed
fi
