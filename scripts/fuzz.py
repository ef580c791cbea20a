#!/usr/bin/env python3
"""make fuzz: every libFuzzer target of fuzz/ for FUZZ_SECONDS each, in parallel.

Seed corpora (out/fuzz/seeds/FORMAT) are put together first from
  - fuzz/seeds/FORMAT/        small files written by hand for this (committed);
  - Debian's assimp-testmodels (glTF made self-contained: buffers and images
    inlined as data: URIs, and packed as .glb; OBJ/MTL, PLY, FBX as they are);
  - files rtlab writes: builtin scenes exported as OBJ/MTL and PLY, short ray
    recordings on both back ends, a rendered EXR; the .vdb files embedded in
    tests/ecs/test_volume_and_scene_json.cpp; the study files of docs/studies
    and the RT-core presets.
Each target then runs with its dictionary (fuzz/dict/FORMAT.dict), its corpus
kept in out/fuzz/corpus/FORMAT (it grows from run to run), a 10 s time limit
per input and 2 GiB of memory; what it finds goes to out/fuzz/findings/FORMAT/.
Prints per target: executions, execs/s, coverage (edges), corpus size and
findings; exits 1 when any target found something.

usage: scripts/fuzz.py --fuzz-build build/fuzz --rtlab build/release/apps/rtlab
                       [--seconds 60] [--jobs N] [--targets all|a,b] [--out out/fuzz] [--seeds-only]
"""
import argparse, base64, concurrent.futures, glob, json, os, re, shutil, struct, subprocess, sys, tempfile, time

FORMATS = ["gltf", "glb", "scene_json", "vdb", "obj", "mtl", "ply", "fbx", "ray_trace", "study", "rtcore_config", "exr"]
DICTIONARY = {"glb": "gltf"}  # targets sharing another's dictionary
MODELS = "/usr/share/assimp/models"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def small(paths, limit):
    return sorted(p for p in paths if os.path.getsize(p) <= limit)


def put(seeds, fmt, name, data):
    d = os.path.join(seeds, fmt)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, re.sub(r"[^A-Za-z0-9_.-]", "_", name)), "wb") as f:
        f.write(data)


