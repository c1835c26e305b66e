#!/usr/bin/env bash
# Fetches the pinned three.js (MIT) from npm for the interactive 3D view of each asset in report.html.
# Called by scripts/setup.sh; the view is optional, so this never fails its caller: when something is missing
# it says so in one line on stderr and exits 0, and the report's asset cards show everything but the 3D view
# (with one line saying how to install it).
#
# Cache (outside the source tree; src/synth/report_assets.h ThreeJsDir() reads the same place):
#   ${SYNTHDRIVE_WEB:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/web}
#     npm/three-<version>.tgz     the packed tarball, checked against its npm integrity
#     three/                      only the files the report copies, at their package paths:
#                                 package.json, LICENSE, build/three.min.js,
#                                 examples/js/loaders/GLTFLoader.js, examples/js/controls/OrbitControls.js
# three/ is built under a temporary name and renamed into place, so an interrupted run leaves no half folder.
set -u

CACHE="${SYNTHDRIVE_WEB:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/web}"
NPM_TIMEOUT_S="${SYNTHDRIVE_NPM_TIMEOUT:-180}"
# r147 is the last release that ships the classic (non-module) examples/js scripts. The report must work when
# opened from disk, and Chromium refuses ES-module imports on file:// pages, so the view needs classic scripts.
VERSION=0.147.0
# dist.integrity of the pinned tarball (`npm view three@0.147.0 dist.integrity`).
INTEGRITY="sha512-LPTOslYQXFkmvceQjFTNnVVli2LaVF6C99Pv34fJypp8NbQLbTlu3KinZ0zURghS5zEehK+VQyvWuPZ/Sm8fzw=="
FILES="package.json LICENSE build/three.min.js examples/js/loaders/GLTFLoader.js examples/js/controls/OrbitControls.js"
DEST="$CACHE/three"

TEMPS=()
remove_temps() {
  local t
  for t in "${TEMPS[@]}"; do rm -rf "$t"; done
}
trap remove_temps EXIT

give_up() {
  echo "fetch_web: $1; report.html will show the assets without the interactive 3D view" >&2
  exit 0
}

current() {
  local f
  grep -q "\"version\": \"$VERSION\"" "$DEST/package.json" 2>/dev/null || return 1
  for f in $FILES; do [ -s "$DEST/$f" ] || return 1; done
}

sri_sha512() {
  python3 -c 'import base64, hashlib, sys
print("sha512-" + base64.b64encode(hashlib.sha512(open(sys.argv[1], "rb").read()).digest()).decode())' "$1"
}

# Makes $CACHE/npm/three-$VERSION.tgz, verified against the pinned integrity.
pack() {
  local tgz="$CACHE/npm/three-$VERSION.tgz" tmp
  if [ -f "$tgz" ] && [ "$(sri_sha512 "$tgz")" = "$INTEGRITY" ]; then
    return 0
  fi
  tmp=$(mktemp -d "$CACHE/npm/.pack.XXXXXX") || give_up "cannot write to $CACHE/npm"
  TEMPS+=("$tmp")
  if ! timeout "$NPM_TIMEOUT_S" npm pack "three@$VERSION" --pack-destination "$tmp" >"$tmp/npm.log" 2>&1 </dev/null; then
    give_up "npm pack three@$VERSION failed or timed out (registry unreachable?)"
  fi
  [ -f "$tmp/three-$VERSION.tgz" ] || give_up "npm pack did not produce three-$VERSION.tgz"
  [ "$(sri_sha512 "$tmp/three-$VERSION.tgz")" = "$INTEGRITY" ] ||
    give_up "three-$VERSION.tgz does not match its pinned sha512 integrity"
  mv -f "$tmp/three-$VERSION.tgz" "$tgz"
}

extract() {
  local tmp f members=()
  for f in $FILES; do members+=("package/$f"); done
  tmp=$(mktemp -d "$CACHE/.extract.XXXXXX") || give_up "cannot write to $CACHE"
  TEMPS+=("$tmp")
  tar -xzf "$CACHE/npm/three-$VERSION.tgz" -C "$tmp" "${members[@]}" ||
    give_up "three-$VERSION.tgz lacks one of: $FILES"
  chmod -R u+rwX,go+rX "$tmp"
  rm -rf "$DEST"
  mv "$tmp/package" "$DEST"
}

main() {
  current && exit 0
  command -v npm >/dev/null 2>&1 || give_up "npm not found"
  command -v tar >/dev/null 2>&1 || give_up "tar not found"
  command -v timeout >/dev/null 2>&1 || give_up "timeout not found"
  command -v python3 >/dev/null 2>&1 || give_up "python3 not found (needed to check the tarball's sha512)"
  mkdir -p "$CACHE/npm" 2>/dev/null || give_up "cannot create $CACHE/npm"
  if command -v flock >/dev/null 2>&1; then
    # Two setups at once (parallel CI jobs) would otherwise race on the same temporary-then-rename steps.
    exec 9>"$CACHE/.lock" || give_up "cannot write $CACHE/.lock"
    flock -w 900 9 || give_up "another fetch_web holds $CACHE/.lock"
    current && exit 0
  fi
  pack
  extract
  current || give_up "$DEST is incomplete after extraction"
  echo "fetch_web: three.js $VERSION (MIT) installed in $DEST for the report's 3D view"
}

main "$@"
