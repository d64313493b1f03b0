# The README's two commands: `make demo` and `make test`. Everything else is set up from here.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= demo-output
# The application installs the versions in requirements.lock (tested together); pyproject.toml keeps the loose
# ranges for library users. `make lock` refreshes the lock with uv and runs the tests on the new versions.
LOCK   := requirements.lock
UV_VERSION  := 0.13.9
PIP_VERSION := 25.3
LOCK_TOOL   := .lock-tool

.PHONY: demo test lint install system-check browser-check lock clean

# System libraries we cannot pip-install: EGL (libglvnd) and Mesa's software GL driver (llvmpipe).
system-check:
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || \
	  { echo "Python 3.11+ is required (found: $$($(PYTHON) --version))."; exit 1; }
	@ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libGL.so.1' || \
	  { echo "Missing system EGL/GL libraries. Install them with:"; \
	    echo "  sudo apt-get install -y libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"; exit 1; }

# The monitor's browser tests need Debian's chromium and its driver: installed here when root, else reported.
browser-check:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || \
	  { if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y chromium chromium-driver; else \
	    echo "Missing chromium (the monitor's browser tests). Install it with:"; \
	    echo "  sudo apt-get install -y chromium chromium-driver"; exit 1; fi; }

$(VENV)/.installed-test: pyproject.toml $(LOCK)
	$(MAKE) system-check
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q pip==$(PIP_VERSION)
	$(BIN)/pip install -q -c $(LOCK) -e '.[test]'
	touch $@

install: $(VENV)/.installed-test

demo: install
	$(BIN)/antarium demo --out $(OUT)
	@echo "Next: '. $(VENV)/bin/activate' puts antarium (and the python that imports it) on this shell's PATH"
	@echo "for the other commands in README.md, e.g. 'antarium demo --rig-seconds 8', 'antarium --help'."

test: install browser-check
	$(BIN)/ruff check .
	$(BIN)/pytest

# Refresh the lock to the newest versions pyproject.toml allows (every platform, Python 3.11+), then install them
# into a new .venv and run the tests on them: commit requirements.lock only if that passes.
lock:
	$(PYTHON) -m venv $(LOCK_TOOL)
	$(LOCK_TOOL)/bin/pip install -q uv==$(UV_VERSION)
	$(LOCK_TOOL)/bin/uv pip compile pyproject.toml --extra test --universal --fork-strategy fewest --python-version 3.11 --upgrade \
	  --custom-compile-command "make lock" \
	  --quiet -o $(LOCK)
	rm -rf $(VENV)
	$(MAKE) test

clean:
	rm -rf $(VENV) $(LOCK_TOOL) build *.egg-info $(OUT)
