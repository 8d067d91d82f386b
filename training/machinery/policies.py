"""Learned and evolved controllers behind the same :class:`~baselines.base.Policy` interface.

Every neural controller here, whether trained by SB3, by TorchRL or evolved by CMA-ES, is
one network shared by all modules that maps a module's flattened observation
(:class:`~proteo_env.adapters.flatten.ObservationEncoder`) to one logit vector per action field
(``move``, ``mode``, ``role_c``, ``message_target``, ``message_value``, concatenated). A
:class:`LogitsPolicy` turns logits into actions the same way for all of them: illegal moves
(``action_mask`` 0) get probability zero, and each field is sampled from its softmax with the
policy's own NumPy generator (``reset(seed)`` makes an episode reproducible) or, with
``deterministic=True``, its arg-max is taken.

Networks (``hidden`` sizes, tanh activations):

- :func:`torch_mlp` builds the TorchRL actor (``torch.nn.Sequential``);
- :class:`NumpyMLP` is the CMA-ES controller, whose weights are one flat parameter vector.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from baselines.base import Policy
from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from proteo_env.spaces import N_MOVES

MEMORIES = ("none", "last_move", "last_action")
"""What a network remembers between cycles, as extra inputs after the observation's features:
``none``; ``last_move``, the one-hot move the module chose in the previous cycle (13 inputs);
``last_action``, the one-hot of every field it chose in the previous cycle (``sum(nvec)``
inputs; the same as ``last_move`` at control level ``move``). All zero-index (stay, and the
first value of every other field) at an episode's start. The hand-coded rules keep such private memory (their heading, a seed's growth
direction that it broadcasts every cycle, whether they asked to move, how long a seed has
waited for a hand-over); the observation does not carry it."""


def check_memory(memory, nvec=(N_MOVES,)) -> int:
    """The number of extra inputs of ``memory`` for action fields ``nvec``; a ``ConfigError``
    naming the allowed memories."""
    if memory not in MEMORIES:
        raise ConfigError(f"memory={memory!r} is not allowed; allowed: {', '.join(map(repr, MEMORIES))}")
    return {"none": 0, "last_move": N_MOVES, "last_action": int(np.sum(nvec))}[memory]


def with_memory(features: np.ndarray, previous: np.ndarray, memory: str, nvec=(N_MOVES,)) -> np.ndarray:
    """``(N, D + extra)``: ``features (N, D)`` followed by the memory inputs of each row, from
    each row's previous action ``(N, F)`` (or its previous move ``(N,)``) over fields ``nvec``."""
    if memory == "none":
        return features
    previous = np.asarray(previous).reshape(len(features), -1)
    sizes = [N_MOVES] if memory == "last_move" else [int(n) for n in nvec]
    extra = np.zeros((len(features), sum(sizes)), dtype=np.float32)
    rows, start = np.arange(len(features)), 0
    for k, size in enumerate(sizes):
        extra[rows, start + previous[:, k]] = 1.0
        start += size
    return np.concatenate([features, extra], axis=1)


SAMPLED = ("all", "move")
"""Which fields a :class:`LogitsPolicy` samples (the others take their arg-max): ``all``, or
``move`` only. A clone of the rules (:mod:`training.trainers.imitate`) at ``move+mode`` or ``full``
samples its moves, as the rules' random moves do, and takes the arg-max of the mode, scent
roles and messages, which the rules choose deterministically: one sampled slip in a seed's
mode or its broadcast breaks the structure (docs/journal/learning-memory-full-action.md)."""


def check_sampled(sampled) -> str:
    """``sampled`` when it is one of :data:`SAMPLED`; otherwise a ``ConfigError`` naming them."""
    if sampled not in SAMPLED:
        raise ConfigError(f"sampled={sampled!r} is not allowed; allowed: {', '.join(map(repr, SAMPLED))}")
    return sampled


