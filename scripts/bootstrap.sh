#!/usr/bin/env bash
# Installs, through apt, every Debian package phos needs to build, test and
# benchmark. Called by the Makefile before every configure; does nothing (and
# needs no network) when everything is already installed.
#   bootstrap.sh        everything (make build, test, bench, fuzz)
#   bootstrap.sh demo   what the Release build and the demo need (make demo):
#                       not the test suite's browser, Slurm cluster and clang
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build pkg-config git
  # model / fit: Ceres with Eigen, OpenCV for image regions
  libceres-dev libeigen3-dev libopencv-dev
  # acquire: Aravis (GigE Vision / USB3 Vision) and its tools, libgpiod v1.6
  libaravis-dev aravis-tools libusb-1.0-0-dev zlib1g-dev libgpiod-dev
  # render: Embree 3, OpenImageIO (+ OpenEXR), TBB
  libembree-dev libopenimageio-dev openimageio-tools libopenexr-dev libtbb-dev
  # render: mesh loaders (OBJ, glTF 2.0)
  libtinyobjloader-dev libtinygltf-dev libstb-dev
  # session records: XXH3 checksums of frame files
  libxxhash-dev
  # contact-sheet labels
  fonts-dejavu-core
  # JSON, command line, HTTP (editor)
  nlohmann-json3-dev libcli11-dev libcpp-httplib-dev
  # tests and benchmarks (the configure step finds them, make demo included)
  libgtest-dev libgmock-dev libbenchmark-dev
  # the demo's gallery page (scripts/gallery.py) and the README test (scripts/readme_check.py)
  python3
)
# Only the tests, the fuzzing and the formatting use these.
TEST_PACKAGES=(
  # the fuzz harnesses (fuzz/): clang 14 with libFuzzer and the sanitizer runtimes
  clang libclang-rt-14-dev
  # make format (.clang-format)
  clang-format
  # the editor page's browser test (Playwright drives Debian's Chromium)
  chromium nodejs
  # phos slurm's test runs a one-node Slurm cluster (munged, slurmctld, slurmd)
  slurm-wlm munge
)

if [ "${1:-}" != demo ]; then PACKAGES+=("${TEST_PACKAGES[@]}"); fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "bootstrap: installing ${#missing[@]} missing package(s): ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "bootstrap: need root (or sudo) to install: ${missing[*]}" >&2; exit 2
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "bootstrap: done"
