#!/usr/bin/env bash
# One call on a lent GPU machine (the `device` tool runs it in the repository root): install, then the self-play
# throughput rows, the simulator bench, the SAC and PPO throughput rows and a short learning run, everything
# under $OUT (or ./gpu-results). Most wanted first: a stage cut off by its timeout leaves the earlier ones' files.
# Budget: ~9.6 minutes of stages (timeouts below) plus the install; run it with the device tool's timeout_s=600.
#
# Install: the lent machines reach no package index, but their image holds Python 3.12 with JAX (CUDA), Flax, Optax,
# Orbax, NumPy, SciPy, Matplotlib...; what it lacks travels as wheels in .whl/ (git-ignored; `carry: [".whl"]`):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 -d .whl shapely google-crc32c tensorboardX orjson
# With no .whl/ it installs from the network instead (`pip install -e .[sim] jax[cuda12]`).
# Usage: bash benchmarks/gpu.sh [LEARN_MINUTES] [STAGES]   (default 0.5, "rows bench training learn")
#   STAGES, any of: rows (self-play throughput), bench (simulator), training (SAC / PPO throughput),
#   learn (the default preset for LEARN_MINUTES; its RUN/ensemble comes back as learn_ensemble.tgz.*:
#   `cat learn_ensemble.tgz.* | tar xz` here, then `vmax-sim evaluate --policy ensemble --data REAL_SHARDS`), selfplay (self-play PPO taught by IDM, 64 scenes x 8 agents, for LEARN_MINUTES)
set -uo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-gpu-results}"
mkdir -p "$out"
learn_minutes="${1:-0.5}"
stages=" ${2:-rows bench training learn} "
want() { [[ "$stages" == *" $1 "* ]]; }
site=/tmp/vmax-gpu-site
log() { echo "[$(date +%H:%M:%S)] $*" | tee -a "$out/gpu.log"; }
export PYTHONUNBUFFERED=1 VMAX_CACHE_DIR=/tmp/vmax-gpu-cache
small="data.synthetic_train_scenarios=200"  # every stage shares one generated split (the default 2,000 take minutes)

log "install"
if [ -d .whl ]; then  # into a folder on PYTHONPATH: the image's python3 is itself a venv, which a new venv would not see
  python3 -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --target "$site" .whl/*.whl . \
    >>"$out/gpu.log" 2>&1 || log "install failed (see gpu.log)"
  export PYTHONPATH="$site" PATH="$site/bin:$PATH"
  py=python3
else
  python3 -m venv /tmp/vmax-gpu-venv && /tmp/vmax-gpu-venv/bin/pip install -q -e '.[sim]' 'jax[cuda12]' \
    >>"$out/gpu.log" 2>&1 || log "install failed (see gpu.log)"
  export PATH="/tmp/vmax-gpu-venv/bin:$PATH"
  py=/tmp/vmax-gpu-venv/bin/python
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv >"$out/device.txt" 2>&1
"$py" -c "import jax, flax, optax; print(jax.__version__, flax.__version__, optax.__version__, jax.devices())" \
  >>"$out/device.txt" 2>&1
nproc >>"$out/device.txt"
cat "$out/device.txt"

# a stage cut off by `timeout` leaves benchmarks/training.py's child (and its GPU memory) behind: end it
stop_children() { pkill -f "benchmarks/training.py" 2>/dev/null; sleep 1; }

want rows && log "self-play throughput rows: the CPU table's 8 x 8, then 256 x 32 scenes x agent slots" &&
timeout 200 "$py" benchmarks/training.py --chunks 3 --only "ppo-selfplay selfplay.max_agents=8,\
ppo-selfplay selfplay.max_agents=32 algo.num_envs=256" \
  "$small" 2>>"$out/gpu.log" | tee "$out/selfplay.txt"
stop_children

want bench && log "simulator bench (batches 32 to 4096)" &&
timeout 70 vmax-sim bench --batch-sizes 32,1024,4096 2>>"$out/gpu.log" | tee "$out/bench.txt"

want training && log "training throughput rows (SAC and PPO, MLP encoder)" &&
timeout 150 "$py" benchmarks/training.py --chunks 3 --only "sac-mlp,ppo-mlp" "$small" \
  2>>"$out/gpu.log" | tee "$out/training.txt"
stop_children

# the budget counts from the first training chunk: generating the splits and compiling come before it (~90 s)
budget() { python3 -c "print(int(${learn_minutes} * 60 + ${1}))"; }
if want learn; then
  log "a learning run: the default preset, ${learn_minutes} min wall-clock budget, its own 2,000-scene split"
  timeout "$(budget 240)" vmax-sim train --out /tmp/vmax-gpu-learn --quiet train.max_wall_minutes="$learn_minutes" \
    train.total_env_steps=100000000 >"$out/learn.log" 2>&1
  tail -8 "$out/learn.log"
  cp /tmp/vmax-gpu-learn/summary.json "$out/learn_summary.json" 2>/dev/null
  # the ensemble's checkpoints (~25 MB) in pieces under the 16 MB a returned file may have: `cat | tar xz` here
  [ -d /tmp/vmax-gpu-learn/ensemble ] && tar czf - -C /tmp/vmax-gpu-learn ensemble | split -b 15m - "$out/learn_ensemble.tgz."
fi
if want selfplay; then
  log "self-play PPO taught by IDM (64 scenes x 8 agents), ${learn_minutes} min wall-clock budget"
  timeout "$(budget 240)" vmax-sim train --preset ppo-selfplay --out /tmp/vmax-gpu-selfplay --quiet \
    algo.num_envs=64 train.max_wall_minutes="$learn_minutes" train.total_env_steps=100000000 \
    >"$out/selfplay_learn.log" 2>&1
  tail -8 "$out/selfplay_learn.log"
  cp /tmp/vmax-gpu-selfplay/summary.json "$out/selfplay_summary.json" 2>/dev/null
  cp /tmp/vmax-gpu-selfplay/eval.csv "$out/selfplay_eval.csv" 2>/dev/null
fi
log "done"
