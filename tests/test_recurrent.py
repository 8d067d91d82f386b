"""The recurrent option of training/ppo.py (``recurrent: R``): a GRU state per module that
restarts with its world's episode, in the network, the trainer's rollout and update, the
loaded policy and the teacher; starting from a feed-forward clone; refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import proteo_env  # noqa: E402
from proteo_env.adapters.flatten import ObservationEncoder  # noqa: E402
from proteo_env.config import ConfigError  # noqa: E402
from training import ppo  # noqa: E402
from training.checkpoints import CheckpointError, load_policy, read_meta  # noqa: E402
from training.networks import ActorCritic  # noqa: E402
from training.teachers import Teachers  # noqa: E402

SMALL_ENV = {"n_modules": 6, "max_cycles": 30}


def tiny_run(run_dir, *extra: str, steps: int = 2000):
    argv = [
        "--task",
        "chain-v0",
        "--control",
        "move",
        "--env",
        json.dumps(SMALL_ENV),
        "--seed",
        "2",
        "--n-envs",
        "4",
        "--n-steps",
        "16",
        "--minibatch-size",
        "128",
        "--arch",
        "shared",
        "--message-encoding",
        "compact",
        "--hidden",
        "[16, 16]",
        "--total-steps",
        str(steps),
        "--checkpoint-every",
        "100000",
        "--run-dir",
        str(run_dir),
        "--tensorboard",
        "false",
        "--progress-bar",
        "false",
        *extra,
    ]
    return ppo.main(argv)


@pytest.fixture(scope="module")
def recurrent_run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("gru") / "run", "--recurrent", "8")


def small_net(recurrent: int = 8) -> ActorCritic:
    env = proteo_env.make("chain-v0", control="move", **SMALL_ENV)
    torch.manual_seed(0)
    net = ActorCritic(
        ObservationEncoder.for_env(env, message_encoding="compact"), [13], "shared", (16, 16), recurrent=recurrent
    )
    for head in (net.actor_memory, net.critic_memory):  # as after training: the state matters
        torch.nn.init.normal_(head.weight)
    return net


def test_unroll_restarts_a_modules_state_at_zero_after_its_episode_ends():
    net = small_net()
    x = torch.randn(6, 3, net.trunk[0].in_features)
    done = torch.zeros(6, 3, dtype=torch.bool)
    done[2, 1] = True  # module 1's episode ends after cycle 2
    start = torch.randn(3, 8)
    logits, values = net.unroll(x, start, done)
    state = start
    for t in range(6):  # the same cycle by cycle
        step_logits, step_values, state = net(x[t], state)
        assert torch.allclose(logits[t], step_logits) and torch.allclose(values[t], step_values)
        state = torch.where(done[t][:, None], torch.zeros_like(state), state)
    fresh, _ = net.unroll(x[3:, 1:2], net.initial_state(1), done[3:, 1:2])
    assert torch.allclose(logits[3:, 1], fresh[:, 0], atol=1e-6)  # after the end: as from zero state
    assert not torch.allclose(logits[3:, 0], net.unroll(x[3:, :1], net.initial_state(1), done[3:, :1])[0][:, 0])


def test_the_state_carries_information_between_cycles():
    net = small_net()
    x = torch.randn(2, 1, net.trunk[0].in_features)
    other_first = torch.cat([torch.randn(1, 1, x.shape[2]), x[1:]])
    none = torch.zeros(2, 1, dtype=torch.bool)
    assert not torch.allclose(
        net.unroll(x, net.initial_state(1), none)[0][1], net.unroll(other_first, net.initial_state(1), none)[0][1]
    )


def test_a_recurrent_run_saves_a_checkpoint_that_loads_as_a_policy_whose_state_restarts_with_its_episode(recurrent_run):
    meta = read_meta(recurrent_run)
    assert meta["recurrent"] == 8 and meta["agent_steps"] >= 2000
    env = proteo_env.make("chain-v0", control="move", **SMALL_ENV)
    policy = load_policy(recurrent_run, env, seed=0)
    assert policy.state_size == 8
    observations, _ = env.reset(seed=0)
    first = policy.act(observations)
    assert set(policy.states) == set(observations) and all(s.shape == (8,) for s in policy.states.values())
    after_one = {k: s.copy() for k, s in policy.states.items()}
    observations, *_ = env.step(first)
    policy.act(observations)
    assert any(not np.allclose(after_one[k], policy.states[k]) for k in after_one)
    policy.reset(seed=0)
    assert policy.states == {}
    observations, _ = env.reset(seed=0)
    assert policy.act(observations) == first  # the same episode start: the same state, the same draws


def test_same_seed_same_recurrent_run(recurrent_run, tmp_path):
    again = tiny_run(tmp_path / "again", "--recurrent", "8")
    kept, other = (torch.load(p / "policy.pt", weights_only=True) for p in (recurrent_run, again))
    assert set(kept) == set(other) and all(torch.equal(kept[k], other[k]) for k in kept)
    assert any(k.startswith("gru.") for k in kept)


def test_a_feed_forward_checkpoint_starts_a_recurrent_run_that_first_acts_as_it(tmp_path):
    feed_forward = tiny_run(tmp_path / "ff", steps=1000)
    start = tiny_run(tmp_path / "start", "--recurrent", "8", "--init", str(feed_forward), steps=0)
    env = proteo_env.make("chain-v0", control="move", **SMALL_ENV)
    policies = [load_policy(p, env, seed=1) for p in (feed_forward, start)]
    assert policies[1].state_size == 8 and policies[0].state_size == 0
    observations, _ = env.reset(seed=4)
    for _ in range(5):
        actions = [p.act(observations) for p in policies]
        assert actions[0] == actions[1]
        observations, *_ = env.step(actions[0])


def test_a_recurrent_checkpoint_teaches_with_its_state_restarting_per_world(recurrent_run):
    batch = proteo_env.make_batched("chain-v0", 2, control="move", **SMALL_ENV)
    teachers = Teachers(batch, 2, str(recurrent_run), seed=0)
    buffers = batch.reset(seed=0)
    labels = teachers.labels([buffers])
    assert labels.shape == (12, 1) and len(teachers.checkpoint.states) == 12
    teachers.restart([1])
    assert sorted(teachers.checkpoint.states) == list(range(6))  # world 1's modules start afresh


def test_bad_recurrent_settings_and_mismatched_checkpoints_are_refused_with_nothing_written(recurrent_run, tmp_path):
    with pytest.raises(ConfigError, match=r"recurrent=8 is not allowed with arch='mlp'.*arch='shared'"):
        tiny_run(tmp_path / "a", "--recurrent", "8", "--arch", "mlp")
    with pytest.raises(ConfigError, match=r"recurrent=-1 is not allowed"):
        tiny_run(tmp_path / "b", "--recurrent", "-1")
    with pytest.raises(CheckpointError, match=r"recurrent=8\); this run has recurrent=0"):
        tiny_run(tmp_path / "c", "--init", str(recurrent_run), steps=0)
    with pytest.raises(CheckpointError, match=r"recurrent=8\); this run has recurrent=4"):
        tiny_run(tmp_path / "d", "--init", str(recurrent_run), "--recurrent", "4", steps=0)
    assert not any((tmp_path / name).exists() for name in "abcd")
