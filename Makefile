# The two commands of the README. Each sets everything up (idempotently) first.
.PHONY: demo test setup benchmark clean

setup:
	@tools/setup.sh

# Seed example 1a on the seed's mesh (58,482 triangles, 2,600 steps, about a minute):
# fields, series and pictures in out/ex01a/ (m_snapshots.png: rows of spots behind the wave).
# --overwrite: a second `make demo` replaces the first one's run instead of being refused.
demo: setup
	.venv/bin/primordia run examples/ex01a.toml --out out/ex01a --overwrite

test: setup
	.venv/bin/python -m pytest -q -p no:cacheprovider

benchmark: setup
	.venv/bin/python benchmarks/bench_examples.py

clean:
	rm -rf out .pytest_cache
