"""The showcase half of `make demo`: every grasp of the scene library (sample_scenes/library.py),
headless, recorded, baked, analysed, rendered and plotted, with an index page.

For each scene: build it, run the session (every haptic tick recorded to MCAP, god-objects and
force arrows in the scene), check it against its own claim (``library.measure`` /
``library.verdict``), bake the recording into the scene (keys and the grasp measures as `gl_*`
properties: the Graph Editor's curves), add the forces rendered to each fingertip as orange
arrows, save the .blend, render one frame (Workbench), and run ``grasp-lab analyze`` on the
recording (in the background, while the next scene runs). Then a contact sheet of the frames,
per scene a plot of grip force against load force over time (chapter §2.2.1) with the fingers'
states, a summary table (printed, and in the index page).

    OUT/index.html                  the page: the table, the contact sheet, the plots, the files
    OUT/contact_sheet.png           one frame per scene
    OUT/summary.txt                 the table as printed
    OUT/scenes/NAME.blend           the scene after its session, baked (opens on the rendered frame)
    OUT/scenes/NAME.png             its rendered frame
    OUT/scenes/NAME.wav             its sound (docs/sound.md), a sound strip of the .blend
    OUT/scenes/pinch_and_lift.mp4   the pinch and lift as a short video with its sound (H.264 + AAC)
    OUT/recordings/NAME.mcap        its recording (grasp-lab info / export / resim / bake)
    OUT/analysis/NAME/              grasp-lab analyze: grasp.csv, contacts.csv, summary.txt
    OUT/plots/NAME.png              grip and load force, finger states, over time

Usage: python sample_scenes/showcase.py [--out build/demo] [--only NAME ...] [--zip ZIP]
``run(bpy, out_dir, names=None)`` is importable (the extension must be enabled).
"""
from __future__ import annotations

import argparse
import csv
import html
import importlib.util
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
STATE_NAMES = ("free", "stick", "slip")
STATE_COLORS = ("#d0d0d0", "#3a9a3a", "#d23c2a")
ANALYZE_EVERY = 10                  # every 10th haptic tick: 100 Hz at 1 kHz
RENDER_SIZE = (480, 300)
SKIN = (0.86, 0.66, 0.55, 1.0)
FORCE_ARROW_FRACTION = 0.35         # the largest fingertip force: this fraction of the scene's size
VIDEO_SCENES = ("pinch_and_lift",)  # rendered whole to a video with their sound
VIDEO_SIZE = (320, 200)             # a third of a frame's cost at RENDER_SIZE (Workbench on llvmpipe)


def _load(name, filename):
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, os.path.join(HERE, filename))
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def library():
    return _load("grasp_lab_library", "library.py")


def _pinch():
    return library()._pinch_and_lift_module()


def _grasp_lab_command():
    """The `grasp-lab` launcher beside this Python (make core writes it), else the module."""
    exe = os.path.join(os.path.dirname(sys.executable), "grasp-lab")
    if os.path.exists(exe):
        return [exe]
    return [sys.executable, "-c", "import sys; sys.path.insert(0, %r); from addon.launcher import launch; "
            "sys.exit(launch())" % ROOT]


def render_frame(sc, m) -> int:
    """The frame that shows the grasp: mid first hold (or the first of the phase the scene
    shows); for a slide, just after it starts."""
    lib = library()
    if isinstance(sc.claim, lib.Slides) and "onset_frame" in m:
        return min(m["onset_frame"] + 4, sc.frame_end)
    hold = sc.frames_of(sc.shown)
    return hold[len(hold) // 2] if hold else (sc.keys[0].frame + sc.frame_end) // 2


def _render_setup(bpy, sc):
    """Workbench, studio light, materials: bodies a warm grey, static ones wood-coloured, palms
    and finger pads skin."""
    pinch = _pinch()
    scene = bpy.context.scene
    for b in sc.bodies:
        obj = bpy.data.objects[b.name]
        colour = (0.78, 0.66, 0.50, 1.0) if b.static else (0.93, 0.90, 0.80, 1.0)
        obj.data.materials.append(pinch._material(bpy, "Static" if b.static else "Body", colour))
    for f in sc.fingers:            # palms and finger pads (convex fingers) render, skin-coloured
        if f.shape is not None:
            bpy.data.objects[f.name].data.materials.append(pinch._material(bpy, "Hand", SKIN))
    if sc.hand is not None:         # the hand: its rendered (god-pose) skinned mesh renders, not the input's
        arm = bpy.data.objects[library().hand_armature_name(sc)]
        mesh = bpy.data.objects[f"{arm.name} Mesh"]
        mesh.data.materials.append(pinch._material(bpy, "Hand", SKIN))
        mesh.hide_render = True
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.studio_light = "studio.sl"
    scene.display.shading.color_type = "MATERIAL"
    scene.display.shading.show_shadows = True
    scene.view_settings.view_transform = "Standard"
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.80, 0.84, 0.90)
    scene.render.resolution_x, scene.render.resolution_y = RENDER_SIZE
    scene.render.resolution_percentage = 100


