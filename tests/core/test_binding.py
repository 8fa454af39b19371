"""The binding's tables (native/binding/graspcore_module.c): every keyword of World(), add_body,
add_finger, start and attach_serial comes with the core's default (WORLD_DEFAULTS, ...), the
Python signatures take exactly those keywords, the enum names Python shows are the ones the core
answers with, and arguments are refused with an error naming them."""
import inspect
import re
import socket
import time

import numpy as np
import pytest

import graspcore
from scenes import box_points


def test_python_add_body_takes_exactly_the_cores_body_parameters():
    """World.add_body (Python) forwards every row of the binding's body table: a parameter added
    to one side only fails here."""
    python_side = set(inspect.signature(graspcore.World.add_body).parameters) - {"self", "points", "parts", "radius"}
    assert python_side == set(graspcore.BODY_DEFAULTS)
    for name, parameter in inspect.signature(graspcore.World.add_body).parameters.items():
        if name in graspcore.BODY_DEFAULTS and isinstance(parameter.default, float):
            assert parameter.default == graspcore.BODY_DEFAULTS[name], name


def world_after_steps(**finger):
    w = graspcore.World(**graspcore.WORLD_DEFAULTS)
    w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0, 0, 0.1))
    w.add_finger(**finger)
    w.set_hip(0, (0.015, 0, 0.1))
    w.step(1e-3, steps=20)
    return w


def test_defaults_given_explicitly_change_nothing():
    """Each dict holds what the core uses when the keyword is left out (a default exported
    wrong, or a parameter read into the wrong field, changes the state hash)."""
    finger = dict(graspcore.FINGER_DEFAULTS, position=(0.02, 0, 0.1))
    assert world_after_steps(**finger).state_hash() == world_after_steps(position=(0.02, 0, 0.1)).state_hash()
    a, b = graspcore.World(), graspcore.World()
    a.add_body(box_points(0.02, 0.03, 0.01))
    b.add_body(box_points(0.02, 0.03, 0.01), **graspcore.BODY_DEFAULTS)
    assert a.body_mass(0) == b.body_mass(0) and a.body_pose(0) == b.body_pose(0)
    a.step(1e-3, steps=10), b.step(1e-3, steps=10)
    assert a.state_hash() == b.state_hash()
    w = graspcore.World()
    w.add_finger()
    w.start(**dict(graspcore.RUNTIME_DEFAULTS, realtime=False))
    try:
        w.advance(10)
        assert w.stats()["haptic_ticks"] == 10
    finally:
        w.stop()


def test_each_parameter_reaches_its_own_field():
    """One non-default value at a time lands where the world reports it (a row pointing at the
    wrong field of the definition fails here)."""
    w = graspcore.World(gravity=(0, 0, -1.0))
    b = w.add_body(box_points(0.01, 0.01, 0.01), mass=0.5, position=(1, 2, 3), mu_s=0.9, mu_d=0.2,
                   linear_velocity=(0.1, 0, 0), angular_velocity=(0, 0.2, 0), center_of_mass=(0.001, 0, 0))
    mass, com, _ = w.body_mass(b)
    assert mass == 0.5 and com == (0.001, 0.0, 0.0)
    assert w.body_pose(b)[0] == pytest.approx((1.0, 2.0, 3.0), abs=1e-12)
    lin, ang = w.body_velocity(b)
    assert ang == (0.0, 0.2, 0.0) and lin[0] == pytest.approx(0.1)
    w.step(0.5)
    assert w.body_velocity(b)[0][2] == pytest.approx(-0.5, rel=1e-5)      # gravity (0, 0, -1)
    f = w.add_finger(radius=0.004, position=(5, 6, 7), orientation=(0, 1, 0, 0))
    assert w.finger_pose(f) == ((5.0, 6.0, 7.0), (0.0, 1.0, 0.0, 0.0))
    assert graspcore.World(max_bodies=1).add_body(box_points(0.01, 0.01, 0.01)) == 0
    with pytest.raises(ValueError, match="max_bodies"):
        w1 = graspcore.World(max_bodies=1)
        w1.add_body(box_points(0.01, 0.01, 0.01))
        w1.add_body(box_points(0.01, 0.01, 0.01))


