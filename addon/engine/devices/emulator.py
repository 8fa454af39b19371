"""The reference device emulator: a Grasp Lab serial device (docs/protocol.md) in software.

    python -m addon.engine.devices.emulator (--pty | PORT) [--fingers N]
        [--motion NAME | --from SCENE.blend [--first K]] [--orientation NAME] [--rate HZ] [--duration S]
        [--estop-at S] [--force-log PATH]

With ``--pty`` it opens a pseudo-terminal in raw mode and prints ``PORT /dev/pts/N`` as its
first line; the host opens that path. After the host's hello it answers with its
capabilities and streams pose frames at the rate, playing a named motion (``MOTIONS``)
or the fingertip animation of a .blend. It behaves as firmware must: forces stay off
until ENABLE(1), each force frame lives for its TTL, an e-stop latches. It checks every
force frame it gets (finger count, NaN, the force limit, the TTL limit, forces while
disabled), measures pose-to-force latency by the acknowledged sequence number, and prints
a report (``REPORT {json}``) when it ends (duration, SIGTERM or SIGINT). ``--estop-at S``
presses its stop button S seconds into streaming (ESTOP(1) sent, forces latched off until
ENABLE(1)); ``--force-log PATH`` writes every force frame it received (CSV: time since its
streaming started, ack_seq, ttl_us, then fx fy fz per finger, exactly as sent). ``--orientation
NAME`` offers each finger's orientation in its hello and sends it in every pose once the host's
force frames say they take it (a convex finger turns with it).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import select
import signal
import sys
import time
import tty

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))))
    from addon.engine.devices import protocol as P  # noqa: E402
else:
    from . import protocol as P


# ---- motions: fingertip positions (device metres) of n fingers at time t ---------------

def _ring(n, radius, z):
    if n == 1:
        return [(radius, 0.0, z)]
    return [(radius * math.cos(2 * math.pi * i / n), radius * math.sin(2 * math.pi * i / n), z) for i in range(n)]


def motion_static(t, n):
    return _ring(n, 0.06, 0.0)


def motion_grip(t, n):
    """Close from 6 cm to 3 cm from the centre over 0.5 s, then hold."""
    return _ring(n, 0.06 - 0.03 * min(1.0, t / 0.5), 0.0)


def motion_pinch(t, n):
    """Close and open every 4 s (3 to 6 cm from the centre)."""
    return _ring(n, 0.045 + 0.015 * math.cos(2 * math.pi * t / 4.0), 0.0)


def motion_circle(t, n):
    """The whole hand circles 2 cm around the centre every 2 s, 6 cm open."""
    cx, cy = 0.02 * math.cos(math.pi * t), 0.02 * math.sin(math.pi * t)
    return [(x + cx, y + cy, z) for x, y, z in _ring(n, 0.06, 0.0)]


def motion_lift(t, n):
    """Grip (0.5 s), then lift 5 cm over 1 s and hold."""
    z = 0.05 * min(1.0, max(0.0, t - 0.5))
    return _ring(n, 0.06 - 0.03 * min(1.0, t / 0.5), z)


MOTIONS = {"static": motion_static, "grip": motion_grip, "pinch": motion_pinch, "circle": motion_circle,
           "lift": motion_lift}


# ---- orientations (--orientation): each finger's unit quaternion (w, x, y, z, device axes) --

def orientation_level(t, n):
    return [(1.0, 0.0, 0.0, 0.0)] * n


def orientation_tilt(t, n):
    """Level for 0.5 s, then tilted 20 degrees about the device's x axis over 1 s, then held."""
    a = math.radians(20.0) * min(1.0, max(0.0, t - 0.5))
    return [(math.cos(a / 2), math.sin(a / 2), 0.0, 0.0)] * n


ORIENTATIONS = {"level": orientation_level, "tilt": orientation_tilt}


# ---- the device -------------------------------------------------------------------------

HOST_SILENCE = 0.3      # s without an answer to a pose: the host is not streaming with this device

