"""Checks the layering of the core and of the add-on.

The core (``--core SRC OBJ_DIR ARCHITECTURE_MD``): native/src is one folder a layer. Each folder's
README.md says its layer (``# native/src/NAME: layer N of the core``), what it owns, what it may use
(``May use: a, b.``: folders of lower layers only) and has a row for each of its files. A file may
call (symbols of the compiled objects, read with nm) and include (``#include "..."``, read from the
source) only its own folder and the folders its folder may use; a folder's ``*_internal.h`` is
private to it; within a folder, files may call one another but never in a circle. A static inline
function can only be reached through an include, so the include rule covers it. docs/architecture.md
holds the table of layers made from the READMEs (``--table SRC`` prints it) and must match them.

The add-on (``--addon ADDON_DIR``): addon/engine/ imports neither Blender (bpy and its modules)
nor any module of the add-on outside engine/, not even inside a function; and no modules of the
add-on import each other in a circle. Imports are read from the source (ast), every one of them,
wherever it stands; a module loaded by name (importlib) is not seen.
"""
import ast
import os
import re
import subprocess
import sys

TABLE_BEGIN = "<!-- layers: made by `make layers-table` from native/src/*/README.md -->"
TABLE_END = "<!-- layers: end -->"


def read_layers(src):
    """Folder name -> {rank, owns, uses, files: {name: what it owns}}, from each folder's README.md."""
    layers, problems = {}, []
    for name in sorted(os.listdir(src)):
        folder = os.path.join(src, name)
        if not os.path.isdir(folder):
            problems.append(f"native/src/{name}: a file outside the layer folders")
            continue
        readme = os.path.join(folder, "README.md")
        if not os.path.exists(readme):
            problems.append(f"native/src/{name}/: no README.md saying its layer, what it owns and may use")
            continue
        text = open(readme).read()
        rank = re.search(r"^# native/src/([a-z_0-9]+): layer (\d+) of the core$", text, re.M)
        owns = re.search(r"^Owns: (.*)$", text, re.M)
        uses = re.search(r"^May use: (.*)\.$", text, re.M)
        if not (rank and owns and uses) or rank.group(1) != name:
            problems.append(f"native/src/{name}/README.md: needs '# native/src/{name}: layer N of the core', "
                            "'Owns: ...' and 'May use: ...' lines")
            continue
        used = [] if uses.group(1).startswith("nothing") else [u.strip() for u in uses.group(1).split(",")]
        files = dict(re.findall(r"^\| `([a-z_0-9]+\.[ch])` \| (.*) \|$", text, re.M))
        layers[name] = {"rank": int(rank.group(2)), "owns": owns.group(1), "uses": used, "files": files}
        for f in sorted(os.listdir(folder)):
            if f.endswith((".c", ".h")) and f not in files:
                problems.append(f"native/src/{name}/{f}: no row in its folder's README.md")
        for f in files:
            if not os.path.exists(os.path.join(folder, f)):
                problems.append(f"native/src/{name}/README.md: a row for {f}, which is not there")
    for name, layer in layers.items():
        for u in layer["uses"]:
            if u not in layers:
                problems.append(f"native/src/{name}/README.md: may use '{u}', which is no layer folder")
            elif layers[u]["rank"] >= layer["rank"]:
                problems.append(f"native/src/{name}/README.md: may use {u} (layer {layers[u]['rank']}), "
                                f"which is not below it (layer {layer['rank']})")
    return layers, problems


def table(layers):
    """The layers as docs/architecture.md shows them, top floor first."""
    rows = ["| layer | folder | owns | may use |", "| --- | --- | --- | --- |"]
    for name, layer in sorted(layers.items(), key=lambda kv: -kv[1]["rank"]):
        files = ", ".join(f"`{f}`" for f in layer["files"] if f.endswith(".c"))
        rows.append(f"| {layer['rank']} | `{name}/` ({files}) | {layer['owns']} | "
                    f"{', '.join(layer['uses']) or '—'} |")
    return "\n".join(rows)


