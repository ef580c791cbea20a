#!/usr/bin/env python3
"""Checks the source tree's structure (issue 30, "Structure"); standard library only.

  1. Layering: no file of a module includes a module it may not depend on
     (the LAYERS table below, from ../shared/DESIGN.md), nor another module's
     private files (anything outside OTHER/include/rtlab/OTHER/); no module's
     CMakeLists.txt links (rtlab_add_module PUBLIC_DEPS/PRIVATE_DEPS,
     target_link_libraries) an rtlab:: module it may not depend on.
  2. No include cycle among the project's own files (<rtlab/M/...> resolves to
     M/include/rtlab/M/..., a quoted include relative to the including file
     first, then to the folder's include root).
  3. No non-test source file (.cpp/.hpp under the module folders, perf/ and
     examples/) longer than MAX_LINES lines, unless a comment in its first
     MARKER_WINDOW lines says why: `// longer than 800 lines: REASON`.

Usage: scripts/check_structure.py [--root DIR] [--strict] | --self-test
Prints every violation (file, line, what), then one summary line; exits 1 on any
violation, 0 otherwise. Run by ctest (label "structure"): structure.check on the
tree, structure.self_test on synthetic trees with known violations.
"""

import argparse
import io
import os
import re
import sys
import tempfile
from dataclasses import dataclass

# ---------------------------------------------------------------------------
# The layering: the "may depend on" column of the "Folders" table in
# ../shared/DESIGN.md (the design's copy is authoritative; keep the two in step).
# One line per module, the rtlab modules it may depend on; third-party packages
# are not checked. "*" is everything. "MODULE:INTERFACE" allows only the headers
# of INTERFACES[MODULE:INTERFACE]. Dependencies are transitive (a layering): a
# module may also use what its dependencies may use (shaders_cpp reaches the ECS
# snapshot through tracer), unless --strict, which reads the table literally.
# A new module (e.g. a session/ frame driver above shaders_cpp, denoise and
# rtcore_sim) is one new line here plus its name in the lines of the modules
# above it (study, apps).
LAYERS = {
    "core":        [],
    "ecs":         ["core"],
    "tracer":      ["core", "ecs:snapshot"],                        # "ecs (read-only snapshot types)"
    "rtcore_sim":  ["core", "tracer"],                              # "tracer's back-end interface"
    "shaders_cpp": ["core", "tracer"],
    "denoise":     ["core"],                                        # denoisers see images, never the scene
    "session":     ["core", "ecs", "tracer", "rtcore_sim", "shaders_cpp", "denoise"],  # the frame driver (docs/architecture.md)
    "study":       ["core", "tracer", "rtcore_sim", "shaders_cpp", "session"],
    "apps":        ["*"],                                           # "everything"
}

# Restricted views of a module: the headers (under MODULE/include/rtlab/MODULE/)
# a "MODULE:INTERFACE" entry allows. ecs:snapshot is the plain snapshot the
# tracer consumes ("tracer/ and rtcore_sim/ never include ECS internals"):
# snapshot.hpp and what it is made of; not world.hpp, component_store.hpp, load/.
INTERFACES = {
    "ecs:snapshot": ["snapshot.hpp", "assets.hpp", "components.hpp", "entity.hpp",
                     "frame_update.hpp", "volume_grid.hpp"],
}

# Folders outside the layering: their files may include anything (DESIGN.md:
# perf/ and tests/ "everything", examples/ the installed package); a module may
# include none of them.
FREE_FOLDERS = ["perf", "tests", "examples", "fuzz"]

# Extra include roots per folder (besides MODULE/include for a module), as the
# CMake targets set them: tests/ compile with tests/ on the include path.
INCLUDE_ROOTS = {"tests": ["tests"]}

# Source length: the limit, the folders it applies to (never tests/) and the marker.
MAX_LINES = 800
MARKER_WINDOW = 10
MARKER = f"longer than {MAX_LINES} lines:"
LENGTH_SUFFIXES = (".cpp", ".hpp")
LENGTH_EXTRA_FOLDERS = ["perf", "examples"]

SOURCE_SUFFIXES = (".cpp", ".hpp", ".h", ".cc", ".hh", ".cxx", ".inc", ".inl", ".ipp", ".tpp")
SKIP_DIRS = {"build", "out"}  # never sources (examples/*/build from a local out-of-tree build)

