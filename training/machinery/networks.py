"""The network of :mod:`training.trainers.ppo` and :mod:`training.trainers.imitate` (``arch``: ``shared``,
``mlp`` or ``slots``), the masked categorical distribution over its action fields, and the scale of the
critic's returns (:class:`ReturnScale`). Checkpoints of both scripts hold an :class:`ActorCritic`'s
weights, and :mod:`training.machinery.checkpoints` rebuilds it from here."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from proteo_env.core.lattice import DIRECTIONS
from training.machinery.policies import check_memory

ARCHS = ("shared", "mlp", "slots")
"""``shared``: one MLP trunk under the actor's and the critic's heads; ``mlp``: an MLP each;
``slots``: one encoder shared by the 12 neighbour directions (:class:`SlotTrunk`)."""
ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}
"""The hidden layers' activations, by the name a checkpoint records. ``tanh`` is what every published
network uses; ``relu`` costs about a thirtieth of it per element on a CPU without AVX-512 (tanh is
then a fifth of a rollout's forward pass and of the update: docs/speed/ppo_throughput.md)."""


def check_arch(arch) -> str:
    """``arch`` if it is one of :data:`ARCHS`, else a :class:`ConfigError` naming it and the allowed ones."""
    if arch not in ARCHS:
        raise ConfigError(f"arch={arch!r} is not allowed; allowed: {', '.join(ARCHS)}")
    return arch


def check_activation(activation) -> str:
    """``activation`` if it is one of :data:`ACTIVATIONS`, else a :class:`ConfigError` naming it and the allowed ones."""
    if activation not in ACTIVATIONS:
        raise ConfigError(f"activation={activation!r} is not allowed; allowed: {', '.join(ACTIVATIONS)}")
    return activation


def network_meta(args) -> dict:
    """What a checkpoint of :mod:`training.trainers.ppo` or :mod:`training.trainers.imitate` records of its network
    (from the script's ``args``): the control level, the architecture, the layer sizes, their
    activation (:data:`ACTIVATIONS`) and the memory."""
    return {
        "control": args.control,
        "arch": args.arch,
        "hidden": list(args.hidden),
        "activation": args.activation,
        "memory": args.memory,
    }


def hidden_layers(in_dim: int, hidden: tuple[int, ...], activation: str = "tanh") -> list[nn.Module]:
    """Layers of sizes ``hidden`` from ``in_dim`` inputs, each followed by ``activation``, orthogonally initialised."""
    layers, last = [], in_dim
    for h in hidden:
        layers += [_orthogonal(nn.Linear(last, h), np.sqrt(2)), ACTIVATIONS[check_activation(activation)]()]
        last = h
    return layers


def mlp(
    in_dim: int, out_dim: int, hidden: tuple[int, ...], *, out_gain: float, activation: str = "tanh"
) -> nn.Sequential:
    """An MLP with orthogonal initialisation; ``out_gain`` scales the last layer."""
    last = hidden[-1] if hidden else in_dim
    return nn.Sequential(*hidden_layers(in_dim, hidden, activation), _orthogonal(nn.Linear(last, out_dim), out_gain))


def _orthogonal(layer: nn.Linear, gain: float) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, gain=gain)
    if layer.bias is not None:
        nn.init.zeros_(layer.bias)
    return layer


