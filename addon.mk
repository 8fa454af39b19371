# Blender extension targets. Included by the top Makefile (`-include addon.mk`), so
# VENV, PY, PIP and BUILD come from there.
#
#   make extension     dist/grasp_lab-<version>-linux_x64.zip, built and validated by
#                      Blender's own blender_ext.py (from the bpy wheel), carrying the
#                      abi3 core and the third-party wheels (cp311 + cp313).
#   make test-blender  tests/blender on bpy 4.5 (.venv, full set), then an install +
#                      focused subset on bpy 4.2 (.venv-bpy42) and 5.0.1 (.venv-bpy50).

.PHONY: extension extension-validate test-blender test-gui test-blender-45 test-blender-42 \
        test-blender-50 test-blender-fast test-blender-45-pty test-blender-45-rest venv-bpy42 venv-bpy50 clean-extension sample-scenes scenes fit-table blender-docs-image docs-images \
        bench-blender

EXT_VERSION := $(shell sed -n 's/^version *= *"\(.*\)"/\1/p' blender_manifest.toml | head -1)
EXT_ZIP := dist/grasp_lab-$(EXT_VERSION)-linux_x64.zip
EXT_STAGE := $(BUILD)/extension/grasp_lab
EXT_WHEELS := $(BUILD)/extension-wheels
BLENDER_EXT = $(shell ls $(VENV)/lib/python3.11/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py 2>/dev/null | head -1)
ADDON_SRC := $(shell find addon \( -name '*.py' -o -name '*.toml' \) -not -path '*/__pycache__/*' 2>/dev/null)
# Third-party wheels bundled in the zip (numpy comes with Blender). Pinned so the zip
# is reproducible offline once downloaded.
EXT_PURE_WHEELS := trimesh==5.2.0 pyserial==3.5 mcap==1.6.0
# Binary wheels without an abi3 build: bundled for cp311 (Blender 4.2-5.0) and cp313 (5.1+).
EXT_BINARY_WHEELS := hidapi==0.15.0 lz4==4.4.5 zstandard==0.25.0
PIPDL := $(PY) -m pip --disable-pip-version-check -q download --no-deps --only-binary=:all: -d $(EXT_WHEELS)

$(EXT_WHEELS)/.done: addon.mk | $(VENV)/.deps
	mkdir -p $(EXT_WHEELS)
	$(PIPDL) $(EXT_PURE_WHEELS)
	$(PIPDL) --python-version 3.11 --implementation cp --abi cp311 --platform manylinux2014_x86_64 $(EXT_BINARY_WHEELS)
	$(PIPDL) --python-version 3.13 --implementation cp --abi cp313 --platform manylinux2014_x86_64 $(EXT_BINARY_WHEELS)
	touch $@

