"""native/check_layers.py --addon: the add-on's rule (engine/ never imports Blender nor the
add-on above it, even inside a function; no import circles) on small trees made to break it,
and on the add-on itself."""
import importlib.util
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("check_layers", ROOT / "native" / "check_layers.py")
check_layers = importlib.util.module_from_spec(spec)
spec.loader.exec_module(check_layers)


def tree(tmp_path, files):
    for name, text in files.items():
        path = tmp_path / "addon" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return str(tmp_path / "addon")


CLEAN = {"__init__.py": "", "ui.py": "import bpy\nfrom . import session\n",
         "session.py": "import bpy\nfrom .engine import runner\nfrom .engine.recording import open_recording\n",
         "engine/__init__.py": "", "engine/runner.py": "import numpy\nfrom .recording import reader\n",
         "engine/recording/__init__.py": "from .reader import open_recording\n",
         "engine/recording/reader.py": "from .format import X\n", "engine/recording/format.py": "X = 1\n"}


def test_a_clean_tree_passes(tmp_path, capsys):
    assert check_layers.check_addon(tree(tmp_path, CLEAN)) == 0
    assert "8 add-on modules" in capsys.readouterr().out


def test_the_engine_importing_blender_or_the_addon_above_fails_naming_the_line(tmp_path, capsys):
    files = dict(CLEAN)
    files["engine/runner.py"] = ("def f():\n    import bpy\n\n\ndef g():\n    from mathutils import Matrix\n\n\n"
                                 "def h():\n    from .. import session\n    from ..ui import x\n")
    assert check_layers.check_addon(tree(tmp_path, files)) == 1
    out = capsys.readouterr().out
    for needle in ("engine/runner.py:2: engine/ imports bpy", "engine/runner.py:6: engine/ imports mathutils",
                   "engine/runner.py:10: engine/ imports session from the add-on above it",
                   "engine/runner.py:11: engine/ imports ui from the add-on above it"):
        assert needle in out, out


def test_a_circle_fails_naming_each_tie(tmp_path, capsys):
    files = dict(CLEAN)
    files["session.py"] = "import bpy\n\n\ndef f():\n    from .ui import panel\n"
    files["engine/recording/format.py"] = "def f():\n    from .reader import g\n"
    assert check_layers.check_addon(tree(tmp_path, files)) == 1
    out = capsys.readouterr().out
    assert "import circle: session -> ui (" in out and "ui -> session (" in out, out
    assert "engine.recording.format -> engine.recording.reader" in out, out


def test_the_addon_keeps_the_rule(capsys):
    assert check_layers.check_addon(str(ROOT / "addon")) == 0, capsys.readouterr().out


# --- the core: layer folders (check_layers.py --core) on small compiled trees -------------------
import shutil
import subprocess

import pytest

needs_cc = pytest.mark.skipif(shutil.which("cc") is None or shutil.which("nm") is None,
                              reason="cc and nm build the small trees")


def readme(name, rank, uses, files):
    rows = "\n".join(f"| `{f}` | {f} |" for f in files)
    return (f"# native/src/{name}: layer {rank} of the core\n\nOwns: {name} things.\n\n"
            f"May use: {', '.join(uses) if uses else 'nothing of the core (the C library only)'}.\n\n"
            f"| file | owns |\n| --- | --- |\n{rows}\n")


CORE = {
    "base/README.md": readme("base", 1, [], ["maths.c", "maths.h"]),
    "base/maths.c": '#include "maths.h"\nint gc_twice(int x) { return 2 * x; }\n',
    "base/maths.h": "int gc_twice(int x);\nstatic inline int gc_inc(int x) { return x + 1; }\n",
    "world/README.md": readme("world", 2, ["base"], ["body.c", "body.h", "world_internal.h"]),
    "world/body.c": '#include "body.h"\n#include "world_internal.h"\n#include "base/maths.h"\n'
                    "int gc_body(int x) { return gc_twice(x) + gc_inc(x); }\n",
    "world/body.h": "int gc_body(int x);\n",
    "world/world_internal.h": "struct gcSecret { int x; };\n",
    "api/README.md": readme("api", 3, ["base", "world"], ["api.c"]),
    "api/api.c": '#include "world/body.h"\nint gc_api(int x) { return gc_body(x); }\n',
}


