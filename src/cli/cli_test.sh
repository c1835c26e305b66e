#!/usr/bin/env bash
# End-to-end CLI checks: every bad input gets one line naming the file and the problem, a non-zero exit,
# and no output directory; good runs write a dataset our own reader opens again.
# usage: cli_test.sh <synthdrive binary> <repo data dir>
set -u
BIN=$1
DATA=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
pass=0
fail=0
ok() { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*"; }

INFO=$DATA/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json

# Assets used by the checks below.
"$BIN" -q asset import --mesh "$DATA/assets/metadrive_traffic_cone/scene.gltf" --up +y --height 0.7 \
  --category traffic_cone --out "$T/cone" || bad "asset import"
cat > "$T/one_cone.json" <<'J'
{"seed": 3, "objects": [{"category": "traffic_cone", "count": 1, "distance_m": [6, 15], "lateral_m": [-3, 3]}]}
J

# LibTorch is loaded only by a process that runs a model (models/torch_backend.h): listing the categories maps
# none of its libraries.
if LD_DEBUG=files "$BIN" categories 2>&1 >/dev/null | grep -q "file=libtorch"; then
  bad "synthdrive categories loaded LibTorch"
else
  ok
fi

# expect_error <name> <fragment expected in stderr> <output dir that must not exist> -- command...
expect_error() {
  local name=$1 fragment=$2 out=$3
  shift 4
  "$@" >"$T/stdout" 2>"$T/stderr"
  local rc=$?
  local lines
  lines=$(grep -c . "$T/stderr")
  if [ $rc -eq 0 ]; then bad "$name: exit 0"; return; fi
  if ! grep -q -- "$fragment" "$T/stderr"; then bad "$name: stderr lacks '$fragment': $(cat "$T/stderr")"; return; fi
  if [ "$lines" -ne 1 ]; then bad "$name: $lines lines of error output: $(cat "$T/stderr")"; return; fi
  if [ -n "$out" ] && [ -e "$out" ]; then bad "$name: output $out was created"; return; fi
  if ls "$T" | grep -q '\.tmp-'; then bad "$name: temporary output left behind"; return; fi
  ok
}

synth() { "$BIN" -q synth "$@"; }

expect_error "missing log" "nope.json: no such file" "$T/o1" -- synth --log "$T/nope.json" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/o1"
printf '{"data_list": [' > "$T/broken.json"
expect_error "malformed info JSON" "broken.json: malformed JSON" "$T/o2" -- synth --log "$T/broken.json" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/o2"
printf '{"objects": [' > "$T/bad_scenario.json"
expect_error "malformed scenario" "bad_scenario.json: malformed JSON" "$T/o3" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/bad_scenario.json" --out "$T/o3"
expect_error "asset folder without asset.json" "not an asset folder" "$T/o4" -- synth --log "$INFO" --asset "$DATA/assets/torcs_p406" --scenario "$T/one_cone.json" --out "$T/o4"
cp -r "$T/cone" "$T/odd" && sed -i 's/"traffic_cone"/"flying_saucer"/' "$T/odd/asset.json"
expect_error "unknown category" "unknown category 'flying_saucer'" "$T/o5" -- synth --log "$INFO" --asset "$T/odd" --scenario "$T/one_cone.json" --out "$T/o5"
cp -r "$T/cone" "$T/corrupt" && printf 'glTF garbage' > "$T/corrupt/mesh.glb"
expect_error "corrupt asset mesh" "mesh.glb" "$T/o6" -- synth --log "$INFO" --asset "$T/corrupt" --scenario "$T/one_cone.json" --out "$T/o6"
cat > "$T/crowd.json" <<'J'
{"objects": [{"category": "traffic_cone", "count": 400, "distance_m": [6, 8], "lateral_m": [-1, 1]}]}
J
expect_error "impossible scenario" "impossible scenario" "$T/o7" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/crowd.json" --out "$T/o7"
# A dataset whose sweep is truncated (size not a whole number of 20-byte records).
mkdir -p "$T/trunc" && cp -r "$DATA/driving/nuscenes-scene0061-kf0/." "$T/trunc/" && chmod -R u+w "$T/trunc"
SWEEP=$(ls "$T"/trunc/samples/LIDAR_TOP/*.pcd.bin)
head -c 1003 "$SWEEP" > "$SWEEP.x" && mv "$SWEEP.x" "$SWEEP"
expect_error "truncated sweep" "not a whole number of 20-byte records" "$T/o8" -- synth --log "$T/trunc/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/o8"
expect_error "impossible asset scale" "impossible scale" "$T/a1" -- "$BIN" -q asset import --mesh "$DATA/assets/torcs_p406/obj/torcs_p406.obj" --category car --scale -2 --out "$T/a1"
expect_error "missing mesh" "missing.obj: file not found" "$T/a2" -- "$BIN" -q asset import --mesh "$T/missing.obj" --category car --out "$T/a2"

# A good run, then: the existing output is refused and left intact.
if synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/good"; then
  [ -f "$T/good/report.html" ] && [ -f "$T/good/synth.json" ] && [ -f "$T/good/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" ] \
    && [ "$(ls "$T"/good/samples/*/* | wc -l)" -eq 7 ] && ok || bad "good run: missing outputs"
  before=$(find "$T/good" -type f -exec md5sum {} + | sort | md5sum)
  expect_error "existing output" "already exists" "" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/good"
  after=$(find "$T/good" -type f -exec md5sum {} + | sort | md5sum)
  [ "$before" = "$after" ] && ok || bad "existing output was modified"
  # The derivative dataset reads back through our own reader with one more box.
  synth --log "$T/good/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" --asset "$T/cone" --scenario "$T/one_cone.json" \
    --out "$T/again" && ok || bad "derivative dataset does not read back"
  n=$(grep -o '"num_lidar_pts"' "$T/again/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" | wc -l)
  [ "$n" -eq 71 ] && ok || bad "expected 69 + 1 + 1 boxes after two runs, found $n"
  # LiDAR realism is the default: synth.json names the model fitted from the frame's sweep. --no-lidar-realism
  # is the ideal sensor: "off", the same images, another sweep.
  synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/ideal" --no-lidar-realism \
    && grep -Eq '"lidar_model": ?"off"' "$T/ideal/synth.json" \
    && grep -Eq '"lidar_model": ?"32 lasers \(ring feature\)' "$T/good/synth.json" \
    && diff -r --exclude=LIDAR_TOP "$T/good/samples" "$T/ideal/samples" >/dev/null \
    && ! diff -r "$T/good/samples/LIDAR_TOP" "$T/ideal/samples/LIDAR_TOP" >/dev/null \
    && ok || bad "synth --no-lidar-realism"
else
  bad "good run failed"
fi

# Mesh refinement: oracle views of the cone, a short refinement from their visual hull, geometry metrics.
CONE=$DATA/assets/metadrive_traffic_cone/scene.gltf
"$BIN" -q views --mesh "$CONE" --size 64 --out "$T/views" && [ -f "$T/views/cameras.json" ] && ok || bad "views"
if "$BIN" -q refine --views "$T/views" --out "$T/refined.glb" --steps 2 --iterations 3 --log "$T/refine_log.json"; then
  [ -s "$T/refined.glb" ] && [ -s "$T/refine_log.json" ] && ok || bad "refine: missing outputs"
  "$BIN" -q eval geometry --pred "$T/refined.glb" --gt "$CONE" --samples 2000 --iou-resolution 32 --out "$T/geo.json" >"$T/eval.txt" \
    && grep -q '"chamfer"' "$T/geo.json" && grep -q 'chamfer' "$T/eval.txt" && grep -q 'protocol' "$T/eval.txt" && ok || bad "eval geometry"
  expect_error "refine: existing output" "already exists" "" -- "$BIN" -q refine --views "$T/views" --out "$T/refined.glb"
else
  bad "refine good run failed"
fi
expect_error "refine: views folder without cameras.json" "cameras.json: missing" "$T/r1.glb" -- "$BIN" -q refine --views "$T/nowhere" --out "$T/r1.glb"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n' > "$T/fin.obj"
expect_error "refine: non-manifold coarse mesh" "fin.obj: the mesh is not manifold" "$T/r2.glb" -- "$BIN" -q refine --views "$T/views" --mesh "$T/fin.obj" --out "$T/r2.glb"
: > "$T/empty.obj"
expect_error "refine: empty coarse mesh" "empty.obj" "$T/r3.glb" -- "$BIN" -q refine --views "$T/views" --mesh "$T/empty.obj" --out "$T/r3.glb"
cp -r "$T/views" "$T/views_bad" && cp "$T/views_bad/mask_00.png" "$T/views_bad/keep.png"
"$BIN" -q views --mesh "$CONE" --size 32 --out "$T/views_small" && cp "$T/views_small/mask_02.png" "$T/views_bad/mask_02.png"
expect_error "refine: mask size disagrees" "mask_02.png: image is 32x32" "$T/r4.glb" -- "$BIN" -q refine --views "$T/views_bad" --out "$T/r4.glb"
expect_error "refine: impossible steps" "must be at least 1" "$T/r5.glb" -- "$BIN" -q refine --views "$T/views" --steps 0 --out "$T/r5.glb"
expect_error "refine: unsupported output" "written as .glb or .ply" "" -- "$BIN" -q refine --views "$T/views" --out "$T/r6.obj"
"$BIN" -q eval texture --pred "$CONE" --gt "$CONE" --size 48 --out "$T/tex.json" >"$T/tex.txt" \
  && grep -q '"psnr": 120' "$T/tex.json" && grep -q 'SSIM' "$T/tex.txt" && ok || bad "eval texture of a mesh against itself"
expect_error "eval texture: missing ground truth" "nogt.obj: no such file" "$T/tex2.json" -- "$BIN" -q eval texture --pred "$CONE" --gt "$T/nogt.obj" --out "$T/tex2.json"
# Texture: the refined cone gets the oracle views' colour, baked and as vertex colours.
if [ -s "$T/refined.glb" ]; then
  "$BIN" -q texture --mesh "$T/refined.glb" --views "$T/views" --texture-size 512 --out "$T/textured.glb" \
    && [ -s "$T/textured.glb" ] && ok || bad "texture bake"
  "$BIN" -q texture --mesh "$T/refined.glb" --views "$T/views" --mode vertex --out "$T/vertex.glb" \
    && [ -s "$T/vertex.glb" ] && ok || bad "texture vertex"
  "$BIN" -q eval texture --pred "$T/textured.glb" --gt "$CONE" --size 48 --out "$T/tex3.json" >/dev/null \
    && grep -q '"ssim"' "$T/tex3.json" && ok || bad "eval texture of the baked cone"
fi
# Upscale: one image and a folder, bicubic and whatever "auto" finds; bad models and inputs.
png_size() { od -An -tu1 -j16 -N8 "$1" | awk '{print $3*256+$4 "x" $7*256+$8}'; }
IMG=$T/views/image_00.png
"$BIN" -q upscale --in "$IMG" --out "$T/up_bicubic.png" --model bicubic \
  && [ "$(png_size "$T/up_bicubic.png")" = "$(png_size "$IMG" | awk -Fx '{print $1*2 "x" $2*2}')" ] && ok || bad "upscale bicubic doubles the size"
"$BIN" -q upscale --in "$IMG" --out "$T/up_auto.png" && [ -s "$T/up_auto.png" ] && ok || bad "upscale auto"
mkdir -p "$T/imgs" && cp "$T/views/image_00.png" "$T/views/image_01.png" "$T/imgs/"
"$BIN" -q upscale --in "$T/imgs" --out "$T/imgs_x3" --scale 3 --model bicubic && [ "$(ls "$T/imgs_x3" | wc -l)" -eq 2 ] \
  && ok || bad "upscale a folder"
expect_error "upscale: missing input" "nope.png: no such file" "$T/up1.png" -- "$BIN" -q upscale --in "$T/nope.png" --out "$T/up1.png"
printf 'PK not really a zip' > "$T/corrupt.pt"
expect_error "upscale: corrupt model file" "corrupt.pt: not a readable TorchScript archive" "$T/up2.png" -- "$BIN" -q upscale --in "$IMG" --out "$T/up2.png" --model "$T/corrupt.pt"
expect_error "upscale: unknown model" "esrgan-nope-x2.pt: no such model file" "$T/up3.png" -- "$BIN" -q upscale --in "$IMG" --out "$T/up3.png" --model esrgan-nope
expect_error "upscale: existing output" "up_bicubic.png: already exists" "" -- "$BIN" -q upscale --in "$IMG" --out "$T/up_bicubic.png" --model bicubic
mkdir -p "$T/noimgs"
expect_error "upscale: folder without images" "no .png or .jpg images" "$T/up4" -- "$BIN" -q upscale --in "$T/noimgs" --out "$T/up4"
if [ -s "$T/refined.glb" ]; then
  "$BIN" -q texture --mesh "$T/refined.glb" --views "$T/views" --texture-size 256 --upscale bicubic --out "$T/textured_sr.glb" \
    && [ -s "$T/textured_sr.glb" ] && ok || bad "texture with bicubic super-resolution"
  expect_error "texture: corrupt upscaler" "corrupt.pt: not a readable TorchScript archive" "$T/t2.glb" -- "$BIN" -q texture --mesh "$T/refined.glb" --views "$T/views" --upscale "$T/corrupt.pt" --out "$T/t2.glb"
fi
# Generate: the cone's views -> a metric asset folder that `asset show` and synth accept.
"$BIN" -q generate --views "$T/views" --category traffic_cone --steps 3 --hull-resolution 32 --texture-size 256 \
  --upscale bicubic --out "$T/gen_cone" && [ -f "$T/gen_cone/views/cameras.json" ] \
  && "$BIN" -q asset show "$T/gen_cone" | grep -q "traffic_cone" && grep -q '"views_to_asset"' "$T/gen_cone/asset.json" \
  && ok || bad "generate from views"
printf 'not an image' > "$T/object.png"
expect_error "generate: unreadable image" "object.png" "$T/g1" -- "$BIN" -q generate --image "$T/object.png" --category traffic_cone --out "$T/g1"
# One photo, no learned model: the shape prior path (docs/shape_prior.md) builds a metric asset and records
# the prior; what cannot make a shape is refused in one line with no asset folder.
"$BIN" -q views --mesh "$CONE" --size 160 --out "$T/views_for_image" >/dev/null
PHOTO=$T/views_for_image/image_00.png
env SYNTHDRIVE_MODELS="$T/no_models" "$BIN" -q generate --image "$PHOTO" --mask "$T/views_for_image/mask_00.png" \
  --category traffic_cone --steps 2 --hull-resolution 32 --texture-size 256 --upscale bicubic --out "$T/g_photo" \
  && grep -q '"prior": "revolve"' "$T/g_photo/asset.json" && grep -q '"photo_silhouette_iou"' "$T/g_photo/asset.json" \
  && "$BIN" -q asset show "$T/g_photo" | grep -q "traffic_cone" && ok || bad "generate: one photo by the revolve prior"
# The report's asset card of that photo asset: its real view (the photo) and not the prior's virtual views
# (marked "synthetic" here as the shape prior marks them), the turntable, and no network reference.
if [ -f "$T/g_photo/views/cameras.json" ] && python3 - "$T/g_photo" <<'PY'
import json, sys
asset = json.load(open(sys.argv[1] + "/asset.json"))
real = asset["quality"]["shape_prior"]["real_views"]
path = sys.argv[1] + "/views/cameras.json"
cameras = json.load(open(path))
for k, v in enumerate(cameras["views"]):
    v["synthetic"] = k >= real
json.dump(cameras, open(path, "w"))
PY
then
  id=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["id"])' "$T/g_photo/asset.json")
  card="$T/photo_synth/report/assets/$id"
  if synth --log "$INFO" --asset "$T/g_photo" --scenario "$T/one_cone.json" --out "$T/photo_synth"; then
    [ -s "$card/turntable.png" ] && [ -s "$card/view_00.png" ] && [ ! -e "$card/view_01.png" ] \
      && grep -q "id='asset-$id'" "$T/photo_synth/report.html" && grep -q "href='#asset-$id'" "$T/photo_synth/report.html" \
      && ! grep -qiE 'https?://' "$T/photo_synth/report.html" && ok || bad "synth report: the photo asset's card"
    if [ -f "${SYNTHDRIVE_WEB:-${XDG_CACHE_HOME:-$HOME/.cache}/synthdrive/web}/three/build/three.min.js" ]; then
      [ -s "$T/photo_synth/report/three/three.min.js" ] && [ -s "$T/photo_synth/report/three/LICENSE" ] \
        && [ -s "$card/mesh_glb.js" ] && ok || bad "synth report: three.js viewer files"
    else
      echo "skip: three.js is not installed (scripts/fetch_web.sh); the report's viewer files are not checked"
      grep -q "three.js is not installed" "$T/photo_synth/report.html" && ok || bad "synth report: no note without three.js"
    fi
  else
    bad "synth with the photo asset"
  fi
