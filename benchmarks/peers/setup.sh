#!/usr/bin/env bash
# Set up the peer map matchers for benchmarks/compare_peers.py. Idempotent; benchmark-only:
# nothing here is a runtime dependency of the project. Everything lands in .peers/ (gitignored).
#
#   bash benchmarks/peers/setup.sh [EXTRACT ...]
#
#   .peers/valhalla   Python 3.12 venv with pyvalhalla (its 3.9.x wheels are CPython 3.12 only)
#   .peers/py311      Python 3.11 venv with leuvenmapmatching, mappymatch, osmnx, osmium, rtree
#   .peers/tiles/<stem>/valhalla.json + tiles.tar   Valhalla tiles per extract, built offline
#   .bench/fmm        FMM (C++) and its Python binding, built from the source in
#                     ../shared/peers/fmm/ by its build.sh (apt-installs cmake, g++, Boost, GDAL,
#                     SWIG; 10-20 minutes on 2 cores the first time; skipped with a notice when
#                     ../shared/peers/fmm is absent, e.g. on a user's clone). SKIP_FMM=1 skips it.
#                     The edge files and UBODTs are made per extract by compare_peers.py and
#                     cached under .bench/fmm/cache/.
#
# EXTRACT defaults to every file in ../shared/data/osm/ (PBF directly; .osm/.bz2/.gz are
# converted to PBF with pyosmium first, since valhalla_build_tiles reads PBF only).
# Python interpreters: PY312 / PY311 override the pyenv defaults below.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
PEERS="$ROOT/.peers"
OSM_DIR="${OSM_DIR:-$ROOT/../shared/data/osm}"
PY312="${PY312:-$HOME/.pyenv/versions/3.12.1/bin/python}"
PY311="${PY311:-$HOME/.pyenv/versions/3.11.7/bin/python}"
command -v "$PY312" >/dev/null 2>&1 || PY312="$(command -v python3.12 || true)"
command -v "$PY311" >/dev/null 2>&1 || PY311="$(command -v python3.11 || true)"

log() { printf '[peers/setup] %s\n' "$*"; }

make_venv() {  # make_venv DIR PYTHON PACKAGES...
  local dir="$1" py="$2"; shift 2
  local stamp="$dir/.installed-$(echo "$*" | md5sum | cut -c1-12)"
  if [[ -f "$stamp" ]]; then log "$dir up to date"; return 0; fi
  if [[ -z "$py" ]]; then log "no interpreter for $dir; set PY312/PY311"; return 1; fi
  [[ -x "$dir/bin/python" ]] || "$py" -m venv "$dir"
  "$dir/bin/python" -m pip install --quiet --upgrade pip
  "$dir/bin/python" -m pip install --quiet "$@"
  touch "$stamp"
  log "$dir ready: $*"
}

mkdir -p "$PEERS"
make_venv "$PEERS/valhalla" "$PY312" "pyvalhalla>=3.9,<3.10"
make_venv "$PEERS/py311" "$PY311" \
  "leuvenmapmatching>=1.1.4" "mappymatch>=0.7" "osmnx>=2.0" "osmium>=4.0" "rtree>=1.3" \
  "pyproj>=3.6" "shapely>=2.0" "pandas>=2.0"

