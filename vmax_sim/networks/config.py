"""Encoder settings (frozen; one field per knob, checked on construction)."""

from __future__ import annotations

import dataclasses

ENCODER_NAMES = ("none", "mlp", "lq", "lqh", "mtr", "wayformer")


def _is_int_at_least(value, low: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


@dataclasses.dataclass(frozen=True)
class EncoderConfig:
    """Which encoder turns an `Observation` into one embedding, and its sizes.

    Fields that an encoder does not use are ignored by it (e.g. `mtr_neighbours` outside "mtr").
    """

    name: str = "lq"  # one of ENCODER_NAMES
    embed_dim: int = 64  # token / latent width of the attention encoders and the per-token MLPs
    num_latents: int = 16  # learned latent queries of "lq", "lqh" (global level) and "wayformer"
    num_heads: int = 4  # attention heads; must divide embed_dim
    num_layers: int = 2  # self-attention layers (latent or local); 0 allowed
    mlp_hidden: tuple[int, ...] = (256, 256)  # hidden widths of the "none" MLP and the "mlp" fusion MLP
    output_dim: int = 128  # size of the embedding every encoder returns
    mtr_neighbours: int = 8  # k of the k-nearest-token local attention of "mtr"
    roadgraph_chunk: int = 10  # consecutive roadgraph points per polyline token of "mtr"
    group_latents: int = 4  # latents per feature group at the first level of "lqh"
    ff_multiplier: int = 2  # feed-forward width of the transformer blocks, in multiples of embed_dim

    def __post_init__(self):
        # YAML / command-line overrides give lists: keep the config hashable
        object.__setattr__(self, "mlp_hidden", tuple(self.mlp_hidden))
        if self.name not in ENCODER_NAMES:
            raise ValueError(f"EncoderConfig.name must be one of {ENCODER_NAMES}, got {self.name!r}")
        for field in ("embed_dim", "num_latents", "num_heads", "output_dim", "mtr_neighbours", "roadgraph_chunk",
                      "group_latents", "ff_multiplier"):
            if not _is_int_at_least(getattr(self, field), 1):
                raise ValueError(f"EncoderConfig.{field} must be a positive int, got {getattr(self, field)!r}")
        if not _is_int_at_least(self.num_layers, 0):
            raise ValueError(f"EncoderConfig.num_layers must be an int >= 0, got {self.num_layers!r}")
        if self.embed_dim % self.num_heads:
            raise ValueError(f"EncoderConfig.embed_dim ({self.embed_dim}) must be a multiple of num_heads "
                             f"({self.num_heads})")
        if not self.mlp_hidden or not all(_is_int_at_least(width, 1) for width in self.mlp_hidden):
            raise ValueError(f"EncoderConfig.mlp_hidden must be a non-empty tuple of positive ints, "
                             f"got {self.mlp_hidden!r}")


DEFAULT_ENCODER_CONFIG = EncoderConfig()