class SlotTrunk(nn.Module):
    """The lattice's structure in the network: one encoder shared by the 12 neighbour directions,
    and one round of message passing between the directions that are neighbours themselves.

    Direction ``k``'s token is site ``k``'s columns of every per-site block of the encoding (its
    kind, mode and scent blocks, the message received from it) and whether the move towards it is
    legal; each token is embedded by one shared layer plus a learned embedding of its direction
    (``(N, 12, E)``). A module's own features (its mode, scent, contact, load, the task's hint,
    the messages' values, the memory's inputs and whether staying is legal) join every token in
    the message-passing round, where token ``k`` also reads the mean of the four directions next
    to it on the cuboctahedron of the 12 face neighbours (the sites a roll towards ``k`` pivots
    on). The own features ask a query of the 12 tokens (one head of scaled dot-product
    attention); the tokens' mean, the attended one and the own features make the context
    ``(N, H)`` through the hidden layers. The logit of "move towards ``k``" is token ``k``'s dot
    product with a vector the context chooses, plus a shared bias head on the token (so every
    direction is judged by the same weights, and the context decides which wins); staying, the
    other action fields and the value are linear heads on the context.

    ``hidden = (E, H, ...)``: the tokens' width, then the context's layers (``(E,)`` alone: one
    context layer of ``E``). Needs the 12 face neighbours (``obs_radius=1``).
    """

    SITE_BLOCKS = (
        "neighbour_kind",
        "neighbour_mode",
        "neighbour_scent_present",
        "neighbour_scent_value",
        "neighbour_scent_delta",
    )
    OWN_BLOCKS = ("own_mode", "own_scent_present", "own_scent_value", "contact", "load", "hint")

    def __init__(self, encoder: ObservationEncoder, in_dim: int, hidden: tuple[int, ...], activation: str):
        super().__init__()
        if encoder.n_sites != 12:
            raise ConfigError(
                f"arch='slots' needs the 12 face neighbours (obs_radius=1); the observation has "
                f"{encoder.n_sites} sites; allowed: obs_radius=1, or arch 'shared' or 'mlp'"
            )
        embed, context = hidden[0], (tuple(hidden[1:]) or (hidden[0],))
        slices, compact = encoder.slices, encoder.message_encoding == "compact"
        site_blocks = (*self.SITE_BLOCKS, "message_from" if compact else "messages")
        own_blocks = (*self.OWN_BLOCKS, *(("message_value",) if compact else ()))
        columns = []  # token k: site k's columns of every per-site block (site-major), then "move k+1 is legal"
        for k in range(12):
            for name in site_blocks:
                block = slices[name]
                width = (block.stop - block.start) // 12
                columns += range(block.start + k * width, block.start + (k + 1) * width)
            columns.append(slices["action_mask"].start + 1 + k)
        own = [c for name in own_blocks for c in range(slices[name].start, slices[name].stop)]
        own += [slices["action_mask"].start, *range(encoder.size, in_dim)]  # staying is legal; the memory's inputs
        self.register_buffer("token_columns", torch.tensor(columns))
        self.register_buffer("own_columns", torch.tensor(own))
        gap = ((DIRECTIONS[:, None, :] - DIRECTIONS[None, :, :]) ** 2).sum(axis=2)
        self.register_buffer("next_to", torch.tensor((gap == 2) / 4.0, dtype=torch.float32))
        self.token_dim = len(columns) // 12
        self.act = ACTIVATIONS[check_activation(activation)]()
        self.embed = _orthogonal(nn.Linear(self.token_dim, embed), np.sqrt(2))
        self.direction = nn.Parameter(torch.zeros(12, embed))
        self.own_in = _orthogonal(nn.Linear(len(own), embed), np.sqrt(2))
        self.neighbours_in = _orthogonal(nn.Linear(embed, embed, bias=False), np.sqrt(2))
        self.token_in = _orthogonal(nn.Linear(embed, embed, bias=False), np.sqrt(2))
        self.query = _orthogonal(nn.Linear(len(own), embed), 1.0)
        self.context = nn.Sequential(*hidden_layers(2 * embed + len(own), context, activation))
        self.move_query = _orthogonal(nn.Linear(context[-1], embed), 1.0)
        self.move_bias = _orthogonal(nn.Linear(embed, 1), 0.01)
        self.width = context[-1]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(context (N, H), move logits (N, 12))`` from features ``(N, D)``."""
        n = x.shape[0]
        tokens = self.act(
            self.embed(x.index_select(1, self.token_columns).reshape(n, 12, self.token_dim)) + self.direction
        )
        own = x.index_select(1, self.own_columns)
        around = torch.matmul(self.next_to, tokens)  # (N, 12, E): the mean of each direction's four neighbours
        tokens = self.act(self.token_in(tokens) + self.neighbours_in(around) + self.own_in(own)[:, None, :])
        scores = torch.einsum("nke,ne->nk", tokens, self.query(own)) / tokens.shape[2] ** 0.5
        attended = torch.einsum("nk,nke->ne", torch.softmax(scores, dim=1), tokens)
        context = self.context(torch.cat([tokens.mean(dim=1), attended, own], dim=1))
        moves = torch.einsum("nke,ne->nk", tokens, self.move_query(context)) + self.move_bias(tokens)[..., 0]
        return context, moves


class ActorCritic(nn.Module):
    """The shared policy: logits ``(N, sum(nvec))`` and value ``(N,)`` from flat features
    ``x (N, D)``; ``net(x)`` gives both. ``arch="shared"``: one MLP trunk feeds both heads
    (one pass instead of two); ``arch="mlp"``: separate MLPs for the actor and the critic;
    ``arch="slots"``: :class:`SlotTrunk` feeds the move's logits per direction and, from its
    context, staying, the other fields and the value. The hidden layers' ``activation`` is one of
    :data:`ACTIVATIONS`. With ``memory`` (:data:`training.machinery.policies.MEMORIES`) ``D`` is the
    encoder's size plus the memory's inputs (:func:`training.machinery.policies.with_memory`)."""

    def __init__(
        self,
        encoder: ObservationEncoder,
        nvec,
        arch: str = "shared",
        hidden: tuple[int, ...] = (64, 64),
        memory: str = "none",
        activation: str = "tanh",
    ):
        super().__init__()
        self.arch = check_arch(arch)
        self.nvec = [int(n) for n in nvec]
        hidden = tuple(hidden)
        in_dim = encoder.size + check_memory(memory, self.nvec)
        if arch == "slots":
            self.trunk = SlotTrunk(encoder, in_dim, hidden, activation)
            self.actor = _orthogonal(nn.Linear(self.trunk.width, 1 + sum(self.nvec[1:])), 0.01)  # stay, other fields
            self.critic = _orthogonal(nn.Linear(self.trunk.width, 1), 1.0)
        elif arch == "shared":
            self.trunk = nn.Sequential(*hidden_layers(in_dim, hidden, activation))
            self.actor = _orthogonal(nn.Linear(hidden[-1], sum(self.nvec)), 0.01)
            self.critic = _orthogonal(nn.Linear(hidden[-1], 1), 1.0)
        else:
            self.trunk = nn.Identity()
            self.actor = mlp(in_dim, sum(self.nvec), hidden, out_gain=0.01, activation=activation)
            self.critic = mlp(in_dim, 1, hidden, out_gain=1.0, activation=activation)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(logits (N, sum(nvec)), value (N,))`` from features ``(N, D)``."""
        if self.arch == "slots":
            context, moves = self.trunk(x)
            heads = self.actor(context)
            return torch.cat([heads[:, :1], moves, heads[:, 1:]], dim=1), self.critic(context)[:, 0]
        h = self.trunk(x)
        return self.actor(h), self.critic(h)[:, 0]

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        if self.arch == "slots":
            return self(x)[0]
        return self.actor(self.trunk(x))

    def value(self, x: torch.Tensor) -> torch.Tensor:
        if self.arch == "slots":
            return self(x)[1]
        return self.critic(self.trunk(x))[:, 0]

    def clip_gradients(self, max_norm: float) -> None:
        """Scale the gradients down to norm ``max_norm``: of the whole network at ``arch="shared"``
        and ``"slots"``, of the actor and of the critic separately at ``arch="mlp"``."""
        if self.arch == "mlp":
            nn.utils.clip_grad_norm_(self.actor.parameters(), max_norm)
            nn.utils.clip_grad_norm_(self.critic.parameters(), max_norm)
        else:
            nn.utils.clip_grad_norm_(self.parameters(), max_norm)


