# Shared steps of the quick-start and test scripts: install Debian packages, configure, build.
# Sourced, not run. Every step says what it does and stops the script on failure.
set -euo pipefail

HPRAY_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
HPRAY_BUILD="${HPRAY_BUILD:-$HPRAY_ROOT/build}"

# Debian 12 packages the build and the tests need (see shared build notes).
HPRAY_PACKAGES=(
  g++ cmake ninja-build pkg-config
  libopenmpi-dev openmpi-bin
  libeigen3-dev libembree-dev libopenexr-dev libtbb-dev
  libyaml-cpp-dev libpugixml-dev zlib1g-dev libpng-dev
  libcli11-dev nlohmann-json3-dev libboost-dev libcerf-dev
  libgtest-dev libbenchmark-dev libssl-dev libcpp-httplib-dev
  python3-numpy
)
# What the test command needs beyond building: a headless browser and its driver for the
# viewer's browser test (Debian's chromium, driven through python3-selenium).
HPRAY_TEST_PACKAGES=(chromium chromium-driver python3-selenium)

step() { printf '\n==> %s\n' "$*"; }

install_packages() {  # [extra package ...]
  local missing=()
  for p in "${HPRAY_PACKAGES[@]}" "$@"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
      missing+=("$p")
    fi
  done
  if [ ${#missing[@]} -eq 0 ]; then
    step "all $((${#HPRAY_PACKAGES[@]} + $#)) Debian packages already installed"
    return
  fi
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  step "installing ${#missing[@]} Debian packages: ${missing[*]}"
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
}

configure_and_build() {
  step "configuring (Release) in $HPRAY_BUILD"
  cmake -S "$HPRAY_ROOT" -B "$HPRAY_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release
  step "building with $(nproc) jobs"
  cmake --build "$HPRAY_BUILD" -j "$(nproc)"
}

# OpenMPI refuses to run as root and to oversubscribe unless told; tests and jobs on a
# laptop or CI container need both.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_rmaps_base_oversubscribe=1 OMPI_MCA_mpi_yield_when_idle=1

# build_baseline REV: builds the hpray target of revision REV once in a git worktree,
# build-bench/baseline-<sha>, kept for later runs (remove it with `git worktree remove
# --force build-bench/baseline-<sha>`), for benchmarks that time it against the current
# build. Sets BASELINE_BIN and BASELINE_SHA; exits 2 if REV is not a commit.
build_baseline() {
  local rev="$1" jobs="${JOBS:-$(nproc)}"
  BASELINE_SHA="$(git -C "$HPRAY_ROOT" rev-parse --verify --quiet "$rev^{commit}")" || {
    echo "$(basename "$0"): --baseline $rev is not a commit of this repository" >&2
    exit 2
  }
  local dir="$HPRAY_ROOT/build-bench/baseline-${BASELINE_SHA:0:12}"
  BASELINE_BIN="$dir/build/bin/hpray"
  if [ -x "$BASELINE_BIN" ]; then
    step "baseline $rev ($BASELINE_SHA): reusing $BASELINE_BIN"
    return
  fi
  step "building the baseline $rev ($BASELINE_SHA) in $dir"
  if [ ! -f "$dir/CMakeLists.txt" ]; then
    git -C "$HPRAY_ROOT" worktree prune
    rm -rf "$dir"
    mkdir -p "$(dirname "$dir")"
    git -C "$HPRAY_ROOT" worktree add --detach "$dir" "$BASELINE_SHA"
  fi
  cmake -S "$dir" -B "$dir/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DHPRAY_BUILD_TESTS=OFF -DHPRAY_BUILD_BENCHMARKS=OFF > /dev/null
  cmake --build "$dir/build" --target hpray -j "$jobs"
}
