#!/usr/bin/env bash
# Tolerance asked against mean PSNR delivered (docs/CONVENTIONS.md, "Error metrics").
#
#   scripts/tolerance_bench.sh [OUT]      (default OUT: out/tolerance)
#
# Bakes (once, into OUT) the four benchmark days (Jacksboro and Aletsch, clear and cloudy,
# 512², 240 frames), Jacksboro clear as 8-bit PNG and as 1-channel 8-bit PNG, a day the
# project does not ship (a synthetic fractal terrain, scripts/synthetic_dem.py, on a winter
# day at 58° N with clouds) and, unless LONG=0, the 1000-frame Jacksboro clear day (at 45 dB
# only). Each is encoded with the default preset at every tolerance in TOLERANCES in three
# modes — `aim` (the default: one pass, the budget found on a sample, with the worst-frame
# floor of T − 7 dB), `aim-mean` (the same without the floor, --worst-margin inf) and, at
# PLAIN_TOLERANCES only, `no-aim` (the budget as it is); MODES picks some of them — and
# measured with the reference decoder. Writes
# OUT/tolerance.csv and OUT/tolerance.png (the default mode and the budget as it is).
set -euo pipefail
out=${1:-out/tolerance}
vbim=${VBIM:-target/release/vbim}
tols=${TOLERANCES:-38 41 44 45 47 50}
plain_tols=${PLAIN_TOLERANCES:-38 45 50} # --no-aim only at these (it is the "before")
modes=${MODES:-aim aim-mean no-aim}      # e.g. MODES=aim to measure the default alone
[ -n "${VBIM:-}" ] || cargo build --release --features bench  # the bench commands
if ! command -v ffmpeg >/dev/null; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q && apt-get install -y -q ffmpeg
fi
mkdir -p "$out"
bake() { # $1 = name, rest = bake arguments
    local name=$1
    shift
    [ -f "$out/$name/manifest.json" ] || "$vbim" bake "$@" --out "$out/$name" >/dev/null
}
bake jacksboro-clear samples/jacksboro.toml --size 512 --frames 240 --clouds false
bake jacksboro-cloudy samples/jacksboro.toml --size 512 --frames 240 --clouds true
bake aletsch-clear samples/aletsch.toml --size 512 --frames 240 --clouds false
bake aletsch-cloudy samples/aletsch.toml --size 512 --frames 240 --clouds true
bake jacksboro-png8 samples/jacksboro.toml --size 512 --frames 240 --clouds false --format png8
if [ ! -f "$out/jacksboro-grey/frame_0239.png" ]; then
    mkdir -p "$out/jacksboro-grey"
    ffmpeg -loglevel error -y -i "$out/jacksboro-png8/frame_%04d.png" -pix_fmt gray -start_number 0 "$out/jacksboro-grey/frame_%04d.png"
fi
if [ ! -f "$out/unseen/fractal.toml" ]; then
    mkdir -p "$out/unseen"
    python3 scripts/synthetic_dem.py "$out/unseen/fractal.png"
    cp scripts/scenes/fractal-winter.toml "$out/unseen/fractal.toml"
fi
bake unseen-winter "$out/unseen/fractal.toml"
seqs="jacksboro-clear jacksboro-cloudy aletsch-clear aletsch-cloudy jacksboro-png8 jacksboro-grey unseen-winter"
if [ "${LONG:-1}" != 0 ]; then
    bake jacksboro-1000 samples/jacksboro.toml --size 512 --frames 1000 --clouds false
    seqs="$seqs jacksboro-1000"
fi
csv="$out/tolerance.csv"
echo "sequence,mode,asked,delivered,worst,bytes,seconds,max_levels,p999_levels,internal" >"$csv"
for s in $seqs; do
    ts=$tols
    [ "$s" = jacksboro-1000 ] && ts=45
    for t in $ts; do
        for mode in $modes; do
            [ "$mode" = no-aim ] && [[ " $plain_tols " != *" $t "* ]] && continue
            flags=(--tolerance "$t" --fps 24/1 --report "$out/r.json")
            case "$mode" in
            aim-mean) flags+=(--worst-margin inf) ;;
            no-aim) flags+=(--no-aim) ;;
            esac
            t0=$(date +%s.%N)
            "$vbim" encode "$out/$s" -o "$out/v.vbim" "${flags[@]}" >/dev/null 2>&1
            t1=$(date +%s.%N)
            python3 - "$out/r.json" "$s" "$mode" "$t" "$t0" "$t1" >>"$csv" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
s, mode, t, t0, t1 = sys.argv[2:]
print(f"{s},{mode},{t},{r['mean_psnr']:.3f},{r['worst_psnr']:.3f},{r['bytes']},"
      f"{float(t1) - float(t0):.2f},{r['max_abs_error'] * 255:.2f},{r['p999_levels']:.4f},"
      f"{r['internal_tolerance_db']:.3f}")
PY
            tail -1 "$csv"
        done
    done
done
grep -v ',aim-mean,' "$csv" >"$out/plotted.csv"
"$vbim" bench plot-tolerance "$out/plotted.csv" --out "$out/tolerance.png" --title "Mean PSNR delivered against the tolerance asked (default preset, 512²)"
python3 - "$csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
for mode in ("aim", "aim-mean", "no-aim"):
    sel = [r for r in rows if r["mode"] == mode]
    if not sel:
        continue
    d = [float(r["delivered"]) - float(r["asked"]) for r in sel]
    t = [float(r["seconds"]) for r in sel]
    floor = sum(1 for r in sel if float(r["worst"]) >= float(r["asked"]) - 7.0)
    print(f"{mode}: delivered − asked from {min(d):+.2f} to {max(d):+.2f} dB over {len(d)} encodes; "
          f"{sum(1 for x in d if abs(x) <= 0.5)} within ±0.5 dB; worst frame ≥ T − 7 in {floor}; "
          f"{sum(t):.0f} s in all")
PY
echo "results: $csv, $out/tolerance.png"
