"""The policy interface shared by hand-coded, random, learned and evolved controllers."""

from __future__ import annotations

import functools
import inspect
from typing import NamedTuple

import numba
import numpy as np

from proteo_env.config import CONTROL_LEVELS
from proteo_env.core.jit import generated_kernel, kernel
from proteo_env.core.records import OBSERVATION_FIELDS
from proteo_env.spaces import ActionLayout


class Policy:
    """Maps every agent's observation to its action, seeing nothing else.

    A policy is built from the environment's static interface (``env.action_layout`` and
    the task's mode names) and then only ever receives observations: ``act`` takes the dict
    ``{agent: observation}`` that ``env.reset``/``env.step`` return and gives back
    ``{agent: action}``. Per-agent private memory (the paper's module memory) may be kept
    between calls, keyed by agent name; :meth:`reset` clears it.

    Args:
        action_layout: the task's :class:`~proteo_env.spaces.ActionLayout`.
        modes: the task's mode names (``env.task.modes``).
        scent_max: the scent value that means "no scent" (``env.config.physics.scent_max``).
        seed: seed of the policy's own random generator.
    """

    name = ""
    levels: tuple[str, ...] = ("full",)
    """The control levels (:mod:`proteo_env.control`) whose actions this policy gives."""

    def __init__(self, action_layout: ActionLayout, modes, *, scent_max: int = 65535, seed: int | None = None):
        self.action_layout = action_layout
        self.modes = tuple(modes)
        self.scent_max = scent_max
        self.rng = np.random.default_rng(seed)

    @classmethod
    def for_env(cls, env, *, seed: int | None = None, **params):
        """Build the policy from an environment's static interface (never its state)."""
        check_level(cls, env)
        return cls(env.action_layout, env.task.modes, scent_max=env.config.physics.scent_max, seed=seed, **params)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def act(self, observations: dict) -> dict:
        raise NotImplementedError

    def random_legal_move(self, mask: np.ndarray, allowed=None) -> int:
        """A uniformly chosen legal move ``1..12`` (``allowed``: optional (13,) bool filter), or 0."""
        legal = mask[1:].astype(bool)
        if allowed is not None:
            legal &= allowed[1:]
        choices = np.flatnonzero(legal)
        return int(self.rng.choice(choices)) + 1 if choices.size else 0


def check_level(policy_cls, env) -> None:
    """A ``ValueError`` when ``policy_cls`` gives no actions of ``env``'s control level."""
    level = getattr(env, "control", "full")
    if level not in policy_cls.levels:
        raise ValueError(
            f"policy {policy_cls.name!r} gives actions at control level "
            f"{'/'.join(policy_cls.levels)}, not at the env's control={level!r}; allowed: an env made "
            f"with control={policy_cls.levels[0]!r}, or a policy of that level (random, a checkpoint "
            f"trained at {level!r})"
        )


def constructor_parameters(policy_cls) -> dict[str, inspect.Parameter]:
    """Keyword parameters of ``policy_cls`` with defaults, following ``**kwargs`` up the class tree
    (the fields of a :class:`KernelPolicy`'s ``Params`` are keyword parameters too)."""
    out: dict[str, inspect.Parameter] = {}
    for cls in policy_cls.__mro__:
        for name, default in getattr(vars(cls).get("Params"), "_field_defaults", {}).items():
            out.setdefault(name, inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default))
        if "__init__" not in vars(cls):
            continue
        signature = inspect.signature(cls.__init__).parameters
        for name, p in signature.items():
            if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD:
                out.setdefault(name, p)
        if not any(p.kind is p.VAR_KEYWORD for p in signature.values()):
            break
    return out


FIELD_DTYPES = {
    "own_mode": np.int32,
    "messages": np.int32,
    "neighbour_kind": np.int8,
    "neighbour_mode": np.int32,
    "neighbour_scent": np.int32,
    "own_scent": np.int32,
    "action_mask": np.int8,
    "contact": np.int8,
    "load": np.float32,
    "hint": np.float32,
}
"""The dtype in which the rule kernels take each observation field (those of :mod:`proteo_env.spaces`)."""


Observed = NamedTuple("Observed", [(name, np.ndarray) for name in OBSERVATION_FIELDS])
Observed.__doc__ = """Every observation field stacked over agents (A agents, K neighbourhood sites, C
channels), as a rule kernel (:attr:`KernelPolicy.rule`) reads them by name (dtypes: :data:`FIELD_DTYPES`).

The fields are :data:`~proteo_env.core.records.OBSERVATION_FIELDS`, in its order:
``neighbour_kind`` (A, K), ``neighbour_mode`` (A, K), ``neighbour_scent`` (A, K, C),
``own_mode`` (A, 1), ``own_scent`` (A, C), ``messages`` (A, 12), ``contact`` (A, 2), ``load``
(A, 1), ``hint`` (A, 3) and ``action_mask`` (A, 13) (:mod:`proteo_env.spaces` has their shapes).
"""


def stacked_fields(field, names) -> tuple[np.ndarray, ...]:
    """The observation fields ``names``, each from ``field(name)`` (stacked over agents, first
    axis: agent), contiguous and in :data:`FIELD_DTYPES`."""
    return tuple(np.ascontiguousarray(field(name), dtype=FIELD_DTYPES[name]) for name in names)


class SlotMemory:
    """Private memory of every module for a rule kernel, one entry per memory slot.

    Subclasses list their per-slot arrays in ``FIELDS``: ``{name: (dtype, empty value)}``;
    each is an attribute of shape ``(S,)``.
    """

    FIELDS: dict = {}

    def __init__(self):
        self.version = 0
        """Counts the times the arrays were replaced (:meth:`clear`, :meth:`reserve`)."""
        self.clear()

    def clear(self) -> None:
        for name, (dtype, _) in self.FIELDS.items():
            setattr(self, name, np.empty(0, dtype=dtype))
        self.version += 1

    def reserve(self, n_slots: int) -> None:
        """Make room for slots ``0 .. n_slots - 1``; new slots start empty."""
        if n_slots <= self.n_slots:
            return
        for name, (dtype, empty) in self.FIELDS.items():
            values = getattr(self, name)
            setattr(self, name, np.concatenate([values, np.full(n_slots - len(values), empty, dtype=dtype)]))
        self.version += 1

    @property
    def n_slots(self) -> int:
        return len(getattr(self, next(iter(self.FIELDS))))

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The ``(S,)`` arrays of ``FIELDS``, in their order (the ``memory`` a rule kernel reads)."""
        return tuple(getattr(self, name) for name in self.FIELDS)


class KernelPolicy(Policy):
    """A policy whose rule is a numba kernel over observation fields stacked over agents.

    A subclass is one behaviour's rule, given by:

    - ``Params``: the rule's parameters, a ``NamedTuple`` whose fields with their defaults are
      the policy's keyword parameters (:class:`~baselines.chain.ChainRuleParams`), with a
      ``check()`` raising ``ValueError`` for a value not allowed and, optionally, ``CHOICES``
      (``{field: the values allowed}``; the kernels read such a field as the index of its value);
      a subclass's ``Params`` comes on top of its base class's (:class:`~baselines.branch.BranchPolicy`);
    - ``Memory``: the :class:`SlotMemory` subclass of the rule's private memory;
    - ``rule``: the rule as a numba kernel (a ``staticmethod``),
      ``rule(seen, slots, memory, rules, rng, actions)``: ``seen`` an :class:`Observed` of A
      agent rows, ``slots`` (A,) int64 the memory slot of each row, ``memory`` the tuple
      :meth:`SlotMemory.arrays` (each (S,)), ``rules`` the policy's :attr:`rule_params`, ``rng`` the
      policy's ``numpy.random.Generator``; writes ``actions`` (A, L) int64 full actions.

    The parameters as given are attributes of the policy (``policy.p_random``).

    The same kernel runs here (:meth:`act`, :meth:`act_arrays`) and inside the compiled
    rollout (:mod:`baselines.compiled`), which is how a new behaviour gets both. Private
    memory is one slot per agent: keyed by agent name in :meth:`act`, by row in
    :meth:`act_arrays`; use one of the two between resets (the other raises ``RuntimeError``).
    """

    levels = CONTROL_LEVELS
    """Every control level: below ``full`` the policy gives the leading fields of its full action
    (its moves at ``move``), and the level's autopilot, another instance of the task's rules with
    its own random draws, chooses the rest."""
    Params: type | None = None
    Memory: type[SlotMemory] | None = None
    memory: SlotMemory
    rule = None
    n_fields: int | None = None
    """How many leading fields of the full action :meth:`act` and :meth:`act_arrays` give (the
    env's control level, set by :meth:`for_env`; ``None``: all)."""

    @classmethod
    def for_env(cls, env, *, seed: int | None = None, **params):
        """Build the policy from an environment's static interface; it acts at the env's control level."""
        policy = super().for_env(env, seed=seed, **params)
        policy.n_fields = len(getattr(env, "control_fields", env.action_layout.field_names))
        return policy

    def __init__(
        self, action_layout: ActionLayout, modes, *, scent_max: int = 65535, seed: int | None = None, **params
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        records = [vars(cls)["Params"] for cls in reversed(type(self).__mro__) if vars(cls).get("Params")]
        unknown = set(params) - {name for record in records for name in record._fields}
        if unknown:
            raise TypeError(f"{type(self).__name__}() got an unexpected keyword argument {min(unknown)!r}")
        given = {"scent_max": scent_max, **params}
        self.params = tuple(record(**{k: v for k, v in given.items() if k in record._fields}) for record in records)
        """The rule's parameters as given, one record per ``Params`` in the class tree, base class first."""
        for values in self.params:
            values.check()
        read = tuple(_as_kernels_read(values) for values in self.params)
        self._rule_params = read[0] if len(read) == 1 else read
        if self.Memory is not None:
            self.memory = self.Memory()
            """Private memory of every module (see ``Memory``)."""
        self._slots: dict = {}
        """Memory slot of each agent name seen by :meth:`act`."""
        self._keyed_by: str | None = None
        self._row_slots = np.zeros(0, dtype=np.int64)
        """The slots of rows ``0 .. A-1`` (kept between calls of :meth:`act_arrays`)."""

    def __getattr__(self, name):
        """A rule parameter as given (``policy.p_random``)."""
        for values in self.__dict__.get("params", ()):
            if name in values._fields:
                return getattr(values, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def rule_params(self):
        """The rule's parameters as ``rule`` reads them: the ``Params`` record with every field of
        its default's type and every choice as its index (a tuple of records, base class first,
        when the class tree has several)."""
        return self._rule_params

    def reset(self, seed=None):
        super().reset(seed)
        self.memory.clear()
        self._slots.clear()
        self._keyed_by = None

    def act(self, observations):
        names = list(observations)
        if not names:
            return {}
        obs = [observations[a] for a in names]
        actions = self._act(self._memory_slots("name", names), lambda f: np.stack([o[f] for o in obs]))
        return {a: actions[i, : self.n_fields] for i, a in enumerate(names)}

    def act_arrays(self, buffers) -> np.ndarray:
        """``(A, F)`` actions for all agents from stacked observations (``F`` fields of the
        control level the policy was built for; ``L``, the full action, by default).

        ``buffers`` is an :class:`~proteo_env.spaces.ObservationBuffers` (what
        ``env.observe_arrays()`` returns): the same per-agent observations as :meth:`act`
        receives, one row per agent, so the result is the same rule; it only skips building
        dicts (use with ``env.step_arrays``). Private memory is keyed by row index here and
        by agent name in :meth:`act`; use one of the two between resets (the other raises
        ``RuntimeError``).
        """
        n = buffers.own_mode.shape[0]
        return self._act(self._memory_slots("row", range(n)), lambda f: getattr(buffers, f))[:, : self.n_fields]

    def _memory_slots(self, keyed_by: str, keys) -> np.ndarray:
        """``(A,)`` memory slot of each key: the row itself (``keyed_by="row"``) or a slot
        given to each agent name at first sight (``"name"``)."""
        if self._keyed_by not in (None, keyed_by):
            raise RuntimeError(
                f"{type(self).__name__}: act() and act_arrays() used between two resets; "
                "allowed: one of them per episode (memory is keyed by agent name in act() "
                "and by row in act_arrays())"
            )
        self._keyed_by = keyed_by
        if keyed_by == "row":
            if len(self._row_slots) != len(keys):
                self._row_slots = np.arange(len(keys), dtype=np.int64)
            slots = self._row_slots
        else:
            slots = np.array([self._slots.setdefault(k, len(self._slots)) for k in keys], dtype=np.int64)
        self.memory.reserve(len(slots) if keyed_by == "row" else len(self._slots))
        return slots

    def memory_rows(self, agents) -> SlotMemory:
        """A copy of the memory with one row per agent of ``agents`` (names, in row order), as
        :meth:`act_arrays` reads it; agents without memory get empty rows."""
        rows = type(self.memory)()
        rows.reserve(len(agents))
        if self._keyed_by == "name":
            slots = np.array([self._slots.get(a, -1) for a in agents], dtype=np.int64)
        else:
            slots = np.arange(len(agents), dtype=np.int64)
        known = (slots >= 0) & (slots < self.memory.n_slots)
        for name in rows.FIELDS:
            getattr(rows, name)[known] = getattr(self.memory, name)[slots[known]]
        return rows

    def runs_on(self, task) -> bool:
        """Whether the rule is written for ``task`` (a task instance): a hand-coded policy runs on
        the task of its name (what the compiled rollout, :mod:`baselines.compiled`, checks)."""
        return self.name == task.name

    @classmethod
    def batch(cls, policies) -> PolicyBatch:
        """The :class:`PolicyBatch` of ``policies`` (one per world, this class and its
        parameters): their actions for every world's rows in one kernel call."""
        return PolicyBatch(policies)

    def _act(self, slots: np.ndarray, field) -> np.ndarray:
        """``(A, L)`` actions of the agents with memory ``slots`` (A,), in row order; ``field(name)``
        gives an observation field stacked over them."""
        actions = np.empty((len(slots), self.action_layout.length), dtype=np.int64)
        seen = Observed(*stacked_fields(field, Observed._fields))
        self.rule(seen, slots, self.memory.arrays(), self.rule_params, self.rng, actions)
        return actions


def _as_kernels_read(values):
    """The parameter record ``values`` as a rule kernel reads it: a field of ``CHOICES`` as the
    index of its value among the values allowed (a ``ValueError`` for another), every other
    converted to its default's type."""
    choices = getattr(values, "CHOICES", {})
    for name, allowed in choices.items():
        if getattr(values, name) not in allowed:
            raise ValueError(
                f"{name}={getattr(values, name)!r} is not allowed; allowed: {', '.join(map(str, allowed))}"
            )
    return type(values)(
        *(
            choices[name].index(value) if name in choices else type(values._field_defaults[name])(value)
            for name, value in zip(values._fields, values, strict=True)
        )
    )


@functools.cache
def worlds_rule(rule):
    """The kernel that runs ``rule`` (a :attr:`KernelPolicy.rule`) once per world:
    ``act_worlds(seen, n_agents, slots, memories, rules, rngs, actions)``, where ``seen`` is an
    :class:`Observed` of ``B * A`` rows (world-major, ``A = n_agents``), ``slots`` (A,) the
    memory slot of each of a world's rows, ``memories``, ``rules`` and ``rngs`` ``B`` memory
    tuples, rule parameters and generators (numba typed lists) and ``actions`` ``(B * A, L)``.
    World ``b`` gets exactly the call its own policy's :meth:`KernelPolicy.act_arrays` would make."""

    @generated_kernel
    def act_worlds(seen, n_agents, slots, memories, rules, rngs, actions):
        for b in range(len(rngs)):
            lo, hi = b * n_agents, (b + 1) * n_agents
            world = Observed(
                neighbour_kind=seen.neighbour_kind[lo:hi],
                neighbour_mode=seen.neighbour_mode[lo:hi],
                neighbour_scent=seen.neighbour_scent[lo:hi],
                own_mode=seen.own_mode[lo:hi],
                own_scent=seen.own_scent[lo:hi],
                messages=seen.messages[lo:hi],
                contact=seen.contact[lo:hi],
                load=seen.load[lo:hi],
                hint=seen.hint[lo:hi],
                action_mask=seen.action_mask[lo:hi],
            )
            rule(world, slots, memories[b], rules[b], rngs[b], actions[lo:hi])

    return act_worlds


@kernel
def _typed_list(first):
    """A numba typed list holding ``first`` (compiled here and cached on disk, unlike
    ``numba.typed.List``'s own constructors, which compile on every run)."""
    items = numba.typed.List()
    items.append(first)
    return items


@kernel
def _put(items, i, item):
    """``items[i] = item``, or append it when ``i == len(items)``."""
    if i == len(items):
        items.append(item)
    else:
        items[i] = item


def _kernel_list(items):
    """``items`` (a non-empty sequence of one numba type) as a numba typed list."""
    items = list(items)
    out = _typed_list(items[0])
    for i, item in enumerate(items[1:], 1):
        _put(out, i, item)
    return out


class PolicyBatch:
    """``B`` kernel policies of one class, one per world, acting on all the worlds' rows in one
    kernel call (:func:`worlds_rule`); each world's policy keeps its own rule parameters (the
    programs of a population, say).

    The policies stay the owners of their state: each keeps its memory (keyed by row, as in
    :meth:`KernelPolicy.act_arrays`) and its generator, and :meth:`KernelPolicy.reset` resets
    one world's policy as before. :meth:`act_arrays` gives exactly what concatenating
    ``policies[b].act_arrays(rows of world b)`` gives, draw for draw, without the per-world
    Python of that loop. :meth:`replace` puts another policy of the class in a world's place.

    Args:
        policies: ``B >= 1`` :class:`KernelPolicy` of one class.
    """

    def __init__(self, policies):
        self.policies = list(policies)
        if not self.policies:
            raise ValueError("policies=[] is not allowed; allowed: one policy per world, at least one")
        first = self.policies[0]
        for p in self.policies:
            self._check(p)
        self.kernel = worlds_rule(first.rule)
        self._rngs = self._memories = self._rules = None
        self._synced: list[tuple] = []
        """Per world: the generator, memory and memory version that the typed lists hold."""

    def __getstate__(self) -> dict:
        """Pickled without the typed lists, which only hold the policies' own generators, memories
        and parameters (not picklable; :meth:`_sync` builds them again at the next call)."""
        return {**self.__dict__, "_rngs": None, "_memories": None, "_rules": None, "_synced": []}

    def _check(self, policy) -> None:
        first = self.policies[0]
        if type(policy) is not type(first):
            raise ValueError(
                f"policy {type(policy).__name__} is not allowed in a batch of {type(first).__name__}; "
                "allowed: policies of one class"
            )

    def replace(self, b: int, policy) -> None:
        """Make ``policy`` (of the batch's class) world ``b``'s policy from the next call on."""
        self._check(policy)
        self.policies[b] = policy
        if self._rules is not None:
            _put(self._rules, b, policy.rule_params)

    def act_arrays(self, buffers) -> np.ndarray:
        """``(B * A, F)`` actions (``F`` as :meth:`KernelPolicy.act_arrays` gives) from ``buffers``,
        an :class:`~proteo_env.spaces.ObservationBuffers` of ``B * A`` rows, world-major (what a
        batched env's ``observe_arrays`` returns)."""
        n_worlds = len(self.policies)
        n_agents = buffers.own_mode.shape[0] // n_worlds
        if n_agents * n_worlds != buffers.own_mode.shape[0]:
            raise ValueError(
                f"{buffers.own_mode.shape[0]} observation rows are not allowed for {n_worlds} worlds; "
                "allowed: a multiple of the number of worlds"
            )
        self._sync(n_agents)
        first = self.policies[0]
        actions = np.empty((n_agents * n_worlds, first.action_layout.length), dtype=np.int64)
        seen = Observed(*stacked_fields(lambda f: getattr(buffers, f), Observed._fields))
        # every world's rows are slots 0 .. A-1 of its own memory: the slots act_arrays keeps
        self.kernel(seen, n_agents, first._row_slots, self._memories, self._rules, self._rngs, actions)
        return actions[:, : first.n_fields]

    def _sync(self, n_agents: int) -> None:
        """Every policy's memory keyed by row with ``n_agents`` slots, and the typed lists holding
        each world's current generator and memory arrays (both are replaced at a reset)."""
        for p in self.policies:
            if p._keyed_by != "row" or len(p._row_slots) != n_agents:
                p._memory_slots("row", range(n_agents))
        if self._rngs is None:
            self._rules = _kernel_list(p.rule_params for p in self.policies)
            self._rngs = _kernel_list(p.rng for p in self.policies)
            self._memories = _kernel_list(p.memory.arrays() for p in self.policies)
            self._synced = [(p.rng, p.memory, p.memory.version) for p in self.policies]
            return
        for b, p in enumerate(self.policies):
            rng, memory, version = self._synced[b]
            if p.rng is not rng or p.memory is not memory or p.memory.version != version:
                _put(self._rngs, b, p.rng)
                _put(self._memories, b, p.memory.arrays())
                self._synced[b] = (p.rng, p.memory, p.memory.version)
