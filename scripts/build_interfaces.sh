#!/usr/bin/env bash
# Builds the ROS 2 interface packages against the ROS 2 Jazzy wheels in .venv and installs them
# into the venv, so that
#   .venv/bin/python -c 'from grasp_safety_msgs.msg import GraspRanking'
# works, and rclpy can publish/call them, with no setup file sourced and no variable set:
#   - msg_defs/ (grasp_safety_msgs), this project's own, built per checkout in build/interfaces/;
#   - the subsets of the upstream packages in ../shared/interfaces/ that the project uses
#     (control_msgs, moveit_msgs and what they include; the list is KEEP in
#     scripts/stage_interfaces.py), definition files unchanged so the types keep their upstream
#     type hashes. Their install tree is kept per machine in
#     ~/.cache/grasp_safety_ros/interfaces/<digest>/ (digest of the staged sources, these
#     scripts, Python, numpy and the ROS wheels' versions), so a second checkout or venv copies
#     it in seconds; the keys beyond the 6 most recently used, unused for a day, are deleted
#     (scripts/interface_cache.py). A package a ROS installation already provides (its ament index, in a prefix
#     of AMENT_PREFIX_PATH other than the venv) is not built, and a copy of ours is removed.
#
# How: colcon + the ament_cmake/rosidl wheels (requirements-interfaces.txt) build a package
# into <out>/{build,install,log}; the install tree is then copied into the venv
# prefix, laid out like the ros-* wheels lay out their own packages:
#   .venv/lib/python3.X/site-packages/<pkg>/   Python package + C extensions
#   .venv/lib/lib<pkg>__*.so                    typesupport libraries
#   .venv/share/<pkg>/, .venv/include/...       interface files, CMake config, headers
#   .venv/share/ament_index/resource_index/*/<pkg>
# .venv/lib is on LD_LIBRARY_PATH in every venv Python process (the ros-wheels-bootstrapper
# .pth re-executes the interpreter with it), which is how rclpy/rosidl_typesupport_c find
# the libraries, exactly as for geometry_msgs.
#
# Workaround, applied inside .venv only: the wheels' exported CMake targets of the *_msgs
# Python typesupport name the include dirs of the machine that built them
# (/opt/python/cp311-cp311/...); they are rewritten to this venv's Python and numpy headers.
#
# Idempotent: re-running rebuilds incrementally and replaces the previous copy in the venv
# (files listed in .venv/.<pkg>.files). Usage, from anywhere:
#   bash scripts/build_interfaces.sh            (the Makefile calls it; VENV=... to override,
#                                                SHARED_INTERFACES=... for ../shared/interfaces)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
VENV=$(cd "${VENV:-.venv}" && pwd)
PY=$VENV/bin/python
SHARED=${SHARED_INTERFACES:-$ROOT/../shared/interfaces}
OUT=$ROOT/build/interfaces
CACHE_ROOT=${XDG_CACHE_HOME:-$HOME/.cache}/grasp_safety_ros/interfaces
# a sourced ROS installation, read before step 3 resets the environment
OUTSIDE_PREFIXES=${AMENT_PREFIX_PATH:-} OUTSIDE_PYTHONPATH=${PYTHONPATH:-}

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
unset PYTHONPATH COLCON_PREFIX_PATH AMENT_CURRENT_PREFIX
export AMENT_PREFIX_PATH=$VENV CMAKE_PREFIX_PATH=$VENV

CMAKE_ARGS=(-DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY"
  -DPython3_FIND_VIRTUALENV=FIRST)

