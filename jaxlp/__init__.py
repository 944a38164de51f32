"""jaxlp: the 3LP walking model, periodic gaits, constrained DLQR and time projection in JAX."""

from jaxlp.xla_flags import configure_cpu as _configure_cpu

_configure_cpu()
