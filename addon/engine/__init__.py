"""bpy-free logic of Grasp Lab: scene description, decomposition, input sources and
the session runner. Importable (and tested) without Blender."""
