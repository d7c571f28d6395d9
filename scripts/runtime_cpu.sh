#!/usr/bin/env bash
# The player's reader and decoder threads while playing: their CPU time as a share of one
# core, on the four benchmark days (docs/CONVENTIONS.md: Jacksboro and Aletsch, clear and
# cloudy, 512², 240 frames at 24/1 fps, default preset).
#
#   scripts/runtime_cpu.sh [OUT] [RUNS]      (defaults: out/runtime_cpu, 3)
#
# Bakes and encodes each day once (kept in OUT), then plays each RUNS times for 10 s in
# real time (`vbim play --headless --realtime`, threads as a game runs them) and prints
# every run and the median of the sum. The decoder's share follows the bytes it decodes, so
# each row names its file's size: streams from another encoder build are another measurement.
set -euo pipefail
out=${1:-out/runtime_cpu}
runs=${2:-3}
vbim=${VBIM:-target/release/vbim}
[ -n "${VBIM:-}" ] || cargo build --release --features bench  # the bench commands
echo "| day | file | reader | decoder | reader + decoder (median of $runs) |"
echo "|---|---:|---:|---:|---:|"
for sample in jacksboro aletsch; do
    for sky in clear cloudy; do
        dir="$out/$sample-$sky"
        file="$dir/day.vbim"
        if [ ! -f "$file" ]; then
            mkdir -p "$dir"
            clouds=false
            [ "$sky" = cloudy ] && clouds=true
            "$vbim" bake "samples/$sample.toml" --out "$dir/exr" --size 512 --frames 240 \
                --clouds "$clouds" >/dev/null
            # (stderr: notes about files beside the frames, such as the contact sheet)
            "$vbim" encode "$dir/exr" -o "$file" --fps 24/1 >/dev/null 2>&1
            rm -rf "$dir/exr"
        fi
        reads=() decodes=() sums=()
        for _ in $(seq "$runs"); do
            line=$("$vbim" play "$file" --headless --duration 10s --realtime | grep '^advance')
            r=$(sed -E 's/.*reader ([0-9.]+)%.*/\1/' <<<"$line")
            d=$(sed -E 's/.*decoder ([0-9.]+)%.*/\1/' <<<"$line")
            reads+=("$r") decodes+=("$d") sums+=("$(python3 -c "print(f'{$r + $d:.2f}')")")
        done
        median=$(printf '%s\n' "${sums[@]}" | sort -n | awk '{a[NR]=$1} END {print a[int((NR + 1) / 2)]}')
        echo "| $sample $sky | $(stat -c %s "$file") bytes | ${reads[*]}% | ${decodes[*]}% | **$median%** (${sums[*]}) |"
    done
done
