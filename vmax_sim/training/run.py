"""`train`: a whole training run into a run directory, resumable after a crash or `kill -9`.

RUN_DIR/
  config.json          the TrainConfig (and the package version) -- everything needed to resume or evaluate
  checkpoints/<step>/  Orbax checkpoints: learner state, environments, replay buffer (optional), PRNG key,
                       and the host's position in the scenario stream
  metrics.csv          every logged scalar, one row per chunk (env_steps first)
  tensorboard/         TensorBoard event files of the same scalars
  eval.csv             the held-out evaluations (accuracy, V-Max score, ...)
  learning_curve.png   accuracy and V-Max score against env steps and wall time
  summary.json         the final evaluation and run statistics

Several processes (`jax.distributed`, `vmax-sim train --coordinator ...`) train one run over one global mesh:
every process steps its devices' environments and converts its share of the scenario stream, writes its part of
each checkpoint, and process 0 alone writes the rest of the run directory (vmax_sim.training.distributed).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import math
import resource
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.errors import InputError, describe_os_error
from scenariomax.locks import FolderBusyError, FolderLock
from vmax_sim.agents import make_learner
from vmax_sim.agents.common import learning_rate_scale
from vmax_sim.data import DataConfig, cache_dir
from vmax_sim.data.mixture import SYNTHETIC, format_sources, parse_sources, source_probabilities
from vmax_sim.env.learning import LearningEnv
from vmax_sim.env.selfplay import SelfPlayEnv
from vmax_sim.networks import make_encoder
from vmax_sim.policies.teacher import idm_teacher, pdm_state_teacher, pdm_teacher
from vmax_sim.policies.traffic import TRAFFIC_STANDING_CLEARANCE_M, idm_traffic
from vmax_sim.training import distributed
from vmax_sim.training.best import SDC_SCORE, SELFPLAY_SCORE, BestCheckpoint
from vmax_sim.training.checkpoint import CheckpointStore
from vmax_sim.training.config import (
    TrainConfig,
    action_repeat,
    apply_overrides,
    brake_guard,
    chunk_steps,
    config_from_dict,
    config_to_dict,
    policy_name,
    pool_refresh,
)
from vmax_sim.training.ensemble import EnsembleCheckpoints, ensemble_learner, is_ensemble, member_params
from vmax_sim.training.interrupt import StopRequests
from vmax_sim.training.logger import RunLogger
from vmax_sim.training.loop import (
    OFF_POLICY,
    TrainCarry,
    env_steps_per_chunk,
    make_off_policy_chunk,
    make_on_policy_chunk,
    transition_of,
    update_batch_size,
)
from vmax_sim.training.memory import release_freed_memory
from vmax_sim.training.parallel import data_mesh, replay_shardings, replicated_placer, shard_carry
from vmax_sim.training.pool import (
    WHOLE_STREAM,
    ScenarioStream,
    StreamShare,
    initial_pool,
    pool_shapes,
    rebuild_pool,
    refresh_pool,
)
from vmax_sim.training.replay import MIN_TRUNCATED_LENGTH, lost_last_observations, replay_bytes, replay_init

CONFIG_FILE = "config.json"


@dataclasses.dataclass
class TrainResult:
    run_dir: Path
    env_steps: int
    wall_s: float
    env_steps_per_s: float
    final_evaluation: dict | None  # evaluate()'s summary of the trained policy on the held-out split
    summary: dict
    # why the loop ended: total_env_steps, max_wall_minutes, interrupted (SIGINT / SIGTERM: checkpoint saved),
    # stop_after_chunks
    stopped: str = "total_env_steps"

    @property
    def interrupted(self) -> bool:
        return self.stopped == "interrupted"


def build_learner(config: TrainConfig, env: LearningEnv):
    network = config.network
    return make_learner(config.algo, config.algo_config, lambda: make_encoder(network), env.action_dim)


@functools.lru_cache(maxsize=8)
def components(config: TrainConfig):
    """(LearningEnv or SelfPlayEnv, Learner) of a configuration, built once per process so jitted functions are
    reused."""
    if config.is_selfplay:
        env = SelfPlayEnv(config.env, config.obs, config.reward, selfplay=config.selfplay,
                          action_repeat=action_repeat(config), teacher=teacher_of(config), rule_driver=TEACHERS["idm"])
    else:
        env = LearningEnv(config.env, config.obs, config.reward, expert_labels=config.imitates,
                          action_repeat=action_repeat(config), traffic=TRAFFIC_DRIVERS[config.train.traffic],
                          traffic_agents=config.train.traffic_agents, teacher=teacher_of(config),
                          traffic_sees_sdc_cos=TRAFFIC_SEES_SDC_COS.get(config.train.traffic))
    return env, build_learner(config, env)


def teacher_of(config: TrainConfig):
    """The run's teacher factory (`train.teacher`; the idm teacher driving by `train.teacher_speed_factor`,
    `train.teacher_max_accel` and `train.teacher_bend_lateral_accel`); None: the log."""
    train = config.train
    if train.teacher == "idm":
        return functools.partial(idm_teacher, speed_factor=train.teacher_speed_factor,
                                 max_accel=train.teacher_max_accel, bend_lateral_accel=train.teacher_bend_lateral_accel)
    return TEACHERS[train.teacher]


# train.traffic -> LearningEnv.traffic (None: the log)
_PASSING_IDM = functools.partial(idm_traffic, standing_clearance=TRAFFIC_STANDING_CLEARANCE_M)
TRAFFIC_DRIVERS = {"log": None, "idm": idm_traffic, "idm_pass": _PASSING_IDM, "idm_follow": idm_traffic,
                   "idm_follow_pass": _PASSING_IDM}
# train.traffic -> LearningEnv.traffic_sees_sdc_cos (absent: the agents always see the learner)
TRAFFIC_SEES_SDC_COS = dict.fromkeys(("idm_follow", "idm_follow_pass"), math.cos(math.radians(45.0)))
# train.teacher -> LearningEnv.teacher (None: the log-following action)
TEACHERS = {"log": None, "idm": idm_teacher, "pdm": pdm_teacher, "pdm_state": pdm_state_teacher}

_CHUNKS: dict = {}


def _chunk_function(config: TrainConfig, learner, env: LearningEnv, shapes):
    """The jitted chunk of `config` (one per configuration and process)."""
    if config in _CHUNKS:
        return _CHUNKS[config]
    algo_config = config.algo_config
    if config.algo in OFF_POLICY:
        learner_shapes, example = shapes
        sample = jax.tree.map(lambda a: jax.ShapeDtypeStruct((update_batch_size(algo_config),) + a.shape, a.dtype),
                              example)
        template = jax.eval_shape(lambda s, b, k: learner.update(s, b, k)[1], learner_shapes, sample,
                                  jax.random.PRNGKey(0))
        template = jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), template)
        chunk = make_off_policy_chunk(env, learner, config.algo, algo_config, chunk_steps(config), template)
    else:
        chunk = make_on_policy_chunk(env, learner, algo_config, chunk_steps(config))
    _CHUNKS[config] = jax.jit(chunk, donate_argnums=(0,))
    return _CHUNKS[config]


def data_config(config: TrainConfig, path: str, **changes) -> DataConfig:
    """The DataConfig of `config`'s data sizes for the shards at `path` (evaluation order by default)."""
    data = config.data
    values = dict(path=path, batch_size=config.train.eval_batch_size, num_objects=data.num_objects,
                  num_roadgraph_points=data.num_roadgraph_points, num_paths=data.num_paths,
                  num_points_per_path=data.num_points_per_path, max_num_lights=data.max_num_lights,
                  shuffle_buffer=data.shuffle_buffer)
    values.update(changes)
    return DataConfig(**values)


