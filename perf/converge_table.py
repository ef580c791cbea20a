#!/usr/bin/env python3
"""The converge table of README and docs/denoise.md from `make converge`.

Reads DIR/*/converge.json (written by `rtlab converge`) and prints one
Markdown row per run: effect (stack), resolution, raw and denoised 1-spp
time and relMSE, how much lower the error is, and the equal-error speed-ups
against accumulated 1-spp frames and against N spp in one frame (`*` where
the raw curve had to be extrapolated). Usage: converge_table.py [DIR]
(default out/converge).
"""
import json
import pathlib
import sys


def row(j):
    s = j["summary"]
    rows = j["rows"]
    settings = j["settings"]
    raw = next(r for r in rows if r["method"] == "raw" and r["kind"] == "spp" and r["spp"] == 1)
    den = next(r for r in rows if r["method"] == s["stack"] and r["kind"] == "spp" and r["spp"] == 1)
    star = lambda extrapolated: "*" if extrapolated else ""
    return (f"| {j['effect']} ({s['stack']}) | {settings['width']}×{settings['height']} "
            f"| {raw['ms']:.0f}, {raw['relMse']:.3g} | {den['ms']:.0f}, {den['relMse']:.3g} "
            f"| {s['relMseReduction']:.1f}× | {s['equalErrorSpeedupFrames']:.1f}×{star(s['extrapolatedFrames'])} "
            f"| {s['equalErrorSpeedup']:.1f}×{star(s['extrapolated'])} |")


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "out/converge")
    files = sorted(root.glob("*/converge.json"))
    if not files:
        print(f"converge_table.py: no */converge.json under {root}", file=sys.stderr)
        return 2
    runs = [json.loads(f.read_text()) for f in files]
    order = {"shadows": 0, "reflections": 1, "ao": 2, "gi": 3}
    runs.sort(key=lambda j: (order.get(j["effect"], 9), -j["settings"]["width"]))
    print("| effect (stack) | size | raw 1 spp: ms, relMSE | denoised 1 spp: ms, relMSE | lower by "
          "| speed-up vs 1-spp frames | vs N spp in one frame |")
    print("|---|---|---|---|---|---|---|")
    for j in runs:
        print(row(j))
    return 0


if __name__ == "__main__":
    sys.exit(main())
