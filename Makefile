# Set-up on a fresh machine is part of every target: .venv is created and filled on demand,
# with every extra (train, video, sb3, ray) and the dev tools; constraints.txt pins torch.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
export SDL_VIDEODRIVER ?= dummy
export SDL_AUDIODRIVER ?= dummy
export WANDB_MODE ?= offline
export PYGAME_HIDE_SUPPORT_PROMPT := 1

.PHONY: install test demo lint bench clean

$(BIN)/alphatank: pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e '.[all,dev]'
	touch $(BIN)/alphatank

install: $(BIN)/alphatank

# One BLAS/OpenMP thread per test worker: two workers share the two cores.
test: export OPENBLAS_NUM_THREADS = 1
test: export OMP_NUM_THREADS = 1
test: install
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n 2 --durations=15

demo: install
	$(BIN)/alphatank demo

lint: install
	$(BIN)/ruff check .

bench: install
	$(BIN)/alphatank bench

clean:
	rm -rf $(VENV) runs .pytest_cache
