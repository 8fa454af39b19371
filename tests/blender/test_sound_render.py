"""The baked sound in Blender (addon/bake.py, docs/sound.md): a bake writes the recording's sound as
a WAV and puts it in the sequencer as a sound strip at the session's first frame (again: replaced,
not doubled); a headless render to video (bpy's FFmpeg output, QuickTime with 16-bit PCM audio)
carries an audio stream of the rendered range's length whose samples are the WAV's at those
frames. The container is read here (its atoms), so no ffprobe is needed."""
import os

import numpy as np
import pytest

import grasp_env
import media

FPS = 24
RATE = 48000


@pytest.fixture()
def baked(bpy, sample, core, tmp_path):
    """The sample scene's 1.5 s session recorded, then baked into a fresh copy of the scene."""
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record, s.recording_folder, s.duration = True, str(tmp_path), 1.5
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    path = s.last_recording
    bpy.ops.wm.read_homefile(use_empty=True)
    sample.build(bpy)
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}
    return path


def _strips(scene):
    editor = scene.sequence_editor
    return list(editor.strips_all if hasattr(editor, "strips_all") else editor.sequences_all)


def test_a_bake_writes_the_sound_and_puts_it_in_the_sequencer_once(bpy, baked, tmp_path):
    sound = grasp_env.submodule("engine.sound")
    scene = bpy.context.scene
    wav = os.path.splitext(baked)[0] + ".wav"           # the .blend is not saved: beside the recording
    samples, rate = sound.read_wav(open(wav, "rb").read())
    assert rate == RATE and len(samples) == pytest.approx(1.5 * RATE, abs=2) and np.abs(samples).max() > 0.05
    strips = _strips(scene)
    assert [(st.name, st.type, int(st.frame_start)) for st in strips] == [("Grasp Lab Sound", "SOUND", 1)]
    assert os.path.samefile(bpy.path.abspath(strips[0].sound.filepath), wav)
    # Baked again: one strip still. Saved: the strip's path is relative to the .blend.
    assert bpy.ops.grasp_lab.import_recording(filepath=baked) == {"FINISHED"}
    assert len(_strips(scene)) == 1
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "baked.blend"))
    assert _strips(scene)[0].sound.filepath.startswith("//")


def test_a_headless_render_to_video_carries_the_sound_of_its_frames(bpy, baked, tmp_path):
    sound = grasp_env.submodule("engine.sound")
    wav, _ = sound.read_wav(open(os.path.splitext(baked)[0] + ".wav", "rb").read())
    scene = bpy.context.scene
    r = scene.render
    r.engine = "BLENDER_WORKBENCH"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 64, 48, 100
    first, last = 13, 30            # session time 0.5 s to 1.25 s: the strip is placed at frame 1
    scene.frame_start, scene.frame_end = first, last
    r.image_settings.file_format = "FFMPEG"
    r.ffmpeg.format = "QUICKTIME"
    r.ffmpeg.codec = "H264"
    r.ffmpeg.audio_codec = "PCM"
    r.ffmpeg.audio_channels = "MONO"
    r.ffmpeg.audio_mixrate = RATE
    r.filepath = str(tmp_path / "pinch.mov")
    bpy.ops.render.render(animation=True)
    track = media.sound_track(open(tmp_path / "pinch.mov", "rb").read())
    rate, duration, codec, pcm = track["rate"], track["duration"], track["codec"], track["pcm"]
    frames = last - first + 1
    expected = frames * RATE // FPS
    assert (rate, codec) == (RATE, b"sowt")
    # The stream covers the rendered frames (Blender writes whole blocks of 8192 samples).
    assert duration == len(pcm) and expected <= duration < expected + 8192
    # ... with the WAV's samples at those frames (16 bits in, 16 bits out: exact, give or take one
    # step), within two samples (Blender rounds the frame's time to its own sample).
    start = (first - 1) * RATE // FPS
    wav16 = np.round(wav * 32767.0)
    assert np.abs(wav16[start:start + expected]).max() > 1000
    got = pcm[4:expected - 4].astype(np.float64)
    error = {lag: np.abs(got - wav16[start + 4 + lag:start + expected - 4 + lag]).max() for lag in range(-2, 3)}
    assert min(error.values()) <= 1, error


def test_grasp_lab_bake_writes_the_sound_beside_the_saved_blend(bpy, baked, tmp_path):
    import io
    cli = grasp_env.submodule("engine.cli")
    scene_blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene_blend))
    (tmp_path / "out").mkdir()
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(["bake", baked, str(scene_blend), "--save", str(tmp_path / "out" / "after.blend")],
                    out=out, err=err)
    assert code == 0, err.getvalue()
    wav = tmp_path / "out" / (os.path.splitext(os.path.basename(baked))[0] + ".wav")
    assert wav.is_file() and "a sound strip in the sequencer" in out.getvalue()
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "out" / "after.blend"))
    strips = _strips(bpy.context.scene)
    assert [st.sound.filepath for st in strips] == [f"//{wav.name}"]
