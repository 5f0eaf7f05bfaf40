# VisionCell: `make run` sets up and starts the demo cell, `make test` sets up and runs every test.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: run test lint typecheck-backend bench install install-dev demo-serial clean

$(BIN)/python:
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "VisionCell needs Python >= 3.11, found " + sys.version.split()[0]'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	@touch $@ $(VENV)/.installed

install: $(VENV)/.installed
install-dev: $(VENV)/.installed-dev

run: install
	$(BIN)/visioncell serve

# Two workers, whole files each, handed out in collection order (tests/conftest.py puts the
# long files first, so both workers end together); bytecode is cached, so the workers and
# every `visioncell` subprocess reuse the compiled modules (pytest's rewritten tests too).
test: install-dev
	PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -q -ra -n 2 --dist loadfile --no-loadscope-reorder --durations=15

# Lint and the type checker (mypy, configured in pyproject.toml) on robot/, vision/ and backend/.
lint: install-dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy robot vision backend

# Kept as an alias: the type check is part of `make lint` now.
typecheck-backend: lint

# The whole serial path: an emulated controller (robot/drivers/serial/emulator.py) on a
# pseudo-terminal drives the cell; the server starts once the emulator has published its port.
demo-serial: install
	@mkdir -p var; if [ -L var/robot-tty ]; then rm var/robot-tty; fi
	@$(BIN)/visioncell emulator --link var/robot-tty & emu=$$!; trap "kill $$emu 2>/dev/null" EXIT INT TERM; \
	for i in $$(seq 100); do [ -L var/robot-tty ] && break; sleep 0.1; done; \
	[ -L var/robot-tty ] || { echo "emulator did not publish var/robot-tty" >&2; exit 1; }; \
	VISIONCELL_DRIVER=serial VISIONCELL_SERIAL_PORT=var/robot-tty $(BIN)/visioncell serve

bench: install-dev
	@for b in $$(grep -l '__name__ == "__main__"' benchmarks/[a-z]*.py); do \
		m=$$(basename $$b .py); echo "== benchmarks.$$m"; \
		$(BIN)/python -m benchmarks.$$m || exit 1; \
	done

clean:
	rm -rf $(VENV) var .pytest_cache .ruff_cache
