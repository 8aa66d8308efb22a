# Two commands on a fresh Debian machine with Python 3.11: `make run` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SYSTEM_LIBS := libusb-1.0-0 libgl1 libegl1 libgomp1 bubblewrap
# Browser tests drive Debian's Chromium through Playwright (never a downloaded browser); the
# production image's sandbox is tested in a podman container (runc: crun refuses hybrid cgroups);
# the multi-host test makes network namespaces with iproute2 and its own PostgreSQL cluster and
# Redis server in them.
TEST_SYSTEM_PACKAGES := chromium podman runc iproute2 postgresql redis-server
# The HTTP load generator of benchmarks/leaderboard_throughput.py (benchmarks only).
BENCHMARK_SYSTEM_PACKAGES := wrk

.PHONY: install system-deps test-system-deps benchmark-system-deps apt-packages run demo-run test test-fast lint typecheck benchmark clean

install: $(STAMP)

# Open3D's wheels link against these shared libraries, and the planner sandbox runs in
# bubblewrap; install whichever are missing.
system-deps:
	@$(MAKE) --no-print-directory apt-packages PACKAGES="$(SYSTEM_LIBS)"

test-system-deps:
	@$(MAKE) --no-print-directory apt-packages PACKAGES="$(TEST_SYSTEM_PACKAGES)"

benchmark-system-deps:
	@$(MAKE) --no-print-directory apt-packages PACKAGES="$(BENCHMARK_SYSTEM_PACKAGES)"

apt-packages:
	@missing=""; for p in $(PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing system libraries:$$missing"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	fi

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory system-deps
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[dev]'
	touch $(STAMP)

# The embedded service (API, web pages, one worker; SQLite and a local broker under
# $FLYBO_DATA_DIR, default ~/.local/share/flybo),
# with a demo user and a short MAZE + Classic job. Stop it with Ctrl-C.
HOST ?= 127.0.0.1
PORT ?= 8000
run: install
	$(BIN)/flybo serve --host $(HOST) --port $(PORT) --demo

demo-run: install
	$(BIN)/flybo run --area maze --planner classic --seed 0 --out data/runs/maze-classic-$$(date +%Y%m%d-%H%M%S)

# Tests run in TEST_JOBS processes (pytest-xdist); TEST_JOBS=0 runs them in this process. One
# process more than cores: many tests spend their time waiting on services, sandboxes and
# subprocesses they started, and the extra process keeps every core busy meanwhile (two per core
# loaded the machine so that a Redis round trip of the shared rate limit timed out). The 25
# slowest test phases are listed at the end.
TEST_JOBS ?= $(shell echo $$(( $$(nproc) + 1 )))

# Everything: lint, types and every test (the slow ones, the browser tests and the wheel's
# install into a fresh environment included). Tests are handed to the processes in chunks as they
# free up; a module fixture is set up in each process that runs one of its file's tests.
test: install test-system-deps
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/pytest -n $(TEST_JOBS) --dist load --durations=25

# The inner loop, a few minutes: lint, types and the tests not marked `slow` (tests/conftest.py
# marks the long ones of every folder). Needs no browser.
test-fast: install
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/pytest -n $(TEST_JOBS) --dist load -m "not slow"

benchmark: install benchmark-system-deps
	$(BIN)/python benchmarks/sim_speed.py

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache
