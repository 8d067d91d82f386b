"""A behaviour defined outside the package, registered at run time, runs everywhere a built-in
one does: ``make``, the hand-coded rules, the ``move`` level's autopilot, ``proteo eval`` and
the compiled rollout. The example reuses the chain's rules under a new name, so what is tested
is the plumbing (docs/guides/adding_a_behaviour.md)."""

from __future__ import annotations

import importlib
import sys
import textwrap

import numpy as np
import pytest
import yaml

import proteo_env
from baselines import POLICIES, make_policy
from baselines.compiled import compiled_rollout
from proteo_env import control
from proteo_env.config import ConfigError
from proteo_env.core.lattice import DIRECTIONS
from proteo_env.rollout import run_episode

MODULE = '''
"""A behaviour of my own: the paper's chain, as a new task with its own rules."""
import proteo_env
from baselines import register_policy
from baselines.chain import ChainPolicy
from proteo_env.tasks.chain import Chain


@proteo_env.register
class Worm(Chain):
    name = "worm"
    version = 0
    default_policy = "worm"


@register_policy
class WormPolicy(ChainPolicy):
    name = "worm"
'''

SMALL = {"n_modules": 10, "motion_model": "sphere", "max_cycles": 300}


@pytest.fixture
def worm(tmp_path, monkeypatch):
    (tmp_path / "my_worm.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("my_worm")
    yield module
    proteo_env.TASKS.pop("worm-v0", None)
    POLICIES.pop("worm", None)
    control._autopilots.pop("worm", None)
    sys.modules.pop("my_worm", None)


def test_a_behaviour_from_outside_the_package_runs_everywhere(worm, tmp_path):
    env = proteo_env.make("worm", **SMALL)
    assert env.task.task_id() == "worm-v0" and type(env.task) is worm.Worm
    policy = make_policy("worm", env, seed=0)
    result = run_episode(env, policy, seed=0)
    assert result.success and result.metrics["chain_length"] == 10

    env.reset(seed=0)  # the compiled rollout runs the same episode
    rollout = compiled_rollout(env, make_policy("worm", env, seed=0))
    assert rollout.success and rollout.cycles == result.cycles

    moving = proteo_env.make("worm", control="move", **SMALL)  # the autopilot: the rules, found by name
    buffers = moving.batch.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        moves = (rng.random(buffers.action_mask.shape) * buffers.action_mask).argmax(axis=1)
        moving.step_arrays(moves[:, None])
        buffers = moving.observe_arrays()
    assert (moving.world.modes != 0).any()  # the rules woke the blob (SLEEP is mode 0)

    from training.judging.evaluate import run_evaluation

    config = tmp_path / "eval.yaml"
    config.write_text(yaml.safe_dump({"seeds": 2, "first_seed": 0, "tasks": {"worm": {"env": SMALL}}}))
    rows = run_evaluation(config=config, tasks=["worm"], out=tmp_path / "eval", progress=False, plots=False)
    rules = [r.summary() for r in rows if r.kind == "hand-coded"]
    assert rules and rules[0]["policy"] == "worm" and rules[0]["successes"] == 2


def test_registering_a_taken_name_or_a_non_task_is_refused(worm):
    from baselines import register_policy

    class Other(worm.Worm):
        pass

    with pytest.raises(ConfigError, match=r"task id 'worm-v0' is taken by Worm"):
        proteo_env.register(Other)
    with pytest.raises(ConfigError, match=r"allowed: a subclass of proteo_env.tasks.base.Task"):
        proteo_env.register(dict)
    with pytest.raises(ValueError, match=r"policy name 'worm' is taken by WormPolicy"):
        register_policy(type("Twin", (worm.WormPolicy,), {}))


def test_the_task_base_class_example_is_a_working_task():
    """The example in ``Task``'s docstring, run as written: a ball flattens under random moves."""
    from proteo_env.tasks.base import Task

    source = Task.__doc__.split("touches the ground; ``tests/test_plugin.py`` runs it)::")[1]
    source = source.split("\n\n    ``docs/guides")[0]
    namespace = {}
    exec(compile(textwrap.dedent(source), "Task example", "exec"), namespace)
    flatten = namespace["Flatten"]
    proteo_env.register(flatten)
    try:
        with pytest.raises(TypeError, match="build_layout"):
            type("NoLayout", (Task,), {"name": "none"})()  # the one required hook
        env = proteo_env.make("flatten", max_cycles=3000)
        env.reset(seed=0)
        start = env.world.positions
        assert (start[:, 2] > 0).any(), "the ball starts above the ground"
        rng = np.random.default_rng(0)
        down = np.concatenate([[0.0], -DIRECTIONS[:, 2]])  # per move: +1 rolls down, -1 up, 0 stay/level
        buffers = env.observe_arrays()
        terminated = False
        while not terminated and env.cycle < env.max_cycles:  # roll down when possible, else wander level
            actions = np.zeros((len(env.possible_agents), env.action_layout.length), dtype=np.int64)
            score = (rng.random(buffers.action_mask.shape) + 2 * down) * buffers.action_mask
            score[:, 1:][:, DIRECTIONS[:, 2] > 0] = 0
            actions[:, env.action_layout.move] = score.argmax(axis=1)
            result = env.step_arrays(actions)
            terminated = bool(result.terminated[0])
            buffers = env.observe_arrays()
        assert terminated and (env.world.positions[:, 2] == 0).all()
    finally:
        proteo_env.TASKS.pop("flatten-v0", None)