def core_tree(tmp_path, files):
    src = tmp_path / "src"
    for name, text in files.items():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        (src / name).write_text(text)
    obj = tmp_path / "obj"
    for c in src.rglob("*.c"):
        out = obj / c.relative_to(src).with_suffix(".o")
        out.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["cc", "-c", "-I", str(src), "-o", str(out), str(c)], check=True)
    doc = tmp_path / "architecture.md"
    doc.write_text(f"# Layers\n\n{check_layers.TABLE_BEGIN}\n{check_layers.TABLE_END}\n")
    assert check_layers.write_table(str(src), str(doc)) == 0
    return str(src), str(obj), str(doc)


def run_core(tmp_path, files, capsys):
    code = check_layers.check_core(*core_tree(tmp_path, files))
    return code, capsys.readouterr().out


@needs_cc
def test_core_a_clean_tree_passes(tmp_path, capsys):
    code, out = run_core(tmp_path, CORE, capsys)
    assert code == 0 and "3 layer folders, 3 files" in out, out


@needs_cc
def test_core_a_call_up_a_floor_fails(tmp_path, capsys):
    files = dict(CORE)
    files["base/maths.c"] = 'int gc_body(int x);\nint gc_twice(int x) { return 2 * gc_body(x); }\n'
    code, out = run_core(tmp_path, files, capsys)
    assert code == 1 and "base/maths.c (layer base) calls gc_body of world/body.c (layer world)" in out, out


@needs_cc
def test_core_a_static_inline_reached_up_a_floor_fails_through_its_include(tmp_path, capsys):
    files = dict(CORE)
    files["world/body.h"] = "int gc_body(int x);\nstatic inline int gc_peek(int x) { return x; }\n"
    files["base/maths.c"] = '#include "world/body.h"\nint gc_twice(int x) { return 2 * gc_peek(x); }\n'
    code, out = run_core(tmp_path, files, capsys)
    assert code == 1 and "native/src/base/maths.c:1: includes world/body.h of layer world" in out, out


@needs_cc
def test_core_a_private_header_of_another_folder_fails(tmp_path, capsys):
    files = dict(CORE)
    files["api/api.c"] = '#include "world/body.h"\n#include "world/world_internal.h"\nint gc_api(int x) { return gc_body(x); }\n'
    code, out = run_core(tmp_path, files, capsys)
    assert code == 1 and "api/api.c:2: includes world/world_internal.h, private to world/" in out, out


@needs_cc
def test_core_a_folder_not_named_in_may_use_fails_even_when_below(tmp_path, capsys):
    files = dict(CORE)
    files["api/README.md"] = readme("api", 3, ["world"], ["api.c"])
    files["api/api.c"] = '#include "base/maths.h"\nint gc_api(int x) { return gc_twice(x); }\n'
    code, out = run_core(tmp_path, files, capsys)
    assert code == 1 and "api/api.c:1: includes base/maths.h of layer base, which api/ may not use" in out, out
    assert "api/api.c (layer api) calls gc_twice of base/maths.c (layer base), which api/ may not use" in out, out


@needs_cc
def test_core_a_circle_within_a_floor_fails(tmp_path, capsys):
    files = dict(CORE)
    files["world/README.md"] = readme("world", 2, ["base"], ["body.c", "body.h", "world_internal.h", "other.c"])
    files["world/body.c"] = "int gc_other(int x);\nint gc_body(int x) { return x ? gc_other(x - 1) : 0; }\n"
    files["world/other.c"] = "int gc_body(int x);\nint gc_other(int x) { return gc_body(x); }\n"
    code, out = run_core(tmp_path, files, capsys)
    assert code == 1 and "call circle within a layer: world/body.c -> world/other.c (gc_other)" in out, out


@needs_cc
def test_core_a_file_without_its_row_and_a_stale_table_fail(tmp_path, capsys):
    src, obj, doc = core_tree(tmp_path, CORE)
    (pathlib.Path(src) / "api" / "extra.h").write_text("int gc_extra(void);\n")
    pathlib.Path(src, "base", "README.md").write_text(readme("base", 1, [], ["maths.c", "maths.h"]).replace(
        "base things", "base stuff"))
    assert check_layers.check_core(src, obj, doc) == 1
    out = capsys.readouterr().out
    assert "native/src/api/extra.h: no row in its folder's README.md" in out, out
    assert "the table of layers differs" in out, out


def test_core_the_table_in_architecture_md_is_the_folders(capsys):
    layers, problems = check_layers.read_layers(str(ROOT / "native" / "src"))
    assert problems == [], problems
    doc = (ROOT / "docs" / "architecture.md").read_text()
    assert check_layers.table(layers) in doc
    assert [n for n, _ in sorted(layers.items(), key=lambda kv: kv[1]["rank"])][:2] == ["base", "geometry"]