else
  bad "generate: the photo asset's views/cameras.json"
fi
"$BIN" -q generate --image "$PHOTO" --box 20,10,140,150 --shape hull --category traffic_cone --steps 2 \
  --hull-resolution 32 --texture-size 256 --upscale bicubic --out "$T/g_photo_box" \
  && grep -q '"prior": "hull"' "$T/g_photo_box/asset.json" && ok || bad "generate: one photo, GrabCut in --box, forced hull"
# Masks as binary PGMs: empty, full, and an L that no surface of revolution makes.
pgm() {  # pgm <file> <python expression of (x, y) -> 0/1>
  python3 -c "import sys; w=h=160; sys.stdout.buffer.write(b'P5 160 160 255\n' + bytes(255 if ($2) else 0 for y in range(h) for x in range(w)))" > "$1"
}
pgm "$T/empty_mask.pgm" "False"
pgm "$T/full_mask.pgm" "True"
pgm "$T/ell_mask.pgm" "40 <= x < 120 and 20 <= y < 140 and (x < 60 or y >= 120)"
expect_error "generate: empty mask" "empty_mask.pgm: the mask holds no object" "$T/g2" -- "$BIN" -q generate --image "$PHOTO" --mask "$T/empty_mask.pgm" --category traffic_cone --out "$T/g2"
expect_error "generate: mask of the whole photo" "full_mask.pgm: the mask covers the whole photo" "$T/g2" -- "$BIN" -q generate --image "$PHOTO" --mask "$T/full_mask.pgm" --category traffic_cone --out "$T/g2"
expect_error "generate: revolve on an asymmetric silhouette" "ell_mask.pgm: revolve cannot fit" "$T/g2" -- "$BIN" -q generate --image "$PHOTO" --mask "$T/ell_mask.pgm" --shape revolve --category traffic_cone --out "$T/g2"
expect_error "generate: box outside the photo" "lies outside the 160x160 photo" "$T/g2" -- "$BIN" -q generate --image "$PHOTO" --box 400,400,500,500 --category traffic_cone --out "$T/g2"
expect_error "generate: mask of another size" "mask_00.png: the mask is 32x32" "$T/g2" -- "$BIN" -q generate --image "$PHOTO" --mask "$T/views_small/mask_00.png" --category traffic_cone --out "$T/g2"
expect_error "generate: unknown category" "unknown category 'ufo'" "$T/g3" -- "$BIN" -q generate --views "$T/views" --category ufo --out "$T/g3"
expect_error "generate: existing output" "gen_cone: already exists" "" -- "$BIN" -q generate --views "$T/views" --category traffic_cone --out "$T/gen_cone"
sed 's/"image": "image_0[0-9].png", *//; s/, *"image": "image_0[0-9].png"//' "$T/views/cameras.json" > "$T/noimg.json"
cp -r "$T/views" "$T/views_noimg" && cp "$T/noimg.json" "$T/views_noimg/cameras.json"
expect_error "texture: views without images" "has no \"image\"" "$T/t1.glb" -- "$BIN" -q texture --mesh "$CONE" --views "$T/views_noimg" --out "$T/t1.glb"
expect_error "generate: views without images" "has no colour image" "$T/g4" -- "$BIN" -q generate --views "$T/views_noimg" --category traffic_cone --out "$T/g4"
expect_error "eval: missing prediction" "nothing.glb: no such file" "$T/nothing.geometry.json" -- "$BIN" -q eval geometry --pred "$T/nothing.glb" --gt "$CONE"

