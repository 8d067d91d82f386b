"""The batched evaluator (``training.machinery.evaluator``) gives what ``run_episode`` gives, episode by
episode, for every task and every compiled controller kind; its results do not depend on the
batch size or the number of worker processes; bad input is refused before any episode runs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import small_overrides, task_params

import proteo_env
from baselines import make_policy
from baselines.program import PROGRAMS_DIR
from proteo_env.config import ConfigError
from proteo_env.rollout import run_episode
from training.machinery.evaluator import Controller, Episode, evaluate, run_episodes, settings_json

SEEDS = [3, 11, 4, 27, 8]


def _alone(task_id, overrides, level, controller, seed):
    """The episode as ``run_episode`` runs it, through the per-agent dict API."""
    env = proteo_env.make(task_id, **overrides, **({} if level == "full" else {"control": level}))
    policy = make_policy(controller.policy, env, seed=seed, **dict(controller.params))
    return run_episode(env, policy, seed=seed)


def _same(alone, batched) -> bool:
    return (alone.cycles, alone.success, alone.total_reward, alone.metrics) == (
        batched.cycles,
        batched.success,
        batched.total_reward,
        batched.metrics,
    )


def _controllers(task_id) -> list[Controller]:
    """The task's rules, the same rules with other parameters where they have some, random, and
    the task's program where it has one."""
    name = proteo_env.TASKS[task_id].name
    out = [Controller.rules("random")]
    if name in ("sandbox",):
        return out
    out.append(Controller.rules(name))
    if name == "chain":
        out.append(Controller.rules(name, p_random=0.3))
    if (PROGRAMS_DIR / f"{name}.yaml").is_file():
        out.append(Controller.program(name))
    return out


@pytest.mark.parametrize("task_id", task_params())
def test_every_episode_is_the_one_run_episode_gives(task_id):
    overrides = small_overrides(task_id, max_cycles=60)
    controllers = _controllers(task_id)
    # batch_size 2 < episodes per controller: rows end at different cycles and start new episodes
    results = evaluate(task_id, controllers, SEEDS, env=overrides, workers=1, batch_size=2)
    for controller, row in zip(controllers, results, strict=True):
        for seed, batched in zip(SEEDS, row, strict=True):
            alone = _alone(task_id, overrides, "full", controller, seed)
            assert _same(alone, batched), (controller.policy, seed, alone, batched)


@pytest.mark.parametrize("level", ["move", "move+mode"])
def test_every_episode_is_the_one_run_episode_gives_below_full(level):
    overrides = small_overrides("chain-v1", max_cycles=80)
    controllers = [Controller.rules("chain"), Controller.rules("random")]
    results = evaluate("chain-v1", controllers, SEEDS, env=overrides, level=level, workers=1, batch_size=3)
    for controller, row in zip(controllers, results):
        for seed, batched in zip(SEEDS, row):
            assert _same(_alone("chain-v1", overrides, level, controller, seed), batched)


@pytest.mark.parametrize("one_call_after", [0, 10**9])  # from the start in one kernel call, or world by world
def test_programs_of_a_population_share_one_batch_with_their_own_tables(one_call_after, monkeypatch):
    """Different programs in the rows of one batch: each row acts with its own program."""
    from proteo_env import batched as batched_env

    monkeypatch.setattr(batched_env, "ONE_CALL_AFTER", one_call_after)
    from training.trainers.program_variation import ProgramSpace, random_program

    overrides = small_overrides("chain-v1", max_cycles=150)
    env = proteo_env.make("chain-v1", **overrides)
    rng = np.random.default_rng(5)
    space = ProgramSpace.for_env(env)
    from baselines.program import format_program

    texts = [format_program(random_program(space, rng, "chain")) for _ in range(4)] + ["chain"]
    controllers = [Controller.program(t) for t in texts]
    results = evaluate("chain-v1", controllers, SEEDS[:3], env=overrides, workers=1, batch_size=4)
    for controller, row in zip(controllers, results):
        for seed, batched in zip(SEEDS[:3], row):
            assert _same(_alone("chain-v1", overrides, "full", controller, seed), batched)
    assert len({r.total_reward for row in results for r in row}) > 3, "the programs behave differently"
    assert len({r.cycles for row in results for r in row}) > 1, "rows restart while others run on"


def test_results_do_not_depend_on_batch_size_workers_or_order():
    overrides = small_overrides("grasp-v0", max_cycles=50)
    controllers = [Controller.rules("grasp"), Controller.program("grasp")]
    reference = evaluate("grasp-v0", controllers, SEEDS, env=overrides, workers=1, batch_size=64)
    assert evaluate("grasp-v0", controllers, SEEDS, env=overrides, workers=1, batch_size=1) == reference
    assert evaluate("grasp-v0", controllers, SEEDS, env=overrides, workers=2, batch_size=2) == reference
    reversed_seeds = evaluate("grasp-v0", controllers[::-1], SEEDS[::-1], env=overrides, workers=1, batch_size=3)
    assert [row[::-1] for row in reversed_seeds[::-1]] == reference