def _session_module(bpy):
    import importlib
    for mod in bpy.context.preferences.addons.keys():
        if mod.endswith(".grasp_lab"):
            return importlib.import_module(f"{mod}.session")
    raise RuntimeError("the grasp_lab extension is not enabled")


def run_scene(bpy, name, out_dir) -> dict:
    """Build, run, check, bake, save, render one scene. Returns what it measured and wrote."""
    import numpy as np
    lib = library()
    pkg = _session_module(bpy).__package__
    bake = importlib.import_module(f"{pkg}.bake")
    recording = importlib.import_module(f"{pkg}.engine.recording")
    paths = {"blend": os.path.join(out_dir, "scenes", f"{name}.blend"),
             "png": os.path.join(out_dir, "scenes", f"{name}.png"),
             "recording": os.path.join(out_dir, "recordings", f"{name}.mcap")}
    for p in paths.values():
        os.makedirs(os.path.dirname(p), exist_ok=True)
    t = {}
    bpy.ops.wm.read_homefile(use_empty=True)
    sc = lib.build(bpy, name)
    _render_setup(bpy, sc)
    s = bpy.context.scene.grasp_lab
    s.record = True
    s.recording_folder = os.path.join(out_dir, "recordings")
    s.bake = False                  # the recording is baked below: keys and the grasp measures
    t0 = time.perf_counter()
    # (a hand's god-objects are its rendered bones: no spheres over them)
    r = lib.run(bpy, display_objects=sc.hand is None)
    t["session"] = time.perf_counter() - t0
    if sc.hand is not None:         # made by the session as a copy of the input's, hidden too
        bpy.data.objects[f"{lib.hand_armature_name(sc)} Mesh Rendered"].hide_render = False
    if os.path.exists(paths["recording"]):
        os.remove(paths["recording"])
    os.replace(s.last_recording, paths["recording"])
    s.last_recording = paths["recording"]
    m = lib.measure(sc, r)
    bad = lib.verdict(sc, m)

    # Arrows a fixed fraction of the scene's size for its largest fingertip force.
    _, radius = lib.extent(sc)
    peak = float(np.linalg.norm(r.finger_forces, axis=2).max())
    force_scale = FORCE_ARROW_FRACTION * radius / max(peak, 1e-6)
    s.force_scale = force_scale
    t0 = time.perf_counter()
    rec = recording.open_recording(paths["recording"])
    report = bake.bake_recording(bpy.context, rec, force_scale=force_scale, blend_path=paths["blend"])
    if report.sound_error:
        raise RuntimeError(f"{name}: no sound baked: {report.sound_error}")
    paths["sound"] = report.sound
    display = importlib.import_module(f"{pkg}.display")
    if sc.hand is not None and display.COLLECTION in bpy.data.collections:
        # the baked god-objects of a hand's bones are where its rendered mesh is: the mesh renders
        bpy.data.collections[display.COLLECTION].hide_render = True
    if sc.hand is None:             # (a hand's are its rendered bones: no arrows over them)
        # from the god-object sphere's surface, so that a small force is not hidden inside it
        radii = np.array([f.radius for f in sc.fingers])[None, :, None]
        norms = np.linalg.norm(r.finger_forces, axis=2, keepdims=True)
        tails = r.god_objects + radii * r.finger_forces / np.maximum(norms, 1e-12)
        _pinch().add_finger_force_arrows(bpy, r.frames, tails, r.finger_forces, force_scale)
    t["bake"] = time.perf_counter() - t0

    frame = render_frame(sc, m)
    bpy.context.scene.frame_set(frame)
    if os.path.exists(paths["blend"]):
        os.remove(paths["blend"])
    bpy.ops.wm.save_as_mainfile(filepath=paths["blend"], compress=True)
    t0 = time.perf_counter()
    _pinch().render(bpy, paths["png"])
    video_frames = 0
    if name in VIDEO_SCENES:
        paths["video"] = os.path.join(out_dir, "scenes", f"{name}.mp4")
        video_frames = render_video(bpy, paths["video"])
        bpy.context.scene.frame_set(frame)
    t["render"] = time.perf_counter() - t0
    return {"name": name, "scene": sc, "result": r, "measured": m, "failures": bad, "paths": paths,
            "frame": frame, "force_scale": force_scale, "keys": report.keys, "timings": t,
            "ticks": len(rec.ticks), "stats": r.stats, "video_frames": video_frames}


