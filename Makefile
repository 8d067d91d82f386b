# Set-up and the main commands. Every target creates .venv if needed and installs the
# project with exactly the versions in constraints.txt.
PY ?= python3
BIN := .venv/bin

.PHONY: install install-distributed demo test test-all fuzz lint results bench learning-results learning-results-v7 benchmark-references benchmark-references-v8 scale-results-v8 size-results-v9 benchmarl test-benchmarl

$(BIN)/python:
	$(PY) -m venv .venv

install: $(BIN)/python
	$(BIN)/pip install -q -c constraints.txt torch==2.13.0
	$(BIN)/pip install -q -c constraints.txt -e ".[test,train]"

# The tests also cover Ray (the distributed extra, docs/guides/distributed.md).
install-distributed: install
	$(BIN)/pip install -q -c constraints.txt -e ".[test,train,distributed]"

demo: install
	$(BIN)/proteo demo

# The fast tier (tests not marked slow) over both cores; test-all adds the slow tier (Ray, the
# browser, every training config, multi-seed evidence, no-JIT runs, every task id): CI runs it.
test: install-distributed
	$(BIN)/python -m pytest -n 2 -m "not slow"

test-all: install-distributed
	$(BIN)/python -m pytest -n 2

# The property-based search for bad input (tests/test_fuzz.py: env settings, array-API actions, program texts,
# checkpoint metadata) with 2,000 examples each instead of the test suite's 40: about 20 minutes on 2 cores.
fuzz: install
	PROTEO_FUZZ_EXAMPLES=2000 $(BIN)/python -m pytest -n 2 -p no:cacheprovider tests/test_fuzz.py

# BenchMARL in its own environment, .venv-benchmarl (BenchMARL 1.5 needs torchrl < 0.12, the train
# extra pins 0.14): proteo with the versions of constraints-benchmarl.txt; test-benchmarl runs
# BenchMARL's MAPPO and IPPO on proteo there (tests/test_benchmarl.py; CI runs it after test-all).
.venv-benchmarl/bin/python:
	$(PY) -m venv .venv-benchmarl

benchmarl: .venv-benchmarl/bin/python
	.venv-benchmarl/bin/pip install -q -c constraints-benchmarl.txt torch==2.13.0
	.venv-benchmarl/bin/pip install -q -c constraints-benchmarl.txt -e . benchmarl pytest hypothesis

test-benchmarl: benchmarl
	PROTEO_NEEDS=benchmarl .venv-benchmarl/bin/python -m pytest -p no:cacheprovider tests/test_benchmarl.py

# Format, lint and import order (configured in pyproject.toml); CI runs it before the tests.
lint: install
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .

bench: install
	NUMBA_NUM_THREADS=1 $(BIN)/python benchmarks/step_speed.py --sizes 1000 10000
	$(BIN)/python benchmarks/mobility.py

# docs/results.md: every controller judged under benchmark protocol v9 (v7, v8's scale splits and v9's
# recipe trained for size: docs/benchmark/v7, v8 and v9, written by proteo eval --benchmark;
# docs/guides/benchmark.md), with paired
# intervals, the aggregate, learning curves and success against size; the README's held-out table and
# marl-eval's file from the same judgements.
results: install
	$(BIN)/python -m training.judging.results --benchmark v9 --publish README.md --marl-eval docs/results/marl_eval.json

