#!/usr/bin/env bash
# The runtime's GPU figures on a hardware GPU, in one short run: for every stream in DIR,
# the GPU time of a displayed frame against a reference blend (`vbim bench render`, a
# 60 Hz display, with a game's own GPU work of GAME_LOAD ms (8 by default) before each
# frame, as a game keeps its card's clock up, and without it), where it goes, pass by pass (`--passes`, one run: its frames include the
# timestamps' own cost) and a segment's GPU decode by pass (`vbim bench decode --gpu
# --fit`, with the card's latency per dispatch and cost per unit of each pass; for a
# format 2.0 or 3.0 file also with its sections decoded on the GPU as coded, `--lanes true`,
# and so with the lanes' job in a storage buffer);
# then the speed–accuracy trade on the first stream (scripts/reuse_bench.sh). Everything goes to
# OUT/device.log (the adapter's name first), OUT/reuse.csv and each stream's frames
# (the last run of `bench render --csv`) in OUT/render-NAME.csv.
#
#   VBIM=BINARY scripts/device_bench.sh DIR OUT
#
# Made for a machine that only runs a prepared binary. Here, once:
#   cargo build --release --features bench
#   mkdir -p .dev && echo /.dev/ >> .git/info/exclude && strip -o .dev/vbim target/release/vbim
#   cp out/demo/jacksboro.vbim .dev/a512.vbim       # and, say, `vbim bench scale --sizes 2048`'s
#   cp DIR/2048.vbim .dev/b2048.vbim                # stream (the first in name order is the
#                                                   # one the reuse trade is measured on)
# plus the Vulkan loader's packages in .gl/ as the device tool's notes say. There, carrying
# .dev and .gl: `for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig;
# VBIM=.dev/vbim scripts/device_bench.sh .dev $OUT`. FRAMES, RUNS and REUSE=0 shorten it.
set -euo pipefail
dir=${1:?usage: scripts/device_bench.sh DIR OUT}
out=${2:?usage: scripts/device_bench.sh DIR OUT}
vbim=${VBIM:-target/release/vbim}
frames=${FRAMES:-240}
runs=${RUNS:-3}
load=${GAME_LOAD:-8}
mkdir -p "$out"
log="$out/device.log"
: >"$log"
streams=("$dir"/*.vbim)
[ -e "${streams[0]}" ] || { echo "no .vbim file in $dir" >&2; exit 1; }
for f in "${streams[@]}"; do
    echo "== $f" | tee -a "$log"
    "$vbim" inspect "$f" 2>&1 | sed -n 1,4p | tee -a "$log"
    # The frame as a game pays it (the card busy with the game's own work for about
    # GAME_LOAD ms of each display period, then idle between frames as a bare benchmark
    # leaves it), then where its time goes (the timestamps between passes add their own
    # cost to that run's frames).
    "$vbim" bench render "$f" --frames "$frames" --runs "$runs" --game-load "$load" 2>&1 | tee -a "$log"
    "$vbim" bench render "$f" --frames "$frames" --runs "$runs" 2>&1 | tee -a "$log"
    # Every tile every frame (at the files' 24 fps the tile state keeps none, and costs
    # a 4096² frame about 7% under the load).
    "$vbim" bench render "$f" --frames "$frames" --runs 1 --reuse-share 0 --game-load "$load" \
        2>&1 | tee -a "$log"
    "$vbim" bench render "$f" --frames "$frames" --runs 1 --passes --game-load "$load" \
        --csv "$out/render-$(basename "$f" .vbim).csv" 2>&1 | tee -a "$log"
    "$vbim" bench decode "$f" --gpu --fit --runs "$runs" 2>&1 | tee -a "$log"
    # (sed reads all of it: no broken pipe for `pipefail` to report.)
    if [[ "$("$vbim" inspect "$f" | sed -n 1p)" == *".vbim "[23]"."* ]]; then
        "$vbim" bench decode "$f" --gpu --fit --runs "$runs" --lanes true 2>&1 | tee -a "$log"
        # The lanes' job in a storage buffer, as a CPU adapter reads it: whether a GPU
        # minds (DecodeShape::lane_job_storage).
        "$vbim" bench decode "$f" --gpu --runs "$runs" --lanes true --lane-job-storage true \
            2>&1 | tee -a "$log"
    fi
done
if [ "${REUSE:-1}" != 0 ]; then
    CLOCK=timestamps GAME_LOAD="$load" VBIM="$vbim" scripts/reuse_bench.sh "${streams[0]}" "$out/reuse.csv" 2>&1 | tee -a "$log"
fi
