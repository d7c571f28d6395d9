#!/usr/bin/env bash
# Rate–distortion benchmark (docs/CONVENTIONS.md, "Rate–distortion comparisons").
#
#   scripts/rd_bench.sh clear|cloudy [OUT]      (default OUT: out/rd)
#
# Bakes a benchmark day (SAMPLE=jacksboro or aletsch, 512², FRAMES=240 frames, looping),
# then writes OUT/SAMPLE-SEQ/rd.csv, rd.png and summary.md with bytes against mean PSNR for:
# lossless zstd per frame, keyframes + linear interpolation at several spacings, vbim at
# several tolerances (default preset and --best; one pass each, `--tolerance` being the
# mean PSNR asked for), and the anchors (ANCHORS, default all
# three) x265 (gbrp, medium) and x264 (rgb, medium) at CRF 4…30 and libaom AV1 (gbrp,
# cpu-used 6) at CRF 14…44 on the 8-bit PNG export, all scored by `vbim compare` against
# the HDR frames: mean and worst-frame PSNR, the largest error and the 99.9th percentile
# in 8-bit levels. summary.md puts each vbim point beside the anchors at the same mean
# PSNR (scripts/rd_summary.py). VBIM_FLAGS adds flags to every vbim encode (e.g.
# `--format-version 2`). Installs Debian's ffmpeg when missing.
set -euo pipefail
seq=${1:-clear}
out=${2:-out/rd}
sample=${SAMPLE:-jacksboro}
frames=${FRAMES:-240}
anchors=${ANCHORS-x265 x264 av1}
vbim=${VBIM:-target/release/vbim}
read -r -a vbim_flags <<<"${VBIM_FLAGS:-}"
[ -n "${VBIM:-}" ] || cargo build --release --features bench  # the bench commands
if ! command -v ffmpeg >/dev/null; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q && apt-get install -y -q ffmpeg
fi
case "$seq" in clear) clouds=false ;; cloudy) clouds=true ;; *) echo "usage: $0 clear|cloudy [OUT]" >&2; exit 2 ;; esac
dir="$out/$sample-$seq"
mkdir -p "$dir"
"$vbim" bake "samples/$sample.toml" --out "$dir/exr" --size 512 --frames "$frames" --clouds "$clouds" >/dev/null
"$vbim" bake "samples/$sample.toml" --out "$dir/png8" --size 512 --frames "$frames" --clouds "$clouds" --format png8 >/dev/null
csv="$dir/rd.csv"
echo "method,setting,bytes,bpp,mean_psnr,worst_psnr,encode_s,max_levels,p999_levels" >"$csv"
tf=$((512 * 512 * frames))
bpp() { python3 -c "print(f'{$1 * 8 / $tf:.5f}')"; }
score() { # $1 = decoded sequence → "mean,worst"; the error's tail → $dir/tail.txt
    "$vbim" compare "$dir/exr" "$1" >"$dir/cmp.txt"
    local m w
    m=$(awk '/^mean PSNR/ {print $3}' "$dir/cmp.txt")
    w=$(awk '/^worst frame/ {print $3}' "$dir/cmp.txt")
    awk '/^max error/ {for (i = 2; i <= NF; i++) if ($i == "levels") mx = $(i - 1)} /^p99.9 error/ {p = $3} END {print mx "," p}' "$dir/cmp.txt" >"$dir/tail.txt"
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
    "$vbim" encode "$dir/exr" -o "$dir/v.vbim" --fps 24/1 --no-verify "$@" "${vbim_flags[@]}" >/dev/null
    t1=$(now)
    local bytes
    bytes=$(stat -c %s "$dir/v.vbim")
    local sc
    sc=$(score "$dir/v.vbim")
    echo "$method,$setting,$bytes,$(bpp "$bytes"),$sc,$(python3 -c "print(f'{$t1 - $t0:.2f}')"),$(cat "$dir/tail.txt")" >>"$csv"
    tail -1 "$csv"
}
# Keyframes at the default budget as it is (--no-aim): the baseline before the aim.
for n in 2 4 8; do run_vbim "keyframes + linear" "every $n" --max-degree 1 --segment "$n" --no-aim; done
# --tolerance is the mean PSNR delivered (in one pass, with the worst-frame floor).
for t in 40 42 44 45 46 48; do run_vbim "vbim default" "tol $t" --tolerance "$t"; done
for t in 44 45 46; do run_vbim "vbim --best" "tol $t" --best --tolerance "$t"; done

# The anchors on the 8-bit export.
for codec in $anchors; do
    case "$codec" in
    av1) crfs="14 20 26 32 38 44" name="av1 (libaom)" ;;
    x265 | x264) crfs="4 8 12 16 20 24 30" name="$codec medium" ;;
    *) echo "unknown anchor $codec (x265, x264, av1)" >&2; exit 2 ;;
    esac
    for crf in $crfs; do
        case "$codec" in
        x265) args=(-c:v libx265 -pix_fmt gbrp -preset medium -crf "$crf" -x265-params log-level=error) ;;
        x264) args=(-c:v libx264rgb -preset medium -crf "$crf") ;;
        av1) args=(-c:v libaom-av1 -pix_fmt gbrp -crf "$crf" -b:v 0 -cpu-used 6 -row-mt 1) ;;
        esac
        t0=$(now)
        ffmpeg -loglevel error -y -framerate 24 -i "$dir/png8/frame_%04d.png" "${args[@]}" "$dir/a.mkv"
        t1=$(now)
        bytes=$(stat -c %s "$dir/a.mkv")
        rm -rf "$dir/dec" && mkdir -p "$dir/dec"
        ffmpeg -loglevel error -y -i "$dir/a.mkv" -pix_fmt rgb24 -start_number 0 "$dir/dec/frame_%04d.png"
        sc=$(score "$dir/dec")
        echo "$name,crf $crf,$bytes,$(bpp "$bytes"),$sc,$(python3 -c "print(f'{$t1 - $t0:.2f}')"),$(cat "$dir/tail.txt")" >>"$csv"
        tail -1 "$csv"
    done
done
"$vbim" bench plot-rd "$csv" --out "$dir/rd.png" --title "Rate against distortion: $sample $seq, 512², $frames frames"
python3 scripts/rd_summary.py "$csv" >"$dir/summary.md"
cat "$dir/summary.md"
echo "results: $csv, $dir/rd.png, $dir/summary.md"
