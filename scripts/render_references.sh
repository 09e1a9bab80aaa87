#!/usr/bin/env bash
# 1024-spp reference renders of every shared scene (docs/references/*.png) and their times
# (docs/references/README.md). Usage: scripts/render_references.sh [BUILD_DIR] [SPP]
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${1:-$here/build/release}
spp=${2:-1024}
scenes=$here/../shared/scenes
out=$here/docs/references
mkdir -p "$out"
table=$out/README.md
{
  echo "# Reference renders"
  echo
  echo "\`scripts/render_references.sh\`: \`kestrel render\` at $spp spp, max depth 8, seed 0, both threads of"
  echo "the 2-vCPU machine, the default environment (the white overcast sky for scenes without"
  echo "emitters; also for the water bottle, whose only emitter is its small label), tone map of"
  echo "docs/renderer.md. Time = the render alone (wall clock)."
  echo
  echo "| scene | view | resolution | triangles | time (s) | Mrays/s | image |"
  echo "|---|---|---|---:|---:|---:|---|"
} > "$table"
render() {  # name file view res exposure [extra args]
  local name=$1 file=$2 view=$3 res=$4 exposure=$5
  shift 5
  [ -f "$file" ] || { echo "skip $name (no $file)"; return; }
  local log
  log=$("$build/apps/kestrel/kestrel" render "$file" --view "$view" --res "$res" --spp "$spp" --quiet \
        --exposure "$exposure" --png "$out/$name.png" "$@")
  local tris ms mrays
  tris=$(echo "$log" | sed -n 's/^scene .*(\([0-9]*\) triangles.*/\1/p')
  ms=$(echo "$log" | sed -n 's/^render .* in \([0-9.]*\) ms.*/\1/p')
  mrays=$(echo "$log" | sed -n 's/.*rays, \([0-9.]*\) Mrays\/s.*/\1/p')
  printf '| %s | %s | %s | %s | %.1f | %s | ![%s](%s.png) |\n' "$name" "$view" "$res" "$tris" \
    "$(echo "$ms / 1000" | bc -l)" "$mrays" "$name" "$name" >> "$table"
  echo "$name: $(echo "$ms / 1000" | bc -l | cut -c1-6) s"
}
render cornell_box "$scenes/cornell_box/cornell_box.obj" front 320x320 0
render dabrovic_sponza "$scenes/dabrovic_sponza/sponza.obj" inside 320x180 2
render teapot "$scenes/teapot/teapot.obj" framing 320x240 0
render stanford_bunny "$scenes/stanford_bunny/stanford_bunny.obj" framing 320x240 0
render lamborghini "$scenes/lamborghini/lamborghini.obj" framing 320x240 0
render bunny_grid "$scenes/bunny_grid/bunny_grid.obj" framing 320x240 0
render gltf_cornell_box "$scenes/gltf_cornell_box/cornell_box.gltf" front 320x320 0
render gltf_flight_helmet "$scenes/gltf_flight_helmet/FlightHelmet.gltf" framing 240x320 0
render gltf_water_bottle "$scenes/gltf_water_bottle/WaterBottle.gltf" framing 240x320 0 --env sky
render gltf_box_animated "$scenes/gltf_box_animated/BoxAnimated.gltf" framing 320x240 0
render gltf_cesium_milk_truck "$scenes/gltf_cesium_milk_truck/CesiumMilkTruck.gltf" framing 320x240 0
render gltf_truck_fleet "$scenes/gltf_truck_fleet/truck_fleet.gltf" framing 320x240 0
render gltf_animated_morph_cube "$scenes/gltf_animated_morph_cube/AnimatedMorphCube.gltf" framing 320x240 0
render gltf_morph_stress_test "$scenes/gltf_morph_stress_test/MorphStressTest.gltf" framing 320x240 0
render gltf_fox "$scenes/gltf_fox/Fox.glb" framing 320x240 0
