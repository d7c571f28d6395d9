#!/usr/bin/env bash
# Behaviour-unchanged check between two builds of `vbim` (a refactor, a dependency move):
# the Jacksboro clear and cloudy benchmark days (512², 240 frames) encoded at --fast, the
# default preset and --best must give byte-identical files, their decoded frames identical
# EXR files, and playback in simulated time identical per-frame records (timing columns
# aside).
#
#   scripts/compare_builds.sh OLD_VBIM NEW_VBIM [WORK_DIR]      (default WORK_DIR: out/compare)
#
# Prints one line per check and exits 1 if any differs. About 3 minutes on 2 cores.
set -euo pipefail
OLD=$(realpath "$1")
NEW=$(realpath "$2")
W=${3:-out/compare}
cd "$(dirname "$0")/.."
mkdir -p "$W"
status=0
same() { # label, command that succeeds when identical
    if "${@:2}"; then echo "$1: identical"; else echo "$1: DIFFERENT"; status=1; fi
}
for day in clear cloudy; do
    clouds=false; [ "$day" = cloudy ] && clouds=true
    [ -d "$W/$day" ] || "$OLD" bake samples/jacksboro.toml --out "$W/$day" --size 512 \
        --frames 240 --clouds "$clouds" >/dev/null
    for preset in fast default best; do
        flag=(); [ "$preset" = default ] || flag=(--"$preset")
        for b in old new; do
            bin=$OLD; [ $b = new ] && bin=$NEW
            "$bin" encode "$W/$day" -o "$W/$b-$day-$preset.vbim" "${flag[@]}" --no-verify \
                >/dev/null 2>&1
            rm -rf "$W/decoded-$b"
            "$bin" decode "$W/$b-$day-$preset.vbim" -o "$W/decoded-$b" --format exr >/dev/null
        done
        same "$day $preset: file ($(stat -c %s "$W/new-$day-$preset.vbim") bytes)" \
            cmp -s "$W/old-$day-$preset.vbim" "$W/new-$day-$preset.vbim"
        same "$day $preset: decoded frames" diff -rq "$W/decoded-old" "$W/decoded-new"
    done
    for b in old new; do
        bin=$OLD; [ $b = new ] && bin=$NEW
        "$bin" play "$W/old-$day-default.vbim" --headless --duration 40s --bandwidth 1.2x \
            --stall 500ms@10s --stats "$W/play-$b.csv" >/dev/null 2>&1
        # The columns of measured time (read_ns, decode_ns, render_ns: every `*_ns` but
        # the simulated clock_ns) are never the same; found by name, not by position.
        awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) drop[i] = ($i ~ /_ns$/ && $i != "clock_ns") }
                 { out = ""; for (i = 1; i <= NF; i++) if (!drop[i]) out = out $i ","; print out }' \
            "$W/play-$b.csv" >"$W/play-$b.records"
    done
    same "$day play records" cmp -s "$W/play-old.records" "$W/play-new.records"
done
exit $status