def test_positional_order_is_kept():
    """World() and add_finger still take their arguments in their old positional order."""
    w = graspcore.World((0, 0, 0), True, 4, 2)
    f = w.add_finger(0.004, 800.0, 0.1, (1, 2, 3), None, (1, 0, 0, 0), 0.0, "cursor", 0.003)
    assert w.finger_pose(f)[0] == (1.0, 2.0, 3.0)
    with pytest.raises(TypeError, match=r"add_finger\(\) takes at most 9 positional arguments \(10 given\)"):
        w.add_finger(0.004, 800.0, 0.1, (1, 2, 3), None, (1, 0, 0, 0), 0.0, "cursor", 0.003, 1)
    with pytest.raises(TypeError, match=r"start\(\) takes at most 0 positional arguments"):
        w.start(1000.0)


@pytest.mark.parametrize("call, exception, message", [
    (lambda w: w.add_finger(radus=0.01), TypeError, r"add_finger\(\) got an unexpected keyword argument 'radus'"),
    (lambda w: w.add_finger(0.01, radius=0.02), TypeError, r"multiple values for argument 'radius'"),
    (lambda w: w.add_finger(radius="big"), TypeError, r"^radius: must be a real number, not str"),
    (lambda w: w.add_finger(renderer="phong"), ValueError, r"^renderer: must be 'xfca' or 'cursor' \(got 'phong'\)"),
    (lambda w: w.add_finger(renderer=1), TypeError, r"^renderer: must be a str, not int"),
    (lambda w: w.add_finger(position=None), ValueError, r"^position: expected a sequence of 3 numbers"),
    (lambda w: w.add_finger(orientation=(1, 0, "x", 0)), ValueError, r"^orientation: item 2 is not a number"),
    (lambda w: w.start(haptic_rte=1), TypeError, r"start\(\) got an unexpected keyword argument 'haptic_rte'"),
    (lambda w: w.start(priority=2.5), TypeError, r"^priority: must be an integer, not float"),
    (lambda w: w.start(priority=2**40), OverflowError, r"^priority: outside the range of a C int"),
    (lambda w: w.attach_serial(), TypeError, r"attach_serial\(\) missing required argument 'fd'"),
    (lambda w: w.attach_serial(0, 1), TypeError, r"attach_serial\(\) takes at most 1 positional argument \(2 given\)"),
    (lambda w: w.attach_serial(0, udp_host="h" * 64), ValueError, r"^udp_host: longer than 63 bytes"),
    (lambda w: w.attach_serial(0, udp_host="a\0b"), ValueError, r"^udp_host: contains a NUL character"),
    (lambda w: w.attach_serial(0, transform=(1, 0, 0)), ValueError, r"^transform: expected a sequence of 16"),
    (lambda w: graspcore.World(max_bodies="3"), TypeError, r"^max_bodies: must be an integer, not str"),
    (lambda w: graspcore.World(gravity=(0, 0)), ValueError, r"^gravity: expected a sequence of 3 numbers"),
])
def test_bad_keyword_arguments_are_named(call, exception, message):
    w = graspcore.World()
    with pytest.raises(exception, match=message):
        call(w)
    assert w.finger_count == 0 and not w.running


def test_finger_state_names_are_the_cores():
    """FINGER_STATES[i] is the name finger_state() gives for the core's state i, in the
    snapshot's integers and the tick record's (free, stick and, for a sliding finger, slip)."""
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.5, 0.5, 0.01), static=True, mu_s=0.3, mu_d=0.2)
    free, stick, slip = (w.add_finger(radius=0.005, position=(x, 0, 0.1)) for x in (-0.2, 0.0, 0.2))
    w.set_hips(np.array([[-0.2, 0, 0.1], [0.0, 0, 0.0095], [0.2, 0, 0.0095]]))
    w.step(1e-3)
    w.set_hips(np.array([[-0.2, 0, 0.1], [0.0, 0, 0.0095], [0.3, 0, 0.0095]]))   # dragged far: slips
    w.step(1e-3)
    names = [w.finger_state(f) for f in (free, stick, slip)]
    assert names == ["free", "stick", "slip"]
    states = w.tick_record()["state"]
    assert [graspcore.FINGER_STATES[s] for s in states] == names
    assert graspcore.FINGER_STATES == ("free", "stick", "slip")
    assert [w.finger_contact(f) for f in (free, stick, slip)] == [None, 0, 0]
    assert [c["state"] for c in w.finger_contacts(stick)] == ["stick"]


