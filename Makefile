# edgepath: the commands README shows. `make setup` is idempotent and fast when nothing changed:
# each step leaves a stamp file and reruns only when what it depends on changed.
#
#   make setup     Debian packages (if missing), .venv with pinned Python packages, build and
#                  install the package, editable (one CMake build in build/py: module, C++
#                  tests and programs; Python edits need no reinstall, C++ edits a `make`)
#   make build     same as setup
#   make test      C++ tests (ctest) and Python tests (pytest)
#   make demo      the inverse-rendering demo: images, GIF and convergence plot in demo_out/
#   make bench     run bench/run.sh, if there is one (options: BENCH_ARGS="--runs 3")
#   make fuzz      N mutated scene, mesh and image files through the loaders and a small render,
#                  and mutated values and forms of a Python scene through ep.render (one view
#                  or two), render_channels or derivative_image and their gradients, and
#                  that scene moved elsewhere (the same image and gradients over the scale),
#                  each in a child process with time and memory caps (N=1000 SEED=0; inputs
#                  that crash are copied to build/fuzz/found, a line per case in build/fuzz/log.jsonl)
#   make truth     N random forms of that scene, a random parameter each: derivative images
#                  against finite differences over seeds (N=1000 SEED=0; a line per case in
#                  build/fuzz/truth.jsonl, the cases whose estimates disagree printed)
#   make sanitize  C++ tests built with AddressSanitizer + UBSan (build/asan)
#   make lint      byte-compile the Python sources; ruff if the venv has it
#   make clean     remove build outputs (distclean: also the venv)

SHELL := /bin/bash
.DEFAULT_GOAL := build

PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
JOBS := $(shell nproc 2>/dev/null || echo 2)
export CMAKE_BUILD_PARALLEL_LEVEL := $(JOBS)
CMAKE_GENERATOR_FLAG := $(if $(shell command -v ninja 2>/dev/null),-G Ninja,)

APT_PACKAGES := cmake ninja-build g++ make pkg-config python3-venv python3-dev \
	libembree-dev libtbb-dev libgtest-dev libtinyobjloader-dev \
	libopenexr-dev libpng-dev libjpeg-dev
# torch is pinned to the version the tests run; the package itself accepts torch>=2,<3.
PIP_PACKAGES := torch==2.13.0 numpy opencv-python-headless nanobind scikit-build-core pytest \
	pillow matplotlib

# Everything the package build reads. The list itself is a prerequisite (through
# build/sources.list, rewritten only when it changes) so adding or deleting a file rebuilds.
SOURCES := $(sort $(shell find src support bindings python apps bench tests/cpp tests/cmake_package cmake \
	-type f \( -name '*.cpp' -o -name '*.h' -o -name '*.py' -o -name '*.cmake' -o -name '*.in' \
	-o -name CMakeLists.txt \) 2>/dev/null)) CMakeLists.txt pyproject.toml

APT_STAMP := build/apt.stamp
DEPS_STAMP := $(VENV)/edgepath-deps.stamp
INSTALL_STAMP := build/py/edgepath-install.stamp

.PHONY: setup build test demo bench fuzz truth sanitize lint clean distclean FORCE

setup: $(INSTALL_STAMP)
build: setup

$(APT_STAMP): Makefile
	@mkdir -p $(@D)
	@missing=""; \
	for p in $(APT_PACKAGES); do \
	  dpkg -s $$p 2>/dev/null | grep -q '^Status: install ok installed' || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  sudo=""; [ "$$(id -u)" = 0 ] || sudo=sudo; \
	  echo "installing Debian packages:$$missing"; \
	  $$sudo apt-get update && \
	  $$sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $$missing; \
	fi
	@touch $@

$(VENV)/pyvenv.cfg: | $(APT_STAMP)
	$(PYTHON) -m venv $(VENV)

$(DEPS_STAMP): Makefile $(VENV)/pyvenv.cfg | $(APT_STAMP)
	$(VPY) -m pip install $(PIP_PACKAGES)
	@touch $@

build/sources.list: FORCE
	@mkdir -p $(@D)
	@printf '%s\n' $(SOURCES) > $@.new
	@if cmp -s $@.new $@; then rm $@.new; else mv $@.new $@; fi

$(INSTALL_STAMP): $(DEPS_STAMP) build/sources.list $(SOURCES)
	@echo "building edgepath in build/py (the first build takes a few minutes)"
	$(VPY) -m pip install --no-build-isolation -e . \
	  -C cmake.define.EDGEPATH_TESTS=ON -C cmake.define.EDGEPATH_APPS=ON
	@touch $@

test: setup
	ctest --test-dir build/py --output-on-failure -j $(JOBS)
	$(VPY) -m pytest tests/python -q

demo: setup
	$(VENV)/bin/edgepath demo --output-dir demo_out

bench: setup
	@if [ -f bench/run.sh ]; then PATH="$(CURDIR)/$(VENV)/bin:$$PATH" bash bench/run.sh $(BENCH_ARGS); \
	else echo "no benchmarks yet (bench/run.sh)"; fi

N ?= 1000
SEED ?= 0
fuzz: setup
	@mkdir -p build/fuzz
	$(VPY) tests/fuzz/fuzz.py --cases $(N) --seed $(SEED) --save build/fuzz/found \
	  --log build/fuzz/log.jsonl

truth: setup
	@mkdir -p build/fuzz
	$(VPY) tests/fuzz/truth.py --cases $(N) --seed $(SEED) --log build/fuzz/truth.jsonl

sanitize: | $(APT_STAMP)
	cmake -S . -B build/asan $(CMAKE_GENERATOR_FLAG) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DEDGEPATH_SANITIZE=ON -DEDGEPATH_PYTHON=OFF -DEDGEPATH_TESTS=ON -DEDGEPATH_APPS=OFF
	cmake --build build/asan --target edgepath_tests -j $(JOBS)
	UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  build/asan/edgepath_tests

lint: $(DEPS_STAMP)
	$(VPY) -m compileall -q python/edgepath tests/python
	@if $(VPY) -m ruff --version >/dev/null 2>&1; then $(VPY) -m ruff check python tests/python; \
	else echo "ruff not installed in $(VENV): skipped"; fi

clean:
	rm -rf build demo_out

distclean: clean
	rm -rf $(VENV)
