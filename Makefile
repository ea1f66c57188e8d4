# gransim: the two set-up commands are `make run` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.gransim-installed
# numba's on-disk cache lives outside the source tree so a clean clone stays clean
export NUMBA_CACHE_DIR ?= $(CURDIR)/.venv/numba-cache

.PHONY: run test bench setup setup-run setup-test system-test warm warm-run engines browser liggghts clean help lint

help:
	@echo "make run   - set up, run the default validation suite, write results/report/index.html"
	@echo "make test  - set up, lint (ruff check, ruff format --check), run the test suite"
	@echo "make lint  - ruff check and ruff format --check"
	@echo "make coverage - the suite as plain Python under coverage (docs/coverage.md)"
	@echo "make bench - set up, run the benchmark suite (results/bench.json)"
	@echo "make engines - install LIGGGHTS, LAMMPS, YADE and escript with apt-get when root (else say how)"

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

# compile every command's numba kernels into NUMBA_CACHE_DIR (gransim warmup, docs/startup.md), so
# that a first run does not wait for numba; redone when a source file is newer than the stamp (the
# stamp takes the time the warm-up started: a file edited during it is warmed again next time)
WARM := $(VENV)/.gransim-warm
$(WARM): $(STAMP) $(shell find gransim -name '*.py' 2>/dev/null)
	@t=$$(date +%s.%N); $(VENV)/bin/gransim warmup && touch -d "@$$t" $@

warm: $(WARM)

# make run warms what its validation suite runs (`gransim warmup --laws biaxial`: the shear command
# with its default law only, 3 steps and about 20 s of CPU fewer); a complete warm-up newer than the
# sources and the venv stands for it
WARM_RUN := $(VENV)/.gransim-warm-run
$(WARM_RUN): $(STAMP) $(shell find gransim -name '*.py' 2>/dev/null)
	@if [ -f $(WARM) ] && [ $(WARM) -nt $(STAMP) ] && [ -z "$$(find gransim -name '*.py' -newer $(WARM))" ]; then \
	  touch $@; \
	else \
	  t=$$(date +%s.%N); $(VENV)/bin/gransim warmup --laws biaxial && touch -d "@$$t" $@; \
	fi

warm-run: $(WARM_RUN)

# the set-up: the venv and the numba warm-up (CPU-bound) beside the apt install of the codes (mostly
# waiting on the network and the disk), at the same time; `make test` also installs Chromium, after
# the codes (one apt-get at a time: they share dpkg's lock). `make run` does not need Chromium.
setup:
	@$(MAKE) --no-print-directory -j2 warm engines

setup-run:
	@$(MAKE) --no-print-directory -j2 warm-run engines

setup-test:
	@$(MAKE) --no-print-directory -j2 warm system-test

system-test:
	@$(MAKE) --no-print-directory engines
	@$(MAKE) --no-print-directory browser

# the DEM codes the validation compares with: LIGGGHTS (binary `liggghts`, Debian package
# `liggghts`), LAMMPS (binary `lmp`, Debian package `lammps`) and YADE, the independent third code
# (binary `yade`, Debian package `yade`, docs/yade.md), with escript (Debian `python3-escript`,
# `run-escript3`), the finite elements of Guo & Zhao's FEM x DEM code (docs/femxdem_reference.md). As root, the missing ones are installed with
# apt-get, without the packages they only recommend (liggghts recommends ParaView, lammps its
# documentation: 380 packages and 468 MB to fetch with them, 199 and 273 MB without, docs/validation.md);
# otherwise make says how. None is required: without LIGGGHTS or LAMMPS the comparisons use
# their stored outputs in reference_runs/stored/; the tests that need YADE are skipped without it.
engines:
	@missing=""; \
	if command -v liggghts >/dev/null 2>&1; then echo "LIGGGHTS found: $$(command -v liggghts)"; \
	  else missing="$$missing liggghts"; fi; \
	if command -v lmp >/dev/null 2>&1; then echo "LAMMPS found: $$(command -v lmp)"; \
	  else missing="$$missing lammps"; fi; \
	if command -v yade >/dev/null 2>&1; then echo "YADE found: $$(command -v yade)"; \
	  else missing="$$missing yade"; fi; \
	if command -v run-escript3 >/dev/null 2>&1; then echo "escript found: $$(command -v run-escript3)"; \
	  else missing="$$missing python3-escript"; fi; \
	if [ -z "$$missing" ]; then \
	  :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "missing:$$missing; installing Debian's package(s)$$missing with apt-get"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing >/dev/null) \
	    || echo "WARNING: apt-get install$$missing failed; those comparisons will use stored reference outputs only (YADE's tests are skipped)"; \
	else \
	  echo "WARNING: not installed:$$missing (binaries 'liggghts', 'lmp', 'yade', 'run-escript3'), and this user cannot install them."; \
	  echo "         Install them with:  sudo apt-get install --no-install-recommends$$missing"; \
	  echo "         Until then, comparisons use the stored reference outputs in reference_runs/stored/"; \
	  echo "         and the tests that need YADE are skipped."; \
	fi

# the former name of the target
liggghts: engines

# headless Chromium (Debian package `chromium`): the test suite opens the validation report in it at
# 1400 px (every image loads, no section is empty). As root it is installed when missing; otherwise
# make says how, and that one check is skipped.
browser:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then \
	  echo "Chromium found: $$(command -v chromium || command -v chromium-browser)"; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "Chromium missing; installing Debian's package chromium with apt-get (for the report check)"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	    || echo "WARNING: apt-get install chromium failed; the report's browser check will be skipped"; \
	else \
	  echo "NOTE: Chromium is not installed; the report's browser check is skipped (sudo apt-get install chromium)"; \
	fi

run: setup-run
	$(VENV)/bin/gransim validate --suite default --jobs 2

# style: ruff's lint rules and formatter (configured in pyproject.toml), on every Python folder
LINT_DIRS := gransim reference_runs validation bench tests
lint: $(STAMP)
	$(VENV)/bin/ruff check $(LINT_DIRS)
	$(VENV)/bin/ruff format --check $(LINT_DIRS)

test: setup-test lint
	$(PY) -m pytest -q -n 2 --dist loadfile

bench: setup
	$(PY) -m bench

clean:
	rm -rf results .pytest_cache

# the test suite as plain Python (NUMBA_DISABLE_JIT=1) under coverage.py: per-module table in
# results/coverage/report.txt and docs/coverage.md (.ci/coverage; not part of make test)
.PHONY: coverage
coverage: $(STAMP) engines
	.ci/coverage
