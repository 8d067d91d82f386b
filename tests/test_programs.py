"""Programs of the paper's primitives (baselines/program.py, baselines/program_policy.py).

The chain program's limit comes from a measurement on the benchmark's setting (12 modules,
``sphere``, worlds 1000..1019, docs/guides/programs.md): every world formed the chain, in a
mean 94 cycles, the slowest in 118; the limit here, 200 cycles, is well under the task's 300.
The grasp program's bounds come from the same measurement on grasp's benchmark setting (100
modules, distance 3, 300 cycles): 7 of the 20 worlds grasped, the slowest in 168 cycles; the
test asks for 5 and 250. The branch program on branch's benchmark setting (40 modules, T = 4,
B = 3, 200 cycles): 12 of the 20 worlds, the slowest in 166 cycles; the test asks for 8. The
table program on table's (a 9 x 9 board, 16 spares, 600 cycles): 5 of 20 worlds; the test asks
for 2 of them.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import small_overrides
from test_compiled_rollout import assert_same_trajectory, drive

import proteo_env
from baselines import make_policy
from baselines.compiled import compiled_rollout
from baselines.program import (
    ACTIONS,
    CONDITIONS,
    DIRECTION_CLASSES,
    PROGRAMS_DIR,
    SET_TARGETS,
    format_program,
    load_program,
)
from baselines.program_policy import ProgramMemory, ProgramPolicy, ProgramReading
from proteo_env.config import ConfigError
from proteo_env.rollout import run_episode

CHAIN = (PROGRAMS_DIR / "chain.yaml").read_text()
GRASP_PAPER = (PROGRAMS_DIR / "grasp.yaml").read_text()
BRANCH_PAPER = (PROGRAMS_DIR / "branch.yaml").read_text()
TABLE_PAPER = (PROGRAMS_DIR / "table.yaml").read_text()
TABLE_BENCHMARK = {
    "board_size": 9,
    "depth": 2,
    "n_spares": 16,
    "schedule": [[0, 8, 2], [150, 2, 8], [300, 5, 5]],
    "stable_window": 50,
    "motion_model": "minimal",
    "max_cycles": 600,
}

RICH = """\
task: chain-v1
channels: [scent]
start: [SLEEP, SEED]
parameters:
  patience: 3
  weak: 40
modes:
  SLEEP:
    - if: [detects scent, not touching object]
      do: [relay scent, move up]
      go: SEARCH
    - if: [not touching ground, scent scent above weak, load below 0.5]
      do: [block scent, move hint]
      set: FINAL to SEARCH
    - if: [neighbour FINAL at down, waited patience, can move, chance 0.25]
      do: [emit scent, move level]
      go: SEED
  SEARCH:
    - if: [at spot SEED, chance 0.5, not sent 3]
      do: [move around SEED]
      set: FINAL at one to SEARCH
    - if: [neighbour SEED]
      do: [move spot SEED]
    - if: [chance 0.1, not load above 0.5]
      do: [move down]
    - if: [scent scent below 2, neighbour SEARCH at hint]
      do: [stay]
      go: FINAL
    - do: [move gradient scent]
  SEED:
    - if: [waited 1, neighbour SEARCH at growth]
      do: [emit scent]
      set: SEARCH at growth to SEED
      go: FINAL
    - if: [waited 20, chance 0.1]
      do: [pick growth, tell growth]
      go: SLEEP
    - if: [waited 10, chance 0.1]
      do: [drop growth, pick hint growth]
    - do: [emit scent, pick level growth, tell growth, move growth]
  FINAL:
    - if: [not detects scent]
      do: [move any]
    - if: [neighbour SLEEP at up, chance 0.05]
      go: SLEEP
    - do: [relay scent]
