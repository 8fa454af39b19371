"""The extension in a real GUI Blender, used as a person uses it (docs/gui-tests.md).

Each test starts a GUI Blender under Xvfb (tests/gui/gui_blender.sh: Debian 13's Blender
4.3 in a cached chroot, or $BLENDER) with tests/gui/driver.py, which clicks, types and
takes screenshots (kept in build/gui/<scenario>/) and writes what it saw to result.json.
"""
import os
import re
import subprocess
import sys

import pytest

import gui_run


@pytest.fixture(scope="session")
def gui(tmp_path_factory):
    return gui_run.environment(str(tmp_path_factory.mktemp("blender_user")))


run = gui_run.run


def ok(result, console):
    assert result.get("ok"), f"{result.get('error')}\n{console[-3000:]}"
    assert "import_error" not in result, result["import_error"]


def stopped_cleanly(result):
    for tag, threads in result["threads_after"].items():
        assert threads == [], f"{tag}: core threads left: {threads}"
        assert result["running_after"][tag] is False, f"{tag}: session still marked running"


def test_start_session_then_esc_then_the_stop_button(gui):
    r, console, code = run(gui, "start_esc_stop")
    ok(r, console)
    assert code == 0
    # The abi3 core and the bundled hidapi import under the GUI Blender's own Python.
    assert r["graspcore"] == "_core.abi3.so" and r["hidapi"].startswith("hid.")
    assert r["threads_running"] == ["gc-haptic", "gc-object"]
    stopped_cleanly(r)
    # On screen while it runs: god-object spheres (green: squeezing, far from slip), force
    # arrows (red), the HUD (white).
    before, during = r["pixels"]["before"], r["pixels"]["during"]
    assert during["green"] > before["green"] + 100, r["pixels"]
    assert during["red"] > before["red"] + 100, r["pixels"]
    assert before["hud_white"] < 50 < 1000 < during["hud_white"], r["pixels"]
    # The HUD leads with the grasp, then the C loop's own numbers, not the display's.
    hud = r["hud"].replace("\u00a0", " ").split("\n")     # no-break spaces as spaces
    assert hud[0].startswith("Box: held") and hud[1].startswith("Box: closure ")    # words, then numbers
    assert "Finger 0 stick" in hud[4] and "Finger 1 stick" in hud[4]
    assert hud[5].startswith("t ") and "until Esc" in hud[5] and "haptic 0 Hz" not in hud[5]
    assert "safety:" not in r["hud"] and "forces held at zero" not in r["hud"]    # no device: no safety line
    # Esc ends it within one display frame: no later than the longest of the last display
    # updates (Blender answers the key once the frame it is drawing is done), plus the
    # time xdotool takes to send it.
    assert r["esc_latency_s"] < max(r["frame_max_s"], r["interval"]) + 0.1, r
    assert r["last_time"] > 0.5


