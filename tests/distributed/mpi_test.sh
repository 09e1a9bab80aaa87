#!/usr/bin/env bash
# Distributed rendering under mpirun on loopback (docs/distributed.md):
# - `render` on 2 and 3 ranks writes every AOV bit-identical to one process (two scenes, with
#   and without the denoiser, thin lens and motion vectors);
# - `render-sequence` on 2 ranks: every frame of an orbit (and of an animated glTF where
#   ../shared/scenes has one) bit-identical to one process;
# - a rank whose scene is missing, and a rank killed mid-frame, make mpirun exit non-zero with
#   a message naming the rank, and leave the existing output file as it was.
#   mpi_test.sh KESTREL_CLI WORK_DIR [SCENES_DIR]
set -euo pipefail
K=$1
work=$2
scenes=${3:-}
mpi=(mpirun --oversubscribe)
[ "$(id -u)" -eq 0 ] && mpi+=(--allow-run-as-root)
rm -rf "$work"
mkdir -p "$work"
cd "$work"

same_dirs() {  # every file of $1 equals the same name in $2
  local n=0
  for f in "$1"/*; do
    cmp -s "$f" "$2/$(basename "$f")" || { echo "FAIL: $f differs from $2/$(basename "$f")"; exit 1; }
    n=$((n + 1))
  done
  [ "$n" -gt 0 ] || { echo "FAIL: $1 is empty"; exit 1; }
}

# A scene made here (a floor, a tilted box and a light panel): nothing the tests saw before.
cat > made.obj <<'OBJ'
v -2 0 -2
v 2 0 -2
v 2 0 2
v -2 0 2
v -0.5 0 -0.5
v 0.5 0 -0.3
v 0.3 0 0.6
v -0.6 0 0.4
v -0.5 1.2 -0.5
v 0.5 1.1 -0.3
v 0.3 1.3 0.6
v -0.6 1.0 0.4
v -0.4 2.5 -0.4
v 0.4 2.5 -0.4
v 0.4 2.5 0.4
v -0.4 2.5 0.4
usemtl floor
f 1 2 3 4
usemtl box
f 5 6 10 9
f 6 7 11 10
f 7 8 12 11
f 8 5 9 12
f 9 10 11 12
usemtl light
f 16 15 14 13
OBJ
cat > made.mtl <<'MTL'
newmtl floor
Kd 0.7 0.7 0.7
newmtl box
Kd 0.8 0.3 0.2
Ks 0.5 0.5 0.5
Ns 200
newmtl light
Kd 0 0 0
Ke 20 18 15
MTL
sed -i '1i mtllib made.mtl' made.obj

render() {  # render NAME RANKS SCENE ARGS...
  local name=$1 ranks=$2 scene=$3
  shift 3
  if [ "$ranks" -eq 1 ]; then
    "$K" render "$scene" --quiet -o "$name.exr" --pfm "$name" "$@" > "$name.log"
  else
    "${mpi[@]}" -n "$ranks" "$K" render "$scene" --quiet -o "$name.exr" --pfm "$name" "$@" > "$name.log"
  fi
}

cam="--camera 3,2.5,4,0,0.8,0,50,0.02,4"
for ranks in 1 2 3; do
  render "cornell_$ranks" "$ranks" builtin:cornell_box --res 150x100 --spp 8 --seed 11 --threads 1
  render "made_$ranks" "$ranks" made.obj --res 130x90 --spp 6 --seed 3 --threads 1 $cam
  render "denoised_$ranks" "$ranks" builtin:cornell_box --res 96x64 --spp 2 --seed 5 --threads 1 --denoise neural
done
for ranks in 2 3; do
  for name in cornell made denoised; do
    same_dirs "${name}_1" "${name}_$ranks"
    cmp "${name}_1.exr" "${name}_$ranks.exr"
  done
  grep -q "parallel efficiency" "cornell_$ranks.log" || { echo "FAIL: no per-rank report"; exit 1; }
done
echo "render: every AOV identical on 1, 2 and 3 ranks"

seq_same() {  # seq_same NAME SCENE ARGS...: render-sequence on 1 and 2 ranks, every frame file equal
  local name=$1 scene=$2
  shift 2
  "$K" render-sequence "$scene" --quiet -o "$name.1" "$@" > /dev/null
  "${mpi[@]}" -n 2 "$K" render-sequence "$scene" --quiet -o "$name.2" "$@" > /dev/null
  same_dirs "$name.1" "$name.2"
}
seq_same orbit made.obj --path orbit:40 --frames 4 --res 80x60 --spp 3 --threads 1 --view framing
if [ -n "$scenes" ] && [ -f "$scenes/gltf_box_animated/BoxAnimated.gltf" ]; then
  seq_same animated "$scenes/gltf_box_animated/BoxAnimated.gltf" --path orbit:20 --frames 3 --res 64x48 --spp 2 \
    --threads 1 --denoise svgf
fi
echo "render-sequence: every frame identical on 1 and 2 ranks"

# Faults. The existing output must survive each.
echo "the old file" > keep.exr
cp keep.exr keep.orig
set +e
"${mpi[@]}" -n 1 "$K" render made.obj --res 64x48 --spp 2 --quiet -o keep.exr : \
  -n 1 "$K" render missing_on_this_rank.obj --res 64x48 --spp 2 --quiet -o keep.exr > missing.log 2>&1
code=$?
set -e
[ "$code" -ne 0 ] || { echo "FAIL: a missing scene on rank 1 exited 0"; exit 1; }
grep -q "rank 1 of 2: error: missing_on_this_rank.obj" missing.log || { echo "FAIL: no message naming rank 1:"; cat missing.log; exit 1; }
cmp keep.exr keep.orig

"${mpi[@]}" -n 2 "$K" render made.obj --res 320x240 --spp 4000 --threads 1 --quiet -o keep.exr > killed.log 2>&1 &
launcher=$!
victim=""
for _ in $(seq 1 200); do  # find rank 1 by its environment
  # this run's binary only (another clone's test may run the same command at the same time)
  for pid in $(pgrep -f "$K render made.obj --res 320x240" || true); do
    if tr '\0' '\n' < "/proc/$pid/environ" 2>/dev/null | grep -qx "OMPI_COMM_WORLD_RANK=1"; then victim=$pid; fi
  done
  [ -n "$victim" ] && break
  sleep 0.05
done
[ -n "$victim" ] || { echo "FAIL: rank 1 never started"; kill "$launcher"; exit 1; }
sleep 0.5
kill -9 "$victim"
set +e
wait "$launcher"
code=$?
set -e
[ "$code" -ne 0 ] || { echo "FAIL: mpirun exited 0 after rank 1 was killed"; exit 1; }
grep -qi "rank 1" killed.log || { echo "FAIL: mpirun did not name rank 1:"; cat killed.log; exit 1; }
cmp keep.exr keep.orig
ls -a | grep -q partial && { echo "FAIL: a partial file was left"; exit 1; }
echo "faults: mpirun exits non-zero naming the rank; the existing output is untouched"
