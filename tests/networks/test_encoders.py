"""Encoders: shapes, exact invariance to masked entries, empty groups, batching, no recompiles; the blocks by hand."""

from __future__ import annotations

import collections
import functools

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.networks import (
    ENCODER_NAMES,
    EncoderConfig,
    GroupedCrossAttention,
    make_encoder,
    masked_max,
    masked_mean,
    masked_softmax,
)
from vmax_sim.networks.encoders import GROUPS, LocalTransformer, flatten_batch, knn_mask
from vmax_sim.observation import Observation

# small sizes keep compiles short; k=3 and roadgraph 23 (not a multiple of the chunk) on purpose
SIZES = {"sdc": (3, 6), "objects": (4, 3, 12), "roadgraph": (23, 8), "lights": (2, 6), "path_targets": (3, 2)}
SMALL = {"embed_dim": 16, "num_latents": 4, "num_heads": 2, "num_layers": 1, "mlp_hidden": (32,), "output_dim": 8,
         "mtr_neighbours": 4, "roadgraph_chunk": 5, "group_latents": 2}
BATCH = 3
FAST_COMPILE = {"xla_backend_optimization_level": 0}  # LLVM -O0: same HLO graph, ~40 % less compile time


def random_observation(seed: int, lead: tuple[int, ...] = (BATCH,), sizes: dict = SIZES,
                       valid_fraction: float = 0.6) -> Observation:
    """Features N(0, 1), masks Bernoulli; every group keeps its first entry valid so none is empty."""
    rng = np.random.default_rng(seed)
    fields = {}
    for name, shape in sizes.items():
        valid = rng.random(lead + shape[:-1]) < valid_fraction
        valid[(...,) + (0,) * (len(shape) - 1)] = True
        fields[name] = jnp.asarray(rng.normal(size=lead + shape), jnp.float32)
        fields[f"{name}_valid"] = jnp.asarray(valid)
    return Observation(**fields)


def scramble_masked(obs: Observation, seed: int, scale: float = 1e3) -> Observation:
    """Masked features replaced by large random values (valid ones untouched)."""
    rng = np.random.default_rng(seed)
    fields = {}
    for name in GROUPS:
        x, valid = getattr(obs, name), getattr(obs, f"{name}_valid")
        garbage = jnp.asarray(scale * rng.normal(size=x.shape), jnp.float32)
        fields[name] = jnp.where(valid[..., None], x, garbage)
    return obs.replace(**fields)


def mask_group(obs: Observation, group: str) -> Observation:
    return obs.replace(**{f"{group}_valid": jnp.zeros_like(getattr(obs, f"{group}_valid"))})


def random_params(module: nn.Module, *args) -> dict:
    """Init's shapes filled with N(0, 0.3^2): nonzero biases too, and no init compile (tests stay fast)."""
    shapes = jax.eval_shape(module.init, jax.random.PRNGKey(0), *args)
    leaves, tree = jax.tree.flatten(shapes)
    keys = jax.random.split(jax.random.PRNGKey(1), len(leaves))
    return jax.tree.unflatten(tree, [0.3 * jax.random.normal(k, x.shape, x.dtype) for k, x in zip(keys, leaves)])


class Compiled:
    """One encoder's parameters and jitted apply (counting its traces per input shape), shared by its tests."""

    def __init__(self, name: str):
        self.name = name
        self.module = make_encoder(name, **SMALL)
        self.params = random_params(self.module, random_observation(0))
        self.traces = collections.Counter()

        def counted(params, obs):
            self.traces[obs.sdc.shape] += 1  # runs once per trace, not per call
            return self.module.apply(params, obs)

        self.apply = jax.jit(counted, compiler_options=FAST_COMPILE)
        loss = lambda params, obs: (jnp.sum(self.module.apply(params, obs)), self.module.apply(params, obs))  # noqa: E731
        self.value_and_grad = jax.jit(jax.value_and_grad(loss, has_aux=True), compiler_options=FAST_COMPILE)

    def single(self, obs: Observation) -> tuple[jnp.ndarray, dict]:
        """Output and parameter gradients of one observation (no batch dim): one compile serves both."""
        (_, out), grads = self.value_and_grad(self.params, obs)
        return out, grads


