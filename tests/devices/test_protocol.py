"""The serial protocol codec (docs/protocol.md) against the test vectors, independent
computations (CRC check value, binascii's CRC, the COBS paper's examples) and fuzzing."""
import math
import os
import random
import struct

import numpy as np
import pytest

from addon.engine.devices import protocol as P

VECTORS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "protocol_vectors.txt")


def load_vectors():
    ok, bad = [], []
    with open(VECTORS) as fh:
        for line in fh:
            if line.startswith("#") or not line.strip():
                continue
            f = line.split()
            unhex = (lambda s: b"" if s == "-" else bytes.fromhex(s))
            if f[0] == "ok":
                ok.append((f[1], int(f[2]), int(f[3]), unhex(f[4]), unhex(f[5])))
            else:
                bad.append((f[1], f[2], unhex(f[3])))
    return ok, bad


OK, BAD = load_vectors()


def test_crc_check_value():
    # The catalogue check value of CRC-16/CCITT-FALSE.
    assert P.crc16(b"123456789") == 0x29B1
    assert P.crc16(b"") == 0xFFFF


def bitwise_crc16(data):
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_crc_matches_a_bitwise_computation_on_random_data():
    rng = random.Random(1)
    assert bitwise_crc16(b"123456789") == 0x29B1
    for n in range(0, 300, 7):
        data = bytes(rng.getrandbits(8) for _ in range(n))
        assert P.crc16(data) == bitwise_crc16(data)


@pytest.mark.parametrize("data, wire", [
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(0, 255)), b"\x01\xff" + bytes(range(1, 255))),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
])
def test_cobs_reference_examples(data, wire):
    assert P.cobs_encode(data) == wire
    assert P.cobs_decode(wire) == data


def test_cobs_round_trip_random():
    rng = random.Random(2)
    for _ in range(300):
        n = rng.randrange(0, 700)
        data = bytes(rng.choice((0, rng.getrandbits(8))) for _ in range(n))
        enc = P.cobs_encode(data)
        assert 0 not in enc
        assert len(enc) <= n + n // 254 + 1
        assert P.cobs_decode(enc) == data


@pytest.mark.parametrize("name, type_, seq, payload, wire", OK, ids=[v[0] for v in OK])
def test_vector_round_trip(name, type_, seq, payload, wire):
    assert wire[-1] == 0 and 0 not in wire[:-1]
    assert P.encode(type_, seq, payload) == wire
    assert P.decode(wire[:-1]) == (type_, seq, payload)
    body = P.cobs_decode(wire[:-1])
    assert body[:4] == struct.pack("<BBH", 1, type_, seq)
    assert struct.unpack("<H", body[-2:])[0] == bitwise_crc16(body[:-2])


def test_vector_payload_fields():
    by_name = {v[0]: v for v in OK}
    hello = P.parse_hello_device(by_name["hello_device"][3])
    assert hello == P.HelloDevice(5, True, P.UNITS_METRE, 1000, 4.0, 50, "grasp-lab-emulator")
    pose = P.parse_pose(by_name["pose_2"][3])
    assert pose.time_us == 123456 and pose.status == P.STATUS_FORCES_ON
    assert pose.positions[1] == pytest.approx((-0.01, 0.0, 0.5), abs=1e-7)
    force = P.parse_force(by_name["force_2"][3])
    assert force.ack_seq == 7 and force.ttl_us == 20000
    assert force.forces == ((0.0, 0.0, 1.5), (0.25, -0.5, 0.0))
    assert P.parse_heartbeat(by_name["heartbeat"][3]) == 0xDEADBEEF
    assert len(P.parse_pose(by_name["pose_32"][3]).positions) == 32
    assert P.parse_pose(by_name["pose_32"][3]).orientations is None


