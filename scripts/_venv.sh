# Shared by scripts/demo, scripts/test and scripts/build_extension: create and reuse .venv with
# pinned dependencies. Sourced, not executed. Re-installs only when a requirements file changes.
#
# By default the Blender side is installed too (requirements-blender.txt: the bpy wheel, plus the
# Debian libraries bpy loads, installed with apt-get when missing). TCB_SKIP_BLENDER=1 installs
# only the engine's requirements (the Blender tests then skip instead of failing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [ ! -x "$VENV/bin/python" ]; then
  if ! "$PY" -m venv "$VENV" 2>/dev/null; then
    echo "python venv module missing: installing python3-venv" >&2
    (apt-get update -qq && apt-get install -y -qq python3-venv) >&2
    "$PY" -m venv "$VENV"
  fi
fi

# Debian packages that the bpy wheel's shared libraries link against and that a bare machine
# lacks (found with ldd on bpy/__init__.so and bpy/lib/*.so). libxxf86vm1 and libgomp1 were
# needed by bpy 4.x; libxt6 by bpy's MaterialX render library. Checked on every run (one
# dpkg-query call, ~10 ms) because the machine may change while the work tree is kept.
TCB_BLENDER_DEBS="libx11-6 libxext6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libice6 libgl1 libxxf86vm1 libgomp1 libxt6"
_tcb_blender_debs() {
  command -v dpkg-query >/dev/null 2>&1 || return 0   # not Debian: nothing we can do here
  local installed missing=() p
  installed=" $(dpkg-query -W -f='${db:Status-Abbrev} ${Package}\n' $TCB_BLENDER_DEBS 2>/dev/null \
                | awk '$1 == "ii" {sub(/:.*/, "", $2); printf "%s ", $2}') "
  for p in $TCB_BLENDER_DEBS; do
    case "$installed" in *" $p "*) ;; *) missing+=("$p") ;; esac
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "warning: bpy needs these Debian packages: ${missing[*]} (run as root: apt-get install ${missing[*]})" >&2
    return 0
  fi
  echo "installing the libraries bpy needs: ${missing[*]}" >&2
  (export DEBIAN_FRONTEND=noninteractive
   apt-get update -qq && apt-get install -y -qq --no-install-recommends "${missing[@]}") >/dev/null </dev/null
}

REQS=("$ROOT/requirements.txt")
if [ "${TCB_SKIP_BLENDER:-0}" != 1 ]; then
  REQS=("$ROOT/requirements-blender.txt")   # includes requirements.txt
  _tcb_blender_debs
fi
STAMP="$VENV/.requirements.sha"
WANT="$(cat "$ROOT/requirements.txt" "${REQS[@]}" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
  "$VENV/bin/python" -m pip install -q --upgrade pip >&2
  "$VENV/bin/python" -m pip install -q -r "${REQS[0]}" >&2
  echo "$WANT" > "$STAMP"
fi
export PATH="$VENV/bin:$PATH"
cd "$ROOT"
