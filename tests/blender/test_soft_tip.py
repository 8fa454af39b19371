"""Soft fingertips as a Blender user reaches them (issue #15 item 3): a Finger's *Soft Tip Radius*
(``grasp_lab.torsion``) through properties -> convert -> session -> core -> recording -> analysis,
and ``--set FINGER.torsion=`` on ``run`` and ``resim``.

The scene is the chapter's example: a 0.1 kg bar (20 x 2 x 2 cm) pinched across its width by two
fingertips 5 cm from its centre of mass, so its weight twists it about the pinch axis with
m g d = 0.049 N m. Two point contacts leave that rotation free (the grasp has rank 5); a soft
tip of patch radius rho resists it up to mu_s F_n rho per tip (docs/physics.md "Soft
fingertips"), and below that limit holds it where the two twist springs carry the moment,
2 k rho^2 theta = m g d cos theta."""
import io
import math
import sys

import numpy as np
import pytest

import grasp_env

sys.path.insert(0, grasp_env.ROOT)

MASS, D, HALF_WIDTH = 0.1, 0.05, 0.01       # kg; centre of mass off the pinch axis (m); bar half width
K, SQUEEZE, TIP = 3000.0, 0.003, 0.008      # N/m; how far the HIPs are inside the bar (m); tip radius
MU_S, MU_D = 0.8, 0.6
RHO = 0.01                                  # the soft tip's patch radius (m)
G = 9.81
TIPS = ("Tip A", "Tip B")


def build(bpy, rho=RHO):
    """The pinched bar, built as a user would: a mesh of role Dynamic, two Empties of role Finger."""
    bar = grasp_env.add_cube(bpy, "Bar", size=1.0, location=(D, 0.0, 0.0))
    bar.scale = (0.2, 2 * HALF_WIDTH, 2 * HALF_WIDTH)
    gl = bar.grasp_lab
    gl.role, gl.mass_mode, gl.mass, gl.mu_s, gl.mu_d = "DYNAMIC", "MASS", MASS, MU_S, MU_D
    for channel, (name, side) in enumerate(zip(TIPS, (-1.0, 1.0))):
        tip = bpy.data.objects.new(name, None)
        bpy.context.scene.collection.objects.link(tip)
        tip.location = (0.0, side * (HALF_WIDTH + TIP - SQUEEZE), 0.0)
        f = tip.grasp_lab
        f.role, f.radius, f.stiffness, f.damping, f.channel = "FINGER", TIP, K, 2.0, channel
        f.torsion = rho
    bpy.context.view_layer.update()
    return bar


def call(*args):
    """``grasp-lab`` in this process (cli.main): (exit code, stdout, stderr)."""
    from addon.engine import cli
    out, err = io.StringIO(), io.StringIO()
    code = cli.main([str(a) for a in args], out=out, err=err)
    return code, out.getvalue(), err.getvalue()


def turn(rec):
    """The bar's turn about the pinch axis (y) at every tick, degrees, down positive."""
    q = rec.ticks["pose"][:, 0, 3:]
    w, x, y, z = q.T
    r00, r20 = 1 - 2 * (y * y + z * z), 2 * (x * z - w * y)
    return np.degrees(-np.arctan2(r20, r00))


def normal_force(rec, row):
    """Each tip's normal force at a tick record (N): its force along its contact normal."""
    t = rec.ticks[row]
    return np.abs(np.einsum("fi,fi->f", t["force"], t["normal"]))


def hold_angle(rho):
    """2 k rho^2 theta = m g d cos theta (scipy's root finder, independent of the add-on)."""
    from scipy.optimize import brentq
    return math.degrees(brentq(lambda t: 2 * K * rho ** 2 * t - MASS * G * D * math.cos(t), 0.0, 1.5))


