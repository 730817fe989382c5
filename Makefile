# hmlvs: one command each for a new user on a fresh Debian/Ubuntu machine.
#   make demo   install everything, then calibrate a simulated session
#   make test   install everything, then run the test suite
#   make bench  install everything, then run the benchmarks and write bench/RESULTS.md
#
# Everything Python goes into the project's virtual environment .venv (made with the Python
# found as $(PYTHON) when it is missing; uv, installed inside it, does the installing), never
# into the system Python. Afterwards: `. .venv/bin/activate`, then `hmlvs --help`.
# The Debian packages (Eigen, Ceres; GoogleTest for the tests) come from apt.

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
UV := $(VENV)/bin/uv
APT_PACKAGES ?= libeigen3-dev libceres-dev
# needed by make test (the C++ tests); the browser is only for the report's screenshot check,
# so a failure to install it does not stop the run (with CI=true the check then fails)
TEST_APT_PACKAGES ?= libgtest-dev
BROWSER_APT_PACKAGES ?= chromium

# The extension is built without build isolation, by the build tools installed in .venv (the
# dependency group `build`), in one persistent CMake tree: a second build compiles only what
# changed, and nothing when nothing did. The wheel is installed into .venv (newest releases of
# the dependencies) and, by make test, into .venv-lowest (the declared lower bounds).
BUILD_DIR := build/venv
WHEEL_DIR := build/wheel
# CI (CI=true) builds with warnings as errors; make test builds the C++ tests in the same tree.
CMAKE_WERROR := $(if $(CI),-C cmake.define.HMLVS_WERROR=ON,)
SOURCES := CMakeLists.txt pyproject.toml README.md \
	$(shell find cpp python -type f \( -name '*.cpp' -o -name '*.h' -o -name '*.py' \
	  -o -name 'CMakeLists.txt' -o -name 'py.typed' \) -not -path '*/__pycache__/*')
CPP_SOURCES = $(shell find cpp python/bindings bench -name '*.cpp' -o -name '*.h')
SUDO := $(shell if [ "$$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then echo sudo; fi)

.PHONY: deps test-deps venv install test-install style deps-check demo test test-fast test-lowest \
	bench clean

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

# Build the wheel in $(BUILD_DIR) with the CMake options $(1), install it into .venv with the
# newest releases of its dependencies (and the test extra), then leave the stamp $(2).
# Installs compile the bytecode (as pip does; uv does not unless asked): otherwise, where
# PYTHONDONTWRITEBYTECODE is set, every start of hmlvs compiles its libraries again (3 s).
define build_and_install
	rm -rf $(WHEEL_DIR)
	$(UV) build --quiet --no-build-isolation --python $(PY) --wheel --out-dir $(WHEEL_DIR) \
	  -C build-dir=$(BUILD_DIR) $(CMAKE_WERROR) $(1) .
	$(UV) pip install --quiet --compile-bytecode --python $(PY) -r pyproject.toml --extra test
	$(UV) pip install --quiet --compile-bytecode --python $(PY) --no-deps --reinstall \
	  $(WHEEL_DIR)/hmlvs-*.whl
	rm -f $(VENV)/.installed-*
	touch $(2)
endef

deps:
	$(call apt_install,$(APT_PACKAGES))

test-deps: deps
	$(call apt_install,$(TEST_APT_PACKAGES))
	-$(call apt_install,$(BROWSER_APT_PACKAGES))

$(VENV)/.created:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check "uv>=0.9,<1"
	$(UV) pip install --quiet --python $(PY) --group build
	touch $@

venv: $(VENV)/.created

# The stamps make a second `make demo` or `make test` skip the build and the install when no
# source changed since.
$(VENV)/.installed-app: $(VENV)/.created $(SOURCES)
	$(call build_and_install,-C cmake.define.HMLVS_BUILD_TESTS=OFF,$@)

$(VENV)/.installed-test: $(VENV)/.created $(SOURCES)
	$(call build_and_install,-C cmake.define.HMLVS_BUILD_TESTS=ON,$@)

install: deps $(VENV)/.installed-app

test-install: test-deps $(VENV)/.installed-test

demo: install
	$(VENV)/bin/hmlvs demo

# ruff (Python) and clang-format (C++), the versions pinned in the test extras.
style: test-install
	$(PY) -m ruff check .
	$(VENV)/bin/clang-format --dry-run -Werror $(CPP_SOURCES)

# Every package the code imports is declared in pyproject.toml (configuration there).
deps-check: test-install
	$(PY) -m deptry .

# Style, the dependency check, the C++ tests, the Python suite, then the tests that use
# simulated sessions or images, but for those marked slow, once more under another BLAS kernel:
# a result that depends on the CPU's last bits fails here, not on a user's machine (the slow
# ones are left out of that pass to keep the whole of make test under 10 minutes on 2 cores).
# Last, the same wheel against the declared lower bounds of the dependencies (make test-lowest).
# pytest runs one worker per core (pytest-xdist), each test file on one worker so that a file's
# fixtures are built once.
# The second pass reads the sessions of the tests' independent renderer (an oracle, not
# hmlvs) that the first one drew (tests/oracles/independent_render.py); the cache lives for
# one make test.
PYTEST := $(PY) -m pytest -q -n auto --dist loadfile
RENDER_CACHE := build/test-render-cache
test: test-install style deps-check
	$(VENV)/bin/ctest --test-dir $(BUILD_DIR) --output-on-failure
	rm -rf $(RENDER_CACHE) && mkdir -p $(RENDER_CACHE)
	HMLVS_TEST_RENDER_CACHE=$(abspath $(RENDER_CACHE)) $(PYTEST)
	HMLVS_TEST_RENDER_CACHE=$(abspath $(RENDER_CACHE)) OPENBLAS_CORETYPE=Prescott \
	  $(PYTEST) -m "scene and not one_kernel and not slow"
	rm -rf $(RENDER_CACHE)
	$(MAKE) --no-print-directory test-lowest

# A quick loop while developing: the Python suite without the tests marked slow (make test
# runs everything).
test-fast: test-install
	$(PYTEST) -m "not slow"

# The oldest releases pyproject.toml admits (uv's lowest-direct resolution), with the wheel
# make test built, over the command-line and API smoke tests (marker `smoke`).
LOWEST := .venv-lowest
test-lowest: test-install
	rm -rf $(LOWEST)
	$(UV) venv --quiet --python $(PY) $(LOWEST)
	$(UV) pip install --quiet --python $(LOWEST)/bin/python --resolution lowest-direct \
	  -r pyproject.toml --extra test
	$(UV) pip install --quiet --python $(LOWEST)/bin/python --no-deps $(WHEEL_DIR)/hmlvs-*.whl
	$(UV) pip list --python $(LOWEST)/bin/python | grep -iE '^(numpy|scipy|matplotlib|opencv-python-headless|typer|click|rich|pyyaml|pillow|pytest) '
	$(LOWEST)/bin/python -m pytest -q -p no:cacheprovider -n auto --dist loadfile -m smoke

# vision-calibration (the bench extra) is optional: without it the joint-calibration section
# says so and still gives hmlvs' numbers.
bench: deps $(VENV)/.installed-app
	-$(UV) pip install --quiet --python $(PY) "vision-calibration>=0.9,<1" || \
	  echo "vision-calibration not installed: bench/RESULTS.md will show hmlvs alone"
	-$(UV) pip install --quiet --python $(PY) "pyswarms>=1.3,<2" || \
	  echo "pyswarms not installed: bench/RESULTS.md will say so"
	$(PY) bench/run_bench.py

clean:
	rm -rf build dist *.egg-info $(VENV) $(LOWEST)
