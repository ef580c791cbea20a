#!/usr/bin/env python3
"""The converge table of README and docs/denoise.md from `make converge`.

Reads DIR/*/converge.json (written by `rtlab converge`) and prints one
Markdown row per run: effect (stack), resolution, raw and denoised 1-spp
time and relMSE, how much lower the error is, and the equal-error speed-ups
against accumulated 1-spp frames and against N spp in one frame (`*` where
the raw curve had to be extrapolated). With --full (docs/denoise.md's
table) the 1-spp cells also carry SSIM and FLIP, and two columns follow:
the best speed-up against N spp over the denoised 1, 2, 4 ... spp rows, and
the share of the denoised 1-spp error held by the worst 1 % of the pixels.
Usage: converge_table.py [--full] [DIR] (default out/converge).
"""
import json
import pathlib
import sys


def row(j, full):
    s = j["summary"]
    rows = j["rows"]
    settings = j["settings"]
    raw = next(r for r in rows if r["method"] == "raw" and r["kind"] == "spp" and r["spp"] == 1)
    den = next(r for r in rows if r["method"] == s["stack"] and r["kind"] == "spp" and r["spp"] == 1)
    star = lambda extrapolated: "*" if extrapolated else ""
    quality = lambda r: f", {r['ssim']:.3f}, {r['flip']:.3f}" if full else ""
    cells = (f"| {j['effect']} ({s['stack']}) | {settings['width']}×{settings['height']} "
             f"| {raw['ms']:.0f}, {raw['relMse']:.3g}{quality(raw)} | {den['ms']:.0f}, {den['relMse']:.3g}{quality(den)} "
             f"| {s['relMseReduction']:.1f}× | {s['equalErrorSpeedupFrames']:.1f}×{star(s['extrapolatedFrames'])} "
             f"| {s['equalErrorSpeedup']:.1f}×{star(s['extrapolated'])} |")
    if full:
        best = max((r for r in rows if r["method"] == s["stack"] and r["kind"] == "spp"), key=lambda r: r["speedup"])
        cells += (f" {best['speedup']:.1f}×{star(best['extrapolated'])} ({best['spp']} spp) "
                  f"| {s['denoisedWorstPercentShare1spp']:.2f} |")
    return cells


def main():
    args = sys.argv[1:]
    full = "--full" in args
    args = [a for a in args if a != "--full"]
    root = pathlib.Path(args[0] if args else "out/converge")
    files = sorted(root.glob("*/converge.json"))
    if not files:
        print(f"converge_table.py: no */converge.json under {root}", file=sys.stderr)
        return 2
    runs = [json.loads(f.read_text()) for f in files]
    order = {"shadows": 0, "reflections": 1, "ao": 2, "gi": 3}
    runs.sort(key=lambda j: (order.get(j["effect"], 9), -j["settings"]["width"]))
    if full:
        print("| effect (stack) | size | raw 1 spp: ms, relMSE, SSIM, FLIP | denoised 1 spp: ms, relMSE, SSIM, FLIP "
              "| relMSE ratio | speed-up vs 1-spp frames | vs N spp in one frame | best of 1, 2, 4 denoised spp "
              "| worst 1 % |")
        print("|---|---|---|---|---|---|---|---|---|")
    else:
        print("| effect (stack) | size | raw 1 spp: ms, relMSE | denoised 1 spp: ms, relMSE | lower by "
              "| speed-up vs 1-spp frames | vs N spp in one frame |")
        print("|---|---|---|---|---|---|---|")
    for j in runs:
        print(row(j, full))
    return 0


if __name__ == "__main__":
    sys.exit(main())
