#!/usr/bin/env bash
# Packs what a GPU machine without Debian's packages needs to run SynthDrive's GPU work (docs/gpu.md):
#   <out>/deps   headers and libraries for building the model runtime against a CUDA LibTorch there
#                (tools/gpu/CMakeLists.txt), and GoogleTest's sources;
#   <out>/bin    the CUDA-enabled programs of a build made here (-DSYNTHDRIVE_WITH_CUDA=ON), and
#   <out>/lib    the shared libraries they load that a stock CUDA image lacks (found with ldd);
#   <out>/models the installed super-resolution model, for the end-to-end generate benchmark;
#   <out>/clip   CLIP's BPE vocabulary and reference tokenisations, from ../shared/data/models/clip when it is
#                there (the CLIP check of run_gpu.sh).
# Usage: tools/gpu/pack.sh <cuda-build-dir> <out-dir>   (a build dir of "-" packs no programs: the model runtime
#        is built on the GPU machine from the sources and deps/)
set -euo pipefail
build=${1:?usage: pack.sh <cuda-build-dir> <out-dir>}
out=${2:?usage: pack.sh <cuda-build-dir> <out-dir>}
rm -rf "$out.tmp" && mkdir -p "$out.tmp"/{deps/include,deps/lib,bin,lib,models,clip}

inc=/usr/include
cp -r $inc/eigen3 $inc/nlohmann $inc/stb $inc/oneapi $inc/tbb "$out.tmp/deps/include/"
cp $inc/tiny_gltf.h $inc/tiny_obj_loader.h $inc/nanoflann.hpp $inc/zlib.h $inc/zconf.h "$out.tmp/deps/include/"
lib=/usr/lib/x86_64-linux-gnu
cp -L $lib/libtbb.so.12 $lib/libstb.so $lib/libtinyobjloader.so $lib/libz.so.1 "$out.tmp/deps/lib/"
# Programs linked against them ask for their sonames (libstb.so.0, ...), not the development links' names.
for so in libstb.so libtinyobjloader.so; do
  soname=$(objdump -p "$lib/$so" | awk '/SONAME/ {print $2}')
  [[ -n $soname && $soname != "$so" ]] && ln -sf "$so" "$out.tmp/deps/lib/$soname"
done
cp -r /usr/src/googletest "$out.tmp/deps/googletest"

if [[ $build != - ]]; then
  for program in bench_refine bench_generate; do
    [[ -x $build/bin/$program ]] && cp "$build/bin/$program" "$out.tmp/bin/"
  done
  for t in "$build"/tests/raster_*; do cp "$t" "$out.tmp/bin/"; done
fi
# Libraries the programs need, except the C/C++ runtime every Linux has (glibc, libstdc++, libgcc, libm).
if compgen -G "$out.tmp/bin/*" > /dev/null; then
  ldd "$out.tmp"/bin/* 2>/dev/null | awk '/=> \// {print $3}' | sort -u |
    grep -Ev '/(libc|libm|libdl|librt|libpthread|libstdc\+\+|libgcc_s|ld-linux-x86-64)\.so' |
    while read -r so; do cp -L "$so" "$out.tmp/lib/"; done
fi
models=${SYNTHDRIVE_MODELS:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/models}
[[ -f $models/esrgan-slim-x2.pt ]] && cp "$models/esrgan-slim-x2.pt" "$out.tmp/models/"
clip_data=$(dirname "$0")/../../../shared/data/models/clip
if [[ -f $clip_data/bpe_simple_vocab_16e6.txt.gz ]]; then
  cp "$clip_data/bpe_simple_vocab_16e6.txt.gz" "$clip_data/reference_tokens.json" "$out.tmp/clip/"
fi
rm -rf "$out" && mv "$out.tmp" "$out"
du -sh "$out" "$out"/*