# Stage: the add-on package + manifest + vendored core (from the core's abi3 wheel, in engine/: the
# bpy-free side loads it) + wheels.
$(EXT_ZIP): $(VENV)/.core $(EXT_WHEELS)/.done blender_manifest.toml $(ADDON_SRC) addon.mk
	rm -rf $(BUILD)/extension && mkdir -p $(EXT_STAGE)/wheels dist
	cp -r addon/. $(EXT_STAGE)/
	find $(EXT_STAGE) -name __pycache__ -prune -exec rm -rf {} +
	$(PY) -c "import zipfile,glob,sys; w=sorted(glob.glob('$(BUILD)/wheel/graspcore-*.whl'))[-1]; z=zipfile.ZipFile(w); [z.extract(n,'$(EXT_STAGE)/engine') for n in z.namelist() if n.startswith('graspcore/')]"
	cp $(EXT_WHEELS)/*.whl $(EXT_STAGE)/wheels/
	cp blender_manifest.toml $(EXT_STAGE)/
	$(PY) $(BLENDER_EXT) build --source-dir $(EXT_STAGE) --output-dir dist --split-platforms
	$(PY) $(BLENDER_EXT) validate $@

extension: $(EXT_ZIP)
	@ls -l $(EXT_ZIP)

extension-validate: $(EXT_ZIP)
	$(PY) $(BLENDER_EXT) validate $(EXT_ZIP)

# --- multi-version bpy venvs (the zip brings trimesh/pyserial/hidapi and the core) ---
# pytest and what tests/blender imports when it is collected (hypothesis, pinned in requirements.txt).
TEST_TOOLS = pytest $(shell grep '^hypothesis==' requirements.txt)

.venv-bpy42/.deps: requirements.txt
	$(PYTHON) -m venv .venv-bpy42
	.venv-bpy42/bin/python -m pip --disable-pip-version-check -q install "bpy==4.2.*" $(TEST_TOOLS)
	touch $@

.venv-bpy50/.deps: requirements.txt
	$(PYTHON) -m venv .venv-bpy50
	.venv-bpy50/bin/python -m pip --disable-pip-version-check -q install "bpy==5.0.1" $(TEST_TOOLS)
	touch $@

venv-bpy42: .venv-bpy42/.deps
venv-bpy50: .venv-bpy50/.deps

# Full set on 4.5 (dev venv, graspcore installed there too); on 4.2 / 5.0.1 the
# extension is installed from the zip and a focused subset runs (-m multiversion).
# make test runs these two halves of it side by side with the other stages (docs/testing.md):
# the files that open pseudo-terminals (device emulators, Find Devices, a --device) one after
# another with the other such stages, found by what they call; the rest beside anything.
BLENDER_PTY_TESTS := $(shell grep -l -E 'devices\.emulator|emulate_blend|devices_refresh|find_devices|openpty|hello_fingers|"--device"|serial:' tests/blender/test_*.py 2>/dev/null)
BLENDER_OTHER_TESTS := $(filter-out $(BLENDER_PTY_TESTS),$(wildcard tests/blender/test_*.py))

test-blender-45: test-blender-45-pty test-blender-45-rest

test-blender-45-pty: $(EXT_ZIP)
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) -m pytest -q $(BLENDER_PTY_TESTS)

test-blender-45-rest: $(EXT_ZIP)
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) -m pytest -q $(BLENDER_OTHER_TESTS)

test-blender-42: $(EXT_ZIP) .venv-bpy42/.deps
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) .venv-bpy42/bin/python -m pytest -q -m multiversion tests/blender

test-blender-50: $(EXT_ZIP) .venv-bpy50/.deps
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) .venv-bpy50/bin/python -m pytest -q -m multiversion tests/blender

test-blender: test-blender-45 test-blender-42 test-blender-50

# make test-fast's share of tests/blender: the multiversion subset on bpy 4.5.
test-blender-fast: $(EXT_ZIP)
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) -m pytest -q -m multiversion tests/blender

# A real GUI Blender (docs/gui-tests.md): Debian 13's Blender 4.3 in a chroot cached in
# ~/.cache/grasp-lab (built once, as root), or BLENDER=/path/to/blender. Where it cannot be
# had, the tests say why and how to get it (and fail under CI=true).
test-gui: $(EXT_ZIP)
	@tests/gui/gui_blender.sh setup || echo "GUI Blender: not set up; the GUI tests say why"
	@tests/gui/rerun_viewer.sh setup || echo "Rerun viewer (Xvfb, software Vulkan): not set up; its test says why"
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) -m pytest -q -rs tests/gui

# The sample scene as a .blend (built, not committed) and the docs render.
sample-scenes: $(EXT_ZIP)
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/build_pinch_and_lift.py --save $(BUILD)/pinch_and_lift.blend

# The scene library (docs/scenes.md): every scene of sample_scenes/library.py as a .blend in
# build/scenes/, each run headless once and checked against what it claims (a few seconds).
# Built, not committed: the script is the source; the files are mostly Blender's own UI data.
scenes: $(VENV)/.core
	$(PY) sample_scenes/library.py --out $(BUILD)/scenes --run

# docs/devices.md's table of which device renders which library grasp: every scene run and recorded,
# each recording evaluated against every device profile (grasp-lab fit's evaluation).
fit-table: $(VENV)/.core
	$(PY) sample_scenes/fit_table.py --docs docs/devices.md --out $(BUILD)/fit

# Frame 43: halfway through the lift (what `make demo` renders too).
blender-docs-image: $(EXT_ZIP)
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/build_pinch_and_lift.py --frame 43 \
	  --force-scale 0.01 --render docs/images/pinch_and_lift.png

# The README's pictures (docs/images/demo_contact_sheet.png, gui_*.png): the demo's contact sheet,
# and the GUI Blender of the tests walking through the README (tests/gui/docs_images.py); and
# docs/viewers.md's rerun_*.png: the Rerun viewer's own pictures of library scenes under Xvfb.
# Run again when the UI changes; commit the pictures.
docs-images: $(EXT_ZIP)
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/showcase.py --out $(BUILD)/demo
	@tests/gui/gui_blender.sh setup || echo "GUI Blender: not set up; docs_images.py says why"
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) tests/gui/docs_images.py --demo $(BUILD)/demo --out docs/images
	@tests/gui/rerun_viewer.sh setup || echo "Rerun viewer: not set up; rerun_shots.py says why"
	$(PY) tests/gui/rerun_shots.py --out docs/images

bench-blender: $(EXT_ZIP)
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) bench/bench_blender.py

clean-extension:
	rm -rf $(BUILD)/extension dist/grasp_lab-*.zip