@pytest.fixture(scope="module", params=ENCODER_NAMES)
def enc(request) -> Compiled:
    return Compiled(request.param)


def close(a, b, tol=1e-5):
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=tol, atol=tol)


# ------------------------------------------------------------------------------------------------ encoders


def test_output_shape_for_any_leading_dims(enc):
    assert enc.apply(enc.params, random_observation(1)).shape == (BATCH, SMALL["output_dim"])
    assert enc.single(random_observation(1, lead=()))[0].shape == (SMALL["output_dim"],)
    out = jax.eval_shape(enc.module.apply, enc.params, random_observation(1, lead=(2, 2)))  # traced, not compiled
    assert out.shape == (2, 2, SMALL["output_dim"]) and out.dtype == jnp.float32


def test_masked_entries_do_not_change_the_output(enc):
    obs = random_observation(2)
    close(enc.apply(enc.params, obs), enc.apply(enc.params, scramble_masked(obs, 3)))


def test_masked_entries_may_hold_nan_and_inf(enc):
    obs = random_observation(17)
    poison = (jnp.nan, jnp.inf, -jnp.inf, jnp.nan, jnp.inf)  # one per group
    poisoned = obs.replace(**{g: jnp.where(getattr(obs, f"{g}_valid")[..., None], getattr(obs, g), poison[i])
                              for i, g in enumerate(GROUPS)})
    close(enc.apply(enc.params, obs), enc.apply(enc.params, poisoned))


@pytest.mark.parametrize("group", GROUPS)
def test_a_fully_masked_group_is_ignored_and_finite(enc, group):
    obs = mask_group(random_observation(4), group)
    out = enc.apply(enc.params, obs)
    assert np.isfinite(np.asarray(out)).all()
    close(out, enc.apply(enc.params, scramble_masked(obs, 5)))


def test_every_group_empty_gives_finite_output_and_gradients(enc):
    obs = random_observation(6, lead=())
    for group in GROUPS:
        obs = mask_group(obs, group)
    out, grads = enc.single(scramble_masked(obs, 7))
    assert np.isfinite(np.asarray(out)).all()
    assert all(np.isfinite(np.asarray(g)).all() for g in jax.tree.leaves(grads))
    close(out, enc.single(obs)[0])


def test_batch_equals_each_element_alone(enc):
    obs = random_observation(8)
    batched = enc.apply(enc.params, obs)
    for i in range(BATCH):
        close(batched[i], enc.single(jax.tree.map(lambda x, i=i: x[i], obs))[0])


@pytest.mark.parametrize("group", GROUPS)
def test_output_depends_on_valid_entries_of_every_group(enc, group):
    obs = random_observation(9)
    x, valid = getattr(obs, group), getattr(obs, f"{group}_valid")
    moved = obs.replace(**{group: jnp.where(valid[..., None], x + 0.5, x)})
    diff = np.abs(np.asarray(enc.apply(enc.params, obs) - enc.apply(enc.params, moved))).max()
    assert diff > 1e-4, f"{enc.name}: changing valid {group} entries left the output unchanged"


def test_parameters_exist_and_jit_traces_once(enc):
    assert sum(x.size for x in jax.tree.leaves(enc.params)) > 0
    for seed in (10, 11):  # same shapes, new values
        enc.apply(enc.params, random_observation(seed))
    assert enc.traces[(BATCH,) + SIZES["sdc"]] == 1


