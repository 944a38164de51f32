"""The controller registry: names, variants as configurations, overrides, errors naming the bad value."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman.controllers.base import Setting


def test_names_cover_the_seed_000_variants_and_the_example():
    assert {"time-projection", "open-loop", "no-deadzone", "dlqr", "joint-pd"} <= set(controllers.names())


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown controller 'nope'.*time-projection.*joint-pd"):
        controllers.get("nope")


def test_variants_share_the_family_functions_and_differ_in_their_defaults():
    tp, ol, dl = (controllers.get(n) for n in ("time-projection", "open-loop", "dlqr"))
    assert tp.core() == ol.core() == dl.core() and controllers.get("joint-pd").core() != tp.core()
    assert ol.defaults()["footstep_gain"] == 0.0 and tp.defaults()["footstep_gain"] == 1.0
    assert dl.defaults()["hold_adjustment"] == 1.0 and tp.defaults()["hold_adjustment"] == 0.0
    diff = {k for k in tp.defaults() if tp.defaults()[k] != ol.defaults()[k]}
    assert diff == {"footstep_gain"}


def test_load_applies_overrides_to_the_tunables():
    _, base = controllers.load("time-projection")
    _, cfg = controllers.load("time-projection", {"hip_attack": 0.5, "deadzone": [0.01, 0.01, 0.1, 0.1]})
    assert float(cfg.hip_attack) == 0.5 and np.allclose(cfg.deadzone, 0.01 * np.array([1, 1, 10, 10]))
    np.testing.assert_array_equal(np.asarray(cfg.footstep_table), np.asarray(base.footstep_table))
    assert float(base.hip_attack) == 0.75  # the defaults' config is untouched
    again = controllers.load("time-projection", {"deadzone": (0.01, 0.01, 0.1, 0.1), "hip_attack": 0.5})[1]
    assert again is cfg  # built once per value set


@pytest.mark.parametrize("overrides, word", [
    ({"nope": 1.0}, "nope"),
    ({"hip_attack": 1.5}, "hip_attack"),
    ({"deadzone": [0.1, 0.1]}, "deadzone"),
    ({"zeta": float("nan")}, "zeta"),
    ({"window": 0}, "window"),
])
def test_a_bad_override_is_a_value_error_naming_it(overrides, word):
    with pytest.raises(ValueError, match=word):
        controllers.load("time-projection", overrides)


@pytest.mark.parametrize("text, expected", [
    ("zeta=0.2", {"zeta": 0.2}), ("window=12", {"window": 12}), ("deadzone=1,2,3,4", {"deadzone": (1.0, 2.0, 3.0, 4.0)}),
    ("max_adjustment_m=none", {"max_adjustment_m": None}), ("max_adjustment_m=0.1", {"max_adjustment_m": 0.1}),
    ("robot=coman", {"robot": "coman"}),
])
def test_set_items_are_typed_by_the_defaults(text, expected):
    assert controllers.parse_overrides(controllers.get("time-projection"), [text]) == expected


@pytest.mark.parametrize("text, word", [("zeta", "KEY=VALUE"), ("nope=1", "nope"), ("window=1.5", "window"),
                                        ("zeta=fast", "zeta"), ("deadzone=a,b", "deadzone")])
def test_bad_set_items_name_the_problem(text, word):
    with pytest.raises(ValueError, match=word):
        controllers.parse_overrides(controllers.get("time-projection"), [text])


def test_bool_settings_parse_true_and_false():
    s = Setting("flag", False, "a switch")
    assert controllers.parse_setting(s, "true") is True and controllers.parse_setting(s, "0") is False
    with pytest.raises(ValueError, match="flag"):
        controllers.parse_setting(s, "maybe")


def test_describe_is_json_with_every_setting():
    for name in controllers.names():
        d = json.loads(json.dumps(controllers.describe(name)))
        assert d["name"] == name and d["settings"]
        assert {s["name"] for s in d["settings"]} == set(controllers.get(name).defaults())
        assert any(s["tunable"] for s in d["settings"])


def test_registering_a_variant_is_one_line():
    controllers.register("stiff-pd", "mjx_coman.controllers.joint_pd", "a stiffer example", gain=1.5)
    try:
        ctrl, cfg = controllers.load("stiff-pd")
        assert ctrl.name == "stiff-pd" and float(cfg.gain) == 1.5 and "stiff-pd" in controllers.names()
        with pytest.raises(ValueError, match="gain"):
            controllers.load("stiff-pd", {"gain": 5.0})
    finally:
        controllers._REGISTRY.pop("stiff-pd")
        controllers._LOADED.pop("stiff-pd", None)


def test_a_variant_of_an_unknown_setting_is_refused():
    with pytest.raises(ValueError, match="bogus"):
        controllers.get("joint-pd").variant("x", bogus=1.0)
