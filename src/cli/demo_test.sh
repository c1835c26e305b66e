#!/usr/bin/env bash
# `synthdrive demo` end to end on the repo's data (what `make demo` runs): the loop mine -> generate (no learned
# model) -> bank behind its gate -> synth from the bank, and the report that shows where each inserted asset
# came from. No hand-made mesh may be inserted.
# usage: demo_test.sh <synthdrive binary>
set -u
BIN=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail=0
bad() { fail=$((fail + 1)); echo "FAIL: $*"; }

"$BIN" demo --out "$T/demo" > "$T/stdout" 2> "$T/stderr" || { bad "demo exited $?: $(tail -5 "$T/stderr")"; echo "1 failed"; exit 1; }
OUT=$T/demo
SYN=$OUT/nuscenes-scene0061-kf0-synth
grep -q "report: $SYN/report.html" "$T/stdout" || bad "demo does not print the report's path"
[ -s "$SYN/report.html" ] || bad "no report.html"
# The bank: assets passed the gate, and every catalogued folder lies in the published output (not the staging one).
"$BIN" -q bank verify --bank "$OUT/bank.sqlite" > "$T/verify" 2>&1 || bad "bank verify: $(cat "$T/verify")"
"$BIN" -q bank list --bank "$OUT/bank.sqlite" > "$T/list" || bad "bank list"
grep -q traffic_cone "$T/list" || bad "no cone passed the gate: $(cat "$T/list")"
grep -q "\.tmp-" "$T/list" && bad "the bank names the staging folder"
grep -q "\.tmp-" "$SYN/synth.json" "$OUT/scenario.json" && bad "synth.json or scenario.json names the staging folder"
# Inserted objects came from generated assets only: each synth.json asset id is a folder under assets/ whose
# asset.json has a generate stage and quality figures (the shipped CG meshes are never imported).
ids=$(grep -o '"asset": "[^"]*"' "$SYN/synth.json" | sort -u | sed 's/.*: "//; s/"//')
[ -n "$ids" ] || bad "nothing inserted"
for id in $ids; do
  a=$OUT/assets/$id/asset.json
  [ -f "$a" ] || { bad "inserted asset $id is not a generated asset"; continue; }
  grep -q '"stage": "generate"' "$a" || bad "$id: no generate stage"
  grep -q '"real_texture_fraction"' "$a" || bad "$id: no quality figures"
  grep -q "metadrive\|torcs" "$a" && bad "$id: made from a CG mesh"
  # The report's card for it shows its real crop(s) and its turntable.
  grep -q "$id" "$SYN/report.html" || bad "$id: no card in the report"
done
ls "$SYN"/report/assets/*/turntable.png > /dev/null 2>&1 || bad "no turntable in the report"
# Each inserted object at full resolution with its figures against the image's real objects (synth/realism.h).
grep -q "Inserted objects at full resolution" "$SYN/report.html" || bad "no full-resolution crops in the report"
ls "$SYN"/report/crop*_after.png > /dev/null 2>&1 || bad "no crop images in the report"
# And whether a classifier tells the inserts from the real objects by those figures.
grep -qE "with a balanced accuracy of <b>[01]\.[0-9]{2}</b>" "$SYN/report.html" || bad "no real-vs-inserted classifier in the report"
grep -qE 'src="https?:|href="https?:' "$SYN/report.html" && bad "the report references the network"
# The log hits were mined and harvested: their assets exist (whether or not the gate let them in).
[ -s "$OUT/mine/run/manifest.jsonl" ] || bad "no mining run"
n_log=$(grep -l '"stage": "harvest"' "$OUT"/assets/*/asset.json 2>/dev/null | wc -l)
[ "$n_log" -ge 3 ] || bad "only $n_log assets harvested from the logs"
echo "$fail failed"
[ $fail -eq 0 ]
