#!/bin/sh
# Installs everything lidar2d needs to build, test and benchmark on Debian 12 (bookworm).
# Each package is used: the libraries by CMakeLists.txt's find_package calls (OpenCV's core and
# imgproc via cmake/OpenCVMinimal.cmake), gtest/gmock by tests/, benchmark by bench/, python3-rosbag
# by tools/make-test-bags.py (test fixtures), chromium by the SLAM report's rendering test,
# pybind11-dev and python3-dev by the Python module (python/), python3-numpy by its arrays,
# python3-distributed by its Dask batch runner (lidar2d.batch), python3-pytest by tests/python,
# ccache by the Makefile (compilation cache, used when present).
# Idempotent: does nothing (not even 'apt-get update') when every package is already installed.
set -eu
PKGS="build-essential make cmake git ccache
  libeigen3-dev libceres-dev libnanoflann-dev
  libopencv-core-dev libopencv-imgproc-dev libpng-dev
  libcli11-dev libfmt-dev libyaml-cpp-dev nlohmann-json3-dev
  zlib1g-dev libbz2-dev liblz4-dev libzstd-dev libsqlite3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-rosbag
  python3-dev pybind11-dev python3-numpy python3-distributed python3-pytest
  chromium"
missing=""
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -z "$missing" ]; then
  echo "install-deps: all packages present"
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing:$missing"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
