"""Property-based tests of the study-file reader (issue 10).

Each example starts from the bundled example's TOML dict and corrupts one random key path
(wrong type, missing key, extra key, NaN/inf, negative/zero/huge numbers, a table replaced
by a scalar...). The property: :func:`wallcal.study.parse_study` either accepts the study
or raises :class:`wallcal.errors.StudyError` naming the corrupted key path - never any
other exception. Random *valid* studies (random layer stacks and probe depths) load and
simulate. A few corrupted files go through the CLI: exit 2, a ``wallcal: error:`` message
and no traceback.
"""

from __future__ import annotations

import copy
import datetime as dt
import math
import tomllib

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import EXAMPLE
from wallcal.cli import main
from wallcal.errors import StudyError, WallcalError
from wallcal.study import parse_study

RAW = tomllib.loads(EXAMPLE.read_text())
BASE = EXAMPLE.parent
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------------------- key paths of the example
def _leaves(node, path=""):
    """(key path, value) of every leaf and table of the example, in wallcal's key-path notation."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            p = f"{path}.{k}" if path else k
            out.append((p, v))
            out.extend(_leaves(v, p))
    elif isinstance(node, list) and node and isinstance(node[0], dict):
        for i, v in enumerate(node):
            p = f"{path}[{i}]"
            out.append((p, v))
            out.extend(_leaves(v, p))
    return out


# every key, [calibration] included (validated at load with the others)
PATHS = _leaves(RAW)
LEAVES = [(p, v) for p, v in PATHS if not isinstance(v, (dict, list))]
# keys that must be there (deleting them is an error at that path)
REQUIRED = {
    "wall",
    "wall.layers",
    "data",
    "data.file",
    "boundary",
    "boundary.exterior",
    "boundary.interior",
    "period",
    "period.start",
    "period.end",
    "sensors",
}
REQUIRED_LEAF_NAMES = {
    "id",
    "thickness",
    "conductivity",
    "density",
    "specific_heat",
    "name",
    "depth",
    "type",
    "column",
    "face",
}
# numbers that must be > 0 (zero and negative values are errors)
POSITIVE = {
    "thickness",
    "conductivity",
    "density",
    "specific_heat",
    "accuracy",
    "accuracy_relative",
    "max_gap",
    "time_step",
    "grid_constant",
}


def _split(path):
    """'wall.layers[2].conductivity' -> ['wall', 'layers', 2, 'conductivity']."""
    keys = []
    for part in path.split("."):
        while "[" in part:
            head, rest = part.split("[", 1)
            if head:
                keys.append(head)
            idx, part = rest.split("]", 1)
            keys.append(int(idx))
        if part:
            keys.append(part)
    return keys


def _set(raw, path, value=None, delete=False):
    keys = _split(path)
    node = raw
    for k in keys[:-1]:
        node = node[k]
    if delete:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value


def _parse(raw):
    """parse_study, turning any exception that is not wallcal's own into a test failure."""
    try:
        return parse_study(raw, base_dir=BASE), None
    except WallcalError as exc:
        return None, exc
    except Exception as exc:  # pragma: no cover - this is what the tests look for
        pytest.fail(f"parse_study raised {type(exc).__name__} (not a WallcalError): {exc!r}")


def _assert_names(exc, path):
    assert isinstance(exc, StudyError), exc
    assert any(p.startswith(path) for p in exc.problems), (path, exc.problems)


# ---------------------------------------------------------------------------- value strategies
WRONG_FOR_STRING = st.one_of(
    st.integers(-5, 5).filter(lambda i: True),
    st.floats(allow_nan=True),
    st.booleans(),
    st.lists(st.integers(), max_size=2),
    st.just({"a": 1}),
)
WRONG_FOR_NUMBER = st.one_of(
    st.text(max_size=5),
    st.booleans(),
    st.lists(st.floats(), max_size=2),
    st.just({"x": 1.0}),
    st.just(dt.datetime(2025, 1, 1)),
)
WRONG_FOR_DATETIME = st.one_of(
    st.integers(),
    st.floats(),
    st.booleans(),
    st.lists(st.integers(), max_size=2),
    st.sampled_from(["yesterday", "2025-13-01", "2025-05-30T25:00", ""]),
    st.just(dt.datetime(2025, 5, 30, tzinfo=dt.timezone(dt.timedelta(hours=2)))),
    st.just(dt.time(12, 0)),
)
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])
HUGE = st.sampled_from([1e300, -1e300, 1e16, 10**30, -(10**30), 10**400])


