"""Evolution of programs (:mod:`baselines.program`): their structure and their numbers.

A (mu + lambda) evolutionary algorithm over programs of the paper's primitives, the
direction the paper's conclusions propose. The population starts as ``population`` random
programs (:func:`training.trainers.program_variation.random_program`), or as ``seed_program`` (a
program name, path or text) and mutants of it. Each generation breeds ``offspring`` children:
two parents picked by tournaments of ``tournament``, crossed with probability
``crossover_rate`` (else a copy of the first), then 1 + Poisson(``mutations`` - 1) mutations
(:mod:`training.trainers.program_variation`). Parents and children are all scored on the
generation's worlds and the best ``population`` distinct programs survive (elitism: the best
is never lost to a child, only to a program that scores better on the same worlds).

Fitness of a program: the mean episode score over ``variations`` (env overrides over
``env``: sizes, object shapes or directions, weight schedules, T and B ...) times
``episodes_per_variation`` worlds, minus ``complexity_penalty`` times its rules + conditions +
actions. An episode's score is its return (``fitness: return``) or, for a task whose reward a
program can collect without succeeding, ``2 - cycles / max_cycles`` for a success and 0 for a
failure (``fitness: success``: success first, then speed), or, on branch and table, a partial
credit only the behaviour earns plus the success's speed (``fitness: progress``,
:func:`progress_score`: branching levels of a tree; weight shifts the legs moved for and
restabilised after). The worlds are common random
numbers: the same for every program of a generation, new each generation, their seeds drawn
from a ``numpy.random.SeedSequence`` child of the run seed (generation ``g`` uses the child's
child ``g``). Policy seeds equal world seeds.

A generation's best is chosen on few worlds, so it is partly luck. With
``final_episodes_per_variation`` the surviving population is scored once more after the last
generation, on that many new worlds per variation (a third stream of the run seed), and the
best there is the final checkpoint; its ``proteo.json`` records that fitness.

Every generation's episodes run as one list through :mod:`training.machinery.evaluator`: the programs
of the population in the rows of batched worlds, on every core (``workers``), or as Ray tasks
of one batch each (``ray``); the results do not depend on how they are spread.

The best program of each generation is the checkpoint: ``program.yaml`` beside ``proteo.json``
(algorithm ``program-evolution``), loaded by ``proteo eval --checkpoint`` and
:func:`training.load_controller`. ``progress.csv`` and TensorBoard log the best and median
fitness per generation. A run resumes like training/trainers/cma_es.py: rerun the same command after
an interruption, or ``--resume CHECKPOINT --generations N`` to go on from a checkpoint.

    python -m training.trainers.evolve --config configs/train/evolve_chain_full.yaml
    python -m training.trainers.evolve --config configs/train/evolve_paper_chain_full.yaml --generations 5
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import proteo_env
from baselines.program import format_program, load_program
from proteo_env.config import ConfigError
from proteo_env.registry import task_name
from training.machinery.distributed import ray_options
from training.machinery.evaluator import Controller, Episode, run_episodes
from training.machinery.runs import (
    GenerationalArgs,
    GenerationalRun,
    check_integers,
    check_numbers,
    parse_args,
    seed_everything,
)
from training.trainers.program_variation import ProgramSpace, complexity, crossover, mutate, random_program

ALGORITHM = "program-evolution"
"""The ``algorithm`` of an evolved program's checkpoint."""


