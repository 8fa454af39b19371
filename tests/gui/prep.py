"""Prepare a fresh Blender user-resources folder for the GUI tests (run with ``blender -b``):
install the built extension zip ($GRASP_LAB_ZIP) and turn the first-run splash off, as a
person does once after installing."""
import os

import bpy

bpy.ops.extensions.package_install_files(filepath=os.environ["GRASP_LAB_ZIP"], repo="user_default",
                                         enable_on_install=True)
if not any(m.endswith(".grasp_lab") for m in bpy.context.preferences.addons.keys()):
    raise SystemExit("the grasp_lab extension did not enable")
bpy.context.preferences.view.show_splash = False
bpy.ops.wm.save_userpref()
print("grasp-lab-gui-prep: ok")
