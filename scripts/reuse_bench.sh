#!/usr/bin/env bash
# The runtime's speed–accuracy trade: for each `--reuse-share` (how far a tile of the
# lightmap may lag the exact image, as a share of the protocol's GPU bound), the GPU time
# of a displayed frame against a reference blend of two Rgba16Float frames measured in the
# same run (`vbim bench render`, wall clock from submission to completion), and the shown
# error against the reference decoder at the time asked for (`vbim play --headless`,
# every 4th frame, the protocol's metric). At two paces: the file's own 24 fps on a 60 Hz
# display, and 144× slower (a 240-frame day at 1/6 fps, a 24-minute day), from frame 120.
#
#   scripts/reuse_bench.sh [FILE] [OUT.csv]   (defaults: out/demo/jacksboro.vbim, out/reuse.csv)
#   CLOCK=timestamps scripts/reuse_bench.sh ...   (a hardware GPU: its timestamps, not the wall clock)
#   GAME_LOAD=8 ...   (a game's 8 ms of GPU work before each frame, `bench render --game-load`:
#                      a hardware GPU then keeps the clock a game keeps it at)
#   target/release/vbim bench plot-reuse OUT.csv -o docs/images/reuse.png --title "..."
set -euo pipefail
file=${1:-out/demo/jacksboro.vbim}
csv=${2:-out/reuse.csv}
vbim=${VBIM:-target/release/vbim}
[ -n "${VBIM:-}" ] || cargo build --release --features bench  # the bench commands
mkdir -p "$(dirname "$csv")"
echo "pace,share,gpu_ms,gpu_p99_ms,blend_ms,mean_ratio,p99_ratio,psnr_db,worst_db" > "$csv"
for slow in 1 144; do
    if [ "$slow" = 1 ]; then start=0 dur=4s; else start=120 dur=2s; fi
    for share in 0 0.25 1 4 16; do
        r=$("$vbim" bench render "$file" --frames 120 --runs 1 --reuse-share "$share" \
            --slow "$slow" --start "$start" --game-load "${GAME_LOAD:-0}")
        # GPU timestamps where the adapter has them inside a frame (a hardware GPU); the
        # wall clock from submission to completion on lavapipe, whose timestamps do not
        # bracket its work.
        if [ "${CLOCK:-wall}" = timestamps ]; then
            frame=$(grep "GPU time per displayed frame (timestamps)" <<<"$r")
            blend=$(grep "reference: blend two Rgba16Float frames (timestamps)" <<<"$r")
            ratio=$(grep "  timestamps:" <<<"$r")
        else
            frame=$(grep "the player's frame (wall)" <<<"$r")
            blend=$(grep "the reference blend (wall)" <<<"$r")
            ratio=$(grep "  wall clock:" <<<"$r")
        fi
        p=$("$vbim" play "$file" --headless --slow "$slow" --start "$start" --duration "$dur" \
            --check-every 4 --reuse-share "$share" | grep '^shown')
        num() { sed -E "s/.*$1 ([0-9.]+).*/\1/" <<<"$2"; }
        echo "$slow,$share,$(num mean "$frame"),$(num p99 "$frame"),$(num mean "$blend"),$(sed -E 's/.*(wall clock|timestamps): mean ([0-9.]+)×.*/\2/' <<<"$ratio"),$(num p99 "$ratio"),$(sed -E 's/.*shown +([0-9.]+) dB.*/\1/' <<<"$p"),$(sed -E 's/.*frame ([0-9.]+) dB.*/\1/' <<<"$p")" | tee -a "$csv"
    done
done