def test_orientation_vectors():
    """Orientations: offered in the hello (flags bit 1), taken in the FORCE (flags bit 0), sent
    after the positions (6 + 28 n), each a float32 unit quaternion."""
    by_name = {v[0]: v for v in OK}
    hello = P.parse_hello_device(by_name["hello_device_oriented"][3])
    assert hello == P.HelloDevice(2, True, P.UNITS_METRE, 1000, 4.0, 50, "hand", True)
    assert by_name["hello_device_oriented"][3][1] == 0x03
    assert not P.parse_hello_device(by_name["hello_device"][3]).orientations
    force = P.parse_force(by_name["force_takes_orientation"][3])
    assert force.takes_orientations and force.forces == ((0.0, 0.0, 1.5), (0.25, -0.5, 0.0))
    assert by_name["force_takes_orientation"][3][5] == 0x01
    assert not P.parse_force(by_name["force_2"][3]).takes_orientations
    pose = P.parse_pose(by_name["pose_2_oriented"][3])
    assert len(by_name["pose_2_oriented"][3]) == 6 + 28 * 2
    assert pose.positions == P.parse_pose(by_name["pose_2"][3]).positions
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    np.testing.assert_allclose(pose.orientations, [(c, s, 0, 0), (0.5, 0.5, 0.5, 0.5)], atol=1e-7)
    pose = P.parse_pose(by_name["pose_32_oriented"][3])
    assert len(pose.orientations) == 32 and pose.orientations[0] == (0.0, 0.0, 0.0, -1.0)


@pytest.mark.parametrize("turns, match", [
    ([(1.0, 0.0, 0.0)], "range: pose: orientation"),
    ([(2.0, 0.0, 0.0, 0.0)], "range: pose: orientation"),
    ([(0.0, 0.0, 0.0, 0.0)], "range: pose: orientation"),
    ([(float("nan"), 0.0, 0.0, 0.0)], "range: pose: orientation"),
    ([(1.0, 0.0, 0.0, 0.0)] * 2, "length: pose: 2 orientations for 1 fingers"),
])
def test_pose_encoder_refuses_bad_orientations(turns, match):
    with pytest.raises(P.ProtocolError, match=match):
        P.pose(0, [(0.0, 0.0, 0.0)], 0, turns)


def parse_payload(frame):
    return {P.POSE: P.parse_pose, P.FORCE: P.parse_force, P.HELLO_DEVICE: P.parse_hello_device}.get(
        frame.type, lambda p: p)(frame.payload)


@pytest.mark.parametrize("name, kind, wire", BAD, ids=[v[0] for v in BAD])
def test_bad_vectors_are_rejected_by_kind(name, kind, wire):
    with pytest.raises(P.ProtocolError) as info:
        parse_payload(P.decode(wire[:-1]))
    assert info.value.kind == kind


def test_stream_decoder_counts_and_resynchronises():
    dec = P.StreamDecoder()
    stream = b"".join(w for _, _, w in BAD if _ != "range") + b"".join(v[4] for v in OK)
    frames = dec.feed(stream)
    assert [f.type for f in frames] == [v[1] for v in OK]
    assert dec.errors == {"cobs": 1, "short": 1, "crc": 1, "version": 1, "type": 1, "length": 3, "overflow": 0}


def test_stream_decoder_byte_by_byte_and_overflow():
    dec = P.StreamDecoder()
    wire = OK[3][4]
    # A run longer than any frame, then a frame: the run counts once as overflow.
    frames = []
    for byte in b"\x07" * (P.MAX_WIRE + 10) + b"\x00" + wire:
        frames += dec.feed(bytes([byte]))
    assert frames == [P.decode(wire[:-1])]
    assert dec.errors["overflow"] == 1 and dec.dropped == 1


def test_fuzzed_decoder_never_crashes_and_resynchronises():
    rng = random.Random(3)
    good = [v[4] for v in OK]
    for trial in range(400):
        dec = P.StreamDecoder()
        noise = bytes(rng.getrandbits(8) for _ in range(rng.randrange(1, 800)))
        # Noise, then a delimiter, then known frames in random chunks.
        tail = b"\x00" + b"".join(rng.choice(good) for _ in range(5))
        data = noise + tail
        out = []
        i = 0
        while i < len(data):
            n = rng.randrange(1, 64)
            out += dec.feed(data[i:i + n])
            i += n
        tail_frames = P.StreamDecoder().feed(tail)
        assert out[-len(tail_frames):] == tail_frames, trial
        assert dec.frames == len(out)