# Mine: index the repo's logs, query by label, and the batch/resume contract; bad input named in one line.
"$BIN" -q mine index --log "$INFO" --log "$DATA/driving/kitti-object" --out "$T/mi" --clip none \
  && [ "$(ls "$T/mi/shards" | wc -l)" -eq 2 ] && ok || bad "mine index"
"$BIN" -q mine index --log "$INFO" --log "$DATA/driving/kitti-object" --out "$T/mi" --clip none 2>&1 | grep -q . \
  && bad "mine index rerun printed something with -q" || ok
"$BIN" mine index --log "$INFO" --log "$DATA/driving/kitti-object" --out "$T/mi" --clip none 2>&1 \
  | grep -q "0 new chunks (2 already done" && ok || bad "mine index resumes: nothing rebuilt"
"$BIN" -q mine query --index "$T/mi" --prompt car --prompt "orange traffic cone" --k 5 --out "$T/mr" \
  && [ -s "$T/mr/manifest.jsonl" ] && [ -f "$T/mr/index.html" ] \
  && [ "$(grep -c '"category":"car".*"prompt":"car"' "$T/mr/manifest.jsonl")" -eq "$(grep -c '"prompt":"car"' "$T/mr/manifest.jsonl")" ] \
  && [ "$(grep -c '"category":"traffic_cone".*"prompt":"orange traffic cone"' "$T/mr/manifest.jsonl")" -eq "$(grep -c '"prompt":"orange traffic cone"' "$T/mr/manifest.jsonl")" ] \
  && [ "$(grep -c '"prompt":"car"' "$T/mr/manifest.jsonl")" -gt 0 ] \
  && ok || bad "mine query by label"
