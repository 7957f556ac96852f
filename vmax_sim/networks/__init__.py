"""Observation encoders (none, mlp, lq, lqh, mtr, wayformer) and the masked attention blocks they share."""

from vmax_sim.networks.attention import (
    CrossAttentionBlock,
    GroupedCrossAttention,
    GroupedCrossAttentionBlock,
    MultiHeadAttention,
    PolylineEncoder,
    SelfAttentionBlock,
    masked_max,
    masked_mean,
    masked_softmax,
)
from vmax_sim.networks.config import DEFAULT_ENCODER_CONFIG, ENCODER_NAMES, EncoderConfig
from vmax_sim.networks.encoders import (
    HierarchicalLatentQueryEncoder,
    LatentQueryEncoder,
    MLPEncoder,
    MTREncoder,
    NoneEncoder,
    WayformerEncoder,
    make_encoder,
)

__all__ = [
    "DEFAULT_ENCODER_CONFIG",
    "ENCODER_NAMES",
    "CrossAttentionBlock",
    "EncoderConfig",
    "GroupedCrossAttention",
    "GroupedCrossAttentionBlock",
    "HierarchicalLatentQueryEncoder",
    "LatentQueryEncoder",
    "MLPEncoder",
    "MTREncoder",
    "MultiHeadAttention",
    "NoneEncoder",
    "PolylineEncoder",
    "SelfAttentionBlock",
    "WayformerEncoder",
    "make_encoder",
    "masked_max",
    "masked_mean",
    "masked_softmax",
]
