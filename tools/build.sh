#!/usr/bin/env bash
# Installs missing Debian packages, configures (Release) and builds spml into build/.
# Extra arguments go to CMake's configure step, e.g. tools/build.sh -DSPML_WITH_TORCH=OFF
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$@"
cmake --build build -j"$(nproc)"