def test_the_hud_and_viewport_show_a_held_grasp(gui):
    """Three fingertips hold the box: the HUD's first line says it is in force closure with
    its epsilon, the weakest wrench is drawn (magenta) and the god-objects are coloured by
    their friction use, on screen and in their materials; the sidebar's grasp lines fit."""
    r, console, _ = run(gui, "grasp_hud")
    ok(r, console)
    stopped_cleanly(r)
    (g,) = r["grasps"]
    assert g["force_closure"] and g["epsilon"] > 0 and sorted(c["finger"] for c in g["contacts"]) == [0, 1, 2]
    assert abs(sum(w * w for w in g["weakest"]) - 1.0) < 1e-9            # a unit wrench
    hud = r["hud"].replace("\u00a0", " ").split("\n")     # no-break spaces as spaces
    assert hud[0].startswith("Box: held firmly"), hud       # the verdict in words: in closure, far from slip
    assert hud[1].startswith(f"Box: closure yes  ε {g['epsilon']:.3f}  resists "), hud
    assert hud[2].startswith("  grip ") and " / load " in hud[2] and hud[3].startswith("  slip margin ")
    assert all(f"Finger {i} stick" in hud[4] for i in range(3)), hud
    assert hud[-1].startswith("magenta: ")                      # the weakest wrench's legend
    before, during = r["pixels"]["before"], r["pixels"]["during"]
    assert during["magenta"] > before["magenta"] + 100, r["pixels"]          # the weakest wrench
    assert during["green"] > before["green"] + 100, r["pixels"]              # god-objects far from slip
    assert before["hud_white"] < 50 < 1000 < during["hud_white"], r["pixels"]
    # Drawn where the grasp's weakest wrench is: its ring, projected with the viewport's matrices,
    # lies on magenta pixels; the same ring 10 cm away does not.
    on = r["weakest_on_screen"]
    assert on["ring_points"] >= 10 and on["ring_hits"] >= 0.8 * on["ring_points"], on
    assert on["moved_ring_hits"] <= 0.2 * on["ring_points"] and on["arrow_tip_hit"], on
    for name, c in r["god_object_colours"].items():
        assert c["material"] == c["expected"], (name, c)
    assert all(c["friction_use"] < 0.5 for c in g["contacts"]), g       # squeezing on a table: green
    side = r["sidebar"]
    assert max(side["text_px"]) < side["region_width"] - 20 * side["ui_scale"], side
    words = " ".join(side["lines"]).replace("\u00a0", " ").split()
    assert words[:3] == ["Box:", "held", "firmly;"] and "Box: closure yes" in " ".join(words), words   # words, numbers


def test_ctrl_z_after_a_session_and_during_one(gui):
    r, console, _ = run(gui, "undo")
    ok(r, console)
    stopped_cleanly(r)
    assert r["z_after_session"] > r["z_rest"] + 0.02          # the session lifted the box
    assert r["z_after_undo"] == pytest.approx(r["z_rest"], abs=1e-6)   # Ctrl+Z put it back
    # Ctrl+Z during a session ends it and goes back to the scene as it was before it.
    assert r["z_after_undo_mid_session"] == pytest.approx(r["z_rest"], abs=1e-6)


def test_loading_a_file_mid_session(gui):
    r, console, _ = run(gui, "load_file")
    ok(r, console)
    stopped_cleanly(r)
    assert r["running_flag_after_load"] is False


def test_disabling_the_extension_mid_session(gui):
    r, console, _ = run(gui, "disable")
    ok(r, console)
    stopped_cleanly(r)


def test_quitting_blender_mid_session(gui):
    r, console, code = run(gui, "quit", timeout=60)
    assert r["threads_running"] == ["gc-haptic", "gc-object"]
    assert code == 0, console[-3000:]
    # The session was stopped by Blender's cancel, not killed with the process.
    assert "Grasp session:" in console and "ended by Blender" in console, console[-3000:]


def test_an_error_inside_a_session_stops_it_cleanly_and_says_why(gui):
    r, console, _ = run(gui, "error")
    ok(r, console)
    stopped_cleanly(r)
    assert r["session_error"] == "RuntimeError: injected by the GUI test"
    assert r["overlay_left"] is False
    assert "(ended by an error): RuntimeError: injected by the GUI test" in console


def test_moving_a_fingertip_with_g_during_a_session(gui):
    r, console, _ = run(gui, "interactive")
    ok(r, console)
    stopped_cleanly(r)
    assert r["open_ended"], "nothing animated: the session runs until Esc"
    assert r["contacts_before"] == [0, -1]                 # finger 0 rests on the box
    assert r["moved_by"] == pytest.approx(0.02, abs=1e-6)
    assert r["hip_x_after_move"] == pytest.approx(0.048 - 0.02, abs=1e-6)  # the haptic loop followed
    assert r["contact_after_move"] == 0 and r["force_after_move"] > 1.0    # squeezing the box
    assert r["go_hip_gap"] > 1e-3                                           # the god-object stays out
    assert r["contact_after_back"] == -1 and r["still_running"]