def test_renderer_names_round_trip():
    assert graspcore.FINGER_DEFAULTS["renderer"] in graspcore.RENDERERS
    w = graspcore.World()
    for name in graspcore.RENDERERS:
        w.add_finger(renderer=name)
    assert w.finger_count == len(graspcore.RENDERERS)


def test_serial_names_and_stats_are_what_a_device_reports():
    """A UDP device that never answers: its state and the names of the events it raises are in
    SERIAL_STATES / SERIAL_EVENTS, estop raises the event the add-on listens for by name, and
    serial_stats() has every field of gcSerialStats, in the header's order."""
    w = graspcore.World()
    w.add_finger()
    w.start(realtime=True)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        device = w.attach_serial(sock.fileno(), udp_host="127.0.0.1", udp_port=9, **{
            k: v for k, v in graspcore.SERIAL_DEFAULTS.items() if k not in ("udp_host", "udp_port")})
        w.serial_estop(device)
        stats = w.serial_stats(device)
        assert stats["state"] in graspcore.SERIAL_STATES and stats["state"] == "waiting"
        assert list(stats) == struct_fields("gcSerialStats") and isinstance(stats["enabled"], bool)
        assert list(stats["frame_errors"]) == ["cobs", "short", "crc", "version", "type", "length", "overflow",
                                               "range"]
        events, deadline = [], time.monotonic() + 5.0
        while "estop" not in events and time.monotonic() < deadline:    # the device thread takes it
            events += [name for _, name, _, _ in w.serial_events(device)]
            time.sleep(0.005)
        assert "estop" in events and set(events) <= set(graspcore.SERIAL_EVENTS)
        w.detach_serial(device)
    finally:
        w.stop()
        sock.close()
    assert graspcore.SERIAL_EVENTS[0] == "?"


def test_accessor_rows_check_their_ids_and_the_world():
    w = graspcore.World()
    w.add_body(box_points(0.01, 0.01, 0.01))
    w.add_finger()
    for query in (w.body_pose, w.body_velocity, w.body_mass, w.residual_wrench, w.body_chain):
        with pytest.raises(ValueError, match="^body"):
            query(3)
    for query in (w.finger_pose, w.finger_force, w.finger_torque, w.god_object, w.finger_state, w.finger_contact):
        with pytest.raises(ValueError, match="^finger"):
            query(3)
    with pytest.raises(ValueError, match="^angular: item 1 is not a number"):
        w.set_body_velocity(0, (0, 0, 0), (0, "x", 0))
    with pytest.raises(ValueError, match="^orientation: expected a sequence of 4 numbers"):
        w.set_finger_pose(0, (0, 0, 0), (1, 0, 0))
    with pytest.raises(ValueError, match="^mu_d"):
        w.set_body_friction(0, 0.2, 0.5, 0.0)
    uninitialised = graspcore.World.__new__(graspcore.World)
    for call in (lambda: uninitialised.body_pose(0), lambda: uninitialised.state_hash(),
                 lambda: uninitialised.time, lambda: uninitialised.running, lambda: uninitialised.tick_log_overflow()):
        with pytest.raises(RuntimeError, match="World is not initialised"):
            call()
    assert isinstance(w.state_hash(), int) and w.chain_count() == 0 and w.stopped_bodies() == 0
    assert w.contact_overflow() == 0 and w.tick_log_overflow() == 0 and w.time == 0.0
    assert (w.body_count, w.finger_count, w.running) == (1, 1, False)


