#!/usr/bin/env bash
# `kestrel view` under a virtual X server: it runs a few frames along a path and writes what
# the window shows; without the overlay that must be, bit for bit, the frame `kestrel run`
# writes for the same path (same pipeline, same seeds); with the overlay it must differ
# (text drawn) and not be blank. Skips (77) without xvfb-run or an SDL2 build.
set -euo pipefail
kestrel=$1
out=$2
command -v xvfb-run >/dev/null || { echo "xvfb-run not installed: skipped"; exit 77; }
if "$kestrel" view builtin:nope --frames 1 2>&1 | grep -q "without SDL2"; then echo "built without SDL2: skipped"; exit 77; fi
rm -rf "$out" && mkdir -p "$out"
args=(builtin:cornell_box --path orbit:20 --frames 3 --res 320x180 --internal 160x90 --max-depth 3)
"$kestrel" run "${args[@]}" -o "$out/headless" --quiet > /dev/null
timeout 300 xvfb-run -a "$kestrel" view "${args[@]}" --screenshot "$out/plain.png" --no-overlay
timeout 300 xvfb-run -a "$kestrel" view "${args[@]}" --screenshot "$out/overlay.png"
cmp "$out/headless/frame_0002.png" "$out/plain.png" || { echo "FAIL: the window differs from the headless frame"; exit 1; }
if cmp -s "$out/plain.png" "$out/overlay.png"; then echo "FAIL: the overlay drew nothing"; exit 1; fi
/usr/bin/python3 - "$out/plain.png" "$out/overlay.png" <<'PY'
import sys
from PIL import Image
for path in sys.argv[1:]:
    im = Image.open(path).convert("L")
    lo, hi = im.getextrema()
    assert im.size == (320, 180), f"{path}: size {im.size}"
    assert hi - lo > 60, f"{path}: blank (values {lo}..{hi})"
a, b = (Image.open(p).convert("RGB") for p in sys.argv[1:])
# The overlay sits in the top-left corner; the bottom half is the frame itself.
box = (0, 120, 320, 180)
assert list(a.crop(box).getdata()) == list(b.crop(box).getdata()), "the overlay changed the frame below it"
print("view: window matches the headless frame; overlay drawn")
PY
