#!/usr/bin/env bash
# Installs every build, test and benchmark dependency from Debian 12's packages (idempotent).
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
packages=(
  build-essential cmake pkg-config git ca-certificates ccache
  libeigen3-dev nlohmann-json3-dev libcpp-httplib-dev libcli11-dev
  libsqlite3-dev sqlite3 libssl-dev zlib1g-dev libbrotli-dev libicu-dev
  libbz2-dev liblz4-dev libzstd-dev python3-rosbag python3-sensor-msgs
  libpq-dev postgresql-15
  libgtest-dev libgmock-dev libbenchmark-dev
  clang libclang-rt-14-dev
  curl procps python3 chromium fonts-dejavu-core
)
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo
# PostgreSQL (the tests start their own throw-away clusters, tests/storage/pg_test_cluster.h):
# Debian's package would create and start a cluster "main" that calibd never uses (and whose
# start fails on a machine without an init system). postgresql-common first, told not to.
if ! dpkg-query -W -f='${Status}' postgresql-15 2>/dev/null | grep -q "install ok installed"; then
  if ! dpkg-query -W -f='${Status}' postgresql-common 2>/dev/null | grep -q "install ok installed"; then
    $SUDO apt-get update
    $SUDO apt-get install -y --no-install-recommends postgresql-common
  fi
  $SUDO sed -ri 's/^#? *create_main_cluster *=.*$/create_main_cluster = false/' \
    /etc/postgresql-common/createcluster.conf
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  $SUDO apt-get update
  $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
fi
