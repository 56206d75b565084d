"""The documentation lists every study-file key the validator accepts."""

import re

from conftest import REPO
from wallcal import study, wallfile


def test_every_study_key_is_documented():
    doc = (REPO / "docs" / "study-file.md").read_text()
    documented = set(re.findall(r"`([a-z_]+)`", doc))
    tuples = [
        study.STUDY_KEYS,
        wallfile.WALL_KEYS,
        wallfile.LAYER_KEYS,
        wallfile.PROBE_KEYS,
        study.DATA_KEYS,
        study.BOUNDARY_KEYS,
        study.SENSOR_KEYS,
        study.PERIOD_KEYS,
        study.SIMULATION_KEYS,
    ]
    missing = sorted({k for t in tuples for k in t} - documented)
    assert not missing, f"undocumented study keys: {missing}"


def test_every_calibration_key_and_setting_is_documented():
    from wallcal.calibration import algorithms, space

    doc = (REPO / "docs" / "calibration.md").read_text()
    documented = set(re.findall(r"`([a-z_0-9-]+)`", doc))
    keys = set(space.CALIBRATION_KEYS) | set(space.PARAMETER_KEYS) | set(space.OBJECTIVES) | set(space.ALGORITHMS)
    keys |= set(algorithms.PSO_HJ_DEFAULTS)
    missing = sorted(keys - documented)
    assert not missing, f"undocumented calibration keys or settings: {missing}"
