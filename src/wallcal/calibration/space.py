"""The calibration parameter space: the ``[calibration]`` table of the study file.

A parameter is one value shared by one or more layers (tied layers) for one
property, a probe's depth, or a target sensor's offset (a correction added to its measured
signal, like the sensor's own ``offset`` key). Bounds are absolute or relative to the base
value. The table is validated here, once, when the study is loaded
(:func:`wallcal.load_study` calls :func:`parse_calibration` with the study's other keys):
base value inside the bounds, physical values positive over the whole box, no layer or probe
named twice for the same property, settings known to the algorithm, unknown names listed with
the closest valid ones. The result, a frozen :class:`ParameterSpace`, is ``Study.calibration``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..engines.base import HYGRIC_PROPERTIES, PropertyArrays
from ..errors import StudyError, closest
from ..schema import Problems, Table, check_number, describe
from ..wall import Wall
from ..wallfile import load_wall
from .algorithms import check_settings

LAYER_PROPERTIES = (
    "conductivity",
    "density",
    "specific_heat",
    "conductivity_temperature_coefficient",
    "contact_resistance",
    *HYGRIC_PROPERTIES,  # the moisture engines' (ham): mu, b of lambda(w), the sorption and liquid scales
)
PROBE_PROPERTIES = ("depth",)
SENSOR_PROPERTIES = ("offset", "response_time")
#: ``sensor = "faces"`` with ``property = "offset"``: one offset of both boundary (face) sensors
FACES = "faces"
OBJECTIVES = ("cse", "rmse_accuracy", "weighted_cse", "weighted_rmse")
ALGORITHMS = ("pso-hj", "least-squares", "differential-evolution", "nelder-mead", "cma-es")
CALIBRATION_KEYS = ("targets", "objective", "algorithm", "seed", "parameters", "settings", "reference_wall")
PARAMETER_KEYS = ("layers", "probe", "sensor", "property", "bounds", "bounds_kind")
#: physical lower limits (exclusive) per property
_POSITIVE = {"conductivity": 0.0, "density": 0.0, "specific_heat": 0.0, "sorption_scale": 0.0}
_NONNEGATIVE = {
    "contact_resistance": 0.0,
    "depth": 0.0,
    "moisture_conductivity_coefficient": 0.0,
    "liquid_transport_scale": 0.0,
}


@dataclass(frozen=True)
class Parameter:
    """One calibration parameter.

    Attributes
    ----------
    name : str
        ``"conductivity[5,8]"``, ``"depth[T3A]"`` or ``"offset[T3A]"``.
    property : str
    layers : tuple of int
        Layer indices sharing the value (empty for a probe or sensor parameter).
    probe : str or None
    base : float
        Base-case value (SI units of the property).
    lower, upper : float
        Absolute bounds.
    sensor : str or None
        The target sensor of an ``offset`` parameter: a correction [degC or W/m2] added to its
        measured signal before it is compared with the model (the meaning of the sensor's own
        ``offset`` key; the calibrated value adds to it). ``"faces"`` for the offset of both boundary (face)
        sensors together (:data:`FACES`).
    shifts : tuple of str
        For the face offset: the temperature targets it moves. A constant offset d of both face temperatures
        moves every temperature of a linear wall by d (after the warm-up) and no heat flux, so it is applied as
        the correction -d of each of these targets' measured signals.
    """

    name: str
    property: str
    layers: tuple[int, ...]
    probe: str | None
    base: float
    lower: float
    upper: float
    sensor: str | None = None
    shifts: tuple[str, ...] = ()

    @property
    def span(self) -> float:
        return self.upper - self.lower


@dataclass(frozen=True)
class ParameterSpace:
    """The parameters, the objective and the algorithm settings of a calibration.

    Attributes
    ----------
    parameters : tuple of Parameter
        Resolved against the study's wall (base values and absolute bounds).
    targets : tuple of str
        Sensor names in the objective.
    objective, algorithm : str
    seed : int
    settings : tuple of (str, value)
        The study's ``[calibration.settings]`` (checked), as name-value pairs: ``dict(space.settings)``.
    reference_wall : Path or None
        The reference wall file (resolved against the study's folder).
    """

    parameters: tuple[Parameter, ...]
    targets: tuple[str, ...]
    objective: str = "cse"
    algorithm: str = "pso-hj"
    seed: int = 1
    settings: tuple[tuple[str, Any], ...] = ()
    reference_wall: Path | None = None

    @property
    def n(self) -> int:
        return len(self.parameters)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def base(self) -> np.ndarray:
        return np.array([p.base for p in self.parameters])

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Absolute values -> [0, 1] per parameter."""
        return (np.asarray(x) - self.lower) / (self.upper - self.lower)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        return self.lower + np.asarray(u) * (self.upper - self.lower)

    def bound_sides(self, x: np.ndarray, band: float = 1e-6) -> list[str]:
        """Per parameter, ``"lower"`` or ``"upper"`` when its value in ``x`` [SI] lies within ``band`` of its
        range from that bound of the box (in unit coordinates), else ``""``."""
        u = self.to_unit(np.asarray(x, dtype=float))
        return ["lower" if v <= band else "upper" if v >= 1 - band else "" for v in u]

    def response_times(self, X: np.ndarray) -> dict[int, np.ndarray]:
        """Target index -> first-order response time [s] per candidate, shape (n_candidates,), of every
        ``response_time`` parameter (a probe that reads its temperature through a first-order lag)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return {
            self.targets.index(p.sensor): X[:, j]
            for j, p in enumerate(self.parameters)
            if p.property == "response_time" and p.sensor in self.targets
        }

    @property
    def contact_layers(self) -> frozenset[int]:
        """Layers whose contact resistance is a parameter (the grid needs a contact link there)."""
        return frozenset(i for p in self.parameters if p.property == "contact_resistance" for i in p.layers)

    def offsets(self, X: np.ndarray) -> np.ndarray:
        """Sensor offsets [degC or W/m2] per candidate and target, shape (n_candidates, n_targets): the
        correction added to each target's measured signal (0 for targets without an ``offset`` parameter)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        out = np.zeros((X.shape[0], len(self.targets)))
        for j, p in enumerate(self.parameters):
            if p.property == "offset" and p.sensor is not None and p.sensor in self.targets:
                out[:, self.targets.index(p.sensor)] += X[:, j]
            for name in p.shifts:  # a face offset: the opposite correction of every temperature target
                out[:, self.targets.index(name)] -= X[:, j]
        return out

    def offset_values(self, x: np.ndarray) -> dict[str, float]:
        """Sensor name -> calibrated offset [degC or W/m2] of the ``offset`` parameters at ``x``."""
        out: dict[str, float] = {}
        for p, v in zip(self.parameters, np.asarray(x, dtype=float), strict=True):
            if p.property == "offset" and p.sensor is not None and not p.shifts:
                out[p.sensor] = out.get(p.sensor, 0.0) + float(v)
            for name in p.shifts:
                out[name] = out.get(name, 0.0) - float(v)
        return out

    # ------------------------------------------------------------------ applying parameters
    def properties(self, wall: Wall, X: np.ndarray) -> tuple[PropertyArrays, dict[str, np.ndarray]]:
        """Property arrays of candidate walls and probe depths.

        Parameters
        ----------
        wall : Wall
            The base wall.
        X : ndarray, shape (n_candidates, n_parameters)
            Absolute parameter values.

        Returns
        -------
        props : PropertyArrays
        depths : dict
            Probe name -> depths [m], shape (n_candidates,), for probe parameters.
        """
        X = np.atleast_2d(np.asarray(X, dtype=float))
        nc = X.shape[0]
        base = PropertyArrays.from_walls([wall])
        props = PropertyArrays(
            **{k: np.repeat(v, nc, axis=0) for k, v in base.__dict__.items() if k != "hygric"},
            hygric={k: np.repeat(v, nc, axis=0) for k, v in base.hygric.items()},
        )
        depths: dict[str, np.ndarray] = {}
        for j, p in enumerate(self.parameters):
            if p.probe is not None:
                depths[p.probe] = X[:, j].copy()
                continue
            for li in p.layers:
                if p.property == "conductivity":
                    props.conductivity[:, li] = X[:, j]
                elif p.property == "conductivity_temperature_coefficient":
                    props.temperature_coefficient[:, li] = X[:, j]
                elif p.property == "contact_resistance":
                    props.contact_resistance[:, li] = X[:, j]
                elif p.property in props.hygric:
                    props.hygric[p.property][:, li] = X[:, j]
        # volumetric heat capacity = density * specific heat, each possibly a parameter
        rho = np.array([[layer.density or 0.0 for layer in wall.layers]] * nc, dtype=float)
        cp = np.array([[layer.specific_heat or 0.0 for layer in wall.layers]] * nc, dtype=float)
        for j, p in enumerate(self.parameters):
            for li in p.layers:
                if p.property == "density":
                    rho[:, li] = X[:, j]
                elif p.property == "specific_heat":
                    cp[:, li] = X[:, j]
        massive = np.array([not layer.is_massless for layer in wall.layers])
        props.volumetric_heat_capacity[:, massive] = (rho * cp)[:, massive]
        return props, depths

    def wall_at(self, wall: Wall, x: np.ndarray) -> Wall:
        """The wall with parameter values ``x`` applied (for writing and reporting; sensor offsets are no part
        of the wall: :meth:`offset_values`)."""
        for p, v in zip(self.parameters, np.asarray(x, dtype=float), strict=True):
            if p.sensor is not None:
                continue
            if p.probe is not None:
                wall = wall.replace_probe(p.probe, depth=float(v))
            else:
                for li in p.layers:
                    wall = wall.replace_layer(wall.layers[li].id, **{p.property: float(v)})
        return wall


def space_of(study) -> ParameterSpace:
    """The study's parameter space (validated when the study was loaded).

    Raises
    ------
    StudyError
        When the study has no ``[calibration]`` table.
    """
    if study.calibration is None:
        raise StudyError(
            ["calibration: the study has no [calibration] table (see docs/calibration.md)"],
            source=str(study.path) if study.path else None,
        )
    return study.calibration


def parse_space(study, raw: dict | None = None) -> ParameterSpace:
    """The study's parameter space, or another ``[calibration]`` table validated against the study.

    Parameters
    ----------
    study : Study
    raw : dict, optional
        A ``[calibration]`` table (as parsed TOML) to validate against the study's wall and
        sensors, e.g. a variant of the study's own. Without it, the study's own space (validated by
        :func:`wallcal.load_study`) is returned.

    Raises
    ------
    StudyError
        Listing every problem with its key path; or the study has no ``[calibration]`` table.
    """
    if raw is None:
        return space_of(study)
    problems = Problems()
    t = Table(raw, "calibration", problems, CALIBRATION_KEYS)
    base_dir = Path(study.path).parent if study.path else None
    space = parse_calibration(t, problems, study.wall, study.sensors, base_dir=base_dir)
    if problems:
        raise StudyError(problems, source=str(study.path) if study.path else None)
    return space


def parse_calibration(
    t: Table,
    problems: Problems,
    wall: Wall | None,
    sensors,
    sensor_names=None,
    base_dir: Path | None = None,
) -> ParameterSpace | None:
    """Validate the ``[calibration]`` table ``t`` of a study, recording every problem in ``problems``.

    The study parser (:func:`wallcal.study.parse_study`) calls it with the study's other keys.

    Parameters
    ----------
    t : Table
        The ``calibration`` table.
    problems : Problems
    wall : Wall or None
        The study's wall; None when it has problems of its own, in which case the parameters are
        checked only for what does not depend on the wall (no follow-up problems).
    sensors : sequence of SensorSpec
        The study's valid sensors (accuracies, for ``rmse_accuracy``).
    sensor_names : collection of str, optional
        Every sensor name the study declares (also those with problems of their own); default
        the names of ``sensors``.
    base_dir : Path, optional
        The study's folder (``reference_wall`` is relative to it).

    Returns
    -------
    ParameterSpace or None
        None when there were problems.
    """
    if not t.ok:  # not a table: Table said so
        return None
    n_problems = len(problems)
    sensors = tuple(sensors)
    by_name = {s.name: s for s in sensors}
    declared = list(dict.fromkeys(sensor_names if sensor_names is not None else by_name))
    targets_raw = t.raw("targets", None)
    targets: list[str] = []
    if targets_raw is None:
        targets = [s.name for s in sensors if s.quantity == "temperature"]
    elif not isinstance(targets_raw, list) or not all(isinstance(x, str) for x in targets_raw) or not targets_raw:
        problems.add(t.at("targets"), "must be a non-empty list of sensor names")
    else:
        for i, name in enumerate(targets_raw):
            if name not in declared:
                problems.add(f"{t.at('targets')}[{i}]", f"{name!r} is not a sensor; {closest(name, declared)}")
            elif name in targets:
                problems.add(f"{t.at('targets')}[{i}]", f"{name!r} is listed twice")
            else:
                targets.append(name)
    objective = t.str("objective", "cse", choices=OBJECTIVES)
    algorithm = t.str("algorithm", "pso-hj", choices=ALGORITHMS)
    seed = t.num("seed", 1, integer=True, ge=0)
    settings: dict = {}
    raw_settings = t.raw("settings", None)
    if raw_settings is not None and not isinstance(raw_settings, dict):
        problems.add(t.at("settings"), f"must be a table, got {describe(raw_settings)}")
    elif raw_settings is not None and algorithm is not None:
        settings = check_settings(algorithm, raw_settings, t.at("settings"), problems)
    if objective == "rmse_accuracy":
        for name in targets:
            s = by_name.get(name)
            if s is not None and s.accuracy is None and s.accuracy_relative is None:
                problems.add(t.at("objective"), f"rmse_accuracy needs an accuracy for sensor {name!r}")
    ref = t.str("reference_wall", None)
    ref_path = None
    if ref is not None:
        ref_path = (base_dir / ref) if base_dir else Path(ref)
        try:
            load_wall(ref_path)
        except StudyError as exc:
            for p in exc.problems:
                problems.add(f"{t.at('reference_wall')} ({ref_path})", p)

    params: list[Parameter] = []
    used: set[tuple[str, str]] = set()  # (layer id or "probe:NAME", property): no property is a parameter twice
    for pt in t.tables("parameters", PARAMETER_KEYS, required=False):
        temps = [n for n in targets if n in by_name and by_name[n].quantity == "temperature"]
        got = _parse_parameter(pt, problems, wall, targets, temps)
        if got is None:
            continue
        p, keys = got
        twice = [(k, key) for k, key in enumerate(keys) if (key, p.property) in used]
        for k, key in twice:
            if p.sensor:
                at, what = pt.at("sensor"), f"sensor {p.sensor!r}"
            elif p.probe:
                at, what = pt.at("probe"), f"probe {p.probe!r}"
            else:
                at, what = f"{pt.at('layers')}[{k}]", f"layer {key!r}"
            problems.add(at, f"{what} {p.property} is already a parameter")
        used.update((key, p.property) for key in keys)
        if not twice:
            params.append(p)
    if not t.has("parameters"):
        problems.add(t.at("parameters"), "required: at least one [[calibration.parameters]]")
    elif isinstance(t.raw("parameters"), list) and not t.raw("parameters"):
        problems.add(t.at("parameters"), "list at least one parameter")
    if len(problems) > n_problems or wall is None:
        return None
    return ParameterSpace(
        parameters=tuple(params),
        targets=tuple(targets),
        objective=objective or "cse",
        algorithm=algorithm or "pso-hj",
        seed=int(seed if seed is not None else 1),
        settings=tuple(settings.items()),
        reference_wall=ref_path,
    )


def _parse_bounds(pt: Table, problems: Problems) -> tuple[float | None, float | None]:
    """The ``bounds = [lower, upper]`` pair of a parameter table (None, None after a problem)."""
    bounds = pt.raw("bounds")
    if not (isinstance(bounds, list) and len(bounds) == 2):
        problems.add(pt.at("bounds"), "must be a pair [lower, upper]" + ("" if pt.has("bounds") else "; missing"))
        return None, None
    lo = check_number(bounds[0], pt.at("bounds") + "[0]", problems)
    hi = check_number(bounds[1], pt.at("bounds") + "[1]", problems)
    if lo is not None and hi is not None and not hi > lo:
        problems.add(pt.at("bounds"), f"upper bound must exceed lower bound, got [{lo:g}, {hi:g}]")
        return None, None
    return lo, hi


def _parse_parameter(pt: Table, problems: Problems, wall: Wall | None, targets=(), temperature_targets=()):
    """One ``[[calibration.parameters]]`` table: (Parameter, (layer ids, probe or sensor)) or None."""
    has_layers, has_probe, has_sensor = pt.has("layers"), pt.has("probe"), pt.has("sensor")
    if has_layers + has_probe + has_sensor != 1:
        if pt.ok:
            problems.add(pt.path, 'give one of layers = [...], probe = "..." or sensor = "..."')
        return None
    if has_sensor:
        return _parse_offset(pt, problems, wall, targets, temperature_targets)
    prop = pt.str("property", choices=PROBE_PROPERTIES if has_probe else LAYER_PROPERTIES)
    kind = pt.str("bounds_kind", "relative" if has_layers else "absolute", choices=("relative", "absolute"))
    lo, hi = _parse_bounds(pt, problems)
    if has_probe:
        name = pt.raw("probe")
        if not isinstance(name, str):
            problems.add(pt.at("probe"), f"must be a probe name (a string), got {describe(name)}")
            return None
        keys: tuple[str, ...] = ("probe:" + name,)
    else:
        ids = pt.raw("layers")
        if not isinstance(ids, list) or not ids:
            problems.add(pt.at("layers"), "must be a non-empty list of layer ids")
            return None
        ids = [str(i) if isinstance(i, int) and not isinstance(i, bool) else i for i in ids]
        bad = [k for k, lid in enumerate(ids) if not isinstance(lid, str)]
        for k in bad:
            problems.add(f"{pt.at('layers')}[{k}]", f"must be a layer id (a string), got {describe(ids[k])}")
        if bad:
            return None
        keys = tuple(ids)
    if wall is None or prop is None or kind is None or lo is None or hi is None:
        return None

    # ------------------------------------------------------------ checks against the wall
    if has_probe:
        probe_names = [p.name for p in wall.probes]
        if name not in probe_names:
            problems.add(pt.at("probe"), f"{name!r} is not a probe of the wall; {closest(name, probe_names)}")
            return None
        base = wall.probe(name).depth
        idx: tuple[int, ...] = ()
        pname = f"depth[{name}]"
    else:
        layer_ids = [layer.id for layer in wall.layers]
        idx_list = []
        n0 = len(problems)
        for k, lid in enumerate(keys):
            at = f"{pt.at('layers')}[{k}]"
            if lid not in layer_ids:
                problems.add(at, f"{lid!r} is not a layer id; {closest(lid, layer_ids)}")
                continue
            if lid in keys[:k]:
                problems.add(at, f"layer {lid!r} {prop} is already a parameter")
                continue
            i = layer_ids.index(lid)
            if wall.layers[i].is_massless and prop != "contact_resistance":
                problems.add(at, f"layer {lid!r} is a no-mass layer: it has no {prop}")
                continue
            if prop == "contact_resistance" and i == len(layer_ids) - 1:
                problems.add(at, "the innermost layer has no next layer for a contact resistance")
                continue
            idx_list.append(i)
        if len(problems) > n0:
            return None
        idx = tuple(idx_list)
        values = [getattr(wall.layers[i], prop) or 0.0 for i in idx]
        if len(set(values)) > 1:
            problems.add(
                pt.at("layers"),
                f"tied layers must share a base {prop}; got "
                + ", ".join(f"{wall.layers[i].id}: {v:g}" for i, v in zip(idx, values, strict=True)),
            )
            return None
        base = float(values[0])
        pname = f"{prop}[{','.join(wall.layers[i].id for i in idx)}]"
    if kind == "relative":
        if base == 0.0:
            problems.add(
                pt.at("bounds_kind"),
                f'relative bounds need a non-zero base value ({pname} is 0): use bounds_kind = "absolute"',
            )
            return None
        lower, upper = base * (1 + lo), base * (1 + hi)
        lower, upper = min(lower, upper), max(lower, upper)
    else:
        lower, upper = lo, hi
    if not lower <= base <= upper:
        problems.add(
            pt.at("bounds"), f"the base value {base:g} of {pname} is outside the bounds [{lower:g}, {upper:g}]"
        )
        return None
    if prop == "vapour_resistance_factor" and lower < 1:
        problems.add(pt.at("bounds"), f"{pname} must stay >= 1 over the whole box; lower bound is {lower:g}")
        return None
    if prop in _POSITIVE and lower <= 0:
        problems.add(pt.at("bounds"), f"{pname} must stay > 0 over the whole box; lower bound is {lower:g}")
        return None
    if prop in _NONNEGATIVE and lower < 0:
        problems.add(pt.at("bounds"), f"{pname} must stay >= 0 over the whole box; lower bound is {lower:g}")
        return None
    if prop == "depth" and upper > wall.thickness:
        problems.add(pt.at("bounds"), f"{pname} upper bound {upper:g} m is beyond the wall ({wall.thickness:g} m)")
        return None
    return Parameter(pname, prop, idx, name if has_probe else None, base, lower, upper), keys


def _parse_offset(pt: Table, problems: Problems, wall: Wall | None, targets, temperature_targets=()):
    """A ``sensor = "..."`` table: ``property = "offset"``, a target sensor's offset [degC or W/m2], or
    ``"response_time"``, a temperature target's first-order response time [s] (its reading lags the temperature
    at its depth: dm/dt = (T - m) / tau); base 0, absolute bounds holding 0."""
    prop = pt.str("property", choices=SENSOR_PROPERTIES)
    kind = pt.str("bounds_kind", "absolute", choices=("absolute",))
    name = pt.raw("sensor")
    if not isinstance(name, str):
        problems.add(pt.at("sensor"), f"must be a sensor name (a string), got {describe(name)}")
        return None
    lo, hi = _parse_bounds(pt, problems)
    if lo is not None and hi is not None and not lo <= 0.0 <= hi:
        problems.add(pt.at("bounds"), f"an offset's bounds must hold 0 (its base value), got [{lo:g}, {hi:g}]")
        lo = hi = None
    if name == FACES:
        if not temperature_targets:
            problems.add(pt.at("sensor"), "an offset of the faces acts on the temperature targets: there are none")
            return None
        if wall is None or prop is None or kind is None or lo is None or hi is None:
            return None
        par = Parameter(f"offset[{FACES}]", prop, (), None, 0.0, float(lo), float(hi), sensor=FACES)
        return dataclasses.replace(par, shifts=tuple(temperature_targets)), ("sensor:" + FACES,)
    if name not in targets:
        problems.add(
            pt.at("sensor"),
            f"{name!r} is not a target of the calibration (an offset acts on a target only); "
            f"{closest(name, list(targets))}",
        )
        return None
    if prop == "response_time":
        if name not in temperature_targets:
            problems.add(pt.at("sensor"), f"{name!r}: a response time belongs to a temperature target")
            return None
        if lo is not None and hi is not None and lo < 0.0:
            problems.add(pt.at("bounds"), f"a response time is >= 0 s, got lower bound {lo:g}")
            return None
    if wall is None or prop is None or kind is None or lo is None or hi is None:
        return None
    return Parameter(f"{prop}[{name}]", prop, (), None, 0.0, float(lo), float(hi), sensor=name), ("sensor:" + name,)
