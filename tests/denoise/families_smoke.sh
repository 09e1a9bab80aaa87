#!/usr/bin/env bash
# scripts/denoise/families.py end to end: every family's scene (seed 3) is made twice (the
# same files: everything follows from the seed), loads, and renders one tiny frame with the
# family's lighting flags, so the training-data generator cannot rot. Each scene is also
# written as glTF (--gltf, the writer of the scenes with animated objects) and must render the
# same frames as its OBJ (to float rounding of the emission's factor and strength); and with
# animated objects (--movers) it must load, move and render without a warning.
set -euo pipefail
kestrel=$1 dir=$2 python=${3:-/usr/bin/python3}  # Debian's: it has PIL (python3-pil) and numpy
here=$(cd "$(dirname "$0")" && pwd)
gen="$here/../../scripts/denoise/families.py"
rm -rf "$dir" && mkdir -p "$dir"
field() { "$python" -c "import json,sys; v=json.load(open(sys.argv[1]))[sys.argv[2]]; print('\n'.join(v) if isinstance(v, list) else v)" "$1" "$2"; }
render() {  # render SCENE_JSON OUT [extra flags...]: 2 frames at 32x18, 1 spp, PFMs in OUT/pfm
  local json=$1 out=$2; shift 2
  mapfile -t flags < <(field "$json" flags)
  "$kestrel" render-sequence "$(field "$json" scene)" --path "$(field "$json" path)" --frames 2 \
    --res 32x18 --spp 1 --quiet "${flags[@]}" "$@" -o "$out" --pfm "$out/pfm" > /dev/null 2> "$out.err"
  test -s "$out/frame_0001.exr"
  if grep -q . "$out.err"; then cat "$out.err"; exit 1; fi  # not even a warning
}
same_pfms() {  # same_pfms A B: every PFM of A equals B's to 1e-4 relative
  "$python" - "$1" "$2" <<'EOF'
import pathlib, sys
import numpy as np
def pfm(p):
    b = p.read_bytes().split(b"\n", 3)
    w, h = map(int, b[1].split())
    return np.frombuffer(b[3], "<f4" if float(b[2]) < 0 else ">f4").reshape(h, w, -1)
a, b = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
files = sorted(a.rglob("*.pfm"))
assert files, f"no PFMs in {a}"
for f in files:
    x, y = pfm(f), pfm(b / f.relative_to(a))
    d = np.abs(x - y) / (np.abs(x) + 1e-3)
    assert d.max() < 1e-4, f"{f.relative_to(a)}: OBJ and glTF differ by {d.max():.3g} (relative)"
EOF
}
for family in $("$python" "$gen" --list | cut -d' ' -f1); do
  "$python" "$gen" --no-movers "$family" 3 "$dir/$family/a" > "$dir/$family.json"
  "$python" "$gen" --no-movers "$family" 3 "$dir/$family/b" > /dev/null
  cmp "$dir/$family/a/scene.obj" "$dir/$family/b/scene.obj"
  cmp "$dir/$family/a/scene.mtl" "$dir/$family/b/scene.mtl"
  render "$dir/$family.json" "$dir/$family/out"
  "$python" "$gen" --gltf "$family" 3 "$dir/$family/gltf" > "$dir/$family.gltf.json"
  render "$dir/$family.gltf.json" "$dir/$family/out_gltf"
  same_pfms "$dir/$family/out/pfm" "$dir/$family/out_gltf/pfm"
  "$python" "$gen" --movers "$family" 3 "$dir/$family/m" > "$dir/$family.movers.json"
  "$python" "$gen" --movers "$family" 3 "$dir/$family/m2" > /dev/null
  cmp "$dir/$family/m/scene.gltf" "$dir/$family/m2/scene.gltf"
  cmp "$dir/$family/m/scene.bin" "$dir/$family/m2/scene.bin"
  test "$(field "$dir/$family.movers.json" movers)" -ge 1
  "$python" - "$dir/$family/m/scene.gltf" <<'EOF'
import json, sys
doc = json.load(open(sys.argv[1]))
channels = doc["animations"][0]["channels"]
moved = {c["target"]["node"] for c in channels if c["target"]["path"] == "translation"}
assert moved and all(doc["nodes"][n]["name"].startswith("mover_") for n in moved), moved
EOF
  render "$dir/$family.movers.json" "$dir/$family/out_movers"
done
"$python" "$gen" --list | grep -q "gallery heldout"
echo "families: $("$python" "$gen" --list | tr '\n' ' ')"