# Valhalla tiles per extract. The console scripts find their binaries through PATH.
export PATH="$PEERS/valhalla/bin:$PATH"
if [[ $# -gt 0 ]]; then extracts=("$@"); else extracts=("$OSM_DIR"/*.osm*); fi
for src in "${extracts[@]}"; do
  [[ -f "$src" ]] || src="$OSM_DIR/$src"
  [[ -f "$src" ]] || { log "skip $src: not found"; continue; }
  name="$(basename "$src")"; stem="${name%%.*}"
  dir="$PEERS/tiles/$stem"
  if [[ -s "$dir/tiles.tar" && -s "$dir/valhalla.json" && "$dir/tiles.tar" -nt "$src" ]]; then
    log "tiles for $stem up to date"; continue
  fi
  mkdir -p "$dir"; rm -rf "$dir/tiles"; mkdir -p "$dir/tiles"
  pbf="$src"
  if [[ "$name" != *.pbf ]]; then  # valhalla reads PBF only
    pbf="$dir/$stem.osm.pbf"
    "$PEERS/py311/bin/python" - "$src" "$pbf" <<'PYEOF'
import sys, osmium
writer = osmium.SimpleWriter(sys.argv[2], overwrite=True)
for obj in osmium.FileProcessor(sys.argv[1]):
    writer.add(obj)
writer.close()
PYEOF
  fi
  valhalla_build_config \
    --mjolnir-tile-dir "$dir/tiles" --mjolnir-tile-extract "$dir/tiles.tar" \
    --mjolnir-timezone "" --mjolnir-admin "" --mjolnir-traffic-extract "" \
    --logging-type "" > "$dir/valhalla.json"
  if valhalla_build_tiles -c "$dir/valhalla.json" "$pbf" > "$dir/build.log" 2>&1 \
     && valhalla_build_extract -c "$dir/valhalla.json" -v >> "$dir/build.log" 2>&1; then
    rm -rf "$dir/tiles"
    log "tiles for $stem built ($(du -h "$dir/tiles.tar" | cut -f1))"
  else
    log "tiles for $stem FAILED, see $dir/build.log"
  fi
done
# FMM: built from the shared source into .bench/fmm for the project venv's interpreter (its runner
# reads our compiled network, so it runs in that venv with the binding on PYTHONPATH).
FMM_SRC="${FMM_SRC:-$ROOT/../shared/peers/fmm}"
PROJECT_PY="${PROJECT_PY:-$ROOT/.venv/bin/python}"
if [[ "${SKIP_FMM:-0}" == 1 ]]; then
  log "FMM skipped (SKIP_FMM=1)"
elif [[ ! -f "$FMM_SRC/build.sh" ]]; then
  log "FMM skipped: no $FMM_SRC/build.sh (the FMM source and build script live in ../shared/peers/fmm)"
elif [[ ! -x "$PROJECT_PY" ]]; then
  log "FMM skipped: no project venv at $PROJECT_PY (make the venv first, or set PROJECT_PY)"
elif [[ -f "$ROOT/.bench/fmm/src/build/ubodt_gen" && -f "$ROOT/.bench/fmm/src/build/python/_fmm.so" ]] \
     && PYTHONPATH="$ROOT/.bench/fmm/src/build/python" "$PROJECT_PY" -c "import fmm" 2>/dev/null; then
  log "FMM up to date in .bench/fmm"
else
  log "building FMM into .bench/fmm (10-20 minutes on 2 cores the first time; log .bench/fmm-build.log)"
  mkdir -p "$ROOT/.bench"
  # an absolute interpreter path: build.sh resolves it from inside its build folder; FMM's
  # python/CMakeLists.txt also runs a bare `python` (for distutils): the project venv's first
  if PATH="$(dirname "$PROJECT_PY"):$PATH" bash "$FMM_SRC/build.sh" "$ROOT/.bench/fmm" "$PROJECT_PY" \
       > "$ROOT/.bench/fmm-build.log" 2>&1; then
    log "FMM ready: $(tail -1 "$ROOT/.bench/fmm-build.log")"
  else
    log "FMM build FAILED, see .bench/fmm-build.log"; tail -20 "$ROOT/.bench/fmm-build.log"
    # build.sh configures only once; a configure that failed must run again next time
    [[ -f "$ROOT/.bench/fmm/src/build/Makefile" ]] || rm -f "$ROOT/.bench/fmm/src/build/CMakeCache.txt"
  fi
fi
log "done; run: .venv/bin/python benchmarks/compare_peers.py"