INCLUDE_RE = re.compile(r'^[ \t]*#[ \t]*include[ \t]*([<"])([^>"\n]+)[>"]', re.MULTILINE)
RTLAB_RE = re.compile(r"^rtlab/([A-Za-z0-9_]+)/")


@dataclass(frozen=True)
class Violation:
    kind: str   # layering | cmake | cycle | length | table
    path: str   # relative to the root, '/'-separated
    line: int   # 0 when it is about the whole file
    message: str

    def __str__(self):
        where = f"{self.path}:{self.line}" if self.line else self.path
        return f"{self.kind}: {where}: {self.message}"


# --------------------------------------------------------------------------- the table

def allowed_deps(layers, interfaces, strict=False):
    """Per module: {module it may use: None (all of it) or a set of header names}."""
    for module, deps in layers.items():
        for entry in deps:
            name = entry.split(":")[0]
            if entry != "*" and name not in layers:
                raise ValueError(f"LAYERS[{module!r}] names unknown module {name!r}")
            if ":" in entry and entry not in interfaces:
                raise ValueError(f"LAYERS[{module!r}] names unknown interface {entry!r}")

    def merge(acc, module, headers):
        if module in acc and (acc[module] is None or headers is None):
            acc[module] = None
        elif module in acc:
            acc[module] = acc[module] | headers
        else:
            acc[module] = None if headers is None else set(headers)

    result, visiting = {}, set()

    def visit(module):
        if module in result:
            return result[module]
        if module in visiting:
            raise ValueError(f"LAYERS has a cycle through {module!r}")
        visiting.add(module)
        acc = {}
        for entry in layers[module]:
            if entry == "*":
                for other in layers:
                    if other != module:
                        merge(acc, other, None)
                continue
            name = entry.split(":")[0]
            merge(acc, name, set(interfaces[entry]) if ":" in entry else None)
            if not strict:
                for dep, headers in visit(name).items():
                    if dep != module:
                        merge(acc, dep, headers)
        visiting.discard(module)
        result[module] = acc
        return acc

    for module in layers:
        visit(module)
    return result


def describe(allowed):
    if not allowed:
        return "nothing"
    parts = []
    for module in sorted(allowed):
        headers = allowed[module]
        parts.append(module if headers is None else f"{module} ({', '.join(sorted(headers))})")
    return ", ".join(parts)


# --------------------------------------------------------------------------- reading files

def strip_comments(text):
    """The text with C++ comments and raw string bodies blanked (newlines kept, so
    line numbers hold); other string and character literals, which cannot span
    lines and so cannot hold a directive, are skipped, not blanked."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if c == "/" and text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif c == "/" and text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            raw = re.match(r'R"([^()\\ \n]{0,16})\(', text[i - 1:i + 20]) if i > 0 else None
            if raw and (i < 2 or not (text[i - 2].isalnum() or text[i - 2] == "_") or text[i - 2] in "uU8L"):
                # A raw string may span lines: blank its body, or a line in it could read as a directive.
                end = text.find(")" + raw.group(1) + '"', i)
                j = n if end < 0 else end + len(raw.group(1)) + 2
                out.append(re.sub(r"[^\n]", " ", text[i:j]))
                i = j
                continue
            else:
                j = i + 1
                while j < n and text[j] != '"' and text[j] != "\n":
                    j += 2 if text[j] == "\\" else 1
                j = min(j + 1, n)
            out.append(text[i:j])
            i = j
        elif c == "'" and not (i > 0 and (text[i - 1].isalnum() or text[i - 1] == "_")):
            j = i + 1  # a character literal (a ' after a digit or letter is a digit separator)
            while j < n and text[j] != "'" and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(text[i:j])
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def find_includes(text):
    """[(line, '<' or '"', name)] of the #include directives outside comments."""
    code = strip_comments(text)
    return [(code.count("\n", 0, m.start()) + 1, m.group(1), m.group(2).strip())
            for m in INCLUDE_RE.finditer(code)]