@pytest.mark.parametrize("sizes", [
    {"sdc": (1, 6), "objects": (16, 1, 12), "roadgraph": (7, 8), "lights": (1, 6), "path_targets": (1, 2)},
    {"sdc": (5, 6), "objects": (8, 5, 12), "roadgraph": (200, 8), "lights": (5, 6), "path_targets": (10, 2)},
])
@pytest.mark.parametrize("name", ENCODER_NAMES)
def test_observation_sizes_of_every_config_trace(name, sizes):
    module = make_encoder(name)  # default config
    obs = jax.eval_shape(lambda: random_observation(12, lead=(2,), sizes=sizes))
    params = jax.eval_shape(module.init, jax.random.PRNGKey(0), obs)
    assert jax.eval_shape(module.apply, params, obs).shape == (2, 128)


def test_flatten_batch_folds_leading_dims():
    flat, lead = flatten_batch(random_observation(14, lead=(2, 3)))
    assert lead == (2, 3) and flat.objects.shape == (6, 4, 3, 12) and flat.roadgraph_valid.dtype == jnp.bool_


# ---------------------------------------------------------------------------------------------- mtr locality


def test_mtr_local_attention_ignores_tokens_outside_every_neighbourhood():
    """A valid token far from the others is in no one's k nearest: the near tokens' outputs ignore it."""
    config = EncoderConfig(name="mtr", **SMALL)
    module = LocalTransformer(config)
    rng = np.random.default_rng(15)
    num_tokens = 8
    pos = rng.normal(size=(1, num_tokens, 2)).astype(np.float32) * 0.1
    pos[0, -1] = (50.0, 50.0)  # the far token
    tokens = jnp.asarray(rng.normal(size=(1, num_tokens, SMALL["embed_dim"])), jnp.float32)
    valid = jnp.ones((1, num_tokens), bool)
    params = random_params(module, tokens, jnp.asarray(pos), valid)
    apply = jax.jit(module.apply, compiler_options=FAST_COMPILE)
    before = apply(params, tokens, jnp.asarray(pos), valid)
    after = apply(params, tokens.at[0, -1].multiply(-2.0), jnp.asarray(pos), valid)
    close(before[0, :-1], after[0, :-1])
    assert np.abs(np.asarray(before[0, -1] - after[0, -1])).max() > 1e-3  # it still sees itself


def test_knn_mask_by_hand():
    pos = jnp.asarray([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [10.0, 0.0]]])  # (1, 4, 2) on a line
    valid = jnp.asarray([[True, True, True, False]])
    mask = np.asarray(knn_mask(pos, valid, 2))[0]
    np.testing.assert_array_equal(mask, [[1, 1, 0, 0],  # 0: itself and 1
                                         [1, 1, 0, 0],  # 1: itself and 0 (0 at 1, 2 at 2)
                                         [0, 1, 1, 0],  # 2: itself and 1
                                         [0, 1, 1, 0]])  # 3 (masked, at 10): nearest valid 2 and 1; never itself
    assert np.asarray(knn_mask(pos, valid, 5))[0, :, 3].sum() == 0  # K above the valid count: masked keys stay out


# --------------------------------------------------------------------------------------------------- blocks


def test_masked_softmax_by_hand():
    logits = jnp.asarray([[1.0, 2.0, 1e6], [5.0, -5.0, 7.0]])
    mask = jnp.asarray([[True, True, False], [False, False, False]])
    weights = np.asarray(masked_softmax(logits, mask))
    e = np.exp([1.0, 2.0]) / np.exp([1.0, 2.0]).sum()
    np.testing.assert_allclose(weights, [[e[0], e[1], 0.0], [0.0, 0.0, 0.0]], rtol=1e-6)


def test_masked_pools_by_hand():
    x = jnp.asarray([[[1.0, -1.0], [3.0, 5.0], [1e9, 1e9]], [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]])  # (2, 3, 2)
    mask = jnp.asarray([[True, True, False], [False, False, False]])
    np.testing.assert_allclose(masked_mean(x, mask), [[2.0, 2.0], [0.0, 0.0]])
    np.testing.assert_allclose(masked_max(x, mask), [[3.0, 5.0], [0.0, 0.0]])


