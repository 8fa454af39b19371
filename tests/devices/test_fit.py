"""Can this device do this task? (engine/fit.py, engine/devices/device_profiles.py; docs/devices.md)

Closed-form cases, each against its analytic tick: a path leaving a box, a force ramp crossing the
peak, a held force crossing the continuous limit through the duty model, two thimbles passing too
close, fingers crossing, a stiffness above the stable bound; placements found exactly (box, cylinder,
sphere, a turn) and, applied, making the task fit; the profiles' files checked; bad input refused.
"""
import math

import numpy as np
import pytest

from addon.engine import fit
from addon.engine.devices import device_profiles as dp

RATE = 1000.0


def make_task(hip, force=None, contact=None, stiffness=500.0, rate=RATE, names=None):
    hip = np.asarray(hip, dtype=np.float64)
    if hip.ndim == 2:
        hip = hip[:, None, :]
    T, F, _ = hip.shape
    force = np.zeros((T, F, 3)) if force is None else np.asarray(force, dtype=np.float64).reshape(T, F, 3)
    contact = np.zeros((T, F), bool) if contact is None else np.asarray(contact, bool).reshape(T, F)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (T, F)).copy() if np.ndim(stiffness) < 2 \
        else np.asarray(stiffness, dtype=np.float64)
    return fit.Task(names or [f"Finger {i}" for i in range(F)], np.arange(T) / rate, hip, force, contact, k, rate)


def only(result):
    assert len(result.fingers) == 1
    return result.fingers[0]


# ------------------------------------------------------------------------------------------ profiles

def test_every_builtin_profile_loads_cites_its_source_and_says_its_limits():
    names = set(dp.available())
    assert {"touch", "touch_x", "falcon", "omega3", "sigma7", "inverse3", "chapter_rig", "three_finger"} <= names
    for p in dp.load_all():
        assert p.source.startswith("https://"), p.name
        with open(p.path) as f:
            assert p.source in f.read()         # the sheet is cited in the file itself
        assert 0 < p.continuous_force <= p.peak_force
        assert len(p.workspaces) == p.end_effectors
        assert p.line().startswith(p.name + " ")
    rig = dp.find("chapter_rig")
    assert rig.end_effectors == 2 and not rig.can_cross
    assert dp.find("touch").workspaces[0].size.tolist() == [0.160, 0.070, 0.120]


def _write(tmp_path, text, name="mine.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


GOOD = """title = "Mine"
source = "https://example.org/sheet"
end_effectors = 2
workspace = { shape = "sphere", radius = 0.05 }
peak_force = 5.0
continuous_force = 1.0
stable_stiffness = 800.0
effector_radius = 0.01
can_cross = true
duty_time = 5.0
"""


def test_a_users_profile_is_one_small_file_by_path_or_folder(tmp_path, monkeypatch):
    path = _write(tmp_path, GOOD)
    p = dp.find(path)
    assert p.name == "mine" and p.end_effectors == 2 and p.workspaces[0].radius == 0.05
    monkeypatch.setenv(dp.PROFILES_ENV, str(tmp_path))
    assert dp.find("mine").path == path


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("peak_force = 5.0\n", ""), "field 'peak_force' is missing"),
    (lambda t: t.replace("stable_stiffness = 800.0", "stable_stiffness = -800.0"),
     "field 'stable_stiffness' must be positive, got -800.0"),
    (lambda t: t.replace("radius = 0.05", "radius = -0.05"), "field 'workspace.radius' must be positive"),
    (lambda t: t.replace('shape = "sphere"', 'shape = "cone"'), "workspace shape must be one of"),
    (lambda t: t.replace("continuous_force = 1.0", "continuous_force = 9.0"), "is above peak_force"),
    (lambda t: t.replace("end_effectors = 2", "end_effectors = 0"), "'end_effectors' must be a whole number"),
    (lambda t: t.replace("can_cross = true\n", ""), "'can_cross' is missing"),
    (lambda t: t + "oops = [", "not valid TOML"),
])
def test_a_bad_profile_file_is_one_line_naming_the_file_and_the_field(tmp_path, edit, message):
    path = _write(tmp_path, edit(GOOD))
    with pytest.raises(dp.ProfileError) as ex:
        dp.load(path)
    text = str(ex.value)
    assert message in text and path in text and "\n" not in text


