"""A checkpoint written on other devices (a run trained on a GPU, evaluated on a laptop's CPU) restores here."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.training.checkpoint import CheckpointStore

# Written in a process with two CPU devices, the learner on the second: its saved sharding names a device this
# process does not have, as a GPU's does on a CPU-only machine.
WRITER = textwrap.dedent("""
    import sys
    import jax, jax.numpy as jnp
    from vmax_sim.training.checkpoint import CheckpointStore
    import orbax.checkpoint as ocp
    second = jax.sharding.SingleDeviceSharding(jax.devices()[1])
    learner = {"w": jax.device_put(jnp.arange(6.0).reshape(2, 3), second), "step": jax.device_put(jnp.int32(7), second)}
    store = CheckpointStore(sys.argv[1])
    store.manager.save(100, args=ocp.args.Composite(learner=ocp.args.StandardSave(learner)), force=True)
    store.manager.wait_until_finished()
""")


def test_a_learner_saved_on_devices_this_machine_lacks_restores(tmp_path):
    environment = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}
    written = subprocess.run([sys.executable, "-c", WRITER, str(tmp_path / "checkpoints")], env=environment,
                             capture_output=True, text=True, timeout=300)
    assert written.returncode == 0, written.stderr[-2000:]
    assert len(jax.devices()) == 1  # this process: one device, so the saved one (its second) does not exist here
    like = jax.eval_shape(lambda: {"w": jnp.zeros((2, 3)), "step": jnp.int32(0)})  # shapes with no sharding
    restored = CheckpointStore(tmp_path / "checkpoints").restore_learner(100, like)
    np.testing.assert_array_equal(np.asarray(restored["w"]), np.arange(6.0).reshape(2, 3))
    assert int(restored["step"]) == 7
