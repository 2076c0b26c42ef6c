# M3DP — the two commands a new machine needs:
#   make demo   installs everything (Debian 12, as root or with sudo), builds, runs the default demo
#   make test   installs and builds as needed, then runs every test
BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
M3DP = $(BUILD_DIR)/apps/m3dp/m3dp

.PHONY: all setup configure build install test demo bench fuzz clean

all: build

setup:
	@bash scripts/setup-debian.sh

$(BUILD_DIR)/build.ninja:
	cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: setup $(BUILD_DIR)/build.ninja

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

# The m3dp program and the Python module into /usr/local (PREFIX=... for another place). Both
# read the material presets and robot models from this checkout.
PREFIX ?= /usr/local
install: build
	cmake --install $(BUILD_DIR) --prefix $(PREFIX)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 900
	bash scripts/fuzz.sh $(FUZZ_SECONDS)

# The readers under AddressSanitizer and UndefinedBehaviorSanitizer, fuzzed FUZZ_SECONDS a target
# (make test runs it; FUZZ_SECONDS=3600 make fuzz for a long run).
FUZZ_SECONDS ?= 60
fuzz: setup
	bash scripts/fuzz.sh $(FUZZ_SECONDS)

demo: build
	$(M3DP) run scenes/ur10_wall.sdf -o out/ur10_wall
	@echo "To watch the demo in the browser: $(M3DP) view out/ur10_wall  (then open the address it prints)"

bench: build
	$(M3DP) bench --particles 50000
	$(M3DP) bench ur10_wall
	$(BUILD_DIR)/bench/bench_sph

clean:
	rm -rf $(BUILD_DIR) build-fuzz
