"""The agent interface: observation fields, the action encoding, and their gymnasium spaces.

Observation (a ``Dict`` per agent; ``K`` neighbourhood sites, ``C`` scent channels)
------------------------------------------------------------------------------------
=================== ========= ======= ================================================
field               shape     dtype   meaning
=================== ========= ======= ================================================
``neighbour_kind``  (K,)      int8    0 empty, 1 module, 2 solid (ground, obstacle,
                                      outside the box), 3 object
``neighbour_mode``  (K,)      int32   that module's mode, -1 where no module
``neighbour_scent`` (K, C)    int32   that module's scent values, ``scent_max`` if none
``own_mode``        (1,)      int32   this module's mode
``own_scent``       (C,)      int32   this module's scent values
``messages``        (12,)     int32   value received last cycle from each direction
``contact``         (2,)      int8    touching the ground, touching the object
``load``            (1,)      float32 weight carried (table task; 0 elsewhere)
``hint``            (3,)      float32 the task's global hint (rough object direction)
``action_mask``     (13,)     int8    1 where the move is legal now: stay, then the
                                      12 directions of :data:`DIRECTIONS`
=================== ========= ======= ================================================

The first 12 neighbourhood sites are the face neighbours in :data:`DIRECTIONS` order; with
``obs_radius=2`` the 42 sites two hops away follow.

Action (``MultiDiscrete``; use :class:`ActionLayout` to build and read it)
-----------------------------------------------------------------------
``[move, mode, role_0 .. role_{C-1}, message_target, message_value]`` where ``move`` is 0
(stay) or ``k + 1`` (roll towards ``DIRECTIONS[k]``), ``mode`` the new mode, ``role_c`` the
scent role on channel ``c`` (0 silent, 1 relay, 2 emit), ``message_target`` a direction
0..11 or 12 (all neighbours) and ``message_value`` 0 (send nothing) or ``1..V``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from gymnasium import spaces

from .core.cycle import EMIT, KIND_EMPTY, KIND_MODULE, KIND_OBJECT, KIND_SOLID, RELAY, SILENT
from .core.jit import kernel
from .core.records import OBSERVATION_FIELDS
from .core.world import MESSAGE_TO_ALL

__all__ = [
    "EMIT",
    "KIND_EMPTY",
    "KIND_MODULE",
    "KIND_OBJECT",
    "KIND_SOLID",
    "RELAY",
    "SILENT",
    "MESSAGE_TO_ALL",
    "N_MOVES",
    "ActionLayout",
    "ModuleActionSpace",
    "ObservationBuffers",
    "observation_space",
]

N_MOVES = 13


class ModuleActionSpace(spaces.MultiDiscrete):
    """``MultiDiscrete`` action of one module; ``sample(mask)`` also takes the (13,) move mask.

    Passing the observation's ``action_mask`` samples a legal move and uniform other fields,
    which is what PettingZoo's test utilities and random baselines do.
    """

    def sample(self, mask=None, probability=None):
        if isinstance(mask, np.ndarray) and mask.shape == (N_MOVES,):
            mask = (mask.astype(np.int8),) + tuple(np.ones(n, dtype=np.int8) for n in self.nvec[1:])
        return super().sample(mask=mask, probability=probability)


@kernel
def all_below(rows, nvec):
    """Whether every entry of ``rows`` (R, F) integers lies in ``0 .. nvec[f] - 1`` for its column ``f``."""
    for r in range(rows.shape[0]):
        for f in range(rows.shape[1]):
            if rows[r, f] < 0 or rows[r, f] >= nvec[f]:
                return False
    return True


@dataclass(frozen=True)
class ActionLayout:
    """Named positions in the action vector of a task with ``n_modes``, ``n_channels``, ``n_message_values``."""

    n_modes: int
    n_channels: int
    n_message_values: int

    @property
    def length(self) -> int:
        return 4 + self.n_channels

    @cached_property
    def nvec(self) -> np.ndarray:
        """``(length,)`` int64 number of values of each field (read-only; built once, read every step)."""
        nvec = np.array(
            [N_MOVES, self.n_modes] + [3] * self.n_channels + [MESSAGE_TO_ALL + 1, self.n_message_values + 1],
            dtype=np.int64,
        )
        nvec.setflags(write=False)
        return nvec

    @property
    def move(self) -> int:
        return 0

    @property
    def mode(self) -> int:
        return 1

    @property
    def roles(self) -> slice:
        return slice(2, 2 + self.n_channels)

    @property
    def message_target(self) -> int:
        return 2 + self.n_channels

    @property
    def message_value(self) -> int:
        return 3 + self.n_channels

    @property
    def field_names(self) -> list[str]:
        return ["move", "mode"] + [f"role_{c}" for c in range(self.n_channels)] + ["message_target", "message_value"]

    def space(self) -> ModuleActionSpace:
        return ModuleActionSpace(self.nvec)

    def encode(self, *, move=0, mode=0, roles=None, message_target=0, message_value=0) -> np.ndarray:
        """One action vector from named parts (``roles``: sequence of C roles, default relay)."""
        action = np.empty(self.length, dtype=np.int64)
        action[self.move] = move
        action[self.mode] = mode
        action[self.roles] = 1 if roles is None else roles
        action[self.message_target] = message_target
        action[self.message_value] = message_value
        return action

    def check(self, actions: np.ndarray, agents) -> None:
        """Raise ``ValueError`` naming the agent, field, value and range for a bad ``(A, L)`` batch."""
        if actions.ndim != 2 or actions.shape[1] != self.length:
            raise ValueError(
                f"action shape {actions.shape[1:]} is not allowed; allowed: ({self.length},) = {self.field_names}"
            )
        if not all_below(actions, self.nvec):
            a, f = np.argwhere((actions < 0) | (actions >= self.nvec))[0]
            raise ValueError(
                f"action of {agents[a]}: {self.field_names[f]}={actions[a, f]} is not allowed; "
                f"allowed: 0..{self.nvec[f] - 1}"
            )


class ObservationBuffers:
    """Per-agent observation arrays for ``A`` agents; field ``f`` of agent ``i`` is ``getattr(self, f)[i]``."""

    FIELDS = OBSERVATION_FIELDS

    def __init__(self, n_agents: int, n_sites: int, n_channels: int):
        a = n_agents
        self.neighbour_kind = np.zeros((a, n_sites), dtype=np.int8)
        self.neighbour_mode = np.zeros((a, n_sites), dtype=np.int32)
        self.neighbour_scent = np.zeros((a, n_sites, n_channels), dtype=np.int32)
        self.own_mode = np.zeros((a, 1), dtype=np.int32)
        self.own_scent = np.zeros((a, n_channels), dtype=np.int32)
        self.messages = np.zeros((a, 12), dtype=np.int32)
        self.contact = np.zeros((a, 2), dtype=np.int8)
        self.load = np.zeros((a, 1), dtype=np.float32)
        self.hint = np.zeros((a, 3), dtype=np.float32)
        self.action_mask = np.zeros((a, N_MOVES), dtype=np.int8)

    def rows(self, start: int, stop: int) -> ObservationBuffers:
        """The agents ``start .. stop - 1`` as buffers of their own (views, not copies)."""
        view = object.__new__(ObservationBuffers)
        for f in self.FIELDS:
            setattr(view, f, getattr(self, f)[start:stop])
        return view

    def copy(self) -> ObservationBuffers:
        """Buffers of their own with the same values."""
        twin = object.__new__(ObservationBuffers)
        for f in self.FIELDS:
            setattr(twin, f, getattr(self, f).copy())
        return twin

    def agent(self, i: int) -> dict[str, np.ndarray]:
        """The observation dict of agent ``i`` (views into the buffers)."""
        return {f: getattr(self, f)[i] for f in self.FIELDS}

    def per_agent(self, names) -> dict[str, dict[str, np.ndarray]]:
        """``{names[i]: observation dict of agent i}`` for every row (views into the buffers).

        The same as calling :meth:`agent` per row; iterating the arrays builds the row views
        in C, which is what bounds the PettingZoo API (10 views per agent).
        """
        columns = [getattr(self, f) for f in self.FIELDS]
        return {name: dict(zip(self.FIELDS, row)) for name, row in zip(names, zip(*columns))}


def observation_space(
    *, n_sites: int, n_channels: int, n_modes: int, n_message_values: int, scent_max: int
) -> spaces.Dict:
    """The ``Dict`` space of one agent's observation (see the module docstring)."""

    def box(low, high, shape, dtype):
        return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)

    return spaces.Dict(
        {
            "neighbour_kind": box(0, 3, (n_sites,), np.int8),
            "neighbour_mode": box(-1, n_modes - 1, (n_sites,), np.int32),
            "neighbour_scent": box(0, scent_max, (n_sites, n_channels), np.int32),
            "own_mode": box(0, n_modes - 1, (1,), np.int32),
            "own_scent": box(0, scent_max, (n_channels,), np.int32),
            "messages": box(0, n_message_values, (12,), np.int32),
            "contact": box(0, 1, (2,), np.int8),
            "load": box(0.0, np.inf, (1,), np.float32),
            "hint": box(-1.0, 1.0, (3,), np.float32),
            "action_mask": box(0, 1, (N_MOVES,), np.int8),
        }
    )