for k in 0 1; do "$BIN" -q mine index --log "$INFO" --log "$DATA/driving/kitti-object" --out "$T/mi_split" --clip none --shard $k/2; done
[ "$(ls "$T/mi_split/shards" | sort)" = "$(ls "$T/mi/shards" | sort)" ] && ok || bad "mine index --shard 0/2 + 1/2 = the whole index"
expect_error "mine: missing log" "nope.json: no such file" "$T/mi2" -- "$BIN" -q mine index --log "$T/nope.json" --out "$T/mi2" --clip none
expect_error "mine: bad shard" "--shard '2/2'" "$T/mi3" -- "$BIN" -q mine index --log "$INFO" --out "$T/mi3" --clip none --shard 2/2
mkdir -p "$T/not_an_index"
expect_error "mine: not an index" "not a mining index" "$T/mr2" -- "$BIN" -q mine query --index "$T/not_an_index" --prompt car --out "$T/mr2"
expect_error "mine: prompt without a category and no CLIP" "names no category" "$T/mr3" -- "$BIN" -q mine query --index "$T/mi" --prompt "purple elephant" --out "$T/mr3"
expect_error "mine: an unknown prompt suggests example mode" "mine query --example" "$T/mr3" -- "$BIN" -q mine query --index "$T/mi" --prompt "purple elephant" --out "$T/mr3"
# Prompts that are no dataset label (mining/lexicon.h): a road word, and with WordNet a synonym, each hit of the
# category they name and the run saying why.
"$BIN" -q mine query --index "$T/mi" --prompt pylons --prompt automobile --prompt giraffe --out "$T/mr_lex" \
  && [ "$(grep -c '"prompt":"pylons"' "$T/mr_lex/manifest.jsonl")" -gt 0 ] \
  && [ "$(grep -c '"category":"traffic_cone".*"prompt":"pylons"' "$T/mr_lex/manifest.jsonl")" -eq "$(grep -c '"prompt":"pylons"' "$T/mr_lex/manifest.jsonl")" ] \
  && grep -q 'road word for traffic_cone' "$T/mr_lex/run.json" && grep -q "'giraffe' names no category" "$T/mr_lex/run.json" \
  && { [ ! -f /usr/share/wordnet/index.noun ] || { grep -q 'automobile = car#1' "$T/mr_lex/run.json" \
       && [ "$(grep -c '"category":"car".*"prompt":"automobile"' "$T/mr_lex/manifest.jsonl")" -gt 0 ]; }; } \
  && ok || bad "mine query by lexical prompts"
