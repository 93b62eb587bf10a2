# The README's commands. `make test` works on a fresh machine with only Python 3.11 and make.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install system-deps test run bench lint lock

# Debian packages some tests need (a headless GL for MuJoCo rendering, a real browser for the report).
SYSTEM_PACKAGES := libegl1 libgl1-mesa-dri libgl1 libopengl0 chromium chromium-driver

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade "pip>=24"
	$(PY) -m pip install -q -c constraints.txt -e ".[all,test]"
	touch $(STAMP)

install: $(STAMP)

system-deps:
	@missing=""; for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; fi

test: system-deps install
	$(PY) -m pytest -q

run: install
	$(VENV)/bin/contextrl run quickstart

bench: install
	$(PY) benchmarks/bench_envs.py

lint: install
	$(VENV)/bin/ruff check src tests benchmarks examples
	$(VENV)/bin/ruff format --check src tests benchmarks examples

# Re-pin every installed distribution (run after changing dependencies in pyproject.toml).
lock: install
	$(PY) -m pip freeze --exclude-editable | grep -v '^-e' > constraints.txt
