# Two entry points: `make reproduce` (the main job) and `make test` (what CI runs).
# Both build .venv from environment.txt the first time.
PY := .venv/bin/python
BUDGET ?= smoke

.PHONY: reproduce test venv clean

venv: .venv/installed

.venv/installed: environment.txt pyproject.toml
	python3 -m venv .venv
	.venv/bin/pip install --quiet --upgrade pip
	.venv/bin/pip install --quiet -r environment.txt
	# jsonschema's optional rfc3987-syntax (pulled in by jupyter-events) builds a parser on import,
	# 2 s of CPU in every process that imports ray; on a busy machine Ray's agents then missed the
	# raylet's fixed 15 s start-up window. Nothing here validates IRIs.
	.venv/bin/pip uninstall --quiet --yes rfc3987-syntax
	.venv/bin/pip install --quiet --no-deps --no-build-isolation -e .
	.venv/bin/python -m ipykernel install --sys-prefix --name python3 > /dev/null
	touch $@

reproduce: venv
	$(PY) -m oapo_lite reproduce --budget $(BUDGET)

test: venv
	$(PY) -m pytest -q tests
	$(PY) -m oapo_lite reproduce --budget smoke --check
	$(PY) -m pytest -q -p no:cacheprovider --nbval --nbval-current-env --nbval-sanitize-with notebooks/sanitize.cfg notebooks

clean:
	rm -rf .venv build figures/smoke