def sample_actions(
    logits: np.ndarray,
    nvec: np.ndarray,
    move_mask: np.ndarray,
    rng: np.random.Generator,
    *,
    deterministic: bool = False,
    sampled: str = "all",
    noise: np.ndarray | None = None,
) -> np.ndarray:
    """``(B, len(nvec))`` actions from concatenated logits ``(B, sum(nvec))``; moves limited to
    ``move_mask``. ``sampled="move"``: fields after the move take their arg-max (the generator
    is drawn from the same either way). ``noise``: the Gumbel draws ``(B, sum(nvec))`` when the
    caller drew them already (several generators' rows at once); ``rng`` is then not read."""
    logits = np.array(logits, dtype=np.float64, copy=True)
    logits[:, :N_MOVES] = np.where(np.asarray(move_mask, dtype=bool), logits[:, :N_MOVES], -np.inf)
    if not deterministic:
        if noise is None:
            noise = rng.gumbel(size=logits.shape)  # Gumbel-max: a sample from each softmax
        else:
            noise = np.array(noise, dtype=np.float64, copy=True)
        if sampled == "move":
            noise[:, N_MOVES:] = 0.0
        logits = logits + noise
    out = np.empty((logits.shape[0], len(nvec)), dtype=np.int64)
    start = 0
    for k, n in enumerate(nvec):
        out[:, k] = logits[:, start : start + n].argmax(axis=1)
        start += n
    return out


class LogitsPolicy(Policy):
    """A shared controller given by ``logits_fn(features (B, D)) -> logits (B, sum(nvec))``.

    Args:
        action_layout, modes, scent_max, seed: as for every :class:`~baselines.base.Policy`.
        encoder: the observation encoding the network was trained on.
        logits_fn: the network.
        label: the name shown in tables (``"sb3-ppo"``, ``"cma-neural"``, ...).
        deterministic: take each field's arg-max instead of sampling.
        sampled: which fields are sampled when not ``deterministic`` (:data:`SAMPLED`).
        nvec: values of each field the network chooses (default: every field of ``action_layout``);
            at control level ``move`` only ``[13]``, and an action is then the move alone.
        memory: what the network remembers (:data:`MEMORIES`); with memory the policy keeps
            each agent's previous action (by name in :meth:`act`, by row in :meth:`act_arrays`),
            cleared by :meth:`reset`.
    """

    name = "learned"

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max: int = 65535,
        seed: int | None = None,
        encoder: ObservationEncoder,
        logits_fn: Callable[[np.ndarray], np.ndarray],
        label: str = "learned",
        deterministic: bool = False,
        nvec=None,
        memory: str = "none",
        sampled: str = "all",
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        self.nvec = np.asarray(action_layout.nvec if nvec is None else nvec, dtype=np.int64)
        self.levels = (self.level_of(action_layout, self.nvec),)
        self.encoder = encoder
        self.logits_fn = logits_fn
        self.name = label
        self.deterministic = deterministic
        self.sampled = check_sampled(sampled)
        check_memory(memory)
        self.memory = memory
        self.previous: dict = {}
        """Each agent's (name or row) previous action ``(F,)``, with memory."""

    @classmethod
    def over(cls, env, logits_fn, encoder: ObservationEncoder, *, seed: int | None, **options) -> LogitsPolicy:
        """A network ``logits_fn`` over ``encoder``'s features acting in ``env`` (from its static
        interface; ``options``: ``label``, ``deterministic``, ``nvec``, ``memory``, ``sampled``)."""
        return cls(
            env.action_layout,
            env.task.modes,
            scent_max=env.config.physics.scent_max,
            seed=seed,
            encoder=encoder,
            logits_fn=logits_fn,
            **options,
        )

    def reset(self, seed=None):
        super().reset(seed)
        self.previous = {}

    def forget(self, keys) -> None:
        """Start the agents ``keys`` (names or rows) afresh: no previous action (a world's new
        episode when one policy acts for several worlds by row)."""
        for key in keys:
            self.previous.pop(key, None)

    def act(self, observations):
        if not observations:
            return {}
        features = self.encoder.encode_observations(observations)
        mask = np.stack([o["action_mask"] for o in observations.values()])
        return dict(zip(observations, self._act(list(observations), features, mask)))

    def act_arrays(self, features: np.ndarray, move_mask: np.ndarray) -> np.ndarray:
        """Actions of a batch given encoded features and move masks (the array API's path; with
        memory, row ``i`` is the same agent from call to call until :meth:`reset`)."""
        return self._act(range(len(features)), features, move_mask)

    def _act(self, keys, features: np.ndarray, move_mask: np.ndarray) -> np.ndarray:
        if self.memory != "none":
            start = np.zeros(len(self.nvec), dtype=np.int64)
            previous = np.array([self.previous.get(k, start) for k in keys], dtype=np.int64).reshape(-1, len(start))
            features = with_memory(features, previous, self.memory, self.nvec)
        logits = self.logits_fn(features)
        actions = sample_actions(
            logits, self.nvec, move_mask, self.rng, deterministic=self.deterministic, sampled=self.sampled
        )
        if self.memory != "none":
            self.previous.update(zip(keys, actions))
        return actions

    @staticmethod
    def level_of(action_layout, nvec) -> str:
        """The control level whose action fields ``nvec`` are (a prefix of ``action_layout.nvec``)."""
        return {1: "move", 2: "move+mode"}.get(len(nvec), "full")