# The study under benchmark protocols v1 to v6 (configs/benchmark/, docs/guides/benchmark.md),
# about 230 minutes on 2 cores: five independent training (or evolution) seeds of each recipe of
# docs/benchmark/v6/results.md (python -m training.trainers.study) into checkpoints/v1 (v2: CMA-ES over the rules'
# parameters; v3: evolved chain programs; v4 and v5: evolved branch, table and grasp programs, from the paper's and from random ones;
# v6: evolution with ten times the episodes per generation on all four), each recipe judged on every split of its task (proteo eval
# --benchmark) into docs/benchmark/<version>/<task>/<recipe>, then v6's results page. The rules' and random's rows are
# judged once per protocol (v1, and v7, which does not extend it): make benchmark-references (v7: about 10 minutes).
STUDY := --minutes 0 --parallel 2 --seeds "[0, 1, 2, 3, 4]"
STUDY_V1 := $(STUDY) --keep-dir checkpoints/v1 --docs-dir docs/benchmark/v1/learning --runs-dir runs/v1
STUDY_V2 := $(STUDY) --keep-dir checkpoints/v2 --docs-dir docs/benchmark/v2/learning --runs-dir runs/v2
STUDY_V3 := $(STUDY) --keep-dir checkpoints/v3 --docs-dir docs/benchmark/v3/learning --runs-dir runs/v3
STUDY_V4 := $(STUDY) --keep-dir checkpoints/v4 --docs-dir docs/benchmark/v4/learning --runs-dir runs/v4
STUDY_V5 := $(STUDY) --keep-dir checkpoints/v5 --docs-dir docs/benchmark/v5/learning --runs-dir runs/v5
STUDY_V6 := $(STUDY) --keep-dir checkpoints/v6 --docs-dir docs/benchmark/v6/learning --runs-dir runs/v6
learning-results: install
	$(BIN)/python -m training.trainers.study --recipes "[imitation, kickstart]" --tasks "[chain, branch, table, grasp, locomotion]" $(STUDY_V1)
	$(BIN)/python -m training.trainers.study --recipes "[credit]" --tasks "[grasp]" $(STUDY_V1)
	$(BIN)/python -m training.trainers.study --recipes "[ppo]" --tasks "[chain, branch, grasp, locomotion]" --total-steps 16000000 $(STUDY_V1)
	$(BIN)/python -m training.trainers.study --recipes "[cma]" --tasks "[grasp, table, branch, chain]" --level full $(STUDY_V2)
	$(BIN)/python -m training.trainers.study --recipes "[evolve, evolve-paper]" --tasks "[chain]" --level full $(STUDY_V3)
	$(BIN)/python -m training.trainers.study --recipes "[evolve-paper]" --tasks "[branch, table, grasp]" --level full $(STUDY_V4)
	$(BIN)/python -m training.trainers.study --recipes "[evolve]" --tasks "[branch, table, grasp]" --level full $(STUDY_V5)
	$(BIN)/python -m training.trainers.study --recipes "[evolve-large, evolve-large-paper]" --tasks "[chain, branch, table, grasp]" --level full $(STUDY_V6)
	for version in v1 v2 v3 v4 v5 v6; do for recipe in checkpoints/$$version/*/*_*; do \
		$(BIN)/proteo eval --benchmark $$version $$(printf -- '--checkpoint %s ' $$recipe/seed_*) \
			--out docs/benchmark/$$version/$$(basename $$(dirname $$recipe))/$$(basename $$recipe) || exit 1; done; done
	$(BIN)/python -m training.judging.results --benchmark v6 --out docs/benchmark/v6/results.md

# Protocol v7 (standalone: ten training seeds, 100 worlds each, table-v2, branch's edge_start): each recipe's
# config, budget, task id and starting clone come from configs/benchmark/v7.yaml (training.trainers.study --benchmark
# v7). About 18 hours on 2 cores, 14 of them evolution; a study stopped part way resumes from runs/v7.
STUDY_V7 := --benchmark v7 --minutes 0 --parallel 2 --seeds "[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]" \
	--keep-dir checkpoints/v7 --docs-dir docs/benchmark/v7/learning --runs-dir runs/v7
learning-results-v7: install
	$(BIN)/python -m training.trainers.study --recipes "[imitation, kickstart, ppo]" --tasks "[chain, branch, table, grasp, locomotion]" $(STUDY_V7)
	$(BIN)/python -m training.trainers.study --recipes "[credit]" --tasks "[grasp]" $(STUDY_V7)
	$(BIN)/python -m training.trainers.study --recipes "[cma, evolve-large, evolve-large-paper]" --tasks "[chain, branch, table, grasp]" --level full $(STUDY_V7)
	for recipe in checkpoints/v7/*/*_*; do \
		$(BIN)/proteo eval --benchmark v7 $$(printf -- '--checkpoint %s ' $$recipe/seed_*) \
			--out docs/benchmark/v7/$$(basename $$(dirname $$recipe))/$$(basename $$recipe) || exit 1; done
	$(MAKE) results

