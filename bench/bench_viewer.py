"""Viewer channel benchmarks (docs/viewers.md); prints a Markdown section (docs/benchmarks.md,
"Viewer channels").

Whether every recording can carry the Foxglove channels, or a copy is written afterwards
(``grasp-lab export --foxglove``): what one display update's channels cost to build and
write (numbers of the frame, SceneUpdate, FrameTransforms, plot channels, into an MCAP
file through foxglove-sdk), beside what the recorder itself does for the same display
period in the same run (write the period's tick records and derive its events), for the
sample scene (2 bodies + 2 fingers, a real EXEC recording) and 20 bodies + 10 fingers
(synthetic motion, every finger pressing). Then the export's speed and the copy's size per
second of session beside the recording's.

Live view: snapshots of the same sessions offered at 30 Hz (as display updates offer them)
to a LiveView watched by one WebSocket client on localhost: what ``offer`` costs the display
update, what the live view's thread spends per update, and the delay from the display
update to the client receiving the scene.

Usage: .venv/bin/python bench/bench_viewer.py [--seconds 20]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, ROOT)


DISPLAY_UPDATE_MS = 2.52     # main-thread time of a display update, 20 bodies + 10 fingers (bench_gui.py)


def pressing(rec):
    """Every finger on a body, pushing (synthetic sessions have free fingers): arrows and
    plot numbers as in a grasp."""
    t = rec.ticks
    nb = len(rec.body_names)
    t["contact"][:] = np.arange(t["contact"].shape[1]) % nb
    t["state"][:] = 1
    t["normal"][:, :, 2] = 1.0
    t["force"][:, :, 0] = 0.3
    t["force"][:, :, 2] = 2.0
    t["god_object"][:, :, 2] += 0.002


def per_frame_costs(rec, tmp, repeats=3):
    """µs per display update: the viewer channels (frame numbers + messages + MCAP write) and
    the recorder's work for the same period (tick records written, events derived), one
    after the other for each display update, so load on the machine weighs on both alike."""
    import foxglove
    from foxglove.mcap import MCAPWriteOptions

    from addon.engine import recording, viewer
    model = viewer.SceneModel(rec.header)
    rate = model.display_rate
    per = int(round(rec.haptic_rate / rate))
    times = np.arange(0, (len(rec.ticks) - 1) // per) / rate
    idx = rec.sample(times)
    viewer_us, rec_us = [], []
    for r in range(repeats):
        ctx = foxglove.Context()
        writer = recording.RecordingWriter(os.path.join(tmp, f"r{r}.mcap"), rec.header, compression="lz4")
        events = recording.EventDetector(rec.header)
        with open(os.path.join(tmp, f"v{r}.mcap"), "wb") as fh:
            w = foxglove.open_mcap(fh, context=ctx, writer_options=MCAPWriteOptions(profile=""))
            ch = viewer.FoxgloveChannels(model, ctx)
            for k, i in enumerate(idx):
                block = rec.ticks[k * per:(k + 1) * per]
                t0 = time.perf_counter()
                writer.write_ticks(block)
                for tick, t, kind, subject, detail in events(block):
                    writer.event(t, kind, subject, detail, tick=tick)
                t1 = time.perf_counter()
                fr = viewer.frames_of(model, rec, rec.ticks[i:i + 1], times[k:k + 1])[0]
                ch.log_frame(fr)
                t2 = time.perf_counter()
                rec_us.append((t1 - t0) * 1e6)
                viewer_us.append((t2 - t1) * 1e6)
            w.close()
        writer.close()
    return viewer_us, rec_us, rate


def live_costs(rec, seconds=6.0, rate=30.0, analysed=True):
    """offer() µs, live thread µs per update, delay ms (display update -> client has the
    scene), updates received / offered. ``analysed=False``: snapshots offered without their
    grasp analysis (its channels and arrows left out)."""
    import json
    import struct

    from websockets.sync.client import connect

    from addon.engine import analysis
    from addon.engine.live_view import LiveView
    from addon.engine.runner import Snapshot
    lv = LiveView(rec.header, port=0)
    ws = connect(lv.address, subprotocols=["foxglove.sdk.v1"])
    json.loads(ws.recv(timeout=5))
    channels = {}
    while len(channels) < 4 + len(rec.body_names) + len(rec.finger_names):
        msg = json.loads(ws.recv(timeout=5))
        if msg["op"] == "advertise":
            channels.update({c["id"]: c["topic"] for c in msg["channels"]})
    scene = [cid for cid, topic in channels.items() if topic == "/grasp_lab/scene"][0]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": c, "channelId": c} for c in channels]}))
    time.sleep(0.3)
    delays, offers, received = [], [], [0]
    stop = [False]

    def listen():
        while not stop[0]:
            try:
                m = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(m, bytes):
                _, sub, log_time = struct.unpack_from("<BIQ", m)
                if sub == scene:
                    delays.append((time.time() - log_time / 1e9) * 1e3)
                    received[0] += 1
    import threading
    th = threading.Thread(target=listen)
    th.start()
    n = int(seconds * rate)
    step = max(1, int(len(rec.ticks) / n))
    # The display update's grasp analysis, handed over with its snapshot as the session does
    # (made here beforehand: the live view does not pay for it).
    models = analysis.body_models(rec.header["scene"])
    radii = [f["radius"] for f in rec.header["scene"]["fingers"]]
    snaps = []
    for k in range(n):
        t = rec.ticks[(k * step) % len(rec.ticks)]
        snap = Snapshot(float(t["time"]), t["pose"], t["pose"][:, :3], t["wrench"][:, :3], t["wrench"][:, 3:],
                        t["hip"], t["god_object"], t["force"], t["state"], t["contact"], t["force"], t["normal"],
                        t["velocity"])
        snaps.append((snap, analysis.analyse(models, snap.poses, snap.god_objects, snap.spring_forces, snap.normals,
                                             snap.finger_states, snap.contacts, radii, volume=False)
                      if analysed else None))
    t0 = time.perf_counter()
    for k, (snap, grasps) in enumerate(snaps):
        a = time.perf_counter()
        lv.offer(snap, grasps)
        offers.append((time.perf_counter() - a) * 1e6)
        time.sleep(max(0.0, t0 + (k + 1) / rate - time.perf_counter()))
    time.sleep(0.5)
    stop[0] = True
    th.join()
    ws.close()
    cost = list(lv.cost_us)
    lv.close()
    return offers, cost, delays, received[0], n


def display_updates_with_live_view(seconds=2.0, rounds=5, rate=30.0):
    """A live Blender session of the sample scene (threaded runtime), display updates at 30 Hz
    with one viewer subscribed: the main thread's time per display update (``session.tick``)
    with the live view on and off, in alternating blocks. Returns (off µs, on µs) lists."""
    import json
    import threading

    import grasp_env
    grasp_env.isolate()
    import bpy
    grasp_env.enable()
    import recordings
    from websockets.sync.client import connect
    session_mod = grasp_env.submodule("session")
    bpy.ops.wm.read_homefile(use_empty=True)
    recordings.sample_module().build(bpy)
    live = session_mod.BlenderSession(bpy.context, live=True, duration=1e6)
    lv = session_mod.start_live_view(live, 0, "127.0.0.1")
    live.live_view = None
    ws = connect(lv.address, subprotocols=["foxglove.sdk.v1"])
    channels = {}
    json.loads(ws.recv(timeout=5))
    while len(channels) < 8:
        msg = json.loads(ws.recv(timeout=5))
        if msg["op"] == "advertise":
            channels.update({c["id"]: c["topic"] for c in msg["channels"]})
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": c, "channelId": c} for c in channels]}))
    stop = [False]

    def drain():
        while not stop[0]:
            try:
                ws.recv(timeout=0.2)
            except TimeoutError:
                pass
    th = threading.Thread(target=drain)
    th.start()
    times = {False: [], True: []}
    t0 = time.perf_counter()
    k = 0
    try:
        for _ in range(rounds):
            for on in (False, True):
                live.live_view = lv if on else None
                end = time.perf_counter() + seconds
                while time.perf_counter() < end:
                    a = time.perf_counter()
                    live.tick(a - t0)
                    times[on].append((time.perf_counter() - a) * 1e6)
                    k += 1
                    time.sleep(max(0.0, t0 + k / rate - time.perf_counter()))
    finally:
        live.live_view = lv
        live.finish()
        stop[0] = True
        th.join()
        ws.close()
    return times[False], times[True]


def export_costs(rec, out, repeats=3):
    """Best of ``repeats`` (seconds, export_foxglove's answer) of the copy with the grasp
    analysis, and of the same copy without it (the analysis's channels and arrows left out),
    alternating."""
    from addon.engine import viewer
    full, bare = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        done = viewer.export_foxglove(rec, out)
        full.append(time.perf_counter() - t0)
        with_analysis = viewer.SceneModel.grasp_numbers
        viewer.SceneModel.grasp_numbers = lambda self, rec, rows: None
        try:
            t0 = time.perf_counter()
            viewer.export_foxglove(rec, out)
            bare.append(time.perf_counter() - t0)
        finally:
            viewer.SceneModel.grasp_numbers = with_analysis
    return (min(full), done), (min(bare), None)


def pct(a, q):
    return float(np.percentile(a, q))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="synthetic session length")
    args = ap.parse_args(argv)
    import bench_recording
    import graspcore as gc
    import recordings

    from addon.engine import viewer
    from addon.engine.recording import open_recording
    tmp = tempfile.mkdtemp(prefix="grasp_bench_viewer_")
    sample = os.path.join(tmp, "sample.mcap")
    recordings.record_exec(sample, gc, seconds=6.0)
    many = os.path.join(tmp, "many.mcap")
    bench_recording.synthetic_session(many, args.seconds / 60.0, "lz4")
    rows, targets = [], []
    for label, path, synthetic in (("sample scene, 2 + 2", sample, False),
                                   ("20 bodies + 10 fingers", many, True)):
        rec = open_recording(path)
        if synthetic:
            pressing(rec)
        v, r, rate = per_frame_costs(rec, tmp)
        rows.append((f"one display update's viewer channels, {label} (median / p95)",
                     f"{statistics.median(v):.0f} / {pct(v, 95):.0f} µs"))
        rows.append((f"the recorder's work for the same {1e3 / rate:.1f} ms of ticks, {label} (median / p95)",
                     f"{statistics.median(r):.0f} / {pct(r, 95):.0f} µs"))
        rows.append((f"viewer channels / recorder, {label}",
                     f"{statistics.median(v) / statistics.median(r):.1f} x"))
        out = os.path.join(tmp, "copy.mcap")
        duration = float(rec.ticks["time"][-1] - rec.ticks["time"][0])
        (spent, done), (bare, _) = export_costs(rec, out)
        rows.append((f"export --foxglove, {label}: time per second of session",
                     f"{spent / duration * 1e3:.0f} ms ({done['frames']} frames at {rate:g} Hz)"))
        rows.append((f"export --foxglove, {label}: of which the grasp analysis (per second of session; "
                     "with / without it)",
                     f"{(spent - bare) / duration * 1e3:.0f} ms; {spent / bare:.2f} x"))
        rows.append((f"file per second of session, {label}: viewer copy / recording",
                     f"{done['bytes'] / duration / 1e3:.1f} / {os.path.getsize(path) / duration / 1e3:.1f} kB"))
        offers, cost, delays, got, n = live_costs(rec)
        rows.append((f"live view, {label}: offer() on the display update (median / max)",
                     f"{statistics.median(offers):.1f} / {max(offers):.1f} µs"))
        rows.append((f"live view, {label}: its thread per update (median / p95)",
                     f"{statistics.median(cost):.0f} / {pct(cost, 95):.0f} µs"))
        rows.append((f"live view, {label}: display update to client, localhost (median / p95 / max)",
                     f"{statistics.median(delays):.1f} / {pct(delays, 95):.1f} / {max(delays):.1f} ms "
                     f"({got} of {n} updates received at 30 Hz)"))
        targets.append((f"live viewer receives updates at the display rate, < 100 ms late on localhost, {label}",
                        f"{got} of {n}; p95 {pct(delays, 95):.1f} ms, max {max(delays):.1f} ms",
                        got >= 0.95 * n and pct(delays, 95) < 100.0))
    off, on = display_updates_with_live_view()
    rows.append(("live Blender session, sample scene: main-thread time per display update, live view off / on, "
                 "one viewer subscribed (median; mean)",
                 f"{statistics.median(off):.0f} / {statistics.median(on):.0f} µs; "
                 f"{statistics.mean(off):.0f} / {statistics.mean(on):.0f} µs"))
    share = (statistics.median(on) - statistics.median(off)) / statistics.median(off) * 100
    targets.insert(0, ("live view costs a live Blender session's display update ≤ 5 % (sample scene; the "
                       "interpreter lock shared with the live view's thread included)",
                       f"{share:+.1f} % (median {statistics.median(off):.0f} -> {statistics.median(on):.0f} µs)",
                       share <= 5.0))
    print("### Viewer channels (Foxglove)\n")
    print(f"`bench/bench_viewer.py`: foxglove-sdk {_version('foxglove-sdk')}. "
          "Every recording could carry the viewer channels, or a copy can be written afterwards "
          "(`grasp-lab export --foxglove`). A display update's channels cost about ten times what the "
          "recorder does for the same period, and more than the 5 % of a display update allowed "
          f"(the main thread's display update: {DISPLAY_UPDATE_MS} ms for 20 bodies + 10 fingers, "
          "GUI section above), so recordings do not carry them: the haptic loop and the recorder pay "
          "nothing, and the copy is written at the command line. The live view builds the same "
          "channels on a thread of its own; the display update hands its snapshot over as its last "
          "step, so that thread's Python work (below) holds the interpreter lock while the main "
          "thread waits for its next update, not during one: a live Blender session's display "
          "updates are timed with the live view on and off, alternating.\n")
    print("| target | result | met |")
    print("|---|---|---|")
    for name, value, met in targets:
        print(f"| {name} | {value} | {'yes' if met else '**no**'} |")
    print()
    print("| measurement | value |\n|---|---|")
    for k, val in rows:
        print(f"| {k} | {val} |")
    return 0


def _version(dist):
    from importlib.metadata import version
    return version(dist)


if __name__ == "__main__":
    sys.exit(main())
