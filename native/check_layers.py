"""Checks the layering of the core and of the add-on.

The core: no file of native/src calls a function of a file above it. The order is the table in
docs/architecture.md (rank, file); the calls are read from the compiled objects with nm (a gc_
symbol one object needs and another defines). Every .c file of native/src must have a row.
Usage: check_layers.py ARCHITECTURE_MD OBJ_DIR SOURCE.c...

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


def ranks(doc_path):
    rows = re.findall(r"^\| (\d+) \| `([a-z_0-9]+\.c)` \|", open(doc_path).read(), re.M)
    return {name[:-2]: int(rank) for rank, name in rows}


def symbols(obj, *flags):
    out = subprocess.run(["nm", *flags, obj], check=True, capture_output=True, text=True).stdout
    return {line.split()[-1] for line in out.splitlines() if line.split() and line.split()[-1].startswith("gc_")}


def main(doc_path, obj_dir, sources):
    rank = ranks(doc_path)
    units = [os.path.basename(s)[:-2] for s in sources]
    problems = [f"{u}.c: no row in {doc_path}" for u in units if u not in rank]
    defined = {}
    for u in units:
        for sym in symbols(os.path.join(obj_dir, u + ".o"), "--defined-only", "--extern-only"):
            defined[sym] = u
    for u in units:
        for sym in sorted(symbols(os.path.join(obj_dir, u + ".o"), "--undefined-only")):
            owner = defined.get(sym)
            if owner and owner in rank and u in rank and rank[owner] >= rank[u]:
                problems.append(f"{u}.c (rank {rank[u]}) calls {sym} of {owner}.c (rank {rank[owner]}), "
                                f"which is not below it")
    for p in problems:
        print("check_layers:", p)
    if not problems:
        print(f"check_layers: {len(units)} files, every call goes down the layers")
    return 1 if problems else 0


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
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3:]))
