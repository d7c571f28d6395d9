#!/usr/bin/env bash
# Two builds' displayed frames on a hardware GPU, alternating in one run, so that a change
# to the runtime is measured against the build before it on the same card and clock
# (a device's time is short: one run of this, not two of scripts/device_bench.sh).
#
#   A=OLD_VBIM B=NEW_VBIM scripts/device_ab.sh DIR OUT
#
# For every stream in DIR, ROUNDS rounds (2 by default; A then B in odd rounds, B then A
# in even ones) of `vbim bench render FILE --frames FRAMES --runs 1 --game-load GAME_LOAD`
# (240 frames, 8 ms: a card kept busy as a game keeps it, BENCHMARKS.md "On a hardware
# GPU"), then B alone with each of EXTRA's flag sets (default: every frame deciding which
# tiles to keep, `--reuse-probe 0`, and every tile every frame, `--reuse-share 0`), and
# a segment's decode back to back with each build (`bench decode --gpu --fit --runs 2`:
# its dispatches, their latency), once with each of DECODES's flag sets (default: the
# build's own shape, and a format 2.0 or 3.0 file's sections decoded on the GPU as coded,
# `--lanes true`, which a 1.1 file ignores). Everything goes to OUT/ab.log, the adapter's name
# first. Prepare as scripts/device_bench.sh says, with both binaries in the carried
# folder (`strip -o .dev/vbim-a …`, and xz them if the carry's 64 MiB needs it).
set -euo pipefail
dir=${1:?usage: A=OLD B=NEW scripts/device_ab.sh DIR OUT}
out=${2:?usage: A=OLD B=NEW scripts/device_ab.sh DIR OUT}
a=${A:?A: the build before}
b=${B:?B: the build to measure}
frames=${FRAMES:-240}
rounds=${ROUNDS:-2}
load=${GAME_LOAD:-8}
extra=${EXTRA:-"--reuse-probe 0;--reuse-share 0"}
decodes=${DECODES:-";--lanes true"}
mkdir -p "$out"
log="$out/ab.log"
: >"$log"
streams=("$dir"/*.vbim)
[ -e "${streams[0]}" ] || { echo "no .vbim file in $dir" >&2; exit 1; }
render() { # label, binary, file, flags…
    echo "-- $1 $3 ${*:4}" | tee -a "$log"
    "$2" bench render "$3" --frames "$frames" --runs 1 --game-load "$load" "${@:4}" 2>&1 |
        grep -E "render benchmark|render thread CPU|GPU time per displayed|reference: blend|each frame against|of which|max " |
        tee -a "$log"
}
for f in "${streams[@]}"; do
    echo "== $f" | tee -a "$log"
    for ((r = 1; r <= rounds; r++)); do
        if ((r % 2)); then order=(A B); else order=(B A); fi
        for w in "${order[@]}"; do
            bin=$a
            [ "$w" = B ] && bin=$b
            render "$w" "$bin" "$f"
        done
    done
    IFS=';' read -ra sets <<<"$extra"
    for s in "${sets[@]}"; do
        read -ra flags <<<"$s"
        render B "$b" "$f" "${flags[@]}"
    done
    IFS=';' read -ra shapes <<<"$decodes"
    for s in "${shapes[@]}"; do
        read -ra flags <<<"$s"
        for w in A B; do
            bin=$a
            [ "$w" = B ] && bin=$b
            echo "-- $w decode $f ${flags[*]}" | tee -a "$log"
            "$bin" bench decode "$f" --gpu --fit --runs 2 "${flags[@]}" 2>&1 |
                grep -E "GPU decode|GPU memory|fit over|per unit|clears and|steps" | tee -a "$log"
        done
    done
done