def train_data_config(config: TrainConfig, path: str, seed: int) -> DataConfig:
    """The training stream: one scenario at a time, seeded shuffle, repeated forever (with every agent's path
    under self-play and IDM traffic)."""
    return data_config(config, path, batch_size=1, shuffle_seed=seed, repeat=True, prefetch=0,
                       include_agent_paths=config.is_selfplay or config.train.traffic != "log",
                       hide_lights=config.data.hide_lights, hide_lights_from=config.data.hide_lights_from)


# ----------------------------------------------------------------------------- embedded synthetic data


def _finished_conversion(out: Path) -> bool:
    try:
        return json.loads((out / "manifest.json").read_text()).get("state") == "complete"
    except (OSError, ValueError, AttributeError):  # none yet, or cut short by a crash
        return False


def synthetic_split(num_scenarios: int, seed: int, num_objects: int, print_fn: Callable[[str], None],
                    knobs=None) -> str:
    """Shards of `num_scenarios` synthetic scenarios drawn with `seed` (randomised by the `SyntheticKnobs`
    `knobs`, None: the default generator), generated once into the cache. Non-default knobs add a short hash
    of the knobs that differ from their defaults to the folder name."""
    import hashlib

    from scenariomax import (
        ConversionError,
        ConvertSettings,
        Sizes,
        SyntheticKnobs,
        SyntheticSource,
        convert,
        make_transform,
    )

    name = f"seed{seed}-n{num_scenarios}-objects{num_objects}"
    changed = {}
    if knobs is not None and not knobs.is_default():
        default = SyntheticKnobs().as_dict()
        changed = {key: value for key, value in knobs.as_dict().items() if value != default[key]}
        digest = hashlib.sha256(json.dumps(changed, sort_keys=True).encode()).hexdigest()[:10]
        name += f"-knobs{digest}"
    out = cache_dir() / "synthetic" / name
    if _finished_conversion(out):
        return str(out)
    described = f", knobs {', '.join(f'{k}={v}' for k, v in changed.items())}" if changed else ""
    print_fn(f"generating {num_scenarios} synthetic scenarios (seed {seed}{described}) into {out} (once; cached): "
             f"{disk_estimate(num_scenarios, num_objects)}")
    sizes = Sizes(num_objects=num_objects)
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=out, workers=None, sizes=sizes, progress=True, transform=transform,
                               transform_settings=transform_settings, resume=out.exists())
    source = SyntheticSource(num_scenarios=num_scenarios, seed=seed, sizes=sizes, knobs=knobs if changed else None)
    try:
        result = convert(source, settings)  # an interrupted generation continues where it stopped
    except ConversionError:  # our cache folder, left by another version: start it again
        shutil.rmtree(out)
        result = convert(source, dataclasses.replace(settings, resume=False))
    if result.num_scenarios == 0:
        raise InputError(f"{out}: the synthetic generator produced no scenarios")
    return str(out)