def test_few_long_episodes_are_split_over_every_worker_and_many_fill_their_batches(monkeypatch):
    """Fifty episodes that one batch could hold go to two batches on two workers (a scale split's
    episodes are long: one batch would leave a worker idle); a thousand fill batches of 64; and the
    results do not depend on the split."""
    from training.machinery import evaluator

    assert evaluator.chunk_count(50, 64, 2) == 2 and evaluator.chunk_count(50, 64, 1) == 1
    assert evaluator.chunk_count(1000, 64, 2) == 16 and evaluator.chunk_count(1, 64, 4) == 1
    overrides = small_overrides("chain-v1", max_cycles=30)
    reference = evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1)
    sizes = []
    run_chunk = evaluator._run_chunk
    monkeypatch.setattr(evaluator, "_run_chunk", lambda chunk: sizes.append(len(chunk[0])) or run_chunk(chunk))
    monkeypatch.setattr(evaluator, "chunk_count", lambda n, per_chunk, workers: 3)  # as three workers would
    assert evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1) == reference
    assert len(sizes) == 3 and sum(sizes) == len(SEEDS)


def test_a_batch_holds_as_many_worlds_as_each_worker_s_memory_share_and_a_world_too_large_is_refused(monkeypatch):
    """Batches shrink to what each worker's share of the memory holds (the results do not change);
    a world larger than that share is one error naming its task, settings and size, before any
    episode runs."""
    from proteo_env.core.world import world_bytes
    from training.machinery import evaluator

    overrides = small_overrides("chain-v1", max_cycles=30)
    episode = Episode("chain-v1", settings_json(overrides), "full", Controller.rules("chain"), 3)
    env = proteo_env.make("chain-v1", **overrides)
    env.reset(seed=3)
    need = world_bytes(env.engine.shape.size, env.engine.shape.extent, env.engine.n_modules, env.max_cycles)
    reference = evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1)
    monkeypatch.setattr(evaluator, "machine_memory", lambda: 2 * (3 * need) + 2)  # three worlds for one worker
    assert evaluator.worlds_per_batch(episode, 64, 1) == 3 and evaluator.worlds_per_batch(episode, 2, 1) == 2
    assert evaluator.worlds_per_batch(episode, 64, 2) == 1
    chunks = []
    run_chunk = evaluator._run_chunk
    monkeypatch.setattr(evaluator, "_run_chunk", lambda chunk: chunks.append(chunk[:2]) or run_chunk(chunk))
    assert evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1) == reference
    assert sorted(len(episodes) for episodes, _ in chunks) == [2, 3] and {size for _, size in chunks} == {3}
    monkeypatch.setattr(evaluator, "machine_memory", lambda: 2 * need - 2)
    with pytest.raises(
        ConfigError,
        match=r"chain-v1 with .*: a world needs up to about .* 12 modules, 30 cycles\); allowed: worlds that fit",
    ):
        run_episodes([episode], workers=1)


def test_episodes_of_several_settings_and_tasks_in_one_call():
    chain, grasp = small_overrides("chain-v1", max_cycles=40), small_overrides("grasp-v0", max_cycles=40)
    episodes = [
        Episode("chain-v1", settings_json(chain), "full", Controller.rules("chain"), 1),
        Episode("grasp-v0", settings_json(grasp), "full", Controller.rules("grasp"), 1),
        Episode("chain-v1", settings_json({**chain, "n_modules": 10}), "full", Controller.rules("chain"), 2),
    ]
    results = run_episodes(episodes, workers=1)
    for e, batched in zip(episodes, results):
        assert _same(_alone(e.task, json.loads(e.overrides), e.level, e.controller, e.seed), batched)


def _network_checkpoint(folder, env, overrides, seed: int, control: str = "full"):
    """A checkpoint of a 16-unit NumPy MLP (CMA-ES's neural controller) with random weights, at
    ``control`` (``env`` made at that level)."""
    from proteo_env.adapters.flatten import ObservationEncoder
    from training.machinery.checkpoints import mlp_meta, write_checkpoint_meta
    from training.machinery.policies import NumpyMLP

    encoder = ObservationEncoder.for_env(env)
    net = NumpyMLP(encoder.size, int(np.sum(env.control_nvec)), (16,))
    folder.mkdir()
    np.save(folder / "genome.npy", net.init_genome(np.random.default_rng(seed)) * 10)  # its choices matter
    write_checkpoint_meta(
        folder,
        algorithm="cma-neural",
        task=env.task.task_id(),
        env_overrides=overrides,
        encoder_spec=encoder.spec(),
        nvec=env.control_nvec,
        agent_steps=0,
        seed=seed,
        extra=mlp_meta(control, [16]),
    )
    return folder