class ForceChecker:
    """Every force frame against the device's rules; counts what broke them."""

    def __init__(self, n_fingers, force_max, ttl_max_ms):
        self.n, self.force_max, self.ttl_max_us = n_fingers, force_max, ttl_max_ms * 1000
        self.frames = 0
        self.violations = dict.fromkeys(("fingers", "nan", "over_limit", "ttl", "while_disabled"), 0)
        self.max_norm = 0.0
        self.last_ttl_us = 0

    def check(self, force: "P.Force", enabled: bool) -> list:
        """The forces the device renders (clamped; zero when disabled), noting violations."""
        self.frames += 1
        self.last_ttl_us = force.ttl_us
        if len(force.forces) != self.n:
            self.violations["fingers"] += 1
            return [(0.0, 0.0, 0.0)] * self.n
        if (self.ttl_max_us and force.ttl_us > self.ttl_max_us) or force.ttl_us == 0:
            self.violations["ttl"] += 1     # rejected: zero every force (protocol.md section 3)
            return [(0.0, 0.0, 0.0)] * self.n
        out = []
        for f in force.forces:
            norm = math.sqrt(sum(c * c for c in f))
            if norm != norm:
                self.violations["nan"] += 1
                f, norm = (0.0, 0.0, 0.0), 0.0
            if norm > self.force_max * (1 + 1e-6) + 1e-6:
                self.violations["over_limit"] += 1
                f = tuple(c * self.force_max / norm for c in f)
            if norm > 0 and not enabled:
                self.violations["while_disabled"] += 1
                f = (0.0, 0.0, 0.0)
            self.max_norm = max(self.max_norm, min(norm, self.force_max))
            out.append(f)
        return out


def _percentile(sorted_values, q):
    if not sorted_values:
        return None
    return sorted_values[min(len(sorted_values) - 1, int(math.ceil(q * len(sorted_values))) - 1)]