expect_error "mine: existing run" "mr: exists" "" -- "$BIN" -q mine query --index "$T/mi" --prompt car --out "$T/mr"
printf '{"id": 1}\n' > "$T/bad_manifest.jsonl"
expect_error "generate: malformed manifest" "bad_manifest.jsonl:1" "$T/g5" -- "$BIN" -q generate --manifest "$T/bad_manifest.jsonl" --out "$T/g5"
# Without learned models a log hit is harvested from its log (docs/harvest.md): one asset per hit (per track),
# carrying the quality figures the bank's gate reads; a hit no camera sees whole fails on its own line, exit 1.
env SYNTHDRIVE_MODELS="$T/no_models" "$BIN" -q mine query --index "$T/mi" --prompt barrier --k 3 --out "$T/mr_barrier" \
  && { env SYNTHDRIVE_MODELS="$T/no_models" "$BIN" -q generate --manifest "$T/mr_barrier/manifest.jsonl" \
         --steps 4 --hull-resolution 48 --texture-size 256 --upscale bicubic --out "$T/g6"; [ $? -le 1 ]; } \
  && [ "$(ls "$T"/g6/*/asset.json | wc -l)" -ge 1 ] \
  && grep -q '"lidar_p2m_median_m"' "$(ls "$T"/g6/*/asset.json | head -1)" \
  && grep -q '"real_texture_fraction"' "$(ls "$T"/g6/*/asset.json | head -1)" \
  && grep -q '"source"' "$(ls -d "$T"/g6/*/views | head -1)/cameras.json" \
  && ok || bad "generate --manifest without models: harvested log assets with quality figures"
