"""Programs of the paper's primitives (baselines/program.py, baselines/program_policy.py).

The chain program's limit comes from a measurement on the benchmark's setting (12 modules,
``sphere``, worlds 1000..1019, docs/guides/programs.md): every world formed the chain, in a
mean 94 cycles, the slowest in 118; the limit here, 200 cycles, is well under the task's 300.
"""

from __future__ import annotations

import numpy as np
import pytest

import proteo_env
from baselines import make_policy
from baselines.program import PROGRAMS_DIR, format_program, load_program
from proteo_env.config import ConfigError
from proteo_env.rollout import run_episode

CHAIN = (PROGRAMS_DIR / "chain.yaml").read_text()

RICH = """\
task: chain-v1
channels: [scent]
start: [SLEEP]
parameters:
  patience: 3
  weak: 40
modes:
  SLEEP:
    - if: [not touching ground, scent scent above weak, load below 0.5]
      do: [block scent, move hint]
      set: FINAL to SEARCH
    - if: [neighbour FINAL at down, waited patience, can move, chance 0.25]
      do: [emit scent, move level]
      go: SEED
  SEED:
    - if: [not detects scent]
      do: [pick growth, tell growth]
      go: SLEEP
"""


def chain_env():
    return proteo_env.make("chain-v1", n_modules=12, max_cycles=300, motion_model="sphere")


def test_the_paper_chain_program_builds_chains():
    env = chain_env()
    for seed in range(1000, 1005):
        result = run_episode(env, make_policy("program", env, program="chain", seed=seed), seed=seed)
        assert result.success and result.cycles <= 200, (seed, result.cycles)


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
