# The README's commands. `make test` works on a fresh machine with only Python 3.11 and make.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install system-deps test test-quick test-slow test-order run bench bench-all bench-learning docs docs-gifs lint lock

# Debian packages some tests need (a headless GL for MuJoCo rendering, a real browser for the report).
SYSTEM_PACKAGES := libegl1 libgl1-mesa-dri libgl1 libopengl0 chromium chromium-driver

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade "pip>=24"
	$(PY) -m pip install -q -c constraints.txt -e ".[all,test,docs]"
	touch $(STAMP)

install: $(STAMP)

# Installs the missing ones with apt-get, which needs Debian (dpkg) and root. Anywhere else it says what
# to install and goes on: without Chromium the browser tests skip; MuJoCo's rendering tests need EGL.
system-deps:
	@if ! command -v dpkg >/dev/null 2>&1 || ! command -v apt-get >/dev/null 2>&1; then \
		echo "system-deps: not a Debian system; install with your package manager: a headless EGL/OpenGL"; \
		echo "  (libEGL, Mesa DRI drivers) and Chromium with chromedriver (browser tests skip without it;"; \
		echo "  MuJoCo rendering tests need EGL)."; \
		exit 0; fi; \
	missing=""; for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" != 0 ]; then \
		echo "system-deps: missing Debian packages:$$missing"; \
		echo "  install them with: sudo apt-get install$$missing"; \
		echo "  (browser tests skip without Chromium; MuJoCo rendering tests need EGL)"; \
		exit 0; fi; \
	apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing

# Both cores, one test file per worker: a file's module fixtures (compiled programs, the PB2 runs, the
# CLI's trained run) are built once. (pytest-xdist 3.8's loadgroup does not group tests under pytest 9.)
# Three tiers: `test` before every commit (every module and family; 15 minutes on 2 cores from a fresh
# clone), `test-quick` after every edit (no learning, no large compiles; 90 s), `test-slow` for what
# cannot be made cheap (the other MJX and Brax parity programs, the reaching tasks' checker, the
# families' own learning checks, PB2 on Ray, the wheel in a fresh venv); CI runs `test` and `test-slow`.
PYTEST := $(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

test: system-deps install
	$(PYTEST) -m "not slow" --durations=25 --junitxml=.pytest_cache/junit.xml

test-quick: install
	$(PYTEST) -m quick

test-slow: system-deps install
	$(PYTEST) -m slow --durations=25 --junitxml=.pytest_cache/junit-slow.xml

# After a fresh clone's `make test` and `make test-slow`, as CI runs them: the test files' order and
# the expected times (tests/file_durations.json), from their durations.
test-order:
	$(PY) tools/order_tests.py .pytest_cache/junit.xml --slow .pytest_cache/junit-slow.xml

run: install
	$(VENV)/bin/contextrl run quickstart

# The environment speed tables; also written as Markdown where the docs' benchmarks page includes them.
bench: install
	$(PY) benchmarks/bench_envs.py --markdown benchmarks/results/envs.md

# The agents beside Stable-Baselines3, PureJaxRL and CleanRL at equal budgets (benchmarks/learning.py):
# final returns with intervals over seeds, curves, wall time. PUREJAXRL: a checkout of
# luchris429/purejaxrl; CLEANRL: a checkout of vwxyzjn/cleanrl.
bench-learning: install
	@test -f "$(PUREJAXRL)/purejaxrl/ppo.py" || { echo "give PUREJAXRL=<a checkout of luchris429/purejaxrl>"; exit 2; }
	@test -f "$(CLEANRL)/cleanrl/dqn_jax.py" || { echo "give CLEANRL=<a checkout of vwxyzjn/cleanrl>"; exit 2; }
	$(PY) benchmarks/learning.py --purejaxrl $(PUREJAXRL) --cleanrl $(CLEANRL)

# Every speed table of docs/benchmarks.md, one script after another, each printing its table (with the
# load average and peers' versions) into benchmarks/results/latest/<script>.txt. Hours on 2 cores: the
# agent, findings and optimality-gap scripts train many agents. Peers' environments are built on first use.
BENCH_TABLES := bench_envs bench_gymnasium bench_faces bench_box2d bench_host_vector bench_dmc \
	bench_vehicle_racing bench_rna bench_platformer bench_brax bench_compile_cache bench_compile_flags \
	bench_agents bench_sac_host learning_curves bench_findings bench_optimality_gap

bench-all: install
	mkdir -p benchmarks/results/latest
	for script in $(BENCH_TABLES); do \
		echo "== benchmarks/$$script.py"; \
		$(PY) benchmarks/$$script.py | tee benchmarks/results/latest/$$script.txt || exit 1; \
	done

# The documentation site (docs/, mkdocs.yml) into site/; --strict turns a broken link, a missing page or a
# docstring the API reference cannot read into an error. The family pages' feature tables are generated
# from the feature declarations during the build (tools/docs_hooks.py).
docs: install
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet

# Re-render the family pages' animations (docs/images/*.gif, committed) with `contextrl render`.
docs-gifs: install
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(PY) tools/render_docs_gifs.py

lint: install
	$(VENV)/bin/ruff check src tests benchmarks examples
	$(VENV)/bin/ruff format --check src tests benchmarks examples

# Re-pin every installed distribution (run after changing dependencies in pyproject.toml).
lock: install
	$(PY) -m pip freeze --exclude-editable | grep -v '^-e' > constraints.txt