class Emulator:
    def __init__(self, fd, n_fingers=2, motion=motion_grip, rate=1000.0, force_max=5.0, ttl_max_ms=50,
                 renders_forces=True, name="grasp-lab-emulator", corrupt_every=0, estop_at=None, log_forces=False,
                 udp=None, drop_every=0, dup_every=0, reorder_every=0, orientation=None):
        self.fd = fd
        self.n = int(n_fingers)
        self.motion = motion
        self.orientation = orientation      # (t, n) -> quaternions: offered in the hello (CAP_ORIENTATION)
        self.host_takes_orientations = False    # until a FORCE frame says so (protocol.md section 2)
        self.oriented_poses = 0
        self.rate = float(rate)
        self.hello = P.hello_device(self.n, renders_forces, P.UNITS_METRE, int(rate), force_max, ttl_max_ms, name,
                                    orientations=orientation is not None)
        self.decoder = P.StreamDecoder()
        self.checker = ForceChecker(self.n, force_max, ttl_max_ms)
        self.corrupt_every = int(corrupt_every)
        self.seq = 0
        self.enabled = False
        self.estopped = False
        self.host_hellos = 0
        self.sent_at = {}          # pose seq -> send time, until acknowledged
        self.latencies = []        # s, pose sent -> its force frame received
        self.force_expiry = 0.0    # the applied force lives until then
        self.ttl_expiries = 0
        self.rendered = [(0.0, 0.0, 0.0)] * self.n
        self.poses_sent = 0
        self.write_errors = 0
        self.stop = False
        self.started = None         # the host's conversation started (see _on_frame)
        self.last_answer = None     # when the host last answered a pose (a force frame)
        self.say = None             # a line for whoever runs it (main: standard output), e.g. its button
        self.answered = False       # the host has answered a pose in this conversation (it streams)
        self.estop_at = estop_at    # s into streaming: the stop button (None: never)
        self.estop_sent_at = None
        self.forces_after_estop = 0     # non-zero force frames answering a pose sent after the button (a host
                                        # that had read it), before ENABLE(1)
        self.forces_in_flight = 0       # non-zero ones answering a pose sent before it (on their way then)
        self.estop_seq = None           # the sequence number of its ESTOP frame
        self.force_log = [] if log_forces else None     # (t, ack_seq, ttl_us, forces) of every force frame
        # UDP (--udp): a bound socket; frames go to the host that said hello (others are ignored).
        self.udp, self.host_addr, self.foreign = udp, None, 0
        self.drop_every, self.dup_every, self.reorder_every = int(drop_every), int(dup_every), int(reorder_every)
        self.held = None            # a pose held back, to be sent after the next one (reordering)
        self.injected = dict.fromkeys(("dropped", "duplicated", "reordered"), 0)

    def _send(self, type_, payload):
        frame = P.encode(type_, self.seq, payload)
        if self.corrupt_every and type_ == P.POSE and self.seq % self.corrupt_every == 0:
            frame = frame[:2] + bytes([frame[2] ^ 0x40 or 1]) + frame[3:]   # a CRC error, still framed
        seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        if self.udp is None:
            self._write(frame)
            return
        # The network's faults, injected on poses: lost, duplicated, delivered after the next one.
        if type_ == P.POSE and self.drop_every and seq % self.drop_every == 0:
            self.injected["dropped"] += 1
            return
        if type_ == P.POSE and self.reorder_every and seq % self.reorder_every == 0 and self.held is None:
            self.held = frame
            self.injected["reordered"] += 1
            return
        self._write(frame)
        if type_ == P.POSE and self.dup_every and seq % self.dup_every == 0:
            self._write(frame)
            self.injected["duplicated"] += 1
        if self.held is not None and type_ == P.POSE:
            held, self.held = self.held, None
            self._write(held)

    def _write(self, frame):
        try:
            if self.udp is None:
                if os.write(self.fd, frame) < len(frame):
                    self.write_errors += 1    # the pty full: the rest of the frame lost, the host drops it
            elif self.host_addr is not None:
                self.udp.sendto(frame, self.host_addr)
        except (BlockingIOError, OSError):
            self.write_errors += 1

    def _on_frame(self, frame, now):
        # A hello starts a new conversation, and the motion, --estop-at and --duration count from
        # there, unless the host has answered a pose within HOST_SILENCE: a host that streams
        # answers every pose, and re-says hello only while it waits for poses that stopped. A
        # Find Devices probe never answers poses: the session after it sees the motion from its start.
        new_conversation = self.last_answer is None or now - self.last_answer > HOST_SILENCE
        if frame.type == P.FORCE:
            self.last_answer = now
            self.answered = True
        if frame.type == P.HELLO_HOST:
            self.host_hellos += 1       # a (re)started host: forces off until it enables them again
            self.enabled = False
            self.host_takes_orientations = False    # and positions only until its FORCE frames take orientations
            self.rendered = [(0.0, 0.0, 0.0)] * self.n
            self._send(P.HELLO_DEVICE, self.hello)
            if new_conversation:
                self.started = now
                self.answered = False
                if self.estop_sent_at is not None:  # the script's button, pressed to nobody: pressed in this one
                    self.estop_sent_at, self.estopped = None, False
        elif frame.type == P.ENABLE:
            self.enabled = P.parse_u8(frame.payload) == 1   # any other value is off; ENABLE(1) clears an e-stop
            self.estopped = self.estopped and not self.enabled
        elif frame.type == P.ESTOP:
            self.enabled, self.estopped = False, True
        elif frame.type == P.FORCE:
            try:
                force = P.parse_force(frame.payload)
            except P.ProtocolError:
                self.checker.violations["nan"] += 1
                self.rendered = [(0.0, 0.0, 0.0)] * self.n      # a rejected frame zeroes every force
                return
            self.rendered = self.checker.check(force, self.enabled)
            self.host_takes_orientations = force.takes_orientations and self.orientation is not None
            if self.estopped and any(any(f) for f in force.forces):
                after = self.estop_seq is not None and 0 < (force.ack_seq - self.estop_seq) & 0xFFFF < 0x8000
                if after:
                    self.forces_after_estop += 1
                else:
                    self.forces_in_flight += 1
            if self.force_log is not None:
                self.force_log.append((now - (self.started or now), force.ack_seq, force.ttl_us, force.forces))
            self.force_expiry = now + force.ttl_us * 1e-6
            sent = self.sent_at.pop(force.ack_seq, None)
            if sent is not None:
                self.latencies.append(now - sent)

    def _read(self, timeout):
        r, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        if not r:
            return
        if self.udp is not None:
            self._read_datagrams()
            return
        try:
            data = os.read(self.fd, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:       # the host side is gone (EIO on a pty)
            time.sleep(max(0.0, timeout))
            return
        now = time.perf_counter()
        for frame in self.decoder.feed(data):
            self._on_frame(frame, now)

    def _read_datagrams(self):
        now = time.perf_counter()
        while True:
            try:
                data, addr = self.udp.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:         # an ICMP error from an earlier send (the host is gone)
                continue
            frames = self.decoder.feed(data if data.endswith(b"\0") else data + b"\0")
            if self.host_addr is None and any(f.type == P.HELLO_HOST for f in frames):
                self.host_addr = addr       # the host that said hello: the only one from now on
            if addr != self.host_addr:
                self.foreign += 1
                continue
            for frame in frames:
                self._on_frame(frame, now)

    def run(self, duration=None, wait_hello=30.0):
        """Streams poses once the host has said hello (``wait_hello`` seconds at most; 0 or
        None: as long as it takes), for ``duration`` seconds (None: until stopped)."""
        t_open = time.perf_counter()
        while self.started is None and not self.stop:
            if wait_hello and time.perf_counter() - t_open > wait_hello:
                raise TimeoutError(f"no hello from the host within {wait_hello} s")
            self._read(0.05)
        period = 1.0 / self.rate
        next_t = time.perf_counter()
        while not self.stop:
            now = time.perf_counter()
            t = now - self.started
            if duration is not None and t >= duration:
                break
            if self.force_expiry and now > self.force_expiry and any(any(f) for f in self.rendered):
                self.ttl_expiries += 1        # the host went quiet: the device lets go by itself
                self.rendered = [(0.0, 0.0, 0.0)] * self.n
            if self.estop_at is not None and self.estop_sent_at is None and t >= self.estop_at:
                self.estop_sent_at = t        # the stop button: forces off at once, latched, and said so
                self.estop_seq = self.seq
                self.enabled, self.estopped = False, True
                self.rendered = [(0.0, 0.0, 0.0)] * self.n
                self._send(P.ESTOP, P.estop(P.ESTOP_BUTTON))
                if self.say is not None:    # a test waits for this, not for a time: who got it
                    self.say(f"ESTOP {t:.3f} {'streaming' if self.answered else 'unanswered'}")
            status = (P.STATUS_FORCES_ON if self.enabled else 0) | (P.STATUS_ESTOPPED if self.estopped else 0)
            positions = self.motion(t, self.n)
            turns = self.orientation(t, self.n) if self.host_takes_orientations else None
            self._send(P.POSE, P.pose(int(t * 1e6), positions, status, turns))
            self.oriented_poses += turns is not None
            self.sent_at[(self.seq - 1) & 0xFFFF] = now
            if len(self.sent_at) > 4096:     # never acknowledged: forget the oldest
                for k in list(self.sent_at)[:2048]:
                    del self.sent_at[k]
            self.poses_sent += 1
            next_t += period
            if next_t < time.perf_counter() - 0.1:     # far behind (suspended): do not burst
                next_t = time.perf_counter()
            while not self.stop:
                remaining = next_t - time.perf_counter()
                if remaining <= 0:
                    break
                self._read(remaining)
        return self.report(time.perf_counter() - (self.started or t_open))

    def report(self, elapsed):
        lat = sorted(self.latencies)
        c = self.checker
        return {
            "fingers": self.n, "rate_hz": self.rate, "elapsed_s": round(elapsed, 3),
            "host_hellos": self.host_hellos, "poses_sent": self.poses_sent,
            "force_frames": c.frames, "force_rate_hz": round(c.frames / elapsed, 1) if elapsed > 0 else 0.0,
            "enabled": self.enabled, "estopped": self.estopped,
            "violations": c.violations, "ttl_expiries": self.ttl_expiries, "last_ttl_us": c.last_ttl_us,
            "max_force_n": round(c.max_norm, 6), "rendered": [list(f) for f in self.rendered],
            "latency_p50_ms": _ms(_percentile(lat, 0.50)), "latency_p99_ms": _ms(_percentile(lat, 0.99)),
            "latency_max_ms": _ms(lat[-1] if lat else None), "unacknowledged": self.poses_sent - len(lat),
            "host_frames_dropped": self.decoder.errors, "write_errors": self.write_errors,
            "estop_at_s": self.estop_sent_at, "forces_after_estop": self.forces_after_estop,
            "forces_in_flight_at_estop": self.forces_in_flight,
            "injected": self.injected, "foreign_datagrams": self.foreign, "oriented_poses": self.oriented_poses,
        }

    def write_force_log(self, path):
        with open(path, "w") as fh:
            for t, ack, ttl, forces in self.force_log or ():
                fh.write(",".join([repr(t), str(ack), str(ttl)] + [repr(c) for f in forces for c in f]) + "\n")


def _ms(v):
    return None if v is None else round(v * 1e3, 4)


def open_pty():
    """A raw-mode pseudo-terminal: (master fd the emulator uses, slave fd kept open, slave path)."""
    master, slave = os.openpty()
    tty.setraw(slave)          # no echo, no line discipline: bytes pass unchanged
    tty.setraw(master)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def build_parser(parser=None):
    p = parser or argparse.ArgumentParser(prog="grasp-lab emulate", description=__doc__.split("\n\n")[0])
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="open a pseudo-terminal and print its path")
    where.add_argument("port", nargs="?", help="a serial port to speak on (e.g. one end of a null-modem pair)")
    where.add_argument("--udp", type=int, metavar="PORT",
                       help="speak UDP on 127.0.0.1:PORT (0: a free port); prints 'PORT udp:127.0.0.1:N'")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--motion", default="grip", choices=sorted(MOTIONS), help="named demo motion (default grip)")
    what.add_argument("--from", dest="from_blend", metavar="SCENE.blend", help="play the fingertip animation of a .blend")
    p.add_argument("--orientation", choices=sorted(ORIENTATIONS), default=None,
                   help="also send each finger's orientation (offered in the hello; sent once the host's force "
                        "frames take them): level, or tilt (20 deg about x from 0.5 s to 1.5 s)")
    p.add_argument("--fingers", type=int, default=None,
                   help="fingertips (default 2; with --from, the scene's from --first on)")
    p.add_argument("--first", type=int, default=0, metavar="K",
                   help="with --from: play the scene's fingertips from the Kth (in channel order, from 0) on: "
                        "one of several devices of a scene")
    p.add_argument("--rate", type=float, default=1000.0, help="pose rate, Hz (default 1000)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds of streaming")
    p.add_argument("--force-max", type=float, default=5.0, help="the device's force limit, N per finger (default 5)")
    p.add_argument("--ttl-max", type=int, default=50, help="longest force TTL the device accepts, ms (default 50)")
    p.add_argument("--estop-at", type=float, default=None, metavar="S",
                   help="press the device's stop button S seconds into streaming (ESTOP sent, forces latched off)")
    p.add_argument("--force-log", metavar="PATH", help="write every force frame received (CSV) here at the end")
    p.add_argument("--corrupt-every", type=int, default=0, help="break the CRC of every Kth pose frame (tests)")
    p.add_argument("--drop-every", type=int, default=0, help="UDP: lose every Kth pose (tests)")
    p.add_argument("--dup-every", type=int, default=0, help="UDP: send every Kth pose twice (tests)")
    p.add_argument("--reorder-every", type=int, default=0, help="UDP: send every Kth pose after the next one (tests)")
    p.add_argument("--wait", type=float, default=0.0,
                   help="seconds to wait for the host's hello, then give up (default 0: as long as it takes, "
                        "a person starts the emulator and then goes to Blender)")
    p.add_argument("--report", metavar="PATH", help="also write the report as JSON here")
    return p


