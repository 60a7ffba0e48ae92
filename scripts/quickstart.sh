#!/usr/bin/env bash
# Quick start: install what is missing, build in Release, run the main job on built-in data.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_packages
configure_and_build
cd "$HPRAY_ROOT"
step "running: hpray info builtin:nk-sinc"
"$HPRAY_BUILD/bin/hpray" info builtin:nk-sinc
step "running: hpray render configs/quickstart.yaml (writes out/quickstart.{exr,png,json})"
"$HPRAY_BUILD/bin/hpray" render configs/quickstart.yaml
step "done"
