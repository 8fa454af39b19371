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
