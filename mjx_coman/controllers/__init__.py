"""The controller registry: every walking controller of the simulated COMAN, by name.

    from mjx_coman import controllers
    controllers.names()                                  # ('time-projection', 'open-loop', ...)
    ctrl, config = controllers.load("open-loop", {"hip_attack": 0.5})
    controllers.default_config("time-projection")        # the config pytree of the defaults

A family is one folder under ``mjx_coman/controllers/`` whose package exposes
``CONTROLLER`` (a :class:`~mjx_coman.controllers.base.Controller`); it is
imported on first use. A variant is a registered configuration of a family:
its name and other defaults, the same compiled functions. Adding a controller
is one folder and one :func:`register` line below; the contract test
(``tests/mjx_coman/controllers/test_contract.py``) runs every name.
"""

from __future__ import annotations

import functools
import importlib
from typing import Any, Mapping

from mjx_coman.controllers.base import (  # noqa: F401 - the interface, re-exported
    SUPPORT_DOUBLE,
    SUPPORT_LEFT,
    SUPPORT_RIGHT,
    Controller,
    Gait,
    Joystick,
    Observation,
    Setting,
    Telemetry,
    joystick,
)

_REGISTRY: dict[str, tuple[str, str, dict]] = {}  # name -> (family module, description, defaults)
_LOADED: dict[str, Controller] = {}
_STANDING: set[str] = set()  # names that do not walk (examples)


def register(name: str, family: str, description: str = "", *, walking: bool = True, **defaults) -> None:
    """Register ``name`` as the controller of the package ``family`` (its ``CONTROLLER``) with other defaults.

    ``walking=False`` marks a controller that does not walk (left out of the comparisons' defaults).
    """
    _REGISTRY[name] = (family, description, defaults)
    _LOADED.pop(name, None)
    (_STANDING.add if not walking else _STANDING.discard)(name)


def names(walking: bool = False) -> tuple[str, ...]:
    """Every registered controller name, in registration order (``walking=True``: only those that walk)."""
    return tuple(n for n in _REGISTRY if not (walking and n in _STANDING))


