"""The networks of :mod:`training.ppo` and :mod:`training.imitate` (``arch``: ``mlp``,
``shared`` or ``lattice``; see :mod:`training.ppo`'s docstring). Checkpoints of both scripts
hold an :class:`ActorCritic`'s weights, and :mod:`training.checkpoints` rebuilds it from here."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from training.policies import check_memory

ARCHS = ("mlp", "lattice", "shared")


def hidden_layers(in_dim: int, hidden: tuple[int, ...]) -> list[nn.Module]:
    """Tanh layers of sizes ``hidden`` from ``in_dim`` inputs, orthogonally initialised."""
    layers, last = [], in_dim
    for h in hidden:
        layers += [_orthogonal(nn.Linear(last, h), np.sqrt(2)), nn.Tanh()]
        last = h
    return layers


def mlp(in_dim: int, out_dim: int, hidden: tuple[int, ...], *, out_gain: float) -> nn.Sequential:
    """A tanh MLP with orthogonal initialisation; ``out_gain`` scales the last layer."""
    last = hidden[-1] if hidden else in_dim
    return nn.Sequential(*hidden_layers(in_dim, hidden), _orthogonal(nn.Linear(last, out_dim), out_gain))


def _orthogonal(layer: nn.Linear, gain: float) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, gain=gain)
    nn.init.zeros_(layer.bias)
    return layer


class LatticeActor(nn.Module):
    """Logits ``(N, sum(nvec))`` from flat features ``(N, D)`` through one encoder shared by the 12 directions.

    Args:
        encoder: the observation encoding (its named blocks are cut out of the features).
        nvec: values of each controlled field (``nvec[0] = 13``, the move).
        hidden: ``(embedding, head)`` sizes.
    """

    SITE_BLOCKS = (
        "neighbour_kind",
        "neighbour_mode",
        "neighbour_scent_present",
        "neighbour_scent_value",
        "neighbour_scent_delta",
    )
    OWN_BLOCKS = ("own_mode", "own_scent_present", "own_scent_value", "contact", "load", "hint")

    def __init__(self, encoder: ObservationEncoder, nvec, hidden: tuple[int, ...] = (32, 64)):
        super().__init__()
        if encoder.n_sites != 12:
            raise ConfigError(
                f"arch='lattice' needs the 12 face neighbours (obs_radius=1); the observation has "
                f"{encoder.n_sites} sites; allowed: obs_radius=1, or arch='mlp'"
            )
        embed, head = (tuple(hidden) + (32, 64))[:2]
        self.nvec = [int(n) for n in nvec]
        slices = encoder.slices
        mask = slices["action_mask"]
        compact = encoder.message_encoding == "compact"
        site_blocks = self.SITE_BLOCKS + (("message_from",) if compact else ("messages",))
        own_blocks = self.OWN_BLOCKS + (("message_value",) if compact else ())
        # token k: every site block's columns of site k (blocks are site-major), then "move k+1 is legal"
        columns = []
        for k in range(12):
            for name in site_blocks:
                s = slices[name]
                width = (s.stop - s.start) // 12
                columns += range(s.start + k * width, s.start + (k + 1) * width)
            columns.append(mask.start + 1 + k)
        self.register_buffer("token_columns", torch.tensor(columns))
        own = [c for name in own_blocks for c in range(slices[name].start, slices[name].stop)] + [mask.start]
        self.register_buffer("own_columns", torch.tensor(own))
        self.token_dim = len(columns) // 12
        self.embed = _orthogonal(nn.Linear(self.token_dim, embed), np.sqrt(2))
        self.direction = nn.Parameter(torch.zeros(12, embed))
        """A learned embedding of each direction, added to its token's."""
        self.context = _orthogonal(nn.Linear(2 * embed + len(own), head), np.sqrt(2))
        self.move_token = _orthogonal(nn.Linear(embed, head), np.sqrt(2))
        self.move_context = _orthogonal(nn.Linear(head, head), np.sqrt(2))
        self.move_out = _orthogonal(nn.Linear(head, 1), 0.01)
        self.stay_head = _orthogonal(nn.Linear(head, 1), 0.01)
        self.other_heads = _orthogonal(nn.Linear(head, sum(self.nvec[1:])), 0.01) if len(self.nvec) > 1 else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n = x.shape[0]
        tokens = x.index_select(1, self.token_columns).reshape(n, 12, self.token_dim)
        emb = torch.tanh(self.embed(tokens) + self.direction)  # (n, 12, embed)
        pooled = torch.cat([emb.mean(dim=1), emb.amax(dim=1), x.index_select(1, self.own_columns)], dim=1)
        ctx = torch.tanh(self.context(pooled))  # (n, head)
        moves = self.move_out(torch.tanh(self.move_token(emb) + self.move_context(ctx)[:, None, :]))[..., 0]
        parts = [self.stay_head(ctx), moves]
        if self.other_heads is not None:
            parts.append(self.other_heads(ctx))
        return torch.cat(parts, dim=1)


class ActorCritic(nn.Module):
    """The shared policy: logits ``(N, sum(nvec))`` and value ``(N,)`` from flat features
    ``x (N, D)``; ``net(x)`` gives both (one pass through the trunk at ``arch="shared"``). With
    ``memory`` (:data:`training.policies.MEMORIES`) ``D`` is the encoder's size plus the memory's
    inputs (:func:`training.policies.with_memory`).

    Recurrent (``recurrent = R > 0``, ``arch="shared"`` only): a GRU cell reads the trunk's
    output and carries each module's state ``(N, R)`` from cycle to cycle (zeros at an episode's
    start, :meth:`initial_state`); the logits and the value are the feed-forward heads' plus
    linear heads on the new state. Those memory heads start at zero, so a recurrent network
    whose other weights come from a feed-forward checkpoint (``training/ppo.py --init``) acts
    exactly as that checkpoint until training teaches it to use its state.

    ``net(x, state)`` returns ``(logits, value, next_state)`` (``next_state`` is ``None`` for a
    feed-forward network); :meth:`unroll` runs a sequence, resetting the state where episodes end.
    """

    def __init__(
        self,
        encoder: ObservationEncoder,
        nvec,
        arch: str = "mlp",
        hidden: tuple[int, ...] = (64, 64),
        memory: str = "none",
        recurrent: int = 0,
    ):
        super().__init__()
        if arch not in ARCHS:
            raise ConfigError(f"arch={arch!r} is not allowed; allowed: {', '.join(ARCHS)}")
        if memory != "none" and arch == "lattice":
            raise ConfigError(
                f"memory={memory!r} is not allowed with arch='lattice'; allowed: memory='none', "
                "or arch='mlp' or 'shared'"
            )
        if isinstance(recurrent, bool) or not isinstance(recurrent, int) or recurrent < 0:
            raise ConfigError(
                f"recurrent={recurrent!r} is not allowed; allowed: 0 (feed-forward) or the GRU's "
                "state size, an integer >= 1"
            )
        if recurrent and arch != "shared":
            raise ConfigError(
                f"recurrent={recurrent!r} is not allowed with arch={arch!r}; allowed: recurrent=0, or arch='shared'"
            )
        self.nvec = [int(n) for n in nvec]
        self.recurrent = recurrent
        """The GRU's state size ``R`` (0: feed-forward)."""
        hidden = tuple(hidden)
        in_dim = encoder.size + check_memory(memory, self.nvec)
        if arch == "shared":
            self.trunk = nn.Sequential(*hidden_layers(in_dim, hidden))
            self.actor = _orthogonal(nn.Linear(hidden[-1], sum(self.nvec)), 0.01)
            self.critic = _orthogonal(nn.Linear(hidden[-1], 1), 1.0)
        else:
            self.trunk = nn.Identity()
            self.actor = (
                mlp(in_dim, sum(self.nvec), hidden, out_gain=0.01)
                if arch == "mlp"
                else LatticeActor(encoder, self.nvec, hidden)
            )
            self.critic = mlp(in_dim, 1, hidden, out_gain=1.0)
        if recurrent:
            self.gru = nn.GRUCell(hidden[-1], recurrent)
            self.actor_memory = _orthogonal(nn.Linear(recurrent, sum(self.nvec)), 0.0)
            self.critic_memory = _orthogonal(nn.Linear(recurrent, 1), 0.0)

    def initial_state(self, n: int) -> torch.Tensor | None:
        """``(n, R)`` zeros: every module's state at an episode's start (``None`` when feed-forward)."""
        if not self.recurrent:
            return None
        return torch.zeros((n, self.recurrent), device=self.critic_memory.weight.device)

    def forward(self, x: torch.Tensor, state: torch.Tensor | None = None):
        """``(logits (N, sum(nvec)), value (N,), next_state (N, R) or None)`` from features
        ``(N, D)`` and, when recurrent, the state ``(N, R)`` before this cycle."""
        h = self.trunk(x)
        logits, value = self.actor(h), self.critic(h)[:, 0]
        if not self.recurrent:
            return logits, value, None
        state = self.gru(h, state)
        return logits + self.actor_memory(state), value + self.critic_memory(state)[:, 0], state

    def logits(self, x: torch.Tensor, state: torch.Tensor | None = None) -> torch.Tensor:
        return self.forward(x, state)[0] if self.recurrent else self.actor(self.trunk(x))

    def value(self, x: torch.Tensor, state: torch.Tensor | None = None) -> torch.Tensor:
        return self.forward(x, state)[1] if self.recurrent else self.critic(self.trunk(x))[:, 0]

    def unroll(self, x: torch.Tensor, state: torch.Tensor, done: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits ``(T, M, sum(nvec))`` and values ``(T, M)`` of ``M`` modules over ``T`` cycles
        (features ``(T, M, D)``) from their state ``(M, R)`` before the first; ``done (T, M)``
        marks the cycles after which a module's episode ended, where its state restarts at zero."""
        logits, values = [], []
        for t in range(x.shape[0]):
            step_logits, step_value, state = self.forward(x[t], state)
            logits.append(step_logits)
            values.append(step_value)
            state = state * (1.0 - done[t].to(state.dtype))[:, None]
        return torch.stack(logits), torch.stack(values)