# colcon_build SRC OUT KEY: builds every package under SRC into OUT/{build,install,log}.
# rosidl never deletes what it generated for a removed interface, so a KEY (digest of the
# sources) other than the last build's means a clean build; otherwise it takes seconds.
colcon_build() {
  local src=$1 out=$2 key=$3 log=$2/colcon_build.log
  if [ "$(cat "$out/.src_hash" 2>/dev/null)" != "$key" ]; then
    rm -rf "${out:?}/build" "$out/install" "$out/.src_hash"
  fi
  mkdir -p "$out"
  # COLCON_HOME: no user-level colcon defaults or mixins
  if ! COLCON_HOME=$out/colcon_home "$VENV/bin/colcon" --log-base "$out/log" build \
        --base-paths "$src" --build-base "$out/build" --install-base "$out/install" \
        --cmake-args "${CMAKE_ARGS[@]}" >"$log" 2>&1; then
    tail -n 40 "$log" >&2
    die "colcon build failed; full log: $log"
  fi
  echo "$key" >"$out/.src_hash"
}

# tree_digest DIR...: one digest of the files (paths and contents) under each DIR
tree_digest() {
  local dir
  for dir in "$@"; do (cd "$dir" && find . -type f | LC_ALL=C sort | xargs -d '\n' sha256sum); done \
    | sha256sum | cut -d' ' -f1
}

SITE_REL=$("$PY" -c 'import sys; print("lib/python%d.%d/site-packages" % sys.version_info[:2])')

# uninstall PKG: removes the copy of PKG a previous run put into the venv
uninstall() {
  local pkg=$1 manifest=$VENV/.$1.files
  if [ -f "$manifest" ]; then
    (cd "$VENV" && xargs -d '\n' -r rm -f -- <"$manifest")
    rm -f "$manifest"
  fi
  rm -rf "${VENV:?}/$SITE_REL/$pkg" "$VENV/include/$pkg" "$VENV/share/$pkg"
  rm -rf "$VENV/$SITE_REL/$pkg"-*.egg-info
}

# install_pkg INSTALL PKG: replaces the previous copy of PKG in the venv with INSTALL/PKG
install_pkg() {
  local install=$1/$2 pkg=$2 manifest=$VENV/.$2.files
  [ -d "$install/$SITE_REL" ] || die "unexpected Python install dir in $install"
  uninstall "$pkg"
  (cd "$install" && find . \( -path ./share/colcon-core -o -name __pycache__ \
      -o -path "./share/$pkg/package.*" ! -name package.xml \) -prune \
      -o \( -type f -o -type l \) -print | sed 's#^\./##' | sort) >"$manifest.new"
  tar -C "$install" -cf - -T "$manifest.new" | tar -C "$VENV" -xf -
  mv "$manifest.new" "$manifest"
  "$PY" -m compileall -q "$VENV/$SITE_REL/$pkg" >/dev/null
}

