"""The XLA options jaxgrasp compiles with exist in the XLA that runs.

XLA refuses to compile with an option it does not know (``No such compile option``), and
its options come and go between jaxlib releases: jaxlib 0.11 dropped
``xla_cpu_use_fusion_emitters``, and every executable failed to compile with it.
"""

import jax
import jax.numpy as jnp
import pytest

from jaxgrasp.engine._xla_options import COMPILER_OPTIONS, LATENCY_CPU_OPTIONS


@pytest.mark.parametrize("options", [COMPILER_OPTIONS, LATENCY_CPU_OPTIONS], ids=["compiler", "latency_cpu"])
@pytest.mark.parametrize("platform", sorted({"cpu", jax.default_backend()}))
def test_every_option_is_known_to_this_xla(options, platform):
    device = jax.devices(platform)[0]
    x = jax.device_put(jnp.arange(3.0), device)
    fn = jax.jit(lambda a: jnp.sum(a * 2.0 + 1.0), compiler_options=options)
    assert float(fn(x)) == 9.0  # 1 + 3 + 5
