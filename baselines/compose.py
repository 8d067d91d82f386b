"""Behaviours that compose: one behaviour's finite-state machine hands over to the next.

A composed behaviour runs two behaviours' rules (two :class:`~baselines.base.KernelPolicy`
classes, the *stages*) in one robot. Its task's modes are the first stage's modes followed by
the second's, so every module shows by its mode which stage it is in, and each module runs
the rule of its own stage. A module of the first stage moves on to the second when the
*handover*, a numba kernel reading only that module's observation, says so: a local
condition, such as "I am the chain's tail and see no module still looking for the chain".
It then acts under the second stage's rule from that very cycle, in the mode the handover
names, with fresh memory. There is no way back.

Each stage's rule is written for its own behaviour and never sees a mode it does not know:
the composition shows it its own modes in its own numbering, and every mode of the other
stage as the mode of its own that the stage's ``sees`` names (or, unnamed, as one number past
its own modes, "a module of some other behaviour"). Its actions' modes are mapped back.

Example (:mod:`baselines.snake`, the chain then the crawl)::

    SnakePolicy = compose(
        "snake",
        Stage(ChainPolicy, tuple(ChainMode.__members__), sees={"CRAWL": "SEARCH", "HEAD": "SEED", "BODY": "FINAL"}),
        Stage(CrawlPolicy, tuple(CrawlMode.__members__), sees={"SLEEP": "CRAWL", "SEARCH": "CRAWL", "SEED": "HEAD", "FINAL": "BODY"}),
        chain_handover,
    )

The composed rule is a numba kernel like any behaviour's, so ``act``, ``act_arrays`` and the
compiled rollout (:mod:`baselines.compiled`) all run it, with the same draws: the first
stage's rule on its modules (in row order), then the second's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import generated_kernel

from .base import KernelPolicy, Observed, SlotMemory


class Stage(NamedTuple):
    """One behaviour of a composition.

    Attributes:
        policy: the behaviour's rules, a :class:`~baselines.base.KernelPolicy` subclass.
        modes: its mode names in its own numbering (mode ``i`` is ``modes[i]``).
        sees: how its rule reads the other stage's modes: ``{other mode name: own mode name}``;
            a mode left out reads as ``len(modes)`` ("some other behaviour").
    """

    policy: type
    modes: tuple[str, ...]
    sees: dict


class ComposedMemory(SlotMemory):
    """The stages' private memories side by side (fields prefixed with the stage policy's name);
    :meth:`arrays` gives them as one tuple per stage."""

    STAGE_FIELDS: tuple[tuple[str, ...], ...] = ()

    def arrays(self):
        return tuple(tuple(getattr(self, name) for name in names) for names in self.STAGE_FIELDS)


def _view_table(stage: Stage, composed: tuple[str, ...], own_first: int) -> np.ndarray:
    """``(M,)`` int32: the mode each composed mode reads as to ``stage`` (its modes start at ``own_first``)."""
    own = {name: i for i, name in enumerate(stage.modes)}
    table = np.full(len(composed), len(stage.modes), dtype=np.int32)
    for m, name in enumerate(composed):
        if own_first <= m < own_first + len(stage.modes):
            table[m] = m - own_first
        elif name in stage.sees:
            table[m] = own[stage.sees[name]]
    return table


def composed_rule(first_rule, then_rule, handover):
    """The rule kernel of a composition (:attr:`~baselines.base.KernelPolicy.rule`): ``memory`` is
    ``(first's memory, then's memory)``, ``rules`` is ``(first's rule_params, then's,
    first's view table (M,), then's view table (M,), the number of first's modes)``."""

    @generated_kernel
    def rule(seen, slots, memory, rules, rng, actions):
        first_params, then_params, first_view, then_view, n_first = rules
        n = seen.own_mode.shape[0]
        mode = np.empty(n, dtype=np.int32)
        n_then = 0
        for i in range(n):
            mode[i] = seen.own_mode[i, 0]
            if mode[i] < n_first:
                handed = handover(seen, i, first_params)
                if handed >= 0:
                    mode[i] = handed
            if mode[i] >= n_first:
                n_then += 1
        first_rows = np.empty(n - n_then, dtype=np.int64)
        then_rows = np.empty(n_then, dtype=np.int64)
        a, b = 0, 0
        for i in range(n):
            if mode[i] >= n_first:
                then_rows[b] = i
                b += 1
            else:
                first_rows[a] = i
                a += 1
        _run_stage(first_rule, seen, slots, mode, first_rows, first_view, memory[0], first_params, rng, actions, 0)
        _run_stage(then_rule, seen, slots, mode, then_rows, then_view, memory[1], then_params, rng, actions, n_first)

    return rule


@generated_kernel
def _run_stage(stage_rule, seen, slots, mode, rows, view, memory, params, rng, actions, offset):
    """Run ``stage_rule`` on the agent rows ``rows`` (the modules in that stage, own modes ``mode``)
    as the stage sees them (``view``), and write their actions with modes numbered as composed
    (plus ``offset``)."""
    q = rows.shape[0]
    if q == 0:
        return
    own_mode = np.empty((q, 1), dtype=np.int32)
    neighbour_mode = np.empty((q, seen.neighbour_mode.shape[1]), dtype=np.int32)
    for r in range(q):
        i = rows[r]
        own_mode[r, 0] = view[mode[i]]
        for k in range(seen.neighbour_mode.shape[1]):
            m = seen.neighbour_mode[i, k]
            neighbour_mode[r, k] = view[m] if m >= 0 else -1
    stage_seen = Observed(
        neighbour_kind=seen.neighbour_kind[rows],
        neighbour_mode=neighbour_mode,
        neighbour_scent=seen.neighbour_scent[rows],
        own_mode=own_mode,
        own_scent=seen.own_scent[rows],
        messages=seen.messages[rows],
        contact=seen.contact[rows],
        load=seen.load[rows],
        hint=seen.hint[rows],
        action_mask=seen.action_mask[rows],
    )
    stage_actions = np.empty((q, actions.shape[1]), dtype=np.int64)
    stage_rule(stage_seen, slots[rows], memory, params, rng, stage_actions)
    for r in range(q):
        actions[rows[r]] = stage_actions[r]
        actions[rows[r], 1] = stage_actions[r, 1] + offset


def _composed_memory(parts) -> type[ComposedMemory]:
    """The memory class of a composition of the policies ``parts``: their fields, prefixed with
    each policy's name."""
    fields, stage_fields = {}, []
    for part in parts:
        names = []
        for field, spec in part.memory.FIELDS.items():
            fields[f"{part.name}_{field}"] = spec
            names.append(f"{part.name}_{field}")
        stage_fields.append(tuple(names))
    return type("ComposedMemory", (ComposedMemory,), {"FIELDS": fields, "STAGE_FIELDS": tuple(stage_fields)})


def compose(name: str, first: Stage, then: Stage, handover, *, doc: str = "") -> type[KernelPolicy]:
    """A policy class running ``first``'s rules, then ``then``'s (module docstring).

    Args:
        name: the composed policy's name (the composed task's name, for the autopilot, the
            compiled rollout and ``proteo eval`` to find it).
        first, then: the two stages (:class:`Stage`).
        handover: numba kernel ``handover(seen, i, rules) -> int``: the composed mode that the
            module at row ``i`` of ``seen`` (an :class:`~baselines.base.Observed` with modes as
            composed), now in ``first``'s stage, hands over into (one of ``then``'s modes,
            numbered from ``len(first.modes)``), or -1 to stay; ``rules`` is ``first``'s
            ``rule_params`` (its ``scent_max``, say).
        doc: the class docstring.

    The class takes the composed task's modes (``first.modes + then.modes``; anything else is
    a ``ValueError``) and ``first`` and ``then``, dicts of parameters for each stage's policy.
    """

    class Composed(KernelPolicy):
        stages = (first, then)
        rule = staticmethod(composed_rule(first.policy.rule, then.policy.rule, handover))

        def __init__(self, action_layout, modes, *, scent_max=65535, seed=None, first=None, then=None):
            super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
            composed = self.stages[0].modes + self.stages[1].modes
            if self.modes != composed:
                raise ValueError(
                    f"policy {self.name!r} composes {'+'.join(s.policy.name for s in self.stages)} with the "
                    f"modes {composed}; the task's modes are {self.modes}; allowed: a task with those modes"
                )
            self.parts = tuple(
                stage.policy(action_layout, stage.modes, scent_max=scent_max, seed=seed, **(params or {}))
                for stage, params in zip(self.stages, (first, then), strict=True)
            )
            """The stages' policies (their parameters; their generators and memories are not used)."""
            n_first = len(self.stages[0].modes)
            self.views = (_view_table(self.stages[0], composed, 0), _view_table(self.stages[1], composed, n_first))
            self.memory = _composed_memory(self.parts)()

        @property
        def rule_params(self):
            """``(first's rule_params, then's, the two view tables, the number of first's modes)``."""
            return (self.parts[0].rule_params, self.parts[1].rule_params, *self.views, len(self.stages[0].modes))

    Composed.name = name
    Composed.__name__ = Composed.__qualname__ = f"{name.title()}Policy"
    Composed.__doc__ = doc or f"{first.policy.name} then {then.policy.name}, composed ({__name__})."
    return Composed
