# One command sets everything up and runs the demo (`make demo`), one the tests (`make test`).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
EXTRAS ?= test,rl,cluster
# On machines that carry the CPU build of torch 2.13.0 in /opt/wheels, pin it so that
# stable-baselines3 does not pull a multi-GB CUDA build; elsewhere install normally.
TORCH_PIN := $(if $(wildcard /opt/wheels/torch-2.13.0*),-c constraints/local-cpu-torch.txt,)

.PHONY: setup logs test test-slow demo bench docs-check clean

comma := ,
setup: $(VENV)/.installed-$(subst $(comma),_,$(EXTRAS))

$(VENV)/.installed-%: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip >/dev/null
	$(BIN)/python -m pip install $(TORCH_PIN) -e '.[$(EXTRAS)]'
	touch $@

# The log parsers of the `logs` extra (keep this list in step with pyproject.toml), installed in their own
# step: orangebox 0.5.0's wheel declares a console script without a callable (`bb2csv = scripts:None`), so
# pip installs the module and then exits with status 1. We tolerate exactly that status and then prove the
# install by importing every parser; any other failure stops make.
LOG_PARSERS := 'pyulog>=1.0' 'pymavlink>=2.4'
LOG_DECODER := 'orangebox>=0.4'

logs: $(VENV)/.installed-logs

$(VENV)/.installed-logs: pyproject.toml | setup
	$(BIN)/python -m pip install $(LOG_PARSERS)
	$(BIN)/python -m pip install $(LOG_DECODER) || test $$? -eq 1
	$(BIN)/python -c "import orangebox, pyulog, pymavlink.DFReader; print('log parsers: ok')"
	touch $@

# The suite without the tests marked slow (each over ~5 s and covered at smaller size by a fast one);
# test-slow runs only those.
test: setup logs
	$(BIN)/python -m pytest -q -m "not slow"

test-slow: setup logs
	$(BIN)/python -m pytest -q -m slow

demo: setup
	$(BIN)/python scripts/demo.py --out demo-out

bench: setup
	$(BIN)/python scripts/bench.py

# Re-run the quick figures of docs/ and fail when one drifted from the text (about 3 minutes).
docs-check: setup
	$(BIN)/python scripts/docs_check.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache
