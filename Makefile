# Grasp Lab. `make demo` and `make test` set everything up from nothing.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip --disable-pip-version-check -q
BPY_VERSION ?= 4.5.*
BUILD := build

CORE_SRC := $(wildcard native/src/*.c)
CORE_HDR := $(wildcard native/src/*.h native/include/*.h)
BINDING := native/binding/graspcore_module.c
PY_SRC := $(wildcard native/python/graspcore/*.py)
CFLAGS_COMMON := -std=c11 -Inative/include -Inative/src -Wall -Wextra -Wno-unused-parameter -ffp-contract=off
C_TESTS := $(patsubst native/tests/%.c,%,$(wildcard native/tests/test_*.c))

.PHONY: all venv core demo test test-c test-c-asan test-c-tsan test-py bench clean

all: core

# --- Python environment -------------------------------------------------------
$(VENV)/.deps: requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip setuptools wheel
	$(PIP) install "bpy==$(BPY_VERSION)" -r requirements.txt
	touch $@

venv: $(VENV)/.deps

# The core is built as a cp311-abi3 wheel and installed into the venv.
$(VENV)/.core: $(VENV)/.deps $(CORE_SRC) $(CORE_HDR) $(BINDING) $(PY_SRC) native/setup.py
	rm -rf native/build native/*.egg-info $(BUILD)/wheel
	$(PY) -m pip wheel --no-deps --no-build-isolation -q -w $(BUILD)/wheel ./native
	$(PIP) install --force-reinstall --no-deps $(BUILD)/wheel/graspcore-*.whl
	rm -rf native/build native/*.egg-info
	touch $@

# `grasp-lab` in the venv (docs/cli.md): the command line of this checkout's extension.
$(VENV)/bin/grasp-lab: $(VENV)/.deps
	printf '%s\n' '#!/bin/sh' '# grasp-lab (docs/cli.md), written by make' \
	  'exec "$(CURDIR)/$(PY)" -c "import sys; sys.path.insert(0, \"$(CURDIR)\"); from addon.engine.cli import launch; sys.exit(launch())" "$$@"' > $@
	chmod +x $@

core: $(VENV)/.core $(VENV)/bin/grasp-lab

# --- C tests (plain, then ASan/UBSan) -----------------------------------------
$(BUILD)/c/%: native/tests/%.c $(CORE_SRC) $(CORE_HDR) native/tests/gc_test.h
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_COMMON) -O2 -g -o $@ $< $(CORE_SRC) -lm -lpthread

$(BUILD)/c-asan/%: native/tests/%.c $(CORE_SRC) $(CORE_HDR) native/tests/gc_test.h
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_COMMON) -O1 -g -fsanitize=address,undefined -fno-sanitize-recover=all \
	  -fno-omit-frame-pointer -o $@ $< $(CORE_SRC) -lm -lpthread

test-c: $(addprefix $(BUILD)/c/,$(C_TESTS))
	@for t in $^; do echo "== $$t"; $$t || exit 1; done

test-c-asan: $(addprefix $(BUILD)/c-asan/,$(C_TESTS))
	@for t in $^; do echo "== $$t (ASan/UBSan)"; ASAN_OPTIONS=detect_leaks=1 $$t || exit 1; done

# The threaded tests under ThreadSanitizer (the runtime's loops, its lock-free channels).
TSAN_TESTS := $(filter test_runtime test_contacts test_serial_io test_tick_log,$(C_TESTS))
$(BUILD)/c-tsan/%: native/tests/%.c $(CORE_SRC) $(CORE_HDR) native/tests/gc_test.h
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_COMMON) -O1 -g -fsanitize=thread -o $@ $< $(CORE_SRC) -lm -lpthread

test-c-tsan: $(addprefix $(BUILD)/c-tsan/,$(TSAN_TESTS))
	@for t in $^; do echo "== $$t (TSan)"; TSAN_OPTIONS=halt_on_error=1 $$t || exit 1; done

# --- Python tests ---------------------------------------------------------------
test-py: core
	$(PY) -m pytest -q tests/core tests/devices

# test-blender (addon.mk) runs tests/blender on bpy 4.5, 4.2 and 5.0.1; test-gui (addon.mk)
# the extension in a real GUI Blender under Xvfb.
test: test-c test-c-asan test-c-tsan test-py test-blender test-gui

# --- The main job -------------------------------------------------------------
# (a) the core alone, a table in the terminal; (b) the sample scene headless in Blender
# through the extension (EXEC session, baked .blend, recording, CSV, render) in build/demo.
# `extension` (addon.mk) builds $(EXT_ZIP), which is defined after this point.
demo: core extension
	@echo "== (a) the core alone: sample_scenes/pinch_and_lift.py"
	$(PY) sample_scenes/pinch_and_lift.py
	@echo "== (b) Blender, headless, through the extension: sample_scenes/demo_session.py"
	GRASP_LAB_ZIP=$(EXT_ZIP) $(PY) sample_scenes/demo_session.py --out $(BUILD)/demo

bench: core extension
	$(PY) bench/run_bench.py

clean:
	rm -rf $(BUILD) native/build native/*.egg-info

# Blender extension targets (extension zip, multi-version bpy tests) live in addon.mk.
-include addon.mk