def read(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return f.read()


def top_folder(rel):
    return rel.split("/", 1)[0]


def scan_files(root, folders):
    files = []
    for folder in folders:
        base = os.path.join(root, folder)
        for dirpath, dirnames, filenames in os.walk(base):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d not in SKIP_DIRS)
            for name in sorted(filenames):
                if name.endswith(SOURCE_SUFFIXES):
                    files.append(os.path.relpath(os.path.join(dirpath, name), root).replace(os.sep, "/"))
    return files


def resolve(root, rel, quote, name, layers):
    """The project file an include names (relative to root), or None (a system or
    generated header)."""
    candidates = []
    if quote == '"':
        candidates.append(os.path.join(os.path.dirname(rel), name))
    folder = top_folder(rel)
    if folder in layers:
        candidates.append(os.path.join(folder, "include", name))
    for include_root in INCLUDE_ROOTS.get(folder, []):
        candidates.append(os.path.join(include_root, name))
    m = RTLAB_RE.match(name)
    if m:
        candidates.append(os.path.join(m.group(1), "include", name))
    for candidate in candidates:
        candidate = os.path.normpath(candidate).replace(os.sep, "/")
        if candidate.startswith("../") or candidate == "..":
            continue
        if os.path.isfile(os.path.join(root, candidate)):
            return candidate
    return None


# --------------------------------------------------------------------------- the checks

def check_layering(rel, line, quote, name, target, layers, allowed):
    """The violation of one include of a module's file, or None."""
    source = top_folder(rel)
    spelled = f"<{name}>" if quote == "<" else f'"{name}"'
    if target is not None:
        dest = top_folder(target)
        if dest == source:
            return None
        if dest in FREE_FOLDERS:
            return Violation("layering", rel, line, f"{source} includes {dest}/ ({spelled}); a module may not")
        if dest not in layers:
            if target.startswith(f"{dest}/include/rtlab/{dest}/"):
                return Violation("layering", rel, line,
                                 f"{source} includes {spelled} of module {dest}, which the layering table does not "
                                 "list (add it to LAYERS in scripts/check_structure.py and to DESIGN.md)")
            return None  # not a module folder: nothing to say
        public = f"{dest}/include/rtlab/{dest}/"
        if not target.startswith(public):
            return Violation("layering", rel, line,
                             f"{source} includes {dest}'s private {target} ({spelled}); only {public} is public")
        header = target[len(public):]
    else:
        m = RTLAB_RE.match(name)
        if not m or m.group(1) == source:
            return None
        dest, header = m.group(1), name[len(m.group(0)):]
        if dest not in layers:
            return Violation("layering", rel, line,
                             f"{source} includes {spelled} of module {dest}, which the layering table does not list "
                             "(add it to LAYERS in scripts/check_structure.py and to DESIGN.md)")
    deps = allowed[source]
    if dest not in deps:
        return Violation("layering", rel, line,
                         f"{source} may not include {dest} ({spelled}); {source} may use: {describe(deps)}")
    if deps[dest] is not None and header not in deps[dest]:
        return Violation("layering", rel, line,
                         f"{source} may use only {dest}'s {', '.join(sorted(deps[dest]))}, not {header} ({spelled})")
    return None


def cmake_calls(text):
    """[(line, call text)] of rtlab_add_module(...) and target_link_libraries(...)
    calls, comments removed."""
    lines = []
    for line in text.split("\n"):
        quoted, cut = False, len(line)
        for k, ch in enumerate(line):
            if ch == '"':
                quoted = not quoted
            elif ch == "#" and not quoted:
                cut = k
                break
        lines.append(line[:cut])
    code = "\n".join(lines)
    calls = []
    for m in re.finditer(r"\b(rtlab_add_module|target_link_libraries)\s*\(", code, re.IGNORECASE):
        depth, j = 1, m.end()
        while j < len(code) and depth:
            depth += {"(": 1, ")": -1}.get(code[j], 0)
            j += 1
        calls.append((code.count("\n", 0, m.start()) + 1, code[m.start():j]))
    return calls


def check_cmake(root, module, layers, allowed):
    rel = f"{module}/CMakeLists.txt"
    path = os.path.join(root, rel)
    if not os.path.isfile(path):
        return [], 0
    violations, links = [], 0
    for first_line, call in cmake_calls(read(path)):
        for m in re.finditer(r"\brtlab::([A-Za-z0-9_]+)", call):
            dep = m.group(1)
            if dep == module:
                continue
            links += 1
            line = first_line + call.count("\n", 0, m.start())
            if dep not in layers:
                violations.append(Violation("cmake", rel, line,
                                            f"{module} links rtlab::{dep}, a module the layering table does not list"))
            elif dep not in allowed[module]:
                violations.append(Violation("cmake", rel, line,
                                            f"{module} links rtlab::{dep}; {module} may use: {describe(allowed[module])}"))
    return violations, links


