# kbcli: two commands for a newcomer, `make demo` and `make test`; the rest rebuilds data and
# reproduces the paper. Every target installs into .venv first when needed.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
KBCLI  := $(BIN)/kbcli
STAMP  := $(VENV)/.kbcli-installed
OUT    ?= out
SEED   ?= 0

.PHONY: help install demo test lint data reproduce reproduce-ideal bench clean

help:
	@echo "make demo        install, then run the main job on the embedded default model"
	@echo "make test        install (with the dev extra), then run the test suite"
	@echo "make data        rebuild data/ (keyboard and default model) from scratch"
	@echo "make reproduce   learn, evaluate and report the paper's experiments (out/report/)"
	@echo "make bench       print the benchmark tables"

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	@touch $@

install: $(STAMP)

test: $(STAMP)
	$(BIN)/pytest -q

lint: $(STAMP)
	$(BIN)/ruff check kbcli tests

demo: $(STAMP)
	@mkdir -p $(OUT)/demo
	$(KBCLI) keyboard --config pipelines/keyboard.toml -o $(OUT)/demo/keyboard.h5
	$(KBCLI) plot keyboard $(OUT)/demo/keyboard.h5 -o $(OUT)/demo/keyboard.png
	$(KBCLI) inspect $(OUT)/demo/keyboard.h5

data: $(STAMP)
	$(KBCLI) keyboard --config pipelines/keyboard.toml -o data/keyboard.h5

clean:
	rm -rf $(OUT) report