def test_an_unknown_profile_says_which_ones_exist():
    with pytest.raises(dp.ProfileError, match=r"unknown device profile 'phantom9'.*known: .*touch"):
        dp.find("phantom9")


def test_more_fingers_than_end_effectors_is_refused():
    task = make_task(np.zeros((3, 2, 3)))
    with pytest.raises(fit.FitError, match="2 fingers given .*the device has 1 end-effector$"):
        fit.evaluate(task, dp.find("touch"), ["Finger 0", "Finger 1"])
    with pytest.raises(fit.FitError, match="no finger 'Thumb'"):
        fit.evaluate(task, dp.find("touch"), ["Thumb"])


# ------------------------------------------------------------------------------------------ workspace

def test_a_path_that_leaves_the_box_fails_at_the_exact_tick_with_the_placement_holding_it_longest():
    # still for 100 ticks, then up at 0.1 m/s: the Touch's box is 0.12 m high, so the longest any
    # placement holds it is until z = 0.12: tick 100 + 1200; the first tick out is 1301.
    n = np.arange(2000)
    z = np.where(n > 100, 0.1 * (n - 100) / RATE, 0.0)
    task = make_task(np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1))
    r = fit.evaluate(task, dp.find("touch"))
    f = only(r)
    assert (r.verdict, f.verdict, f.check, f.first_fail_tick) == ("fails", "fails", "workspace", 1301)
    assert f.first_fail_time == pytest.approx(1.301)
    assert f.margin == pytest.approx(-0.0001, abs=1e-12)      # z 0.1201 in a box held over z 0 .. 0.12
    assert "leaves the workspace" in f.cause
    # the placement that holds it longest has the path's first 1301 ticks inside
    q = r.placement.to_device(task.hip[:1301, 0])
    assert np.min(dp.find("touch").workspaces[0].margin(q)) >= -1e-9


def test_at_the_frame_a_path_inside_fits_and_one_outside_is_placed_exactly_and_then_fits():
    touch = dp.find("touch")
    t = np.arange(1000) / RATE
    centre = np.array([0.30, 0.20, 0.10])
    # a path spanning exactly the box: 0.16 along x, 0.07 along y, 0.12 along z
    path = centre + np.stack([0.08 * np.sin(2 * np.pi * t), 0.035 * np.cos(2 * np.pi * t),
                              0.06 * np.sin(4 * np.pi * t + 0.3)], axis=1)
    path[0] = centre + [0.08, 0.035, 0.06]          # every extreme reached exactly
    path[1] = centre - [0.08, 0.035, 0.06]
    task = make_task(path)
    r = fit.evaluate(task, touch)
    assert r.verdict == "placed" and only(r).verdict == "placed"
    assert r.placement.yaw_deg == 0.0
    np.testing.assert_allclose(r.placement.translation, centre, atol=1e-12)
    assert r.placement_margin == pytest.approx(0.0, abs=1e-12)
    again = fit.evaluate(task, touch, frame=r.placement)
    assert again.verdict == "fits" and only(again).verdict == "fits"
    # a hair wider than the box: no translation holds it, and no turn about z does either (0.12 high)
    wider = path.copy()
    wider[1, 2] -= 1e-6
    assert fit.evaluate(make_task(wider), touch).verdict == "fails"


def test_a_segment_too_long_for_the_box_fits_turned_about_the_vertical():
    # 0.17 m along x: longer than the Touch's 0.16 m width, shorter than its 0.1746 m diagonal; it fits
    # turned between acos(0.16/0.17) = 19.8 and asin(0.07/0.17) = 24.3 degrees.
    s = np.linspace(0.0, 0.17, 500)
    task = make_task(np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1))
    r = fit.evaluate(task, dp.find("touch"))
    assert r.verdict == "placed"
    yaw = r.placement.yaw_deg % 180            # a segment turned by 180 degrees is the same segment
    lo, hi = math.degrees(math.acos(0.16 / 0.17)), math.degrees(math.asin(0.07 / 0.17))
    assert lo <= yaw <= hi or lo <= 180 - yaw <= hi
    assert fit.evaluate(task, dp.find("touch"), frame=r.placement).verdict == "fits"


@pytest.mark.parametrize("profile, radius", [("omega3", 0.080), ("inverse3", 0.200)])
def test_round_workspaces_are_placed_by_the_exact_smallest_enclosing_circle_or_ball(profile, radius):
    # an equilateral triangle's smallest enclosing circle is its circumcircle: radius R exactly
    centre = np.array([0.5, -0.2, 0.05])
    angles = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    for R, verdict in ((radius * (1 - 1e-6), "placed"), (radius * (1 + 1e-6), "fails")):
        tri = centre + R * np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
        path = np.repeat(tri, 50, axis=0)
        r = fit.evaluate(make_task(path), dp.find(profile))
        assert r.verdict == verdict, (R, r.placement_margin)
        if verdict == "placed":
            np.testing.assert_allclose(r.placement.translation[:2], centre[:2], atol=1e-9)
            assert r.placement_margin == pytest.approx(radius - R, abs=1e-12)
            assert fit.evaluate(make_task(path), dp.find(profile), frame=r.placement).verdict == "fits"
        else:
            # held from the start until the third vertex: the first tick that needs the whole circle
            assert only(r).first_fail_tick == 100 and only(r).check == "workspace"


def test_min_ball_is_exact_on_known_sets():
    rng = np.random.default_rng(3)
    # points on a sphere of radius 2 about (1, 2, 3), plus points inside: the ball is that sphere
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = np.vstack([np.array([1, 2, 3]) + 2 * d, np.array([1, 2, 3]) + 0.5 * d[:50]])
    c, r = fit.min_ball(pts)
    np.testing.assert_allclose(c, [1, 2, 3], atol=1e-6)
    assert r == pytest.approx(2.0, abs=1e-6)
    # an obtuse triangle: the ball is on its longest side
    c, r = fit.min_ball(np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 0.5]]))
    np.testing.assert_allclose(c, [2.0, 0.0], atol=1e-12)
    assert r == pytest.approx(2.0)


# ------------------------------------------------------------------------------------------ forces

def test_a_force_ramp_crosses_the_peak_at_the_exact_tick():
    # |F| = 2 N/s * t along a tilted direction: the Touch's 3.3 N peak is passed after tick 1650
    n = np.arange(3000)
    direction = np.array([1.0, 2.0, -2.0]) / 3.0
    force = (2.0 * n / RATE)[:, None] * direction
    task = make_task(np.zeros((len(n), 3)), force=force)
    f = only(fit.evaluate(task, dp.find("touch")))
    assert (f.verdict, f.check, f.first_fail_tick) == ("fails", "peak", 1651)
    assert f.margin == pytest.approx(3.3 - 3.302)