def find_cycles(graph):
    """Strongly connected components of more than one file (or a file including
    itself), each as one cycle [a, b, ..., a]; Tarjan's algorithm, iterative."""
    index, low, on_stack, stack, sccs, counter = {}, {}, set(), [], [], [0]
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in graph:
                    continue
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                scc = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    scc.append(member)
                    if member == node:
                        break
                if len(scc) > 1 or node in graph[node]:
                    sccs.append(set(scc))
    cycles = []
    for scc in sccs:
        first = min(scc)
        # Shortest path first -> ... -> first inside the component (breadth first).
        previous, frontier, found = {first: None}, [first], None
        while frontier and found is None:
            following = []
            for node in frontier:
                for child in sorted(graph[node]):
                    if child == first:
                        found = node
                        break
                    if child in scc and child not in previous:
                        previous[child] = node
                        following.append(child)
                if found is not None:
                    break
            frontier = following
        path, node = [first], found
        while node is not None and node != first:
            path.append(node)
            node = previous[node]
        cycles.append([first] + list(reversed(path[1:])) + [first])
    return sorted(cycles)


def check_length(rel, text):
    lines = text.splitlines()
    if len(lines) <= MAX_LINES:
        return None
    comment = re.compile(r"(//|/\*|^\s*\*).*" + re.escape(MARKER) + r"\s*\S")
    if any(comment.search(line) for line in lines[:MARKER_WINDOW]):
        return None
    return Violation("length", rel, 0,
                     f"{len(lines)} lines > {MAX_LINES}: split it, or say why in a comment in its first "
                     f"{MARKER_WINDOW} lines: `// {MARKER} REASON`")


@dataclass
class Result:
    violations: list
    modules: int
    files: int
    edges: int
    module_edges: int
    cmake_links: int


def check(root, layers=LAYERS, interfaces=INTERFACES, strict=False):
    allowed = allowed_deps(layers, interfaces, strict)
    modules = [m for m in layers if os.path.isdir(os.path.join(root, m))]
    free = [f for f in FREE_FOLDERS if os.path.isdir(os.path.join(root, f))]
    violations = []

    # A folder with public rtlab headers is a module: it must have a line in the table.
    for entry in sorted(os.listdir(root)):
        if entry not in layers and os.path.isdir(os.path.join(root, entry, "include", "rtlab", entry)):
            violations.append(Violation("table", entry, 0,
                                        f"module {entry}/ is not in the layering table (LAYERS in "
                                        "scripts/check_structure.py, from DESIGN.md's Folders table)"))

    files = scan_files(root, modules + free)
    graph = {rel: set() for rel in files}
    module_edges = set()
    edges = 0
    for rel in files:
        text = read(os.path.join(root, rel))
        folder = top_folder(rel)
        for line, quote, name in find_includes(text):
            target = resolve(root, rel, quote, name, layers)
            if target is not None:
                graph[rel].add(target)
                graph.setdefault(target, set())
                edges += 1
            if folder in layers:
                violation = check_layering(rel, line, quote, name, target, layers, allowed)
                if violation:
                    violations.append(violation)
                named = RTLAB_RE.match(name)
                dest = top_folder(target) if target else (named.group(1) if named else None)
                if dest and dest != folder:
                    module_edges.add((folder, dest))
        if rel.endswith(LENGTH_SUFFIXES) and folder != "tests" and (folder in layers or folder in LENGTH_EXTRA_FOLDERS):
            violation = check_length(rel, text)
            if violation:
                violations.append(violation)

    cmake_links = 0
    for module in modules:
        found, links = check_cmake(root, module, layers, allowed)
        violations += found
        cmake_links += links

    for cycle in find_cycles(graph):
        violations.append(Violation("cycle", cycle[0], 0, "include cycle: " + " -> ".join(cycle)))

    order = {"table": 0, "layering": 1, "cmake": 2, "cycle": 3, "length": 4}
    violations.sort(key=lambda v: (order.get(v.kind, 9), v.path, v.line, v.message))
    return Result(violations, len(modules), len(files), edges, len(module_edges), cmake_links)