def _wrong_type(value):
    if isinstance(value, bool):
        return st.one_of(st.text(max_size=5), st.integers(), st.floats())
    if isinstance(value, (int, float)):
        return WRONG_FOR_NUMBER
    if isinstance(value, dt.datetime):
        return WRONG_FOR_DATETIME
    return WRONG_FOR_STRING


@st.composite
def corruption(draw):
    """(kind, path, corrupted raw dict, must_fail)."""
    raw = copy.deepcopy(RAW)
    kind = draw(
        st.sampled_from(
            [
                "wrong_type",
                "missing",
                "extra",
                "non_finite",
                "negative",
                "zero",
                "huge",
                "table_to_scalar",
                "bad_choice",
            ]
        )
    )
    if kind == "extra":
        path, node = draw(st.sampled_from([(p, v) for p, v in PATHS if isinstance(v, dict)] + [("", raw)]))
        key = draw(st.sampled_from(["thikness", "conductivty", "colum", "engine_", "foo", "Start", "units"]))
        target = raw if path == "" else None
        if target is None:
            target = raw
            for k in _split(path):
                target = target[k]
        target[key] = draw(st.one_of(st.integers(), st.text(max_size=4)))
        return kind, (f"{path}.{key}" if path else key), raw, True
    if kind == "missing":
        path, _ = draw(st.sampled_from(PATHS))
        _set(raw, path, delete=True) if not path.endswith("]") else _set(raw, path, delete=True)
        keys = _split(path)
        in_list = len(keys) >= 3 and isinstance(keys[-2], int)  # a key of a layer, probe or sensor
        must = (
            path in REQUIRED
            or (in_list and keys[-1] in REQUIRED_LEAF_NAMES)
            or (keys[0] == "boundary" and keys[-1] in ("type", "column"))
        )
        return kind, path, raw, must
    if kind == "table_to_scalar":
        path, _ = draw(st.sampled_from([(p, v) for p, v in PATHS if isinstance(v, dict)]))
        _set(raw, path, draw(st.one_of(st.integers(), st.text(max_size=4), st.booleans())))
        return kind, path, raw, True
    if kind == "bad_choice":
        path, _ = draw(
            st.sampled_from([(p, v) for p, v in LEAVES if _split(p)[-1] in ("type", "engine", "quantity", "face")])
        )
        _set(raw, path, draw(st.sampled_from(["fd-cnn", "surface", "temp", "interor", "", "FD-CN"])))
        return kind, path, raw, True
    if kind == "wrong_type":
        path, value = draw(st.sampled_from(LEAVES))
        new = draw(_wrong_type(value))
        if _split(path)[-1] == "id" and isinstance(new, int) and not isinstance(new, bool):
            new = [new]  # an integer id is accepted (turned into a string)
        _set(raw, path, new)
        return kind, path, raw, True
    # numeric corruptions
    numeric = [(p, v) for p, v in LEAVES if isinstance(v, (int, float)) and not isinstance(v, bool)]
    path, value = draw(st.sampled_from(numeric))
    name = _split(path)[-1]
    if kind == "non_finite":
        _set(raw, path, draw(NON_FINITE))
        return kind, path, raw, True
    if kind == "huge":
        _set(raw, path, draw(HUGE))
        return kind, path, raw, True
    if kind == "zero":
        _set(raw, path, 0.0)
        return kind, path, raw, name in POSITIVE
    _set(raw, path, -abs(value) - draw(st.floats(0.0, 10.0)))  # negative
    return kind, path, raw, name in POSITIVE or name == "depth"


# ---------------------------------------------------------------------------- properties
def test_example_is_valid():
    study, exc = _parse(copy.deepcopy(RAW))
    assert exc is None and study is not None
    assert len(LEAVES) > 60  # every layer, probe, sensor, boundary, period and simulation key is fuzzed


