# gransim: the two set-up commands are `make run` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.gransim-installed
# numba's on-disk cache lives outside the source tree so a clean clone stays clean
export NUMBA_CACHE_DIR ?= $(CURDIR)/.venv/numba-cache

.PHONY: run test bench setup liggghts clean help

help:
	@echo "make run   - set up, run the default validation suite, write results/report/index.html"
	@echo "make test  - set up, run the test suite"
	@echo "make bench - set up, run the benchmark suite (results/bench.json)"

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

setup: $(STAMP) liggghts

liggghts:
	@if command -v liggghts >/dev/null 2>&1; then \
	  echo "LIGGGHTS found: $$(command -v liggghts)"; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "LIGGGHTS missing: installing Debian's liggghts package with apt-get"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq liggghts >/dev/null) \
	    || echo "WARNING: apt-get install liggghts failed; LIGGGHTS comparisons will use stored reference outputs only"; \
	else \
	  echo "WARNING: LIGGGHTS (the 'liggghts' binary) is not installed and this user cannot install it."; \
	  echo "         Install it with:  sudo apt-get install liggghts"; \
	  echo "         Until then, comparisons use the stored reference outputs in reference_runs/stored/."; \
	fi

run: setup
	$(VENV)/bin/gransim validate --suite default

test: setup
	$(PY) -m pytest -q -n 2 --dist loadfile

bench: setup
	$(PY) -m bench

clean:
	rm -rf results .pytest_cache
