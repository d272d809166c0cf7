# The README's two commands: `make demo` and `make test`. Everything else is for developers.
CARGO ?= cargo
OUT ?= out
DEMO_INPUT ?= fixtures/hdri/city_512.exr

.PHONY: all build demo test unit lint fmt fmt-check bench bench-quick fuzz conformance ray-test conformance-engines clean

all: build

build:
	$(CARGO) build --release --workspace --bins

# Where cargo puts the binaries: $(CARGO_TARGET_DIR)/release when it is set, else target/release.
BIN_DIR = $(if $(CARGO_TARGET_DIR),$(CARGO_TARGET_DIR),target)/release

# Bakes the embedded default fixture into out/ and says where the results are. No fallback:
# a missing binary or a failing bake is said as it is.
demo: build
	@test -x $(BIN_DIR)/bake || { echo "make demo: no bake binary in $(BIN_DIR) after the build (CARGO_TARGET_DIR=$(CARGO_TARGET_DIR))" >&2; exit 1; }
	$(BIN_DIR)/bake run pipelines/probe.ron
	$(BIN_DIR)/contact-sheet --quiet out/probe -o out/probe/contact-sheet.png
	@echo "demo outputs are in out/probe/: cube/ (faces), prefiltered/ (GGX chain + prefilter.json),"
	@echo "  irradiance/ (sh.json + E/pi cube), dfg/dfg.exr, shexp/shexp.json; run it again: all up to date"
	@echo "contact sheet of all of it: out/probe/contact-sheet.png"

# Workspace tests (unit, stress and end-to-end), then clippy and rustfmt. Tests run in the
# release profile so that `make test`, `make demo` and `make bench-quick` share one build of
# the dependencies and binaries. Only test targets are built here: the benchmark examples are
# compiled (and linted) by clippy --all-targets and run by `make bench`, and no crate has
# doctests, so building the examples and running rustdoc here would only cost time.
test: unit lint fmt-check

unit:
	$(CARGO) test --release --workspace --lib --bins --tests

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

fmt:
	$(CARGO) fmt --all

fmt-check:
	$(CARGO) fmt --all --check

bench:
	scripts/bench.sh

bench-quick:
	scripts/bench.sh --quick

# Independent readers, decoders and writers (libktx, the ktx2 crate, ktx-parse, imagecodecs)
# check every container and format the bakes write; installs them from PyPI and npm.
conformance: build
	conformance/run.sh

# The Ray executor (python/) on a two-node Ray cluster on 127.0.0.1: builds the release `bake`
# if needed, installs ray, pytest and bake-ray (scripts/setup-ray.sh), runs python/tests.
ray-test: build
	scripts/setup-ray.sh
	cd python && BAKE_RAY_BIN_DIR=$(abspath $(BIN_DIR)) python3 -m pytest -q tests

# Coverage-guided fuzzing of every parser for a bounded time (FUZZ_SECONDS per target).
fuzz:
	scripts/fuzz.sh

# three.js and Babylon.js (npm, in node) read what --target three|babylon bakes.
conformance-engines:
	conformance/engines/run.sh

clean:
	rm -rf $(OUT)
