# mpdem: every target sets itself up first (tools/setup.sh is idempotent).
# MPDEM_MPI=mpich selects MPICH instead of Open MPI.
VENV   ?= .venv
PY     := $(VENV)/bin/python
MPIEXEC := $(VENV)/bin/mpiexec
RANKS  ?= 2
# pytest workers of test-serial and test-validation (pytest-xdist; a worker out of tests takes some of another's):
# the cores, at most 4
TEST_JOBS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); [ $$n -gt 4 ] && n=4; echo $$n)
XDIST  = -n $(TEST_JOBS) --dist worksteal

.PHONY: setup run test docs test-fast lint test-serial test-pytest test-mpi test-validation test-slurm test-gpu-compile bench reproduce collect-dev reproduce-paper collect-paper collect-ladder-dev clean

setup:
	@bash tools/setup.sh

# The built-in example (about 1500 spheres) poured, settled, then analysed (runs/example/analysis).
run: setup
	$(MPIEXEC) -n $(RANKS) $(PY) -m mpdem run --out runs/example --force
	$(PY) -m mpdem analyze runs/example

# Every test: what CI runs. test-fast leaves out the long runs marked validation (docs/testing.md).
# setup, lint, test-pytest, test-mpi, test-gpu-compile, test-slurm, docs in that order; .venv-cuda and
# .venv-docs (downloads and unpacking, little CPU: some 100 s from nothing) are made meanwhile, beside the
# set-up and the tests, their output in build/setup-venvs.log, shown once the MPI tests are done
test:
	@mkdir -p build; \
	{ bash tools/setup_cuda.sh && bash tools/setup_docs.sh; } > build/setup-venvs.log 2>&1 & venvs=$$!; \
	$(MAKE) --no-print-directory setup lint test-pytest test-mpi; rc=$$?; \
	wait $$venvs; v=$$?; cat build/setup-venvs.log; \
	[ $$rc = 0 ] || exit $$rc; \
	[ $$v = 0 ] || { echo "make test: .venv-cuda or .venv-docs not made (build/setup-venvs.log)" >&2; exit $$v; }; \
	$(MAKE) --no-print-directory test-gpu-compile test-slurm docs

test-fast: setup lint test-serial test-mpi

# pyflakes and pycodestyle errors (pyproject.toml [tool.ruff])
lint:
	$(VENV)/bin/ruff check src tests mpi_tests tools

# the GPU engine's kernels compiled by numba-cuda for an H100 (sm_90) without a GPU, and their PTX free of
# fused float64 multiply-adds (tools/gpu_compile.py; .venv-cuda made by tools/setup_cuda.sh, idempotent)
test-gpu-compile:
	@bash tools/setup_cuda.sh
	.venv-cuda/bin/python tools/gpu_compile.py

# the documentation site, docs/ and the API reference from the docstrings (docs/reference.md), into
# build/docs/html; warnings are errors (.venv-docs made by tools/setup_docs.sh, idempotent)
docs:
	@bash tools/setup_docs.sh
	.venv-docs/bin/python -m sphinx -W --keep-going -q -b html docs build/docs/html

# the default selection: pyproject.toml's addopts deselect -m validation
test-serial:
	$(PY) -m pytest -q -rs $(XDIST) tests

# every test of tests/ but the real-Slurm ones, in one pytest-xdist run (test-serial and the first part of
# test-validation together; tests/conftest.py hands the long validation runs out first, so that the short
# tests fill the workers' ends)
test-pytest:
	$(PY) -m pytest -q -rs --durations=25 $(XDIST) -m "not slurm" tests

# every MPI test on 2 ranks; on 3 and 4 those of the decomposition itself (slabs, ghosts, migration, the state
# files' collective writes): the runs of a feature (API, flow arrest, stiffening) match one rank at 2 ranks
MPI_MORE = mpi_tests/test_decomposition.py mpi_tests/test_exchange.py mpi_tests/test_state_files.py \
  mpi_tests/test_mpi_basics.py mpi_tests/test_analysis_files.py mpi_tests/test_grid.py mpi_tests/test_bulk_end.py
# the one-rank references, computed by the 2-rank session and read by the 3- and 4-rank ones (mpi_helpers.py)
MPI_REFERENCES = $(CURDIR)/build/mpi-references.json

test-mpi:
	@if ls mpi_tests/test_*.py >/dev/null 2>&1; then \
	  mkdir -p build; rm -f $(MPI_REFERENCES); \
	  for n in 2 3 4; do \
	    files=mpi_tests; [ $$n -gt 2 ] && files="$(MPI_MORE)"; \
	    echo "== $$files under mpiexec -n $$n"; \
	    MPDEM_TEST_REFERENCES=$(MPI_REFERENCES) timeout 600 $(MPIEXEC) -n $$n $(PY) -m pytest -q --color=no \
	      -p no:cacheprovider $$files || exit 1; \
	  done; \
	  rm -f $(MPI_REFERENCES); \
	else echo "== no mpi_tests yet"; fi