def test_live_sessions_end_like_the_headless_run_at_every_display_rate(gui):
    ref, console, _ = run(gui, "exec_headless", background=True)
    ok(ref, console)
    r, console, _ = run(gui, "display_rates", timeout=300)
    ok(r, console)
    stopped_cleanly(r)
    headless = ref["exec_box"]
    assert r["exec_box"] == pytest.approx(headless, abs=1e-9)   # EXEC in the GUI: the same run
    for rate, run_ in r["runs"].items():
        assert run_["threaded"], rate
        assert run_["box"] == pytest.approx(headless, abs=1e-3), (rate, run_, headless)


def test_a_live_session_driven_by_an_emulated_device(gui):
    import json
    import subprocess
    import sys
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "grip",
                            "--wait", "600"],   # for the GUI Blender's hello: slow to start on a busy machine
                           cwd=gui_run.ROOT, stdout=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        r, console, _ = run(dict(gui, GRASP_LAB_GUI_DEVICE_PORT=port), "device")
        emu.terminate()
        out = emu.communicate(timeout=20)[0]
    finally:
        emu.kill()
    ok(r, console)
    stopped_cleanly(r)
    assert r["threads_running"] == ["gc-haptic", "gc-object", "gc-serial"]
    assert r["contacts"] == [0, 0]                          # the device's fingertips grip the box
    assert f"{port}: streaming, fingers 0..1" in r["hud"] and "forces enabled" in r["hud"], r["hud"]
    # A loaded machine may add "stall" safety events (the haptic loop ran late: forces held
    # at zero meanwhile); the device still connects first and is enabled next.
    assert [e for e in r["device_events"] if e != "stall"][:2] == ["connected", "enabled"], r["device_events"]
    report = json.loads([line for line in out.splitlines() if line.startswith("REPORT ")][0][7:])
    assert report["max_force_n"] > 1.0, report             # forces reached the device once enabled
    assert report["violations"] == dict.fromkeys(report["violations"], 0), report


def test_find_devices_lists_the_emulator_and_its_plus_adds_it(gui):
    """Find Devices with an emulator running: its row (name, fingers, port) on screen under
    the button, and its + adds it with the finger count of its hello."""
    import subprocess
    import sys
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--fingers", "2",
                            "--wait", "600"],   # for Find Devices' hello: the GUI Blender starts slowly when busy
                           cwd=gui_run.ROOT, stdout=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        r, console, _ = run(dict(gui, GRASP_LAB_GUI_DEVICE_PORT=port), "find_devices")
    finally:
        emu.kill()
        emu.wait()
    ok(r, console)
    # ours among them (other emulators running on the machine, tests in parallel, may answer too)
    assert [(d["name"], d["n_fingers"]) for d in r["discovered"] if d["port"] == port] == [("grasp-lab-emulator", 2)], \
        r["discovered"]
    assert r["text_pixels"]["name_line"] > 30 and r["text_pixels"]["count_line"] > 30, r["text_pixels"]
    assert all(px < r["lines"]["region_width"] - 60 for px in r["lines"]["text_px"]), r["lines"]   # never cut
    assert r["entries"] == [["SERIAL", port, 0, 2]], r["entries"]


