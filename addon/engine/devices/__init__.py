"""Haptic devices, bpy-free: the Grasp Lab serial protocol (docs/protocol.md), its
reference emulator, and the SpaceMouse and OpenGloves decoders. Importable (and
tested) in plain Python; the 1 kHz serial I/O itself runs in the C core."""
