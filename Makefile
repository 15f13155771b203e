# Each target creates .venv and installs what is missing by itself (idempotent).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out

.PHONY: demo test bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml constraints.txt
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/telethermal demo --out $(OUT)/demo

test: $(STAMP)
	$(PY) -m pytest tests

bench: $(STAMP)
	$(VENV)/bin/telethermal bench physics --json $(OUT)/bench/physics.json --png $(OUT)/bench/physics.png
	$(VENV)/bin/telethermal bench identify --json $(OUT)/bench/identify.json --png $(OUT)/bench/identify.png
	$(VENV)/bin/telethermal bench render --json $(OUT)/bench/render.json --png $(OUT)/bench/render.png
	$(VENV)/bin/telethermal bench transport --json $(OUT)/bench/transport.json
	$(VENV)/bin/telethermal bench faults --json $(OUT)/bench/faults.json
	$(VENV)/bin/telethermal bench devices --json $(OUT)/bench/devices.json
	$(VENV)/bin/telethermal bench record --json $(OUT)/bench/record.json
	$(VENV)/bin/telethermal bench view --json $(OUT)/bench/view.json
	$(VENV)/bin/telethermal bench report --results $(OUT)/bench --out bench/report.md

clean:
	rm -rf $(VENV) $(OUT)
