#!/usr/bin/env bash
# Rate–distortion benchmark (docs/CONVENTIONS.md, "Rate–distortion comparisons").
#
#   scripts/rd_bench.sh clear|cloudy [OUT]      (default OUT: out/rd)
#
# Bakes the benchmark sequence (Jacksboro, 512², 240 frames, looping), then writes
# OUT/SEQ/rd.csv and OUT/SEQ/rd.png with bytes against mean PSNR for: lossless zstd per
# frame, keyframes + linear interpolation at several spacings, vbim at several tolerances
# (default preset and --best), and the anchors x265 (gbrp, medium) and x264 (rgb, medium)
# at CRF 4…30 on the 8-bit PNG export, all scored by `vbim compare` against the HDR frames.
# Installs Debian's ffmpeg when missing.
set -euo pipefail
seq=${1:-clear}
out=${2:-out/rd}
vbim=${VBIM:-target/release/vbim}
[ -x "$vbim" ] || cargo build --release
if ! command -v ffmpeg >/dev/null; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q && apt-get install -y -q ffmpeg
fi
case "$seq" in clear) clouds=false ;; cloudy) clouds=true ;; *) echo "usage: $0 clear|cloudy [OUT]" >&2; exit 2 ;; esac
dir="$out/$seq"
mkdir -p "$dir"
"$vbim" bake samples/jacksboro.toml --out "$dir/exr" --size 512 --frames 240 --clouds "$clouds" >/dev/null
"$vbim" bake samples/jacksboro.toml --out "$dir/png8" --size 512 --frames 240 --clouds "$clouds" --format png8 >/dev/null
csv="$dir/rd.csv"
echo "method,setting,bytes,bpp,mean_psnr,worst_psnr,encode_s" >"$csv"
tf=$((512 * 512 * 240))
bpp() { python3 -c "print(f'{$1 * 8 / $tf:.5f}')"; }
score() { # $1 = decoded sequence → "mean,worst"
    "$vbim" compare "$dir/exr" "$1" >"$dir/cmp.txt"
    local m w
    m=$(awk '/^mean PSNR/ {print $3}' "$dir/cmp.txt")
    w=$(awk '/^worst frame/ {print $3}' "$dir/cmp.txt")
    echo "$m,$w"
}
now() { date +%s.%N; }

# Lossless zstd per frame (half float): identical by definition.
b=$("$vbim" bench lossless "$dir/exr" | awk '{print $1}')
echo "lossless zstd,level 3,$b,$(bpp "$b"),99,99," >>"$csv"

# vbim: keyframes + linear interpolation at fixed spacings, then the full model.
run_vbim() { # $1 = method, $2 = setting, rest = encoder flags
    local method=$1 setting=$2
    shift 2
    local t0 t1
    t0=$(now)
    "$vbim" encode "$dir/exr" -o "$dir/v.vbim" --fps 24/1 --no-verify "$@" >/dev/null
    t1=$(now)
    local bytes
    bytes=$(stat -c %s "$dir/v.vbim")
    echo "$method,$setting,$bytes,$(bpp "$bytes"),$(score "$dir/v.vbim"),$(python3 -c "print(f'{$t1 - $t0:.2f}')")" >>"$csv"
    tail -1 "$csv"
}
for n in 2 4 8; do run_vbim "keyframes + linear" "every $n" --max-degree 1 --segment "$n"; done
for t in 36 39 40.5 42 45; do run_vbim "vbim default" "tol $t" --tolerance "$t"; done
for t in 39 40.5 42; do run_vbim "vbim --best" "tol $t" --best --tolerance "$t"; done

# The anchors on the 8-bit export.
for codec in x265 x264; do
    for crf in 4 8 12 16 20 24 30; do
        if [ "$codec" = x265 ]; then
            args=(-c:v libx265 -pix_fmt gbrp -preset medium -crf "$crf" -x265-params log-level=error)
        else
            args=(-c:v libx264rgb -preset medium -crf "$crf")
        fi
        t0=$(now)
        ffmpeg -loglevel error -y -framerate 24 -i "$dir/png8/frame_%04d.png" "${args[@]}" "$dir/a.mkv"
        t1=$(now)
        bytes=$(stat -c %s "$dir/a.mkv")
        rm -rf "$dir/dec" && mkdir -p "$dir/dec"
        ffmpeg -loglevel error -y -i "$dir/a.mkv" -pix_fmt rgb24 -start_number 0 "$dir/dec/frame_%04d.png"
        echo "$codec medium,crf $crf,$bytes,$(bpp "$bytes"),$(score "$dir/dec"),$(python3 -c "print(f'{$t1 - $t0:.2f}')")" >>"$csv"
        tail -1 "$csv"
    done
done
"$vbim" bench plot-rd "$csv" --out "$dir/rd.png" --title "Rate against distortion: Jacksboro $seq, 512², 240 frames"
echo "results: $csv, $dir/rd.png"
