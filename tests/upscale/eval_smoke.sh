#!/usr/bin/env bash
# kestrel_upscale_eval and kestrel_pipeline_eval end to end on a tiny clip rendered here (the
# built-in Cornell box, 3 frames: 48x32 targets, inputs at 1/2 and 1/4 point-sampled at the
# jitter), so the evaluation programs cannot rot.
set -euo pipefail
kestrel=$1 upscale_eval=$2 pipeline_eval=$3 dir=$4
rm -rf "$dir" && mkdir -p "$dir/test_box"
common=(render-sequence builtin:cornell_box --path orbit:6 --frames 3 --max-depth 3 --clamp 8 --quiet)
"$kestrel" "${common[@]}" --res 48x32 --spp 16 --seed 7 -o "$dir/test_box/full" --pfm "$dir/test_box/full/pfm" > /dev/null
for f in 2 4; do
  "$kestrel" "${common[@]}" --res $((48 / f))x$((32 / f)) --spp 4 --fixed-jitter --seed 11 -o "$dir/test_box/x$f" \
    --pfm "$dir/test_box/x$f/pfm" > /dev/null
done
cat > "$dir/manifest.json" <<JSON
{"clips": {"test_box": {"split": "test", "scene": "builtin:cornell_box", "path": "orbit:6", "env": "default",
 "frames": 3, "res": "48x32", "max_depth": 3, "clamp": 8.0}}}
JSON
"$upscale_eval" --dataset "$dir" --out "$dir/upscale" --quick --repeat 1
grep -q "neural (learned TAAU)" "$dir/upscale/eval.md"
test -s "$dir/upscale/test_box_x4_crops.png"
"$pipeline_eval" --dataset "$dir" --out "$dir/pipeline" --quick --timing-scene builtin:cornell_box --timing-path orbit:10
grep -q "neural + neural" "$dir/pipeline/eval.md"
grep -q "| 2 | 320x180 | 4 |" "$dir/pipeline/eval.md"
