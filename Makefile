# Two entry points that do all the set-up on a fresh machine:
#   make demo   - create .venv, install, make the tabletop-small scene, train GaussianDS, evaluate, report
#   make test   - create .venv, install with the test extra, run the test suite
PY ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
DEMO := demo_out
PYTEST_ARGS ?=
# pytest-xdist workers: the CPUs this process may use, at most 4. Each worker holds torch and the
# suite's scenes (~0.5 GB); `-n auto` on a 64-core machine would start 64 of them.
TEST_WORKERS ?= $(shell $(PY) -c "import os; print(max(1, min(4, len(os.sched_getaffinity(0)))))")
# pip runs only when this stamp is older than pyproject.toml (the install is editable, so code
# changes need no reinstall).
STAMP := $(VENV)/.installed

.PHONY: demo test install lint clean stress bench claims-page

$(VPY):
	$(PY) -m venv $(VENV)

# torch: use the CPU build of 2.13.0 from this machine's disk unless a torch is already importable.
# pip's build warnings go to .venv/install.log; it is printed only when the install fails.
# --no-compile, then scripts/warm_imports.py: Python caches the bytecode of the ~2,200 files gsbench
# imports instead of pip compiling all ~11,000 installed ones (5 s instead of 28 s on 2 cores).
$(STAMP): pyproject.toml | $(VPY)
	@$(VPY) -c "import torch" 2>/dev/null || (echo "installing torch==2.13.0 (CPU)"; \
	  $(VPY) -m pip install --quiet --no-compile torch==2.13.0 > $(VENV)/torch-install.log 2>&1 \
	  || (cat $(VENV)/torch-install.log; exit 1))
	@echo "installing gsbench[test] into $(VENV) (log: $(VENV)/install.log)"
	@$(VPY) -m pip install --quiet --no-compile -e ".[test]" > $(VENV)/install.log 2>&1 || (cat $(VENV)/install.log; exit 1)
	@env -u PYTHONDONTWRITEBYTECODE $(VPY) scripts/warm_imports.py
	@touch $@

install: $(STAMP)

demo: install
	bash scripts/demo.sh $(VENV) $(DEMO)

# Python's bytecode cache is on for the tests even where PYTHONDONTWRITEBYTECODE is set: without it
# each xdist worker re-does pytest's assertion rewriting of every test module (collection 10 s
# instead of 5) and every process a test starts recompiles gsbench.
test: install
	env -u PYTHONDONTWRITEBYTECODE $(VENV)/bin/pytest -q -n $(TEST_WORKERS) --dist worksteal --durations=10 $(PYTEST_ARGS)

# ruff's rules and line length are set in pyproject.toml ([tool.ruff]).
lint: install
	$(VENV)/bin/ruff check .

stress: install
	$(VENV)/bin/gsbench stress --out $(DEMO)/stress

bench: install
	$(VPY) benchmarks/render_cpu.py

# docs/claims.md, its figures and the README's claims block, from the published store (docs/publishing.md)
claims-page: install
	$(VENV)/bin/gsbench publish --page docs/claims.md --from results/cpu --readme README.md

clean:
	rm -rf $(VENV) $(DEMO) build *.egg-info
