# Two commands set everything up on a fresh machine:
#   make run   - build the FMUs and run the KAVZ-685 scene (plots + summary in results/kavz685/)
#   make test  - run the test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt 2>/dev/null | cksum | cut -d' ' -f1)

.PHONY: run test fmus bench fuzz mutants clean distclean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test]'
	rm -f $(VENV)/.installed-*
	touch $@

fmus: $(STAMP)
	$(BIN)/lever build

run: $(STAMP)
	$(BIN)/lever run

test: $(STAMP)
	$(BIN)/lever build
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/lever bench kavz685
	$(BIN)/lever bench kavz685_stiff

# A longer, randomised property-based fuzz run (20x the CI examples; see tests/test_fuzz.py),
# the physics and FMUs' fuzz and the command line's (tests/test_input_safety.py).
fuzz: $(STAMP)
	$(BIN)/lever build
	LEVER_FUZZ_SCALE=$${LEVER_FUZZ_SCALE:-20} $(BIN)/python -m pytest -q tests/test_fuzz.py tests/test_input_safety.py -k fuzz --hypothesis-show-statistics

# Mutation testing (mutmut) of the physics and the masters with the tests that cover them:
# tens of minutes, outside CI's budget and not part of `make test` (docs/testing.md).
mutants: $(STAMP)
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test,mutation]'
	$(BIN)/lever build
	$(BIN)/python tests/mutation/run_mutants.py $(MUTANTS_ARGS)

clean:
	rm -rf results build/fmus build/tmp .setuptools-build

distclean: clean
	rm -rf $(VENV)
