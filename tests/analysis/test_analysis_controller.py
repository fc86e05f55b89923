"""Reading the controller JSON of ``oos synth`` (format of oos_drake.control.report)."""

import json

import numpy as np
import pytest

from oos_drake.analysis.controller import load_controller


def _write(path, K_p, K_d, **extra):
    record = {
        "controller": {
            "K_p": {"value": K_p, "unit": "N m/rad"},
            "K_d": {"value": K_d, "unit": "N m s/rad"},
        },
        "gamma": 0.4,
        **extra,
    }
    path.write_text(json.dumps(record))
    return path


def test_gains_spec_and_label(tmp_path):
    K_p = np.diag([1.0, 2.0, 3.0]).tolist()
    K_d = (10 * np.eye(3)).tolist()
    _write(
        tmp_path / "controller.json",
        K_p,
        K_d,
        design_specification={
            "additive_weight_db": -70.0,
            "rolloff_order": 4,
            "disturbance_gains": [0.1, 0.2, 0.3],
        },
    )
    c = load_controller(tmp_path)  # a directory works too
    np.testing.assert_array_equal(c.K, np.hstack([K_p, K_d]))
    assert c.label == "synthesized" and c.gamma == 0.4
    assert c.spec.additive_weight_db == -70.0
    assert c.spec.disturbance_gains == (0.1, 0.2, 0.3)
    with pytest.raises(ValueError):
        c.K[0, 0] = 5.0  # immutable


def test_bad_files_name_the_culprit(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        load_controller(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(ValueError, match="K_p"):
        load_controller(bad)
    wrong = _write(tmp_path / "wrong.json", [[1.0, 2.0]], np.eye(3).tolist())
    with pytest.raises(ValueError, match="3x3"):
        load_controller(wrong)
