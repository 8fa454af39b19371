"""The emulator playing a .blend's fingertip animation (``--from``) over a real pty."""
import os
import subprocess
import sys
import time
import tty

import grasp_env

sys.path.insert(0, grasp_env.ROOT)
from addon.engine.devices import protocol as P  # noqa: E402


def test_emulator_plays_the_fingertips_of_a_blend(bpy, sample, tmp_path):
    sample.build(bpy)
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    expected = [tuple(bpy.data.objects[f"Finger {i}"].matrix_world.translation) for i in (0, 1)]
    path = str(tmp_path / "pinch.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--from", path,
                            "--duration", "0.3"], cwd=grasp_env.ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        line = emu.stdout.readline()
        assert line.startswith("PORT "), emu.stderr.read()
        fd = os.open(line.split()[1], os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        os.write(fd, P.encode(P.HELLO_HOST, 0, P.hello_host()))
        dec, frames, end = P.StreamDecoder(), [], time.monotonic() + 10
        while time.monotonic() < end and not any(f.type == P.POSE for f in frames):
            frames += dec.feed(os.read(fd, 4096))
        hello = P.parse_hello_device([f for f in frames if f.type == P.HELLO_DEVICE][0].payload)
        assert hello.n_fingers == 2
        first = P.parse_pose([f for f in frames if f.type == P.POSE][0].payload)
        for got, want in zip(first.positions, expected):
            assert max(abs(g - w) for g, w in zip(got, want)) < 1e-3, (first.positions, expected)
        os.close(fd)
    finally:
        emu.kill()
        emu.wait()