def test_the_readme_walkthrough_click_by_click(gui):
    """The README's walkthrough (the pictures of make docs-images come from this scenario):
    Add Finger beside the selected box, twice; Check with a flat plane names the fix under the
    button, without covering it; live, a fingertip grabbed with G squeezes the box; a recorded
    session leaves the box where it ended and offers Reset Bodies; Bake Recording's browser
    opens on that recording; Show Curves puts the measures in a Graph Editor, no key selected."""
    r, console, _ = run(gui, "walkthrough", timeout=300)
    ok(r, console)
    stopped_cleanly(r)
    # Fingertips beside the 5 cm box, touching its -x then +x face (8 mm radius: at 33 mm)
    (f0, f1), box = r["added_fingers"], r["box"]
    assert f0["radius"] == pytest.approx(0.008) and f1["radius"] == pytest.approx(0.008)
    assert f0["location"] == pytest.approx([-0.033, 0.0, box["location"][2]], abs=1e-6)
    assert f1["location"] == pytest.approx([0.033, 0.0, box["location"][2]], abs=1e-6)
    # Check: the plane's problem and its fix, drawn under the button; the button not covered
    ok_plane, text = r["check_plane"]
    assert not ok_plane and '"Plate": has zero volume' in text and "give it thickness" in text
    assert r["check_button_change"] == 0.0
    before, after = r["check_rows"]["before"], r["check_rows"]["after"]
    assert after[0] == before[0]                       # the Add Finger / Check row stays put
    assert r["check_ok"][0] and r["check_ok"][1].startswith("Grasp scene OK: 1 dynamic, 1 static, 2 fingers")
    # Live: the grabbed fingertip squeezes the box with the other
    hud = r["live_hud"].replace("\u00a0", " ")          # no-break spaces as spaces
    assert "Finger 0 stick" in hud and "Finger 1 stick" in hud, hud
    # Recorded: one recording; the box left where the session ended, Reset Bodies offered
    assert len(r["recordings"]) == 1 and r["moved_after_record"] == ["Box"]
    # Reset Bodies, clicked where it is offered, puts the box back on the table, and goes
    reset = r["reset"]
    assert reset["at_end"][1] == pytest.approx(0.10, abs=0.005), reset          # carried 10 cm along y
    assert reset["after"] == pytest.approx([0.0, 0.0, 0.025], abs=1e-6), reset
    assert reset["still_offered"] is False
    folder, name = os.path.split(r["recordings"][0])
    assert r["browser"] == {"directory": folder + os.sep, "filename": name}
    g = r["graph"]
    assert g["filter"] == "gl_" and g["only_selected"] and g["height"] > 200
    assert g["selected"] == ["GL Force Box", "GL God-object Finger 0", "GL God-object Finger 1"]
    assert g["keys"] > 1000 and g["selected_keys"] == 0


