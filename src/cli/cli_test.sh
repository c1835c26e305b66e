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
"$BIN" -q views --mesh "$CONE" --size 32 --out "$T/views_for_image" >/dev/null
expect_error "generate: single image without models" "needs the multi-view diffusion" "$T/g2" -- env SYNTHDRIVE_MODELS="$T/no_models" "$BIN" -q generate --image "$T/views_for_image/image_00.png" --category traffic_cone --out "$T/g2"
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
  && [ "$(grep -c '"category":"car"' "$T/mr/manifest.jsonl")" -eq "$(wc -l < "$T/mr/manifest.jsonl")" ] \
  && ok || bad "mine query by label"
for k in 0 1; do "$BIN" -q mine index --log "$INFO" --log "$DATA/driving/kitti-object" --out "$T/mi_split" --clip none --shard $k/2; done
[ "$(ls "$T/mi_split/shards" | sort)" = "$(ls "$T/mi/shards" | sort)" ] && ok || bad "mine index --shard 0/2 + 1/2 = the whole index"
expect_error "mine: missing log" "nope.json: no such file" "$T/mi2" -- "$BIN" -q mine index --log "$T/nope.json" --out "$T/mi2" --clip none
expect_error "mine: bad shard" "--shard '2/2'" "$T/mi3" -- "$BIN" -q mine index --log "$INFO" --out "$T/mi3" --clip none --shard 2/2
expect_error "mine: not an index" "not a mining index" "$T/mr2" -- "$BIN" -q mine query --index "$T" --prompt car --out "$T/mr2"
expect_error "mine: prompt without a category and no CLIP" "names no known category" "$T/mr3" -- "$BIN" -q mine query --index "$T/mi" --prompt "purple elephant" --out "$T/mr3"
expect_error "mine: existing run" "mr: exists" "" -- "$BIN" -q mine query --index "$T/mi" --prompt car --out "$T/mr"
printf '{"id": 1}\n' > "$T/bad_manifest.jsonl"
expect_error "generate: malformed manifest" "bad_manifest.jsonl:1" "$T/g5" -- "$BIN" -q generate --manifest "$T/bad_manifest.jsonl" --out "$T/g5"
expect_error "generate: manifest without models" "needs the multi-view diffusion" "$T/g6" -- env SYNTHDRIVE_MODELS="$T/no_models" "$BIN" -q generate --manifest "$T/mr/manifest.jsonl" --out "$T/g6"

echo "$pass passed, $fail failed"
[ $fail -eq 0 ]
