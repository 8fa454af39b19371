"""Load the Grasp Lab extension into the ``bpy`` module, isolated from the user's
Blender configuration. Shared by the tests, the sample-scene builders and the bench.

``BLENDER_USER_RESOURCES`` must point at a private directory before ``import bpy``:
call ``isolate()`` first. Then ``enable()`` installs the built zip (``GRASP_LAB_ZIP``
or the ``zip_path`` argument) into the ``user_default`` repository, or, without a zip,
registers a development repository whose ``grasp_lab`` package links to ``addon/``.
"""
from __future__ import annotations

import os
import re
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DEV_REPO = "grasp_dev"
_state = {}


def isolate():
    if "bpy" in sys.modules and "GRASP_LAB_ISOLATED" not in os.environ:
        raise RuntimeError("bpy was imported before BLENDER_USER_RESOURCES was set")
    if "GRASP_LAB_ISOLATED" not in os.environ:
        tmp = tempfile.mkdtemp(prefix="grasp_lab_blender_")
        os.environ["BLENDER_USER_RESOURCES"] = tmp
        os.environ["GRASP_LAB_ISOLATED"] = tmp
    return os.environ["GRASP_LAB_ISOLATED"]


def _stage_dev_repo(root_tmp):
    repo_dir = os.path.join(root_tmp, "dev_repo")
    pkg = os.path.join(repo_dir, "grasp_lab")
    os.makedirs(pkg, exist_ok=True)
    src = os.path.join(ROOT, "addon")
    for name in os.listdir(src):
        if name != "__pycache__" and not os.path.exists(os.path.join(pkg, name)):
            os.symlink(os.path.join(src, name), os.path.join(pkg, name))
    with open(os.path.join(ROOT, "blender_manifest.toml")) as fh:
        manifest = fh.read()
    # Dev repository: no bundled wheels (the venv provides trimesh & co).
    manifest = re.sub(r"(?ms)^wheels = \[.*?^\]\n", "", manifest)
    with open(os.path.join(pkg, "blender_manifest.toml"), "w") as fh:
        fh.write(manifest)
    return repo_dir


def enable(zip_path=None):
    """Install/enable the extension; returns its module name (``bl_ext.<repo>.grasp_lab``)."""
    if "module" in _state:
        return _state["module"]
    root_tmp = isolate()
    import bpy
    import addon_utils
    zip_path = zip_path or os.environ.get("GRASP_LAB_ZIP")
    if zip_path:
        zip_path = os.path.abspath(zip_path)
        if not os.path.exists(zip_path):
            raise FileNotFoundError(zip_path)
        repos = bpy.context.preferences.extensions.repos
        if "user_default" not in {r.module for r in repos}:
            raise RuntimeError("no user_default extension repository")
        res = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                                       enable_on_install=True)
        if res != {"FINISHED"}:
            raise RuntimeError(f"package_install_files: {res}")
        module = "bl_ext.user_default.grasp_lab"
    else:
        repo_dir = _stage_dev_repo(root_tmp)
        repos = bpy.context.preferences.extensions.repos
        if DEV_REPO not in {r.module for r in repos}:
            repos.new(name="Grasp Lab dev", module=DEV_REPO, custom_directory=repo_dir,
                      source="USER")
        module = f"bl_ext.{DEV_REPO}.grasp_lab"
    addon_utils.enable(module, default_set=True, handle_error=_raise)
    if module not in bpy.context.preferences.addons:
        raise RuntimeError(f"{module} did not enable")
    _state["module"] = module
    _state["source"] = "zip" if zip_path else "dev"
    return module


def _raise(ex):
    raise ex


def source():
    return _state.get("source")


def submodule(name):
    import importlib
    return importlib.import_module(f"{_state['module']}.{name}")


def graspcore():
    """The core the extension uses (vendored in the zip, or the venv's)."""
    return submodule("engine.core_loader").load()


def add_cube(bpy, name, size=1.0, location=(0, 0, 0)):
    """A cube mesh object of edge ``size`` linked to the current scene."""
    import bmesh
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    bm.to_mesh(me)
    bm.free()
    obj = bpy.data.objects.new(name, me)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj
