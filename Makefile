# Each target creates .venv and installs what is missing by itself (idempotent).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out
TT := $(VENV)/bin/telethermal

.PHONY: demo test test-all docs fuzz bench bench-quick bench-full clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml constraints.txt
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/telethermal demo --out $(OUT)/demo

# Two workers (pytest-xdist; tests/conftest.py gives each a whole test file
# at a time); the 25 slowest tests in every log. `test` leaves out the tests
# behind the `compose` and `slow` markers (an image build and a Docker stack;
# the guides run command by command, and every test over about 10 s on a
# 2-core machine), so that it stays under 10 minutes; `test-all` runs every
# test, as .ci/run does.
test: $(STAMP)
	$(PY) -m pytest tests -n 2 --durations=25 -m "not compose and not slow"

test-all: $(STAMP)
	$(PY) -m pytest tests -n 2 --durations=25

# The docs site (mkdocs.yml) into $(OUT)/site, warnings as errors.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir $(OUT)/site

# The fuzz suite's long profile (tests/fuzz/fuzzing.py: 2000 cases per
# reader, bounded by count, not time); prints the cases per reader, their
# outcomes and the loads' peak memory. `make test` runs its short profile.
fuzz: $(STAMP)
	TELETHERMAL_FUZZ=long $(PY) -m pytest tests/fuzz -q -s

# The benches, in the report's order, in three sizes (each bench's own
# options: fewer methods, seeds, sessions, trials, rounds, messages or
# settings; each JSON keeps its command and the report names every reduced
# run):
#   bench-full   every bench at its defaults into bench/results/ and
#                bench/report.md: the committed figures (the longest run)
#   bench        reduced, into $(OUT)/bench/ and $(OUT)/bench/report.md:
#                identify on the default methods (the slave's effusivity-fit
#                among them) and one session, render and faults on their
#                smoke runs (--quick), unseen on 2 seeds
#   bench-quick  reduced further, into $(OUT)/bench-quick/: every bench on
#                its smallest run, every section of each bar render's
#                generator comparison, identify's methods other than
#                effusivity-lda and its physical limit (the oracle)
# `bench` and `bench-quick` train the sessions' identifier and generator once
# (`telethermal models`, fingertip-7, seed 0: the files each bench would train
# by itself, byte for byte) and give them to the benches that run sessions
# (--models); `bench-full` trains them in each bench.
# The view bench needs Chromium (apt-get install chromium).
BENCHES := physics identify render transport faults devices record view unseen
SESSION_BENCHES := render faults devices record view

BENCH_physics   :=
BENCH_identify  := --methods effusivity-fit,effusivity-lda,pca-fnn --sessions 1
BENCH_render    := --quick
BENCH_transport :=
BENCH_faults    := --quick
BENCH_devices   :=
BENCH_record    :=
BENCH_view      :=
BENCH_unseen    := --seeds 2

QUICK_physics   := --repeats 1
QUICK_identify  := --methods effusivity-lda --sessions 1 --no-limit
QUICK_render    := --quick
QUICK_transport := --quick
QUICK_faults    := --quick --seeds 1
QUICK_devices   := --samples 500 --slave-trials 1 --contact-s 1
QUICK_record    := --rounds 1 --contact-s 1
QUICK_view      := --touches 1 --contact-s 1
QUICK_unseen    := --quick --seeds 1

# $(call bench-run,NAME,FOLDER,OPTIONS): one bench, its JSON and figure in FOLDER.
define bench-run
	$(TT) bench $(1) --json $(2)/$(1).json $(3)

endef
# $(call shared-models,NAME,FOLDER): --models FOLDER/models for a session bench.
shared-models = $(if $(filter $(1),$(SESSION_BENCHES)),--models $(2)/models)

bench-full: $(STAMP)
	mkdir -p bench/results
	$(foreach b,$(BENCHES),$(call bench-run,$(b),bench/results,))
	$(TT) bench report --results bench/results --out bench/report.md

bench: $(STAMP)
	mkdir -p $(OUT)/bench
	$(TT) models --scene fingertip-7 --seed 0 --out $(OUT)/bench/models
	$(foreach b,$(BENCHES),$(call bench-run,$(b),$(OUT)/bench,$(BENCH_$(b)) $(call shared-models,$(b),$(OUT)/bench)))
	$(TT) bench report --results $(OUT)/bench --out $(OUT)/bench/report.md

bench-quick: $(STAMP)
	mkdir -p $(OUT)/bench-quick
	$(TT) models --scene fingertip-7 --seed 0 --out $(OUT)/bench-quick/models
	$(foreach b,$(BENCHES),$(call bench-run,$(b),$(OUT)/bench-quick,$(QUICK_$(b)) $(call shared-models,$(b),$(OUT)/bench-quick)))
	$(TT) bench report --results $(OUT)/bench-quick --out $(OUT)/bench-quick/report.md

clean:
	rm -rf $(VENV) $(OUT)
