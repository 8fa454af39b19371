# Grasp Lab. `make demo` and `make test` set everything up from nothing.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip --disable-pip-version-check -q
BPY_VERSION ?= 4.5.*
BUILD := build

# native/src: one folder a layer (docs/architecture.md).
CORE_SRC := $(wildcard native/src/*/*.c)
CORE_HDR := $(wildcard native/src/*/*.h native/include/*.h)
BINDING := native/binding/graspcore_module.c
PY_SRC := $(wildcard native/python/graspcore/*.py)
# One list of compiler flags, shared with native/setup.py; warnings are errors here.
CORE_FLAGS := $(shell cat native/cflags.txt)
CFLAGS_COMMON := $(CORE_FLAGS) -Werror -Inative/include -Inative/src
C_TESTS := $(patsubst native/tests/%.c,%,$(wildcard native/tests/test_*.c))
CORE_OBJ := $(CORE_SRC:native/src/%.c=%.o)

.PHONY: all venv core lib check-layers layers-table demo test test-c test-c-asan test-c-tsan test-py bench clean \
        test-under-load flake-hunt test-fast stage-pty-chain test-core test-devices

all: core

# --- Python environment -------------------------------------------------------
$(VENV)/.deps: requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip setuptools wheel
	$(PIP) install "bpy==$(BPY_VERSION)" -r requirements.txt
	touch $@

venv: $(VENV)/.deps

# The core is built as a cp311-abi3 wheel and installed into the venv.
$(VENV)/.core: $(VENV)/.deps $(CORE_SRC) $(CORE_HDR) $(BINDING) $(PY_SRC) native/setup.py native/cflags.txt
	rm -rf native/build native/*.egg-info $(BUILD)/wheel
	GRASPCORE_WERROR=1 $(PY) -m pip wheel --no-deps --no-build-isolation -q -w $(BUILD)/wheel ./native
	$(PIP) install --force-reinstall --no-deps $(BUILD)/wheel/graspcore-*.whl
	rm -rf native/build native/*.egg-info
	touch $@

# `grasp-lab` in the venv (docs/cli.md): the command line of this checkout's extension. The
# stop signals (SIGHUP, SIGINT, SIGTERM) are held from the first line until launch() handles them.
$(VENV)/bin/grasp-lab: $(VENV)/.deps Makefile
	printf '%s\n' '#!/bin/sh' '# grasp-lab (docs/cli.md), written by make' \
	  'exec "$(CURDIR)/$(PY)" -c "import signal, sys; signal.pthread_sigmask(signal.SIG_BLOCK, (1, 2, 15)); sys.path.insert(0, \"$(CURDIR)\"); from addon.launcher import launch; sys.exit(launch())" "$$@"' > $@
	chmod +x $@

core: $(VENV)/.core $(VENV)/bin/grasp-lab

# --- The core as a static library, and the C tests linked with it ------------------
# Three builds of the library: plain (tests, benches), ASan/UBSan, TSan. Each source is
# compiled once per build; the tests and bench/bench_gjk.sh link the archive.
VARIANT_c := -O2 -g
VARIANT_c-asan := -O1 -g -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
VARIANT_c-tsan := -O1 -g -fsanitize=thread

define core_library
$(BUILD)/$(1)/obj/%.o: native/src/%.c $(CORE_HDR) native/cflags.txt
	@mkdir -p $$(dir $$@)
	$$(CC) $$(CFLAGS_COMMON) $$(VARIANT_$(1)) -c -o $$@ $$<

$(BUILD)/$(1)/libgraspcore.a: $(addprefix $(BUILD)/$(1)/obj/,$(CORE_OBJ))
	rm -f $$@
	$$(AR) rcs $$@ $$^

$(BUILD)/$(1)/test_%: native/tests/test_%.c $(BUILD)/$(1)/libgraspcore.a $(CORE_HDR) native/tests/gc_test.h
	$$(CC) $$(CFLAGS_COMMON) $$(VARIANT_$(1)) -o $$@ $$< $(BUILD)/$(1)/libgraspcore.a -lm -lpthread
endef
$(foreach v,c c-asan c-tsan,$(eval $(call core_library,$(v))))

lib: $(BUILD)/c/libgraspcore.a

# No file of native/src calls or includes a folder above it or one its folder's README.md does not
# name (docs/architecture.md); the add-on's engine/ imports neither bpy nor the add-on above it,
# and no add-on modules import each other in a circle.
check-layers: $(BUILD)/c/libgraspcore.a native/check_layers.py docs/architecture.md
	$(PYTHON) native/check_layers.py --core native/src $(BUILD)/c/obj docs/architecture.md
	$(PYTHON) native/check_layers.py --addon addon

# docs/architecture.md's table of layers, made from native/src/*/README.md.
layers-table:
	$(PYTHON) native/check_layers.py --table native/src docs/architecture.md

test-c: $(addprefix $(BUILD)/c/,$(C_TESTS))
	@for t in $^; do echo "== $$t"; $$t || exit 1; done

test-c-asan: $(addprefix $(BUILD)/c-asan/,$(C_TESTS))
	@for t in $^; do echo "== $$t (ASan/UBSan)"; ASAN_OPTIONS=detect_leaks=1 $$t || exit 1; done

# The threaded tests under ThreadSanitizer (the runtime's loops, its lock-free channels).
TSAN_TESTS := $(filter test_runtime test_contacts test_serial_io test_tick_log,$(C_TESTS))

test-c-tsan: $(addprefix $(BUILD)/c-tsan/,$(TSAN_TESTS))
	@for t in $^; do echo "== $$t (TSan)"; TSAN_OPTIONS=halt_on_error=1 $$t || exit 1; done

# --- Python tests ---------------------------------------------------------------
test-py: test-core test-devices

# tests/core (no pty: beside anything) and tests/devices (emulators on ptys, Find Devices).
test-core: core
	$(PY) -m pytest -q tests/core

test-devices: core
	$(PY) -m pytest -q tests/devices

# --- make test: the stages side by side (docs/testing.md) --------------------------------
# What the stages share is built first, once (TEST_PREREQS: the venv and core, the extension,
# the bpy 4.2 / 5.0.1 venvs, the plain C library and tests). Then two kinds of stages run side by
# side, TEST_JOBS at a time, each stage's output in build/test-logs/STAGE.log:
#   TEST_PTY_STAGES   one after another: they start device emulators on pseudo-terminals, and
#                     Find Devices (in tests/devices, tests/blender, tests/gui) probes every raw
#                     pty of the user: two of them at once would talk to each other's devices;
#   TEST_STAGES       beside them and each other: they share nothing at run time.
# The end prints each stage's result and time (and the end of a failed stage's log), and fails
# if any failed. test-blender-* (addon.mk) run tests/blender on bpy 4.5 (its files that open a pty,
# and the rest), 4.2 and 5.0.1 (those two only -m multiversion, which uses no pty); test-gui
# (addon.mk) the extension in a real GUI Blender under Xvfb. A new stage: a target that needs nothing another stage builds at run time (or put
# that in TEST_PREREQS), its name added to TEST_PTY_STAGES if it opens a pty, else TEST_STAGES.
TEST_PTY_STAGES := test-blender-45-pty test-devices test-gui
TEST_STAGES := test-blender-45-rest test-c-asan test-c-tsan test-core test-blender-42 test-blender-50 test-c \
               check-layers
TEST_PREREQS := core extension venv-bpy42 venv-bpy50 $(addprefix $(BUILD)/c/,$(C_TESTS))
TEST_JOBS ?= 3
TEST_LOGS := $(BUILD)/test-logs

test:
	@rm -rf $(TEST_LOGS) && mkdir -p $(TEST_LOGS) && date +%s > $(TEST_LOGS)/.start
	@tests/load/run_stage.sh prepare $(TEST_LOGS) $(MAKE) --no-print-directory $(TEST_PREREQS)
	@if grep -q FAILED $(TEST_LOGS)/prepare.result; then tail -n 40 $(TEST_LOGS)/prepare.log; exit 1; fi
	@$(MAKE) --no-print-directory -j$(TEST_JOBS) stage-pty-chain $(addprefix stage-,$(TEST_STAGES))
	@tests/load/stage_summary.sh $(TEST_LOGS) prepare $(TEST_PTY_STAGES) $(TEST_STAGES)

stage-pty-chain:
	@for s in $(TEST_PTY_STAGES); do tests/load/run_stage.sh $$s $(TEST_LOGS) $(MAKE) --no-print-directory $$s; done

stage-%:
	@tests/load/run_stage.sh $* $(TEST_LOGS) $(MAKE) --no-print-directory $*

# For iteration (docs/testing.md, README): the layers, the plain C tests, tests/core and
# tests/devices, and tests/blender's multiversion subset on bpy 4.5; not the sanitizers, not
# the rest of tests/blender, not the GUI. At most 2 minutes on a quiet 2-core machine.
test-fast: core extension $(addprefix $(BUILD)/c/,$(C_TESTS))
	@rm -rf $(TEST_LOGS) && mkdir -p $(TEST_LOGS) && date +%s > $(TEST_LOGS)/.start
	@$(MAKE) --no-print-directory -j$(TEST_JOBS) stage-check-layers stage-test-c stage-test-core \
	  stage-test-devices stage-test-blender-fast
	@tests/load/stage_summary.sh $(TEST_LOGS) check-layers test-c test-core test-devices test-blender-fast

# --- Under load (docs/testing.md) ----------------------------------------------------
# Both cores kept busy by plain CPU hogs at normal priority (tests/load/under_load.sh starts them
# and stops them however the command ends). No retries anywhere: a flake is a bug to fix.
#   make test-under-load                         the whole of `make test`, under load
#   make flake-hunt TEST=tests/x.py::test_y N=20  one test (or any pytest selection) N times under
#                                                 load: says how many runs failed, keeps their logs
N ?= 20
test-under-load:
	tests/load/under_load.sh $(MAKE) --no-print-directory test

flake-hunt: core extension
	@test -n "$(TEST)" || { echo "usage: make flake-hunt TEST='tests/...::test_name' [N=20]" >&2; exit 2; }
	GRASP_LAB_REQUIRE_CORE=1 GRASP_LAB_ZIP=$(EXT_ZIP) tests/load/under_load.sh \
	  tests/load/flake_hunt.sh $(N) $(BUILD)/flake-hunt $(PY) $(TEST)

# --- The main job -------------------------------------------------------------
# (a) the core alone, a table in the terminal; (b) the sample scene headless in Blender
# through the extension (EXEC session, baked .blend, recording, CSV, render) in build/demo;
# (c) the showcase: every scene of the library run, recorded, baked, analysed, rendered and
# plotted, with build/demo/index.html. `extension` (addon.mk) builds $(EXT_ZIP), which is
# defined after this point.
demo: core extension
	@echo "== (a) the core alone: sample_scenes/pinch_and_lift.py"
	$(PY) sample_scenes/pinch_and_lift.py
	@echo "== (b) Blender, headless, through the extension: sample_scenes/demo_session.py"
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/demo_session.py --out $(BUILD)/demo
	@echo "== (c) the scene library: sample_scenes/showcase.py"
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/showcase.py --out $(BUILD)/demo

bench: core extension
	$(PY) bench/run_bench.py

clean:
	rm -rf $(BUILD) native/build native/*.egg-info

# Blender extension targets (extension zip, multi-version bpy tests) live in addon.mk.
-include addon.mk