@pytest.fixture(scope="module")
def runs(ext, tmp_path_factory):
    """`grasp-lab run` of the saved .blend with soft tips (3 s), and with ``--set
    TIP.torsion=0`` on both (2 s): the recordings, the saved scene."""
    import bpy
    from addon.engine import recording
    tmp = tmp_path_factory.mktemp("soft_tip")
    bpy.ops.wm.read_homefile(use_empty=True)
    build(bpy)
    blend = tmp / "soft_pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    soft, hard, saved = tmp / "soft.mcap", tmp / "hard.mcap", tmp / "after.blend"
    code, out, err = call("run", blend, "--duration", 3, "--record", soft, "--save", saved)
    assert code == 0, err
    code, out_hard, err = call("run", blend, "--duration", 2, "--record", hard,
                               *[a for t in TIPS for a in ("--set", f"{t}.torsion=0")])
    assert code == 0, err
    assert "set Tip A.torsion=0.0, Tip B.torsion=0.0" in out_hard
    return {"blend": blend, "saved": saved, "tmp": tmp, "soft": recording.open_recording(str(soft)),
            "hard": recording.open_recording(str(hard))}


# ---- the property ---------------------------------------------------------------------------------

def test_the_property_says_what_it_does_and_reaches_the_scene_description(bpy):
    prop = bpy.types.Object.bl_rna.properties["grasp_lab"].fixed_type.properties["torsion"]
    assert prop.name == "Soft Tip Radius" and prop.unit == "LENGTH" and prop.hard_min == 0.0
    assert "twist" in prop.description and "0 = a hard point" in prop.description
    build(bpy, rho=0.004)
    convert, scene = grasp_env.submodule("convert"), grasp_env.submodule("engine.scene")
    desc, _, fingers = convert.scene_description(bpy.context)
    scene.prepare(desc)
    assert [f.name for f in fingers] == list(TIPS)
    assert [f.torsion for f in desc.fingers] == [pytest.approx(0.004, rel=1e-7)] * 2
    # the world the session builds has it: a twist of the pinched bar meets the soft tips
    handle = scene.build_world(desc, grasp_env.graspcore())
    assert len(handle.finger_ids) == 2


def test_a_soft_tip_on_a_mesh_finger_or_the_cursor_is_refused_naming_the_finger(bpy):
    build(bpy)
    convert, scene = grasp_env.submodule("convert"), grasp_env.submodule("engine.scene")
    bpy.data.objects["Tip A"].grasp_lab.renderer = "CURSOR"
    desc, _, _ = convert.scene_description(bpy.context)
    with pytest.raises(scene.SceneError, match=r"Tip A.*Soft Tip Radius.*God-Objects"):
        scene.prepare(desc)
    bpy.data.objects["Tip A"].grasp_lab.renderer = "XFCA"
    pad = grasp_env.add_cube(bpy, "Pad", size=0.02, location=(0.0, 0.0, -0.05))
    pad.grasp_lab.role, pad.grasp_lab.channel, pad.grasp_lab.torsion = "FINGER", 2, 0.005
    desc, _, _ = convert.scene_description(bpy.context)
    with pytest.raises(scene.SceneError, match=r"Pad.*Soft Tip Radius.*mesh finger"):
        scene.prepare(desc)
    pad.grasp_lab.torsion = 0.0
    scene.prepare(convert.scene_description(bpy.context)[0])


def test_the_finger_panel_shows_it_for_an_empty_not_for_a_mesh(bpy):
    """The Finger panel's rows, read from its draw code run against a recording layout."""
    ui = grasp_env.submodule("ui")
    build(bpy)
    pad = grasp_env.add_cube(bpy, "Pad", size=0.02, location=(0.0, 0.0, -0.05))
    pad.grasp_lab.role = "FINGER"

    class Layout:       # what draw() asks of a layout: the properties it shows
        def __init__(self, shown):
            self.shown, self.use_property_split, self.use_property_decorate, self.active = shown, 0, 0, True

        def prop(self, data, name, **kw):
            self.shown.append((name, self.active))

        def row(self, **kw):
            return Layout(self.shown)
        column = row

        def label(self, **kw):
            pass

    def shown(obj):
        class Context:
            active_object = obj
        panel = Layout([])
        ui.GRASPLAB_PT_object.draw(type("P", (), {"layout": panel})(), Context)
        return panel.shown
    tip = bpy.data.objects["Tip A"]
    assert ("torsion", True) in shown(tip)
    tip.grasp_lab.renderer = "CURSOR"
    assert ("torsion", False) in shown(tip)       # greyed: the cursor has no torsion
    assert "torsion" not in [n for n, _ in shown(pad)]
    pad.grasp_lab.torsion = 0.003                  # shown where it is set, so that it can be cleared
    assert ("torsion", False) in shown(pad)


