# The two commands of the README. Each sets everything up (idempotently) first.
.PHONY: demo test setup benchmark clean

setup:
	@tools/setup.sh

# Seed example 1a at 86 x 86 squares (about 2 minutes): fields, series, pictures in out/ex01a/.
demo: setup
	.venv/bin/primordia run examples/ex01a.toml --set 'mesh.cells=[86,86]' --out out/ex01a

test: setup
	.venv/bin/python -m pytest -q -p no:cacheprovider

benchmark: setup
	.venv/bin/python benchmarks/bench_examples.py

clean:
	rm -rf out .pytest_cache