def test_the_first_hour_from_the_startup_file_word_for_word(gui):
    """The README's walkthrough from Blender's own startup file, as a new user follows it, with
    the device step on the emulator: a held grasp, a recording in a folder the panel states, a
    bake, readable curves, a device session until Esc and a robustness answer; every label the
    sidebar drew on the way fits its default width."""
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty"],   # the README's
                           cwd=gui_run.ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        r, console, _ = run(dict(gui, GRASP_LAB_GUI_DEVICE_PORT=port), "first_hour", timeout=900)
    finally:
        emu.kill()
        emu.wait()
    ok(r, console)
    stopped_cleanly(r)
    # Blender's startup file, nothing prepared: the cube selected, the file not saved
    assert r["startup_objects"] == ["Camera", "Cube", "Light"] and r["cube_selected"] and r["blend_path"] == ""
    # 1. two fingertips on opposite sides of the 2 m cube, sized to it (a twentieth: 10 cm)
    f0, f1 = r["fingers"]
    assert f0["radius"] == pytest.approx(0.1) and f1["radius"] == pytest.approx(0.1)
    assert f0["location"] == pytest.approx([-1.1, 0, 0], abs=1e-6) and f1["location"] == pytest.approx([1.1, 0, 0], abs=1e-6)
    # the falling cube offered a table before any session; one click put it under the cube
    assert r["support_offer"] == ["Cube"]
    assert r["table"]["role"] == "STATIC" and r["table"]["top"] == pytest.approx(-1.0) and r["table"]["offer_after"] == []
    assert r["check"][0] and r["check"][1].startswith("Grasp scene OK: 1 dynamic, 1 static, 2 fingers"), r["check"]
    # 2. live until Esc; the HUD's first line says in words that the cube is held, and the
    # summary after Esc says it too; no safety counters without a device
    assert r["selected_for_grab"] == ["Finger 1"] and r["live_duration"] == float("inf")
    hud = r["live_hud"].replace("\u00a0", " ").split("\n")
    assert hud[0].startswith("Cube: held"), hud
    assert "safety:" not in r["live_hud"] and "forces held at zero" not in r["live_hud"]
    assert r["summary"] and r["summary"][0].startswith("Cube: "), r["summary"]
    # 3. an unsaved file records to the per-user folder, named after the scene and the time
    assert r["recording_folder"] == os.path.normpath(r["user_folder"]) and "grasp_lab" in r["user_folder"]
    folder, name = os.path.split(r["recording"])
    assert folder == r["recording_folder"] and re.fullmatch(r"Scene_\d{4}-\d\d-\d\d_\d\d-\d\d-\d\d\.mcap", name), name
    # 4. the bake's browser on it; 5. curves normalised, measures with units, a baked frame in words
    assert r["browser"] == {"directory": folder + os.sep, "filename": name}
    assert r["graph"]["normalized"] and r["graph"]["filter"] == "gl_" and ", N" in r["graph"]["grip_description"]
    assert len(r["baked_frame"]) == 1 and r["baked_frame"][0].startswith("Cube: "), r["baked_frame"]
    # 6. the device: on fingers 0..1, its frame on them (not at the cursor), forces on from the
    # start, running until Esc with both fingertips on the cube
    assert r["device_entries"] == [["SERIAL", port, 0, 2]], r["device_entries"]
    # (finger 1 was pushed 5 cm in with G in step 2: the fingers' centre is 2.5 cm off the cube's)
    assert r["device_frame"]["location"] == pytest.approx([(-1.1 + 1.05) / 2, 0, 0], abs=1e-6)
    assert r["device_frame"]["scale"] == pytest.approx([(1.1 + 1.05) / 2 / 0.06] * 3)
    assert r["device_duration"] == float("inf") and r["device_enabled"] == [True]
    assert f"{port}: streaming" in r["device_hud"], r["device_hud"]
    # 7. the sweep of the recording picked (the one made), results only, its process collected
    assert r["sweep_choice"] == r["recording"]
    assert not r["sweep"]["error"] and r["sweep"]["status"].startswith("Held "), r["sweep"]
    assert r["sweep"]["returncode"] == 0 and not [f for f in r["sweep"]["files"] if f.endswith(".zip")], r["sweep"]
    # nothing cut: every label the sidebar drew, at its default width, fits (the measure's
    # model first checked against a label this sidebar cut and one it drew whole)
    model, room = r["label_model"], r["label_model"]["room"]
    if model["width"] == 291:          # the sidebar these were seen in (1600 x 900, UI scale 1)
        assert model["split"]["whole"] <= room["split"] < model["split"]["cut"], model
        assert room["label"] < model["label"]["cut"] and model["icon"]["whole"] <= room["icon"], model
    for step, labels in r["labels"].items():
        cut = [(text, px, room) for text, px, room in labels if px > room]
        assert not cut, (step, cut)


def test_the_robustness_panel_sweeps_the_last_recording(gui):
    """Run Sweep clicked in the Robustness panel: the sweep runs in background processes while
    Blender goes on drawing, its progress bar only moves forwards, and at the end the panel
    says how many samples held and shows the map."""
    r, console, code = run(gui, "robustness", timeout=300)
    ok(r, console)
    assert r["recording"].endswith(".mcap"), r
    assert not r["error"], r["error"]
    assert r["status"].startswith("Held ") and " of 400: p = " in r["status"], r["status"]
    seen = r["progress_seen"]
    assert seen == sorted(seen) and len(seen) > 3, seen
    # Blender's timers ran all along: a look at least every 5 s of the sweep on average (one
    # look in all, had the sweep held the main thread); a gap of half a minute would be a hang.
    assert len(seen) >= (r["sweep_seconds"] or 0) / 5 and r["max_gap_s"] < 30.0, (len(seen), r["sweep_seconds"],
                                                                            r["max_gap_s"])
    assert r["map_path"].endswith("map.png")
    # the map in the sidebar: thousands of pixels in the held probability's colours (red to
    # green), where the sidebar had next to none while the sweep ran
    assert r["warm_before"] < 500 and r["warm_after"] > r["warm_before"] + 3000, r


