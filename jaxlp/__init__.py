"""jaxlp: the 3LP walking model, periodic gaits, constrained DLQR and time projection in JAX."""