def disk_estimate(num_scenarios: int, num_objects: int) -> str:
    """What a synthetic split will take on disk, said before it is built."""
    from vmax_sim.data.cache_admin import MAP_INDEX_BYTES_PER_SCENARIO, SYNTHETIC_BYTES_PER_SCENARIO, human_bytes

    del num_objects  # the 30k-point roadgraph, not the objects, makes most of a record
    shards = num_scenarios * SYNTHETIC_BYTES_PER_SCENARIO
    indices = num_scenarios * MAP_INDEX_BYTES_PER_SCENARIO
    return (f"about {human_bytes(shards)} of shards and {human_bytes(indices)} of map indices once trained on "
            f"(`vmax-sim cache info` lists the cache, `vmax-sim cache clear` frees it)")


def check_shards_exist(path: str) -> None:
    """One-line InputError when `path` names no shard files."""
    from scenariomax import list_shard_files

    try:
        files = list_shard_files(path)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None
    if not files:
        raise InputError(f"{path}: no shard files")


def resolve_data(config: TrainConfig, print_fn: Callable[[str], None]) -> tuple[str, str]:
    """(train spec, eval path): the configured shards, or the embedded synthetic splits (disjoint seeds). The
    training data may be a weighted mixture (`synthetic:0.5,shards/womd:0.5`, vmax_sim.data.mixture), where
    `synthetic` is the embedded training split."""
    data = config.data
    sources = []
    for source in parse_sources(data.train or SYNTHETIC):
        if source.path == SYNTHETIC:
            path = synthetic_split(data.synthetic_train_scenarios, data.synthetic_seed, data.num_objects, print_fn,
                                   knobs=data.synthetic)
            source = dataclasses.replace(source, path=path)
        else:
            check_shards_exist(source.path)
        sources.append(source)
    train = format_sources(tuple(sources))
    if len(sources) > 1:
        shares = ", ".join(f"{s.path} {p:.0%}" for s, p in zip(sources, source_probabilities(tuple(sources))))
        print_fn(f"training data: a mixture of {shares}")
    return train, resolve_eval_data(config, print_fn)


def resolve_eval_data(config: TrainConfig, print_fn: Callable[[str], None]) -> str:
    """The held-out shards of a run (the synthetic evaluation split when none were named): all that evaluating a
    trained run needs, whatever became of its training data."""
    data = config.data
    return data.eval or synthetic_split(data.synthetic_eval_scenarios, data.synthetic_seed + 1, data.num_objects,
                                        print_fn)


# ----------------------------------------------------------------------------- helpers


def peak_rss_mb() -> float:
    """Peak resident memory of this process (MB)."""
    usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return usage / 1024.0 if sys.platform != "darwin" else usage / 2**20


def _float_dtype(name: str):
    return {"float16": jnp.float16, "bfloat16": jnp.bfloat16, "float32": jnp.float32}[name]


def _host_scalars(stats: dict) -> dict[str, float]:
    """Chunk sums -> the logged means (episode stats per finished episode)."""
    values = {k: float(v) for k, v in jax.device_get(stats).items()}
    episodes = values.pop("episodes")
    out: dict[str, float] = {"episodes": episodes}
    for key in list(values):
        if key.startswith("episode/"):
            total = values.pop(key)
            out[key] = total / episodes if episodes > 0 else math.nan
    reward_sum = values.pop("reward_sum")
    out["reward_mean"] = reward_sum / max(values["agent_steps"], 1.0)  # a reward per acting agent and step
    out.update(values)
    return out


