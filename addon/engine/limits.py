"""Legal ranges of every ``--set`` key and argument, and the up-front checks of what a command
will need (ticks, memory, disk), docs/reliability.md. A value outside its range is refused
with the range in the message, never clamped. Plain Python (no bpy)."""
from __future__ import annotations

import math
import os

# --set keys: (low, high, unit); inclusive. The scene's own property ranges where it has them
# (haptic_rate 100-10000 Hz, stiffness >= 1 N/m, mass >= 1e-6 kg), else what a grasp of
# objects in a hand can mean (100 g of gravity, friction coefficients up to 10).
SET_RANGES = {
    "haptic_rate": (100.0, 10000.0, "Hz"),
    "gravity": (-1000.0, 1000.0, "m/s^2 per axis"),
    "mass": (1e-6, 1e6, "kg"),
    "mu_s": (0.0, 10.0, ""),
    "mu_d": (0.0, 10.0, ""),
    "viscosity": (0.0, 100.0, "s"),
    "radius": (0.0, 1.0, "m"),
    "stiffness": (1.0, 1e6, "N/m"),
    "damping": (0.0, 1e4, "N s/m"),
    "cursor_mass": (0.0, 1.0, "kg"),
    "torsion": (0.0, 0.1, "m"),         # a soft fingertip's patch radius (Soft Tip Radius)
}

# Arguments: (low, high); low exclusive where the name says "positive".
MAX_DURATION = 86400.0          # s: a day of session (--duration)
MAX_TOLERANCE = 1e3             # m (--tolerance)
MAX_CONTINUITY_THRESHOLD = 1e4  # N per tick (continuity --threshold)
MAX_EVERY = 1 << 31             # --every
DEFAULT_MAX_SIZE = 10e9         # bytes a recording may take (--max-size)


class LimitError(ValueError):
    """A request beyond what the machine or the documented limits allow; the message has the numbers."""


def describe_range(key: str) -> str:
    lo, hi, unit = SET_RANGES[key]
    return f"{lo:g} .. {hi:g}" + (f" {unit}" if unit else "")


def check_set_value(key: str, value: float) -> str:
    """'' when ``value`` is legal for ``key``, else why not (with the range)."""
    lo, hi, _ = SET_RANGES[key]
    if not math.isfinite(value) or not lo <= value <= hi:
        return f"{key} must be in {describe_range(key)}, got {value!r}"
    return ""


def parse_size(text: str) -> float:
    """'500M', '2G', '1.5e9' -> bytes (decimal units)."""
    t = text.strip().upper().removesuffix("B")
    scale = {"K": 1e3, "M": 1e6, "G": 1e9, "T": 1e12}.get(t[-1:], 1.0)
    if scale != 1.0:
        t = t[:-1]
    try:
        value = float(t) * scale
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"expected a size > 0 such as 500M or 2G, got {text!r}")
    return value


def mb(n: float) -> str:
    return f"{n / 1e6:,.1f} MB"


def free_bytes(path: str) -> float:
    """Bytes free to a user in the folder ``path`` is (or would be) in."""
    folder = os.path.dirname(os.path.abspath(path))
    while folder and not os.path.isdir(folder):
        folder = os.path.dirname(folder)
    st = os.statvfs(folder or "/")
    return float(st.f_bavail) * st.f_frsize


def available_memory() -> float:
    """MemAvailable from /proc/meminfo (bytes); inf where there is none."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return math.inf


def check_recording_size(what: str, path: str, ticks: float, record_bytes: int, max_size: float) -> float:
    """Refuse a recording whose expected size (ticks x record size, uncompressed: an upper
    bound) passes ``max_size`` or the free space where it goes. Returns the estimate."""
    size = float(ticks) * record_bytes
    if size > max_size:
        raise LimitError(f"{what} {path}: {ticks:,.0f} ticks x {record_bytes} bytes would be up to "
                         f"{mb(size)}, over --max-size {mb(max_size)} (raise --max-size or shorten the session)")
    free = free_bytes(path)
    if size > free:
        raise LimitError(f"{what} {path}: {ticks:,.0f} ticks x {record_bytes} bytes would be up to "
                         f"{mb(size)}, {mb(free)} free there")
    return size


def check_memory(what: str, ticks: float, record_bytes: int, copies: float = 1.0) -> float:
    """Refuse holding ``copies`` arrays of ``ticks`` records when memory does not have them."""
    need = float(ticks) * record_bytes * copies
    have = available_memory()
    if need > have:
        raise LimitError(f"{what}: {ticks:,.0f} ticks x {record_bytes} bytes x {copies:g} need "
                         f"{mb(need)} of memory, {mb(have)} available")
    return need
