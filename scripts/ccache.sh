# Sourced by scripts/build.sh and scripts/build-sanitize.sh: when ccache is installed
# (scripts/setup.sh installs it) and CALIBD_CCACHE is not 0, sets `launcher` to the CMake options
# that compile through it, and configures it so that every checkout of this machine shares one
# cache: paths relative to the checkout (CCACHE_BASEDIR, CCACHE_NOHASHDIR), precompiled headers
# allowed (CCACHE_SLOPPINESS, as ccache's manual asks; CMakeLists.txt drops clang's PCH
# timestamps). A build after a change then recompiles only the files the change reaches, in CI
# too when its machine keeps the cache (~/.cache/ccache) between runs; a cold cache costs a few
# per cent over no cache. The cache's outputs are those of the compiler on the same
# preprocessed input and flags, so a cached build is the same build.
launcher=()
if [ "${CALIBD_CCACHE:-1}" != 0 ] && command -v ccache >/dev/null 2>&1; then
  export CCACHE_BASEDIR=$PWD CCACHE_NOHASHDIR=1
  export CCACHE_SLOPPINESS=pch_defines,time_macros,include_file_mtime,include_file_ctime
  export CCACHE_MAXSIZE=${CCACHE_MAXSIZE:-20G}
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
else
  launcher=(-UCMAKE_CXX_COMPILER_LAUNCHER -UCMAKE_C_COMPILER_LAUNCHER)
fi