def symbols(obj, *flags):
    out = subprocess.run(["nm", *flags, obj], check=True, capture_output=True, text=True).stdout
    return {line.split()[-1] for line in out.splitlines() if line.split() and line.split()[-1].startswith("gc_")}


def includes(path, src):
    """(line, folder of the header, header path relative to src) of each quoted include found in src."""
    out = []
    for n, line in enumerate(open(path), 1):
        m = re.match(r'\s*#\s*include\s+"([^"]+)"', line)
        if not m:
            continue
        for base in (os.path.dirname(path), src):
            target = os.path.normpath(os.path.join(base, m.group(1)))
            if os.path.exists(target) and os.path.commonpath([target, os.path.abspath(src)]) == os.path.abspath(src):
                rel = os.path.relpath(target, src)
                out.append((n, rel.split(os.sep)[0], rel))
                break
    return out


def check_core(src, obj_dir, doc_path):
    src = os.path.abspath(src)
    layers, problems = read_layers(src)
    allowed = {name: {name, *layer["uses"]} for name, layer in layers.items()}
    units = {f"{name}/{f[:-2]}": name for name, layer in layers.items() for f in layer["files"] if f.endswith(".c")}
    defined, needs = {}, {}
    for unit in units:
        obj = os.path.join(obj_dir, unit + ".o")
        if not os.path.exists(obj):
            problems.append(f"{obj}: not built")
            continue
        for sym in symbols(obj, "--defined-only", "--extern-only"):
            defined[sym] = unit
        needs[unit] = symbols(obj, "--undefined-only")
    calls = {u: {} for u in units}
    for unit, syms in needs.items():
        for sym in sorted(syms):
            owner = defined.get(sym)
            if not owner or owner == unit:
                continue
            here, there = units[unit], units[owner]
            if there not in allowed[here]:
                problems.append(f"{unit}.c (layer {here}) calls {sym} of {owner}.c (layer {there}), "
                                f"which {here}/ may not use")
            elif there == here:
                calls[unit].setdefault(owner, sym)
    for name in layers:
        for f in layers[name]["files"]:
            path = os.path.join(src, name, f)
            for line, there, header in includes(path, src):
                where = f"native/src/{name}/{f}:{line}"
                if there not in allowed[name]:
                    problems.append(f"{where}: includes {header} of layer {there}, which {name}/ may not use")
                elif there != name and header.endswith("_internal.h"):
                    problems.append(f"{where}: includes {header}, private to {there}/")
    for cycle in circles(calls):
        ties = ", ".join(f"{a}.c -> {b}.c ({calls[a][b]})" for a, b in zip(cycle, cycle[1:] + cycle[:1]))
        problems.append(f"call circle within a layer: {ties}")
    doc = open(doc_path).read()
    if doc_path and TABLE_BEGIN in doc and TABLE_END in doc:
        shown = doc.split(TABLE_BEGIN, 1)[1].split(TABLE_END, 1)[0].strip()
        if shown != table(layers):
            problems.append(f"{doc_path}: the table of layers differs from native/src/*/README.md "
                            "(`make layers-table` writes it)")
    else:
        problems.append(f"{doc_path}: no table of layers between {TABLE_BEGIN} and {TABLE_END}")
    for p in problems:
        print("check_layers:", p)
    if not problems:
        print(f"check_layers: {len(layers)} layer folders, {len(units)} files, every call and include goes down "
              "or stays on its floor, no circle")
    return 1 if problems else 0


def write_table(src, doc_path):
    layers, problems = read_layers(os.path.abspath(src))
    if problems:
        for p in problems:
            print("check_layers:", p)
        return 1
    doc = open(doc_path).read()
    head, rest = doc.split(TABLE_BEGIN, 1)
    tail = rest.split(TABLE_END, 1)[1]
    open(doc_path, "w").write(f"{head}{TABLE_BEGIN}\n{table(layers)}\n{TABLE_END}{tail}")
    return 0