@dataclass(frozen=True)
class Args(GenerationalArgs):
    """Evolution of programs of the paper's primitives (arguments of training/trainers/evolve.py)."""

    task: str = "chain-v1"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"})
    """Overrides passed to ``proteo_env.make``: the world the checkpoint is for."""
    variations: tuple[dict, ...] = ({},)
    """Env overrides over ``env``, one per task variation a program is scored on (at least one)."""
    episodes_per_variation: int = 1
    """Worlds each program plays per variation each generation (the same worlds for every program)."""
    seed_program: str | None = None
    """A program (name, path or text) the population starts from; none: random programs."""
    population: int = 8
    """Programs that survive each generation (mu)."""
    offspring: int = 16
    """Children bred each generation (lambda)."""
    tournament: int = 3
    """Survivors drawn at random (with replacement) per tournament; the best-ranked one drawn is a parent."""
    crossover_rate: float = 0.3
    """Probability that a child is the crossover of two tournament winners (else a copy of the first)."""
    mutations: float = 1.5
    """Mean mutations per child (at least 1)."""
    complexity_penalty: float = 0.001
    """Subtracted from the fitness per rule, condition and action."""
    fitness: str = "return"
    """An episode's score: ``return`` (the task's reward), ``success`` (``2 - cycles /
    max_cycles`` for a success, 0 for a failure) or ``progress`` (branch and table: the
    behaviour's partial credit in [0, 1], plus ``1 - cycles / max_cycles`` for a success)."""
    max_rules: int = 4
    """Rules per mode."""
    max_conditions: int = 3
    """Conditions per rule."""
    max_actions: int = 3
    """Actions per rule."""
    final_episodes_per_variation: int = 0
    """Episodes per variation on which the survivors are scored after the last generation to
    choose the final checkpoint (0: the last generation's best)."""


INDEPENDENT = ("final_episodes_per_variation",)
"""Options beside :data:`training.machinery.runs.RUN_INDEPENDENT` a resumed run may change (the final choice
comes after the generations)."""


# ---------------------------------------------------------------------- episodes
def program_episodes(task: str, variations: list[str], programs: list[str], seeds: list[int]) -> list:
    """The :class:`~training.machinery.evaluator.Episode` of every program (text) on every world: program-major,
    then variation (its overrides as JSON), then seed."""
    return [
        Episode(task, overrides, "full", Controller.program(text), seed)
        for text in programs
        for overrides in variations
        for seed in seeds
    ]


def success_score(episode, env) -> float:
    """``2 - cycles / max_cycles`` for a successful episode (an :class:`~proteo_env.rollout.EpisodeResult`
    of ``env``), 0 for a failure."""
    return 2.0 - episode.cycles / env.max_cycles if episode.success else 0.0


def branch_progress(metrics: dict, params) -> float:
    """The branching levels the grown structure reached, as a share of ``target_levels``, when it is
    a tree (0 when it has cycles): no credit for growing without branching."""
    return metrics["tree"] * min(metrics["levels"], params.target_levels) / params.target_levels


def table_progress(metrics: dict, params) -> float:
    """The share of the weight schedule's entries whose stable configuration the table reached by
    moving its legs (``restabilise_k > 0``: the signature changed after the entry's shift, then held
    for the stable window); a table whose legs stand still after the first entry earns ``1 / K``."""
    return sum(metrics[f"restabilise_{k}"] > 0 for k in range(len(params.schedule))) / len(params.schedule)


TASK_PROGRESS = {"branch": branch_progress, "table": table_progress}
"""Tasks with a partial credit for ``fitness: progress``: task name -> progress in [0, 1] from an
episode's final metrics and the task's parameters, earned only by doing the task's behaviour."""


def progress_score(episode, env) -> float:
    """The task's progress (:data:`TASK_PROGRESS`), plus ``1 - cycles / max_cycles`` for a success:
    at success (progress 1 on branch) it equals :func:`success_score`."""
    task = env.task
    progress = TASK_PROGRESS[task.name](episode.metrics, task.params)
    return progress + (1.0 - episode.cycles / env.max_cycles if episode.success else 0.0)


EPISODE_SCORES = {
    "return": lambda episode, env: episode.total_reward,
    "success": success_score,
    "progress": progress_score,
}
"""The episode score each value of ``fitness`` names, from an episode's result and its env (which
gives the cycle limit and the task's parameters)."""


def generation_seeds(world_stream: np.random.SeedSequence, generation: int, n: int) -> list[int]:
    """The ``n`` world seeds of ``generation``: from the stream's child ``generation``."""
    child = np.random.SeedSequence(world_stream.entropy, spawn_key=(*world_stream.spawn_key, generation))
    return [int(s) for s in child.generate_state(n) % 2**31]


