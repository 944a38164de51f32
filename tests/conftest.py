"""Test-wide settings: the XLA CPU flags of :mod:`jaxlp.xla_flags`, set before JAX starts."""

from jaxlp.xla_flags import configure_cpu

configure_cpu()
