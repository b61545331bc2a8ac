# relray: the README's commands.  Everything installs into .venv from scratch.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
export NUMBA_CACHE_DIR ?= $(CURDIR)/.cache/numba

.PHONY: venv demo test lint stress bench bench-quick clean gallery

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[dev]"
	touch $(STAMP)

venv: $(STAMP)

## make demo: render the default fly-by into out/flyby and a contact sheet
demo: $(STAMP)
	$(BIN)/relray render presets/flyby.toml
	$(BIN)/relray contact-sheet out/flyby --out out/flyby_contact_sheet.png
	@echo "frames:        $(CURDIR)/out/flyby/"
	@echo "contact sheet: $(CURDIR)/out/flyby_contact_sheet.png"

## make test: lint and the whole test suite
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .

## make gallery: the seed report's figures, rendered into docs/gallery
gallery: $(STAMP)
	$(BIN)/python docs/gallery.py

clean:
	rm -rf out .cache .pytest_cache