# ---------------------------------------------------------------------- networks
class NumpyMLP:
    """A tanh MLP in NumPy whose weights are one flat vector (the CMA-ES genome).

    Layers ``in_dim -> hidden[0] -> ... -> out_dim``; the genome is every layer's weight
    matrix (row-major, ``(fan_in, fan_out)``) followed by its bias, layer by layer.
    """

    def __init__(self, in_dim: int, out_dim: int, hidden: tuple[int, ...] = (16,)):
        self.sizes = (in_dim, *hidden, out_dim)
        self.params: list[tuple[np.ndarray, np.ndarray]] = [
            (np.zeros((a, b), dtype=np.float32), np.zeros(b, dtype=np.float32))
            for a, b in zip(self.sizes[:-1], self.sizes[1:])
        ]

    @property
    def n_params(self) -> int:
        return sum(w.size + b.size for w, b in self.params)

    def set_flat(self, genome: np.ndarray) -> NumpyMLP:
        genome = np.asarray(genome, dtype=np.float32)
        if genome.shape != (self.n_params,):
            raise ValueError(
                f"genome of shape {genome.shape} is not allowed; allowed: ({self.n_params},) "
                f"for layer sizes {self.sizes}"
            )
        start = 0
        for w, b in self.params:
            w[...] = genome[start : start + w.size].reshape(w.shape)
            start += w.size
            b[...] = genome[start : start + b.size]
            start += b.size
        return self

    def init_genome(self, rng: np.random.Generator) -> np.ndarray:
        """A start genome: scaled normal weights (``1/sqrt(fan_in)``), zero biases, small output layer."""
        parts = []
        for i, (w, b) in enumerate(self.params):
            scale = 1.0 / np.sqrt(w.shape[0]) * (0.1 if i == len(self.params) - 1 else 1.0)
            parts += [rng.normal(0.0, scale, w.size), np.zeros(b.size)]
        return np.concatenate(parts).astype(np.float32)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        h = np.asarray(x, dtype=np.float32)
        for i, (w, b) in enumerate(self.params):
            h = h @ w + b
            if i < len(self.params) - 1:
                h = np.tanh(h)
        return h


def torch_mlp(in_dim: int, out_dim: int, hidden: tuple[int, ...] = (64, 64), *, out_gain: float = 0.01):
    """A tanh MLP in torch (the TorchRL actor and critic); orthogonal init, small output layer."""
    import torch
    from torch import nn

    layers, last = [], in_dim
    for h in hidden:
        lin = nn.Linear(last, h)
        nn.init.orthogonal_(lin.weight, gain=np.sqrt(2))
        nn.init.zeros_(lin.bias)
        layers += [lin, nn.Tanh()]
        last = h
    out = nn.Linear(last, out_dim)
    nn.init.orthogonal_(out.weight, gain=out_gain)
    nn.init.zeros_(out.bias)
    layers.append(out)
    del torch
    return nn.Sequential(*layers)
