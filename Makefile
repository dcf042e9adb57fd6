# Two commands set everything up on a fresh machine:
#   make run   - build the FMUs and run the KAVZ-685 scene (plots + summary in results/kavz685/)
#   make test  - run the test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt 2>/dev/null | cksum | cut -d' ' -f1)

.PHONY: run test fmus docs bench fuzz mutants clean distclean

# Quiet set-up: pip's -qq prints errors only (not setuptools' notes on how the editable
# install works); a failed install still stops here with pip's error message.
$(STAMP): pyproject.toml constraints.txt
	@echo "setting up $(VENV) with the pinned dependencies (once; about a minute) ..."
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@$(BIN)/python -m pip install -qq --upgrade pip
	@$(BIN)/python -m pip install -qq -c constraints.txt -e '.[test]'
	@rm -f $(VENV)/.installed-*
	@touch $@

fmus: $(STAMP)
	$(BIN)/lever build

run: $(STAMP)
	@$(BIN)/lever run

# The reference pages (docs/reference/) regenerated from the code: the FMUs' model
# descriptions, the click commands, the master registry, the scene format (build/docs.py).
docs: $(STAMP)
	$(BIN)/python build/docs.py

# Tests run side by side on every core (pytest-xdist; `make test JOBS=1` for one at a time);
# those marked serial (tests/conftest.py SERIAL: verdicts on wall-clock time) run alone after.
JOBS     ?= auto
PARALLEL := -n $(JOBS) --dist loadgroup

# Python keeps its compiled bytecode (__pycache__, ignored by git) also where the environment
# says not to write it (PYTHONDONTWRITEBYTECODE): without it every pytest process and every
# `lever` a test starts compiled the project anew, and pytest rewrote every test module's
# asserts - two thirds of each collection's CPU time.  Not PYTHONPYCACHEPREFIX: the
# bytecode of each FMU's unpacked copy would stay there after the copy is removed.
export PYTHONDONTWRITEBYTECODE :=

# After its prerequisite test-dispatch (below), the oracles first - expected values that do
# not come from the code under test, so a wrong model fails within minutes - then the rest.
# The FMUs are built before the workers start, so that none of them waits for the build.
test: $(STAMP)
	$(BIN)/lever build
	$(BIN)/python -m pytest -q -x -m oracle $(PARALLEL)
	$(BIN)/python -m pytest -q -m "not oracle and not serial" $(PARALLEL)
	$(BIN)/python -m pytest -q -m "not oracle and serial"

# The fast subset for the edit-test loop: every test not marked slow (tests/conftest.py
# SLOW), tests of every folder among them; `make test` still runs everything.
.PHONY: test-fast
test-fast: $(STAMP)
	$(BIN)/lever build
	$(BIN)/python -m pytest -q -m "not slow" $(PARALLEL)

# The numerics-sensitive tests again with numpy's SIMD dispatch limited to each lower level
# this CPU has, so that a test that holds at one dispatch level only fails here too
# (docs/testing.md); a prerequisite of `test`, kept apart from its recipe.  One pytest per
# level, no workers: its 119 tests take a few seconds, less than two workers' start-up and
# collection (15 s CPU against 17-25 s, and sooner beside other work).
.PHONY: test-dispatch
test: test-dispatch
test-dispatch: $(STAMP)
	$(BIN)/python tests/numpy_dispatch.py

# The host recipes (examples/hosts/) in the hosts the environment names - PYFMI_PYTHON,
# OMSIMULATOR, OMSIMULATOR_PYTHONPATH (docs/hosts.md) -, each result judged by `lever validate`
# at the default verdict: prints the table host x recipe -> verdict.
.PHONY: hosts
hosts: $(STAMP)
	$(BIN)/lever build
	$(BIN)/python examples/hosts/run_recipes.py

bench: $(STAMP)
	$(BIN)/lever bench kavz685
	$(BIN)/lever bench kavz685_stiff

# A longer, randomised property-based fuzz run (20x the CI examples; see tests/physics/test_fuzz.py),
# the physics and FMUs' fuzz and the command line's (tests/cli/test_input_safety.py).
fuzz: $(STAMP)
	$(BIN)/lever build
	LEVER_FUZZ_SCALE=$${LEVER_FUZZ_SCALE:-20} $(BIN)/python -m pytest -q tests/physics/test_fuzz.py tests/cli/test_input_safety.py -k fuzz --hypothesis-show-statistics

# Mutation testing (mutmut) of the physics, the masters and the judges with the tests that cover them:
# tens of minutes, outside CI's budget and not part of `make test` (docs/testing.md).
mutants: $(STAMP)
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test,mutation]'
	$(BIN)/lever build
	$(BIN)/python tests/mutation/run_mutants.py $(MUTANTS_ARGS)

clean:
	rm -rf results build/fmus build/fmus3 build/tmp .setuptools-build

distclean: clean
	rm -rf $(VENV)