def summary(result):
    kinds = {}
    for v in result.violations:
        kinds[v.kind] = kinds.get(v.kind, 0) + 1
    counts = ", ".join(f"{kinds.get(k, 0)} {k}" for k in ("layering", "cmake", "cycle", "length"))
    if kinds.get("table"):
        counts += f", {kinds['table']} table"
    verdict = "OK" if not result.violations else f"{len(result.violations)} violation(s) ({counts})"
    return (f"check_structure: {result.modules} modules, {result.files} files, {result.edges} include edges "
            f"({result.module_edges} module pairs), {result.cmake_links} CMake module links: {verdict}")


def main(argv=None, out=sys.stdout):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        help="the repository root (default: this script's parent's parent)")
    parser.add_argument("--strict", action="store_true",
                        help="read the table literally: direct dependencies only, no layering closure")
    parser.add_argument("--self-test", action="store_true",
                        help="check the checker on synthetic trees with known violations")
    args = parser.parse_args(argv)
    if args.self_test:
        return self_test(out)
    result = check(os.path.abspath(args.root), strict=args.strict)
    for violation in result.violations:
        print(violation, file=out)
    print(summary(result), file=out)
    return 1 if result.violations else 0


# --------------------------------------------------------------------------- self test

def write(root, rel, text):
    path = os.path.join(root, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def filler(lines, head=""):
    """A C++ file of exactly `lines` lines whose first lines are `head`."""
    head_lines = head.splitlines()
    return "\n".join(head_lines + [f"int f{k}() {{ return {k}; }}" for k in range(lines - len(head_lines))]) + "\n"


def clean_tree(root):
    """A small tree in the project's shape with no violation."""
    write(root, "core/CMakeLists.txt", "rtlab_add_module(core\n  PUBLIC_DEPS glm::glm)  # rtlab::tracer in a comment\n")
    write(root, "core/include/rtlab/core/math.hpp", "#pragma once\n#include <glm/glm.hpp>\n")
    write(root, "core/include/rtlab/core/image.hpp", '#pragma once\n#include "math.hpp"\n')
    write(root, "core/src/image.cpp",
          '#include <rtlab/core/image.hpp>\n#include "detail.hpp"\n'
          "// #include <rtlab/apps/commented_out.hpp>\n"
          "/* #include <rtlab/study/study.hpp>\n#include <rtlab/tracer/pipeline.hpp> */\n"
          'const char* glob = "src/*.cpp"; // a /* in a string opens no comment\n'
          'const char* raw = R"(\n#include <rtlab/study/in_a_raw_string.hpp>\n)";\n'
          "int million = 1'000'000;\n")
    write(root, "core/src/detail.hpp", "#pragma once\n")
    write(root, "core/src/exactly_limit.cpp", filler(MAX_LINES))
    write(root, "core/src/long_with_reason.cpp",
          filler(MAX_LINES + 100, "// image.cpp\n//\n// " + MARKER + " one state machine; splitting it scatters its states\n"))
    write(root, "core/src/long_with_block_reason.hpp",
          filler(MAX_LINES + 1, "#pragma once\n/*\n * " + MARKER + " generated table\n */\n"))
    write(root, "ecs/CMakeLists.txt", "rtlab_add_module(ecs\n  PUBLIC_DEPS rtlab::core\n  PRIVATE_DEPS TinyGLTF::TinyGLTF)\n")
    write(root, "ecs/include/rtlab/ecs/snapshot.hpp", "#pragma once\n#include <rtlab/core/math.hpp>\n")
    write(root, "ecs/include/rtlab/ecs/world.hpp", "#pragma once\n#include <rtlab/ecs/snapshot.hpp>\n")
    write(root, "tracer/CMakeLists.txt", "rtlab_add_module(tracer PUBLIC_DEPS rtlab::core rtlab::ecs embree)\n")
    write(root, "tracer/include/rtlab/tracer/pipeline.hpp", "#pragma once\n#include <rtlab/ecs/snapshot.hpp>\n")
    write(root, "shaders_cpp/CMakeLists.txt", "rtlab_add_module(shaders_cpp PUBLIC_DEPS rtlab::core rtlab::tracer)\n")
    write(root, "shaders_cpp/src/pass.cpp",
          "#include <rtlab/tracer/pipeline.hpp>\n#include <rtlab/ecs/snapshot.hpp>\n#include <rtlab/core/image.hpp>\n")
    write(root, "denoise/include/rtlab/denoise/svgf.hpp", "#pragma once\n#include <rtlab/core/image.hpp>\n")
    write(root, "apps/CMakeLists.txt", "add_executable(rtlab main.cpp)\n"
          "target_link_libraries(rtlab PRIVATE rtlab::study rtlab::denoise rtlab::ecs)\n")
    write(root, "apps/src/main.cpp", "#include <rtlab/ecs/world.hpp>\n#include <rtlab/denoise/svgf.hpp>\n"
          "#include <rtlab/shaders_cpp/missing_but_allowed.hpp>\n")
    write(root, "tests/temp_dir.hpp", "#pragma once\n")
    write(root, "tests/core/test_long.cpp", filler(MAX_LINES + 500, '#include "../temp_dir.hpp"\n'
                                                   '#include "../../core/src/detail.hpp"\n#include "core/util.hpp"\n'))
    write(root, "tests/core/util.hpp", "#pragma once\n#include <rtlab/apps/anything.hpp>\n")
    write(root, "perf/bench.cpp", '#include "../core/src/detail.hpp"\n#include <rtlab/ecs/world.hpp>\n')
    write(root, "examples/custom/main.cpp", "#include <rtlab/ecs/world.hpp>\n")


def broken_tree(root):
    """The clean tree plus one of each violation; returns {(kind, path, line)} expected."""
    clean_tree(root)
    write(root, "core/src/uses_tracer.cpp", "#include <vector>\n\n#include <rtlab/tracer/pipeline.hpp>\n")
    write(root, "tracer/src/world_user.cpp", "#include <rtlab/ecs/world.hpp>\n#include <rtlab/ecs/snapshot.hpp>\n")
    write(root, "denoise/src/scene.cpp", "#include <rtlab/denoise/svgf.hpp>\n#include <rtlab/ecs/snapshot.hpp>\n")
    write(root, "shaders_cpp/src/private.cpp", '#include "../../core/src/detail.hpp"\n')
    write(root, "shaders_cpp/src/test_helper.cpp", '#include "../../tests/temp_dir.hpp"\n')
    write(root, "study/src/probe_user.cpp", "#include <rtlab/probe/probe.hpp>\n")
    write(root, "ecs/CMakeLists.txt",
          "rtlab_add_module(ecs\n  PUBLIC_DEPS rtlab::core\n  PRIVATE_DEPS TinyGLTF::TinyGLTF rtlab::tracer)\n")
    # A cycle of three headers across a quoted and two <rtlab/...> includes.
    write(root, "core/include/rtlab/core/a.hpp", '#pragma once\n#include "b.hpp"\n')
    write(root, "core/include/rtlab/core/b.hpp", "#pragma once\n#include <rtlab/core/c.hpp>\n")
    write(root, "core/include/rtlab/core/c.hpp", "#pragma once\n#include <rtlab/core/a.hpp>\n")
    write(root, "core/src/self.cpp", '#include "self.cpp"\n')
    write(root, "core/src/too_long.cpp", filler(MAX_LINES + 1))
    write(root, "core/src/reason_too_late.cpp", filler(MAX_LINES + 50, "\n" * MARKER_WINDOW + "// " + MARKER + " late\n"))
    write(root, "core/src/no_reason.cpp", filler(MAX_LINES + 50, "// " + MARKER + "   \n"))
    write(root, "core/src/marker_in_code.cpp", filler(MAX_LINES + 50, 'const char* s = "' + MARKER + ' x";\n'))
    write(root, "perf/long_bench.cpp", filler(MAX_LINES + 1))
    write(root, "probe/include/rtlab/probe/probe.hpp", "#pragma once\n")
    return {
        ("table", "probe", 0),
        ("layering", "core/src/uses_tracer.cpp", 3),
        ("layering", "tracer/src/world_user.cpp", 1),
        ("layering", "denoise/src/scene.cpp", 2),
        ("layering", "shaders_cpp/src/private.cpp", 1),
        ("layering", "shaders_cpp/src/test_helper.cpp", 1),
        ("layering", "study/src/probe_user.cpp", 1),
        ("cmake", "ecs/CMakeLists.txt", 3),
        ("cycle", "core/include/rtlab/core/a.hpp", 0),
        ("cycle", "core/src/self.cpp", 0),
        ("length", "core/src/too_long.cpp", 0),
        ("length", "core/src/reason_too_late.cpp", 0),
        ("length", "core/src/no_reason.cpp", 0),
        ("length", "core/src/marker_in_code.cpp", 0),
        ("length", "perf/long_bench.cpp", 0),
    }


def self_test(out):
    failures = []

    def expect(what, ok, detail=""):
        print(f"  {'ok  ' if ok else 'FAIL'} {what}" + (f"\n       {detail}" if detail and not ok else ""), file=out)
        if not ok:
            failures.append(what)

    def found(result):
        return {(v.kind, v.path, v.line) for v in result.violations}

    print("check_structure self-test:", file=out)
    with tempfile.TemporaryDirectory(prefix="check_structure_") as tmp:
        clean = os.path.join(tmp, "clean")
        clean_tree(clean)
        result = check(clean)
        expect("a clean tree passes (allowed and transitive includes, comments, strings, tests/, perf/, "
               "examples/, a long file with the marker, a long test file)",
               not result.violations, "\n       ".join(map(str, result.violations)))
        expect("a clean tree exits 0", main(["--root", clean], out=io.StringIO()) == 0)
        expect("a clean tree's files and resolved includes are counted (commented-out ones not)", result.edges == 18 and result.files == 18,
               f"edges {result.edges}, files {result.files}")

        strict = check(clean, strict=True)
        expect("--strict reads the table literally (shaders_cpp -> ecs is only transitive)",
               found(strict) == {("layering", "shaders_cpp/src/pass.cpp", 2)},
               "\n       ".join(map(str, strict.violations)))

        broken = os.path.join(tmp, "broken")
        expected = broken_tree(broken)
        result = check(broken)
        got = found(result)
        for item in sorted(expected):
            expect(f"detects {item[0]} in {item[1]}" + (f":{item[2]}" if item[2] else ""), item in got)
        extra = got - expected
        expect("no other violation in the broken tree", not extra,
               "\n       ".join(str(v) for v in result.violations if (v.kind, v.path, v.line) in extra))
        cycle = [v.message for v in result.violations if v.path == "core/include/rtlab/core/a.hpp"]
        want = ("include cycle: core/include/rtlab/core/a.hpp -> core/include/rtlab/core/b.hpp -> "
                "core/include/rtlab/core/c.hpp -> core/include/rtlab/core/a.hpp")
        expect("prints the cycle", cycle == [want], f"got {cycle}")
        lengths = [v.message for v in result.violations if v.path == "core/src/too_long.cpp"]
        expect("names the line count", lengths and lengths[0].startswith(f"{MAX_LINES + 1} lines"), f"got {lengths}")
        expect("a broken tree exits 1", main(["--root", broken], out=io.StringIO()) == 1)

        # The table extends by one line: a new module (here "probe") between the lower layers and study/apps.
        layers = dict(LAYERS)
        layers["probe"] = ["core", "tracer", "rtcore_sim", "shaders_cpp", "denoise"]
        layers["study"] = LAYERS["study"] + ["probe"]
        result = check(broken, layers=layers)
        got = found(result)
        expect("a new line in the table accepts probe/ and study -> probe",
               ("table", "probe", 0) not in got and ("layering", "study/src/probe_user.cpp", 1) not in got
               and len(got) == len(expected) - 2)
        write(broken, "probe/src/up.cpp", "#include <rtlab/study/study.hpp>\n")
        expect("... and still refuses probe -> study",
               ("layering", "probe/src/up.cpp", 1) in found(check(broken, layers=layers)))
        try:
            allowed_deps({"a": ["b"]}, {})
            expect("a table naming an unknown module is refused", False)
        except ValueError:
            expect("a table naming an unknown module is refused", True)

    print(f"check_structure self-test: {'OK' if not failures else f'{len(failures)} FAILED'}", file=out)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
