"""training/trainers/imitate.py and kickstarting in training/trainers/ppo.py: the clone learns the rules' moves,
its checkpoint evaluates and starts PPO, the distillation term anneals, and bad input is refused."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import proteo_env  # noqa: E402
from proteo_env.adapters.flatten import ObservationEncoder  # noqa: E402
from proteo_env.config import ConfigError  # noqa: E402
from training.machinery.checkpoints import CheckpointError, load_policy, read_meta  # noqa: E402
from training.machinery.networks import ReturnScale  # noqa: E402
from training.trainers import imitate, ppo  # noqa: E402
from training.trainers.teachers import Teachers  # noqa: E402

SMALL_ENV = {"n_modules": 8, "max_cycles": 100}


def tiny_clone(run_dir, *extra: str):
    argv = [
        "--task",
        "chain-v0",
        "--env",
        json.dumps(SMALL_ENV),
        "--seed",
        "5",
        "--n-envs",
        "16",
        "--rounds",
        "2",
        "--cycles-per-round",
        "150",
        "--n-epochs",
        "8",
        "--minibatch-size",
        "512",
        "--hidden",
        "[32, 32]",
        "--run-dir",
        str(run_dir),
        "--tensorboard",
        "false",
        "--progress-bar",
        "false",
        *extra,
    ]
    return imitate.main(argv)


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    return tiny_clone(tmp_path_factory.mktemp("imitate") / "run")


def rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_the_teacher_driven_round_is_the_rules_and_the_clone_agrees_with_them_on_held_out_states(clone):
    log = rows(clone.parent / "progress.csv")
    assert [float(r["beta"]) for r in log] == [1.0, 0.5, 0.25]
    assert float(log[0]["episode/success"]) == 1.0  # round 0: the rules drive, and the rules build chains
    # agreement is measured on each new round's states before the clone is trained on them
    assert all(float(r["imitation/agreement_move"]) > 0.55 for r in log[1:])
    meta = read_meta(clone)
    assert meta["algorithm"] == "imitation" and meta["control"] == "move" and meta["teacher"] == "rules"


def test_the_clone_agrees_with_the_rules_far_more_than_an_untrained_network(clone):
    env = proteo_env.make_batched("chain-v0", 4, control="move", **SMALL_ENV)
    teachers = Teachers(env, 4, seed=123)
    trained = load_policy(clone, proteo_env.make("chain-v0", control="move", **SMALL_ENV))
    meta = read_meta(clone)
    fresh = ppo.ActorCritic(trained.encoder, [13], "shared", tuple(meta["hidden"]))
    buffers, hits = env.reset(seed=900), {"clone": [], "fresh": []}
    for _ in range(40):
        labels = teachers.labels([buffers])[:, 0]
        features = trained.encoder.encode_buffers(buffers)
        choice = buffers.action_mask.sum(axis=1) > 1
        with torch.no_grad():
            fresh_logits = fresh.logits(torch.from_numpy(features)).numpy()
        for name, logits in (("clone", trained.logits_fn(features)), ("fresh", fresh_logits)):
            best = np.where(buffers.action_mask.astype(bool), logits, -np.inf).argmax(axis=1)
            hits[name] += list((best == labels)[choice])
        env.step_arrays(labels.reshape(4, -1, 1))
        teachers.restart(env.success() | (env.cycles >= SMALL_ENV["max_cycles"]))
        buffers = env.observe_arrays()
    assert np.mean(hits["clone"]) > np.mean(hits["fresh"]) + 0.25


def test_imitation_is_deterministic_for_a_seed(clone, tmp_path):
    again = tiny_clone(tmp_path / "again")
    first, second = (torch.load(p / "policy.pt", weights_only=True) for p in (clone, again))
    assert all(torch.equal(first[k], second[k]) for k in first)


def test_imitation_over_workers_is_the_same_clone(clone, tmp_path):
    """Three processes step, label (each its share's teachers, seeded as in one) and restart the
    same worlds: the same DAgger rounds and the same network, bit for bit."""
    split = tiny_clone(tmp_path / "split", "--workers", "3")
    first, second = (torch.load(p / "policy.pt", weights_only=True) for p in (clone, split))
    assert all(torch.equal(first[k], second[k]) for k in first)
    logs = [list(csv.DictReader((p.parent / "progress.csv").open())) for p in (clone, split)]
    assert [r["imitation/agreement_move"] for r in logs[0]] == [r["imitation/agreement_move"] for r in logs[1]]
    with pytest.raises(ValueError, match="workers=17 is not allowed with n_envs=16"):
        tiny_clone(tmp_path / "refused", "--workers", "17")


def test_kickstarting_starts_from_the_clone_and_anneals_the_distillation_term(clone, tmp_path):
    hidden = json.dumps(read_meta(clone)["hidden"])
    common = [
        "--task",
        "chain-v0",
        "--control",
        "move",
        "--env",
        json.dumps(SMALL_ENV),
        "--n-envs",
        "8",
        "--n-steps",
        "16",
        "--minibatch-size",
        "256",
        "--arch",
        "shared",
        "--message-encoding",
        "compact",
        "--hidden",
        hidden,
        "--tensorboard",
        "false",
        "--progress-bar",
        "false",
        "--init",
        str(clone),
    ]
    start = ppo.main(common + ["--total-steps", "0", "--run-dir", str(tmp_path / "zero")])
    kept, loaded = (torch.load(p / "policy.pt", weights_only=True) for p in (clone, start))
    assert all(torch.equal(kept[k], loaded[k]) for k in kept)
    run = ppo.main(
        common
        + [
            "--total-steps",
            "6000",
            "--distill-coef",
            "1.0",
            "--distill-steps",
            "3000",
            "--run-dir",
            str(tmp_path / "kick"),
        ]
    )
    log = rows(run.parent / "progress.csv")
    weights = [float(r["loss/distill_weight"]) for r in log]
    assert weights[0] == 1.0 and weights == sorted(weights, reverse=True) and weights[-1] == 0.0
    distilled = [float(r["loss/distill"]) for r in log if r["loss/distill"]]
    assert distilled and all(np.isfinite(distilled))


def test_bad_teacher_and_init_are_refused_naming_the_field(clone, tmp_path):
    with pytest.raises(ConfigError, match=r"teacher='grasp' does not fit task 'chain'.*'rules'"):
        tiny_clone(tmp_path / "a", "--teacher", "grasp")
    with pytest.raises(ConfigError, match=r"rounds=-1 is not allowed"):
        tiny_clone(tmp_path / "b", "--rounds", "-1")
    with pytest.raises(ConfigError, match=r"beta=1.5 is not allowed"):
        tiny_clone(tmp_path / "c", "--beta", "1.5")
    base = [
        "--control",
        "move",
        "--n-envs",
        "2",
        "--total-steps",
        "0",
        "--tensorboard",
        "false",
        "--progress-bar",
        "false",
        "--arch",
        "shared",
        "--message-encoding",
        "compact",
        "--init",
        str(clone),
    ]
    with pytest.raises(CheckpointError, match=r"task='chain'; this run has task='branch'"):
        ppo.main(base + ["--task", "branch-v0", "--hidden", "[32, 32]", "--run-dir", str(tmp_path / "d")])
    with pytest.raises(CheckpointError, match=r"hidden=\[32, 32\]; this run has hidden=\[64, 64\]"):
        ppo.main(base + ["--task", "chain-v0", "--env", json.dumps(SMALL_ENV), "--run-dir", str(tmp_path / "e")])


def test_last_move_memory_feeds_each_agent_its_own_previous_move_and_resets_with_the_episode():
    from training.machinery.policies import LogitsPolicy

    env = proteo_env.make("chain-v0", control="move", **SMALL_ENV)
    seen = []

    def logits_fn(features):
        seen.append(features.copy())
        return np.zeros((len(features), 13))

    encoder = ObservationEncoder.for_env(env)
    policy = LogitsPolicy(
        env.action_layout, env.task.modes, seed=1, encoder=encoder, logits_fn=logits_fn, nvec=[13], memory="last_move"
    )
    observations, _ = env.reset(seed=3)
    policy.reset(3)
    first = policy.act(observations)
    assert seen[0].shape == (len(observations), encoder.size + 13)
    assert np.all(seen[0][:, encoder.size :] == np.eye(13)[[0] * len(observations)])  # nothing remembered yet
    observations, *_ = env.step(first)
    policy.act(observations)
    remembered = seen[1][:, encoder.size :].argmax(axis=1)
    assert list(remembered) == [int(first[a][0]) for a in observations]  # by agent name, in row order
    policy.reset(4)
    policy.act(observations)
    assert np.all(seen[2][:, encoder.size :].argmax(axis=1) == 0)


def test_last_action_memory_feeds_every_field_of_each_agents_previous_action_at_full():
    from training.machinery.policies import LogitsPolicy

    env = proteo_env.make("chain-v0", control="full", **SMALL_ENV)
    nvec = env.action_layout.nvec
    seen = []

    def logits_fn(features):
        seen.append(features.copy())
        return np.zeros((len(features), int(np.sum(nvec))))

    encoder = ObservationEncoder.for_env(env)
    policy = LogitsPolicy(
        env.action_layout, env.task.modes, seed=1, encoder=encoder, logits_fn=logits_fn, memory="last_action"
    )
    observations, _ = env.reset(seed=3)
    policy.reset(3)
    first = policy.act(observations)
    assert seen[0].shape == (len(observations), encoder.size + int(np.sum(nvec)))
    observations, *_ = env.step(first)
    policy.act(observations)
    starts = np.concatenate([[0], np.cumsum(nvec)[:-1]])
    for row, agent in enumerate(observations):
        block = seen[1][row, encoder.size :]
        assert np.flatnonzero(block).tolist() == (starts + np.asarray(first[agent])).tolist()


def test_a_clone_with_memory_loads_and_a_run_of_another_memory_refuses_it(tmp_path):
    clone = tiny_clone(tmp_path / "memory", "--memory", "last_move", "--rounds", "0")
    meta = read_meta(clone)
    assert meta["memory"] == "last_move"
    policy = load_policy(clone, proteo_env.make("chain-v0", control="move", **SMALL_ENV))
    assert policy.memory == "last_move"
    with pytest.raises(CheckpointError, match=r"memory='last_move'; this run has memory='none'"):
        ppo.main(
            [
                "--task",
                "chain-v0",
                "--env",
                json.dumps(SMALL_ENV),
                "--n-envs",
                "2",
                "--total-steps",
                "0",
                "--arch",
                "shared",
                "--message-encoding",
                "compact",
                "--hidden",
                "[32, 32]",
                "--init",
                str(clone),
                "--tensorboard",
                "false",
                "--progress-bar",
                "false",
                "--run-dir",
                str(tmp_path / "run"),
            ]
        )
    full = tiny_clone(
        tmp_path / "full", "--control", "full", "--memory", "last_action", "--rounds", "1", "--cycles-per-round", "20"
    )
    policy = load_policy(full, proteo_env.make("chain-v0", control="full", **SMALL_ENV))
    assert policy.memory == "last_action" and len(policy.nvec) == 5
    assert policy.sampled == "move"  # the clone's checkpoint says how it acts: moves sampled, the rest arg-max
    with pytest.raises(ValueError, match=r"memory='recurrent' is not allowed; allowed: 'none', 'last_move'"):
        tiny_clone(tmp_path / "bad", "--memory", "recurrent")


def test_return_scale_tracks_the_mean_and_variance_of_every_return_seen_and_is_the_identity_when_off():
    gen = torch.Generator().manual_seed(0)
    batches = [400 + 30 * torch.randn(500, generator=gen), 380 + 60 * torch.randn(700, generator=gen)]
    scale = ReturnScale(True)
    for batch in batches:
        scale.update(batch)
    seen = torch.cat(batches).double()
    assert scale.mean == pytest.approx(seen.mean().item()) and scale.std == pytest.approx(
        seen.std(unbiased=False).item()
    )
    targets = scale.target(seen)
    assert abs(targets.mean().item()) < 1e-9 and targets.std(unbiased=False).item() == pytest.approx(1.0)
    assert torch.allclose(scale.value(targets), seen)
    off = ReturnScale(False)
    off.update(seen)
    assert off.value(seen) is seen and off.target(seen) is seen


def test_value_norm_is_saved_with_the_trainer_state_and_resumed(tmp_path):
    common = [
        "--task",
        "chain-v0",
        "--env",
        json.dumps(SMALL_ENV),
        "--n-envs",
        "4",
        "--n-steps",
        "8",
        "--minibatch-size",
        "128",
        "--hidden",
        "[16, 16]",
        "--value-norm",
        "true",
        "--tensorboard",
        "false",
        "--progress-bar",
        "false",
    ]
    first = ppo.main(common + ["--total-steps", "512", "--run-dir", str(tmp_path / "run")])
    saved = torch.load(first / "trainer.pt", weights_only=False)["return_scale"]
    assert saved["count"] == 512 and saved["var"] > 0  # every return of both rollouts entered the statistics
    resumed = ppo.main(["--resume", str(first), "--total-steps", "768"])
    assert torch.load(resumed / "trainer.pt", weights_only=False)["return_scale"]["count"] == 768


def test_sampled_move_samples_the_move_as_before_and_takes_the_arg_max_of_every_other_field():
    from training.machinery.policies import LogitsPolicy, sample_actions

    nvec = np.array([13, 4, 3])
    logits = np.random.default_rng(0).normal(size=(500, int(nvec.sum())))
    mask = np.ones((500, 13), dtype=bool)
    everything = sample_actions(logits, nvec, mask, np.random.default_rng(7))
    moves_only = sample_actions(logits, nvec, mask, np.random.default_rng(7), sampled="move")
    assert np.array_equal(everything[:, 0], moves_only[:, 0])  # the same draws for the moves
    assert np.array_equal(moves_only[:, 1], logits[:, 13:17].argmax(axis=1))
    assert np.array_equal(moves_only[:, 2], logits[:, 17:20].argmax(axis=1))
    assert not np.array_equal(everything[:, 1], moves_only[:, 1])
    env = proteo_env.make("chain-v0", control="full", **SMALL_ENV)
    with pytest.raises(ConfigError, match=r"sampled='modes' is not allowed; allowed: 'all', 'move'"):
        LogitsPolicy(
            env.action_layout,
            env.task.modes,
            encoder=ObservationEncoder.for_env(env),
            logits_fn=lambda x: x,
            sampled="modes",
        )


def test_a_checkpoint_teaches_its_own_actions_and_one_of_another_task_is_refused(clone, tmp_path):
    from proteo_env.env import ProteoEnv

    batch = proteo_env.make_batched("chain-v0", 3, control="move", **SMALL_ENV)
    teachers = Teachers(batch, 3, str(clone), seed=11)
    buffers = batch.reset(seed=40)
    labels = teachers.labels([buffers])
    task = batch.tasks[0]
    same = load_policy(clone, ProteoEnv(type(task)(task.params), batch.config), seed=11)
    features = same.encoder.encode_buffers(buffers)
    assert np.array_equal(labels, same.act_arrays(features, buffers.action_mask.astype(bool)))
    assert all(buffers.action_mask[np.arange(len(labels)), labels[:, 0]])  # the teacher's moves are legal
    student = tiny_clone(tmp_path / "student", "--teacher", str(clone), "--rounds", "1")
    log = rows(student.parent / "progress.csv")
    assert float(log[1]["imitation/agreement_move"]) > 0.5 and read_meta(student)["teacher"] == str(clone)
    with pytest.raises(CheckpointError, match=r"was trained on task 'chain-v0'; it cannot control 'branch-v0'"):
        Teachers(proteo_env.make_batched("branch-v0", 1, control="move"), 1, str(clone))


def test_the_distillation_weight_falls_to_distill_final_and_stays_there():
    args = ppo.Args(distill_coef=1.0, distill_steps=1000, distill_final=0.1)
    weights = [args.distill_weight(s) for s in (0, 500, 1000, 5000)]
    assert weights[0] == 1.0 and abs(weights[1] - 0.55) < 1e-12 and weights[2] == weights[3] == 0.1
    assert ppo.Args(distill_coef=1.0, distill_steps=1000).distill_weight(2000) == 0.0
    with pytest.raises(ConfigError, match=r"distill_final=0.5 is not allowed with distill_coef=0.2"):
        ppo.Args(distill_coef=0.2, distill_final=0.5)
