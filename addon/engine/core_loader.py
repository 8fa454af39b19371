"""Find the graspcore module: the copy vendored beside this file (engine/graspcore/, in the
built zip), else an installed ``graspcore`` (development venv)."""
from __future__ import annotations

_core = None


def load():
    """Return the graspcore module or raise ImportError with a helpful message."""
    global _core
    if _core is not None:
        return _core
    try:
        from . import graspcore as gc  # vendored by `make extension`
    except ImportError:
        try:
            import graspcore as gc
        except ImportError as ex:
            raise ImportError("Grasp Lab: the graspcore module is missing; install the "
                              "extension from its built zip (make extension) or run "
                              "`make core` in a development checkout") from ex
    _core = gc
    return gc


def available() -> bool:
    try:
        load()
        return True
    except ImportError:
        return False