def render_video(bpy, path):
    """The scene's whole frame range (Workbench) to an MP4, H.264 with the sequencer's sound (the
    baked WAV) as AAC: what a browser plays. Returns the frames rendered."""
    scene = bpy.context.scene
    r = scene.render
    settings = (r.filepath, r.image_settings.file_format, r.resolution_x, r.resolution_y)
    r.resolution_x, r.resolution_y = VIDEO_SIZE
    r.image_settings.file_format = "FFMPEG"
    r.ffmpeg.format = "MPEG4"
    r.ffmpeg.codec = "H264"
    r.ffmpeg.constant_rate_factor = "MEDIUM"
    r.ffmpeg.audio_codec = "AAC"
    r.ffmpeg.audio_channels = "MONO"
    r.ffmpeg.audio_mixrate = 48000
    r.ffmpeg.audio_bitrate = 128
    r.filepath = os.path.abspath(path)
    if os.path.exists(path):
        os.remove(path)
    bpy.ops.render.render(animation=True)
    r.filepath, r.image_settings.file_format, r.resolution_x, r.resolution_y = settings
    if not os.path.exists(path):
        raise RuntimeError(f"{path}: the video was not written")
    return scene.frame_end - scene.frame_start + 1


def _read_grasp_csv(path, body):
    import numpy as np
    with open(path) as fh:
        rows = [row for row in csv.DictReader(fh) if row["body"] == body]
    col = lambda k: np.array([float(row[k]) for row in rows])      # noqa: E731
    if not rows:
        return {k: np.zeros(0) for k in ("time", "force_closure", "epsilon", "grip_force", "load_force")}
    return {k: col(k) for k in ("time", "force_closure", "epsilon", "grip_force", "load_force")}


def moved_in_fingers(m):
    """What the claim measures as the body's motion in the fingers (m): moved, dropped, swung."""
    return m.get("slip", m.get("drop", m.get("swing", 0.0)))


def largest_slip(r, body) -> float:
    """How far a god-object slid over the body's surface (m): per finger, while it touches the
    body, its point in the body's frame against where it first touched; the largest."""
    import numpy as np
    i = r.body(body)
    n_f = r.god_objects.shape[1]
    pts = library()._in_frame(np.repeat(r.poses[:, i], n_f, axis=0),
                              r.god_objects.reshape(-1, 3)).reshape(r.god_objects.shape)
    out = 0.0
    for f in range(n_f):
        on = np.nonzero(r.contacts[:, f] == i)[0]
        if len(on):
            out = max(out, float(np.linalg.norm(pts[on, f] - pts[on[0], f], axis=1).max()))
    return out


def outcome(sc, m, bad):
    lib = library()
    if isinstance(sc.claim, lib.Slides):
        word = "slides out"
    elif isinstance(sc.claim, lib.Hangs):
        word = "hangs"
    else:
        word = "held"
    return word if not bad else f"FAILS ({word} claimed)"