# Blender's own modules: the bpy side's business, never the engine's.
BLENDER_MODULES = {"bpy", "bpy_extras", "bpy_types", "mathutils", "bmesh", "gpu", "gpu_extras", "blf", "bgl",
                   "addon_utils", "idprop", "aud", "freestyle", "imbuf"}


def addon_modules(root):
    """Module name (dotted, from the add-on's package) -> source path, for every .py of ``root``."""
    found = {}
    for folder, dirs, names in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in ("__pycache__", "graspcore"))
        for n in sorted(names):
            if n.endswith(".py"):
                rel = os.path.relpath(os.path.join(folder, n), root)[:-3].split(os.sep)
                found[".".join(rel[:-1] if rel[-1] == "__init__" else rel)] = os.path.join(folder, n)
    return found


def imports_of(module, path, modules):
    """(line, imported: an add-on module or a top-level outside name, what) of every import in the file."""
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(open(path).read(), path)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name.split(".")[0], a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                out.append((node.lineno, node.module.split(".")[0], node.module))
                continue
            base = package.split(".") if package else []
            base = base[:len(base) - (node.level - 1)] if node.level > 1 else base
            if node.level - 1 > len(package.split(".") if package else []):
                out.append((node.lineno, "..", "an import above the add-on's package"))
                continue
            target = ".".join(base + ([node.module] if node.module else []))
            for a in node.names:
                sub = f"{target}.{a.name}" if target else a.name
                out.append((node.lineno, sub if sub in modules else target, a.name))
    return out


def check_addon(root):
    modules = addon_modules(root)
    problems, graph = [], {m: {} for m in modules}
    for m, path in modules.items():
        in_engine = m == "engine" or m.startswith("engine.")
        for line, target, what in imports_of(m, path, modules):
            where = f"{os.path.relpath(path)}:{line}"
            if target in modules:           # "" is the add-on's own __init__.py
                if target != m:
                    graph[m].setdefault(target, (where, what))
                if in_engine and not (target == "engine" or target.startswith("engine.")):
                    problems.append(f"{where}: engine/ imports {target} from the add-on above it ({what})")
            elif in_engine and (target in BLENDER_MODULES or target == ".."):
                problems.append(f"{where}: engine/ imports {what} (the engine is bpy-free)")
    for cycle in circles(graph):
        ties = ", ".join(f"{a} -> {b} ({graph[a][b][0]}: {graph[a][b][1]})" for a, b in zip(cycle, cycle[1:] + cycle[:1]))
        problems.append(f"import circle: {ties}")
    for p in problems:
        print("check_layers:", p)
    if not problems:
        print(f"check_layers: {len(modules)} add-on modules, engine/ bpy-free and below the rest, no import circle")
    return 1 if problems else 0


def circles(graph):
    """One shortest circle through each strongly connected group of modules (Tarjan)."""
    index, low, stack, on, groups = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(set(group))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    out = []
    for group in groups:
        start = min(group)
        paths, seen = [[start]], {start}
        while paths:          # breadth first: the shortest way back to start
            path = paths.pop(0)
            for w in sorted(graph[path[-1]]):
                if w == start:
                    out.append(path)
                    paths = []
                    break
                if w in group and w not in seen:
                    seen.add(w)
                    paths.append(path + [w])
    return out


if __name__ == "__main__":
    if sys.argv[1] == "--addon":
        sys.exit(check_addon(sys.argv[2]))
    if sys.argv[1] == "--table":
        sys.exit(write_table(sys.argv[2], sys.argv[3]))
    if sys.argv[1] == "--core":
        sys.exit(check_core(sys.argv[2], sys.argv[3], sys.argv[4]))
    sys.exit("usage: check_layers.py --core SRC OBJ_DIR ARCHITECTURE_MD | --table SRC ARCHITECTURE_MD | --addon ADDON")
