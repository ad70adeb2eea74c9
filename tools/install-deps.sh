#!/usr/bin/env bash
# Installs the Debian 12 packages spml needs to build, test and run its tools.
# Idempotent: packages already installed are skipped, and apt is not touched at all
# when nothing is missing. --without-torch leaves out LibTorch (then build with
# -DSPML_WITH_TORCH=OFF: everything but the BNN/BaMbANN learners).
set -euo pipefail

packages=(
  build-essential cmake pkg-config ccache
  libmujoco-dev libqhull-dev          # MuJoCo 2.2.2; its CMake config needs qhull's headers
  libeigen3-dev libnlopt-cxx-dev
  libhdf5-dev libmatio-dev
  liblinear-dev libcli11-dev nlohmann-json3-dev
  libtinyxml2-dev                      # editing MJCF files (spml diagnose writes the extended model)
  libopenblas-dev                      # LAPACK for the GP learners
  libgtest-dev libgmock-dev libbenchmark-dev
  pybind11-dev python3-pybind11 python3-dev   # the Python module spml (tools/python)
  libtorch-dev                         # BNN, BaMbANN (learners/torch)
  python3-h5py python3-numpy python3-scipy python3-sklearn python3-matplotlib
  python3-torch                        # the PyTorch peer of the BNN benchmark
  parallel                             # tools/grid.sh: the sharded grid on one machine
)
without_torch=0
for arg in "$@"; do
  case "$arg" in
    --without-torch) without_torch=1 ;;
    *) echo "install-deps.sh: unknown option '$arg'" >&2; exit 2 ;;
  esac
done

missing=()
for p in "${packages[@]}"; do
  [ "$without_torch" = 1 ] && case "$p" in libtorch-dev|python3-torch) continue ;; esac
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