# Every v7 recipe's ten checkpoints on protocol v8's scale splits, each split in its own folder
# (OUT/x10, OUT/x100: judged apart, so that the short x10 is published before the long x100):
# hours on 2 cores; a split judged already is skipped, an interrupted one resumes from its
# episodes.jsonl; then the results page.
scale-results-v8: install
	for recipe in checkpoints/v7/chain/kickstart_move checkpoints/v7/*/*_*; do \
		task=$$(basename $$(dirname $$recipe)); \
		case $$task in chain|branch) splits="x10 x100";; *) splits=x10;; esac; \
		for split in $$splits; do out=docs/benchmark/v8/$$task/$$(basename $$recipe)/$$split; \
			test -f $$out/benchmark.json || $(BIN)/proteo eval --benchmark v8 $$(printf -- '--checkpoint %s ' $$recipe/seed_*) \
				--splits $$split --out $$out || exit 1; done; done
	$(MAKE) results

# Protocol v9's recipe trained for size, kickstart-sizes-move, on chain and grasp: ten training seeds from
# the published clones (about 1.4 minutes a seed on one core), kept in checkpoints/v9, then judged on
# every split (chain's x100 apart, in OUT/x100: about two hours on one core), then the results page.
size-results-v9: install
	$(BIN)/python -m training.trainers.study --benchmark v9 --recipes "[kickstart-sizes]" --tasks "[chain, grasp]" \
		--seeds "[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]" --minutes 0 --clone-dir checkpoints/v7 --keep-dir checkpoints/v9 \
		--docs-dir docs/benchmark/v9/learning --runs-dir runs/v9
	for task in chain grasp; do out=docs/benchmark/v9/$$task/kickstart-sizes_move; \
		case $$task in chain) splits="--splits heldout,larger,x10";; *) splits="";; esac; \
		test -f $$out/benchmark.json || $(BIN)/proteo eval --benchmark v9 \
			$$(printf -- '--checkpoint %s ' checkpoints/v9/$$task/kickstart-sizes_move/seed_*) $$splits --out $$out || exit 1; done
	test -f docs/benchmark/v9/chain/kickstart-sizes_move/x100/benchmark.json || $(BIN)/proteo eval --benchmark v9 \
		$$(printf -- '--checkpoint %s ' checkpoints/v9/chain/kickstart-sizes_move/seed_*) --splits x100 \
		--out docs/benchmark/v9/chain/kickstart-sizes_move/x100
	$(MAKE) results

# The references on protocol v8's scale splits (configs/benchmark/v8.yaml), about an hour on 2 cores; a
# reference judged already is skipped, an interrupted one resumes from its episodes.jsonl.
benchmark-references-v8: install
	for task in chain branch table grasp locomotion; do \
		case $$task in chain|branch) splits=x10,x100;; *) splits=x10;; esac; \
		for who in "rules full rules_full" "rules move rules_move" "random move random"; do set -- $$who; \
			test -f docs/benchmark/v8/$$task/$$3/benchmark.json || $(BIN)/proteo eval --benchmark v8 --policy $$1 --level $$2 \
				--tasks $$task --splits $$splits --out docs/benchmark/v8/$$task/$$3 || exit 1; done; done

benchmark-references: install
	for version in v1 v7; do for task in chain branch table grasp locomotion; do \
		$(BIN)/proteo eval --benchmark $$version --policy rules --level full --tasks $$task --out docs/benchmark/$$version/$$task/rules_full && \
		$(BIN)/proteo eval --benchmark $$version --policy rules --level move --tasks $$task --out docs/benchmark/$$version/$$task/rules_move && \
		$(BIN)/proteo eval --benchmark $$version --policy random --level move --tasks $$task --out docs/benchmark/$$version/$$task/random \
		|| exit 1; done; done
