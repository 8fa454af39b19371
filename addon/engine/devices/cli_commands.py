"""The ``devices`` and ``emulate`` commands of ``grasp-lab``, and ``--device`` specs for
``run`` (docs/devices.md). The CLI dispatcher adds them with ``add_device_commands``;
the Blender sidebar calls the same functions (``discovery.find_devices``)."""
from __future__ import annotations

import json
import sys

from .discovery import PROBE_TIMEOUT, candidate_ports, probe_ports, serial_ports


# ---- discovery ---------------------------------------------------------------------------

def hid_devices(spacemice_only: bool = True) -> list:
    from .spacemouse import VENDORS, enumerate_spacemice, hid_module
    if spacemice_only:
        found = enumerate_spacemice()
    else:
        try:
            found = hid_module().enumerate()
        except ImportError:
            found = []
    out = []
    for d in found:
        path = d.get("path", b"")
        out.append({"kind": "spacemouse" if d.get("vendor_id") in VENDORS else "hid",
                    "path": path.decode("utf-8", "replace") if isinstance(path, bytes) else str(path),
                    "vid": d.get("vendor_id"), "pid": d.get("product_id"),
                    "description": d.get("product_string") or "", "usage_page": d.get("usage_page"),
                    "usage": d.get("usage")})
    return out


def discover(all_hid: bool = False, probe: bool = True, extra_ports=(), timeout: float = PROBE_TIMEOUT) -> list:
    """Serial ports (pyserial's list and the candidate pseudo-terminals), each candidate
    probed for the Grasp Lab hello (``grasp_lab``: its capabilities; ``probe``: what the probe
    found), then SpaceMice (or every HID device). ``probe=False``: the lists only, no hello."""
    listed = serial_ports()
    found = {d["port"]: d for d in listed}
    ports = (candidate_ports(listed) if probe else []) + [p for p in extra_ports if p]
    for r in probe_ports(ports, timeout) if ports else []:
        d = found.setdefault(r["port"], {"kind": "serial", "port": r["port"], "description": "pseudo-terminal"
                                         if r["port"].startswith("/dev/pts/") else "", "vid": None, "pid": None})
        d["probe"] = {"status": r["status"], "detail": r["detail"]}
        if "hello" in r:
            d["grasp_lab"] = r["hello"]
    return list(found.values()) + hid_devices(spacemice_only=not all_hid)


# ---- --device specs -----------------------------------------------------------------------

def parse_device_spec(spec: str) -> dict:
    """``serial:PORT[@FIRST]`` (a Grasp Lab device driving fingers FIRST.., default 0),
    ``udp:HOST:PORT[@FIRST]`` (the same over UDP), ``spacemouse[:PATH]``, ``opengloves:PORT``.
    Returns a dict; ValueError names what is wrong."""
    kind, _, rest = spec.partition(":")
    if kind == "udp":
        where, _, first = rest.partition("@")
        host, _, port = where.rpartition(":")
        host = host.strip("[]")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ValueError(f"--device {spec!r}: udp needs HOST:PORT with a port 1..65535, e.g. udp:127.0.0.1:5555")
        try:
            offset = int(first) if first else 0
        except ValueError:
            raise ValueError(f"--device {spec!r}: the first finger after '@' must be an integer") from None
        if offset < 0:
            raise ValueError(f"--device {spec!r}: the first finger must be >= 0")
        return {"kind": "udp", "host": host, "port": f"{host}:{port}", "udp_port": int(port), "finger_offset": offset}
    if kind == "serial":
        port, _, first = rest.partition("@")
        if not port:
            raise ValueError(f"--device {spec!r}: serial needs a port, e.g. serial:/dev/ttyACM0")
        try:
            offset = int(first) if first else 0
        except ValueError:
            raise ValueError(f"--device {spec!r}: the first finger after '@' must be an integer") from None
        if offset < 0:
            raise ValueError(f"--device {spec!r}: the first finger must be >= 0")
        return {"kind": "serial", "port": port, "finger_offset": offset}
    if kind == "spacemouse":
        return {"kind": "spacemouse", "path": rest or None}
    if kind == "opengloves":
        if not rest:
            raise ValueError(f"--device {spec!r}: opengloves needs a port")
        return {"kind": "opengloves", "port": rest}
    raise ValueError(f"--device {spec!r}: unknown kind {kind!r} (serial:PORT, udp:HOST:PORT, spacemouse[:PATH], "
                     f"opengloves:PORT)")


# ---- commands ---------------------------------------------------------------------------

def cmd_devices(args, out=None) -> int:
    out = out or sys.stdout
    found = discover(all_hid=args.all_hid, probe=not args.no_probe, extra_ports=args.probe or (),
                     timeout=args.timeout)
    if args.json:
        print(json.dumps(found, indent=1), file=out)
        return 0
    if not found:
        print("no serial ports or SpaceMice found", file=out)
    for d in found:
        where = d.get("port") or d.get("path")
        ids = f"{d['vid']:04x}:{d['pid']:04x}" if d.get("vid") is not None else "-"
        line = f"{d['kind']:<10} {where:<28} {ids:<10} {d.get('description', '')}"
        if "grasp_lab" in d:
            g = d["grasp_lab"]
            line += (f" Grasp Lab device '{g['name']}': {g['n_fingers']} fingers, {g['rate_hz']} Hz, "
                     f"{'forces up to %.3g N' % g['force_max'] if g['renders_forces'] else 'input only'}"
                     f"{', orientations' if g.get('orientations') else ''}")
        elif "probe" in d:
            line += f" ({d['probe']['detail']})"
        elif d["kind"] == "serial":
            line += " (not probed: no USB identity; --probe PORT says hello on it)"
        print(line, file=out)
    return 0


def cmd_emulate(args) -> int:
    from . import emulator
    return emulator.main(args=args)


def configure_devices(p) -> None:
    p.add_argument("--probe", action="append", metavar="PORT",
                   help="also say hello on PORT (a port that is not a candidate: a platform UART)")
    p.add_argument("--no-probe", action="store_true", help="only list the ports: say hello on none")
    p.add_argument("--timeout", type=float, default=PROBE_TIMEOUT,
                   help=f"seconds to wait for the devices' hello (default {PROBE_TIMEOUT})")
    p.add_argument("--all-hid", action="store_true", help="list every HID device, not only SpaceMice")
    p.add_argument("--json", action="store_true", help="machine-readable output")


DEVICES_HELP = "find Grasp Lab devices (a hello on USB serial ports and raw pseudo-terminals) and SpaceMice"
EMULATE_HELP = "run the reference device emulator (on a pty or a port)"
