#!/usr/bin/env bash
# scripts/denoise/families.py end to end: every family's scene (seed 3) is made twice (the
# same files: everything follows from the seed), loads, and renders one tiny frame with the
# family's lighting flags, so the training-data generator cannot rot.
set -euo pipefail
kestrel=$1 dir=$2 python=${3:-/usr/bin/python3}  # Debian's: it has PIL (python3-pil)
here=$(cd "$(dirname "$0")" && pwd)
gen="$here/../../scripts/denoise/families.py"
rm -rf "$dir" && mkdir -p "$dir"
for family in $("$python" "$gen" --list | cut -d' ' -f1); do
  "$python" "$gen" "$family" 3 "$dir/$family/a" > "$dir/$family.json"
  "$python" "$gen" "$family" 3 "$dir/$family/b" > /dev/null
  cmp "$dir/$family/a/scene.obj" "$dir/$family/b/scene.obj"
  cmp "$dir/$family/a/scene.mtl" "$dir/$family/b/scene.mtl"
  mapfile -t flags < <("$python" -c "import json,sys; print('\n'.join(json.load(open(sys.argv[1]))['flags']))" "$dir/$family.json")
  "$kestrel" render-sequence "$dir/$family/a/scene.obj" --path "$dir/$family/a/path.json" --frames 2 \
    --res 32x18 --spp 1 --quiet "${flags[@]}" -o "$dir/$family/out" > /dev/null 2> "$dir/$family.err"
  test -s "$dir/$family/out/frame_0001.exr"
  if grep -q . "$dir/$family.err"; then cat "$dir/$family.err"; exit 1; fi  # not even a warning
done
"$python" "$gen" --list | grep -q "gallery heldout"
echo "families: $("$python" "$gen" --list | tr '\n' ' ')"
