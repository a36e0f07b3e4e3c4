# Everything a fresh machine needs: `make demo`, `make test`, `make bench`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
GL := $(VENV)/mujoco_gl
RUN = MUJOCO_GL=$$(cat $(GL)) $(PY)
NAV = MUJOCO_GL=$$(cat $(GL)) $(VENV)/bin/appearance-nav

.PHONY: setup demo test bench reproduce clean

setup: $(GL)

# torch first, from the CPU wheel on local disk: otherwise a dependency pulls a CUDA build.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

# EGL by default; OSMesa (apt libosmesa6) only when EGL cannot render here.
$(GL): $(STAMP)
	@$(PY) -c "from envs._gl import main; raise SystemExit(main())" > $@ 2>/dev/null || { \
	  echo "EGL cannot render: installing libosmesa6"; \
	  (apt-get update -qq && apt-get install -y -qq libosmesa6) >/dev/null; \
	  $(PY) -c "from envs._gl import main; raise SystemExit(main())" > $@; }
	@echo "MUJOCO_GL=$$(cat $@)"

demo: setup
	$(NAV) demo

# One BLAS / OpenMP / torch thread per xdist worker: two workers with two threads each on two
# cores oversubscribe them (the suite took 14.5 min; 10.5 min on one thread each, stop 62),
# and the results no longer depend on the machine's core count.
test: setup
	OMP_NUM_THREADS=1 $(RUN) -m pytest -n 2 -q

# the agents benchmark fits its street-surface localizers itself (results/localizers_free);
# the robustness rows run its PPO policies (results/agents) beside the scripted agent,
# 12 episodes per city and row (~45 min for the scripted rows; 100, the issue's 200 per row, ~6 h)
bench: setup
	$(NAV) bench --only env,gse,filter,global,appearance,coverage,parallel,noise,city60
	$(NAV) bench --only agents
	$(NAV) bench --only robustness --robustness-workers 2 --robustness-episodes 12 \
		--robustness-oracle-policy results/agents/oracle/oracle/policy.pt \
		--robustness-belief-policy results/agents/belief/belief/policy.pt

reproduce: setup
	$(NAV) reproduce

clean:
	rm -rf $(VENV) results .pytest_cache
