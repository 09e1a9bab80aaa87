#!/usr/bin/env bash
# kestrel_denoise_eval end to end on a tiny clip rendered here (the built-in Cornell box,
# 3 frames of 32x24, 1 spp against 16 spp), so the evaluation program cannot rot.
set -euo pipefail
kestrel=$1 eval=$2 dir=$3
rm -rf "$dir" && mkdir -p "$dir/test_box"
for spp in 1 16; do
  out="$dir/test_box/$([ "$spp" = 1 ] && echo spp1 || echo ref)"
  "$kestrel" render-sequence builtin:cornell_box --path orbit:6 --frames 3 --res 32x24 --spp "$spp" --seed "$spp" \
    --quiet -o "$out" --pfm "$out/pfm" > /dev/null
done
echo '{"clips": {"test_box": {"split": "test"}}}' > "$dir/manifest.json"
"$eval" --dataset "$dir" --out "$dir/eval" --quick --repeat 1
grep -q "neural (recurrent)" "$dir/eval/eval.md"
grep -q "rae (Chaitanya 2017)" "$dir/eval/eval.md"
test -s "$dir/eval/test_box_crops.png"
