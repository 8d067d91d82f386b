# Set-up and the main commands. Every target creates .venv if needed and installs the
# project with exactly the versions in constraints.txt.
PY ?= python3
BIN := .venv/bin

.PHONY: install install-distributed demo test test-all lint results bench eval learning-results learning-task

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

# Format, lint and import order (configured in pyproject.toml); CI runs it before the tests.
lint: install
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .

bench: install
	NUMBA_NUM_THREADS=1 $(BIN)/python benchmarks/step_speed.py --sizes 1000 10000
	$(BIN)/python benchmarks/mobility.py

# docs/results.md: every controller judged under benchmark protocol v1 (docs/benchmark/v1, written by
# proteo eval --benchmark v1; docs/guides/benchmark.md), with intervals, the aggregate and learning curves.
results: install
	$(BIN)/python -m training.results --benchmark v1

eval: install
	$(BIN)/proteo eval --config configs/eval.yaml --out docs/eval --publish docs/journal/learning-first-round.md

# The multi-seed study at control level move (python -m training.study): plain PPO (16 M
# agent-steps per run), then the clones of the rules (training/imitate.py) and PPO kickstarted
# from them (6 M agent-steps), three training seeds each, about 80 minutes on 2 cores; then its
# evaluation: the table with the spread over training seeds goes into docs/eval/study,
# docs/journal/learning-study-move.md and README.md; the same checkpoints at twice their size into
# docs/eval/study_larger and docs/journal/learning-study-move.md.
learning-results: install
	$(BIN)/python -m training.study --total-steps 16000000 --minutes 0 --parallel 2
	$(BIN)/python -m training.study --recipes "[imitation, kickstart]" --minutes 0 --parallel 2
	$(BIN)/python -m training.study --recipes "[imitation]" --level full --tasks "[chain, grasp]" --seeds "[0]" --parallel 2
	$(BIN)/python -m training.study --recipes "[ppo48]" --tasks "[table]" --minutes 0 --parallel 2
	$(BIN)/python -m training.study --recipes "[curriculum]" --tasks "[chain, table, grasp, locomotion]" --minutes 0 --parallel 2
	$(BIN)/python -m training.study --recipes "[credit]" --tasks "[grasp]" --minutes 0 --parallel 2
	$(BIN)/proteo eval --config configs/eval_study.yaml --out docs/eval/study --pictures \
		--publish docs/journal/learning-study-move.md --publish README.md
	$(BIN)/proteo eval --config configs/eval_study_larger.yaml --out docs/eval/study_larger \
		--publish docs/journal/learning-study-move.md
	$(BIN)/proteo eval --config configs/eval_study_larger_curriculum.yaml --tasks chain,table,grasp,locomotion \
		--out docs/eval/study_larger_curriculum --pictures --publish docs/journal/learning-curriculum-credit.md

# One task of the study, every recipe (make learning-task TASK=grasp, about 15 minutes; table's 48 M-step
# curriculum adds half an hour): its checkpoints and curves are replaced; the evaluation goes to
# docs/eval/study_<task> (not published).
learning-task: install
	@test -n "$(TASK)" || { echo "TASK is required; allowed: chain, branch, table, grasp, locomotion"; exit 2; }
	$(BIN)/python -m training.study --tasks "[$(TASK)]" --total-steps 16000000 --minutes 0 --parallel 2
	$(BIN)/python -m training.study --tasks "[$(TASK)]" --recipes "[imitation, kickstart]" --minutes 0 --parallel 2
	case "$(TASK)" in chain|table|grasp|locomotion) \
		$(BIN)/python -m training.study --tasks "[$(TASK)]" --recipes "[curriculum]" --minutes 0 --parallel 2;; esac
	$(BIN)/proteo eval --config configs/eval_study.yaml --tasks $(TASK) --out docs/eval/study_$(TASK)
