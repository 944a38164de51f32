"""The ``mjx`` model's environment: the nominal robot on a controller's plant, on either engine (shared by
:mod:`sweeps.models.mjx` and :mod:`sweeps.models.mjx_tune`; ``mjx_coman`` imported lazily)."""

from __future__ import annotations

import dataclasses
import functools

import jax


def _controllers():
    from mjx_coman import controllers

    return controllers


def _rollout_module():
    from mjx_coman import rollout

    return rollout


def nominal_env(sensor_noise_scale: float, plant: str = "position", engine: str = "mjx"):
    """The nominal robot's environment parameters on a controller's plant (``Gait.plant``:
    :func:`mjx_coman.rollout.plant_env_params`) with the sensor noise scaled, stepped by ``engine``
    (host-built, cached per float width)."""
    return _nominal_env(float(sensor_noise_scale), str(plant), bool(jax.config.jax_enable_x64), str(engine))


@functools.lru_cache(maxsize=8)
def _nominal_env(sensor_noise_scale: float, plant: str, x64: bool, engine: str):
    from mjx_coman.env import use_engine
    from mjx_coman.sensors import make_sensor_params

    if engine != "mjx":
        return use_engine(_nominal_env(sensor_noise_scale, plant, x64, "mjx"), engine)

    with jax.ensure_compile_time_eval():
        s = sensor_noise_scale
        d = make_sensor_params()
        sensor = make_sensor_params(imu_orientation_noise_rad=float(d.imu_orientation_noise_rad) * s,
                                    gyro_noise_rad_per_s=float(d.gyro_noise_rad_per_s) * s,
                                    ft_force_noise_n=float(d.ft_force_noise_n) * s,
                                    ft_torque_noise_nm=float(d.ft_torque_noise_nm) * s)
        return dataclasses.replace(_rollout_module().plant_env_params(plant), sensor=sensor)