def test_a_force_held_above_the_continuous_limit_fails_when_its_duty_says_so():
    # a held force F > Fc from tick s: the thermal state after tick n is F^2 (1 - e^{-(n - s + 1) dt / tau}),
    # so it crosses Fc^2 at n - s + 1 > -tau / dt ln(1 - Fc^2 / F^2).
    touch = dp.find("touch")
    F, s = 2.0, 100
    n = np.arange(6000)
    force = np.where(n >= s, F, 0.0)[:, None] * np.array([0.0, 0.0, 1.0])
    task = make_task(np.zeros((len(n), 3)), force=force)
    f = only(fit.evaluate(task, touch))
    k = -touch.duty_time * RATE * math.log(1 - touch.continuous_force ** 2 / F ** 2)
    assert (f.verdict, f.check) == ("fails", "duty")
    assert f.first_fail_tick == s + math.floor(k)           # n - s + 1 = floor(k) + 1
    # the same force for less time passes
    short = make_task(np.zeros((s + math.floor(k) - 1, 3)), force=force[:s + math.floor(k) - 1])
    assert only(fit.evaluate(short, touch)).verdict == "fits"


def test_a_force_ramp_crosses_the_continuous_limit_at_the_tick_its_closed_form_says():
    # F = a t (t = n dt), held per tick: H_n = alpha sum_{j<=n} beta^(n-j) (a j dt)^2, beta = e^{-dt/tau};
    # the series sum_{m=0}^{n} (n-m)^2 beta^m summed directly.
    touch = dp.find("touch")
    a = 0.05                # N/s: slow enough that the duty, not the peak, fails first
    dt, tau = 1 / RATE, touch.duty_time
    beta = math.exp(-dt / tau)
    alpha = 1 - beta

    def H(n):           # the series summed directly (not the recursion the code runs)
        m = np.arange(n + 1)
        return alpha * (a * dt) ** 2 * float(np.sum((n - m) ** 2.0 * beta ** m))
    lo, hi = 0, 200000                  # H grows with n: bisect for the first n with H(n) > Fc^2
    assert H(hi) > touch.continuous_force ** 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if H(mid) > touch.continuous_force ** 2 else (mid, hi)
    n_cross = hi
    T = n_cross + 50
    n = np.arange(T)
    task = make_task(np.zeros((T, 3)), force=(a * n * dt)[:, None] * np.array([1.0, 0.0, 0.0]))
    f = only(fit.evaluate(task, touch))
    assert (f.check, f.first_fail_tick) == ("duty", n_cross)
    assert a * n_cross * dt < touch.peak_force           # the peak was never the cause


def test_a_stiffness_above_the_stable_bound_fails_at_the_first_tick_in_contact():
    touch = dp.find("touch")
    T = 1000
    contact = np.arange(T) >= 250
    task = make_task(np.zeros((T, 3)), contact=contact, stiffness=2000.0)
    f = only(fit.evaluate(task, touch))
    assert (f.check, f.first_fail_tick, f.margin) == ("stiffness", 250, 1020.0 - 2000.0)
    # a stiffness raised while in contact fails at the tick of the change
    k = np.where(np.arange(T) >= 400, 1500.0, 500.0)[:, None]
    f = only(fit.evaluate(make_task(np.zeros((T, 3)), contact=contact, stiffness=k), touch))
    assert (f.check, f.first_fail_tick) == ("stiffness", 400)
    # at a 2 kHz haptic rate the passivity bound doubles: 2000 N/m is within 2040 N/m
    task2k = make_task(np.zeros((T, 3)), contact=contact, stiffness=2000.0, rate=2000.0)
    assert only(fit.evaluate(task2k, touch)).verdict == "fits"


# ------------------------------------------------------------------------------------------ two fingers

def test_two_thimbles_passing_closer_than_their_size_fail_at_the_exact_tick():
    # fingers on the chapter's two Phantoms pass each other along x, 15 mm apart in y: the thimbles
    # (20 mm across, 20 mm between centres) touch when |0.1 - 2 v t| < sqrt(0.02^2 - 0.015^2)
    rig = dp.find("chapter_rig")
    v, T = 0.1, 700
    t = np.arange(T) / RATE
    a = np.stack([-0.05 + v * t, np.zeros(T), np.zeros(T)], axis=1)
    b = np.stack([0.05 - v * t, np.full(T, 0.015), np.zeros(T)], axis=1)
    task = make_task(np.stack([a, b], axis=1))
    r = fit.evaluate(task, rig)
    gap = math.sqrt(0.02 ** 2 - 0.015 ** 2)
    expected = math.floor((0.1 - gap) / (2 * v) * RATE) + 1
    for f in r.fingers:
        assert (f.verdict, f.check, f.first_fail_tick) == ("fails", "interference", expected)
    assert "closer than the end-effectors allow" in r.fingers[0].cause and "Finger 1" in r.fingers[0].cause


