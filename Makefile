# Convenience targets around CMake. Builds use both cores (-j2) by default.
JOBS ?= 2
BUILD ?= build
ASAN_BUILD ?= build-asan
CMAKE_FLAGS ?=
DEMO_OUT ?= out

# ccache, when installed (tools/install-deps.sh installs it), caches compilations across build
# directories and clones: a clean clone rebuilds in a fraction of the time when the cache has seen
# the same sources. CCACHE_BASEDIR makes its keys independent of where the clone lives, and
# CCACHE_NOHASHDIR keeps the working directory out of the keys of compilations with debug
# information (the sanitizer build's -g1): otherwise every clone in another directory rebuilds
# that build from scratch. The price: a cached object's debug information names the directory it
# was first compiled in (sanitizer reports still give each file's path within the repository).
CCACHE := $(shell command -v ccache 2>/dev/null)
ifneq ($(CCACHE),)
LAUNCHER := -DCMAKE_CXX_COMPILER_LAUNCHER=$(CCACHE) -DCMAKE_C_COMPILER_LAUNCHER=$(CCACHE)
export CCACHE_BASEDIR := $(CURDIR)
export CCACHE_NOHASHDIR := 1
endif

.PHONY: all build python test test-asan test-tsan-bags fuzz bench demo clean format

all: build

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release $(LAUNCHER) $(CMAKE_FLAGS)

build: $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j$(JOBS)

# The Python module and package under $(BUILD)/python (import it with PYTHONPATH=$(BUILD)/python).
python: $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j$(JOBS) --target lidar2d_python
	@echo "python: built $(BUILD)/python/lidar2d; use it with PYTHONPATH=$(BUILD)/python /usr/bin/python3"

test: build
	cd $(BUILD) && ctest --output-on-failure -j$(JOBS)

# -O1 (ASan's recommended level; asserts stay on) and -g1 (line tables, enough for the sanitizers'
# stack traces): the tests run about 7x faster than at -O0 (14 min -> under 2 min on two cores).
$(ASAN_BUILD)/CMakeCache.txt:
	cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug "-DCMAKE_CXX_FLAGS_DEBUG=-g1 -O1" -DLIDAR2D_SANITIZE=ON -DLIDAR2D_BUILD_BENCH=OFF $(LAUNCHER) $(CMAKE_FLAGS)

# AddressSanitizer + UndefinedBehaviorSanitizer build of the whole test suite.
test-asan: $(ASAN_BUILD)/CMakeCache.txt
	cmake --build $(ASAN_BUILD) -j$(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --output-on-failure -j$(JOBS)

# ThreadSanitizer on the ROS1 bag reader's chunk prefetch (its only threads; the whole suite under
# TSan would take another full build): the reader and a small driver, built with -fsanitize=thread,
# read every shared bag and the fixture bags (`make test` builds those).
DATA_DIR ?= $(if $(LIDAR2D_DATA_DIR),$(LIDAR2D_DATA_DIR),../shared/data)
test-tsan-bags: build
	$(CXX) -std=c++20 -O1 -g -fsanitize=thread -I. -Iinclude tests/tsan/ros1_bag_threads.cpp \
	  src/io/internal/ros1_bag.cpp src/io/internal/decompress.cpp src/core/error.cpp -lfmt -lbz2 -llz4 -lzstd -o $(BUILD)/tsan_ros1_bag
	TSAN_OPTIONS=halt_on_error=1 $(BUILD)/tsan_ros1_bag $(wildcard $(DATA_DIR)/raw/*.bag $(DATA_DIR)/bags/*.bag) \
	  $(BUILD)/tests/fixtures/tf_chain.bag $(BUILD)/tests/fixtures/many_chunks.bag

# Mutation fuzzing of the CLI's inputs (logs, bags, maps, databases, options) with the sanitizer
# build: reports crashes, hangs, sanitizer errors, silent failures and partial outputs, keeping the
# inputs in $(FUZZ_WORK). About 10 minutes at the default 50 inputs per mode; FUZZ_SEED varies them.
FUZZ_RUNS ?= 50
FUZZ_SEED ?= 1
FUZZ_WORK ?= fuzz-work
fuzz: $(ASAN_BUILD)/CMakeCache.txt
	cmake --build $(ASAN_BUILD) -j$(JOBS) --target lidar2d_cli
	./tools/fuzz-cli.py $(ASAN_BUILD)/lidar2d --runs $(FUZZ_RUNS) --seed $(FUZZ_SEED) --work $(FUZZ_WORK)

bench: build
	$(BUILD)/bench/lidar2d_bench

# The main job on the built-in default: simulate the office world and run the most complete
# pipeline that exists, writing under $(DEMO_OUT)/. Builds only the program it runs (the tests and
# benchmarks take minutes more on two cores).
demo: $(BUILD)/CMakeCache.txt
	@echo "demo: building the lidar2d program ($(BUILD)/lidar2d) only, not the tests or benchmarks"
	cmake --build $(BUILD) -j$(JOBS) --target lidar2d_cli
	./tools/demo.sh $(BUILD)/lidar2d $(DEMO_OUT)

format:
	find include src apps tests bench -name '*.hpp' -o -name '*.cpp' | xargs clang-format -i

clean:
	rm -rf $(BUILD) $(ASAN_BUILD)
