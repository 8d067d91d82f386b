"""The ``Dict`` observation of one module as one float vector, block by named block.

Learning libraries want a flat ``float32`` vector; this module builds it from the named
observation fields of :mod:`proteo_env.spaces` (never from offsets into another vector) and
names every block of the result, so a feature can be found again by name:
``encoder.slices["neighbour_scent_delta"]``.

Blocks, in order (``K`` sites, ``C`` channels, ``M`` modes, ``V`` message values):

========================== ========= ========================================================
block                      size      value
========================== ========= ========================================================
``neighbour_kind``         K * 4     one-hot of empty / module / solid / object, per site
``neighbour_mode``         K * (M+1) one-hot of "no module" then mode ``0..M-1``, per site
``neighbour_scent_present`` K * C    1 where that module carries scent (value < ``scent_max``)
``neighbour_scent_value``  K * C     ``min(scent, scent_scale) / scent_scale``; 1 where none
``neighbour_scent_delta``  K * C     ``clip(neighbour - own, -2, 2) / 2`` where both carry
                                     scent, else 0 (the local gradient the rules climb)
``own_mode``               M         one-hot
``own_scent_present``      C         1 where this module carries scent
``own_scent_value``        C         ``min(scent, scent_scale) / scent_scale``; 1 where none
``messages``               12*(V+1)  one-hot of the value received from each direction
                                     (``message_encoding="per_direction"``, the default);
                                     with ``"compact"`` two blocks instead:
``message_from``           12        1 where a message arrived from that direction
``message_value``          V         1 where value ``1..V`` arrived from some direction
``contact``                2         touching the ground, touching the object
``load``                   1         ``log1p(load)``
``hint``                   3         the task's global hint
``action_mask``            13        the legal moves (stay, then the 12 directions)
========================== ========= ========================================================

The compact message encoding (``12 + V`` features instead of ``12 * (V + 1)``, 27 against
192 for the paper's tasks) loses only which direction sent which value when two messages
arrive in one cycle; learners that feed the features to a dense first layer spend most of
their arithmetic there, so it roughly halves it.

Sites and channels are site-major: block ``neighbour_scent_delta`` holds site 0's channels,
then site 1's, and so on. The encoder's :meth:`ObservationEncoder.spec` is stored with
every checkpoint, so a policy is only ever fed the encoding it was trained on.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import cached_property

import numpy as np

from ..core.jit import kernel
from ..core.records import OBSERVATION_FIELDS
from ..spaces import N_MOVES

SCENT_SCALE = 16
"""Scent values at or above this read as "far" (1.0) in the ``*_scent_value`` blocks."""
ENCODING_VERSION = 1
"""The version of the blocks above: their order, sizes and values. A change to any of them is a new
version, so that a network is never fed an encoding it was not trained on (it is in
:meth:`ObservationEncoder.spec`, which every checkpoint and entrant records)."""


@dataclass(frozen=True)
class ObservationEncoder:
    """Turns observation fields into ``(B, size)`` float32 features (blocks in the module docstring).

    Args:
        n_sites: neighbourhood sites ``K`` (12, or 54 with ``obs_radius=2``).
        n_channels: scent channels ``C``.
        n_modes: modes ``M`` of the task.
        n_message_values: largest message value ``V``.
        scent_max: the scent value meaning "no scent".
        scent_scale: see :data:`SCENT_SCALE`.
        message_encoding: one of :data:`MESSAGE_ENCODINGS` (see the module docstring).
    """

    n_sites: int
    n_channels: int
    n_modes: int
    n_message_values: int
    scent_max: int
    scent_scale: int = SCENT_SCALE
    message_encoding: str = "per_direction"

    def __post_init__(self):
        for name in ("n_sites", "n_channels", "n_modes", "n_message_values", "scent_max", "scent_scale"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")
        if self.message_encoding not in MESSAGE_ENCODINGS:
            raise ValueError(
                f"message_encoding={self.message_encoding!r} is not allowed; allowed: "
                f"{', '.join(map(repr, MESSAGE_ENCODINGS))}"
            )

    @classmethod
    def for_env(
        cls, env, *, scent_scale: int = SCENT_SCALE, message_encoding: str = "per_direction"
    ) -> ObservationEncoder:
        """The encoder of a :class:`~proteo_env.env.ProteoEnv` (from its static interface only)."""
        space = env.observation_space(env.possible_agents[0])
        return cls(
            n_sites=space["neighbour_kind"].shape[0],
            n_channels=env.task.n_channels,
            n_modes=len(env.task.modes),
            n_message_values=env.task.n_message_values,
            scent_max=env.config.physics.scent_max,
            scent_scale=scent_scale,
            message_encoding=message_encoding,
        )

    # ------------------------------------------------------------------ layout
    @property
    def blocks(self) -> tuple[tuple[str, int], ...]:
        """``(name, size)`` of every block, in order."""
        k, c, m = self.n_sites, self.n_channels, self.n_modes
        return (
            (
                ("neighbour_kind", k * 4),
                ("neighbour_mode", k * (m + 1)),
                ("neighbour_scent_present", k * c),
                ("neighbour_scent_value", k * c),
                ("neighbour_scent_delta", k * c),
                ("own_mode", m),
                ("own_scent_present", c),
                ("own_scent_value", c),
            )
            + self.message_blocks
            + (("contact", 2), ("load", 1), ("hint", 3), ("action_mask", N_MOVES))
        )

    @property
    def message_blocks(self) -> tuple[tuple[str, int], ...]:
        """``(name, size)`` of the message blocks of :attr:`message_encoding`."""
        v = self.n_message_values
        if self.message_encoding == "compact":
            return (("message_from", 12), ("message_value", v))
        return (("messages", 12 * (v + 1)),)

    @property
    def slices(self) -> dict[str, slice]:
        """Block name to its slice of the feature vector."""
        out, start = {}, 0
        for name, size in self.blocks:
            out[name] = slice(start, start + size)
            start += size
        return out

    @property
    def size(self) -> int:
        """Length of the feature vector."""
        return sum(size for _, size in self.blocks)

    @cached_property
    def block_starts(self) -> np.ndarray:
        """``(blocks,)`` int64: where each block of :attr:`blocks` begins, in order."""
        return np.array([part.start for part in self.slices.values()], dtype=np.int64)

    def spec(self) -> dict:
        """Plain-dict description (stored in checkpoints and compared on load): the fields, the
        feature vector's ``size`` and the encoding's ``version`` (:data:`ENCODING_VERSION`)."""
        return {**asdict(self), "size": self.size, "version": ENCODING_VERSION}

    # ------------------------------------------------------------------ encoding
    def encode_buffers(self, buffers) -> np.ndarray:
        """Features of every agent from :class:`~proteo_env.spaces.ObservationBuffers`: ``(A, size)``."""
        return self.encode_fields({name: getattr(buffers, name) for name in OBSERVATION_FIELDS})

    def encode_observations(self, observations: Mapping[str, Mapping[str, np.ndarray]]) -> np.ndarray:
        """Features from the per-agent dict that ``env.reset``/``env.step`` return: ``(len, size)``, in dict order."""
        obs = list(observations.values())
        return self.encode_fields({name: np.stack([o[name] for o in obs]) for name in OBSERVATION_FIELDS})

    def encode_fields(self, fields: Mapping[str, np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
        """Features from observation fields that carry a leading batch axis ``B``: ``(B, size)``,
        written into ``out`` ``(B, size)`` float32 when it is given (and returned)."""
        kind = np.asarray(fields["neighbour_kind"])
        b, k = kind.shape
        if k != self.n_sites:
            raise ValueError(f"observation has {k} neighbour sites; this encoder expects {self.n_sites}")
        if out is None:
            out = np.empty((b, self.size), dtype=np.float32)
        c = self.n_channels
        starts = self.block_starts
        encode_rows(
            kind,
            np.asarray(fields["neighbour_mode"]),
            np.asarray(fields["neighbour_scent"]).reshape(b, k, c),
            np.asarray(fields["own_mode"]).reshape(b),
            np.asarray(fields["own_scent"]).reshape(b, c),
            np.asarray(fields["messages"]),
            np.asarray(fields["contact"]).reshape(b, 2),
            np.asarray(fields["hint"]).reshape(b, 3),
            np.asarray(fields["action_mask"]).reshape(b, N_MOVES),
            self.n_modes,
            self.n_message_values,
            self.scent_max,
            self.scent_scale,
            self.message_encoding == "compact",
            starts,
            out,
        )
        load = starts[-3]  # the blocks end with contact, load, hint, action_mask
        out[:, load : load + 1] = np.log1p(np.maximum(np.asarray(fields["load"]).reshape(b, 1), 0.0))
        return out


@kernel
def encode_rows(
    kind,
    mode,
    scent,
    own_mode,
    own_scent,
    messages,
    contact,
    hint,
    action_mask,
    n_modes,
    v,
    scent_max,
    scale,
    compact,
    starts,
    out,
):
    """Every block of :class:`ObservationEncoder` but ``load`` into ``out`` ``(B, size)``, row by row.

    The fields as :meth:`ObservationEncoder.encode_fields` receives them (``scent`` ``(B, K, C)``,
    ``own_mode`` ``(B,)``, ``own_scent`` ``(B, C)``); ``starts`` holds where each block of
    :attr:`ObservationEncoder.blocks` begins, in order. Values are computed in double precision
    and rounded once to float32.
    """
    b, k = kind.shape
    c = own_scent.shape[1]
    at_kind, at_mode, at_present, at_value, at_delta, at_own_mode, at_own_present, at_own_value = starts[:8]
    at_messages = starts[8]
    at_contact, at_hint, at_mask = starts[-4], starts[-2], starts[-1]
    for r in range(b):
        row = out[r]
        row[:] = 0.0
        for s in range(k):
            row[at_kind + 4 * s + min(max(kind[r, s], 0), 3)] = 1.0
            row[at_mode + (n_modes + 1) * s + min(max(mode[r, s] + 1, 0), n_modes)] = 1.0
            for ch in range(c):
                value, own = np.int64(scent[r, s, ch]), np.int64(own_scent[r, ch])
                i = s * c + ch
                present = value < scent_max
                row[at_present + i] = present
                row[at_value + i] = min(value, scale) / scale
                if present and own < scent_max:
                    row[at_delta + i] = min(max(value - own, -2), 2) / 2.0
        row[at_own_mode + min(max(own_mode[r], 0), n_modes - 1)] = 1.0
        for ch in range(c):
            own = np.int64(own_scent[r, ch])
            row[at_own_present + ch] = own < scent_max
            row[at_own_value + ch] = min(own, scale) / scale
        for d in range(12):
            message = min(max(messages[r, d], 0), v)
            if compact:  # message_from (12), then message_value (V): value u at u - 1
                if message > 0:
                    row[at_messages + d] = 1.0
                    row[at_messages + 12 + message - 1] = 1.0
            else:
                row[at_messages + d * (v + 1) + message] = 1.0
        for i in range(2):
            row[at_contact + i] = contact[r, i]
        for i in range(3):
            row[at_hint + i] = hint[r, i]
        for i in range(action_mask.shape[1]):
            row[at_mask + i] = action_mask[r, i]


MESSAGE_ENCODINGS = ("per_direction", "compact")
"""How :class:`ObservationEncoder` encodes the messages received (module docstring)."""


def flat_action_mask(move_mask: np.ndarray, nvec: np.ndarray) -> np.ndarray:
    """Mask over the concatenated choices of a ``MultiDiscrete`` action: ``(B, sum(nvec))`` bool.

    The first ``nvec[0] = 13`` columns are the observation's move mask; every other action
    field (mode, scent roles, message) is always allowed. This is the layout sb3-contrib's
    ``MaskablePPO`` expects for ``MultiDiscrete`` spaces.
    """
    move_mask = np.asarray(move_mask, dtype=bool)
    b = move_mask.shape[0]
    out = np.ones((b, int(np.sum(nvec))), dtype=bool)
    out[:, :N_MOVES] = move_mask
    return out