def test_network_checkpoints_share_a_batch_and_agree_with_run_episode(tmp_path):
    """Networks act in one forward pass per network over the worlds each plays, sampled or
    arg-max: the same episodes as one world at a time (a 16-unit NumPy MLP's batched arithmetic
    is exact here)."""
    from training.machinery.checkpoints import load_policy

    overrides = small_overrides("chain-v1", max_cycles=40)
    env = proteo_env.make("chain-v1", **overrides)
    paths = [_network_checkpoint(tmp_path / f"net{s}", env, overrides, s) for s in range(2)]
    controllers = [Controller.from_checkpoint(p) for p in paths] + [
        Controller.from_checkpoint(paths[0], deterministic=True)
    ]
    results = evaluate("chain-v1", controllers, SEEDS, env=overrides, workers=1, batch_size=4)
    for controller, row in zip(controllers, results):
        for seed, batched in zip(SEEDS, row):
            policy = load_policy(controller.policy, env, seed=seed, deterministic=controller.deterministic)
            assert _same(run_episode(env, policy, seed=seed), batched)
    assert results[0] != results[1] and results[0] != results[2]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"seeds": [1, "2"]}, "seed='2' is not allowed; allowed: an integer >= 0"),
        ({"seeds": [-1]}, "seed=-1 is not allowed"),
        ({"seeds": []}, "seeds=\\[\\] is not allowed"),
        ({"controllers": []}, "controllers=\\[\\] is not allowed"),
        ({"workers": 0}, "workers=0 is not allowed; allowed: an integer >= 1"),
        ({"batch_size": 0}, "batch_size=0 is not allowed"),
        ({"controllers": [Controller.rules("branch")]}, "controller='branch' is not allowed on task 'chain-v1'"),
    ],
)
def test_bad_input_is_refused_before_any_episode(change, message, monkeypatch):
    from training.machinery import evaluator

    monkeypatch.setattr(evaluator, "run_batch", lambda *a, **k: pytest.fail("an episode ran"))
    args = {"controllers": [Controller.rules("chain")], "seeds": [0], "workers": 1, "batch_size": 4, **change}
    with pytest.raises(ConfigError, match=message):
        evaluate(
            "chain-v1",
            args["controllers"],
            args["seeds"],
            env=small_overrides("chain-v1"),
            **{k: args[k] for k in ("workers", "batch_size")},
        )


def test_a_program_that_fails_its_checks_is_refused_before_any_episode():
    with pytest.raises(ConfigError):
        evaluate("chain-v1", [Controller.program("modes: {NOPE: []}")], [0], env=small_overrides("chain-v1"), workers=1)


def test_an_episode_listed_twice_runs_once_and_gives_both_places_its_result(monkeypatch):
    from training.machinery import evaluator

    ran = []
    original = evaluator.run_batch
    monkeypatch.setattr(evaluator, "run_batch", lambda episodes, *a: ran.extend(episodes) or original(episodes, *a))
    overrides = small_overrides("chain-v1", max_cycles=40)
    twice = evaluate("chain-v1", [Controller.rules("chain")] * 2, [5, 5, 6], env=overrides, workers=1)
    assert len(ran) == 2
    assert twice[0] == twice[1] and twice[0][0] == twice[0][1] != twice[0][2]


def test_the_default_workers_come_from_proteo_workers_when_set(monkeypatch):
    from training.machinery.evaluator import default_workers

    monkeypatch.setenv("PROTEO_WORKERS", "3")
    assert default_workers() == 3
    monkeypatch.setenv("PROTEO_WORKERS", "0")
    with pytest.raises(ConfigError, match="PROTEO_WORKERS='0' is not allowed; allowed: an integer >= 1"):
        evaluate("chain-v1", [Controller.rules("chain")], [0], env=small_overrides("chain-v1"))


