# The README's two commands: `make demo` and `make test`. Everything else is set up from here.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= demo-output

.PHONY: demo test lint install system-check clean

# System libraries we cannot pip-install: EGL (libglvnd) and Mesa's software GL driver (llvmpipe); chromium.
system-check:
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || \
	  { echo "Python 3.11+ is required (found: $$($(PYTHON) --version))."; exit 1; }
	@ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libGL.so.1' || \
	  { echo "Missing system EGL/GL libraries. Install them with:"; \
	    echo "  sudo apt-get install -y libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"; exit 1; }
	@# the monitor's browser tests: Debian's chromium and its driver (installed here when root)
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || \
	  { if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y chromium chromium-driver; else \
	    echo "Missing chromium (the monitor's browser tests). Install it with:"; \
	    echo "  sudo apt-get install -y chromium chromium-driver"; exit 1; fi; }

$(VENV)/.installed-test: pyproject.toml
	$(MAKE) system-check
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

install: $(VENV)/.installed-test

demo: install
	$(BIN)/antarium demo --out $(OUT)

test: install system-check
	$(BIN)/ruff check .
	$(BIN)/pytest

clean:
	rm -rf $(VENV) build *.egg-info $(OUT)
