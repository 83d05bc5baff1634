# The two commands of the README. Each sets everything up (idempotently) first.
.PHONY: demo test setup benchmark clean help

setup: ## make the venv (.venv) with dolfinx from Debian, install primordia and its plugins
	@tools/setup.sh

# Seed example 1a on the seed's mesh (58,482 triangles, 2,600 steps, about a minute):
# fields, series and pictures in out/ex01a/ (m_snapshots.png: rows of spots behind the wave).
# --overwrite: a second `make demo` replaces the first one's run instead of being refused.
demo: setup ## the main job: seed example 1a on the seed's mesh, into out/ex01a (about a minute)
	.venv/bin/primordia run examples/ex01a.toml --out out/ex01a --overwrite

# -n 2: two pytest workers (pytest-xdist), one per core of the 2-core machines it is measured on: 8.5 minutes
# against 14 in one process; the MPI tests' 2-4 ranks share the cores with the other worker.
test: setup ## the test suite, both backends and MPI (about 9 minutes on 2 cores)
	.venv/bin/python -m pytest -q -p no:cacheprovider -n 2

benchmark: setup ## the seed examples' cost per step (benchmarks/bench_examples.py)
	.venv/bin/python benchmarks/bench_examples.py

clean: ## remove out/ (every run's results) and pytest's cache
	rm -rf out .pytest_cache

help: ## this list
	@sed -n 's/^\([a-z]*\):.*## \(.*\)/  make \1\t\2/p' $(MAKEFILE_LIST) | expand -t 18