def test_at_move_a_network_sees_only_the_modules_with_a_choice_and_the_episodes_stay_the_same(tmp_path, monkeypatch):
    """At control level ``move`` a module with one legal move takes it whatever the network says,
    so the batched forward pass skips those rows: the episodes are still the ones ``run_episode``
    plays (which feeds every module to the network), and the network saw fewer rows."""
    from training.machinery import evaluator
    from training.machinery.checkpoints import load_policy

    overrides = small_overrides("chain-v1", max_cycles=40)
    env = proteo_env.make("chain-v1", control="move", **overrides)
    folder = _network_checkpoint(tmp_path / "net", env, overrides, 5, control="move")
    seen = {"rows": 0, "modules": 0}
    sample = evaluator._Actors._sample

    def counting(actors, buffers, playing):
        seen["modules"] += len(buffers.action_mask)
        fn = actors.policies[0].logits_fn
        actors.policies[0].logits_fn = lambda x: (seen.__setitem__("rows", seen["rows"] + len(x)), fn(x))[1]
        try:
            return sample(actors, buffers, playing)
        finally:
            actors.policies[0].logits_fn = fn

    monkeypatch.setattr(evaluator._Actors, "_sample", counting)
    (row,) = evaluate("chain-v1", [Controller.from_checkpoint(folder)], SEEDS, env=overrides, level="move", workers=1)
    for seed, batched in zip(SEEDS, row):
        assert _same(run_episode(env, load_policy(folder, env, seed=seed), seed=seed), batched)
    assert 0 < seen["rows"] < seen["modules"]


def test_a_network_does_not_act_for_a_world_whose_episode_has_ended(tmp_path, monkeypatch):
    """A batch steps until its slowest episode ends; the worlds that finished before it wait, and
    the network's forward pass leaves their rows out: it sees each world's modules for exactly the
    cycles of its episode, and the episodes are the ones ``run_episode`` plays."""
    from training.machinery import evaluator
    from training.machinery.checkpoints import load_policy

    overrides = small_overrides("chain-v1", max_cycles=60, n_modules=5)  # episodes of 1 to 49 cycles
    env = proteo_env.make("chain-v1", **overrides)
    folder = _network_checkpoint(tmp_path / "net", env, overrides, 0)
    seen = []
    sample = evaluator._Actors._sample

    def counting(actors, buffers, playing):
        fns = [p.logits_fn for p in actors.policies]
        for p, fn in zip(actors.policies, fns):
            p.logits_fn = lambda x, fn=fn: (seen.append(len(x)), fn(x))[1]
        try:
            return sample(actors, buffers, playing)
        finally:
            for p, fn in zip(actors.policies, fns):
                p.logits_fn = fn

    monkeypatch.setattr(evaluator._Actors, "_sample", counting)
    (row,) = evaluate("chain-v1", [Controller.from_checkpoint(folder)], SEEDS, env=overrides, workers=1)
    for seed, batched in zip(SEEDS, row):
        assert _same(run_episode(env, load_policy(folder, env, seed=seed), seed=seed), batched)
    cycles = [r.cycles for r in row]
    assert len(set(cycles)) > 2
    assert sum(seen) == 5 * sum(cycles)


def test_a_long_episode_is_a_batch_of_its_own(monkeypatch):
    """An episode of at least ``LONG_EPISODE_MODULE_CYCLES`` modules times cycles (a scale split's)
    runs in a batch of its own, landing when it ends; the results do not change."""
    from training.machinery import evaluator

    overrides = small_overrides("chain-v1", max_cycles=30)
    episode = Episode("chain-v1", settings_json(overrides), "full", Controller.rules("chain"), 3)
    reference = evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1)
    assert evaluator.worlds_per_batch(episode, 64, 1) == 64
    monkeypatch.setattr(evaluator, "LONG_EPISODE_MODULE_CYCLES", 12 * 30)
    assert evaluator.worlds_per_batch(episode, 64, 1) == 1
    sizes = []
    run_chunk = evaluator._run_chunk
    monkeypatch.setattr(
        evaluator, "_run_chunk", lambda chunk: sizes.append((len(chunk[0]), chunk[1])) or run_chunk(chunk)
    )
    assert evaluate("chain-v1", [Controller.rules("chain")], SEEDS, env=overrides, workers=1) == reference
    assert sizes == [(1, 1)] * len(SEEDS)


def test_a_local_pool_s_workers_end_with_the_process_that_started_them():
    """A judge killed mid-run leaves no worker playing its batch on (it would run for an hour at scale)."""
    import subprocess
    import sys
    import time
    from pathlib import Path

    script = (
        "import os, time\n"
        "from training.machinery.distributed import local_pool\n"
        "pool = local_pool(2)\n"
        "print(pool.submit(os.getpid).result(), flush=True)\n"
        "pool.submit(time.sleep, 120)\n"
        "time.sleep(120)\n"
    )
    root = Path(__file__).resolve().parents[1]
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=root)
    worker = int(parent.stdout.readline())
    parent.kill()
    parent.wait()

    def running(pid: int) -> bool:
        try:
            return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
        except (FileNotFoundError, IndexError):
            return False

    deadline = time.monotonic() + 30
    while running(worker) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not running(worker)
