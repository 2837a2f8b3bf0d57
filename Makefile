# Two entry points: `make reproduce` (the main job) and `make test` (what CI runs).
# Both build .venv from environment.txt the first time.
PY := .venv/bin/python
BUDGET ?= smoke
START := $(shell date +%s)

.PHONY: reproduce test venv grf book book-deps browser clean

venv: .venv/installed

.venv/installed: environment.txt pyproject.toml
	python3 -m venv .venv
	.venv/bin/pip install --quiet --upgrade pip
	.venv/bin/pip install --quiet -r environment.txt
	.venv/bin/pip install --quiet --no-deps rliable==1.2.0
	# jsonschema's optional rfc3987-syntax (pulled in by jupyter-events) builds a parser on import,
	# 2 s of CPU in every process that imports ray; on a busy machine Ray's agents then missed the
	# raylet's fixed 15 s start-up window. Nothing here validates IRIs.
	.venv/bin/pip uninstall --quiet --yes rfc3987-syntax
	.venv/bin/pip install --quiet --no-deps --no-build-isolation -e .
	.venv/bin/python -m ipykernel install --sys-prefix --name python3 > /dev/null
	touch $@

# The book's Python packages (Sphinx, MyST-NB, MathJax's files, selenium), into .venv.
book-deps: .venv/book-installed

.venv/book-installed: .venv/installed book-requirements.txt
	.venv/bin/pip install --quiet -r book-requirements.txt
	touch $@

# The notebooks as a static site in build/book (committed outputs; nothing is executed).
book: book-deps
	$(PY) -m oapo_lite book

# Debian's Chromium and its driver, for the book's browser test (installed once; needs root or sudo),
# quietly and without the packages apt merely recommends (as grf below).
browser:
	@command -v chromium > /dev/null && command -v chromedriver > /dev/null || { \
	  SUDO=$$( [ "$$(id -u)" -eq 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends \
	    chromium chromium-driver > /dev/null; }

# Google Research Football: system libraries, then psutil (gfootball's build imports it), then
# its Python deps, then the engine itself (a ~7 min C++ compile; pip caches the built wheel).
GRF_APT := cmake build-essential libgl1-mesa-dev libegl-dev libsdl2-dev libsdl2-image-dev \
	libsdl2-ttf-dev libsdl2-gfx-dev libboost-python-dev libboost-thread-dev \
	libboost-system-dev libboost-filesystem-dev python3-dev
grf: .venv/grf-installed

.venv/grf-installed: .venv/installed requirements-grf.txt
	@SUDO=$$( [ "$$(id -u)" -eq 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $(GRF_APT) > /dev/null
	.venv/bin/pip install --quiet psutil==7.2.2
	.venv/bin/pip install --quiet -r requirements-grf.txt -c environment.txt
	# its build script runs `python3 -c 'import psutil ...'` from PATH, so the venv goes first
	PATH="$(CURDIR)/.venv/bin:$$PATH" .venv/bin/pip install --quiet --no-build-isolation gfootball==2.10.2 -c environment.txt
	touch $@

reproduce: venv
	$(PY) -m oapo_lite reproduce --budget $(BUDGET)

# tests/test_book.py builds the book and opens every page in headless Chromium; tests/envs/test_grf.py
# needs the real GRF engine. tests/numeric_paths.py runs the numeric unit tests again, and nbval
# (the committed notebook outputs, executed again here and compared as text), under numeric paths
# that pick other floating-point kernels on this machine, as another CPU would; it prints how many
# compared cells moved on each (ASSUMPTIONS.md, "Across machines"). tests/stages.py runs the
# stages below and prints the time of each, set-up included, at the end.
test: venv book-deps browser grf
	$(PY) tests/stages.py $(START)

clean:
	rm -rf .venv build figures/smoke