# ---------------------------------------------------------------------- checking the arguments
def check_args(args: Args) -> list[str]:
    """The env overrides of every variation as JSON, after checking the arguments (``ConfigError``)."""
    check_integers(
        args,
        {
            "population": 1,
            "offspring": 1,
            "tournament": 1,
            "episodes_per_variation": 1,
            "final_episodes_per_variation": 0,
            "max_rules": 1,
            "max_conditions": 0,
            "max_actions": 1,
            "checkpoint_every": 1,
        },
    )
    check_numbers(args, {"crossover_rate": (0.0, 1.0), "mutations": (1.0, None), "complexity_penalty": (0.0, None)})
    if args.fitness not in EPISODE_SCORES:
        raise ConfigError(f"fitness: {args.fitness!r} is not allowed; allowed: {', '.join(EPISODE_SCORES)}")
    allowed = "a non-empty list of env overrides over env, such as [{n_modules: 10}, {}, {n_modules: 14}]"
    if not isinstance(args.variations, (list, tuple)) or not args.variations:
        raise ConfigError(f"variations: {args.variations!r} is not allowed; allowed: {allowed}")
    overrides = []
    for i, variation in enumerate(args.variations):
        if not isinstance(variation, dict):
            raise ConfigError(f"variations[{i}]: {variation!r} is not allowed; allowed: {allowed}")
        merged = {**args.env, **variation}
        try:
            proteo_env.make(args.task, **merged)
        except ConfigError as err:
            raise ConfigError(f"variations[{i}]: {variation!r} is not allowed: {err}") from None
        overrides.append(json.dumps(merged, sort_keys=True))
    if args.fitness == "progress" and proteo_env.make(args.task, **args.env).task.name not in TASK_PROGRESS:
        raise ConfigError(
            f"fitness: 'progress' is not allowed on task {args.task!r}; allowed: return or success "
            f"(progress is defined on {', '.join(TASK_PROGRESS)})"
        )
    return overrides


# ---------------------------------------------------------------------- the algorithm
def breed(population: list, space, rng: np.random.Generator, args: Args) -> list:
    """``args.offspring`` children of ``population`` (programs, best first)."""

    def tournament():
        return population[int(rng.integers(len(population), size=args.tournament).min())]

    children = []
    for _ in range(args.offspring):
        child = tournament()
        if rng.random() < args.crossover_rate:
            child = crossover(child, tournament(), space, rng)
        for _ in range(1 + int(rng.poisson(args.mutations - 1.0))):
            child = mutate(child, space, rng)
        children.append(child)
    return children