def test_device_fit_draws_the_workspace_red_where_the_animation_leaves_it(gui):
    """A device profile added in the Devices panel: its workspace in the viewport, red where the pinch's
    animation leaves it, the HUD line saying who leaves when; Fit Devices clicked: the verdicts under
    the button; the frame moved to where the path fits: no red, the HUD says every finger stays."""
    r, console, _ = run(gui, "device_fit", timeout=300)
    ok(r, console)
    before, origin, placed = r["before"], r["at_origin"], r["placed"]
    line, = r["hud_at_origin"]
    assert line.startswith("touch: Finger 0 leaves its workspace at "), line
    # red: the volume tinted and the samples outside it, where there was next to none before
    assert origin["red"] > before["red"] + 2000, (before, origin)
    assert origin["hud_red"] > 100, origin
    assert r["report"].split("\n")[1].startswith("touch: "), r["report"]
    assert "Finger 1: fails at 0.000 s (tick 0): no end-effector (the device has 1)" in r["report"]
    assert r["hud_placed"] == ["touch: every finger stays in its workspace"]
    # placed: the volume drawn in its end-effector's blue, the red gone
    assert placed["red"] < before["red"] + 200 and placed["blue"] > before["blue"] + 2000, (before, placed)
    assert placed["hud_green"] > 100, placed


def test_a_live_session_with_sound_on_runs_and_says_when_it_cannot_play(gui):
    """docs/sound.md: the pinch and lift live with the Session panel's Sound on, then off, twice
    each (the display rates with and without are measured by bench/bench_sound.py, not asserted
    here). Where Blender has an audio output (SDL's dummy driver under Xvfb) every tick is placed
    to play; where it has none (Debian's Blender 4.3 is built without the aud module) each session
    with Sound on says so and runs to its end like the others."""
    r, console, code = run(gui, "sound", timeout=400)
    ok(r, console)
    assert [run_["sound"] for run_ in r["runs"]] == [True, False, True, False]
    for run_, message in zip(r["runs"], r["sound_messages"]):
        st = run_["sound_stats"]
        assert run_["time"] > 5.0, run_                 # every session ran to its end (6 s)
        if not run_["sound"]:
            assert st is None and message == ""
        elif not r["audio"]:
            assert "no audio" in message and st == {"message": message}, (message, st)
        else:
            assert message == ""
            # Every tick sounded: the stretches placed cover the session, both fingers' touches clicked.
            assert abs(st["seconds"] - run_["time"]) < 0.01, run_
            assert st["clicks"] >= 2 and st["updates"] > 5
            assert 0 < st["latency_ms"] < 2000 and st["late"] <= 2, run_
    stopped_cleanly(r)


def test_a_keyed_hand_lifts_the_box_live_and_its_rendered_hand_holds_it(gui):
    """docs/hands.md: the keyed test hand live in the GUI. Once the box is lifted, at a display
    update, the input capsules are 3 mm in the box and the rendered ones on its surface (never
    0.5 mm inside), joints connected; the rendered hand is drawn (pixels that go when it is
    hidden). The picture: build/gui/hand_live/hand_holding_box.png."""
    r, console, code = run(gui, "hand_live", timeout=900)
    ok(r, console)
    stopped_cleanly(r)
    assert r["threaded"] is True
    assert abs(r["box_lift"] - 0.10) < 2e-3, r
    assert r["input_depth"] > 0.0029, r
    assert r["rendered_depth"] <= 0.0005 and r["joint_gap"] <= 0.0005, r
    assert r["rendered_pixels"] > 500, r
    assert "Hand: correction max" in r["hud"], r["hud"]
