# Everything a fresh machine needs: `make demo`, `make test`, `make bench`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
CONSTRAINTS := requirements/constraints.txt
GL := $(VENV)/mujoco_gl
RUN = MUJOCO_GL=$$(cat $(GL)) $(PY)
NAV = MUJOCO_GL=$$(cat $(GL)) $(VENV)/bin/appearance-nav

.PHONY: setup demo test bench reproduce clean lock

setup: $(GL)

# torch first, from the CPU wheel on local disk: otherwise a dependency pulls a CUDA build.
# Every other version comes from $(CONSTRAINTS), so benchmarks rerun on the same libraries.
$(STAMP): pyproject.toml $(CONSTRAINTS)
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -c $(CONSTRAINTS) -e '.[dev]'
	touch $@

# Newest versions pyproject.toml allows, written to $(CONSTRAINTS); then make test and commit.
lock:
	rm -rf $(VENV)-lock
	$(PYTHON) -m venv $(VENV)-lock
	$(VENV)-lock/bin/python -m pip install --quiet torch==2.13.0
	$(VENV)-lock/bin/python -m pip install --quiet -e '.[dev]'
	sed -n '/^#/p' $(CONSTRAINTS) > $(CONSTRAINTS).new
	$(VENV)-lock/bin/python -m pip freeze --exclude-editable | grep -v '^torch==' >> $(CONSTRAINTS).new
	mv $(CONSTRAINTS).new $(CONSTRAINTS)
	rm -rf $(VENV)-lock

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
# and the results no longer depend on the machine's core count. The 15 slowest tests are listed
# at the end, so a test that grows shows in the CI log (stop 73: one took 457 of the suite's
# 877 s on a default-sized fit it did not need).
test: setup
	OMP_NUM_THREADS=1 $(RUN) -m pytest -n 2 -q --durations=15

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