# provided_outside PKG: true when a ROS installation (a prefix of AMENT_PREFIX_PATH other
# than the venv) has PKG in its ament index and the venv's Python imports PKG from there with
# the caller's PYTHONPATH (a ROS built for another Python does not count)
provided_outside() {
  local prefix module
  IFS=: read -ra prefixes <<<"$OUTSIDE_PREFIXES"
  for prefix in "${prefixes[@]}"; do
    [ -n "$prefix" ] && [ -d "$prefix" ] || continue
    prefix=$(cd "$prefix" && pwd -P)
    [ "$prefix" = "$(cd "$VENV" && pwd -P)" ] && continue
    [ -e "$prefix/share/ament_index/resource_index/packages/$1" ] || continue
    module=$(PYTHONPATH=$OUTSIDE_PYTHONPATH "$PY" -c "import os, $1.msg as m
from rosidl_generator_py import import_type_support as load; load('$1')  # its C extension
print(os.path.realpath(m.__file__))" 2>/dev/null) || continue
    [[ $module == "$prefix"/* ]] && return 0
  done
  return 1
}

# 4. This project's grasp_safety_msgs (msg_defs/), per checkout.
colcon_build "$ROOT/msg_defs" "$OUT" "$( { echo "$ROOT $VENV $PYINC $NPINC"
  sha256sum "$ROOT/scripts/build_interfaces.sh"; tree_digest "$ROOT/msg_defs"; } | sha256sum)"
install_pkg "$OUT/install" grasp_safety_msgs
echo "grasp_safety_msgs: built in ${OUT#"$ROOT"/}/, installed into $VENV (importable as-is)"

# 5. The upstream subsets, from the per-machine cache or built into it.
if [ ! -d "$SHARED" ]; then
  echo "build_interfaces.sh: no $SHARED: control_msgs and moveit_msgs not built" \
    "(the speed-scaling monitor and the MoveIt services need them)" >&2
  exit 0
fi
UPSTREAM_TOP=(control_msgs moveit_msgs)  # KEEP's packages in scripts/stage_interfaces.py
SKIP=()
for pkg in "${UPSTREAM_TOP[@]}"; do
  if provided_outside "$pkg"; then SKIP+=("$pkg"); fi
done
STAGE=$OUT/upstream/src
STAGED_LIST=$("$PY" "$ROOT/scripts/stage_interfaces.py" "$SHARED" "$STAGE" --skip "${SKIP[@]}")
mapfile -t STAGED <<<"$STAGED_LIST"
for pkg in $(ls "$SHARED"); do  # our copies of packages no longer built (ROS provides them)
  if [ -f "$VENV/.$pkg.files" ] && ! printf '%s\n' "${STAGED[@]}" | grep -qx "$pkg"; then
    uninstall "$pkg"
  fi
done
[ -n "$STAGED_LIST" ] || { echo "upstream interfaces: all provided by ROS (${SKIP[*]})"; exit 0; }
KEY=$( { echo "$PYINC"; "$PY" -c 'import sys; print(sys.version)'
  ls "$VENV/$SITE_REL" | grep -E '^(ros_|numpy-).*\.dist-info$'
  echo "${CMAKE_ARGS[*]##-DPython3_EXECUTABLE=*}"  # not the venv's path: shared by checkouts
  uname -m  # the architecture: a home shared by several machines shares this cache
  sha256sum "$ROOT/scripts/stage_interfaces.py" "$ROOT/scripts/build_interfaces.sh" | cut -d' ' -f1
  tree_digest "$STAGE"; } | sha256sum | cut -c1-16)
CACHED=$CACHE_ROOT/$KEY
if [ ! -d "$CACHED" ]; then
  start=$SECONDS
  colcon_build "$STAGE" "$OUT/upstream" "$KEY"
  mkdir -p "$CACHE_ROOT"
  tmp=$(mktemp -d "$CACHE_ROOT/.tmp.XXXXXX")
  cp -a "$OUT/upstream/install/." "$tmp/"
  echo "$VENV" >"$tmp/.venv_path"
  mv -T "$tmp" "$CACHED" 2>/dev/null || rm -rf "$tmp"  # another checkout cached it meanwhile
  echo "upstream interfaces: built ${STAGED[*]} in $((SECONDS - start)) s, cached in $CACHED"
fi
touch "$CACHED" 2>/dev/null || true  # used now: the pruning at the end keeps it
# the CMake exports name the venv that built the tree, the ament index its install dirs:
# this venv instead (every dependency is in it)
BUILT_IN=$(cat "$CACHED/.venv_path")
for pkg in "${STAGED[@]}"; do
  install_pkg "$CACHED" "$pkg"
  printf '%s' "$VENV" >"$VENV/share/ament_index/resource_index/parent_prefix_path/$pkg"
  [ "$BUILT_IN" = "$VENV" ] && continue
  { grep -rlZ -F "$BUILT_IN" "$VENV/share/$pkg" || true; } \
    | xargs -0 -r sed -i "s#$BUILT_IN#$VENV#g"
done
echo "upstream interfaces: ${STAGED[*]} (subsets) installed into $VENV from" \
  "$CACHED${SKIP[*]:+ (provided by ROS: ${SKIP[*]})}"
"$PY" "$ROOT/scripts/interface_cache.py" "$CACHE_ROOT"  # the keys long unused go