def planned_env_steps(total_env_steps: int, per_chunk: int) -> int:
    """The env steps a run of `total_env_steps` takes: whole chunks, so rounded up to a multiple of `per_chunk`."""
    return -(-total_env_steps // per_chunk) * per_chunk


class LastEpisodes:
    """The progress line's episode values: those of the latest chunk in which episodes finished (a chunk shorter
    than an episode often finishes none, and its means are undefined)."""

    def __init__(self):
        self.values: dict[str, float] = {}

    def update(self, scalars: dict[str, float]) -> None:
        if scalars.get("episodes", 0) > 0:
            self.values = {"return": scalars["episode/return"], "acc": scalars["episode/accuracy"]}

    def postfix(self) -> dict[str, str]:
        if not self.values:
            return {"return": "-", "acc": "-"}  # no episode has finished yet
        return {name: f"{value:.2f}" for name, value in self.values.items()}


# settings a resumed run may change: its length and how often it evaluates and checkpoints
RESUME_OVERRIDES = ("train.total_env_steps", "train.eval_every", "train.checkpoint_every", "train.keep_checkpoints",
                    "train.max_wall_minutes")


def save_run_config(run_dir: Path, config: TrainConfig) -> None:
    from vmax_sim import __version__

    values = {"vmax_version": __version__, "config": config_to_dict(config)}
    (run_dir / CONFIG_FILE).write_text(json.dumps(values, indent=2))


def load_run_config(run_dir: str | Path) -> TrainConfig:
    path = Path(run_dir) / CONFIG_FILE
    if not path.exists():
        raise InputError(f"{run_dir}: not a training run directory (no {CONFIG_FILE})")
    try:
        return config_from_dict(json.loads(path.read_text())["config"])
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: unreadable run configuration ({error})") from None


# ----------------------------------------------------------------------------- the run


@dataclasses.dataclass
class TrainingSetup:
    """Everything a run needs on the device, before the first chunk."""

    env: LearningEnv
    learner: object
    carry: TrainCarry
    pool: object  # SimulatorState (pool_size, ...)
    stream: ScenarioStream
    chunk_fn: Callable
    per_chunk: int  # env steps per chunk
    mesh: object  # jax Mesh or None
    buffer_mib: float
    place: Callable | None = None  # host rows -> replicated over several processes' devices (None: one process)


def stream_share(pool_size: int) -> StreamShare:
    """This process's share of the training stream: all of it, or with several processes every
    num_processes-th scenario (the pool's first fill must give each process one)."""
    processes = distributed.num_processes()
    if processes == 1:
        return WHOLE_STREAM
    if pool_size < processes:
        raise ValueError(f"train.pool_size={pool_size} is smaller than the {processes} processes: each converts a "
                         f"share of the pool's scenarios; choose at least {processes}")
    return StreamShare(jax.process_index(), processes, distributed.exchange)


def setup_training(config: TrainConfig, train_path: str, print_fn: Callable[[str], None] = print,
                   consumed: int | None = None, compile_also: Callable | None = None) -> TrainingSetup:
    """Fresh carry, scenario pool and jitted chunk of `config` (the pool as after `consumed` scenarios when
    resuming; the caller then restores the carry from the checkpoint). compile_also(learner state shapes) runs
    with the other compilations, before the data and the replay buffer take their memory."""
    loop, algo_config = config.train, config.algo_config
    env, learner = components(config)
    num_envs = algo_config.num_envs
    rows = num_envs * config.agents_per_env  # learner rows per env step: one per agent slot under self-play
    mesh = data_mesh(num_envs)
    blocks = mesh.size if mesh else 1
    share = stream_share(loop.pool_size)
    data_config = train_data_config(config, train_path, loop.seed)
    env_key, learner_key, loop_key = jax.random.split(jax.random.PRNGKey(loop.seed), 3)
    float_dtype = _float_dtype(loop.buffer_dtype)
    # jitted: run eagerly, reset and init leave ~1 GB of freed-but-kept host memory behind
    reset, init = jax.jit(env.reset, static_argnums=1), jax.jit(learner.init)

    def fresh_carry(pool) -> TrainCarry:
        """Environments, learner, key and step; the replay buffer is added apart (fresh, so never copied)."""
        env_state = reset(pool, num_envs, env_key)
        learner_state = init(learner_key, env_state.observation)
        carry = TrainCarry(learner=learner_state, env=env_state, buffer=None, key=loop_key,
                           env_steps=jnp.zeros((), jnp.int32))
        return jax.tree.map(lambda a: jnp.array(a, copy=True), carry)  # distinct buffers: the chunk donates them

    def fresh_replay():  # one buffer row per learner row
        return replay_init(example, algo_config.buffer_size, rows, float_dtype, num_blocks=blocks)

    # Shapes first, real arrays after: everything compiles before the scenario stream fills its shuffle buffer
    # and before the replay buffer exists (XLA takes ~1.4 GB to compile the paper's chunk, freed after).
    pool_abstract = pool_shapes(data_config, loop.pool_size)
    env_abstract = jax.eval_shape(lambda pool: reset(pool, num_envs, env_key), pool_abstract)
    carry_abstract = jax.eval_shape(fresh_carry, pool_abstract)
    example = None
    if config.algo in OFF_POLICY:
        shapes = jax.eval_shape(lambda s, pool: transition_of(env.step(s, jnp.zeros((rows, env.action_dim)),
                                                                       pool)[1]), env_abstract, pool_abstract)
        example = jax.tree.map(lambda a: jnp.zeros(a.shape[1:], a.dtype), shapes)  # one unbatched transition
        carry_abstract = carry_abstract.replace(buffer=jax.eval_shape(fresh_replay))
    # the jitted chunk is cached per configuration: a resumed or repeated run in one process reuses it
    learner_shapes = jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype), carry_abstract.learner)
    chunk_fn = _chunk_function(config, learner, env, (learner_shapes, example))
    if mesh is None:  # with several devices the shardings exist only once placed: compiled at the first call
        release_freed_memory()
        chunk_fn.lower(carry_abstract, pool_abstract).compile()  # the largest first; fills the jit's cache
        release_freed_memory()
        reset.lower(pool_abstract, num_envs, env_key).compile()
        init.lower(learner_key, env_abstract.observation).compile()
    if compile_also is not None:
        compile_also(carry_abstract.learner)
    release_freed_memory()

    if consumed is not None:
        pool, stream = rebuild_pool(data_config, consumed, loop.pool_size, share=share)
    else:
        stream = ScenarioStream(data_config, share=share)
        pool = initial_pool(stream, loop.pool_size)
    carry = fresh_carry(pool)
    release_freed_memory()  # the host copies of the pool's scenarios
    buffer_mib = 0.0
    if example is not None:
        total = replay_bytes(example, algo_config.buffer_size, rows, float_dtype, num_blocks=blocks)
        buffer_mib = total / 2**20
        print_fn(f"replay buffer: {algo_config.buffer_size:,} transitions x {total / algo_config.buffer_size:,.0f} B "
                 f"= {buffer_mib:,.0f} MiB ({loop.buffer_dtype} observations, each stored once)")
        if share.num_processes > 1:  # each process allocates only its devices' blocks
            shardings = replay_shardings(carry_abstract.buffer, mesh)
            carry = carry.replace(buffer=jax.jit(fresh_replay, out_shardings=shardings)())
        else:
            carry = carry.replace(buffer=fresh_replay())
    if mesh is not None:
        carry, pool = shard_carry(carry, pool, mesh)
        processes = f" of {share.num_processes} processes" if share.num_processes > 1 else ""
        print_fn(f"data-parallel over {mesh.size} devices{processes} ({num_envs // mesh.size} envs each)")
    return TrainingSetup(env=env, learner=learner, carry=carry, pool=pool, stream=stream, chunk_fn=chunk_fn,
                         per_chunk=env_steps_per_chunk(config.algo, algo_config, chunk_steps(config),
                                                       config.agents_per_env), mesh=mesh,
                         buffer_mib=buffer_mib, place=replicated_placer(mesh) if share.num_processes > 1 else None)


