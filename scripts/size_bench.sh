#!/usr/bin/env bash
# Bake and encode at the sizes games use: for each size, with and without fractal detail,
# the bake's and the encoder's wall time and peak resident memory, the file's bytes and
# bits per texel, and its mean and worst-frame PSNR (BENCHMARKS.md, "Bake and encode at
# size").
#
#   VBIM=target/release/vbim scripts/size_bench.sh OUT
#
# Environment: SIZES (default "512 1024 2048 4096"), FRAMES (48), DETAIL ("false true"),
# SCENE (samples/jacksboro.toml), KEEP=1 keeps the baked frames (they take 0.1 GB a
# frame at 4096²). Writes OUT/size.csv; one size at a time, so the peaks are each one's.
set -euo pipefail
OUT=${1:?usage: scripts/size_bench.sh OUT}
VBIM=${VBIM:-target/release/vbim}
SIZES=${SIZES:-"512 1024 2048 4096"}
FRAMES=${FRAMES:-48}
DETAIL=${DETAIL:-"false true"}
SCENE=${SCENE:-samples/jacksboro.toml}
mkdir -p "$OUT"
csv="$OUT/size.csv"
[ -f "$csv" ] || echo "size,detail,frames,bake_s,bake_peak_mb,encode_s,encode_peak_mb,band_tiles,bytes,bpp,mean_psnr,worst_psnr,texel_frames_per_s_wall" > "$csv"
for s in $SIZES; do
  for d in $DETAIL; do
    dir="$OUT/$s-detail-$d"
    echo "== $s² detail=$d: bake" >&2
    /usr/bin/time -f "%e %M" -o "$OUT/time.bake" \
      "$VBIM" bake "$SCENE" --size "$s" --frames "$FRAMES" --detail "$d" --no-cache -o "$dir" > /dev/null 2>&1
    read -r bake_s bake_kb < "$OUT/time.bake"
    echo "== $s² detail=$d: encode" >&2
    /usr/bin/time -f "%e %M" -o "$OUT/time.encode" \
      "$VBIM" encode "$dir" -o "$dir.vbim" --no-verify --report "$dir.json" > "$dir.encode.txt" 2> /dev/null
    read -r enc_s enc_kb < "$OUT/time.encode"
    echo "== $s² detail=$d: compare" >&2
    "$VBIM" compare "$dir" "$dir.vbim" --memory-limit 32GB > "$dir.compare.txt" 2> /dev/null
    mean=$(awk '/^mean PSNR/ {print $3}' "$dir.compare.txt")
    worst=$(awk '/^worst frame/ {print $3}' "$dir.compare.txt")
    python3 - "$dir.json" "$s" "$d" "$FRAMES" "$bake_s" "$bake_kb" "$enc_s" "$enc_kb" "$mean" "$worst" >> "$csv" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
s, d, n, bs, bkb, es, ekb, mean, worst = sys.argv[2:]
band = r.get("band_tiles")
print(",".join(str(x) for x in [
    s, d, n, bs, round(int(bkb) / 1024, 1), es, round(int(ekb) / 1024, 1),
    band if band is not None else "whole", r["bytes"], round(r["bpp"], 5), mean, worst,
    round(int(s) * int(s) * int(n) / float(es)),
]))
EOF
    tail -1 "$csv" >&2
    [ "${KEEP:-0}" = 1 ] || rm -rf "$dir"
  done
done
