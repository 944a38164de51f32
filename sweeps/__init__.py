"""Push-recovery sweeps: basin maps over push timing x impulse, controller comparisons.

``coman-sweep map`` / ``coman-sweep compare`` (see :mod:`sweeps.cli`). Modules:
:mod:`sweeps.grid` (configuration, grid), :mod:`sweeps.models` (rollout
registry), :mod:`sweeps.runner` (chunks, sharding, resume), :mod:`sweeps.report`
(csv, png, json). Importing this package does not import JAX.
"""

from jaxlp.xla_flags import configure_cpu

configure_cpu()  # every entry point imports this package first: the XLA CPU flags before JAX starts