class _Progress:
    """tqdm bar over env steps when stderr is a terminal, plain lines every ~10 s otherwise."""

    def __init__(self, total: int, initial: int, enabled: bool):
        self.enabled = enabled
        self.bar = None
        self.last_line = 0.0
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=initial, unit="step", unit_scale=True, dynamic_ncols=True)
        self.total = total

    def update(self, steps: int, env_steps: int, postfix: dict[str, str]) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(steps)
            self.bar.set_postfix(postfix, refresh=False)
        elif time.time() - self.last_line > 10.0 or env_steps >= self.total:
            self.last_line = time.time()
            fields = "  ".join(f"{k} {v}" for k, v in postfix.items())
            print(f"train {env_steps}/{self.total} env steps  {fields}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def resumed_config(saved: TrainConfig, overrides: Sequence[str]) -> TrainConfig:
    """The run directory's config with the overrides a resume may change (RESUME_OVERRIDES: how long the run
    goes and how often it evaluates and checkpoints, none of which changes what it learnt so far)."""
    for item in overrides:
        key = item.split("=", 1)[0].strip()
        if key not in RESUME_OVERRIDES:
            raise InputError(f"--resume keeps the run's own configuration; only {', '.join(RESUME_OVERRIDES)} "
                             f"may change (got {key!r})")
    return apply_overrides(saved, overrides)


def run_progress(config: TrainConfig, env_steps: int, wall_s: float) -> float:
    """How far a run is (0..1): its env-step share, or with train.max_wall_minutes the larger of that and its
    wall-clock share. Several processes read the env steps alone: their clocks differ, their steps do not."""
    progress = env_steps / config.train.total_env_steps
    if config.train.max_wall_minutes and distributed.num_processes() == 1:
        progress = max(progress, wall_s / (60.0 * config.train.max_wall_minutes))
    return min(progress, 1.0)


def with_learning_rate_share(carry: TrainCarry, config: TrainConfig, env_steps: int, wall_s: float) -> TrainCarry:
    """`carry` with its learner's learning-rate share set for the next chunk (BC's `algo.lr_end_fraction`;
    unchanged when the learner keeps a constant rate)."""
    share = getattr(carry.learner, "lr_scale", None)
    if share is None:
        return carry
    algo = config.algo_config
    value = learning_rate_scale(run_progress(config, env_steps, wall_s), algo.lr_decay_start, algo.lr_end_fraction)
    return carry.replace(learner=carry.learner.replace(lr_scale=share * 0.0 + value))  # keeps its placement


def train(config: TrainConfig, run_dir: str | Path, *, resume: bool = False, progress: bool = True,
          print_fn: Callable[[str], None] = print, stop_after_chunks: int | None = None,
          resume_overrides: Sequence[str] = ()) -> TrainResult:
    """Trains `config` into `run_dir` (or continues it from its last checkpoint with `resume`).

    resume_overrides: `key=value` items of RESUME_OVERRIDES applied to the saved config on resume (e.g. a
    finished run extended with `train.total_env_steps=3e6`); saved back into config.json.
    stop_after_chunks stops early (tests: a run "killed" after that many chunks, then resumed).
    """
    run_dir = Path(run_dir)
    if resume:
        load_run_config(run_dir)  # a one-line error for a folder that holds no run, before the lock creates it
    if not distributed.is_primary():  # process 0 reports and holds the lock for the whole run
        print_fn, progress = (lambda line: None), False
    lock = FolderLock(run_dir, "training run") if distributed.is_primary() else contextlib.nullcontext()
    try:
        with lock:  # one writer per run directory
            return _train_locked(config, run_dir, resume=resume, progress=progress, print_fn=print_fn,
                                 stop_after_chunks=stop_after_chunks, resume_overrides=resume_overrides)
    except FolderBusyError as error:
        raise InputError(str(error)) from None
    except OSError as error:  # a full disk or a lost permission, in our code or a library's writer
        raise InputError(describe_os_error(error, resume_with=f"--resume {run_dir}", where=run_dir)) from None


def _train_locked(config: TrainConfig | None, run_dir: Path, *, resume: bool, progress: bool,
                  print_fn: Callable[[str], None], stop_after_chunks: int | None,
                  resume_overrides: Sequence[str]) -> TrainResult:
    run_dir = Path(run_dir)
    if resume:
        saved = load_run_config(run_dir)
        if saved != config and config is not None:
            print_fn("resuming with the run directory's own configuration (config.json)")
        config = resumed_config(saved, resume_overrides)
    elif (run_dir / CONFIG_FILE).exists():
        raise InputError(f"{run_dir}: already holds a training run; pass --resume to continue it or choose "
                         f"another --out")
    distributed.barrier("run directory checked")  # by every process, before process 0 writes into it
    run_dir.mkdir(parents=True, exist_ok=True)
    loop = config.train
    # a synthetic split is generated once, into a cache other processes on the host may share
    train_path, eval_path = distributed.primary_first(lambda: resolve_data(config, print_fn), "training data resolved")
    if distributed.is_primary() and (not resume or config != saved):
        save_run_config(run_dir, config)

    store = CheckpointStore(run_dir / "checkpoints", keep=loop.keep_checkpoints)
    restored_step = store.latest_step() if resume else None
    host = store.host_state(restored_step) if restored_step is not None else {"consumed": 0, "wall_s": 0.0,
                                                                                "chunks": 0}
    evaluator = _Evaluator(config, eval_path, run_dir, print_fn)
    # evaluations during training compile the evaluation early, while memory is low (once the replay buffer and
    # the data stream are there, its ~0.4 GB compilation set the run's peak); the final one runs without them
    periodic = bool(loop.eval_every) and loop.eval_every < loop.total_env_steps
    setup = setup_training(config, train_path, print_fn, consumed=host["consumed"] if restored_step else None,
                           compile_also=evaluator.compile if periodic else None)
    try:
        return _run(config, run_dir, resume, progress, print_fn, stop_after_chunks, store, restored_step, host,
                    setup, evaluator)
    finally:
        setup.stream.close()


def _run(config, run_dir, resume, progress, print_fn, stop_after_chunks, store, restored_step, host, setup,
         evaluator: _Evaluator) -> TrainResult:
    loop = config.train
    carry, pool, stream, chunk_fn, per_chunk = setup.carry, setup.pool, setup.stream, setup.chunk_fn, setup.per_chunk
    learner = setup.learner
    if restored_step is not None:
        carry = store.restore(restored_step, carry, with_buffer=loop.save_buffer)  # the replay is filled in place
        carry = jax.tree.map(lambda a: jnp.array(a, copy=True), carry.replace(buffer=None)).replace(buffer=carry.buffer)
        if setup.mesh is not None:
            carry, pool = shard_carry(carry, pool, setup.mesh)
        print_fn(f"resumed {run_dir} at {restored_step:,} env steps")

    primary = distributed.is_primary()
    logger = RunLogger(run_dir, write=primary)
    env_steps = int(carry.env_steps)
    if resume:
        logger.truncate_after(env_steps)
        evaluator.truncate_after(env_steps)
    target = planned_env_steps(loop.total_env_steps, per_chunk)
    if target != loop.total_env_steps and env_steps == 0:
        print_fn(f"train.total_env_steps={loop.total_env_steps:,} runs as {target:,} env steps (whole chunks of "
                 f"{per_chunk:,})")
    bar = _Progress(target, env_steps, progress)
    best = BestCheckpoint(run_dir, SELFPLAY_SCORE if config.is_selfplay else SDC_SCORE) if loop.keep_best else None
    ensemble = (EnsembleCheckpoints(run_dir, loop.ensemble, loop.ensemble_every, start=env_steps)
                if loop.ensemble else None)

    def save_checkpoint(env_steps: int, carry, host: dict) -> None:  # the run's checkpoint (and an ensemble member)
        store.save(env_steps, carry, host, with_buffer=loop.save_buffer)
        if ensemble is not None and ensemble.every is None:
            ensemble.add(env_steps, carry, host)
    wall_before = float(host["wall_s"])

    def host_record(wall_s: float) -> dict:  # what a checkpoint keeps of the host side
        return {"consumed": stream.consumed, "wall_s": wall_s, "chunks": int(host["chunks"]) + chunks}

    budget_s = loop.max_wall_minutes * 60.0 if loop.max_wall_minutes else math.inf
    start = time.perf_counter()
    last_checkpoint = env_steps
    last_eval = env_steps if env_steps > 0 else 0
    chunks = 0
    warned_lost = False
    stopped = "total_env_steps"
    last_episodes = LastEpisodes()
    with StopRequests(lambda name: print_fn(f"\n{name}: saving a checkpoint after this chunk (again to stop at "
                                            f"once, losing the steps since the last checkpoint)")) as stop:
        try:
            while env_steps < loop.total_env_steps:
                if math.isfinite(budget_s) and distributed.any_process(
                        [wall_before + time.perf_counter() - start >= budget_s])[0]:
                    stopped = "max_wall_minutes"
                    break
                carry = with_learning_rate_share(carry, config, env_steps, wall_before + time.perf_counter() - start)
                tick = time.perf_counter()
                carry, stats = chunk_fn(carry, pool)
                scalars = _host_scalars(stats)  # blocks until the chunk is done
                pool = refresh_pool(pool, stream, pool_refresh(config), place=setup.place)
                env_steps = int(carry.env_steps)
                elapsed = time.perf_counter() - tick
                scalars.update({"sps": per_chunk / elapsed, "wall_s": wall_before + time.perf_counter() - start,
                                "peak_rss_mb": peak_rss_mb(), "data_wait_s": stream.waited_s})
                logger.log(env_steps, scalars)
                chunks += 1
                last_episodes.update(scalars)
                bar.update(per_chunk, env_steps, {"sps": f"{scalars['sps']:.0f}", **last_episodes.postfix()})
                if not warned_lost and carry.buffer is not None and (lost := lost_last_observations(carry.buffer)):
                    warned_lost = True
                    print_fn(f"warning: {lost:,} truncated transitions in the replay buffer lost their last "
                             f"observation (truncated episodes average under {MIN_TRUNCATED_LENGTH} steps); their "
                             f"targets bootstrap from the next episode's first observation")
                # every process stops after the same chunk (a signal or the clock of one of them)
                requested, out_of_time = distributed.any_process([stop.requested, scalars["wall_s"] >= budget_s])
                if requested:
                    stopped = "interrupted"
                elif out_of_time:
                    stopped = "max_wall_minutes"
                last_chunk = env_steps >= loop.total_env_steps or requested or out_of_time
                # evaluations and checkpoints free a lot at once: return it (and what the chunks left) to the system
                if loop.eval_every and env_steps - last_eval >= loop.eval_every and not last_chunk:
                    release_freed_memory()
                    summary = evaluator.run(distributed.local_copy(learner.policy_params(carry.learner)), env_steps,
                                            scalars["wall_s"])
                    if best is not None:
                        best.offer(env_steps, summary, carry, host_record(scalars["wall_s"]))
                    last_eval = env_steps
                    release_freed_memory()
                if ensemble is not None:
                    ensemble.offer(env_steps, carry, host_record(scalars["wall_s"]), final=last_chunk)
                if env_steps - last_checkpoint >= loop.checkpoint_every or last_chunk:
                    release_freed_memory()
                    save_checkpoint(env_steps, carry, host_record(scalars["wall_s"]))
                    last_checkpoint = env_steps
                    release_freed_memory()
                if last_chunk and stopped != "total_env_steps":
                    break
                if stop_after_chunks is not None and chunks >= stop_after_chunks:
                    stopped = "stop_after_chunks"
                    break
        finally:
            bar.close()
            stream.close()
            logger.flush()
    wall_s = wall_before + time.perf_counter() - start
    if stopped == "max_wall_minutes" and last_checkpoint != env_steps:  # the budget ran out before the first chunk
        save_checkpoint(env_steps, carry, host_record(wall_s))
    if ensemble is not None:
        ensemble.offer(env_steps, carry, host_record(wall_s), final=True)
    finished = env_steps >= loop.total_env_steps or stopped == "max_wall_minutes"
    if stopped == "max_wall_minutes":
        print_fn(f"stopped at the wall-clock budget (train.max_wall_minutes={loop.max_wall_minutes:g}) after "
                 f"{env_steps:,} env steps; checkpoint saved in {store.directory / str(env_steps)}")
    if stopped == "interrupted":
        print_fn(f"{stop.signal_name or 'a stop request'}: checkpoint saved at {env_steps:,} env steps in "
                 f"{store.directory / str(env_steps)}; continue with: vmax-sim train --resume {run_dir}")
    final = final_ensemble = None
    carry, pool = carry.replace(buffer=None), None  # done with (the last checkpoint holds the buffer): evaluate without
    release_freed_memory()
    if finished:
        final = evaluator.run(distributed.local_copy(learner.policy_params(carry.learner)), env_steps, wall_s)
        if best is not None:
            best.offer(env_steps, final, carry, host_record(wall_s))
            print_fn(f"best held-out {best.score_name} {best.score:.3f}: its checkpoint is in {best.directory} "
                     f"(vmax-sim evaluate --policy {best.directory})")
        if ensemble is not None and is_ensemble(ensemble.directory):
            params, members = member_params(ensemble.store, carry.learner, learner.policy_params)
            final_ensemble = evaluator.run_ensemble(params, members, ensemble.directory)
        if primary:
            evaluator.plot(run_dir / "learning_curve.png", logger.rows)
    logger.close()
    rows = [row for row in logger.rows if "sps" in row]
    sps = float(np.median([row["sps"] for row in rows[1:]])) if len(rows) > 1 else math.nan
    summary = {"run_dir": str(run_dir), "algo": config.algo, "encoder": config.network.name,
               "reward": config.reward.preset, "env_steps": env_steps, "wall_s": wall_s,
               "median_env_steps_per_s": sps, "peak_rss_mb": peak_rss_mb(), "finished": finished,
               "stopped": stopped, "final_evaluation": final}
    if final_ensemble is not None:
        summary["ensemble_evaluation"] = final_ensemble
    if config.is_selfplay:
        summary["selfplay_evaluation"] = evaluator.selfplay_summary
    if primary:
        (run_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    return TrainResult(run_dir=run_dir, env_steps=env_steps, wall_s=wall_s, env_steps_per_s=sps,
                       final_evaluation=final, summary=summary, stopped=stopped)


def selfplay_env_and_act(config):
    """The self-play evaluation environment of a run's settings (every simulator step, as evaluation acts) and
    its learner's deterministic act(params, observation, key)."""
    learner = components(config)[1]
    # the policy drives every agent, and goals end episodes as GPUDrive's do, whatever the run trained with
    every_agent = dataclasses.replace(config.selfplay, rule_sdc=0.0, rule_agents=0.0, at_goal="leave")
    env = SelfPlayEnv(config.env, config.obs, config.reward, selfplay=every_agent)
    return env, _deterministic_act(learner)


@functools.lru_cache(maxsize=8)
def _deterministic_act(learner):
    return lambda params, observation, key: learner.act(params, observation, key, True)


class _Evaluator:
    """Held-out evaluation of the current policy with `vmax_sim.evaluation.evaluate` (one compilation for every
    evaluation of the run). The scenarios are converted again at each evaluation, one batch at a time: holding
    all of them converted (~190 MB for 100) for the whole run cost more memory than the seconds it saved."""

    def __init__(self, config: TrainConfig, eval_path: str, run_dir: Path, print_fn):
        self.config = config
        self.data = data_config(config, eval_path)
        self.policy = _policy_of(config)
        self.env_config = components(config)[0].env_config
        self.eval_path = eval_path
        self.log = RunLogger(run_dir, tensorboard=False, file_name="eval.csv", write=distributed.is_primary())
        self.print_fn = print_fn
        self.selfplay_summary: dict | None = None  # the last self-play evaluation (self-play runs)

    def truncate_after(self, env_steps: int) -> None:
        self.log.truncate_after(env_steps)

    def compile(self, learner_shapes) -> None:
        """Compiles the evaluation: one batch with zero parameters of the learner's shapes, results dropped."""
        from vmax_sim.evaluation.evaluate import evaluate

        params = jax.eval_shape(components(self.config)[1].policy_params, learner_shapes)
        evaluate(self.policy, self.data, data_config=self.data, env_config=self.env_config, obs_config=self.config.obs,
                 num_scenarios=self.data.batch_size, policy_params=jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype),
                                                                                 params))

    def rows(self) -> list[dict]:
        return self.log.rows

    def run(self, params, env_steps: int, wall_s: float) -> dict:
        from vmax_sim.evaluation.evaluate import evaluate

        result = evaluate(self.policy, self.data, data_config=self.data, env_config=self.env_config,
                          obs_config=self.config.obs, num_scenarios=self.config.train.eval_scenarios,
                          policy_params=params)
        summary = result.summary
        row = {"wall_s": float(wall_s), "accuracy": summary["accuracy"],
               "vmax_score": summary["vmax_score"], "nuplan_score": summary["nuplan_score"],
               "accuracy_at_fault": summary["accuracy_at_fault"]}
        row.update({k: float(v) for k, v in summary["metrics"].items() if v is not None and k in EVAL_COLUMNS})
        line = (f"eval @ {env_steps:,} env steps: accuracy {summary['accuracy']:.3f}  "
                f"V-Max score {summary['vmax_score']:.3f}  ({summary['num_episodes']} held-out episodes)")
        if self.config.is_selfplay:
            selfplay = self._selfplay(params)
            rates = {f"selfplay/{name}": selfplay[name] for name in SELFPLAY_COLUMNS}
            row.update(rates)
            summary = {**summary, **rates}  # the best checkpoint of a self-play run is ranked by its goal-reaching
            line += (f"; every agent: goal {selfplay['goal_reached']:.3f}  collision {selfplay['collision']:.3f}  "
                     f"off-road {selfplay['offroad']:.3f}  ({selfplay['num_agents']} agents)")
        self.log.log(env_steps, row)
        self.print_fn(line)
        return summary

    def run_ensemble(self, params, members: list[int], directory: Path) -> dict:
        """Held-out evaluation of the ensemble of `members` (their parameters stacked: `params`), printed, not
        logged in eval.csv. -> its summary, with the members' env steps"""
        from vmax_sim.evaluation.evaluate import evaluate
        from vmax_sim.evaluation.trained import trained_policy

        learner = ensemble_learner(components(self.config)[1], self.config.train.ensemble_rule)
        policy = trained_policy(learner, name=f"{self.policy.name}-ensemble", guard=brake_guard(self.config))
        summary = evaluate(policy, self.data, data_config=self.data, env_config=self.env_config,
                           obs_config=self.config.obs, num_scenarios=self.config.train.eval_scenarios,
                           policy_params=params).summary
        self.print_fn(f"ensemble of the policies at {', '.join(f'{m:,}' for m in members)} env steps: accuracy "
                      f"{summary['accuracy']:.3f}  V-Max score {summary['vmax_score']:.3f}  ({summary['num_episodes']} "
                      f"held-out episodes; vmax-sim evaluate --policy {directory})")
        return {**summary, "members": members}

    def _selfplay(self, params) -> dict:
        """One policy drives every agent of the held-out scenes (vmax_sim.evaluation.selfplay)."""
        from vmax_sim.evaluation.evaluate import scenario_batches
        from vmax_sim.evaluation.selfplay import evaluate_selfplay

        env, act = selfplay_env_and_act(self.config)
        settings = dataclasses.replace(self.data, include_agent_paths=True)
        batches = scenario_batches(self.eval_path, settings, self.config.train.eval_scenarios)
        self.selfplay_summary = evaluate_selfplay(env, act, params, batches).summary()
        return self.selfplay_summary

    def plot(self, path: Path, train_rows: list[dict]) -> None:
        from vmax_sim.training.plots import plot_learning_curve

        plot_learning_curve(path, self.rows(), train_rows, title=run_title(self.config, self.eval_path))