def test_grouped_cross_attention_equals_the_unfolded_computation():
    """Folded keys / values == embed each token (x W_g + type_g), project, masked softmax, out Dense."""
    rng = np.random.default_rng(16)
    dim, heads, num_latents = 8, 2, 3
    groups = []
    for num_tokens, num_features in ((20, 3), (5, 3), (4, 7)):
        mask = rng.random((2, num_tokens)) < 0.7
        x = np.where(mask[..., None], rng.normal(size=(2, num_tokens, num_features)), 0.0)
        groups.append((jnp.asarray(x, jnp.float32), jnp.asarray(mask)))
    groups[2] = (groups[2][0], groups[2][1].at[1].set(False))  # group 3 empty in example 1
    latents = jnp.asarray(rng.normal(size=(num_latents, dim)), jnp.float32)
    module = GroupedCrossAttention(heads)
    params = random_params(module, latents, groups)

    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def folded_and_unfolded(params):
        p = params["params"]
        tokens = jnp.concatenate([x @ p[f"embed_{i}"] + p["type_embedding"][i] for i, (x, _) in enumerate(groups)], 1)
        mask = jnp.concatenate([m for _, m in groups], 1)  # (2, T)
        split = lambda a: a.reshape(a.shape[:-1] + (heads, dim // heads))  # noqa: E731
        query = split(latents @ p["query"]["kernel"] + p["query"]["bias"]) / np.sqrt(dim // heads)  # (Q, H, d)
        keys = split(tokens @ p["key_kernel"] + p["key_bias"])  # (B, T, H, d)
        values = split(tokens @ p["value_kernel"] + p["value_bias"])
        weights = masked_softmax(jnp.einsum("qhd,bthd->bhqt", query, keys), mask[:, None, None, :])
        attended = jnp.einsum("bhqt,bthd->bqhd", weights, values).reshape(2, num_latents, dim)
        return module.apply(params, latents, groups), attended @ p["out"]["kernel"] + p["out"]["bias"]

    close(*folded_and_unfolded(params), tol=1e-5)


def test_flax_attention_is_not_invariant_when_every_key_is_masked():
    """Why the attention is written by hand: flax gives an all-masked row uniform weights over the masked
    keys, so its output moves with their values."""
    attention = nn.MultiHeadDotProductAttention(num_heads=1, qkv_features=4, out_features=4)
    query = jnp.ones((1, 1, 4))
    keys_a, keys_b = jnp.zeros((1, 3, 4)), jnp.full((1, 3, 4), 5.0)
    mask = jnp.zeros((1, 1, 1, 3), bool)
    params = attention.init(jax.random.PRNGKey(0), query, keys_a, mask=mask)
    out_a = attention.apply(params, query, keys_a, mask=mask)
    out_b = attention.apply(params, query, keys_b, mask=mask)
    assert np.abs(np.asarray(out_a - out_b)).max() > 1e-3


# --------------------------------------------------------------------------------------------------- config


def test_config_validation_and_make_encoder():
    with pytest.raises(ValueError, match="name"):
        EncoderConfig(name="transformer")
    with pytest.raises(ValueError, match="multiple of num_heads"):
        EncoderConfig(embed_dim=30, num_heads=4)
    with pytest.raises(ValueError, match="num_latents"):
        EncoderConfig(num_latents=0)
    with pytest.raises(ValueError, match="mlp_hidden"):
        EncoderConfig(mlp_hidden=())
    assert EncoderConfig(mlp_hidden=[8, 8]).mlp_hidden == (8, 8)  # YAML lists become tuples
    assert make_encoder("mtr", embed_dim=32).config == EncoderConfig(name="mtr", embed_dim=32)
    assert make_encoder(EncoderConfig(name="mlp"), output_dim=4).config.output_dim == 4
    assert {type(make_encoder(name)).__name__ for name in ENCODER_NAMES} == {
        "NoneEncoder", "MLPEncoder", "LatentQueryEncoder", "HierarchicalLatentQueryEncoder", "MTREncoder",
        "WayformerEncoder"}
