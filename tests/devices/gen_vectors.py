"""Writes protocol_vectors.txt (run once; the tests check the file against the codecs
and against independent computations, so a change of the codec shows as a failure).

    python tests/devices/gen_vectors.py

Line format: ``ok NAME TYPE SEQ PAYLOAD_HEX WIRE_HEX`` for a valid frame (WIRE_HEX with
its 00 delimiter), ``bad NAME KIND WIRE_HEX`` for one a receiver must drop and count
under KIND (the frame decode, then the payload check of docs/protocol.md)."""
import os
import struct
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
from addon.engine.devices import protocol as P  # noqa: E402

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "protocol_vectors.txt")


def raw_frame(version, type_, seq, payload):
    body = struct.pack("<BBH", version, type_, seq) + payload
    return body + struct.pack("<H", P.crc16(body))


def main():
    ok = [
        ("hello_host", P.HELLO_HOST, 0, P.hello_host(1000)),
        ("hello_device", P.HELLO_DEVICE, 0, P.hello_device(5, True, P.UNITS_METRE, 1000, 4.0, 50, "grasp-lab-emulator")),
        ("hello_device_mm", P.HELLO_DEVICE, 1, P.hello_device(1, False, P.UNITS_MILLIMETRE, 250, 0.0, 0)),
        ("pose_2", P.POSE, 7, P.pose(123456, [(0.01, 0.02, 0.03), (-0.01, 0.0, 0.5)], P.STATUS_FORCES_ON)),
        ("force_2", P.FORCE, 8, P.force(7, 20000, [(0.0, 0.0, 1.5), (0.25, -0.5, 0.0)])),
        ("enable_wrap", P.ENABLE, 0xFFFF, P.enable(True)),
        ("disable", P.ENABLE, 3, P.enable(False)),
        ("estop_button", P.ESTOP, 9, P.estop(P.ESTOP_BUTTON)),
        ("heartbeat", P.HEARTBEAT, 0x1234, P.heartbeat(0xDEADBEEF)),
        ("pose_32", P.POSE, 0x0100, P.pose(0xFFFFFFFF, [(0.1234567 + i * 0.001, -0.25 - i * 0.002, 0.75 + i * 0.003)
                                                       for i in range(32)], P.STATUS_GRIP)),
        # Orientations (HELLO_DEVICE flags bit 1, FORCE flags bit 0, POSE 6 + 28 n).
        ("hello_device_oriented", P.HELLO_DEVICE, 2, P.hello_device(2, True, P.UNITS_METRE, 1000, 4.0, 50, "hand",
                                                                    orientations=True)),
        ("force_takes_orientation", P.FORCE, 9, P.force(8, 20000, [(0.0, 0.0, 1.5), (0.25, -0.5, 0.0)],
                                                        takes_orientations=True)),
        ("pose_2_oriented", P.POSE, 8, P.pose(123456, [(0.01, 0.02, 0.03), (-0.01, 0.0, 0.5)], P.STATUS_FORCES_ON,
                                              [(0.9848077297210693, 0.1736481785774231, 0.0, 0.0),
                                               (0.5, 0.5, 0.5, 0.5)])),
        ("pose_32_oriented", P.POSE, 0x0101, P.pose(7, [(0.01 * i, 0.0, -0.01 * i) for i in range(32)], 0,
                                                    [(1.0, 0.0, 0.0, 0.0) if i % 2 else (0.0, 0.0, 0.0, -1.0)
                                                     for i in range(32)])),
    ]
    pose2 = P.pose(1, [(0.01, 0.02, 0.03), (0.0, 0.0, 0.0)])
    nan_pose = bytearray(pose2)
    nan_pose[6:10] = struct.pack("<f", float("nan"))
    good = bytearray(raw_frame(1, P.POSE, 5, pose2))
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0x01
    oriented = P.pose(1, [(0.01, 0.02, 0.03)], 0, [(1.0, 0.0, 0.0, 0.0)])
    nan_turn, scaled_turn = bytearray(oriented), bytearray(oriented)
    nan_turn[22:26] = struct.pack("<f", float("nan"))           # x of the finger's quaternion
    scaled_turn[18:34] = struct.pack("<ffff", 2.0, 0.0, 0.0, 0.0)
    bad = [
        ("crc", "crc", P.cobs_encode(bytes(bad_crc)) + b"\0"),
        ("version", "version", P.cobs_encode(raw_frame(2, P.HEARTBEAT, 0, P.heartbeat(0))) + b"\0"),
        ("type", "type", P.cobs_encode(raw_frame(1, 0x7F, 0, b"")) + b"\0"),
        ("length", "length", P.cobs_encode(raw_frame(1, P.POSE, 0, pose2[:-12])) + b"\0"),
        ("length_enable", "length", P.cobs_encode(raw_frame(1, P.ENABLE, 0, b"\x01\x00")) + b"\0"),
        ("short", "short", P.cobs_encode(b"\x01\x03\x00") + b"\0"),
        ("cobs", "cobs", bytes([0x05, 0x01, 0x03]) + b"\0"),
        ("nan", "range", P.cobs_encode(raw_frame(1, P.POSE, 0, bytes(nan_pose))) + b"\0"),
        ("length_oriented", "length", P.cobs_encode(raw_frame(1, P.POSE, 0, oriented[:-4])) + b"\0"),
        ("nan_orientation", "range", P.cobs_encode(raw_frame(1, P.POSE, 0, bytes(nan_turn))) + b"\0"),
        ("scaled_orientation", "range", P.cobs_encode(raw_frame(1, P.POSE, 0, bytes(scaled_turn))) + b"\0"),
    ]
    with open(OUT, "w") as fh:
        fh.write("# Grasp Lab serial protocol v1 test vectors (docs/protocol.md); written by gen_vectors.py\n")
        fh.write("# ok NAME TYPE SEQ PAYLOAD_HEX WIRE_HEX | bad NAME KIND WIRE_HEX  (hex '-' = empty)\n")
        for name, type_, seq, payload in ok:
            fh.write(f"ok {name} {type_} {seq} {payload.hex() or '-'} {P.encode(type_, seq, payload).hex()}\n")
        for name, kind, wire in bad:
            fh.write(f"bad {name} {kind} {wire.hex()}\n")


if __name__ == "__main__":
    main()
