"""Checks the core's layering: no file of native/src calls a function of a file above it.

The order is the table in docs/architecture.md (rank, file); the calls are read from the
compiled objects with nm (a gc_ symbol one object needs and another defines). Every .c file
of native/src must have a row. Usage: check_layers.py ARCHITECTURE_MD OBJ_DIR SOURCE.c...
"""
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


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3:]))