HEADER = __import__("pathlib").Path(__file__).resolve().parents[2] / "native" / "include" / "graspcore.h"


def documented_defaults(struct: str) -> dict:
    """The `default N` each field's comment in graspcore.h promises, by field name: the
    reference the exported dicts are checked against (a row reading the wrong field fails)."""
    text = HEADER.read_text()
    body = re.search(r"typedef struct %s \{(.*?)\} %s;" % (struct, struct), text, re.S).group(1)
    fields = re.split(r"\n(?=    [a-zA-Z_][\w ]*[ *](\w+)(?:\[\w+\])?;)", body)
    found = {}
    for chunk in fields:
        m = re.match(r"\s*[a-zA-Z_][\w ]*[ *](\w+)(?:\[\w+\])?;(.*)", chunk, re.S)
        if not m:
            continue
        d = re.search(r"default (?:= )?(?:\((-?\d[\d.e-]*(?:, -?\d[\d.e-]*)+)\)|(-?\d[\d.e-]*))", m.group(2))
        if d:
            found[m.group(1)] = tuple(map(float, d.group(1).split(", "))) if d.group(1) else float(d.group(2))
    return found


@pytest.mark.parametrize("struct, exported, at_least", [
    ("gcWorldDef", "WORLD_DEFAULTS", 6), ("gcBodyDef", "BODY_DEFAULTS", 4), ("gcFingerDef", "FINGER_DEFAULTS", 5),
    ("gcRuntimeDef", "RUNTIME_DEFAULTS", 10), ("gcSerialDef", "SERIAL_DEFAULTS", 7),
])
def test_exported_defaults_are_the_documented_ones(struct, exported, at_least):
    documented = documented_defaults(struct)
    values = getattr(graspcore, exported)
    checked = {name: value for name, value in documented.items() if name in values}
    assert len(checked) >= at_least, (documented, values)
    for name, value in checked.items():
        assert values[name] == pytest.approx(value), name


def test_forces_enabled_flag_is_the_records_bit():
    """TICK_FORCES_ENABLED is the bit of a record's flags that says the safety layer lets
    forces through: set in a tick whose snapshot says forces_enabled, clear before the ramp."""
    w = graspcore.World()
    w.add_finger()
    w.set_tick_log(16)
    w.start(realtime=False, hip_timeout=1.0)
    try:
        w.advance(1)       # no HIP pushed yet: forces held at zero
        first = w.snapshot()["forces_enabled"]
        w.push_hips(np.zeros((1, 3)), 0.0)
        w.advance(3)
        last = w.snapshot()["forces_enabled"]
        records = w.drain_ticks(np.zeros(16, w.tick_dtype()))
    finally:
        w.stop()
    assert (first, last) == (False, True)
    assert [bool(f & graspcore.TICK_FORCES_ENABLED) for f in records["flags"][[0, -1]]] == [first, last]


def struct_fields(struct: str) -> list:
    """The field names of a struct in graspcore.h, in order."""
    body = re.search(r"typedef struct %s \{(.*?)\} %s;" % (struct, struct), HEADER.read_text(), re.S).group(1)
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    names = []
    for declaration in body.split(";")[:-1]:
        words = re.sub(r"\[\w+\]", "", declaration).replace("*", " ").split(",")
        names += [words[0].split()[-1]] + [w.strip() for w in words[1:]]
    return names


@pytest.mark.parametrize("struct, names, left_out", [
    ("gcWorldDef", lambda: graspcore.WORLD_DEFAULTS, {}),
    ("gcBodyDef", lambda: graspcore.BODY_DEFAULTS, {"is_static": "static", "has_inertia": None,
                                                    "has_center_of_mass": None}),
    ("gcFingerDef", lambda: graspcore.FINGER_DEFAULTS, {"points": None, "num_points": None}),
    ("gcRuntimeDef", lambda: graspcore.RUNTIME_DEFAULTS, {}),
    ("gcSerialDef", lambda: graspcore.SERIAL_DEFAULTS, {}),
    ("gcRuntimeStats", lambda: graspcore.World().stats(), {}),
])
def test_every_field_of_the_core_struct_reaches_python(struct, names, left_out):
    """A field added to a definition or to the runtime's stats in graspcore.h and not to the
    binding's table fails here (the points of a convex finger and the has_* flags are given
    another way: the points argument, inertia=None)."""
    expected = {left_out.get(name, name) for name in struct_fields(struct)} - {None}
    assert expected == set(names())


