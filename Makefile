# One command sets everything up and runs the demo (`make demo`), one the tests (`make test`).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
EXTRAS ?= test,rl
# On machines that carry the CPU build of torch 2.13.0 in /opt/wheels, pin it so that
# stable-baselines3 does not pull a multi-GB CUDA build; elsewhere install normally.
TORCH_PIN := $(if $(wildcard /opt/wheels/torch-2.13.0*),-c constraints/local-cpu-torch.txt,)

.PHONY: setup test test-slow demo bench clean

setup: $(VENV)/.installed-$(subst $(comma),_,$(EXTRAS))

comma := ,
$(VENV)/.installed-%: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip >/dev/null
	$(BIN)/python -m pip install $(TORCH_PIN) -e '.[$(EXTRAS)]'
	touch $@

test: setup
	$(BIN)/python -m pytest -q

test-slow: setup
	$(BIN)/python -m pytest -q -m slow

demo: setup
	$(BIN)/python scripts/demo.py --out demo-out

bench: setup
	$(BIN)/python scripts/bench.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache
