"""Policy and value networks on top of any observation encoder.

Every network takes an `encoder_factory: Callable[[], nn.Module]` returning a *fresh* module that maps
the observation pytree (B, ...) to features (B, D); each network builds its own encoder from it (the
actor's and the critic's encoders are separate parameters). Inside the critic one encoder is shared
by the Q heads: the twin heads differ only in their MLPs, so the (expensive) encoder runs once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from vmax_sim.agents.distributions import TanhGaussian

EncoderFactory = Callable[[], nn.Module]

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "relu": nn.relu, "tanh": nn.tanh, "gelu": nn.gelu, "silu": nn.silu, "elu": nn.elu, "selu": nn.selu,
}


def get_activation(name: str) -> Callable[[jax.Array], jax.Array]:
    if name not in ACTIVATIONS:
        raise ValueError(f"unknown activation {name!r}; choose one of {sorted(ACTIVATIONS)}")
    return ACTIVATIONS[name]


class MLP(nn.Module):
    """Dense layers (B, D_in) -> (B, hidden_sizes[-1]) with the activation after each (after the last if
    `activate_final`)."""

    hidden_sizes: Sequence[int]
    activation: str = "relu"
    activate_final: bool = True

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = get_activation(self.activation)
        for i, size in enumerate(self.hidden_sizes):
            x = nn.Dense(size, name=f"dense_{i}")(x)
            if i < len(self.hidden_sizes) - 1 or self.activate_final:
                x = act(x)
        return x


class Actor(nn.Module):
    """obs (B, ...) -> TanhGaussian with loc (B, A) and log_std (B, A) clipped to [log_std_min, log_std_max]."""

    encoder_factory: EncoderFactory
    action_dim: int
    hidden_sizes: Sequence[int] = (256, 256)
    activation: str = "relu"
    log_std_min: float = -5.0
    log_std_max: float = 2.0
    head_init_scale: float = 0.01  # small initial mean / log_std: actions start near 0 with std near 1

    def setup(self):
        self.encoder = self.encoder_factory()
        self.torso = MLP(self.hidden_sizes, self.activation, activate_final=True)
        head_init = nn.initializers.variance_scaling(self.head_init_scale, "fan_in", "truncated_normal")
        self.loc_head = nn.Dense(self.action_dim, kernel_init=head_init)
        self.log_std_head = nn.Dense(self.action_dim, kernel_init=head_init)

    def __call__(self, obs) -> TanhGaussian:
        h = self.torso(self.encoder(obs))
        log_std = jnp.clip(self.log_std_head(h), self.log_std_min, self.log_std_max)
        return TanhGaussian(loc=self.loc_head(h), log_std=log_std)


class _QHead(nn.Module):
    """[features, action] (B, D + A) -> Q (B,)."""

    hidden_sizes: Sequence[int]
    activation: str

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        h = MLP(self.hidden_sizes, self.activation, activate_final=True)(x)
        return nn.Dense(1)(h)[..., 0]


class Critic(nn.Module):
    """(obs (B, ...), action (B, A)) -> Q (num_heads, B): one shared encoder, `num_heads` independent MLP heads
    (vmapped, so the heads run as one batched matmul)."""

    encoder_factory: EncoderFactory
    hidden_sizes: Sequence[int] = (256, 256)
    activation: str = "relu"
    num_heads: int = 2

    def setup(self):
        self.encoder = self.encoder_factory()
        heads = nn.vmap(_QHead, variable_axes={"params": 0}, split_rngs={"params": True}, in_axes=None,
                        out_axes=0, axis_size=self.num_heads)
        self.heads = heads(tuple(self.hidden_sizes), self.activation)

    def __call__(self, obs, action: jax.Array) -> jax.Array:
        return self.q_from_features(self.encode(obs), action)

    def encode(self, obs) -> jax.Array:
        """obs (B, ...) -> features (B, D)."""
        return self.encoder(obs)

    def q_from_features(self, features: jax.Array, action: jax.Array) -> jax.Array:
        """features (B, D), action (B, A) -> Q (num_heads, B): the heads alone (shared-encoder SAC)."""
        return self.heads(jnp.concatenate([features, action.astype(features.dtype)], axis=-1))


class Identity(nn.Module):
    """Features pass through: the encoder of an actor that reads another network's features."""

    @nn.compact
    def __call__(self, features: jax.Array) -> jax.Array:
        return features


class ValueNet(nn.Module):
    """obs (B, ...) -> V (B,)."""

    encoder_factory: EncoderFactory
    hidden_sizes: Sequence[int] = (256, 256)
    activation: str = "tanh"

    def setup(self):
        self.encoder = self.encoder_factory()
        self.torso = MLP(self.hidden_sizes, self.activation, activate_final=True)
        self.head = nn.Dense(1)

    def __call__(self, obs) -> jax.Array:
        return self.head(self.torso(self.encoder(obs)))[..., 0]
