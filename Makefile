# The two commands that do everything on a fresh machine:
#   make demo   the main job (unified vs decoupled on the default scenario: table + video)
#   make test   create .venv if missing, install the project with its pinned deps, run pytest
VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install test lint demo clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml constraints.txt | $(PY)
	$(PY) -m pip install --quiet -c constraints.txt -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	MUJOCO_GL=$${MUJOCO_GL:-egl} $(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

demo: $(STAMP)
	@echo "The main job (wip-bench compare, unified vs decoupled) arrives with the benchmark issue;"
	@echo "until then, try: $(PY) -m wip_gym.video --env wip_gym/KrangTray-v0 --out out/krang_tray.mp4"

clean:
	rm -rf $(VENV) build dist *.egg-info
