#!/usr/bin/env bash
# Builds the ROS 2 interface package in msg_defs/ (grasp_safety_msgs) against the ROS 2 Jazzy
# wheels in .venv and installs it into the venv, so that
#   .venv/bin/python -c 'from grasp_safety_msgs.msg import GraspRanking'
# works, and rclpy can publish/call it, with no setup file sourced and no variable set.
#
# How: colcon + the ament_cmake/rosidl wheels (requirements-interfaces.txt) build the package
# into build/interfaces/{build,install,log}; the install tree is then copied into the venv
# prefix, laid out like the ros-* wheels lay out their own packages:
#   .venv/lib/python3.X/site-packages/grasp_safety_msgs/   Python package + C extensions
#   .venv/lib/libgrasp_safety_msgs__*.so                    typesupport libraries
#   .venv/share/grasp_safety_msgs/, .venv/include/...       interface files, CMake config, headers
#   .venv/share/ament_index/resource_index/*/grasp_safety_msgs
# .venv/lib is on LD_LIBRARY_PATH in every venv Python process (the ros-wheels-bootstrapper
# .pth re-executes the interpreter with it), which is how rclpy/rosidl_typesupport_c find
# the libraries, exactly as for geometry_msgs.
#
# Workaround, applied inside .venv only: the wheels' exported CMake targets of the *_msgs
# Python typesupport name the include dirs of the machine that built them
# (/opt/python/cp311-cp311/...); they are rewritten to this venv's Python and numpy headers.
#
# Idempotent: re-running rebuilds incrementally and replaces the previous copy in the venv
# (files listed in .venv/.grasp_safety_msgs.files). Usage, from anywhere:
#   bash scripts/build_interfaces.sh            (the Makefile calls it; VENV=... to override)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
VENV=$(cd "${VENV:-.venv}" && pwd)
PY=$VENV/bin/python
PKG=grasp_safety_msgs
SRC_DIR=$ROOT/msg_defs
OUT=$ROOT/build/interfaces
MANIFEST=$VENV/.$PKG.files
LOG=$OUT/colcon_build.log

export PATH=$VENV/bin:$PATH  # venv tools (colcon, maybe cmake) and its python first

die() { echo "build_interfaces.sh: $*" >&2; exit 1; }
[ -x "$PY" ] || die "no venv at $VENV (run 'make setup' first)"

apt_install() {  # Debian packages, only when something is missing
  command -v apt-get >/dev/null && [ "$(id -u)" = 0 ] || die "missing: $* (install it)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get install -y -qq "$@" >/dev/null 2>&1 \
    || { apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq "$@" >/dev/null; } \
    || die "apt-get install $* failed"
}

# 1. Build dependencies (PyPI; the pip.conf of some machines warns about missing local indexes).
"$PY" -m pip install -q -r requirements-interfaces.txt 2>&1 \
  | sed -e '/is ignored: it is neither a file nor a directory/d' >&2
command -v cmake >/dev/null || "$PY" -m pip install -q cmake
for tool in cc c++ make; do command -v $tool >/dev/null || { apt_install gcc g++ make; break; }; done
PYINC=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
if [ ! -f "$PYINC/Python.h" ]; then
  apt_install "python$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')-dev"
  [ -f "$PYINC/Python.h" ] || die "Python.h not found in $PYINC"
fi
NPINC=$("$PY" -c 'import numpy; print(numpy.get_include())')

# 2. Point the wheels' exported include dirs at this venv's Python/numpy headers.
{ grep -rlZ -E --include='*.cmake' '/opt/python/cp3[0-9]+' "$VENV/share" || true; } \
  | xargs -0 -r sed -i -E \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+t?/lib/python3\.[0-9]+t?/site-packages/numpy/(_core|core)/include#$NPINC#g" \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+t?/include/python3\.[0-9]+t?#$PYINC#g"

# 3. Build with colcon, against the venv prefix only (ignore a sourced ROS install).
# rosidl never deletes what it generated for a removed interface, so any change to msg_defs/
# or to this script (or a moved checkout or venv) means a clean build; otherwise it takes seconds.
SRC_HASH=$( { echo "$SRC_DIR $VENV $PYINC $NPINC"; sha256sum "$ROOT/scripts/build_interfaces.sh"
  cd "$SRC_DIR" && find . -type f | LC_ALL=C sort | xargs -d '\n' sha256sum; } | sha256sum | cut -d' ' -f1)
if [ "$(cat "$OUT/.src_hash" 2>/dev/null)" != "$SRC_HASH" ]; then
  rm -rf "${OUT:?}/build" "$OUT/install" "$OUT/.src_hash"
fi
mkdir -p "$OUT"
unset PYTHONPATH COLCON_PREFIX_PATH AMENT_CURRENT_PREFIX
export AMENT_PREFIX_PATH=$VENV CMAKE_PREFIX_PATH=$VENV
export COLCON_HOME=$OUT/colcon_home  # no user-level colcon defaults or mixins
if ! "$VENV/bin/colcon" --log-base "$OUT/log" build \
      --base-paths "$SRC_DIR" --build-base "$OUT/build" --install-base "$OUT/install" \
      --cmake-args -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
        -DPython3_EXECUTABLE="$PY" -DPython3_FIND_VIRTUALENV=FIRST \
      >"$LOG" 2>&1; then
  tail -n 40 "$LOG" >&2
  die "colcon build failed; full log: $LOG"
fi
echo "$SRC_HASH" >"$OUT/.src_hash"

# 4. Replace the previous copy in the venv with the fresh install tree.
INSTALL=$OUT/install/$PKG
SITE_REL=$(cd "$INSTALL" && ls -d lib/python3*/site-packages)
[ "$SITE_REL" = "$("$PY" -c 'import sys; print("lib/python%d.%d/site-packages" % sys.version_info[:2])')" ] \
  || die "unexpected Python install dir $INSTALL/$SITE_REL"
if [ -f "$MANIFEST" ]; then
  (cd "$VENV" && xargs -d '\n' -r rm -f -- <"$MANIFEST")
fi
rm -rf "${VENV:?}/$SITE_REL/$PKG" "$VENV/include/$PKG" "$VENV/share/$PKG"
rm -rf "$VENV/$SITE_REL/$PKG"-*.egg-info
(cd "$INSTALL" && find . \( -path ./share/colcon-core -o -name __pycache__ \
    -o -path "./share/$PKG/package.*" ! -name package.xml \) -prune \
    -o \( -type f -o -type l \) -print | sed 's#^\./##' | sort) >"$MANIFEST.new"
tar -C "$INSTALL" -cf - -T "$MANIFEST.new" | tar -C "$VENV" -xf -
mv "$MANIFEST.new" "$MANIFEST"
"$PY" -m compileall -q "$VENV/$SITE_REL/$PKG" >/dev/null

echo "grasp_safety_msgs: built in ${OUT#"$ROOT"/}/, installed into $VENV (importable as-is)"
