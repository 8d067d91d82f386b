"""proteo's tasks as BenchMARL tasks: IPPO, MAPPO and the rest of BenchMARL on any registered task.

    from proteo_env.adapters.benchmarl import ProteoTask, experiment

    experiment(ProteoTask.CHAIN_V1, "mappo", settings={"n_modules": 12}).run()

or with BenchMARL's own pieces (``Experiment(task=ProteoTask.CHAIN_V1.get_task(), algorithm_config=
MappoConfig.get_from_yaml(), model_config=..., config=experiment_config(), ...)``).

:class:`ProteoTask` has one member per task registered when this module is imported (``chain-v1``
is ``CHAIN_V1``). A member's ``get_task(config)`` gives the BenchMARL task: ``config`` holds the
task's settings as :func:`proteo_env.make` takes them, over :data:`DEFAULT_CONFIG` (control level
``move``: one masked ``Categorical(13)`` per module, the action BenchMARL's masked discrete
algorithms take; the rules' autopilot sets the rest of the action). The env is
:class:`~proteo_env.adapters.torchrl.ProteoTorchRLEnv` with BenchMARL's ``num_envs`` worlds
batched; the modules of a world are the group ``"agents"``; ``max_steps`` is the task's cycle
limit; the global state (``"state"``) is the critic's input for MAPPO when asked.
:func:`experiment_config` is BenchMARL's default experiment with stochastic evaluation
(``evaluation_deterministic_actions: False``): the arg-max of a masked policy can stall a module
for ever (a deterministic evaluation of the chain never succeeded where stochastic ones did).

BenchMARL 1.5 needs torchrl < 0.12, the training extra pins torchrl 0.14: install BenchMARL in its
own environment (``make benchmarl``; docs/guides/learning.md, "BenchMARL").
"""

from __future__ import annotations

from collections.abc import Callable

from benchmarl.environments.common import Task, TaskClass
from benchmarl.experiment import ExperimentConfig
from torchrl.data import Composite
from torchrl.envs import EnvBase

from ..registry import TASKS
from .torchrl import ProteoTorchRLEnv

DEFAULT_CONFIG = {"control": "move"}
"""Settings every proteo task starts from in BenchMARL, under the caller's ``config``."""


def member_name(task_id: str) -> str:
    """The :class:`ProteoTask` member of a task id: ``chain-v1`` -> ``CHAIN_V1``."""
    return task_id.upper().replace("-", "_")


TASK_IDS = {member_name(task_id): task_id for task_id in sorted(TASKS)}
"""Member name -> task id, for every task registered when this module was imported."""


class ProteoTaskClass(TaskClass):
    """One proteo task as BenchMARL runs it (``self.name`` is the member name, ``self.config``
    the settings passed to :func:`proteo_env.make`)."""

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device) -> Callable[[], EnvBase]:
        task_id, settings = TASK_IDS[self.name], dict(self.config)
        return lambda: ProteoTorchRLEnv(task_id, n_copies=num_envs, seed=seed, device=device, **settings)

    def supports_continuous_actions(self) -> bool:
        return False

    def supports_discrete_actions(self) -> bool:
        return True

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return int(_first_world(env).max_cycles)

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return {"agents": list(_first_world(env).possible_agents)}

    def observation_spec(self, env: EnvBase) -> Composite:
        return _unbatched_observation(env, drop=("state", ("agents", "action_mask")))

    def info_spec(self, env: EnvBase) -> Composite | None:
        return None

    def state_spec(self, env: EnvBase) -> Composite | None:
        return Composite(state=env.full_observation_spec_unbatched["state"].clone())

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return _unbatched_observation(env, drop=("state", ("agents", "observation")))

    @staticmethod
    def env_name() -> str:
        return "proteo"


def _first_world(env: EnvBase):
    """The first :class:`~proteo_env.env.ProteoEnv` of a (possibly transformed) proteo TorchRL env."""
    return getattr(env, "base_env", env).envs[0]


def _unbatched_observation(env: EnvBase, drop: tuple) -> Composite:
    """The env's observation spec without its batch dimension (BenchMARL's convention) and ``drop``'s keys."""
    spec = env.full_observation_spec_unbatched.clone()
    for key in drop:
        del spec[key]
    return spec


class _ProteoTasks(Task):
    """The behaviour of :class:`ProteoTask`'s members (its members are made from the registry)."""

    @staticmethod
    def associated_class():
        return ProteoTaskClass

    def get_task(self, config: dict | None = None) -> TaskClass:
        """The BenchMARL task: ``config`` (settings for :func:`proteo_env.make`) over
        :data:`DEFAULT_CONFIG`. There is no YAML file to read: the task's own defaults apply."""
        return ProteoTaskClass(name=self.name, config={**DEFAULT_CONFIG, **(config or {})})


ProteoTask = _ProteoTasks("ProteoTask", {name: None for name in TASK_IDS})
"""One member per registered task (``ProteoTask.CHAIN_V1``, ``ProteoTask.GRASP_V0``, ...)."""


def experiment(task: ProteoTask, algorithm: str = "mappo", *, settings: dict | None = None, seed: int = 0, **changes):
    """A BenchMARL ``Experiment`` of ``algorithm`` (a name of BenchMARL's registry: ``mappo``,
    ``ippo``, ``qmix``, ...) on ``task`` with ``settings`` (:meth:`_ProteoTasks.get_task`), an MLP
    actor and critic as BenchMARL configures them by default, and :func:`experiment_config`
    with ``changes``."""
    from benchmarl.algorithms import algorithm_config_registry
    from benchmarl.experiment import Experiment
    from benchmarl.models import MlpConfig

    if algorithm not in algorithm_config_registry:
        raise ValueError(
            f"algorithm={algorithm!r} is not allowed; allowed: {', '.join(sorted(algorithm_config_registry))}"
        )
    return Experiment(
        task=task.get_task(settings),
        algorithm_config=algorithm_config_registry[algorithm].get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed,
        config=experiment_config(**changes),
    )


def experiment_config(**changes) -> ExperimentConfig:
    """BenchMARL's default :class:`ExperimentConfig` with stochastic evaluation, then ``changes``
    (its field names, e.g. ``max_n_frames=200_000``)."""
    config = ExperimentConfig.get_from_yaml()
    config.evaluation_deterministic_actions = False
    for name, value in changes.items():
        if not hasattr(config, name):
            raise ValueError(f"experiment_config: {name}={value!r} is not allowed; allowed: ExperimentConfig's fields")
        setattr(config, name, value)
    return config
