#!/usr/bin/env bash
# Installs the Debian 12 packages SynthDrive builds and runs with, when they are missing.
# Idempotent and quiet when everything is present. Besides Debian's packages, the only downloads are from the
# npm registry, both optional and cached outside the tree: the super-resolution weights
# (scripts/fetch_models.sh) and three.js for the report's 3D asset view (scripts/fetch_web.sh).
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config
  libeigen3-dev nlohmann-json3-dev libcli11-dev libtbb-dev libembree-dev
  libstb-dev libtinygltf-dev libtinyobjloader-dev
  libnanoflann-dev zlib1g-dev
  libfaiss-dev libcurl4-openssl-dev libsqlite3-dev libssl-dev
  # OpenBLAS takes over libblas.so.3 (Debian alternatives) from the netlib reference BLAS: LibTorch's matrix
  # products (CLIP, the learned stages) and FAISS's batched search run about 11x faster with it.
  libopenblas0-pthread
  libtorch-dev python3-torch python3-onnx
  # Python's own pickle consumers: the tests check that numpy and pandas load the pickles we write.
  python3-numpy python3-pandas
  # WordNet 3.0 (noun files), for prompts without CLIP: `mine query` reads "lorry" as a truck (mining/lexicon.h).
  wordnet-base
  libgtest-dev libgmock-dev libbenchmark-dev
)
# npm fetches the super-resolution weights and three.js; Node may already come from elsewhere (keep that one).
command -v npm >/dev/null 2>&1 || PACKAGES+=(npm)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# Both never fail set-up: offline, they say what is missing in one line and SynthDrive goes on without it.
fetch_npm() {
  "$(dirname "${BASH_SOURCE[0]}")/fetch_models.sh"
  "$(dirname "${BASH_SOURCE[0]}")/fetch_web.sh"
}
if [ ${#missing[@]} -eq 0 ]; then
  fetch_npm
  exit 0
fi

echo "setup: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
  SUDO="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fetch_npm
