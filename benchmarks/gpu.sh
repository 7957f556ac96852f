#!/usr/bin/env bash
# One call on a lent GPU machine (the `device` tool runs it in the repository root): install, then the simulator
# bench, the training throughput rows and a short learning run, everything under $OUT (or ./gpu-results).
# Budget: ~10 minutes; each stage has its own timeout so one slow stage cannot eat the others.
# Usage: bash benchmarks/gpu.sh [LEARN_MINUTES]   (default 4)
set -uo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-gpu-results}"
mkdir -p "$out"
learn_minutes="${1:-4}"
log() { echo "[$(date +%H:%M:%S)] $*" | tee -a "$out/gpu.log"; }

log "install"
python3 -m venv /tmp/vmax-gpu-venv && /tmp/vmax-gpu-venv/bin/pip install -q -e '.[sim]' 'jax[cuda12]' \
  >>"$out/gpu.log" 2>&1 || log "install failed (see gpu.log)"
py=/tmp/vmax-gpu-venv/bin/python
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv >"$out/device.txt" 2>&1
$py -c "import jax; print(jax.devices())" >>"$out/device.txt" 2>&1

log "simulator bench (batches up to 4096)"
timeout 180 /tmp/vmax-gpu-venv/bin/vmax-sim bench --batch-sizes 1,32,1024,4096 --json >"$out/bench.json" 2>>"$out/gpu.log"

log "training throughput rows (SAC, PPO, BC)"
timeout 180 $py benchmarks/training.py --json --chunks 4 --only "sac-mlp,ppo-mlp,bc-mlp" \
  >"$out/training.json" 2>>"$out/gpu.log"

log "self-play throughput rows (the CPU table's: 8 x 8, 16 x 8 and 4 x 32 scenes x agent slots)"
timeout 240 $py benchmarks/training.py --json --chunks 4 --only "ppo-selfplay selfplay.max_agents=8,\
ppo-selfplay selfplay.max_agents=8 algo.num_envs=16,ppo-selfplay selfplay.max_agents=32 algo.num_envs=4" \
  >"$out/selfplay.json" 2>>"$out/gpu.log"

log "a short learning run (default preset, ${learn_minutes} min wall-clock budget)"
timeout $(( learn_minutes * 60 + 150 )) /tmp/vmax-gpu-venv/bin/vmax-sim train --out "$out/learn" --quiet \
  data.synthetic_train_scenarios=200 train.max_wall_minutes="$learn_minutes" train.total_env_steps=100000000 \
  >"$out/learn.log" 2>&1
cp "$out/learn/summary.json" "$out/learn_summary.json" 2>/dev/null
log "done"
