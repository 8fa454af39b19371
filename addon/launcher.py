"""``grasp-lab`` outside Blender (the launcher ``make`` writes into the venv calls ``launch()``):
the command line of engine/cli.py, where the commands that need Blender (run, bake) first load
this extension into the ``bpy`` module and are handed to the extension's own copy of the
command line. The other commands run here, without bpy."""
from __future__ import annotations

import os
import signal
import sys

from .engine import cli

ADDON_DIR = os.path.dirname(os.path.abspath(__file__))
DEV_REPO = "grasp_cli"


def boot_extension() -> str:
    """Load the extension into the ``bpy`` module (isolated user resources): the zip in
    $GRASP_LAB_ZIP, else this checkout's addon/ as a development repository. Returns the
    extension's module name."""
    import atexit
    import re
    import shutil
    import tempfile
    if "bpy" not in sys.modules:
        # Always a private folder, even when BLENDER_USER_RESOURCES is set: installing the zip
        # takes the repository's lock, and a command killed while holding it (kill -9) would
        # leave every later command sharing that folder refused ("lock exists").
        tmp = tempfile.mkdtemp(prefix="grasp_lab_cli_")
        os.environ["BLENDER_USER_RESOURCES"] = tmp
        atexit.register(shutil.rmtree, tmp, True)
    import bpy
    import addon_utils      # Blender's, importable once bpy is
    for name in bpy.context.preferences.addons.keys():
        if name.startswith("bl_ext.") and name.endswith(".grasp_lab"):
            return name
    zip_path = os.environ.get("GRASP_LAB_ZIP")
    if zip_path:
        res = bpy.ops.extensions.package_install_files(filepath=os.path.abspath(zip_path),
                                                       repo="user_default", enable_on_install=True)
        if res != {"FINISHED"}:
            raise RuntimeError(f"{zip_path}: could not install the extension ({res})")
        return "bl_ext.user_default.grasp_lab"
    manifest = os.path.join(os.path.dirname(ADDON_DIR), "blender_manifest.toml")
    if not os.path.exists(manifest):
        raise RuntimeError(f"no extension to load: set GRASP_LAB_ZIP or run from a checkout ({manifest} missing)")
    repo_dir = tempfile.mkdtemp(prefix="grasp_lab_cli_repo_")
    atexit.register(shutil.rmtree, repo_dir, True)
    pkg = os.path.join(repo_dir, "grasp_lab")
    os.makedirs(pkg)
    for name in os.listdir(ADDON_DIR):
        if name != "__pycache__":
            os.symlink(os.path.join(ADDON_DIR, name), os.path.join(pkg, name))
    with open(manifest) as fh:       # the venv provides the wheels
        text = re.sub(r"(?ms)^wheels = \[.*?^\]\n", "", fh.read())
    with open(os.path.join(pkg, "blender_manifest.toml"), "w") as fh:
        fh.write(text)
    bpy.context.preferences.extensions.repos.new(name="Grasp Lab CLI", module=DEV_REPO,
                                                 custom_directory=repo_dir, source="USER")
    module = f"bl_ext.{DEV_REPO}.grasp_lab"

    def fail(ex):
        raise ex
    addon_utils.enable(module, default_set=True, handle_error=fail)
    return module


def extension_main():
    """The extension's own ``engine.cli.main``, the extension loaded first (``boot_extension``)."""
    import importlib
    return importlib.import_module(f"{boot_extension()}.engine.cli").main


def main(argv=None, prog=cli.PROG, out=None, err=None) -> int:
    """The command line outside Blender: commands that need Blender load the extension first."""
    cli.load_extension = extension_main
    return cli.main(argv, prog, out, err)


def _stop_outside_a_command(signum, frame):
    """A stop signal before a command has begun (its arguments read) or after it ended: one
    line and the signal's exit code through ``sys.exit`` (the temporary folders removed)."""
    name = cli.SIGNAL_NAMES.get(signum, f"signal {signum}")
    cli._say(sys.stderr, f"{cli.PROG}: stopped by {name} outside a command; nothing was written")
    sys.exit(128 + signum)


def launch() -> int:
    """``grasp-lab`` in the venv. The launcher script holds the stop signals from its first
    line (imports included); from here they are handled, a held one at once."""
    for sig in cli.STOP_SIGNALS:
        signal.signal(sig, _stop_outside_a_command)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, cli.STOP_SIGNALS)
    return main(sys.argv[1:])
