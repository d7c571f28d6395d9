#!/usr/bin/env python3
"""Each vbim point of an rd.csv (scripts/rd_bench.sh) beside the anchors at the same mean PSNR.

    scripts/rd_summary.py OUT/SAMPLE-SEQ/rd.csv

The protocol's comparison: an anchor's bytes at a given mean PSNR come from linear
interpolation of log(bytes) between its two CRF points nearest that PSNR (bracketing it;
no extrapolation), and its largest and 99.9th-percentile errors (8-bit levels) from linear
interpolation between the same two points. Prints a Markdown table.
"""
import csv
import math
import sys


def bracket(points, psnr):
    """The two points (sorted by PSNR) around psnr, or None outside their range."""
    pts = sorted(points, key=lambda p: p["psnr"])
    for a, b in zip(pts, pts[1:]):
        if a["psnr"] <= psnr <= b["psnr"] and b["psnr"] > a["psnr"]:
            return a, b, (psnr - a["psnr"]) / (b["psnr"] - a["psnr"])
    return None


def at(points, psnr):
    br = bracket(points, psnr)
    if br is None:
        return None
    a, b, t = br
    lerp = lambda x, y: x + t * (y - x)
    out = {"bytes": math.exp(lerp(math.log(a["bytes"]), math.log(b["bytes"])))}
    for k in ("max", "p999"):
        out[k] = lerp(a[k], b[k]) if a[k] is not None and b[k] is not None else None
    return out


def num(s):
    try:
        return float(s)
    except (TypeError, ValueError):
        return None


def main():
    rows = []
    with open(sys.argv[1]) as f:
        for r in csv.DictReader(f):
            rows.append(
                {
                    "method": r["method"],
                    "setting": r["setting"],
                    "bytes": float(r["bytes"]),
                    "psnr": float(r["mean_psnr"]),
                    "worst": num(r.get("worst_psnr")),
                    "secs": num(r.get("encode_s")),
                    "max": num(r.get("max_levels")),
                    "p999": num(r.get("p999_levels")),
                }
            )
    anchors = {}
    for r in rows:
        if not r["method"].startswith(("vbim", "keyframes", "lossless")):
            anchors.setdefault(r["method"], []).append(r)
    names = sorted(anchors)
    head = "| vbim | mean PSNR | worst frame | bytes | max / p99.9 (levels) |"
    rule = "|---|---:|---:|---:|---:|"
    for n in names:
        head += f" {n}: bytes ratio | {n}: max / p99.9 |"
        rule += "---:|---:|"
    print(head)
    print(rule)
    fmt = lambda v, d: "–" if v is None else f"{v:.{d}f}"
    for r in rows:
        if not r["method"].startswith("vbim"):
            continue
        line = (
            f"| {r['method']}, {r['setting']} | {r['psnr']:.2f} | {fmt(r['worst'], 2)} "
            f"| {int(r['bytes'])} | {fmt(r['max'], 1)} / {fmt(r['p999'], 2)} |"
        )
        for n in names:
            a = at(anchors[n], r["psnr"])
            if a is None:
                line += " outside its CRF range | |"
            else:
                line += f" {r['bytes'] / a['bytes']:.2f}× | {fmt(a['max'], 1)} / {fmt(a['p999'], 2)} |"
        print(line)
    # Encode time of each anchor's CRF nearest 45 dB, beside vbim's default nearest 45 dB.
    def nearest(points):
        return min(points, key=lambda p: abs(p["psnr"] - 45.0)) if points else None

    v = nearest([r for r in rows if r["method"] == "vbim default"])
    if v and v["secs"]:
        print()
        print(f"Encode time nearest 45 dB: vbim default {v['secs']:.1f} s ({v['setting']})", end="")
        for n in names:
            a = nearest(anchors[n])
            if a and a["secs"]:
                print(f"; {n} {a['secs']:.1f} s ({a['setting']})", end="")
        print()


if __name__ == "__main__":
    main()