@FUZZ
@given(corruption())
def test_corrupted_study_names_the_key_path(case):
    kind, path, raw, must_fail = case
    study, exc = _parse(raw)
    if exc is None:
        assert not must_fail, f"{kind} at {path} was accepted"
        return
    _assert_names(exc, path) if must_fail else None
    # every problem starts with a key path (or names the study as incomplete)
    for p in exc.problems:
        assert ":" in p and "Traceback" not in p, p


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(PATHS), min_size=2, max_size=5, unique_by=lambda pv: pv[0]), st.data())
def test_several_corruptions_are_reported_together(targets, data):
    """Wrong types at several unrelated leaves: every one is reported in the same error."""
    raw = copy.deepcopy(RAW)
    leaves = [(p, v) for p, v in targets if not isinstance(v, (dict, list))]
    # keep leaves that are not inside one another and not a layer id (ints accepted there)
    leaves = [(p, v) for p, v in leaves if _split(p)[-1] != "id"]
    for p, v in leaves:
        _set(raw, p, data.draw(st.sampled_from([[1, 2], {"k": 1}]) if not isinstance(v, dict) else st.just(3)))
    study, exc = _parse(raw)
    if not leaves:
        return
    assert exc is not None
    for p, _ in leaves:
        _assert_names(exc, p)


# ---------------------------------------------------------------------------- random valid studies
MATERIALS = [  # (conductivity, density, specific heat)
    (0.035, 40.0, 1030.0),
    (0.2, 530.0, 1600.0),
    (0.8, 1800.0, 840.0),
    (2.0, 2400.0, 1000.0),
    (0.13, 500.0, 1600.0),
    (50.0, 7800.0, 450.0),
    (0.021, 30.0, 1400.0),
]


@st.composite
def valid_study(draw):
    n = draw(st.integers(1, 6))
    layers = []
    for i in range(n):
        if draw(st.integers(0, 5)) == 0 and n > 1:
            layers.append(
                {
                    "id": f"L{i}",
                    "thermal_resistance": draw(st.floats(0.05, 0.5)),
                    "thickness": draw(st.sampled_from([0.0, 0.02])),
                }
            )
            continue
        lam, rho, c = draw(st.sampled_from(MATERIALS))
        f = draw(st.floats(0.5, 2.0))
        layer = {
            "id": i if draw(st.booleans()) else f"L{i}",
            "thickness": draw(st.floats(0.001, 0.3)),
            "conductivity": lam * f,
            "density": rho * f,
            "specific_heat": c,
        }
        if draw(st.booleans()):
            layer["contact_resistance"] = draw(st.floats(0.0, 0.1))
        layers.append(layer)
    total = sum(layer["thickness"] for layer in layers)
    probes = [{"name": name, "depth": draw(st.floats(0.0, 1.0)) * total} for name in ("T3A", "T2A", "T1A")]
    raw = copy.deepcopy(RAW)
    raw["wall"] = {"layers": layers, "probes": probes}
    raw["data"]["file"] = str(EXAMPLE.parent / "measured.csv")
    raw["period"] = {
        "warmup_start": dt.datetime(2025, 5, 29),
        "start": dt.datetime(2025, 5, 30),
        "end": dt.datetime(2025, 5, 30, 12),
    }
    raw["simulation"] = {
        "engine": draw(st.sampled_from(["fd-cn", "fd-implicit"])),
        "time_step": draw(st.sampled_from([10.0, 60.0, 300.0, 900.0, 3600.0])),
        "grid_constant": draw(st.floats(0.5, 5.0)),
    }
    raw.pop("calibration")
    return raw


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(raw=valid_study())
def test_random_valid_studies_load_and_simulate(raw, tmp_path_factory):
    from wallcal.simulation import simulate

    study, exc = _parse(raw)
    assert exc is None, exc
    # and it survives a TOML round trip
    d = tmp_path_factory.mktemp("valid")
    (d / "study.toml").write_text(tomli_w.dumps(raw))
    res = simulate(study)
    sim = res.simulated.to_numpy()
    assert np.isfinite(sim).all()
    # Discrete maximum principle with Dirichlet faces (TSe, TSi): every temperature stays between the extreme
    # boundary values (the initial state, the steady state of the first values, lies between them too; the
    # engine's boundary values and the output times interpolate linearly between samples). Guaranteed for the
    # implicit scheme at any step, and for Crank-Nicolson when every node's explicit weight Cap/dt - sum(g)/2 is
    # >= 0 (otherwise CN may overshoot and only finiteness is checked).
    if study.simulation.engine == "fd-implicit" or _cn_monotone(study):
        import pandas as pd

        m = pd.read_csv(BASE / "measured.csv", parse_dates=["timestamp"], index_col="timestamp")
        first = study.period.warmup_start or study.period.start
        span = m.loc[first - pd.Timedelta("1h") : study.period.end + pd.Timedelta("1h")]
        lo = span[["TSe", "TSi"]].min().min()
        hi = span[["TSe", "TSi"]].max().max()
        T = res.simulated[["T3A", "T2A", "T1A"]].to_numpy()
        assert T.min() >= lo - 1e-9 and T.max() <= hi + 1e-9, (lo, hi, T.min(), T.max())


