"""CMA-ES against the task's own reward: the hand-coded rules' parameters, or a small neural controller.

``controller: rules`` evolves the parameters of the task's hand-coded policy (the paper's own
suggestion: seed probabilities, randomness of moves, thresholds such as ``T`` and ``B``). The
parameters are read from the policy's constructor, including those it passes on to a parent
class through ``**kwargs`` (the branch rules take the chain rules' ``p_random`` that way):
floats named ``p_*`` range over [0, 1], other floats over [0, 2 * default] (at least [0, 1]),
ints over [1, 2 * default + 1], booleans are "> 0.5", strings need their options in
``choices``. ``params`` in the config names the ones to evolve (default: all of them),
``bounds`` and ``fixed`` override ranges or drop parameters. The *default* of a parameter is
the value the hand-coded policy uses in this environment (for example the branch task's
``T`` and ``B``, or the table task's ``p_max``, which the policy reads from the task), so the
start point is exactly the hand-coded policy. CMA-ES works in the unit cube. A candidate the
policy rejects (for example ``f_min > f_max`` for the table rules) scores one below the worst
valid candidate of its generation and is counted in ``cma/rejected``.

``controller: neural`` evolves the weights of a :class:`~training.machinery.policies.NumpyMLP`
(observation features -> hidden tanh layer -> logits of every action field) shared by all
modules, with separable CMA-ES (diagonal covariance) since it has thousands of weights.

Fitness of a candidate: the mean episode return over ``episodes_per_candidate`` seeds, the
same seeds for every candidate of a generation (common random numbers), new seeds each
generation. The checkpoint holds the distribution's mean (CMA-ES's best estimate under noise);
``progress.csv`` logs the generation's mean and best return. The run folder, resume (rerun the
same command after an interruption, or ``--resume CHECKPOINT``), the journal of finished
episodes, logs and time limit are :class:`training.machinery.runs.GenerationalRun`'s.

    python -m training.trainers.cma_es --config configs/train/cma_rules_chain_full.yaml
    python -m training.trainers.cma_es --config configs/train/cma_neural_chain.yaml --generations 5
    python -m training.trainers.cma_es --resume runs/cma_rules_chain_s0/checkpoints/step_0000123456 --generations 50
"""

from __future__ import annotations

import hashlib
import inspect
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import proteo_env
from baselines import POLICIES, make_policy
from baselines.base import constructor_parameters
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from proteo_env.registry import task_name
from training.machinery.checkpoints import mlp_meta
from training.machinery.distributed import ray_options, run_jobs
from training.machinery.evaluator import Controller, Episode, run_episodes, settings_json
from training.machinery.policies import LogitsPolicy, NumpyMLP
from training.machinery.runs import GenerationalArgs, GenerationalRun, limit_threads, parse_args, seed_everything


@dataclass(frozen=True)
class Args(GenerationalArgs):
    """CMA-ES over hand-coded rule parameters or a neural controller (arguments of training/trainers/cma_es.py)."""

    task: str = "chain-v0"
    """The task: a registered id such as chain-v1 (a bare name such as chain: its newest version)."""
    env: dict = field(default_factory=lambda: {"n_modules": 12, "max_cycles": 300})
    """Overrides passed to ``proteo_env.make``."""
    controller: str = "rules"
    """``rules`` (the hand-coded policy's parameters) or ``neural`` (a NumpyMLP's weights)."""
    policy: str | None = None
    """Hand-coded policy whose parameters evolve (default: the task's ``default_policy``)."""
    bounds: dict = field(default_factory=dict)
    """``{param: [low, high]}`` overriding the inferred ranges (rules)."""
    choices: dict = field(default_factory=dict)
    """``{param: [option, ...]}`` for string parameters (rules); others stay at their default."""
    params: tuple[str, ...] = ()
    """Names of the rule parameters to evolve (rules); empty: every numeric or boolean one."""
    fixed: tuple[str, ...] = ()
    """Parameters left at their defaults (rules)."""
    hidden: tuple[int, ...] = (16,)
    """Hidden layer sizes (neural)."""
    generations: int = 100
    popsize: int = 12
    """Candidates sampled each generation."""
    sigma0: float = 0.2
    """Initial step size (unit cube for rules, weight scale for neural)."""
    episodes_per_candidate: int = 3
    """Worlds each candidate plays per generation (the same for every candidate of a generation)."""


# ---------------------------------------------------------------------- the rules' parameter space
@dataclass(frozen=True)
class Param:
    """One evolved parameter: its kind, range and default (value = decode(x), x in [0, 1])."""

    name: str
    kind: str  # "float", "int", "bool" or "choice"
    low: float = 0.0
    high: float = 1.0
    options: tuple = ()
    default: object = None

    def decode(self, x: float):
        x = float(np.clip(x, 0.0, 1.0))
        if self.kind == "bool":
            return x > 0.5
        if self.kind == "choice":
            return self.options[min(int(x * len(self.options)), len(self.options) - 1)]
        value = self.low + x * (self.high - self.low)
        return int(round(value)) if self.kind == "int" else float(value)

    def encode(self, value) -> float:
        if self.kind == "bool":
            return 0.75 if value else 0.25
        if self.kind == "choice":
            return (self.options.index(value) + 0.5) / len(self.options)
        return float(np.clip((value - self.low) / (self.high - self.low), 0.0, 1.0))


def rule_params(policy_cls, args: Args, defaults: dict | None = None) -> list[Param]:
    """The evolvable parameters of a hand-coded policy class (see the module docstring).

    ``defaults`` maps parameter names to the values the policy uses in the environment at
    hand (they replace the constructor's defaults as start point and range centre).
    """
    skip = {"self", "action_layout", "modes", "scent_max", "seed", *args.fixed}
    candidates = {
        name: p
        for name, p in constructor_parameters(policy_cls).items()
        if name not in skip and p.default is not inspect.Parameter.empty and p.default is not None
    }
    for what, names in (("params", args.params), ("bounds", args.bounds), ("choices", args.choices)):
        unknown = sorted(set(names) - set(candidates))
        if unknown:
            raise ConfigError(
                f"{what}: {unknown[0]!r} is not a parameter of policy {policy_cls.name!r}; "
                f"allowed: {', '.join(sorted(candidates))}"
            )
    out = []
    for name, p in candidates.items():
        if args.params and name not in args.params:
            continue
        d = (defaults or {}).get(name, p.default)
        if name in args.choices:
            out.append(Param(name, "choice", options=tuple(args.choices[name]), default=d))
        elif isinstance(d, bool):
            out.append(Param(name, "bool", default=d))
        elif isinstance(d, float):
            low, high = args.bounds.get(name, (0.0, 1.0 if name.startswith("p_") else max(2.0 * d, 1.0)))
            out.append(Param(name, "float", float(low), float(high), default=d))
        elif isinstance(d, int):
            low, high = args.bounds.get(name, (1, 2 * d + 1))
            out.append(Param(name, "int", float(low), float(high), default=d))
    if not out:
        raise ValueError(f"policy {policy_cls.name!r} has no numeric or boolean parameters to evolve")
    return out


def policy_defaults(policy) -> dict:
    """The rule parameters a built policy uses: its attributes named like its constructor's parameters.

    Only attributes of the same kind as the constructor's default count (a bool for a bool, a
    number for a number, a string for a string), so an unrelated attribute is never taken.
    """
    out = {}
    for name, p in constructor_parameters(type(policy)).items():
        value = getattr(policy, name, None)
        d = p.default
        if value is None or d is inspect.Parameter.empty or d is None:
            continue
        same_kind = (
            isinstance(value, bool) == isinstance(d, bool)
            and (isinstance(value, str) == isinstance(d, str))
            and (isinstance(value, (int, float, str)))
        )
        if same_kind:
            out[name] = type(d)(value) if isinstance(d, (int, float)) and not isinstance(d, bool) else value
    return out


def distribution_mean(es) -> np.ndarray:
    """The search distribution's mean where candidates live: inside the bounds.

    With ``bounds`` CMA-ES keeps its mean in an unbounded internal space and maps every
    candidate into the box (``BoundTransform``, a reflection, not a clip); ``es.mean`` can lie
    outside the box, and clipping it would give a point no candidate was near (a probability
    at -0.25 clips to 0, while the candidates around it use about 0.15). ``xfavorite`` is the
    mean mapped like the candidates. Without bounds the two are the same.
    """
    return np.asarray(es.result.xfavorite)


# ---------------------------------------------------------------------- fitness
@dataclass(frozen=True)
class CandidateEpisode:
    """One episode of one neural candidate (picklable; a Ray task when ``--ray``); the rules'
    candidates run through :func:`rules_episodes`.

    ``genome`` is the candidate ``x`` (``(n,)`` weights of a :class:`~training.machinery.policies.NumpyMLP`
    with ``hidden`` layers).
    """

    task: str
    env: str
    """The JSON of the ``proteo_env.make`` overrides."""
    hidden: tuple
    genome: tuple
    seed: int

    @property
    def key(self) -> str:
        """The journal key: a hash of the candidate and the seed (generation-independent)."""
        return f"{hashlib.sha256(np.asarray(self.genome, dtype=np.float64).tobytes()).hexdigest()[:16]}|{self.seed}"


_ENVS: dict = {}
"""The environment (and encoder) per (task, overrides), built once per process."""


def _env(task: str, overrides: str):
    if (task, overrides) not in _ENVS:
        limit_threads(1)
        env = proteo_env.make(task, **json.loads(overrides))
        _ENVS[(task, overrides)] = (env, ObservationEncoder.for_env(env))
    return _ENVS[(task, overrides)]


def build_policy(job: CandidateEpisode):
    """The neural candidate's policy in this process's environment."""
    env, encoder = _env(job.task, job.env)

    nvec = env.action_layout.nvec
    net = NumpyMLP(encoder.size, int(nvec.sum()), job.hidden).set_flat(np.asarray(job.genome))
    return env, LogitsPolicy(
        env.action_layout,
        env.task.modes,
        scent_max=env.config.physics.scent_max,
        seed=job.seed,
        encoder=encoder,
        logits_fn=net,
        label="cma-neural",
    )


def candidate_episode(job: CandidateEpisode) -> list:
    """``[return, success, cycles]`` of a neural candidate's episode (through the array API)."""
    env, policy = build_policy(job)
    total, success, cycles = episode_return(env, policy, job.seed)
    return [float(total), bool(success), int(cycles)]


def rules_episodes(args, policy_name: str, env, decoded: list[dict], seeds: list[int], ray, journal) -> list:
    """``[return, success, cycles]`` of every candidate's episode on every seed (candidate-major),
    ``None`` for a candidate whose parameters the policy rejects: the accepted candidates' episodes
    in batches of worlds on every core (:mod:`training.machinery.evaluator`)."""
    accepted = []
    for params in decoded:
        try:
            make_policy(policy_name, env, **params)
            accepted.append(True)
        except ValueError:  # parameters the policy rejects (e.g. f_min > f_max): scored below
            accepted.append(False)
    overrides = settings_json(args.env)
    episodes = [
        Episode(args.task, overrides, "full", Controller.rules(policy_name, **params), s)
        for params, ok in zip(decoded, accepted)
        if ok
        for s in seeds
    ]
    results = iter(
        run_episodes(
            episodes,
            workers=args.workers if ray is None else None,
            ray=ray,
            journal=journal,
            desc="generation",
            progress=args.progress_bar,
        )
        if episodes
        else []
    )
    out = []
    for ok in accepted:
        for _ in seeds:
            r = next(results) if ok else None
            out.append(None if r is None else [float(r.total_reward), bool(r.success), int(r.cycles)])
    return out


def episode_return(env, policy, seed: int) -> tuple[float, bool, int]:
    """Return, success and cycles of one episode of a neural controller, through the array API."""
    env.reset(seed=seed)
    policy.reset(seed)
    total = 0.0
    while True:
        buffers = env.observe_arrays()
        features = policy.encoder.encode_buffers(buffers)
        result = env.step_arrays(policy.act_arrays(features, buffers.action_mask))
        total += float(result.reward[0])
        if result.done[0]:
            return total, bool(result.terminated[0]), env.cycle


def neural_episodes(args, overrides: str, candidates, seeds: list[int], ray, journal, generation: int) -> list:
    """``[return, success, cycles]`` of every candidate network's episode on every seed
    (candidate-major), run as journaled jobs here or on Ray (:func:`candidate_episode`)."""
    jobs = [
        CandidateEpisode(
            task=args.task, env=overrides, hidden=tuple(args.hidden), genome=tuple(float(v) for v in x), seed=s
        )
        for x in candidates
        for s in seeds
    ]
    return run_jobs(
        candidate_episode,
        jobs,
        [j.key for j in jobs],
        ray=ray,
        workers=args.workers if ray is None else None,
        journal=journal,
        desc=f"generation {generation}",
        progress=args.progress_bar,
    )


def candidate_fitness(episodes: list, n_candidates: int, n_seeds: int) -> tuple[list, list]:
    """``(fitness, outcomes)``: each candidate's mean return over its seeds (``None`` for one the
    policy rejected) and the episodes of the scored candidates, in order."""
    fitness, outcomes = [], []
    for c in range(n_candidates):
        results = episodes[c * n_seeds : (c + 1) * n_seeds]
        if any(r is None for r in results):
            fitness.append(None)
            continue
        outcomes += results
        fitness.append(float(np.mean([r[0] for r in results])))
    return fitness, outcomes


def main(argv=None) -> Path:
    args = parse_args(Args, argv)

    if args.controller not in ("rules", "neural"):
        raise ConfigError(f"controller={args.controller!r} is not allowed; allowed: rules, neural")
    ray = ray_options(args)
    seed_everything(args.seed, threads=args.threads)

    import cma

    env = proteo_env.make(args.task, **args.env)
    encoder = ObservationEncoder.for_env(env)
    nvec = env.action_layout.nvec
    algorithm = f"cma-{args.controller}"
    run = GenerationalRun(
        args,
        algorithm=algorithm,
        name=f"cma_{args.controller}_{task_name(args.task)}_s{args.seed}",
        what="CMA-ES run",
        counter="cma/generation",
    )

    # Two independent streams of the run's seed (numpy.random.SeedSequence children): the episodes'
    # world seeds, and CMA-ES's own sampling (cma seeds numpy's legacy generator with an integer;
    # it reads 0 as "the clock").
    episode_stream, cma_stream = np.random.SeedSequence(args.seed).spawn(2)
    cma_seed = int(cma_stream.generate_state(1)[0]) or 1

    # ------------------------------------------------------------------ genome <-> policy
    params: tuple = ()
    policy_name = ""
    if args.controller == "rules":
        policy_name = args.policy or env.task.default_policy
        if policy_name not in POLICIES:
            raise ValueError(f"policy {policy_name!r} is not registered; allowed: {', '.join(sorted(POLICIES))}")
        hand_coded = make_policy(policy_name, env)
        params = tuple(rule_params(POLICIES[policy_name], args, defaults=policy_defaults(hand_coded)))

        def decode(x):
            return {p.name: p.decode(v) for p, v in zip(params, x)}

        x0 = np.array([p.encode(p.default) for p in params])
        options = {"bounds": [0.0, 1.0], "popsize": args.popsize, "seed": cma_seed, "verbose": -9}
    else:
        x0 = NumpyMLP(encoder.size, int(nvec.sum()), args.hidden).init_genome(np.random.default_rng(args.seed))
        options = {"popsize": args.popsize, "seed": cma_seed, "verbose": -9, "CMA_diagonal": True}

    rng = np.random.default_rng(episode_stream)
    agent_steps = 0
    if run.resumed is not None:
        es, agent_steps = run.resumed["es"], run.resumed["agent_steps"]
        rng.bit_generator.state = run.resumed["rng"]
        np.random.set_state(run.resumed["np_random"])  # CMA-ES samples its candidates from numpy's global generator
    else:
        es = cma.CMAEvolutionStrategy(x0, args.sigma0, options)

    def state_now() -> dict:
        return {
            "es": es,
            "agent_steps": agent_steps,
            "rng": rng.bit_generator.state,
            "np_random": np.random.get_state(),
        }

    def write(folder: Path, steps: int) -> None:
        mean = distribution_mean(es)
        if args.controller == "rules":
            extra = {"control": "full", "policy": policy_name, "params": decode(mean)}
        else:
            np.save(folder / "genome.npy", mean.astype(np.float32))
            extra = mlp_meta("full", args.hidden)
        run.write_meta(
            folder,
            task=env.task.task_id(),
            env_overrides=dict(args.env),
            encoder_spec=encoder.spec() if args.controller == "neural" else None,
            nvec=nvec,
            agent_steps=steps,
            generation=int(es.countiter),
            extra=extra,
        )

    # ------------------------------------------------------------------ evolve
    n_agents = len(env.possible_agents)
    overrides = json.dumps(args.env, sort_keys=True)
    run.start(es.countiter)
    while es.countiter < args.generations:
        seeds = [int(s) for s in rng.integers(2**31, size=args.episodes_per_candidate)]
        candidates = es.ask()
        if args.controller == "rules":
            episodes = rules_episodes(args, policy_name, env, [decode(x) for x in candidates], seeds, ray, run.journal)
        else:
            episodes = neural_episodes(args, overrides, candidates, seeds, ray, run.journal, es.countiter + 1)
        fitness, outcomes = candidate_fitness(episodes, len(candidates), len(seeds))
        agent_steps += sum(r[2] for r in outcomes) * n_agents
        valid = [f for f in fitness if f is not None]
        if not valid:
            raise ValueError(
                f"generation {es.countiter + 1}: the policy rejected every candidate; "
                "narrow the ranges with bounds (or fixed) in the config"
            )
        worst = min(valid) - 1.0
        es.tell(candidates, [-(worst if f is None else f) for f in fitness])  # CMA-ES minimises
        values = {
            "episode/return": float(np.mean(valid)),
            "episode/best_candidate_return": max(valid),
            "episode/success": float(np.mean([r[1] for r in outcomes])),
            "episode/cycles": float(np.mean([r[2] for r in outcomes])),
            "cma/sigma": float(es.sigma),
            "cma/rejected": float(len(fitness) - len(valid)),
            "cma/generation": float(es.countiter),
        }
        if args.controller == "rules":
            values.update(
                {f"param/{k}": float(v) for k, v in decode(distribution_mean(es)).items() if not isinstance(v, str)}
            )
        if run.end_generation(es.countiter, agent_steps, values, state_now(), write):
            break
    final = run.finish(agent_steps, state_now(), write)
    print(
        f"final checkpoint: {final}  ({es.countiter} generations, {agent_steps} agent-steps, {run.log.seconds:.0f} s)"
    )
    return final


if __name__ == "__main__":
    from training.machinery.runs import run_script

    raise SystemExit(run_script(main))