ALGORITHM_NAMES = {"sac": "SAC", "ppo": "PPO", "bc": "BC", "bc_sac": "BC+SAC"}


def run_title(config: TrainConfig, eval_path: str) -> str:
    """'BC (MLP encoder, navigation reward): shards/train -> 100 held-out scenarios of shards/eval': what was
    trained on what, for pictures."""
    train = config.data.train or f"{config.data.synthetic_train_scenarios} synthetic scenarios"
    held_out = "synthetic" if not config.data.eval else Path(eval_path).name
    return (f"{ALGORITHM_NAMES.get(config.algo, config.algo)} ({config.network.name.upper()} encoder, "
            f"{config.reward.preset} reward): {train} -> {config.train.eval_scenarios} held-out {held_out} scenarios")


@functools.lru_cache(maxsize=8)
def _policy_of(config: TrainConfig):
    """The evaluation Policy of a configuration's learner (cached: evaluate's rollout compiles once)."""
    from vmax_sim.evaluation.trained import trained_policy

    return trained_policy(components(config)[1], name=policy_name(config), guard=brake_guard(config))


SELFPLAY_COLUMNS = ("goal_reached", "collision", "offroad", "collision_or_offroad", "goal_reached_clean")
EVAL_COLUMNS = ("overlap", "offroad", "red_light", "off_route", "ego_progress", "comfort", "progress_ratio")
