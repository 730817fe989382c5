# hmlvs: one command each for a new user on a fresh Debian/Ubuntu machine.
#   make demo   install everything, then calibrate a simulated session
#   make test   install everything, then run the test suite
#   make bench  install everything, then run the benchmarks and write bench/RESULTS.md

PYTHON ?= python3
APT_PACKAGES ?= libeigen3-dev libceres-dev
# needed by make test (the C++ tests); the browser is only for the report's screenshot check,
# so a failure to install it does not stop the run (with CI=true the check then fails)
TEST_APT_PACKAGES ?= libgtest-dev
BROWSER_APT_PACKAGES ?= chromium
# CI (CI=true) builds with warnings as errors.
PIP_FLAGS := --quiet $(if $(CI),--config-settings=cmake.define.HMLVS_WERROR=ON,)
# make test builds the C++ tests in the extension's own CMake tree (the core compiles once).
TEST_BUILD_DIR := build/test
TEST_PIP_FLAGS := $(PIP_FLAGS) --config-settings=build-dir=$(TEST_BUILD_DIR) \
	--config-settings=cmake.define.HMLVS_BUILD_TESTS=ON
CPP_SOURCES = $(shell find cpp python/bindings bench -name '*.cpp' -o -name '*.h')
SUDO := $(shell if [ "$$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then echo sudo; fi)

.PHONY: deps test-deps install test-install style demo test bench clean

# Install the Debian packages that are missing (apt-get update + install, as root or via sudo).
define apt_install
	@missing=""; for p in $(1); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "Installing Debian packages:$$missing"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $$missing; \
	fi
endef

deps:
	$(call apt_install,$(APT_PACKAGES))

test-deps: deps
	$(call apt_install,$(TEST_APT_PACKAGES))
	-$(call apt_install,$(BROWSER_APT_PACKAGES))

install: deps
	$(PYTHON) -m pip install $(PIP_FLAGS) ".[test]"

demo: install
	$(PYTHON) -m hmlvs demo

test-install: test-deps
	$(PYTHON) -m pip install $(TEST_PIP_FLAGS) ".[test]"

# ruff (Python) and clang-format (C++), the versions pinned in the test extras.
style: test-install
	$(PYTHON) -m ruff check .
	clang-format --dry-run -Werror $(CPP_SOURCES)

# Style, the C++ tests, the Python suite, then the tests that use simulated sessions or images
# once more under another BLAS kernel: a result that depends on the CPU's last bits fails
# here, not on a user's machine.
# pytest runs one worker per core (pytest-xdist), each test file on one worker so that a file's
# fixtures are built once.
PYTEST := $(PYTHON) -m pytest -q -n auto --dist loadfile
test: test-install style
	ctest --test-dir $(TEST_BUILD_DIR) --output-on-failure
	$(PYTEST)
	OPENBLAS_CORETYPE=Prescott $(PYTEST) -m scene

# vision-calibration (the bench extra) is optional: without it the joint-calibration section
# says so and still gives hmlvs' numbers.
bench: deps
	$(PYTHON) -m pip install $(PIP_FLAGS) ".[test]"
	-$(PYTHON) -m pip install --quiet "vision-calibration>=0.9,<1" || \
	  echo "vision-calibration not installed: bench/RESULTS.md will show hmlvs alone"
	-$(PYTHON) -m pip install --quiet "pyswarms>=1.3,<2" || \
	  echo "pyswarms not installed: bench/RESULTS.md will say so"
	$(PYTHON) bench/run_bench.py

clean:
	rm -rf build dist *.egg-info
