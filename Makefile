# Two commands set up a fresh machine: `make run` and `make test`.
VENV    ?= .venv
PYTHON  ?= python3
TORCH   ?= torch==2.13.0
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
GL_PKGS := libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libglu1-mesa
GOAL    ?= bathtub

.PHONY: run test setup gl clean

run: setup
	$(VENV)/bin/dopt train --goal $(GOAL)

test: setup
	$(VENV)/bin/python -m pytest -q

setup: gl $(STAMP)

# torch goes in first: anything that pulls it in later would fetch the CUDA build.
$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(TORCH)
	$(PY) -m pip install -q -c constraints.txt -e ".[test]"
	touch $@

# Headless OpenGL (Mesa llvmpipe) for MiniWorld; installed only when running as root and missing.
gl:
	@if ldconfig -p | grep -q libEGL.so.1 && ldconfig -p | grep -q libGLU.so.1 \
	    && ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = "0" ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(GL_PKGS); \
	else echo "warning: OpenGL libraries missing ($(GL_PKGS)); install them to render the apartment"; fi

clean:
	rm -rf $(VENV) build *.egg-info