def test_fingers_that_cross_fail_where_the_kinematics_cannot_and_pass_where_they_can(tmp_path):
    rig = dp.find("chapter_rig")
    v, T = 0.1, 700
    t = np.arange(T) / RATE
    a = np.stack([-0.04 + v * t, np.full(T, -0.03), np.zeros(T)], axis=1)
    b = np.stack([0.04 - v * t, np.full(T, 0.03), np.zeros(T)], axis=1)
    task = make_task(np.stack([a, b], axis=1))
    r = fit.evaluate(task, rig)
    for f in r.fingers:                          # x_b - x_a = 0.08 - 0.2 t < 0 from tick 401
        assert (f.verdict, f.check, f.first_fail_tick) == ("fails", "crossing", 401)
    # the same task on a rig whose kinematics allow crossing
    text = open(rig.path).read().replace("can_cross = false", "can_cross = true")
    crossing = dp.load(_write(tmp_path, text, "crossing_rig.toml"))
    assert fit.evaluate(task, crossing).verdict == "fits"
    # given in the other order the arms start the other way round: they cross all the same
    swapped = fit.evaluate(task, rig, ["Finger 1", "Finger 0"])
    assert [(f.check, f.first_fail_tick) for f in swapped.fingers] == [("crossing", 401)] * 2
    # the same motion stopped before they meet does not cross
    parted = make_task(np.stack([a[:300], b[:300]], axis=1))                # stopped before meeting
    assert fit.evaluate(parted, rig).verdict == "fits"


def test_a_single_effector_device_on_a_two_finger_task_takes_the_first_and_the_other_has_none():
    task = make_task(np.zeros((10, 2, 3)))
    r = fit.evaluate(task, dp.find("touch"))
    assert [f.verdict for f in r.fingers] == ["fits", "fails"]
    assert r.fingers[1].cause == "no end-effector (the device has 1)"
    assert fit.evaluate(task, dp.find("touch"), ["Finger 1"]).verdict == "fits"


def test_several_profiles_rank_fits_before_placed_before_fails():
    t = np.arange(500) / RATE
    path = np.stack([0.045 * np.sin(2 * np.pi * t), np.zeros_like(t), np.zeros_like(t)], axis=1)   # 90 mm
    task = make_task(path, force=np.full((500, 3), 1.0))                   # 1.73 N
    results = [fit.evaluate(task, dp.find(n)) for n in ("touch", "omega3", "falcon")]
    order = [r.profile.name for r in fit.rank(results)]
    # the Touch's 0.88 N continuous limit is passed by the held 1.73 N only after its duty time: it fits
    assert [r.verdict for r in fit.rank(results)] == ["fits"] * 3
    assert set(order) == {"touch", "omega3", "falcon"}
    far = make_task(path + [0.5, 0, 0], force=np.full((500, 3), 4.0))     # 6.9 N: above the Touch's peak
    ranked = fit.rank([fit.evaluate(far, dp.find(n)) for n in ("touch", "omega3")])
    assert [(r.profile.name, r.verdict) for r in ranked] == [("omega3", "placed"), ("touch", "fails")]
    doc = fit.result_json(ranked)
    assert doc["profiles"][1]["fingers"][0]["verdict"] == "fails"
    assert doc["profiles"][1]["fingers"][0]["first_fail_time"] == 0.0