class ReturnScale:
    """Running mean and variance of the returns (Chan et al.'s parallel update, float64). With
    ``value_norm`` the critic predicts ``(G - mean) / std`` and :meth:`value` maps its output
    back, so that a value loss on the scaled returns stays near 1 whatever the reward's scale:
    on a shared trunk an unscaled value loss of returns in the hundreds swamps the policy's
    gradient under the joint norm clip. Disabled, every method is the identity."""

    def __init__(self, enabled: bool):
        self.enabled, self.mean, self.var, self.count = enabled, 0.0, 1.0, 0

    def update(self, returns: torch.Tensor) -> None:
        if not self.enabled:
            return
        x = returns.double()
        n, mean, var = x.numel(), x.mean().item(), x.var(unbiased=False).item()
        total = self.count + n
        delta = mean - self.mean
        self.var = (self.var * self.count + var * n + delta * delta * self.count * n / total) / total
        self.mean, self.count = self.mean + delta * n / total, total

    @property
    def std(self) -> float:
        return max(self.var, 1e-8) ** 0.5

    def value(self, output: torch.Tensor) -> torch.Tensor:
        """The critic's output ``(N,)`` in return units."""
        return output * self.std + self.mean if self.enabled else output

    def target(self, returns: torch.Tensor) -> torch.Tensor:
        """Returns ``(N,)`` on the critic's scale."""
        return (returns - self.mean) / self.std if self.enabled else returns

    def state_dict(self) -> dict:
        return {"mean": self.mean, "var": self.var, "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.mean, self.var, self.count = state["mean"], state["var"], state["count"]


# ---------------------------------------------------------------------- the action distribution
def masked_log_probs(logits: torch.Tensor, move_mask: torch.Tensor, nvec: list[int]) -> list[torch.Tensor]:
    """Per field, log-probabilities ``(N, nvec[k])``; illegal moves (``move_mask`` False) get ~zero probability."""
    out, start = [], 0
    for k, n in enumerate(nvec):
        part = logits[:, start : start + n]
        if k == 0:
            part = part.masked_fill(~move_mask, -1e8)
        out.append(torch.log_softmax(part, dim=1))
        start += n
    return out


def sample(log_probs: list[torch.Tensor], sampled: str = "all") -> tuple[torch.Tensor, torch.Tensor]:
    """Actions ``(N, F)`` (Gumbel-max, torch's generator) and the joint log-probability ``(N,)`` of
    the fields drawn at random. ``sampled="move"`` (:data:`training.machinery.policies.SAMPLED`): the fields
    after the move take their arg-max and the log-probability is the move's; the generator is
    drawn from the same either way."""
    noisy = [lp - torch.log(-torch.log(torch.rand_like(lp))) for lp in log_probs]
    actions = torch.stack(
        [
            (noise if k == 0 or sampled == "all" else lp).argmax(dim=1)
            for k, (lp, noise) in enumerate(zip(log_probs, noisy))
        ],
        1,
    )
    return actions, joint_log_prob(sampled_fields(log_probs, sampled), actions)


def sampled_fields(log_probs: list[torch.Tensor], sampled: str) -> list[torch.Tensor]:
    """The fields that :func:`sample` draws at random (every field, or the move alone): the ones the
    policy gradient and the entropy bonus act on."""
    return log_probs if sampled == "all" else log_probs[:1]


def joint_log_prob(log_probs: list[torch.Tensor], actions: torch.Tensor) -> torch.Tensor:
    return sum(lp.gather(1, actions[:, k : k + 1])[:, 0] for k, lp in enumerate(log_probs))


def teacher_cross_entropy(log_probs: list[torch.Tensor], labels: torch.Tensor, move_mask: torch.Tensor) -> torch.Tensor:
    """Mean over samples of ``-log pi(label)`` summed over fields, for labels ``(N, F)``; samples
    whose labelled move is illegal under ``move_mask (N, 13)`` count zero."""
    legal = move_mask.gather(1, labels[:, :1])[:, 0].float()
    return -(joint_log_prob(log_probs, labels) * legal).sum() / legal.sum().clamp(min=1.0)


def entropy(log_probs: list[torch.Tensor]) -> torch.Tensor:
    """Sum over fields of each field's entropy ``(N,)``."""
    return sum(-(lp.exp() * lp).sum(dim=1) for lp in log_probs)