def main(argv=None) -> Path:
    args = parse_args(Args, argv)

    variations = check_args(args)
    ray = ray_options(args)
    seed_everything(args.seed, threads=args.threads)

    env = proteo_env.make(args.task, **args.env)
    limits = {"max_rules": args.max_rules, "max_conditions": args.max_conditions, "max_actions": args.max_actions}
    seed_program = None if args.seed_program is None else load_program(args.seed_program, env)
    if seed_program is None:
        space = ProgramSpace.for_env(env, **limits)
    else:
        space = ProgramSpace.for_program(seed_program, type(env.task), **limits)
    run = GenerationalRun(
        args,
        algorithm=ALGORITHM,
        name=f"evolve_{task_name(args.task)}_s{args.seed}",
        what="evolution run",
        counter="evolve/generation",
        independent=INDEPENDENT,
    )

    # Independent streams of the run's seed: the generations' worlds, the variation operators'
    # draws, and the worlds of the final choice.
    world_stream, variation_stream, final_stream = np.random.SeedSequence(args.seed).spawn(3)
    rng = np.random.default_rng(variation_stream)
    if run.resumed is not None:
        state = run.resumed
        population = [load_program(text, env) for text in state["population"]]
        generation, agent_steps, best_fitness = state["generation"], state["agent_steps"], state["best_fitness"]
        rng.bit_generator.state = state["rng"]
    else:
        if seed_program is None:
            population = [random_program(space, rng, env.task.name) for _ in range(args.population)]
        else:
            population = [seed_program] + [mutate(seed_program, space, rng) for _ in range(args.population - 1)]
        generation, agent_steps, best_fitness = 0, 0, None

    def state_now() -> dict:
        return {
            "population": [format_program(p) for p in population],
            "generation": generation,
            "agent_steps": agent_steps,
            "best_fitness": best_fitness,
            "rng": rng.bit_generator.state,
        }

    def write(folder: Path, steps: int) -> None:
        (folder / "program.yaml").write_text(format_program(population[0]))
        run.write_meta(
            folder,
            task=env.task.task_id(),
            env_overrides=dict(args.env),
            encoder_spec=None,
            nvec=env.action_layout.nvec,
            agent_steps=steps,
            generation=generation,
            extra={"control": "full", "fitness": best_fitness, "complexity": complexity(population[0])},
        )

    episode_score = EPISODE_SCORES[args.fitness]
    limits_of = [proteo_env.make(args.task, **json.loads(v)) for v in variations]
    modules = [len(e.possible_agents) for e in limits_of]

    def score(candidates: list, seeds: list[int], desc: str) -> tuple[list[float], list[list]]:
        """The fitness of each candidate on the worlds of ``seeds`` in every variation, and its episodes."""
        nonlocal agent_steps
        texts = [format_program(program) for program in candidates]
        episodes = run_episodes(
            program_episodes(args.task, variations, texts, seeds),
            workers=args.workers if ray is None else None,
            ray=ray,
            journal=run.journal,
            desc=desc,
            progress=args.progress_bar,
        )
        per_program = len(variations) * len(seeds)
        outcomes = [episodes[c * per_program : (c + 1) * per_program] for c in range(len(candidates))]
        variation_of = [v for v in range(len(variations)) for _ in seeds]
        agent_steps += sum(r.cycles * modules[v] for results in outcomes for r, v in zip(results, variation_of))
        fitness = [
            float(np.mean([episode_score(r, limits_of[v]) for r, v in zip(results, variation_of)]))
            - args.complexity_penalty * complexity(program)
            for program, results in zip(candidates, outcomes)
        ]
        return fitness, outcomes

    run.start(generation)
    while generation < args.generations:
        seeds = generation_seeds(world_stream, generation, args.episodes_per_variation)
        candidates = list({format_program(p): p for p in population + breed(population, space, rng, args)}.values())
        fitness, outcomes = score(candidates, seeds, f"generation {generation + 1}")
        order = sorted(range(len(candidates)), key=lambda c: -fitness[c])[: args.population]
        population = [candidates[c] for c in order]
        best = order[0]
        best_fitness = fitness[best]
        generation += 1
        values = {
            "fitness/best": best_fitness,
            "fitness/median": float(np.median(fitness)),
            "episode/return": float(np.mean([r.total_reward for r in outcomes[best]])),
            "episode/success": float(np.mean([r.success for r in outcomes[best]])),
            "episode/cycles": float(np.mean([r.cycles for r in outcomes[best]])),
            "program/complexity": float(complexity(candidates[best])),
            "evolve/candidates": float(len(candidates)),
        }
        if run.end_generation(generation, agent_steps, values, state_now(), write):
            break
    if args.final_episodes_per_variation:
        seeds = generation_seeds(final_stream, generation, args.final_episodes_per_variation)
        fitness, _ = score(population, seeds, "final choice")
        order = sorted(range(len(population)), key=lambda c: -fitness[c])
        population, best_fitness = [population[c] for c in order], fitness[order[0]]
        print(f"final choice on {len(seeds) * len(variations)} worlds: survivor {order[0] + 1}, fitness {best_fitness}")
    final = run.finish(agent_steps, state_now(), write)
    print(
        f"final checkpoint: {final}  ({generation} generations, best fitness {best_fitness}, "
        f"{agent_steps} agent-steps, {run.log.seconds:.0f} s)"
    )
    return final


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))