def _cn_monotone(study) -> bool:
    """Sufficient condition of Crank-Nicolson's discrete maximum principle on the study's grid."""
    from wallcal.grid import PropertyArrays, assemble, build_grid

    sim = study.simulation
    grid = build_grid(study.wall, sim.time_step, sim.grid_constant, sim.node_rule)
    cap, g = assemble(grid, PropertyArrays.from_walls([study.wall]))
    gsum = np.zeros(grid.n_nodes)
    gsum[:-1] += g[0]
    gsum[1:] += g[0]
    return bool(np.all(cap[0, 1:-1] / sim.time_step - 0.5 * gsum[1:-1] >= 0))


# ---------------------------------------------------------------------------- the CLI on corrupted files
def _cli(tmp_path, capsys, text: bytes | str):
    path = tmp_path / "study.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    code = main(["simulate", str(path)])
    err = capsys.readouterr().err
    return code, err


CLI_CASES = {
    "negative conductivity": (
        lambda r: _set(r, "wall.layers[2].conductivity", -0.035),
        "wall.layers[2].conductivity: must be > 0",
    ),
    "nan density": (lambda r: _set(r, "wall.layers[0].density", math.nan), "wall.layers[0].density"),
    "unknown key": (lambda r: _set(r, "wall.layers[1].thikness", 0.1), "did you mean 'thickness'"),
    "missing period": (lambda r: _set(r, "period", delete=True), "period: required table"),
    "huge integer": (lambda r: _set(r, "simulation.time_step", 10**400), "simulation.time_step"),
    "string time step": (lambda r: _set(r, "simulation.time_step", "60 s"), "simulation.time_step"),
    "bad engine": (lambda r: _set(r, "simulation.engine", "fd-cnn"), "did you mean 'fd-cn'"),
}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_cli_reports_one_line_without_traceback(case, tmp_path, capsys):
    change, expect = CLI_CASES[case]
    raw = copy.deepcopy(RAW)
    raw["data"]["file"] = str(EXAMPLE.parent / "measured.csv")
    change(raw)
    text = tomli_w.dumps(raw)
    if case == "huge integer":
        text = text.replace(f"time_step = {10**400}", "time_step = 1" + "0" * 400)
    code, err = _cli(tmp_path, capsys, text)
    assert code == 2, err
    assert err.startswith("wallcal: error: "), err
    assert expect in err, err
    assert "Traceback" not in err
    # one line, or (several problems) a header line and one "  - key.path: ..." line per problem
    first, *rest = err.strip().splitlines()
    assert all(line.startswith("  - ") for line in rest), err
    assert rest == [] or first.endswith("problems:"), err


def test_one_bad_layer_value_gives_one_problem():
    raw = copy.deepcopy(RAW)
    _set(raw, "wall.layers[0].density", math.nan)
    _, exc = _parse(raw)
    assert exc.problems == ["wall.layers[0].density: must be a finite number, got nan"]


@pytest.mark.parametrize(
    "content,expect",
    [
        (b"", "no valid"),  # empty file: every required table is missing
        (b"\xff\xfe[wall]\n", "not valid UTF-8"),
        (b"[wall\nlayers = 3", "not valid TOML"),
        (b"wall = 3\n", "wall: must be a table"),
    ],
)
def test_cli_unreadable_study_files(content, expect, tmp_path, capsys):
    code, err = _cli(tmp_path, capsys, content)
    assert code == 2, err
    assert err.startswith("wallcal: error: ") and "Traceback" not in err, err
    if expect != "no valid":
        assert expect in err, err


def test_parse_study_of_non_dict_is_a_study_error():
    for bad in (None, 3, "x", [1, 2]):
        with pytest.raises(StudyError):
            parse_study(bad, base_dir=BASE)