# the long runs alone (physics to convergence, real Slurm jobs); MPI ones, if any is marked, on 2 ranks.
# The real-Slurm tests run by themselves after the rest: their 2-rank job chain needs both cores to meet its deadline.
test-validation:
	$(PY) -m pytest -q -rs $(XDIST) -m "validation and not slurm" tests
	@$(MAKE) --no-print-directory test-slurm

test-slurm:
	$(PY) -m pytest -q -rs -m "validation and slurm" tests
	@if grep -qs "mark.validation" mpi_tests/test_*.py; then \
	  echo "== mpi_tests -m validation under mpiexec -n 2"; \
	  timeout 1800 $(MPIEXEC) -n 2 $(PY) -m pytest -q --color=no -p no:cacheprovider -m validation mpi_tests || exit 1; \
	fi

# The LAMMPS side-by-side case from a particle table: make bench TABLE=path/to/landed20k.txt.gz
bench: setup
	@test -n "$(TABLE)" || { echo "make bench TABLE=path/to/landed20k.txt.gz: bench needs a particle table"; exit 2; }
	$(PY) -m mpdem bench --table "$(TABLE)"

# The paper at development size: every row of analysis/sweeps/dev/*.tsv not finished yet
# (hours on 2 cores; Ctrl-C checkpoints the running rows, the next `make reproduce` goes on),
# then collect into analysis/results/dev. From nothing: rm -rf analysis/results/dev/runs first.
DEV := analysis/sweeps/dev
reproduce: setup
	$(PY) -m mpdem sweep $(DEV)/fig2-4.tsv $(DEV)/fig7.tsv $(DEV)/fig7b.tsv $(DEV)/fig9.tsv $(DEV)/spinners.tsv --config $(DEV)/dev.toml \
	  --out analysis/results/dev/runs --collect analysis/results/dev

# The tables, fits and figures of analysis/results/dev again, from its committed summaries alone.
collect-dev: setup
	$(PY) -m mpdem collect analysis/results/dev/runs --out analysis/results/dev --no-analyze

# The paper at its own geometry (issue 23; analysis/sweeps/paper): the development k_n = 2e5 rows again,
# the paper's height at a quarter of its area, then the paper's size (hours a row; resumable), then collect.
PAPER := analysis/sweeps/paper
PAPER_RUNS := analysis/results/paper/runs
reproduce-paper: setup
	$(PY) -m mpdem sweep $(PAPER)/dev2e5.tsv --config $(DEV)/dev.toml --out $(PAPER_RUNS)/dev --no-collect
	$(PY) -m mpdem sweep $(PAPER)/height.tsv --config $(PAPER)/height.toml --out $(PAPER_RUNS)/height --no-collect
	$(PY) -m mpdem sweep $(PAPER)/size.tsv --config $(PAPER)/size.toml --out $(PAPER_RUNS)/size --no-collect
	$(PY) -m mpdem sweep $(PAPER)/dev-stiff.tsv --config $(DEV)/dev.toml --out $(PAPER_RUNS)/dev --no-collect
	$(PY) -m mpdem sweep $(PAPER)/dev-claims.tsv $(PAPER)/dev-claims-K0.tsv $(PAPER)/dev-claims-hertz.tsv \
	  --config $(DEV)/dev.toml --out $(PAPER_RUNS)/dev --no-collect
	$(MAKE) collect-paper

# The tables, fits and figures of analysis/results/paper from its committed files alone (summaries and
# packings: a run whose analysis is not of its packing's step, or of older measures, is analysed again): the poured piles, the
# flow-arrest ones and the converged rungs of the paper-size stiffening ladders (each rung a set apart from
# the piles poured at its k_n; runs/ladder-dev has its own results, ladder-dev/, made first since the claim
# table cites them; runs/hstop is a table of verdicts, NOTES).
collect-paper: collect-ladder-dev
	$(PY) -m mpdem collect $(PAPER_RUNS)/dev $(PAPER_RUNS)/size $(PAPER_RUNS)/height $(PAPER_RUNS)/flow $(PAPER_RUNS)/ladder-size --out analysis/results/paper

# The N = 2000 stiffening ladders (runs/ladder-dev: each rung a set, its base the poured piles of runs/dev) into
# analysis/results/paper/ladder-dev; a rung that re-pours a committed row is the same sample, skipped.
collect-ladder-dev: setup
	$(PY) -m mpdem collect $(PAPER_RUNS)/dev $(PAPER_RUNS)/ladder-dev --out analysis/results/paper/ladder-dev

clean:
	rm -rf runs .pytest_cache