# The bank's gate: a figure below the bar refuses the asset in one line naming it; --no-gate admits it.
G6=$(ls -d "$T"/g6/*/ | head -1)
# A bank the failed run would have created is not left behind empty.
expect_error "bank add: below the quality gate" "below the bank's quality gate: lidar_p2m_median_m" "$T/gate.sqlite" -- "$BIN" -q bank add --bank "$T/gate.sqlite" --gate "lidar_p2m_median_m<=0.00001" "$G6"
"$BIN" -q bank add --bank "$T/gate.sqlite" --no-gate "$G6" && "$BIN" -q bank list --bank "$T/gate.sqlite" | grep -q barrier \
  && ok || bad "bank add --no-gate"
expect_error "bank add: malformed gate" "--gate 'watertight=1'" "$T/gate2.sqlite" -- "$BIN" -q bank add --bank "$T/gate2.sqlite" --gate watertight=1 "$G6"

# Synth as a batch on the 3-frame KITTI log: shards 0/2 + 1/2 + --merge write what a plain run writes; each
# shard logs its frames; a bad --shard and a merge with a missing part are refused, creating nothing.
SY=(--log "$DATA/driving/kitti-object" --asset "$T/cone" --scenario "$T/one_cone.json" --spp 1 --ao-samples 2)
synth "${SY[@]}" --out "$T/k_plain" && [ ! -e "$T/k_plain.parts" ] && ok || bad "synth kitti plain run"
# eval realism on that output: the inserted cone measured against the frames' real objects; a folder that is no
# synth output is refused in one line, writing nothing.
"$BIN" -q eval realism --synth "$T/k_plain" --out "$T/k_realism.json" > "$T/realism.txt" \
  && grep -q '"inserted_objects"' "$T/k_realism.json" && grep -q "^traffic_cone" "$T/realism.txt" \
  && [ "$(grep -o '"inserted": true' "$T/k_realism.json" | wc -l)" -ge 1 ] && grep -q '"classifier"' "$T/k_realism.json" \
  && grep -q "^real-vs-inserted classifier" "$T/realism.txt" && ok || bad "eval realism on a synth output"
expect_error "eval realism: not a synth output" "no synth.json" "$T/nr.json" -- "$BIN" -q eval realism --synth "$T/cone" --out "$T/nr.json"
synth "${SY[@]}" --out "$T/k_sh" --shard 0/2 && synth "${SY[@]}" --out "$T/k_sh" --shard 0/2 \
  && [ "$(grep -c '"status":"skipped"' "$T/k_sh.parts/log-0-of-2.jsonl")" -eq 2 ] \
  && ok || bad "synth shard rerun skips its finished frames"
synth "${SY[@]}" --out "$T/k_sh" --shard 1/2 && synth "${SY[@]}" --out "$T/k_sh" --merge && diff -r "$T/k_plain" "$T/k_sh" \
  && ok || bad "synth --shard 0/2 + --shard 1/2 + --merge differs from a plain run"
[ "$(cat "$T"/k_sh.parts/log-0-of-2.jsonl "$T"/k_sh.parts/log-1-of-2.jsonl | grep -c '"status":"done"')" -eq 3 ] \
  && ok || bad "synth shard run logs"
expect_error "synth: bad shard" "--shard '2/2'" "$T/k_bad" -- synth "${SY[@]}" --out "$T/k_bad" --shard 2/2
[ ! -e "$T/k_bad.parts" ] && ok || bad "synth: bad shard created parts"
synth "${SY[@]}" --out "$T/k_half" --shard 1/2 || bad "synth --shard 1/2"
expect_error "synth: merge with a missing part" "selected frame(s): 0, 2 (" "$T/k_half" -- synth "${SY[@]}" --out "$T/k_half" --merge

# Synth with arrangements: --dry-run plans the world-fixed objects without assets or rendering (plan.json +
# plan.html); a real run renders the plan (synth.json ties labels to plan objects); --coco adds coco_2d.json.
cat > "$T/closure.json" <<'J'
{"seed": 5, "arrangements": [{"type": "lane_closure", "category": "traffic_cone", "count": 3, "spacing_m": 3, "distance_m": [8, 30]}]}
J
synth --log "$INFO" --scenario "$T/closure.json" --out "$T/dry" --dry-run > "$T/dry.txt" \
  && [ -f "$T/dry/plan.html" ] && [ "$(grep -c '"role": "cone"' "$T/dry/plan.json")" -eq 3 ] \
  && grep -q "3 object(s) planned" "$T/dry.txt" && grep -q "arrangements.0. lane_closure: 1 placed (3 object(s))" "$T/dry.txt" \
  && [ "$(ls "$T/dry" | wc -l)" -eq 2 ] && ok || bad "synth --dry-run: $(cat "$T/dry.txt")"
synth --log "$INFO" --asset "$T/cone" --scenario "$T/closure.json" --out "$T/wf" --spp 1 --ao-samples 2 --coco \
  && [ "$(grep -c '"plan_object"' "$T/wf/synth.json")" -ge 1 ] && [ -f "$T/wf/plan.json" ] && [ -f "$T/wf/plan.html" ] \
  && grep -q '"synthetic":true' "$T/wf/coco_2d.json" && ok || bad "synth of a world-fixed plan with --coco"
synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/coco" --spp 1 --ao-samples 2 --coco \
  && [ "$(grep -o '"synthetic":true' "$T/coco/coco_2d.json" | wc -l)" -ge 1 ] && [ ! -e "$T/coco/plan.json" ] \
  && ok || bad "synth --coco"
expect_error "synth: --dry-run with --merge" "cannot be combined with --merge" "$T/dry2" -- synth --log "$INFO" --scenario "$T/closure.json" --out "$T/dry2" --dry-run --merge
printf '{"arrangements": [{"type": "lane_closure", "count": 80, "spacing_m": 3, "distance_m": [8, 9]}]}\n' > "$T/long_closure.json"
expect_error "synth: unsatisfiable arrangement" "long_closure.json: impossible scenario: arrangements.0. (lane_closure" "$T/dry3" -- synth --log "$INFO" --scenario "$T/long_closure.json" --out "$T/dry3" --dry-run
printf '{"arrangements": [{"type": "ego_lane_object", "category": "debris", "distance_m": [10, 30]}]}\n' > "$T/debris.json"
expect_error "synth: arrangement without an asset of its category" "debris.json: arrangements.0. places a debris" "$T/wf2" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/debris.json" --out "$T/wf2"
printf '{"world_fixed": "yes", "objects": [{"category": "traffic_cone"}]}\n' > "$T/wf_bad.json"
expect_error "synth: world_fixed not a boolean" "wf_bad.json: .world_fixed: expected true/false" "$T/wf3" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/wf_bad.json" --out "$T/wf3"
expect_error "synth: unknown harmoniser" "clasical: no such harmoniser: give none, classical, auto" "$T/h1" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/h1" --harmonizer clasical
printf 'not a zip' > "$T/bad_harmonizer.pt"
expect_error "synth: harmoniser file that is not TorchScript" "bad_harmonizer.pt: " "$T/h2" -- synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/h2" --harmonizer "$T/bad_harmonizer.pt"

# Bank: catalogue a folder of asset folders, reruns are no-ops, queries, verify finds changed files, one-line errors.
BANK=$T/bank.sqlite
"$BIN" -q asset import --mesh "$DATA/assets/metadrive_traffic_cone/scene.gltf" --up +y --height 0.7 \
  --category traffic_cone --out "$T/bank_assets/bank_cone" || bad "bank: import cone"
"$BIN" -q asset import --mesh "$DATA/assets/metadrive_road_barrier/scene.gltf" --up +y --height 0.9 \
  --category barrier --out "$T/bank_assets/bank_barrier" || bad "bank: import barrier"
"$BIN" -q bank add --bank "$BANK" --clip none "$T/bank_assets" && [ "$("$BIN" -q bank list --bank "$BANK" | wc -l)" -eq 3 ] \
  && ok || bad "bank add a folder of asset folders"
"$BIN" bank add --bank "$BANK" --clip none "$T/bank_assets" 2>&1 | grep -q "0 added, 2 unchanged" && ok || bad "bank add rerun is a no-op"
for k in 0 1; do "$BIN" -q bank add --bank "$T/bank_shards.sqlite" --clip none --shard $k/2 "$T/bank_assets" || bad "bank add --shard $k/2"; done
[ "$("$BIN" -q bank list --bank "$T/bank_shards.sqlite")" = "$("$BIN" -q bank list --bank "$BANK")" ] && ok || bad "bank add --shard 0/2 + 1/2 = the whole list"
"$BIN" -q bank query --bank "$BANK" --category traffic_cone --json > "$T/bq.json" \
  && [ "$(grep -c '"id"' "$T/bq.json")" -eq 1 ] && grep -q '"id": "bank_cone"' "$T/bq.json" && ok || bad "bank query by category"
SYNTHDRIVE_BANK="$BANK" "$BIN" -q bank query --max-extent 2,2,0.8 | grep -q "bank_cone" \
  && ! SYNTHDRIVE_BANK="$BANK" "$BIN" -q bank query --max-extent 2,2,0.8 | grep -q "bank_barrier" && ok || bad "bank query by extent (\$SYNTHDRIVE_BANK)"
printf '{"bank": "bank.sqlite", "category": "barrier", "limit": 1}\n' > "$T/bank_query.json"
"$BIN" -q bank query --from "$T/bank_query.json" --json | grep -q '"id": "bank_barrier"' && ok || bad "bank query from a JSON query file"
[ "$("$BIN" -q bank show --bank "$BANK" bank_cone | grep -c '"sha256"')" -eq 3 ] && ok || bad "bank show lists the files"
"$BIN" -q bank verify --bank "$BANK" && ok || bad "bank verify of an intact bank"
# A scenario that takes its assets from the bank instead of --asset.
cat > "$T/bank_scenario.json" <<'J'
{"seed": 3, "assets_from_bank": {"bank": "bank.sqlite", "category": "traffic_cone"},
 "objects": [{"category": "traffic_cone", "count": 1, "distance_m": [6, 15], "lateral_m": [-3, 3]}]}
J
"$BIN" -q synth --log "$INFO" --scenario "$T/bank_scenario.json" --out "$T/bank_synth" --spp 1 --ao-samples 2 \
  && grep -q '"bank_cone"' "$T/bank_synth/synth.json" && ok || bad "synth with assets_from_bank"
printf '{"assets_from_bank": {"bank": "bank.sqlite", "category": "bus"}, "objects": [{"category": "bus"}]}\n' > "$T/bank_none.json"
expect_error "synth: bank query matching nothing" "matches no asset" "$T/bank_synth2" -- "$BIN" -q synth --log "$INFO" --scenario "$T/bank_none.json" --out "$T/bank_synth2"
sed -i 's/"name": "bank_barrier"/"name": "Barrier B"/' "$T/bank_assets/bank_barrier/asset.json"
"$BIN" -q bank add --bank "$BANK" --clip none "$T/bank_assets/bank_barrier" 2>"$T/stderr" && bad "bank add of changed contents: exit 0" \
  || { grep -q "already in the bank" "$T/stderr" && ok || bad "bank add of changed contents: $(cat "$T/stderr")"; }
"$BIN" -q bank add --bank "$BANK" --clip none --replace "$T/bank_assets/bank_barrier" \
  && "$BIN" -q bank show --bank "$BANK" bank_barrier | grep -q '"name": "Barrier B"' && ok || bad "bank add --replace"
rm "$T/bank_assets/bank_cone/preview.png" && printf 'glTF garbage' > "$T/bank_assets/bank_barrier/mesh.glb"
"$BIN" -q bank verify --bank "$BANK" > "$T/verify.txt"; rc=$?
[ $rc -ne 0 ] && grep -q "bank_cone/preview.png: missing" "$T/verify.txt" && grep -q "bank_barrier/mesh.glb: size changed" "$T/verify.txt" \
  && grep -q "bank_barrier: .*not loadable" "$T/verify.txt" && [ "$(wc -l < "$T/verify.txt")" -eq 3 ] \
  && ok || bad "bank verify finds a missing preview and a corrupt mesh: rc $rc, $(cat "$T/verify.txt")"
"$BIN" -q bank add --bank "$T/bank2.sqlite" --clip none "$T/corrupt" "$T/cone" 2>"$T/stderr"; rc=$?
[ $rc -eq 1 ] && [ "$(grep -c . "$T/stderr")" -eq 1 ] && grep -q "corrupt/mesh.glb" "$T/stderr" \
  && [ "$("$BIN" -q bank list --bank "$T/bank2.sqlite" | wc -l)" -eq 2 ] && ok || bad "bank add batch: one failure reported, the rest added (rc $rc)"
"$BIN" -q bank remove --bank "$BANK" bank_cone && ! "$BIN" -q bank list --bank "$BANK" | grep -q bank_cone && ok || bad "bank remove"
expect_error "bank: no bank file" "no bank here" "$T/nobank.sqlite" -- "$BIN" -q bank list --bank "$T/nobank.sqlite"
expect_error "bank: not an asset folder" "neither an asset folder" "$T/bank3.sqlite" -- "$BIN" -q bank add --bank "$T/bank3.sqlite" "$DATA/assets/torcs_p406"
expect_error "bank: unknown id" "no asset 'nope'" "" -- "$BIN" -q bank show --bank "$BANK" nope
expect_error "bank: text query without CLIP" "needs a CLIP model" "" -- "$BIN" -q bank query --bank "$BANK" --text red --clip none
expect_error "bank: not a bank" "not a SynthDrive bank" "" -- "$BIN" -q bank list --bank "$T/one_cone.json"
printf '{"categroy": "car"}\n' > "$T/bad_query.json"
expect_error "bank: bad JSON query" "unknown key 'categroy'" "" -- "$BIN" -q bank query --bank "$BANK" --from "$T/bad_query.json"

# Data loss: an output that is, holds, or lies inside an input is refused before anything is written, with or
# without --overwrite; every input stays byte-identical (checksums of the whole tree before and after).
mkdir -p "$T/dl/parent" && cp -r "$DATA/driving/nuscenes-scene0061-kf0" "$T/dl/parent/log" && chmod -R u+w "$T/dl/parent"
printf 'unrelated\n' > "$T/dl/parent/notes.txt"
cp -r "$T/cone" "$T/dl/cone" && cp -r "$DATA/assets/metadrive_traffic_cone" "$T/dl/mesh"
"$BIN" -q asset import --mesh "$T/dl/mesh/scene.gltf" --up +y --height 0.7 --category traffic_cone --out "$T/dl/cone.glb.d" \
  && cp "$T/dl/cone.glb.d/mesh.glb" "$T/dl/pred.glb" && cp "$T/dl/cone.glb.d/preview.png" "$T/dl/photo.png" || bad "data loss: set-up"
sums() { (cd "$T/dl" && find . -type f ! -name '*.tmp-*' | LC_ALL=C sort | xargs sha256sum); }
sums > "$T/dl_before.txt"
DLINFO=$T/dl/parent/log/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json
expect_data_safe() {
  local name=$1 fragment=$2
  shift 2
  expect_error "$name" "$fragment" "" -- "$@"
  sums > "$T/dl_after.txt"
  if ! cmp -s "$T/dl_before.txt" "$T/dl_after.txt"; then bad "$name: inputs changed: $(diff "$T/dl_before.txt" "$T/dl_after.txt" | head -3)"; sums > "$T/dl_before.txt"; fi
  if ls "$T/dl" "$T/dl/parent" | grep -q '\.tmp-\|\.parts'; then bad "$name: temporary output left behind"; fi
}
DLS=(--asset "$T/dl/cone" --scenario "$T/one_cone.json" --spp 1 --ao-samples 2 --overwrite)
expect_data_safe "data loss: synth --out the log root" "is the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent/log"
expect_data_safe "data loss: synth --out the log's parent" "holds the input" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent"
expect_data_safe "data loss: synth --out the asset folder" "is the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/cone"
expect_data_safe "data loss: synth --out the info file's folder" "lies inside the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent/log/mmdet3d_info"
expect_data_safe "data loss: synth --out inside the log" "lies inside the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent/log/synth"
expect_data_safe "data loss: synth --out another spelling of the folder holding everything" "holds the input" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent/log/../.."
expect_data_safe "data loss: synth --shard over the log" "is the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl/parent/log" --shard 0/1
expect_data_safe "data loss: synth --dry-run over the log" "is the input folder" synth --log "$DLINFO" --scenario "$T/one_cone.json" --overwrite --dry-run --out "$T/dl/parent/log"
expect_data_safe "data loss: asset import over the mesh folder" "holds the input" "$BIN" -q asset import --mesh "$T/dl/mesh/scene.gltf" --up +y --height 0.7 --category traffic_cone --out "$T/dl/mesh" --overwrite
expect_data_safe "data loss: eval geometry --out the ground truth" "is the input file" "$BIN" -q eval geometry --pred "$T/dl/pred.glb" --gt "$T/dl/mesh/scene.gltf" --out "$T/dl/mesh/scene.gltf" --overwrite
expect_data_safe "data loss: eval texture --out the prediction" "is the input file" "$BIN" -q eval texture --pred "$T/dl/pred.glb" --gt "$T/dl/pred.glb" --out "$T/dl/pred.glb" --overwrite
expect_data_safe "data loss: upscale in place" "is the input file" "$BIN" -q upscale --in "$T/dl/photo.png" --out "$T/dl/photo.png" --model bicubic --overwrite
expect_data_safe "data loss: upscale a folder into itself" "is the input folder" "$BIN" -q upscale --in "$T/dl/cone.glb.d" --out "$T/dl/cone.glb.d" --model bicubic --overwrite
expect_data_safe "data loss: refine --out the coarse mesh" "is the input file" "$BIN" -q refine --views "$T/dl/mesh" --mesh "$T/dl/pred.glb" --out "$T/dl/pred.glb" --overwrite
expect_data_safe "data loss: mine index --out the image folder" "is the input folder" "$BIN" -q mine index --images "$T/dl/cone.glb.d" --out "$T/dl/cone.glb.d" --clip none
ln -s "$T/dl/parent/log" "$T/dl_link"
expect_data_safe "data loss: synth --out a symlink to the log" "is the input folder" synth --log "$DLINFO" "${DLS[@]}" --out "$T/dl_link"
rm "$T/dl_link"

# Pickled infos in, pickles out: the repo's nuScenes keyframe and KITTI frame 000008 (mmdet3d v1.x), each written
# back as a .pkl whose untouched keys equal the input's and which holds the added boxes (checked with Python's own
# loader, SD_PANDAS_PYTHON, where CMake found one with numpy; the unit tests compare every value).
PKL=$DATA/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.pkl
KPKL=$DATA/driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl
cat > "$T/kitti_cone.json" <<'J'
{"seed": 5, "objects": [{"category": "traffic_cone", "count": 2, "distance_m": [6, 14], "lateral_m": [-3, 3]}]}
J
for case in "nus:$PKL:$T/one_cone.json" "kitti:$KPKL:$T/kitti_cone.json"; do
  IFS=: read -r tag src scen <<< "$case"
  out=$T/pkl_$tag
  if ! synth --log "$src" --asset "$T/cone" --scenario "$scen" --out "$out" --spp 1 --ao-samples 2 >/dev/null 2>"$T/stderr"; then
    bad "synth --log $tag .pkl: $(cat "$T/stderr")"; continue
  fi
  written=$(cd "$out" && find . -name '*.pkl' | head -1)
  if [ -z "$written" ]; then bad "synth --log $tag .pkl: no .pkl in the output"; continue; fi
  ok
  if [ -n "${SD_PANDAS_PYTHON:-}" ]; then
    if "$SD_PANDAS_PYTHON" - "$src" "$out/$written" > "$T/py.txt" 2>&1 <<'PY'
import pickle, sys
# Our own test output and the repo's files: trusted here, so Python's loader is the reference consumer.
a = pickle.load(open(sys.argv[1], "rb")); b = pickle.load(open(sys.argv[2], "rb"))
ma, mb = a["metainfo"], b["metainfo"]
for k in ma:  # the input's metainfo is kept; new classes are appended to its categories (or a list is added)
    if k != "categories": assert repr(ma[k]) == repr(mb[k]), "metainfo %s differs" % k
for name, i in ma.get("categories", {}).items(): assert mb["categories"][name] == i, "class %s renumbered" % name
ra, rb = a["data_list"][0], b["data_list"][0]
for k in ra:
    if k not in ("instances", "images", "lidar_points", "cam_instances"):
        assert repr(ra[k]) == repr(rb[k]), "key %s differs" % k
na, nb = len(ra["instances"]), len(rb["instances"])
assert nb > na, "no instance added (%d -> %d)" % (na, nb)
assert repr(ra["instances"]) == repr(rb["instances"][:na]), "the input's instances changed"
labels = set(mb["categories"].values())
assert all(x["bbox_label_3d"] in labels for x in rb["instances"][na:]), "an added box's label is not a class"
print(na, nb)
PY
    then ok; else bad "python reads synth's $tag .pkl: $(tail -2 "$T/py.txt")"; fi
  fi
done
# A pickle that would run code if loaded by Python is refused as data, and nothing is written.
printf '\x80\x02cos\nsystem\nq\x00X\x02\x00\x00\x00idq\x01\x85q\x02Rq\x03.' > "$T/evil.pkl"
expect_error "synth: pickle naming a disallowed global" "evil.pkl: byte 2: refusing to load global 'os.system'" "$T/evil_out" -- synth --log "$T/evil.pkl" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/evil_out"

# Exit status (README): 2 for a refused argument, 1 for a batch with failed items (the rest kept).
"$BIN" -q synth --no-such-flag >/dev/null 2>&1; rc=$?
[ $rc -eq 2 ] && ok || bad "an unknown flag exits $rc, not 2"
mkdir -p "$T/mine_imgs" && cp "$DATA"/images/roadanomaly-cones/frames/*.jpg "$T/mine_imgs/"
GOOD=$(ls "$T"/mine_imgs/*.jpg | head -1)
head -c 300 "$GOOD" > "$T/mine_imgs/truncated.jpg"
"$BIN" -q mine index --images "$T/mine_imgs" --out "$T/mi_trunc" --clip none >/dev/null 2>"$T/stderr"; rc=$?
[ $rc -eq 1 ] && [ -d "$T/mi_trunc/shards" ] && grep -q "could not be read" "$T/stderr" && ok \
  || bad "mine index with a truncated image: exit $rc (want 1, the rest indexed): $(cat "$T/stderr")"

# What a killed run left is cleaned up by the next: a parts folder with only a run log, and a dead writer's
# temporary output folder (pid 4194302 above any live one's here; the kernel's pid_max is 4194304).
mkdir -p "$T/stale.parts" "$T/stale.tmp-4194302-0/half" && echo '{}' > "$T/stale.parts/log-0-of-1.jsonl"
synth --log "$INFO" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/stale" \
  && [ -f "$T/stale/synth.json" ] && [ ! -e "$T/stale.parts" ] && [ ! -e "$T/stale.tmp-4194302-0" ] && ok \
  || bad "stale parts and a dead writer's temporary output are removed by the next run: $(ls "$T" | grep stale)"
# A run refused on the way in leaves no parts folder.
expect_error "synth: no parts folder after a refused frame" "not a whole number of 20-byte records" "$T/o_parts" -- synth --log "$T/trunc/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json" --asset "$T/cone" --scenario "$T/one_cone.json" --out "$T/o_parts"
[ ! -e "$T/o_parts.parts" ] && ok || bad "a failed synth left $T/o_parts.parts"

echo "$pass passed, $fail failed"
[ $fail -eq 0 ]
