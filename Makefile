# relray: the README's commands.  Everything installs into .venv from scratch.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
PIP    := $(BIN)/python -m pip --disable-pip-version-check
UV     := uv==0.13.9
export NUMBA_CACHE_DIR ?= $(CURDIR)/.cache/numba

.PHONY: venv lock demo test lint stress bench bench-quick clean gallery extension test-blender \
	mitsuba-venv mitsuba-lock \
	blender-pictures

## the venv: exactly the versions (and file hashes) of requirements.lock, then relray
## itself as an editable install without dependencies
$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --require-hashes --no-deps -r requirements.lock
	$(PIP) install --quiet --no-deps --no-build-isolation -e .
	$(PIP) check
	touch $(STAMP)

venv: $(STAMP)

## make lock: resolve pyproject.toml (+ the dev extra and the build tools) into
## requirements.lock, with hashes, for CPython 3.11 on x86-64 Linux (uv, pinned, in a
## throw-away venv).  Pins already in the lock stay unless `make lock UPGRADE=1`.
## Commit the result; `make venv` then installs exactly that everywhere.
lock:
	rm -rf .cache/lock-venv && $(PYTHON) -m venv .cache/lock-venv
	.cache/lock-venv/bin/python -m pip install --quiet --disable-pip-version-check "$(UV)"
	.cache/lock-venv/bin/uv pip compile pyproject.toml requirements-build.in --extra dev \
		--python-version 3.11 --python-platform x86_64-manylinux_2_28 --generate-hashes \
		$(if $(UPGRADE),--upgrade) --custom-compile-command "make lock" -o requirements.lock

## make demo: render the default fly-by into out/flyby and a contact sheet
demo: $(STAMP)
	$(BIN)/relray render presets/flyby.toml
	$(BIN)/relray contact-sheet out/flyby --out out/flyby_contact_sheet.png
	@echo "frames:        $(CURDIR)/out/flyby/"
	@echo "contact sheet: $(CURDIR)/out/flyby_contact_sheet.png"

## make test: lint and the whole test suite (tests/blender included: the add-on's tests
## run under the bpy module in one child process, see tests/blender/test_bpy_module.py)
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q --durations=25

## make test-blender: the same tests/blender files under a real `blender -b` (Debian
## trixie's Blender 4.3 with Python 3.13, in a debootstrap chroot cached in
## ~/.cache/relray; needs root; about 3 minutes and 2.5 GB the first time)
test-blender: $(STAMP)
	tests/blender/real_blender.sh all

## make blender-pictures: the README's pictures of the Relativity panels and the Rendered
## viewport, captured from an interactive Blender on a virtual display in the same chroot
## (docs/blender/)
blender-pictures: $(STAMP)
	tests/blender/real_blender.sh all -k test_viewport_draw
	mkdir -p docs/blender
	cp $${RELRAY_CACHE:-$$HOME/.cache/relray}/trixie-blender/tmp/relray-pictures/*.png docs/blender/
	@echo "pictures in docs/blender/"

## make extension: the Blender extension zips in dist/ (linux-x64, macos-arm64,
## windows-x64, each with its platform's wheels of the core's dependencies), built and
## validated with Blender's extension CLI from the bpy module
extension: $(STAMP)
	$(BIN)/python relblend/packaging.py build dist

lint: $(STAMP)
	$(BIN)/ruff check .

## make stress: the stress suite's long variants (about 5 minutes on 2 cores): the full
## render grid, 5000-example fuzzers, every malformed job through a real process and the
## 1920x1080 memory bound (measured with /usr/bin/time -v; apt-get install time if missing)
stress: $(STAMP)
	@test -x /usr/bin/time || echo "note: /usr/bin/time missing, memory read with getrusage"
	RELRAY_STRESS=1 $(BIN)/python -m pytest -q -m stress -s -p no:cacheprovider

## make gallery: the seed report's figures and the moving objects (presets/moving), rendered into docs/gallery
gallery: $(STAMP)
	$(BIN)/python docs/gallery.py
	$(BIN)/python docs/starbow.py

## the Mitsuba 3 peer of the benchmark, in a venv of its own (its numpy and Dr.Jit never
## meet the core's): exactly bench/mitsuba.lock, plus Debian's libLLVM 19 unpacked into
## .cache/llvm19 without root (apt-get download + dpkg -x) for the llvm_ad_spectral
## variant (LLVM 15/16 abort with "Cannot select ... fminimum"; apt-get update first only
## when root and the package lists lack it).  Where that cannot run, the bench reports the
## LLVM variant as not run, with the reason.
MITSUBA_VENV := .cache/mitsuba-venv
MITSUBA_STAMP := $(MITSUBA_VENV)/.installed-stamp
$(MITSUBA_STAMP): bench/mitsuba.lock
	rm -rf $(MITSUBA_VENV)
	$(PYTHON) -m venv $(MITSUBA_VENV)
	$(MITSUBA_VENV)/bin/python -m pip install --quiet --disable-pip-version-check \
		--require-hashes --no-deps -r bench/mitsuba.lock
	-test -e .cache/llvm19/root/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 || \
		(rm -rf .cache/llvm19 && mkdir -p .cache/llvm19 && cd .cache/llvm19 && \
		 { apt-get download libllvm19 </dev/null || { [ "$$(id -u)" = 0 ] && \
		   apt-get update -qq </dev/null && apt-get download libllvm19 </dev/null; }; } && \
		 dpkg -x libllvm19_*.deb root && rm -f libllvm19_*.deb) || \
		echo "note: libLLVM 19 not available; the bench reports llvm_ad_spectral as not run"
	touch $(MITSUBA_STAMP)

mitsuba-venv: $(MITSUBA_STAMP)

## make mitsuba-lock: resolve bench/mitsuba.in into bench/mitsuba.lock (hashed, like lock)
mitsuba-lock:
	rm -rf .cache/lock-venv && $(PYTHON) -m venv .cache/lock-venv
	.cache/lock-venv/bin/python -m pip install --quiet --disable-pip-version-check "$(UV)"
	.cache/lock-venv/bin/uv pip compile bench/mitsuba.in --python-version 3.11 \
		--python-platform x86_64-manylinux_2_28 --generate-hashes \
		--custom-compile-command "make mitsuba-lock" -o bench/mitsuba.lock

## make bench: the benchmark suite (10 min idle, up to an hour busy): bench/results/*.csv,
## plots, bench/RESULTS.md; installs bpy 5.0.1 (Cycles, the anchor) if it is missing
bench: $(STAMP) $(MITSUBA_STAMP)
	$(BIN)/python -c "import bpy" 2>/dev/null || \
		$(BIN)/python -m pip install --quiet --disable-pip-version-check "bpy==5.0.1"
	$(BIN)/python -m relray.bench.run

## make bench-quick: the same at small sizes in under 3 minutes (bench/results/quick/);
## Cycles comes from the dev extra's bpy (without bpy its series are left out)
bench-quick: $(STAMP) $(MITSUBA_STAMP)
	$(BIN)/python -m relray.bench.run --quick

clean:
	rm -rf out .cache .pytest_cache
