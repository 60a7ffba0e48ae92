#!/usr/bin/env bash
# Every test: install what is missing, build in Release, run ctest (MPI tests included).
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_packages "${HPRAY_TEST_PACKAGES[@]}"
configure_and_build
step "running every test (ctest, MPI tests with 2 and more ranks)"
cd "$HPRAY_BUILD"
ctest --output-on-failure -j "$(nproc)" --timeout 900
