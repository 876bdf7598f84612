# hgrender: `make serve` sets up and runs the service; `make test` sets up and runs the tests.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
PYTHON ?= python3
SYSTEM_PACKAGES := libllvm19 redis-server chromium chromium-driver iproute2 curl jq
HOST ?= 127.0.0.1
PORT ?= 8000
DATA_DIR ?= ./data

.PHONY: setup system-packages venv serve test test-fast lint format bench gallery web clean

setup: system-packages $(VENV)/.installed

# Installs the Debian packages the project needs (libLLVM 19 for Dr.Jit, Redis, Chromium for the viewer
# tests) when any is missing. Needs root or sudo; skipped where everything is already there.
system-packages:
	@missing=""; for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing >/dev/null; \
	fi

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -e '.[dev]'
	touch $@

venv: $(VENV)/.installed

# Ctrl-C stops the service in order (hgrender serve exits 130 after a clean shutdown); that is how it is
# meant to end, so make reports no error for it.
serve: setup
	@$(VENV)/bin/hgrender serve --host $(HOST) --port $(PORT) --data-dir $(DATA_DIR) || [ $$? -eq 130 ]

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports --no-cache

format: venv
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

test: setup lint
	$(VENV)/bin/pytest -q

test-fast: venv
	$(VENV)/bin/pytest -q -m "not slow and not browser"

# The API benchmark drives the server with wrk (it falls back to Python load processes without it).
bench: setup
	@$(MAKE) --no-print-directory system-packages SYSTEM_PACKAGES=wrk
	$(PY) -m bench

# Every gallery scene at publication quality (512², GALLERY_SPP) into gallery/<name>/ and docs/gallery.md.
GALLERY_SPP ?= 256
gallery: setup
	$(PY) -m worker.gallery --size 512 --spp $(GALLERY_SPP)

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
