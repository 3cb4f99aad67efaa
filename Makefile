# The two commands that do everything on a fresh machine:
#   make demo   the main job: wip-bench compare on PlanarTray-v0 (table, summary.json, one video
#               per controller and video_grid.mp4 with all of them side by side)
#   make test   create .venv if missing, install the project with its pinned deps and the
#               benchmark peers (the `bench` extra) and Ray (the `sweep` extra), run pytest
VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install test lint typecheck demo clean clean-caches

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml constraints.txt | $(PY)
	$(PY) -m pip install --quiet -c constraints.txt -e ".[dev,bench,sweep]"
	$(PY) -m benchmarks.warm_caches   # compile once (numba, JAX), cached on disk
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	MUJOCO_GL=$${MUJOCO_GL:-egl} $(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# The public API's types ([tool.mypy] in pyproject.toml lists the files).
typecheck: $(STAMP)
	$(VENV)/bin/mypy

demo: $(STAMP)
	MUJOCO_GL=$${MUJOCO_GL:-egl} $(VENV)/bin/wip-bench compare --env wip_gym/PlanarTray-v0 \
		--episodes 1 --video both --out out/demo

clean:
	rm -rf $(VENV) build dist *.egg-info

# Deletes the compiled caches: numba's (wip_gym/compiled_cache.py keys them on the compiled
# sources and the modules they import, so an edit takes effect by itself; each edit leaves the
# previous directory behind) and the MPC's generated modules, then compiles again what
# `warm_caches` runs (the rest compiles on first use).
clean-caches: $(STAMP)
	find wip_gym controllers benchmarks -name '*.nbi' -delete -o -name '*.nbc' -delete
	rm -rf $${NUMBA_CACHE_DIR:+$$NUMBA_CACHE_DIR/wip-gym} $$HOME/.cache/wip-gym/compiled
	cd $${WIP_GYM_NUMBA_CACHE:-$$HOME/.cache/wip-gym/numba} 2>/dev/null && \
		rm -rf wipm_mpc_*.py .wipm_mpc_*.tmp __pycache__ || true  # the MPC's generated modules
	$(PY) -m benchmarks.warm_caches
