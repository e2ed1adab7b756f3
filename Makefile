# The two commands (see README.md): `make demo` and `make test`. Both set up on first use.
SHELL := /bin/bash
ENV := source scripts/env.sh &&

.PHONY: setup check test demo bench clean

setup:
	@bash scripts/setup.sh

# The lint (ruff: pycodestyle, pyflakes, pep257 docstrings) and the type check of the cores
# (mypy, strict): the first part of `make test`, which stops at the first error.
check: setup
	@$(ENV) ruff check . && mypy

test: check
	@$(ENV) python -m pytest

demo: setup
	@$(ENV) scripts/rrtq run scenarios/rrtqx_paper.yaml --out runs/rrtqx-paper --overwrite
	@$(ENV) scripts/rrtq report runs/rrtqx-paper/run.mcap

bench: setup
	@$(ENV) python benchmarks/run_all.py

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log .stamps .mypy_cache .ruff_cache
