"""World streams: every world's generator is a child of numpy's SeedSequence, so training seeds
and the worlds of one run never share a stream, and evaluation seeds stay those of a single env."""

from __future__ import annotations

import numpy as np
import pytest

import proteo_env
from proteo_env.config import ConfigError, world_seeds

pytest.importorskip("torch")
from training.trainers.worlds import TrainingEnvs, training_worlds_seed  # noqa: E402

ENV = {"n_modules": 12, "max_cycles": 20}


def _start_layouts(buffers_or_worlds) -> list[bytes]:
    """Each world's start layout as bytes (the modules' sites, in module order)."""
    return [np.ascontiguousarray(w.positions).tobytes() for w in buffers_or_worlds]


def test_no_two_worlds_of_training_seeds_0_to_4_share_a_stream():
    """16 worlds per run, training seeds 0..4: 80 different start layouts (with ``seed + w``,
    60 of the 80 repeated). The chain's blob is drawn from the world's generator, so equal
    layouts would mean shared streams."""
    layouts = []
    for seed in range(5):
        worlds = TrainingEnvs("chain-v1", "move", ENV, 16, training_worlds_seed(seed, 0))
        layouts += _start_layouts(worlds.batch.worlds)
    assert len(layouts) == 80
    assert len(set(layouts)) == 80


def test_a_curriculum_stage_and_a_resumed_run_get_new_worlds():
    first = world_seeds(training_worlds_seed(0, 0), 2)
    assert [s.generate_state(2).tolist() for s in first] == [s.generate_state(2).tolist() for s in world_seeds(0, 2)]
    later = world_seeds(training_worlds_seed(0, 100_000), 2)
    other_seed = world_seeds(training_worlds_seed(100_000, 0), 2)
    states = {tuple(s.generate_state(4)) for s in first + later + other_seed}
    assert len(states) == 6


def test_the_first_worlds_do_not_depend_on_the_batch_size():
    """A policy judged on fewer worlds gets the first ones."""
    small = proteo_env.make_batched("chain-v1", 2, **ENV)
    large = proteo_env.make_batched("chain-v1", 5, **ENV)
    small.reset(seed=9)
    large.reset(seed=9)
    assert _start_layouts(small.worlds) == _start_layouts(large.worlds[:2])


def test_listed_world_seeds_are_the_single_env_seeds():
    """``reset(world_seeds=[...])`` gives world b the stream of a single env reset with that seed
    (evaluation over seeds 1000.. keeps its worlds)."""
    batch = proteo_env.make_batched("chain-v1", 3, **ENV)
    batch.reset(world_seeds=[1000, 1001, 1002])
    singles = []
    for seed in (1000, 1001, 1002):
        env = proteo_env.make("chain-v1", **ENV)
        env.reset(seed=seed)
        singles.append(env.batch.worlds[0])
    assert _start_layouts(batch.worlds) == _start_layouts(singles)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"world_seeds": [1, 2]}, "world_seeds=[1, 2] is not allowed; allowed: a list of 3 seeds (one per world)"),
        ({"world_seeds": 4}, "world_seeds=4 is not allowed; allowed: a list of 3 seeds (one per world)"),
        ({"world_seeds": [1, -2, 3]}, "world_seeds[1]=-2 is not allowed; allowed: None or an integer >= 0"),
        ({"seed": 1, "world_seeds": [1, 2, 3]}, "seed=1 is not allowed with world_seeds; allowed: one of the two"),
        ({"seed": "x"}, "seed='x' is not allowed; allowed: None or an integer >= 0"),
    ],
)
def test_bad_world_seeds_are_one_clear_error(kwargs, message):
    batch = proteo_env.make_batched("chain-v1", 3, **ENV)
    with pytest.raises(ConfigError) as error:
        batch.reset(**kwargs)
    assert str(error.value).startswith(message)