def plot_scene(entry, grasp, path):
    """Grip and load force on the held body over time (§2.2.1: the grip tracks the load), and
    each finger's state (free, stick, slip)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import ListedColormap
    sc, r = entry["scene"], entry["result"]
    fps = library().FPS
    t_frames = (r.frames - r.frames[0]) / fps
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(6.4, 3.6), sharex=True,
                                  gridspec_kw={"height_ratios": [3, 1.1]}, constrained_layout=True)
    ax.plot(grasp["time"], grasp["grip_force"], color="#1f6fb4", lw=1.4, label="grip force (Σ normal)")
    ax.plot(grasp["time"], grasp["load_force"], color="#e07b00", lw=1.4, label="load force m|a − g|")
    ax.set_ylabel("N")
    ax.set_title(f"{sc.name}: {sc.claim.body}", fontsize=10, loc="left")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    ax.set_xlim(0, t_frames[-1])
    states = np.asarray(r.states).T                  # (fingers, frames)
    ax2.imshow(states, aspect="auto", interpolation="nearest", cmap=ListedColormap(STATE_COLORS),
               vmin=0, vmax=2, extent=(t_frames[0], t_frames[-1] + 1 / fps, len(r.finger_names) - 0.5, -0.5))
    ax2.set_yticks(range(len(r.finger_names)))
    ax2.set_yticklabels(r.finger_names, fontsize=6)
    ax2.set_xlabel("time [s]")
    for c, n in zip(STATE_COLORS, STATE_NAMES):
        ax2.plot([], [], "s", color=c, label=n)
    ax2.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.0, 1.05), frameon=False)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def contact_sheet(entries, path, columns=4):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = (len(entries) + columns - 1) // columns
    w, h = RENDER_SIZE
    fig, axes = plt.subplots(rows, columns, figsize=(columns * w / 100, rows * (h + 36) / 100), dpi=100,
                             squeeze=False)
    fig.subplots_adjust(left=0.005, right=0.995, bottom=0.005, top=0.97, wspace=0.02, hspace=0.12)
    for ax in axes.flat:
        ax.axis("off")
    for ax, e in zip(axes.flat, entries):
        ax.imshow(plt.imread(e["paths"]["png"]))
        ax.set_title(f"{e['name']}: {e['outcome']} (frame {e['frame']})", fontsize=9)
    fig.savefig(path)
    plt.close(fig)


COLUMNS = ("scene", "outcome", "moved in fingers", "largest slip", "force closure", "epsilon", "grip / load", "haptic rate",
           "steps/s achieved", "speed")


def table_rows(entries):
    out = []
    for e in entries:
        g = e["grasp"]
        held = len(g["time"])
        closure = f"{100 * g['force_closure'].mean():.0f} % of held" if held else "never held"
        eps = g["epsilon"][g["force_closure"] > 0]
        if len(eps) == 0:
            epsilon = "0"
        elif f"{eps.min():.3g}" == f"{_median(eps):.3g}":
            epsilon = f"{eps.min():.3g}"
        else:
            epsilon = f"{eps.min():.3g} (median {_median(eps):.3g})"
        loaded = g["load_force"] > 1e-9
        ratio = g["grip_force"][loaded] / g["load_force"][loaded] if loaded.any() else None
        grip_load = f"{float(_median(ratio)):.1f}" if ratio is not None and len(ratio) else "–"
        st = e["stats"]
        out.append((e["name"], e["outcome"], f"{moved_in_fingers(e['measured']) * 1e3:.2f} mm",
                    f"{largest_slip(e['result'], e['scene'].claim.body) * 1e3:.2f} mm", closure,
                    epsilon, grip_load, f"{st['haptic_rate_target']:.0f} Hz", f"{st['haptic_rate']:.0f}",
                    f"{st['time'] / e['timings']['session']:.0f}× real time"))
    return out


def _median(v):
    import numpy as np
    return np.median(v)


def write_index(out_dir, entries, rows, wall):
    e = html.escape
    rel = lambda p: os.path.relpath(p, out_dir)      # noqa: E731
    parts = ["<!doctype html><meta charset='utf-8'><title>Grasp Lab: make demo</title>",
             "<style>body{font-family:sans-serif;max-width:1400px;margin:1em auto;padding:0 1em}"
             "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}"
             "img{max-width:100%}.fail{color:#b00}</style>",
             "<h1>Grasp Lab: the chapter's grasps</h1>",
             f"<p>{len(entries)} scenes of <code>sample_scenes/library.py</code>, run headless in Blender through "
             f"the extension, recorded at every haptic tick, baked, analysed (<code>grasp-lab analyze --every "
             f"{ANALYZE_EVERY}</code>) and rendered, in {wall:.0f} s. God-objects are the spheres on the "
             "surfaces, where the fingertips touch, in the frame's friction-use colour (green far from slipping, "
             "yellow half way, red sliding, blue touching nothing); palms and finger pads (area contacts) are "
             "skin-coloured; the orange arrows are the forces rendered to each fingertip (drawn from the sphere's "
             "surface).</p>",
             f"<p><img src='contact_sheet.png' alt='one frame per scene'></p>",
             "<h2>Summary</h2><table><tr>" + "".join(f"<th>{e(c)}</th>" for c in COLUMNS) + "</tr>"]
    for row, ent in zip(rows, entries):
        cls = " class='fail'" if ent["failures"] else ""
        parts.append(f"<tr{cls}>" + "".join(f"<td>{e(str(v))}</td>" for v in row) + "</tr>")
    parts.append("</table><p><i>moved in fingers</i>: the body's largest motion relative to the fingertips from "
                 "the moment the grasp closes (the finger springs' give included; for the slide, how far it "
                 "dropped; for the hook, its swing). <i>largest slip</i>: the farthest a god-object slid over "
                 "the body's surface while touching it. <i>force closure</i>: the share of analysed ticks, while a "
                 "finger holds the body, in which the contacts resist any wrench (two point contacts never do: "
                 "nothing resists turning about the line through them). <i>epsilon</i>: Ferrari–Canny, the smallest "
                 "while in closure (and the median, where it differs). <i>grip / load</i>: median grip force over load force while held. "
                 "<i>haptic rate</i>: the rate simulated; <i>steps/s achieved</i>: core steps per second of wall time, the "
                 "session's own overhead included (a live session needs the haptic rate); <i>speed</i>: simulated "
                 "time over wall time. "
                 "See docs/analysis.md and docs/scenes.md.</p>")
    parts.append("<h2>Scenes</h2>")
    for ent in entries:
        sc = ent["scene"]
        p = ent["paths"]
        bad = ("<p class='fail'>" + e("; ".join(ent["failures"])) + "</p>") if ent["failures"] else ""
        parts.append(f"<h3 id='{ent['name']}'>{e(ent['name'])}</h3><p>{e(sc.description)}</p>{bad}"
                     f"<p><img src='{rel(p['png'])}' alt='{e(ent['name'])}, frame {ent['frame']}'> "
                     f"<img src='{rel(p['plot'])}' alt='grip and load, finger states'></p>"
                     f"<p>Files: <a href='{rel(p['blend'])}'>{e(os.path.basename(p['blend']))}</a> (baked, "
                     f"{ent['keys']} keys; force arrows {ent['force_scale'] * 1e3:.1f} mm per N), "
                     f"<a href='{rel(p['recording'])}'>{e(os.path.basename(p['recording']))}</a> "
                     f"({ent['ticks']} haptic ticks), its sound "
                     f"<a href='{rel(p['sound'])}'>{e(os.path.basename(p['sound']))}</a>"
                     + (f", the video with sound <a href='{rel(p['video'])}'>{e(os.path.basename(p['video']))}</a>"
                        if "video" in p else "") + ", analysis: "
                     f"<a href='{rel(p['analysis'])}/grasp.csv'>grasp.csv</a>, "
                     f"<a href='{rel(p['analysis'])}/contacts.csv'>contacts.csv</a>, "
                     f"<a href='{rel(p['analysis'])}/summary.txt'>summary</a>.</p>"
                     f"<pre>{e(ent['analysis_summary'])}</pre>")
        if "video" in p:
            parts.append(f"<p><video controls src='{rel(p['video'])}' width='{2 * VIDEO_SIZE[0]}'></video><br>"
                         "With its sound (docs/sound.md): a click as each fingertip touches, a tone rising with "
                         "the squeeze, a scrape while a finger slips, a beep while the box is close to slipping."
                         "</p>")
    extra = [f for f in ("pinch_and_lift.blend", "pinch_and_lift.mcap", "pinch_and_lift_box.csv",
                         "pinch_and_lift_frame43.png") if os.path.exists(os.path.join(out_dir, f))]
    if extra:
        parts.append("<h2>The pinch and lift, in detail</h2><p>" + ", ".join(
            f"<a href='{f}'>{f}</a>" for f in extra) + "</p>")
    with open(os.path.join(out_dir, "index.html"), "w") as fh:
        fh.write("\n".join(parts))


def run(bpy, out_dir, names=None, stream=sys.stdout) -> dict:
    """Every scene (or ``names``): run, check, bake, render, analyse; then plots, the contact
    sheet, the table and the index page. Returns the entries and the table."""
    lib = library()
    out_dir = os.path.abspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    names = list(names or lib.all_scenes())
    p = lambda *a: print(*a, file=stream, flush=True)       # noqa: E731
    t_all = time.perf_counter()
    entries, jobs = [], []
    for k, name in enumerate(names, 1):
        e = run_scene(bpy, name, out_dir)
        e["outcome"] = outcome(e["scene"], e["measured"], e["failures"])
        tm = e["timings"]
        p(f"[{k}/{len(names)}] {name}: {e['outcome']}; {e['stats']['time']:.2f} s simulated in "
          f"{tm['session']:.2f} s, baked in {tm['bake']:.2f} s, rendered in {tm['render']:.2f} s")
        adir = os.path.join(out_dir, "analysis", name)
        if os.path.isdir(adir):
            shutil.rmtree(adir)
        os.makedirs(adir)
        e["paths"]["analysis"] = adir
        log = open(os.path.join(adir, "summary.txt"), "w")
        jobs.append((e, log, subprocess.Popen(
            _grasp_lab_command() + ["analyze", e["paths"]["recording"], "--csv", adir, "--every", str(ANALYZE_EVERY)],
            stdout=log, stderr=subprocess.STDOUT)))
        entries.append(e)
    p(f"analysing the recordings (grasp-lab analyze --every {ANALYZE_EVERY}) ...")
    for e, log, proc in jobs:
        proc.wait()
        log.close()
        with open(os.path.join(e["paths"]["analysis"], "summary.txt")) as fh:
            e["analysis_summary"] = fh.read()
        if proc.returncode != 0:
            raise RuntimeError(f"grasp-lab analyze failed on {e['paths']['recording']}: {e['analysis_summary']}")
        e["grasp"] = _read_grasp_csv(os.path.join(e["paths"]["analysis"], "grasp.csv"), e["scene"].claim.body)
        e["paths"]["plot"] = os.path.join(out_dir, "plots", f"{e['name']}.png")
        os.makedirs(os.path.dirname(e["paths"]["plot"]), exist_ok=True)
        plot_scene(e, e["grasp"], e["paths"]["plot"])
    contact_sheet(entries, os.path.join(out_dir, "contact_sheet.png"))
    rows = table_rows(entries)
    widths = [max(len(str(r[i])) for r in rows + [COLUMNS]) for i in range(len(COLUMNS))]
    lines = ["  ".join(str(v).ljust(w) for v, w in zip(row, widths)) for row in [COLUMNS] + rows]
    wall = time.perf_counter() - t_all
    with open(os.path.join(out_dir, "summary.txt"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    write_index(out_dir, entries, rows, wall)
    p("\n".join(lines))
    p(f"{len(entries)} scenes in {wall:.1f} s; open {os.path.join(os.path.relpath(out_dir), 'index.html')}")
    return {"entries": entries, "rows": rows, "wall": wall}


def main(argv=None):
    lib = library()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "demo"), help="where the outputs go")
    ap.add_argument("--only", nargs="+", choices=sorted(lib.all_scenes()), help="these scenes only")
    ap.add_argument("--zip", help="install the extension from this built zip (default: $GRASP_LAB_ZIP, "
                                  "else a development repository of addon/)")
    args = ap.parse_args(argv)
    sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
    import grasp_env                 # isolates Blender's user resources, then loads the add-on
    grasp_env.isolate()
    import bpy
    grasp_env.enable(args.zip)
    res = run(bpy, args.out, args.only)
    return 1 if any(e["failures"] for e in res["entries"]) else 0


if __name__ == "__main__":
    sys.exit(main())
