"""Atomic writes and strict JSON (jaxlp.files)."""

import json

import numpy as np
import pytest

from jaxlp.files import save_bytes_atomic, save_text_atomic, strict_json


def test_strict_json_turns_non_finite_numbers_into_null_and_numpy_into_python():
    text = strict_json({"a": float("nan"), "b": [np.float32(np.inf), np.int64(3), np.bool_(True)], "c": (1.5,)})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {"a": None, "b": [None, 3, True], "c": [1.5]}


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "out.json"
    save_text_atomic(path, "old")
    with pytest.raises(TypeError):
        save_bytes_atomic(path, "not bytes")  # the write fails inside
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["out.json"]