DEVICE_PRIORITY = 10    # SCHED_FIFO, below the host's haptic loop (80) and device threads (70)
DEVICE_NICE = -10       # where real-time scheduling is refused


def _as_a_device_would_run():
    """A device runs on its own processor: a busy host does not pause it. The emulator (which
    sleeps between poses, never spins) asks for real-time scheduling below the host's own
    threads, else for nice -10, where it may (root, or CAP_SYS_NICE), so that the host's load
    does not pause its stream as no real device would be; elsewhere it runs as it is."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(DEVICE_PRIORITY))
        return
    except (PermissionError, OSError, AttributeError):
        pass
    try:
        if os.getpriority(os.PRIO_PROCESS, 0) > DEVICE_NICE:
            os.setpriority(os.PRIO_PROCESS, 0, DEVICE_NICE)
    except (PermissionError, OSError):
        pass


def main(argv=None, args=None, motion=None):
    """``motion``: (motion, finger count) for ``--from`` (the bpy side reads the .blend:
    emulate_blend.py)."""
    args = args or build_parser().parse_args(argv)
    if args.fingers is not None and not 1 <= args.fingers <= P.MAX_FINGERS:
        raise SystemExit(f"--fingers: {args.fingers} outside 1..{P.MAX_FINGERS}")
    if not 1.0 <= args.rate <= 10000.0:
        raise SystemExit(f"--rate: {args.rate} Hz outside 1..10000")
    if args.first and not args.from_blend:
        raise SystemExit("--first: only with --from (a named motion has no fingers of a scene to choose from)")
    name = "grasp-lab-emulator"
    _as_a_device_would_run()
    if args.from_blend:
        if motion is None:
            raise SystemExit(f"--from {args.from_blend}: reading a .blend needs Blender: grasp-lab emulate --from, "
                             f"or python -m addon.emulate_blend")
        motion, n = motion
        # Named after what it plays, so that Find Devices tells two emulators of a scene apart.
        scene = os.path.splitext(os.path.basename(args.from_blend))[0]
        suffix = f" fingers {args.first}..{args.first + n - 1}"
        while len((scene + suffix).encode()) > P.NAME_MAX:
            scene = scene[:-1]
        name = scene + suffix
    else:
        motion, n = MOTIONS[args.motion], args.fingers or 2
    serial_port = slave = udp = None
    if args.udp is not None:
        import socket
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        udp.bind(("127.0.0.1", args.udp))
        udp.setblocking(False)
        fd, path = udp.fileno(), f"udp:127.0.0.1:{udp.getsockname()[1]}"
    elif args.pty:
        fd, slave, path = open_pty()
    else:
        import serial
        serial_port = serial.Serial(args.port, 115200, timeout=0)
        fd, path = serial_port.fileno(), args.port
    print(f"PORT {path}", flush=True)
    emu = Emulator(fd, n, motion, args.rate, args.force_max, args.ttl_max, name=name,
                   corrupt_every=args.corrupt_every,
                   estop_at=args.estop_at, log_forces=bool(args.force_log), udp=udp, drop_every=args.drop_every,
                   dup_every=args.dup_every, reorder_every=args.reorder_every,
                   orientation=ORIENTATIONS[args.orientation] if args.orientation else None)

    emu.say = lambda line: print(line, flush=True)

    def stop(signum, frame):
        emu.stop = True
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        report = emu.run(args.duration, args.wait)
    except TimeoutError as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        return 2
    finally:
        if serial_port is not None:
            serial_port.close()
    if args.force_log:
        emu.write_force_log(args.force_log)
    print("REPORT " + json.dumps(report), flush=True)
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(report, fh, indent=1)
    if slave is not None:
        os.close(slave)
        os.close(fd)
    if udp is not None:
        udp.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
