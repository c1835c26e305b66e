#!/usr/bin/env bash
# Fetches the pinned UpscalerJS ESRGAN weights (MIT) from npm and imports them into TorchScript for the
# super_resolution stage. Called by scripts/setup.sh; the models are optional, so this never fails its
# caller: when something is missing it says so in one line on stderr and exits 0, and SynthDrive falls
# back to the classical bicubic upscaler.
#
# Cache (outside the source tree, shared by builds and tests):
#   ${SYNTHDRIVE_MODELS:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/models}
#     npm/upscalerjs-esrgan-<size>-<version>.tgz          the packed tarball, checked against its npm integrity
#     npm/upscalerjs-esrgan-<size>-<version>/package/...  extracted; tests read assets/fixture.png and samples
#     esrgan-<size>-x<scale>.pt                           TorchScript + synthdrive_contract.json
# A model is re-imported when the importer is newer than its .pt. Everything is written to a temporary
# name in the same folder and renamed into place, so an interrupted run leaves no half-written file.
set -u

PYTHON=/usr/bin/python3  # Debian's python3-torch lives only here; a pyenv python on PATH has no torch.
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMPORTER="$ROOT/tools/import/tfjs_layers_to_torchscript.py"
CACHE="${SYNTHDRIVE_MODELS:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/models}"
NPM_TIMEOUT_S="${SYNTHDRIVE_NPM_TIMEOUT:-180}"
VERSION=1.0.0
SIZES="slim medium"
SCALES="2 4"
# The fixture round trip reproduces UpscalerJS's own samples at > 90 dB; far below means a wrong import.
MIN_PSNR_DB=30
# dist.integrity of the pinned tarballs (`npm view @upscalerjs/esrgan-<size>@1.0.0 dist.integrity`).
declare -A INTEGRITY=(
  [slim]="sha512-DXtwn5SE71+pZKluN/hGeLaZv6ZylyFQYSvMqU08kKCEA5Y9Q1cIIk4EvPTPZw8VqGi2C6F02c8OjhtId4BK2w=="
  [medium]="sha512-Z8JnR87sgetPABKevasXST3FdnXhaoTu9zpXnu3KLaHYpYStVt0FD1VZS9c6jhSGMBC0H929gN9RbWl+MeisKA=="
)

TEMPS=()
remove_temps() {
  local t
  for t in "${TEMPS[@]}"; do rm -rf "$t"; done
}
trap remove_temps EXIT

give_up() {
  echo "fetch_models: $1; super-resolution will use the classical bicubic upscaler" >&2
  exit 0
}

model_path() { echo "$CACHE/esrgan-$1-x$2.pt"; }
package_dir() { echo "$CACHE/npm/upscalerjs-esrgan-$1-$VERSION"; }

all_current() {
  local size scale
  for size in $SIZES; do
    for scale in $SCALES; do
      [ "$(model_path "$size" "$scale")" -nt "$IMPORTER" ] || return 1
    done
  done
}

sri_sha512() {
  "$PYTHON" -c 'import base64, hashlib, sys
print("sha512-" + base64.b64encode(hashlib.sha512(open(sys.argv[1], "rb").read()).digest()).decode())' "$1"
}

# Makes $CACHE/npm/<name>.tgz, verified against the pinned integrity.
pack() {
  local size=$1 name="upscalerjs-esrgan-$1-$VERSION" tmp
  local tgz="$CACHE/npm/$name.tgz"
  if [ -f "$tgz" ] && [ "$(sri_sha512 "$tgz")" = "${INTEGRITY[$size]}" ]; then
    return 0
  fi
  tmp=$(mktemp -d "$CACHE/npm/.pack.XXXXXX") || give_up "cannot write to $CACHE/npm"
  TEMPS+=("$tmp")
  if ! timeout "$NPM_TIMEOUT_S" npm pack "@upscalerjs/esrgan-$size@$VERSION" --pack-destination "$tmp" \
      >"$tmp/npm.log" 2>&1 </dev/null; then
    give_up "npm pack @upscalerjs/esrgan-$size@$VERSION failed or timed out (registry unreachable?)"
  fi
  [ -f "$tmp/$name.tgz" ] || give_up "npm pack did not produce $name.tgz"
  [ "$(sri_sha512 "$tmp/$name.tgz")" = "${INTEGRITY[$size]}" ] ||
    give_up "$name.tgz does not match its pinned sha512 integrity"
  mv -f "$tmp/$name.tgz" "$tgz"
}

# Makes $CACHE/npm/<name>/package from the tarball; the folder appears only once fully extracted.
extract() {
  local size=$1 dir tmp
  dir=$(package_dir "$size")
  [ -f "$dir/package/package.json" ] && [ "$dir/package/package.json" -nt "$dir.tgz" ] && return 0
  pack "$size"
  tmp=$(mktemp -d "$CACHE/npm/.extract.XXXXXX") || give_up "cannot write to $CACHE/npm"
  TEMPS+=("$tmp")
  tar -xzf "$dir.tgz" -C "$tmp" || give_up "cannot extract $dir.tgz"
  chmod 755 "$tmp"
  touch "$tmp/package/package.json"  # npm stores 1985 mtimes; the freshness test above needs a real one.
  rm -rf "$dir"
  mv "$tmp" "$dir"
}

import_model() {
  local size=$1 scale=$2 out dir log
  out=$(model_path "$size" "$scale")
  [ "$out" -nt "$IMPORTER" ] && return 0
  dir="$(package_dir "$size")/package"
  log=$(mktemp "$CACHE/.import.XXXXXX") || give_up "cannot write to $CACHE"
  TEMPS+=("$log")
  if "$PYTHON" "$IMPORTER" --model "$dir/models/x$scale/model.json" --out "$out" \
      --name "esrgan-$size-x$scale" --source "@upscalerjs/esrgan-$size@$VERSION models/x$scale" \
      --license MIT --stage super_resolution --scale "$scale" --input-range 0 255 \
      --verify-input "$dir/assets/fixture.png" --verify-expected "$dir/assets/samples/${scale}x/result.png" \
      --min-psnr "$MIN_PSNR_DB" >"$log" 2>&1; then
    sed 's/^/fetch_models: /' "$log"
  else
    echo "fetch_models: esrgan-$size-x$scale not imported: $(tail -n 1 "$log"); super-resolution will use" \
         "the classical bicubic upscaler for it" >&2
  fi
}

main() {
  all_current && exit 0
  [ -f "$IMPORTER" ] || give_up "importer $IMPORTER is missing"
  command -v npm >/dev/null 2>&1 || give_up "npm not found"
  command -v tar >/dev/null 2>&1 || give_up "tar not found"
  command -v timeout >/dev/null 2>&1 || give_up "timeout not found"
  "$PYTHON" -c 'import torch, numpy' >/dev/null 2>&1 || give_up "$PYTHON cannot import torch and numpy"
  mkdir -p "$CACHE/npm" 2>/dev/null || give_up "cannot create $CACHE/npm"
  if command -v flock >/dev/null 2>&1; then
    # Two setups at once (parallel CI jobs) would otherwise race on the same temporary-then-rename steps.
    exec 9>"$CACHE/.lock" || give_up "cannot write $CACHE/.lock"
    flock -w 900 9 || give_up "another fetch_models holds $CACHE/.lock"
    all_current && exit 0
  fi
  local size scale
  for size in $SIZES; do
    extract "$size"
    for scale in $SCALES; do
      import_model "$size" "$scale"
    done
  done
}

main "$@"