"""
"""A program with every condition and action phrase, direction class and set target."""

GRASP = """\
task: grasp
channels: [seed, touch]
start: [SLEEP, SEED]
modes:
  SLEEP:
    - if: [touching object]
      do: [emit touch, block seed]
      go: TOUCH
    - if: [load above 0.5, detects touch]
      do: [relay touch, move gradient touch]
    - if: [not scent seed below 65535]
      do: [move hint]
    - do: [move gradient seed]
  SEED:
    - do: [emit seed]
  TOUCH:
    - do: [emit touch]
"""
"""A program for a task with two channels, a load sensor and an object to touch."""


def chain_env():
    return proteo_env.make("chain-v1", n_modules=12, max_cycles=300, motion_model="sphere")


def test_the_paper_chain_program_builds_chains():
    env = chain_env()
    for seed in range(1000, 1005):
        result = run_episode(env, make_policy("program", env, program="chain", seed=seed), seed=seed)
        assert result.success and result.cycles <= 200, (seed, result.cycles)


def test_the_paper_grasp_program_grasps_on_some_worlds():
    env = proteo_env.make("grasp-v0", n_modules=100, distance=3, max_cycles=300)
    results = [
        run_episode(env, make_policy("program", env, program="grasp", seed=s), seed=s) for s in range(1000, 1020)
    ]
    cycles = [r.cycles for r in results if r.success]
    assert len(cycles) >= 5 and max(cycles) <= 250, cycles


def test_the_paper_branch_program_grows_two_levels_on_most_worlds():
    env = proteo_env.make("branch-v0", n_modules=40, T=4, B=3, max_cycles=200)
    results = [
        run_episode(env, make_policy("program", env, program="branch", seed=s), seed=s) for s in range(1000, 1020)
    ]
    assert sum(r.success for r in results) >= 8
    assert all(r.metrics["levels"] >= 1 for r in results if r.metrics["tree_size"] > 20)


def test_the_paper_table_program_restabilises_on_some_worlds():
    env = proteo_env.make("table-v1", **TABLE_BENCHMARK)
    results = [
        run_episode(env, make_policy("program", env, program="table", seed=s), seed=s) for s in range(1000, 1020)
    ]
    assert sum(r.success for r in results) >= 2
    assert all(r.metrics["leg_creations"] >= 2 for r in results)


SENDS_TWICE = """\
task: chain
channels: [scent]
start: [SLEEP, SEED]
modes:
  SEED:
    - if: [sent 2]
      go: FINAL
    - set: SLEEP to SEARCH
