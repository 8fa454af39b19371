"""pytest setup for the Blender extension tests: isolate Blender's user resources
before bpy is imported, load the extension once (built zip from GRASP_LAB_ZIP, else a
development repository), and give each test an empty file."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# tests/support: what every suite shares (waiting.wait_until, docs/testing.md).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support"))
import grasp_env  # noqa: E402

grasp_env.isolate()


def pytest_configure(config):
    config.addinivalue_line("markers", "multiversion: the focused subset run on every bpy version")
    config.addinivalue_line("markers", "needs_core: needs the graspcore module")


_EXIT_STATUS = []


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS.append(int(exitstatus))


def pytest_unconfigure(config):
    """The run's end, its report written: the process ends here with pytest's status. The bpy
    module can hang in its C++ static destructors at interpreter exit once Blender's worker
    threads have run in it (seen: a fresh clone's tests/blender finished, 338 passed, and the
    process then waited 15 min in exit() in bpy's GlobalState destructor beside its idle
    thread_worker threads); nothing is left to write by then."""
    if _EXIT_STATUS:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_EXIT_STATUS[-1])


@pytest.fixture(scope="session")
def ext():
    """Module name of the enabled extension."""
    return grasp_env.enable()


@pytest.fixture()
def bpy(ext):
    import bpy as _bpy
    _bpy.ops.wm.read_homefile(use_empty=True)
    yield _bpy
    session = grasp_env.submodule("session")
    session.stop_active()


@pytest.fixture(scope="session")
def core(ext):
    try:
        return grasp_env.graspcore()
    except ImportError as ex:
        if os.environ.get("GRASP_LAB_REQUIRE_CORE"):
            raise
        pytest.skip(f"graspcore not available: {ex}")


@pytest.fixture()
def sample(bpy):
    """The pinch-and-lift sample scene builder module."""
    import importlib.util
    path = os.path.join(grasp_env.ROOT, "sample_scenes", "build_pinch_and_lift.py")
    spec = importlib.util.spec_from_file_location("build_pinch_and_lift", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
