#!/usr/bin/env bash
# Builds ur_rtde (the Universal Robots RTDE client library) from its pinned PyPI source
# distribution into a prefix, for the `ur-rtde` cargo feature.
#
#   UR_RTDE_PREFIX   install prefix (default /opt/ur_rtde-1.6.5)
#   UR_RTDE_JOBS     make parallelism (default 2)
#
# It installs the Debian build packages it needs, checks the sdist's sha256, builds a static,
# position-independent librtde.a WITHOUT -O3 (no CMAKE_BUILD_TYPE: at -O3 one generated file takes
# ~11 CPU-minutes; the library is I/O bound so -O0 costs nothing that matters), and writes a stamp
# file. When the stamp already names this version and checksum, it does nothing.
# No third-party source is kept in this repository: the sdist is fetched with pip each time.
set -euo pipefail

VERSION=1.6.5
SHA256=3d5b6c6bf73346b806d146f128537abd2afb1d769f4a9c8b3ef5a884fab0bcfa
PREFIX="${UR_RTDE_PREFIX:-/opt/ur_rtde-${VERSION}}"
JOBS="${UR_RTDE_JOBS:-2}"
STAMP="$PREFIX/.handeye-ur-rtde-stamp"
WANT_STAMP="ur_rtde ${VERSION} static-pic ${SHA256}"

if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT_STAMP" ] && [ -f "$PREFIX/lib/librtde.a" ]; then
  echo "install-ur-rtde: $PREFIX already holds ur_rtde $VERSION; nothing to do"
  exit 0
fi

# Debian build packages (only those missing, so a warm machine needs no apt at all).
bash "$(dirname "$0")/apt-install.sh" cmake make g++ libboost-system-dev libboost-thread-dev \
  libboost-program-options-dev

WORK="$(mktemp -d /tmp/ur-rtde-build.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
cd "$WORK"

# `pip download --no-binary :all:` alone tries to build the build deps from source and hangs;
# a venv with wheel+setuptools and --no-build-isolation just fetches the sdist.
python3 -m venv venv
venv/bin/pip install -q wheel setuptools
venv/bin/pip download -q --no-deps --no-binary :all: --no-build-isolation \
  "ur-rtde==${VERSION}" -d dl
SDIST="dl/ur_rtde-${VERSION}.tar.gz"
echo "${SHA256}  ${SDIST}" | sha256sum -c -

tar -xzf "$SDIST"
cd "ur_rtde-${VERSION}"
# One build dir only: configuring writes a generated header into the source tree, which makes
# any second build dir rebuild everything.
mkdir build && cd build
cmake .. -DPYTHON_BINDINGS=OFF -DEXAMPLES=OFF -DBUILD_STATIC=ON \
  -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DCMAKE_INSTALL_PREFIX="$PREFIX"
nice -n 10 make -j"$JOBS"
# The prefix may need root (/opt): through sudo when this user cannot write it.
if mkdir -p "$PREFIX" 2>/dev/null && [ -w "$PREFIX" ]; then
  make install
  echo "$WANT_STAMP" >"$STAMP"
else
  sudo -n make install
  echo "$WANT_STAMP" | sudo -n tee "$STAMP" >/dev/null
fi
echo "install-ur-rtde: installed ur_rtde $VERSION into $PREFIX"
