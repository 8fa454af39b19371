"""Build graspcore: the C core plus its one binding file, for the stable ABI (cp311-abi3)."""
import glob
import os

from setuptools import Extension, setup

HERE = os.path.dirname(os.path.abspath(__file__))


# The compiler flags the Makefile builds the C tests with (one flag a line); make adds
# -Werror through GRASPCORE_WERROR=1.
with open(os.path.join(HERE, "cflags.txt")) as f:
    core_flags = f.read().split()
if os.environ.get("GRASPCORE_WERROR") == "1":
    core_flags.append("-Werror")

core_sources = sorted(glob.glob("src/*/*.c"))  # one folder a layer
setup(
    name="graspcore",
    version="0.1.0",
    description="Friction-cone haptic rendering and rigid-body dynamics for multi-finger grasps",
    package_dir={"": "python"},
    packages=["graspcore"],
    ext_modules=[
        Extension(
            "graspcore._core",
            sources=core_sources + ["binding/graspcore_module.c"],
            include_dirs=["include", "src"],
            define_macros=[("Py_LIMITED_API", "0x030B0000")],
            py_limited_api=True,
            extra_compile_args=["-O2", "-fno-strict-aliasing"] + core_flags,
            extra_link_args=["-lm", "-lpthread"],
        )
    ],
    options={"bdist_wheel": {"py_limited_api": "cp311"}},
    python_requires=">=3.11",
)