def test_contact_dicts_have_every_field_of_the_core():
    """contacts() and finger_contacts() carry each field of gcContactPoint and
    gcFingerContactPoint, in the header's order, as the types the fields mean."""
    w = graspcore.World()
    w.add_body(box_points(0.2, 0.2, 0.01), static=True)
    box = w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0, 0, 0.0299))
    w.add_finger(radius=0.005, position=(0.0, 0, 0.0549))
    w.set_hip(0, (0.0, 0, 0.047))
    w.step(1e-3, steps=5)
    contacts, patch = w.contacts(), w.finger_contacts(0)
    assert contacts and patch
    assert list(contacts[0]) == struct_fields("gcContactPoint")
    assert list(patch[0]) == struct_fields("gcFingerContactPoint")
    c, p = contacts[0], patch[0]
    assert (c["body_a"], c["body_b"]) == (0, box) and isinstance(c["sticking"], bool)
    assert len(c["friction_impulse"]) == 3 and c["normal"] == pytest.approx((0, 0, 1), abs=1e-5)
    assert p["body"] == box and p["state"] in graspcore.FINGER_STATES and p["reversed"] is False
    assert p["normal"] == pytest.approx((0, 0, 1), abs=1e-5) and p["force"][2] > 0


def test_grasp_quality_record_is_the_cores():
    """grasp_quality's dict and grasp_quality_batch's records carry each field of
    gcGraspQuality (but its padding, `reserved`) at the core's offsets: the batch's rows are the
    single calls' answers, field for field."""
    assert set(graspcore.GRASP_QUALITY_DTYPE.names) == set(struct_fields("gcGraspQuality")) - {"reserved"}
    points = np.array([[0.03, 0, 0], [-0.03, 0.01, 0], [-0.03, -0.01, 0], [0, 0.03, 0.005]])
    normals = -points / np.linalg.norm(points, axis=1, keepdims=True)
    single = graspcore.grasp_quality(points, normals, 0.5, center=(0, 0, 0), radius=0.03)
    batch = graspcore.grasp_quality_batch(np.vstack([points, points[:3]]), np.vstack([normals, normals[:3]]), 0.5,
                                          [4, 3], centers=[(0, 0, 0)] * 2, radii=[0.03, 0.03])
    assert set(single) == set(graspcore.GRASP_QUALITY_DTYPE.names)
    for name in graspcore.GRASP_QUALITY_DTYPE.names:
        assert np.array_equal(np.asarray(batch[0][name]), np.asarray(single[name])), name
    assert single["force_closure"] and single["rank"] == 6 and single["epsilon"] > 0


def test_tick_fields_are_the_documented_record():
    """The core's table of tick record fields (TICK_FIELDS, which tick_dtype is built from and
    the record size summed from) is the table of docs/recording-format.md, field for field:
    name, type and shape, in order."""
    doc = (HEADER.parents[2] / "docs" / "recording-format.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| ([uif]\d\d)(?: \(([FB])((?:, \d+)*)\))? \|", doc, re.M)
    types = {"u64": "<u8", "f64": "<f8", "f32": "<f4", "u32": "<u4", "i32": "<i4"}
    scopes = {"": "once", "F": "finger", "B": "body"}
    documented = [(name, types[t], scopes[scope], tuple(int(d) for d in re.findall(r"\d+", dims)))
                  for name, t, scope, dims in rows]
    assert documented == list(graspcore._core.TICK_FIELDS)
    nb, nf = 3, 4
    assert graspcore.tick_dtype(nb, nf).itemsize == 52 + 8 * (19 * nf + 19 * nb) + 12 * nf + 32 * nf + 16   # the doc's sum