def test_it_round_trips_through_a_blend_and_the_recording_header(runs):
    import bpy
    from addon.engine import recording
    bpy.ops.wm.open_mainfile(filepath=str(runs["saved"]))
    for name in TIPS:
        assert bpy.data.objects[name].grasp_lab.torsion == pytest.approx(RHO, rel=1e-7)
    header = runs["soft"].header["scene"]["fingers"]
    stored = float(np.float32(RHO))           # the property is a float32, given to the core as it is
    assert [f["torsion"] for f in header] == [stored, stored]
    assert [f.torsion for f in recording.scene_from_dict(runs["soft"].header["scene"]).fingers] == [stored] * 2
    assert all("torsion" not in f for f in runs["hard"].header["scene"]["fingers"])   # 0: no entry
    code, out, _ = call("info", runs["tmp"] / "soft.mcap")
    assert code == 0 and "Tip A (r 0.008 m, k 3000 N/m, c 2 N s/m, soft tip 0.01 m)" in out
    code, out, _ = call("info", runs["tmp"] / "hard.mcap")
    assert code == 0 and "Tip A (r 0.008 m, k 3000 N/m, c 2 N s/m)" in out


# ---- the physics, through the add-on --------------------------------------------------------------

def test_soft_tips_hold_the_bar_where_their_twist_springs_carry_its_weight(runs):
    rec = runs["soft"]
    theta = turn(rec)
    fn = normal_force(rec, -1)
    np.testing.assert_allclose(fn, K * SQUEEZE, rtol=0.02)            # 9 N each
    # The closed-form torsional limit, 2 mu_s F_n rho = 0.144 N m, is above the twist m g d = 0.049 N m
    assert 2 * MU_S * fn.min() * RHO > 2.5 * MASS * G * D
    expected = hold_angle(RHO)                                         # 4.68 degrees
    last = rec.ticks["time"] > rec.ticks["time"][-1] - 1.0
    assert theta[last].mean() == pytest.approx(expected, rel=0.02)
    assert np.abs(theta).max() < 2.2 * expected                        # the swing from rest overshoots
    assert np.all(rec.ticks["state"][-1] == 1)                         # both stick


def test_without_soft_tips_the_bar_turns_down(runs):
    theta = turn(runs["hard"])
    assert theta.max() > 90.0


def test_the_threaded_runtime_holds_it_too(runs):
    """`run --realtime` (the haptic loop in C, as a live session): soft tips hold the bar within a
    few degrees of the closed form; `--set TIP.torsion=0` lets it turn down."""
    from addon.engine import recording
    turned = {}
    for soft in (True, False):
        path = runs["tmp"] / f"realtime_{soft}.mcap"
        hard = [] if soft else [a for t in TIPS for a in ("--set", f"{t}.torsion=0")]
        code, out, err = call("run", runs["blend"], "--realtime", "--duration", 1.5, "--record", path, *hard)
        assert code == 0 and "threaded runtime" in out, err
        turned[soft] = turn(recording.open_recording(str(path)))
    assert np.abs(turned[True]).max() < 3 * hold_angle(RHO)
    assert turned[False].max() > 90.0


