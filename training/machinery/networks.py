"""The network of :mod:`training.trainers.ppo` and :mod:`training.trainers.imitate` (``arch``: ``shared`` or
``mlp``), the masked categorical distribution over its action fields, and the scale of the
critic's returns (:class:`ReturnScale`). Checkpoints of both scripts hold an :class:`ActorCritic`'s
weights, and :mod:`training.machinery.checkpoints` rebuilds it from here."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from proteo_env.adapters.flatten import ObservationEncoder
from proteo_env.config import ConfigError
from training.machinery.policies import check_memory

ARCHS = ("shared", "mlp")
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
    nn.init.zeros_(layer.bias)
    return layer


class ActorCritic(nn.Module):
    """The shared policy: logits ``(N, sum(nvec))`` and value ``(N,)`` from flat features
    ``x (N, D)``; ``net(x)`` gives both. ``arch="shared"``: one MLP trunk feeds both heads
    (one pass instead of two); ``arch="mlp"``: separate MLPs for the actor and the critic; the hidden
    layers' ``activation`` is one of :data:`ACTIVATIONS`.
    With ``memory`` (:data:`training.machinery.policies.MEMORIES`) ``D`` is the encoder's size plus the
    memory's inputs (:func:`training.machinery.policies.with_memory`)."""

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
        if arch == "shared":
            self.trunk = nn.Sequential(*hidden_layers(in_dim, hidden, activation))
            self.actor = _orthogonal(nn.Linear(hidden[-1], sum(self.nvec)), 0.01)
            self.critic = _orthogonal(nn.Linear(hidden[-1], 1), 1.0)
        else:
            self.trunk = nn.Identity()
            self.actor = mlp(in_dim, sum(self.nvec), hidden, out_gain=0.01, activation=activation)
            self.critic = mlp(in_dim, 1, hidden, out_gain=1.0, activation=activation)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(logits (N, sum(nvec)), value (N,))`` from features ``(N, D)``."""
        h = self.trunk(x)
        return self.actor(h), self.critic(h)[:, 0]

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        return self.actor(self.trunk(x))

    def value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(self.trunk(x))[:, 0]

    def clip_gradients(self, max_norm: float) -> None:
        """Scale the gradients down to norm ``max_norm``: of the whole network at ``arch="shared"``,
        of the actor and of the critic separately at ``arch="mlp"``."""
        if self.arch == "shared":
            nn.utils.clip_grad_norm_(self.parameters(), max_norm)
        else:
            nn.utils.clip_grad_norm_(self.actor.parameters(), max_norm)
            nn.utils.clip_grad_norm_(self.critic.parameters(), max_norm)


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