"""
"""A seed that sends a mode set to all neighbours each cycle and goes FINAL after two."""


def test_sent_counts_the_mode_sets_a_module_sent_in_its_mode():
    env = chain_env()
    policy = make_policy("program", env, program=SENDS_TWICE, seed=0)
    observations, _ = env.reset(seed=1000)
    seed_mode = env.task.modes.index("SEED")
    (seed,) = [a for a in env.agents if observations[a]["own_mode"][0] == seed_mode]
    modes = []
    for _ in range(3):
        actions = policy.act(observations)
        modes.append(env.task.modes[actions[seed][1]])
        observations, *_ = env.step(actions)
    assert modes == ["SEED", "SEED", "FINAL"]
    assert dict(zip(ProgramMemory.FIELDS, policy.memory.arrays()))["sent"].max() == 2


@pytest.mark.parametrize("text", [CHAIN, RICH], ids=["chain", "rich"])
def test_format_and_load_round_trip(text):
    program = load_program(text, "chain-v1")
    printed = format_program(program)
    assert load_program(printed, "chain-v1") == program
    assert format_program(load_program(printed, "chain-v1")) == printed


def test_a_program_by_path_by_name_and_by_text_is_the_same():
    path = str(PROGRAMS_DIR / "chain.yaml")
    assert load_program(path, chain_env()) == load_program("chain", "chain") == load_program(CHAIN, "chain-v1")


def _edit(old: str, new: str) -> str:
    assert old in CHAIN
    return CHAIN.replace(old, new, 1)


BAD = {
    "unknown primitive": (_edit("move gradient scent", "move uphill scent"), "modes.SEARCH[2].do[1]", "unknown action"),
    "unknown condition": (_edit("[detects scent]", "[smells scent]"), "modes.SLEEP[0].if[0]", "unknown condition"),
    "unknown mode": (_edit("go: SEARCH", "go: HUNT"), "modes.SLEEP[0].go", "SLEEP, SEARCH, SEED, FINAL"),
    "unreachable mode": (_edit("go: FINAL", "go: SEARCH"), "modes.FINAL", "no rule reaches it"),
    "undeclared channel": (_edit("[detects scent]", "[detects node]"), "modes.SLEEP[0].if[0]", "unknown channel"),
    "channel the task lacks": (_edit("channels: [scent]", "channels: [scent, node]"), "channels", "at most 1"),
    "another task": (_edit("task: chain", "task: grasp"), "task", "a program for another task"),
    "bad probability": (_edit("p_random: 0.05", "p_random: 1.5"), "modes.SEARCH[1].if[0]", "[0, 1]"),
    "unknown parameter": (_edit("chance p_random", "chance p_wander"), "modes.SEARCH[1].if[0]", "p_random"),
    "unknown direction class": (_edit("at growth]", "at north]"), "modes.SEED[0].if[1]", "unknown class"),
    "unknown key": (_edit("      go: SEARCH", "      goto: SEARCH"), "modes.SLEEP[0].goto", "if, do, go, set"),
    "two rolls in a rule": (_edit("move any]", "move any, stay]"), "modes.SEARCH[1]", "one roll"),
    "two messages in a rule": (
        _edit("do: [emit scent]", "do: [emit scent, tell growth]"),
        "modes.SEED[0]",
        "one message",
    ),
    "bad set target": (_edit("SEARCH at growth to", "SEARCH at hint to"), "modes.SEED[0].set", "growth, any"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_each_bad_program_is_one_error_naming_line_field_and_value(case):
    text, field, allowed = BAD[case]
    with pytest.raises(ConfigError) as error:
        load_program(text, "chain-v1")
    message = str(error.value)
    assert f", {field}:" in message and "line " in message and allowed in message, message


def test_a_missing_program_is_one_error():
    with pytest.raises(ConfigError, match="'no_such_program' does not exist.*chain"):
        load_program("no_such_program", "chain")


def test_the_program_policy_without_a_program_is_one_error():
    env = proteo_env.make("chain-v1", n_modules=12)
    with pytest.raises(ConfigError, match="program = None is not allowed; allowed: .*chain, grasp"):
        make_policy("program", env)


def test_same_seed_same_observations_same_actions():
    env = chain_env()
    observations, _ = env.reset(seed=1003)
    first, second = (make_policy("program", env, program="chain", seed=7) for _ in range(2))
    for _ in range(40):
        actions = first.act(observations)
        again = second.act(observations)
        assert all(np.array_equal(actions[a], again[a]) for a in actions)
        observations, *_ = env.step(actions)


def test_every_phrase_runs_and_gives_allowed_actions():
    env = chain_env()
    policy = make_policy("program", env, program=RICH, seed=0)
    observations, _ = env.reset(seed=1000)
    for _ in range(30):
        actions = policy.act(observations)
        env.action_layout.check(np.stack(list(actions.values())), list(actions))
        observations, *_ = env.step(actions)


def test_proteo_run_takes_a_program(capsys):
    from training.cli import main

    settings = ["--set", "n_modules=12", "--set", "max_cycles=300", "--set", "motion_model=sphere"]
    assert main(["run", "chain-v1", *settings, "--program", "chain", "--seed", "1000"]) == 0
    assert "success 1/1" in capsys.readouterr().out


PROGRAMS = {
    "chain": ("chain-v1", CHAIN, {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"}),
    "rich": ("chain-v1", RICH, {"n_modules": 12, "max_cycles": 120}),
    "grasp": ("grasp-v0", GRASP, small_overrides("grasp-v0", max_cycles=120)),
    "grasp paper": ("grasp-v0", GRASP_PAPER, small_overrides("grasp-v0", max_cycles=120)),
    "branch paper": ("branch-v0", BRANCH_PAPER, {"n_modules": 40, "T": 4, "B": 3, "max_cycles": 120}),
    "table paper": ("table-v1", TABLE_PAPER, {**TABLE_BENCHMARK, "max_cycles": 200}),
}
"""Programs run by the compiled interpreter against their plain-Python reading: task, text, settings."""


def test_the_rich_program_uses_every_phrase_class_and_set_target():
    program = load_program(RICH, "chain-v1")
    rules = [rule for _, mode_rules in program.modes for rule in mode_rules]
    phrases = [p for rule in rules for p in (*rule.conditions, *rule.actions)]
    assert {p.pattern for p in phrases} == set(CONDITIONS) | set(ACTIONS)
    assert {a for p in phrases for a in p.arguments if a in DIRECTION_CLASSES} == set(DIRECTION_CLASSES)
    assert {rule.set.at for rule in rules if rule.set} == set(SET_TARGETS)


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_the_kernel_and_the_python_reading_give_the_same_actions(name):
    """Whole episodes, cycle for cycle: the same actions, and at the end the same memory and generator."""
    task_id, text, settings = PROGRAMS[name]
    env = proteo_env.make(task_id, **settings)
    for seed in range(1000, 1003):
        env.reset(seed=seed)
        compiled = make_policy("program", env, program=text, seed=seed)
        reading = ProgramReading.for_env(env, program=text, seed=seed)
        done = False
        while not done:
            buffers = env.observe_arrays()
            actions = compiled.act_arrays(buffers)
            np.testing.assert_array_equal(
                actions, reading.act_arrays(buffers), err_msg=f"seed {seed} cycle {env.cycle}"
            )
            result = env.step_arrays(actions)
            done = bool(result.terminated[0] or result.truncated[0])
        for field, a, b in zip(ProgramMemory.FIELDS, compiled.memory.arrays(), reading.memory.arrays()):
            np.testing.assert_array_equal(a, b, err_msg=field)
        assert compiled.rng.bit_generator.state == reading.rng.bit_generator.state


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_the_compiled_rollout_of_a_program_is_the_env_stepped_with_it(name):
    task_id, text, settings = PROGRAMS[name]
    env = proteo_env.make(task_id, **settings)
    for seed in (1000, 1001):
        env.reset(seed=seed)
        result = compiled_rollout(env, make_policy("program", env, program=text, seed=seed), record_every=1)
        policy = make_policy("program", env, program=text, seed=seed)
        positions, modes, success = drive(env, policy, env.max_cycles)
        assert_same_trajectory(result, positions, modes, success, policy.rng)
        assert success or name != "chain", f"seed {seed}: no chain"


def test_a_batch_of_program_policies_acts_as_each_alone():
    env = proteo_env.make_batched("chain-v1", 3, **small_overrides("chain-v1"))
    together = [make_policy("program", env, program="chain", seed=b) for b in range(3)]
    alone = [make_policy("program", env, program="chain", seed=b) for b in range(3)]
    batch, buffers, a = ProgramPolicy.batch(together), env.reset(seed=4), env.n_agents
    for _ in range(30):
        actions = batch.act_arrays(buffers)
        expected = np.concatenate([p.act_arrays(buffers.rows(b * a, (b + 1) * a)) for b, p in enumerate(alone)])
        np.testing.assert_array_equal(actions, expected)
        env.step_arrays(actions.reshape(3, a, -1))
        buffers = env.observe_arrays()


def test_a_program_for_another_task_is_no_compiled_rollout():
    env = proteo_env.make("grasp-v0", **small_overrides("grasp-v0"))
    env.reset(seed=0)
    policy = make_policy("program", chain_env(), program="chain", seed=0)
    with pytest.raises(ValueError, match="a program for 'grasp'"):
        compiled_rollout(env, policy)