def test_fuzzed_single_bit_flips_are_caught():
    rng = random.Random(4)
    for _ in range(500):
        name, type_, seq, payload, wire = rng.choice(OK)
        body = bytearray(P.cobs_decode(wire[:-1]))
        bit = rng.randrange(8 * len(body))
        body[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(P.ProtocolError):
            P.decode(P.cobs_encode(bytes(body)))


def test_encoders_reject_bad_values():
    with pytest.raises(P.ProtocolError, match="range: pose"):
        P.pose(0, [(0.0, float("nan"), 0.0)])
    with pytest.raises(P.ProtocolError, match="n_fingers"):
        P.hello_device(0, True, 0, 1000, 1.0, 10)
    with pytest.raises(P.ProtocolError, match="fingers outside"):
        P.force(0, 100, [(0, 0, 0)] * 33)


def test_protocol_doc_worked_examples_decode():
    import re
    doc = open(os.path.join(os.path.dirname(VECTORS), "..", "..", "docs", "protocol.md")).read()
    wires = re.findall(r"^    wire  ([0-9a-f ]+)$", doc, flags=re.M)
    bodies = re.findall(r"^    body  ([0-9a-f |]+?)\s+\(crc 0x([0-9A-F]{4})\)$", doc, flags=re.M)
    assert len(wires) == len(bodies) == 8
    types = set()
    for wire, (body, crc) in zip(wires, bodies):
        raw = bytes.fromhex(wire.replace(" ", ""))
        assert raw[-1] == 0 and 0 not in raw[:-1]
        body = bytes.fromhex(body.replace("|", "").replace(" ", ""))
        assert P.cobs_decode(raw[:-1]) == body
        assert bitwise_crc16(body[:-2]) == int(crc, 16) == body[-2] | body[-1] << 8   # the stated CRC, little-endian
        frame = P.decode(raw[:-1])
        assert P.encode(*frame) == raw
        types.add(frame.type)
    assert types == set(range(1, 8)), "a worked example of every frame type"
    # The example fields the text states.
    decoded = [P.decode(bytes.fromhex(w.replace(" ", ""))[:-1]) for w in wires]
    frames = {f.type: f for f in decoded if f.type != P.POSE or len(f.payload) == 6 + 12}
    oriented = [P.parse_pose(f.payload) for f in decoded if f.type == P.POSE and len(f.payload) == 6 + 28]
    assert len(oriented) == 1
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    assert oriented[0].positions == P.parse_pose(frames[P.POSE].payload).positions
    np.testing.assert_allclose(oriented[0].orientations, [(c, s, 0, 0)], atol=1e-7)      # float32
    hello = P.parse_hello_device(frames[P.HELLO_DEVICE].payload)
    assert (hello.n_fingers, hello.renders_forces, hello.rate_hz, hello.force_max, hello.ttl_max_ms, hello.name) == \
        (2, True, 1000, 4.0, 50, "hand")
    force = P.parse_force(frames[P.FORCE].payload)
    assert (force.ack_seq, force.ttl_us, force.forces) == (7, 20000, ((0.0, 0.0, 1.5), (0.25, -0.5, 0.0)))
    assert P.parse_u8(frames[P.ESTOP].payload) == P.ESTOP_BUTTON and P.parse_u8(frames[P.ENABLE].payload) == 1


def test_protocol_doc_sizes_are_the_codecs():
    """Section 1's sizes: the largest body and encoding, as the codecs define them."""
    import re
    doc = open(os.path.join(os.path.dirname(VECTORS), "..", "..", "docs", "protocol.md")).read()
    assert f"a body of 4 + 390 + 2 = **{P.DEVICE_MAX_BODY} bytes**" in doc
    assert f"an encoding of at most 396 + 2\n  = **{P.DEVICE_MAX_WIRE} bytes**" in doc
    assert f"a body of 4 + 902 + 2 = **{P.MAX_BODY}\n  bytes**" in doc
    assert f"an encoding of at most 908 + 4 = **{P.MAX_WIRE} bytes**" in doc
    largest_force = P.encode(P.FORCE, 0, P.force(0, 1, [(1.0, 2.0, 3.0)] * 32))
    assert len(largest_force) - 1 <= P.DEVICE_MAX_WIRE and len(P.cobs_decode(largest_force[:-1])) == P.DEVICE_MAX_BODY
    one = (1.0, 0.0, 0.0, 0.0)
    largest = P.encode(P.POSE, 0, P.pose(0, [(1.0, 2.0, 3.0)] * 32, orientations=[one] * 32))
    assert len(largest) - 1 <= P.MAX_WIRE and len(P.cobs_decode(largest[:-1])) == P.MAX_BODY
    # The worst case of COBS: no zero at all in a body of the largest size.
    assert len(P.cobs_encode(b"\x01" * P.MAX_BODY)) == P.MAX_WIRE
    assert not re.search(r"\b398 bytes and its encoding\b", doc)