def self_contained_gltf(path, limit=256 * 1024):
    """The .gltf with its external buffers and images inlined, or None (too big, missing files)."""
    try:
        doc = json.load(open(path, encoding="utf-8"))
    except (ValueError, UnicodeDecodeError):
        return None, None
    base = os.path.dirname(path)
    total, first_buffer = 0, None
    for kind, mime in (("buffers", "application/octet-stream"), ("images", "image/png")):
        for i, item in enumerate(doc.get(kind, []) if isinstance(doc, dict) else []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if not isinstance(uri, str) or uri.startswith("data:"):
                continue
            file = os.path.join(base, uri.replace("%20", " "))
            if not os.path.isfile(file):
                return None, None
            data = open(file, "rb").read()
            total += len(data)
            if total > limit:
                return None, None
            if kind == "buffers" and i == 0:
                first_buffer = data
            if kind == "images" and uri.lower().endswith((".jpg", ".jpeg")):
                mime = "image/jpeg"
            item["uri"] = f"data:{mime};base64," + base64.b64encode(data).decode()
    return doc, first_buffer


def glb(doc, bin_data):
    """A .glb of doc, its first buffer (bin_data) moved to the BIN chunk."""
    doc = json.loads(json.dumps(doc))
    if bin_data is not None and doc.get("buffers"):
        del doc["buffers"][0]["uri"]
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if bin_data is not None:
        data = bin_data + b"\0" * (-len(bin_data) % 4)
        chunks += struct.pack("<II", len(data), 0x004E4942) + data
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def test_vdb_files():
    """The sparse byte images of tests/ecs/test_volume_and_scene_json.cpp (name -> bytes)."""
    text = open(os.path.join(ROOT, "tests/ecs/test_volume_and_scene_json.cpp")).read()
    files = {}
    for m in re.finditer(r"const SparseBytes (\w+)\{(\d+), \{(.*?)\n\}\};", text, re.S):
        data = bytearray(int(m.group(2)))
        for run in re.finditer(r"\{(\d+), ((?:\s*\"[0-9a-f]*\")+)\}", m.group(3)):
            hexs = "".join(re.findall(r"\"([0-9a-f]*)\"", run.group(2)))
            o = int(run.group(1))
            data[o:o + len(hexs) // 2] = bytes.fromhex(hexs)
        files[m.group(1)] = bytes(data)
    return files


def run_rtlab(rtlab, *args):
    r = subprocess.run([rtlab, *args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"fuzz: rtlab {' '.join(args)} failed: {r.stderr.strip()}")


def make_seeds(seeds, rtlab):
    shutil.rmtree(seeds, ignore_errors=True)
    for fmt in FORMATS:  # Step: the committed seeds.
        for p in glob.glob(os.path.join(ROOT, "fuzz/seeds", fmt, "*")):
            put(seeds, fmt, os.path.basename(p), open(p, "rb").read())
    if os.path.isdir(MODELS):  # Step: assimp-testmodels.
        for p in small(glob.glob(f"{MODELS}/glTF2/**/*.gltf", recursive=True), 128 * 1024):
            doc, first = self_contained_gltf(p)
            if doc is None:
                continue
            name = os.path.relpath(p, f"{MODELS}/glTF2").replace("/", "_")
            put(seeds, "gltf", name, json.dumps(doc, indent=1).encode())
            if isinstance(doc, dict) and len(doc.get("buffers", [])) == 1:
                put(seeds, "glb", name[:-5] + ".glb", glb(doc, first))
        for p in small(glob.glob(f"{MODELS}/glTF2/**/*.glb", recursive=True), 256 * 1024):
            put(seeds, "glb", os.path.relpath(p, f"{MODELS}/glTF2").replace("/", "_"), open(p, "rb").read())
        doc, first = self_contained_gltf(f"{MODELS}/glTF2/draco/2CylinderEngine.gltf", 512 * 1024)
        if doc is not None:  # Draco: the only compressed model there
            put(seeds, "glb", "draco_2CylinderEngine.glb", glb(doc, first))
        for fmt, pattern, limit in (("obj", "OBJ/*.obj", 64 * 1024), ("mtl", "OBJ/*.mtl", 64 * 1024),
                                    ("ply", "PLY/*.ply", 64 * 1024), ("fbx", "FBX/*.[fF][bB][xX]", 128 * 1024)):
            for p in small(glob.glob(f"{MODELS}/{pattern}"), limit):
                put(seeds, fmt, os.path.basename(p), open(p, "rb").read())
    # Step: files rtlab writes.
    with tempfile.TemporaryDirectory(prefix="rtlab_seeds_") as tmp:
        for scene, name in (("builtin:cornell", "cornell"), ("builtin:slivers?triangles=1000", "slivers")):
            run_rtlab(rtlab, "export", "--scene", scene, "--out", f"{tmp}/{name}.obj")
            run_rtlab(rtlab, "export", "--scene", scene, "--out", f"{tmp}/{name}.ply")
            for ext, fmt in ((".obj", "obj"), (".mtl", "mtl"), (".ply", "ply")):
                put(seeds, fmt, "rtlab_" + name + ext, open(f"{tmp}/{name}{ext}", "rb").read())
        for backend in ("embree", "rtcore"):
            run_rtlab(rtlab, "render", "--scene", "builtin:cornell", "--width", "6", "--height", "4", "--effects",
                      "gbuffer,shadows,ao", "--denoise", "none", "--backend", backend, "--record-rays",
                      f"{tmp}/{backend}", "--out", f"{tmp}/{backend}-out")
            put(seeds, "ray_trace", f"cornell_{backend}.rays", open(f"{tmp}/{backend}/frame_0000.rays", "rb").read())
        put(seeds, "exr", "cornell_6x4.exr", open(f"{tmp}/embree-out/frame_0000.exr", "rb").read())
    for name, data in test_vdb_files().items():
        put(seeds, "vdb", name + ".vdb", data)
    for p in glob.glob(os.path.join(ROOT, "docs/studies/*.json")):
        put(seeds, "study", os.path.basename(p), open(p, "rb").read())
    for p in glob.glob(os.path.join(ROOT, "rtcore_sim/presets/*.json")):
        put(seeds, "rtcore_config", os.path.basename(p), open(p, "rb").read())
    return {fmt: len(os.listdir(os.path.join(seeds, fmt))) if os.path.isdir(os.path.join(seeds, fmt)) else 0
            for fmt in FORMATS}


def fuzz_one(a, fmt):
    binary = os.path.join(a.fuzz_build, "fuzz", "fuzz_" + fmt)
    corpus = os.path.join(a.out, "corpus", fmt)
    findings = os.path.join(a.out, "findings", fmt)
    os.makedirs(corpus, exist_ok=True)
    os.makedirs(findings, exist_ok=True)
    before = set(os.listdir(findings))
    log = os.path.join(a.out, "logs", fmt + ".log")
    os.makedirs(os.path.dirname(log), exist_ok=True)
    cmd = [binary, corpus, os.path.join(a.out, "seeds", fmt), f"-max_total_time={a.seconds}", "-timeout=10",
           "-rss_limit_mb=2048", "-malloc_limit_mb=2048", "-print_final_stats=1", "-close_fd_mask=3",
           f"-artifact_prefix={findings}/"]
    dictionary = os.path.join(ROOT, "fuzz/dict", DICTIONARY.get(fmt, fmt) + ".dict")
    if os.path.exists(dictionary):
        cmd.append("-dict=" + dictionary)
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=0",
               LSAN_OPTIONS="suppressions=" + os.path.join(ROOT, "tests/lsan.supp") + ":print_suppressions=0",
               UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1", TMPDIR=tempfile.gettempdir(),
               RTLAB_FUZZ_READER_CHECK=os.path.abspath(a.rtlab))  # the separate reader check: a release rtlab
    started = time.time()
    with open(log, "w") as f:
        process = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(process.pid, 0)  # the fuzzer's CPU time, its reader-check children included
        code = process.returncode = os.waitstatus_to_exitcode(status)
    text = open(log, errors="replace").read()
    stat = dict(re.findall(r"stat::(\w+):\s+(\d+)", text))
    cov = re.findall(r"cov: (\d+)", text)
    corp = re.findall(r"corp: (\d+)", text)
    new = sorted(set(os.listdir(findings)) - before)
    return {"target": fmt, "seconds": round(time.time() - started, 1),
            "cpuSeconds": round(usage.ru_utime + usage.ru_stime, 1), "execs": int(stat.get("number_of_executed_units", 0)),
            "execsPerSecond": int(stat.get("average_exec_per_sec", 0)), "edges": int(cov[-1]) if cov else 0,
            "corpus": int(corp[-1]) if corp else 0, "peakRssMb": int(stat.get("peak_rss_mb", 0)),
            "findings": [os.path.join(findings, n) for n in new], "exit": code, "log": log}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fuzz-build", default="build/fuzz")
    ap.add_argument("--rtlab", default="build/release/apps/rtlab")
    ap.add_argument("--seconds", type=int, default=60, help="per target (FUZZ_SECONDS)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count())
    ap.add_argument("--targets", default="all", help="all, or a comma-separated list (FUZZ_TARGETS)")
    ap.add_argument("--out", default="out/fuzz")
    ap.add_argument("--seeds-only", action="store_true", help="put the seed corpora together (OUT/seeds) and stop")
    ap.add_argument("--ledger", action="store_true", help="print the totals of OUT/runs.jsonl per target and stop")
    a = ap.parse_args()
    if a.ledger:
        totals = {}
        for line in open(os.path.join(a.out, "runs.jsonl")):
            for r in json.loads(line)["results"]:
                t = totals.setdefault(r["target"], {"seconds": 0.0, "execs": 0, "edges": 0, "findings": 0, "runs": 0})
                # CPU time where the run recorded it; earlier runs recorded wall time only (a core each).
                t["seconds"] += r.get("cpuSeconds", r["seconds"])
                t["execs"] += r["execs"]
                t["edges"] = max(t["edges"], r["edges"])
                t["findings"] += len(r["findings"])
                t["runs"] += 1
        print("| target | runs | fuzzing time (CPU-min) | executions | edges (most in one run) | findings |")
        print("|---|---|---|---|---|---|")
        for fmt in FORMATS:
            if fmt in totals:
                t = totals[fmt]
                print(f"| `{fmt}` | {t['runs']} | {t['seconds'] / 60:.1f} | {t['execs']} | {t['edges']} | {t['findings']} |")
        return
    if a.seeds_only:
        counts = make_seeds(os.path.join(a.out, "seeds"), a.rtlab)
        print("fuzz: seeds in " + os.path.join(a.out, "seeds") + ": " + ", ".join(f"{t} {n}" for t, n in counts.items()))
        return
    targets = FORMATS if a.targets == "all" else [t for t in a.targets.split(",") if t]
    for t in targets:
        if t not in FORMATS:
            sys.exit(f"fuzz: unknown target '{t}' (known: {', '.join(FORMATS)})")
        if not os.path.exists(os.path.join(a.fuzz_build, "fuzz", "fuzz_" + t)):
            sys.exit(f"fuzz: {a.fuzz_build}/fuzz/fuzz_{t} is not built (cmake --preset fuzz && cmake --build --preset fuzz)")
    counts = make_seeds(os.path.join(a.out, "seeds"), a.rtlab)
    print("fuzz: seeds: " + ", ".join(f"{t} {counts[t]}" for t in targets), flush=True)
    print(f"fuzz: {len(targets)} targets, {a.seconds} s each, {a.jobs} at a time", flush=True)
    results = []
    ledger = os.path.join(a.out, "runs.jsonl")
    with concurrent.futures.ThreadPoolExecutor(a.jobs) as pool:
        for r in pool.map(lambda t: fuzz_one(a, t), targets):
            results.append(r)
            with open(ledger, "a") as f:  # each target as it ends: a stopped run keeps the targets it finished
                f.write(json.dumps({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "results": [r]}) + "\n")
            print(f"fuzz: {r['target']:<14} {r['cpuSeconds']:>7} CPU-s {r['execs']:>9} execs {r['execsPerSecond']:>6} /s {r['edges']:>6} edges "
                  f"corpus {r['corpus']:>5}  {len(r['findings'])} findings" +
                  "".join(f"\n      finding: {f}" for f in r["findings"]) +
                  (f"\n      stopped with exit {r['exit']}; see {r['log']}" if r["exit"] and not r["findings"] else ""),
                  flush=True)
    bad = [r for r in results if r["findings"] or r["exit"]]
    print(f"fuzz: {sum(r['execs'] for r in results)} executions in all; "
          f"{'findings in ' + ', '.join(r['target'] for r in bad) if bad else 'no findings'} (runs logged in {ledger})")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