def get(name: str) -> Controller:
    """The registered controller (its family imported on first use).

    Raises:
        ValueError: an unknown name, listing the known ones.
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; choose one of {', '.join(names())}")
    if name not in _LOADED:
        module, description, defaults = _REGISTRY[name]
        base = importlib.import_module(module).CONTROLLER
        _LOADED[name] = base.variant(name, description, **defaults)
    return _LOADED[name]


def check_overrides(controller: Controller, overrides: Mapping[str, Any] | None) -> dict[str, Any]:
    """``overrides`` as a dict of known settings (values unchecked: ``make_config`` checks them).

    Raises:
        ValueError: an unknown setting, naming it and the known ones.
    """
    overrides = dict(overrides or {})
    known = controller.defaults()
    for key in overrides:
        if key not in known:
            raise ValueError(f"unknown setting {key!r} of controller {controller.name}; known: {', '.join(known)}")
    return overrides


_TRUE, _FALSE = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def parse_setting(setting: Setting, text: str):
    """The value of ``KEY=VALUE`` text for a setting, by the type of its default.

    Raises:
        ValueError: text that is not a value of that type, naming the setting.
    """
    d, t = setting.default, str(text).strip()
    try:
        if isinstance(d, bool):
            if t.lower() not in _TRUE + _FALSE:
                raise ValueError
            return t.lower() in _TRUE
        if isinstance(d, int):
            return int(t)
        if isinstance(d, tuple):
            return tuple(float(v) for v in t.split(","))
        if d is None:
            return None if t.lower() == "none" else float(t)
        if isinstance(d, float):
            return float(t)
        return t
    except ValueError:
        kind = ("true/false" if isinstance(d, bool) else "a whole number" if isinstance(d, int)
                else "comma-separated numbers" if isinstance(d, tuple) else "a number or none" if d is None
                else "a number")
        raise ValueError(f"setting {setting.name}={text!r} must be {kind}") from None


def parse_overrides(controller: Controller, items) -> dict[str, Any]:
    """``{"KEY": value}`` from ``["KEY=VALUE", ...]`` (the command lines' ``--set``), typed by the settings.

    Raises:
        ValueError: a malformed item or an unknown key, naming it.
    """
    by_name = {s.name: s for s in controller.settings}
    out = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--set {item!r} must be KEY=VALUE")
        if key not in by_name:
            raise ValueError(f"unknown setting {key!r} of controller {controller.name}; known: {', '.join(by_name)}")
        out[key] = parse_setting(by_name[key], text)
    return out


def _freeze(v):
    return tuple(_freeze(x) for x in v) if isinstance(v, (list, tuple)) else v


@functools.lru_cache(maxsize=64)
def _build(name: str, items: tuple, x64: bool):
    import jax

    ctrl = get(name)
    with jax.ensure_compile_time_eval():  # concrete arrays even when first asked for inside a trace
        return ctrl.make_config(**{**ctrl.defaults(), **dict(items)})


def load(name: str, overrides: Mapping[str, Any] | None = None) -> tuple[Controller, Any]:
    """The controller ``name`` and its config with ``overrides`` (built once per value set and precision).

    Raises:
        ValueError: an unknown name or setting, or a bad value (naming it).
    """
    import jax

    ctrl = get(name)
    items = tuple(sorted((k, _freeze(v)) for k, v in check_overrides(ctrl, overrides).items()))
    return ctrl, _build(name, items, bool(jax.config.jax_enable_x64))


def default_config(name: str) -> Any:
    """The config of ``name`` with its registered defaults."""
    return load(name)[1]


def describe(name: str) -> dict:
    """A JSON-ready description: name, description, privileged, and every setting with its default."""
    c = get(name)
    return dict(name=name, description=c.description, privileged=c.privileged, walking=name not in _STANDING,
                settings=[dict(name=s.name, default=list(s.default) if isinstance(s.default, tuple) else s.default,
                               tunable=s.tunable, bounds=None if s.bounds is None else list(s.bounds), help=s.help)
                          for s in c.settings])


# --- the registry -----------------------------------------------------------------------------------
_TP = "mjx_coman.controllers.time_projection"
register("time-projection", _TP, "seed 000: 3LP time projection, footstep adjustment at every tick")
register("open-loop", _TP, "seed 000 without footstep adjustment (adaptive lift and foot pitch stay)",
         footstep_gain=0.0)
register("no-deadzone", _TP, "time projection without the dead-zones of eq. 27 (thresholds 1e-7)",
         deadzone=(1e-7, 1e-7, 1e-7, 1e-7))
register("dlqr", _TP, "seed 000's baseline: the DLQR adjustment of the phase start, held for the phase",
         hold_adjustment=1.0)
register("joint-pd", "mjx_coman.controllers.joint_pd", "example: stands still by joint-space PD on the motor encoders",
         walking=False)
register("wbc-stand", "mjx_coman.controllers.wbc_stand", "stands by the whole-body QP on the ideal-torque robot",
         walking=False)
register("wbc-stand-sea", "mjx_coman.controllers.wbc_stand", "wbc-stand through the series-elastic torque loop",
         walking=False, plant="torque-sea")
_FM = "mjx_coman.controllers.footstep_mpc"
register("footstep-mpc", _FM, "seed 001: LIPM footstep MPC with steering over the whole-body QP, ideal torques")
_SL = "mjx_coman.controllers.straight_leg"
register("straight-leg", _SL, "seed 004: ICP walking with straight knees in the QP's null space, ideal torques")
register("straight-leg-no-toe-off", _SL, "straight-leg with both feet flat in transfer", toe_off=False)
register("bent-knee", _SL, "seed 004's baseline: the same ICP controller holding the crouched CoM height",
         knee_mode="bent")
register("straight-leg-step-adjust", _SL, "straight-leg moving its footsteps by the ICP error its CMP cannot null",
         step_adjust=True)
