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
