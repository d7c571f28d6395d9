#!/usr/bin/env bash
# Runs the fuzz targets of fuzz/ (cargo fuzz, stable Rust, no sanitizer) for SECONDS each
# (default 60): `container` (header, index, metadata, chunk checksums), `chunks` (every
# chunk payload parser), `decode` (the whole reference decode within small limits) and
# `player_decoder` (the player's decoder thread: scanning the streams for the GPU; it
# starts from decode's seeds), `plane2` (format 2's coefficient sections: what decodes must
# code again to the same blocks), `package` (a package file's JSON: what parses names only
# paths inside its folder and writes itself out the same).
# Checksums are made right before parsing (vbim_format::fuzz::with_checksums), so the
# fuzzer reaches the semantic checks. A crash's input is copied into
# fuzz/regressions/TARGET/, which `cargo test --workspace --all-features` replays; the script then fails. The last
# line per target gives executions per second and coverage (libFuzzer's cov / ft).
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-60}"
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked --version 0.13.2
cd fuzz
cargo fuzz build --sanitizer none -O -a
failed=0
for t in container chunks decode player_decoder plane2 package; do
    mkdir -p "corpus/$t" "regressions/$t"
    log="corpus/$t.log"
    seeds="seeds/$t"
    [ "$t" = player_decoder ] && seeds="seeds/decode regressions/decode"
    # shellcheck disable=SC2086 # $seeds is one or two directories
    if cargo fuzz run --sanitizer none -O -a "$t" "corpus/$t" $seeds "regressions/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=1024 -max_len=8192 -timeout=10 \
        -print_final_stats=1 >"$log" 2>&1; then
        echo "$t: $(grep -E 'DONE' "$log" | tail -1)"
    else
        failed=1
        echo "$t: FAILED — the input is kept in fuzz/regressions/$t/:"
        grep -E 'panicked|ERROR|SUMMARY|Test unit written' "$log" | head -5 || true
        for a in artifacts/"$t"/*; do
            [ -e "$a" ] && cp "$a" "regressions/$t/" && echo "  $(basename "$a")"
        done
    fi
done
exit "$failed"
