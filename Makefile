# Set-up and checks. `make demo` and `make test` work on a fresh machine.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# rustup installs cargo here; maturin needs it on the PATH
export PATH := $(HOME)/.cargo/bin:$(PATH)

.PHONY: demo test lint docs fuzz bench wheel install install-test system-deps rust clean

$(VENV)/bin/python:
	python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip

# the package with its Rust extension, built in release mode by maturin
install: $(VENV)/bin/python rust
	$(PIP) install -q -e '.[all]'

install-test: install system-deps
	$(PIP) install -q -e '.[all,test]'

# Rust toolchain: the one on the PATH (rustup's), else Debian's cargo and rustc
rust:
	@command -v cargo >/dev/null || { \
	  echo "cargo not found: installing a Rust toolchain"; \
	  $(SUDO) apt-get update -qq && $(SUDO) DEBIAN_FRONTEND=noninteractive apt-get install -y -qq cargo rustc; }

# LinuxCNC's interpreter (rs274) is the peer the NC tests compare against; Chromium renders the
# freeform report in a test
system-deps:
	@missing=""; \
	command -v rs274 >/dev/null || missing="$$missing linuxcnc-uspace"; \
	command -v chromium >/dev/null || missing="$$missing chromium"; \
	if [ -n "$$missing" ]; then \
	  $(SUDO) apt-get update -qq && \
	  $(SUDO) DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; fi

demo: install
	$(VENV)/bin/ncadapt demo --out demo-out

test: install-test
	cargo test -q --workspace --exclude ncadapt-nc-py
	$(PY) -m pytest -q

# ruff (lint and format), cargo fmt and clippy, mypy on the public API
lint: install-test
	$(VENV)/bin/ruff check python tests benchmarks examples
	$(VENV)/bin/ruff format --check python tests benchmarks examples
	cargo fmt --all --check
	cargo clippy -q --workspace -- -D warnings
	$(VENV)/bin/mypy

# the documentation with its API reference (mkdocs + mkdocstrings, from the docstrings, offline) in site/
docs: install-test
	$(VENV)/bin/mkdocs build --strict

# the property tests with large budgets: generated programs against rs274 (make test runs 25
# examples) and the CLI contract on mutated inputs and extreme options (make test: 100 per target,
# about 3,500 cases; here 300 per target, about 10,500)
fuzz: install-test
	NCADAPT_HYPOTHESIS=explore NCADAPT_FUZZ_EXAMPLES=2000 $(PY) -m pytest -q tests/test_fuzz_programs.py
	NCADAPT_HYPOTHESIS=explore NCADAPT_CLI_FUZZ_EXAMPLES=300 $(PY) -m pytest -q tests/test_cli_fuzz.py

# bCNC is the peer of the benchmark: only its CNC.py is used, so its GUI dependencies are skipped
bench: install-test
	$(PIP) install -q --no-deps bCNC==0.9.16 svgelements
	$(PY) benchmarks/bench_correct.py
	$(PY) benchmarks/bench_freeform.py
	$(PY) benchmarks/bench_skin.py
	$(PY) benchmarks/bench_waffle.py

# a manylinux abi3 wheel built with maturin and zig (no docker), then installed into fresh virtual
# environments by tests/test_wheel.py: the base install corrects a program, [all] runs the demo
wheel: install-test
	$(PIP) install -q 'maturin>=1.7,<2' ziglang
	rm -rf dist
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(VENV)/bin/maturin build --release --zig --compatibility manylinux2014 -o dist
	NCADAPT_WHEEL="$$(ls dist/ncadapt-*.whl)" $(PY) -m pytest -q tests/test_wheel.py

clean:
	rm -rf $(VENV) target demo-out dist site
