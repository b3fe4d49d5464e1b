# gesture_sim: two commands do everything on a fresh Debian/Ubuntu machine.
#   make demo   set up, then render the shipped example speech to out/demo.mp4 (+ timeline)
#   make test   set up, then run the test suite headless (MUJOCO_GL=egl)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Runtime: PortAudio for the microphone, EGL/Mesa for headless rendering.
DEB_RUNTIME := libportaudio2 libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgles2
# Tests also speak with espeak-ng, measure with sox and host the viewer on Xvfb.
DEB_TEST := espeak-ng sox xvfb xauth

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

setup-test: setup
	@bash tools/install_system_deps.sh $(DEB_TEST)

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
