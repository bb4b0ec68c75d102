# One command sets everything up (`make setup`: the package, its extras and every log parser), one runs the
# demo (`make demo`), one the tests (`make test`).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
EXTRAS ?= test,rl,cluster,logs
# On machines that carry the CPU build of torch 2.13.0 in /opt/wheels, pin it so that
# stable-baselines3 does not pull a multi-GB CUDA build; elsewhere install normally.
TORCH_PIN := $(if $(wildcard /opt/wheels/torch-2.13.0*),-c constraints/local-cpu-torch.txt,)
# Extra flags for pip's install of the package and its extras. .ci/run passes --no-compile: its venv lives for one
# run, and byte-compiling every installed module (torch's, scipy's, ...) took 33 of setup's 56 s on a fresh clone,
# while the tests, which lift PYTHONDONTWRITEBYTECODE, compile the modules they import in about no time (pytest
# 4:36 against 4:39 in the same hour). A venv you keep wants the compile: where PYTHONDONTWRITEBYTECODE is set,
# every command would compile its imports again (`heli`'s start 3.4 s against 1.5 s).
PIP_INSTALL_FLAGS ?=

.PHONY: setup logs test test-slow demo bench docs-check clean

comma := ,
setup: $(VENV)/.installed-$(subst $(comma),_,$(EXTRAS)) $(VENV)/.installed-blackbox

$(VENV)/.installed-%: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip >/dev/null
	$(BIN)/python -m pip install $(PIP_INSTALL_FLAGS) $(TORCH_PIN) -e '.[$(EXTRAS)]'
	touch $@

# The blackbox decoder, installed apart from the `logs` extra (pyulog, pymavlink): orangebox 0.5.0's wheel
# declares console scripts without a callable (`bb2csv = scripts/bb2csv`), so pip installs the module and then
# exits with status 1. The line below is heli_core.errors.BLACKBOX_INSTALL, the command `heli` prints when
# orangebox is missing: pip's status is tolerated and the import decides. Then every parser must import.
LOG_DECODER := 'orangebox>=0.5'

$(VENV)/.installed-blackbox: pyproject.toml | $(VENV)/.installed-$(subst $(comma),_,$(EXTRAS))
	$(BIN)/python -m pip install $(LOG_DECODER) || $(BIN)/python -c 'import orangebox'
	$(BIN)/python -c "import orangebox, pyulog, pymavlink.DFReader; print('log parsers: ok')"
	touch $@

# Kept for those who learnt it: the log parsers are part of `make setup`.
logs: setup

# The suite without the tests marked slow (each over ~5 s and covered at smaller size by a fast one);
# test-slow runs only those. One pytest worker per core (pytest-xdist), each test file in one worker so
# that its module fixtures are built once; `make test PYTEST_WORKERS=0` runs in this process alone.
# PYTHONDONTWRITEBYTECODE (set on some machines and runners) is lifted for the tests: with it every worker
# rewrites every test file's assertions at collection and every process a test starts (the CLI, pool workers)
# compiles the package from source again; the bytecode goes to __pycache__/, which git ignores.
PYTEST_WORKERS ?= auto
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile
test: setup
	$(PYTEST) -m "not slow"

test-slow: setup
	$(PYTEST) -m slow

demo: setup
	$(BIN)/python scripts/demo.py --out demo-out

bench: setup
	$(BIN)/python scripts/bench.py

# Re-run the quick figures of docs/ and fail when one drifted from the text (README: how long).
docs-check: setup
	$(BIN)/python scripts/docs_check.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache
