"""A behaviour defined outside the package, registered at run time, runs everywhere a built-in
one does: ``make``, the hand-coded rules, the ``move`` level's autopilot, ``proteo eval`` and
the compiled rollout. The example reuses the chain's rules under a new name, so what is tested
is the plumbing (docs/guides/adding_a_behaviour.md)."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest
import yaml

import proteo_env
from baselines import POLICIES, make_policy
from baselines.compiled import compiled_rollout
from proteo_env import control
from proteo_env.config import ConfigError
from proteo_env.rollout import run_episode

MODULE = '''
"""A behaviour of my own: the paper's chain, as a new task with its own rules."""
import proteo_env
from baselines import register_policy
from baselines.chain import ChainPolicy
from proteo_env.tasks.chain import Chain


@proteo_env.register
class Snake(Chain):
    name = "snake"
    version = 0
    default_policy = "snake"


@register_policy
class SnakePolicy(ChainPolicy):
    name = "snake"
'''

SMALL = {"n_modules": 10, "motion_model": "sphere", "max_cycles": 300}


@pytest.fixture
def snake(tmp_path, monkeypatch):
    (tmp_path / "my_snake.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("my_snake")
    yield module
    proteo_env.TASKS.pop("snake-v0", None)
    POLICIES.pop("snake", None)
    control._autopilots.pop("snake", None)
    sys.modules.pop("my_snake", None)


def test_a_behaviour_from_outside_the_package_runs_everywhere(snake, tmp_path):
    env = proteo_env.make("snake", **SMALL)
    assert env.task.task_id() == "snake-v0" and type(env.task) is snake.Snake
    policy = make_policy("snake", env, seed=0)
    result = run_episode(env, policy, seed=0)
    assert result.success and result.metrics["chain_length"] == 10

    env.reset(seed=0)  # the compiled rollout runs the same episode
    rollout = compiled_rollout(env, make_policy("snake", env, seed=0))
    assert rollout.success and rollout.cycles == result.cycles

    moving = proteo_env.make("snake", control="move", **SMALL)  # the autopilot: the rules, found by name
    buffers = moving.batch.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        moves = (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1)
        moving.step_arrays(moves[:, None])
        buffers = moving.observe_arrays()
    assert (moving.world.modes != 0).any()  # the rules woke the blob (SLEEP is mode 0)

    from training.evaluate import evaluate

    config = tmp_path / "eval.yaml"
    config.write_text(yaml.safe_dump({"seeds": 2, "first_seed": 0, "tasks": {"snake": {"env": SMALL}}}))
    rows = evaluate(config=config, tasks=["snake"], out=tmp_path / "eval", progress=False, plots=False)
    rules = [r.summary() for r in rows if r.kind == "hand-coded"]
    assert rules and rules[0]["policy"] == "snake" and rules[0]["successes"] == 2


def test_registering_a_taken_name_or_a_non_task_is_refused(snake):
    from baselines import register_policy

    class Other(snake.Snake):
        pass

    with pytest.raises(ConfigError, match=r"task id 'snake-v0' is taken by Snake"):
        proteo_env.register(Other)
    with pytest.raises(ConfigError, match=r"allowed: a subclass of proteo_env.tasks.base.Task"):
        proteo_env.register(dict)
    with pytest.raises(ValueError, match=r"policy name 'snake' is taken by SnakePolicy"):
        register_policy(type("Twin", (snake.SnakePolicy,), {}))
