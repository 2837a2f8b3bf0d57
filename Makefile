# Two entry points: `make reproduce` (the main job) and `make test` (what CI runs).
# Both build .venv from environment.txt the first time.
PY := .venv/bin/python
BUDGET ?= smoke

.PHONY: reproduce test venv grf clean

venv: .venv/installed

.venv/installed: environment.txt pyproject.toml
	python3 -m venv .venv
	.venv/bin/pip install --quiet --upgrade pip
	.venv/bin/pip install --quiet -r environment.txt
	.venv/bin/pip install --quiet --no-deps --no-build-isolation -e .
	.venv/bin/python -m ipykernel install --sys-prefix --name python3 > /dev/null
	touch $@

# Google Research Football: system libraries, then psutil (gfootball's build imports it), then
# its Python deps, then the engine itself (a ~7 min C++ compile; pip caches the built wheel).
GRF_APT := cmake build-essential libgl1-mesa-dev libegl-dev libsdl2-dev libsdl2-image-dev \
	libsdl2-ttf-dev libsdl2-gfx-dev libboost-python-dev libboost-thread-dev \
	libboost-system-dev libboost-filesystem-dev python3-dev
grf: .venv/grf-installed

.venv/grf-installed: .venv/installed requirements-grf.txt
	apt-get update -qq
	DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(GRF_APT) > /dev/null
	.venv/bin/pip install --quiet psutil==7.2.2
	.venv/bin/pip install --quiet -r requirements-grf.txt -c environment.txt
	# its build script runs `python3 -c 'import psutil ...'` from PATH, so the venv goes first
	PATH="$(CURDIR)/.venv/bin:$$PATH" .venv/bin/pip install --quiet --no-build-isolation gfootball==2.10.2 -c environment.txt
	touch $@

reproduce: venv
	$(PY) -m oapo_lite reproduce --budget $(BUDGET)

test: venv
	$(PY) -m pytest -q tests
	$(PY) -m oapo_lite reproduce --budget smoke --check
	$(PY) -m pytest -q -p no:cacheprovider --nbval --nbval-current-env --nbval-sanitize-with notebooks/sanitize.cfg notebooks

clean:
	rm -rf .venv build figures/smoke