def test_resim_with_a_soft_tip_below_the_torsional_limit_turns(runs):
    """`resim --set TIP.torsion=0.002`: 2 mu_s F_n rho = 0.029 N m < m g d: the bar turns down.
    With the recorded torsion the replay is identical."""
    from addon.engine import recording
    code, out, err = call("resim", runs["tmp"] / "soft.mcap")
    assert code == 0 and out.startswith("identical"), err
    small = 0.002
    fn = normal_force(runs["soft"], 0)
    assert 2 * MU_S * fn.max() * small < MASS * G * D
    out_path = runs["tmp"] / "small.mcap"
    code, out, err = call("resim", runs["tmp"] / "soft.mcap", "--record", out_path,
                          *[a for t in TIPS for a in ("--set", f"{t}.torsion={small}")])
    assert code == 0, err
    rec = recording.open_recording(str(out_path))
    assert [f["torsion"] for f in rec.header["scene"]["fingers"]] == [small, small]
    assert turn(rec).max() > 45.0


def test_set_torsion_is_refused_out_of_range_on_a_body_and_on_the_cursor(runs, capsys):
    code, _, err = call("resim", runs["tmp"] / "soft.mcap", "--set", "Tip A.torsion=-0.01")
    assert code == 2 and "torsion must be in 0 .. 0.1 m, got -0.01" in err + capsys.readouterr().err  # argparse's
    code, _, err = call("resim", runs["tmp"] / "soft.mcap", "--set", "Bar.torsion=0.01")
    assert code != 0 and "'Bar' is a body; torsion is not a body property" in err
    code, _, err = call("resim", runs["tmp"] / "soft.mcap", "--set", "Tip B.renderer=cursor")
    assert code != 0 and "'Tip B'" in err and "Soft Tip Radius" in err


# ---- the analysis of the recording -----------------------------------------------------------------

def test_the_analysis_reports_closure_with_soft_tips_and_rank_5_without(runs):
    from addon.engine import analysis
    rec = runs["soft"]
    row = len(rec.ticks) - 1
    table = analysis.analyse_recording(rec, rows=[row])
    (g,) = analysis.body_grasps(table)
    assert g.force_closure and table.quality["rank"][0] == 6 and g.epsilon > 0
    # The same contacts as point contacts (no torsion): the turn about the pinch axis is free.
    t = rec.ticks[row:row + 1]
    radii = [f["radius"] for f in rec.header["scene"]["fingers"]]
    point = analysis.analyse_arrays(analysis.body_models(rec.header["scene"]), t["pose"], t["god_object"],
                                    t["force"], t["normal"], t["state"], t["contact"], radii)
    assert not point.quality["force_closure"][0] and point.quality["rank"][0] == 5
    # The run without soft tips, while both fingers still pinch it (0.05 s): rank 5, not closed.
    hard = runs["hard"]
    early = int(np.searchsorted(hard.ticks["time"], 0.05))
    assert np.all(hard.ticks["state"][early] > 0)
    table = analysis.analyse_recording(hard, rows=[early])
    assert not table.quality["force_closure"][0] and table.quality["rank"][0] == 5


def test_a_sweep_varies_the_soft_tips_and_reports_closure_only_with_them(runs):
    """`sweep --vary TIP.torsion=0,0.01` on both tips (a 2 x 2 grid, one sample a cell): every sample holds the bar
    in its fingers (turned or not); the analysis finds it in force closure all along with a soft
    tip and never with two point contacts."""
    import csv
    out = runs["tmp"] / "sweep"
    code, stdout, err = call("sweep", runs["tmp"] / "soft.mcap", "--samples", 1, "--workers", 1, "--out", out,
                             *[a for t in TIPS for a in ("--vary", f"{t}.torsion=0,{RHO}")])
    assert code == 0, err
    with open(out / "samples.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4
    by_cell = {(float(r["Tip A.torsion"]), float(r["Tip B.torsion"])): r for r in rows}
    assert set(by_cell) == {(a, b) for a in (0.0, RHO) for b in (0.0, RHO)}
    for (a, b), r in by_cell.items():
        assert r["held"] == "1"
        if a or b:
            assert float(r["closure_time"]) > 2.5 and float(r["min_epsilon"]) > 0
        else:
            assert float(r["closure_time"]) == 0.0
