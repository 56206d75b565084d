"""The calibration parameter space: the ``[calibration]`` table of the study file.

A parameter is one value shared by one or more layers (tied layers) for one
property, or a probe's depth. Bounds are absolute or relative to the base
value. Validation happens here, once: base value inside the bounds, physical
values positive over the whole box, no layer or probe named twice for the same
property, unknown names listed with the closest valid ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import StudyError, closest
from ..grid import PropertyArrays
from ..schema import Problems, Table, check_number
from ..wall import Wall

LAYER_PROPERTIES = (
    "conductivity",
    "density",
    "specific_heat",
    "conductivity_temperature_coefficient",
    "contact_resistance",
)
PROBE_PROPERTIES = ("depth",)
OBJECTIVES = ("cse", "rmse_accuracy", "weighted_cse", "weighted_rmse")
ALGORITHMS = ("pso-hj", "least-squares", "differential-evolution", "nelder-mead", "cma-es")
CALIBRATION_KEYS = ("targets", "objective", "algorithm", "seed", "parameters", "settings", "reference_wall")
PARAMETER_KEYS = ("layers", "probe", "property", "bounds", "bounds_kind")
#: physical lower limits (exclusive) per property
_POSITIVE = {"conductivity": 0.0, "density": 0.0, "specific_heat": 0.0}
_NONNEGATIVE = {"contact_resistance": 0.0, "depth": 0.0}


@dataclass(frozen=True)
class Parameter:
    """One calibration parameter.

    Attributes
    ----------
    name : str
        ``"conductivity[5,8]"`` or ``"depth[T3A]"``.
    property : str
    layers : tuple of int
        Layer indices sharing the value (empty for a probe parameter).
    probe : str or None
    base : float
        Base-case value (SI units of the property).
    lower, upper : float
        Absolute bounds.
    """

    name: str
    property: str
    layers: tuple[int, ...]
    probe: str | None
    base: float
    lower: float
    upper: float

    @property
    def span(self) -> float:
        return self.upper - self.lower


@dataclass(frozen=True)
class ParameterSpace:
    """The parameters, the objective and the algorithm settings of a calibration."""

    parameters: tuple[Parameter, ...]
    targets: tuple[str, ...]
    objective: str = "cse"
    algorithm: str = "pso-hj"
    seed: int = 1
    settings: dict = field(default_factory=dict)
    reference_wall: str | None = None

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

    @property
    def contact_layers(self) -> frozenset[int]:
        """Layers whose contact resistance is a parameter (the grid needs a contact link there)."""
        return frozenset(i for p in self.parameters if p.property == "contact_resistance" for i in p.layers)

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
        props = PropertyArrays(**{k: np.repeat(v, nc, axis=0) for k, v in base.__dict__.items()})
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
        """The wall with parameter values ``x`` applied (for writing and reporting)."""
        for p, v in zip(self.parameters, np.asarray(x, dtype=float), strict=True):
            if p.probe is not None:
                wall = wall.replace_probe(p.probe, depth=float(v))
            else:
                for li in p.layers:
                    wall = wall.replace_layer(wall.layers[li].id, **{p.property: float(v)})
        return wall


def parse_space(study, raw: dict | None = None) -> ParameterSpace:
    """Validate a study's ``[calibration]`` table.

    Raises
    ------
    StudyError
        Listing every problem with its key path.
    """
    raw = study.calibration if raw is None else raw
    problems = Problems()
    t = Table(raw, "calibration", problems, CALIBRATION_KEYS)
    wall = study.wall
    sensor_names = [s.name for s in study.sensors]
    targets_raw = t.raw("targets", None)
    targets: list[str] = []
    if targets_raw is None:
        targets = [s.name for s in study.sensors if s.quantity == "temperature"]
    elif not isinstance(targets_raw, list) or not all(isinstance(x, str) for x in targets_raw) or not targets_raw:
        problems.add("calibration.targets", "must be a non-empty list of sensor names")
    else:
        for i, name in enumerate(targets_raw):
            if name not in sensor_names:
                problems.add(f"calibration.targets[{i}]", f"{name!r} is not a sensor; {closest(name, sensor_names)}")
            elif name in targets:
                problems.add(f"calibration.targets[{i}]", f"{name!r} is listed twice")
            else:
                targets.append(name)
    objective = t.str("objective", "cse", choices=OBJECTIVES)
    algorithm = t.str("algorithm", "pso-hj", choices=ALGORITHMS)
    seed = t.num("seed", 1, integer=True, ge=0)
    settings = t.raw("settings", {}) or {}
    if not isinstance(settings, dict):
        problems.add("calibration.settings", "must be a table")
        settings = {}
    if objective == "rmse_accuracy":
        for name in targets:
            s = study.sensor(name)
            if s.accuracy is None and s.accuracy_relative is None:
                problems.add("calibration.objective", f"rmse_accuracy needs an accuracy for sensor {name!r}")
    ref = t.str("reference_wall", None)

    layer_ids = [layer.id for layer in wall.layers]
    probe_names = [p.name for p in wall.probes]
    params: list[Parameter] = []
    used: set[tuple[str, str]] = set()
    for pt in t.tables("parameters", PARAMETER_KEYS):
        has_layers, has_probe = pt.has("layers"), pt.has("probe")
        if has_layers == has_probe:
            problems.add(pt.path, 'give either layers = [...] or probe = "..."')
            continue
        prop = pt.str("property", choices=PROBE_PROPERTIES if has_probe else LAYER_PROPERTIES)
        kind = pt.str("bounds_kind", "relative" if has_layers else "absolute", choices=("relative", "absolute"))
        bounds = pt.raw("bounds")
        if not (isinstance(bounds, list) and len(bounds) == 2):
            problems.add(pt.at("bounds"), "must be a pair [lower, upper]")
            continue
        lo = check_number(bounds[0], pt.at("bounds") + "[0]", problems)
        hi = check_number(bounds[1], pt.at("bounds") + "[1]", problems)
        if prop is None or kind is None or lo is None or hi is None:
            continue
        if not hi > lo:
            problems.add(pt.at("bounds"), f"upper bound must exceed lower bound, got [{lo:g}, {hi:g}]")
            continue
        if has_probe:
            name = pt.raw("probe")
            if not isinstance(name, str) or name not in probe_names:
                problems.add(pt.at("probe"), f"{name!r} is not a probe of the wall; {closest(str(name), probe_names)}")
                continue
            if ("probe:" + name, prop) in used:
                problems.add(pt.at("probe"), f"probe {name!r} {prop} is already a parameter")
                continue
            used.add(("probe:" + name, prop))
            base = wall.probe(name).depth
            idx: tuple[int, ...] = ()
            pname = f"depth[{name}]"
        else:
            ids = pt.raw("layers")
            if not isinstance(ids, list) or not ids:
                problems.add(pt.at("layers"), "must be a non-empty list of layer ids")
                continue
            ids = [str(i) if isinstance(i, int) and not isinstance(i, bool) else i for i in ids]
            bad = False
            idx_list = []
            for k, lid in enumerate(ids):
                if not isinstance(lid, str) or lid not in layer_ids:
                    problems.add(
                        f"{pt.at('layers')}[{k}]", f"{lid!r} is not a layer id; {closest(str(lid), layer_ids)}"
                    )
                    bad = True
                    continue
                if (lid, prop) in used:
                    problems.add(f"{pt.at('layers')}[{k}]", f"layer {lid!r} {prop} is already a parameter")
                    bad = True
                    continue
                used.add((lid, prop))
                layer = wall.layers[layer_ids.index(lid)]
                if layer.is_massless and prop in (
                    "conductivity",
                    "density",
                    "specific_heat",
                    "conductivity_temperature_coefficient",
                ):
                    problems.add(f"{pt.at('layers')}[{k}]", f"layer {lid!r} is a no-mass layer: it has no {prop}")
                    bad = True
                    continue
                if prop == "contact_resistance" and layer_ids.index(lid) == len(layer_ids) - 1:
                    problems.add(
                        f"{pt.at('layers')}[{k}]", "the innermost layer has no next layer for a contact resistance"
                    )
                    bad = True
                    continue
                idx_list.append(layer_ids.index(lid))
            if bad:
                continue
            idx = tuple(idx_list)
            values = [getattr(wall.layers[i], prop) or 0.0 for i in idx]
            if len(set(values)) > 1:
                problems.add(
                    pt.at("layers"),
                    f"tied layers must share a base {prop}; got "
                    + ", ".join(f"{wall.layers[i].id}: {v:g}" for i, v in zip(idx, values, strict=True)),
                )
                continue
            base = float(values[0])
            pname = f"{prop}[{','.join(wall.layers[i].id for i in idx)}]"
        if kind == "relative":
            if base == 0.0:
                problems.add(
                    pt.at("bounds_kind"),
                    f'relative bounds need a non-zero base value ({pname} is 0): use bounds_kind = "absolute"',
                )
                continue
            lower, upper = base * (1 + lo), base * (1 + hi)
            lower, upper = min(lower, upper), max(lower, upper)
        else:
            lower, upper = lo, hi
        if not lower <= base <= upper:
            problems.add(
                pt.at("bounds"), f"the base value {base:g} of {pname} is outside the bounds [{lower:g}, {upper:g}]"
            )
            continue
        if prop in _POSITIVE and lower <= 0:
            problems.add(pt.at("bounds"), f"{pname} must stay > 0 over the whole box; lower bound is {lower:g}")
            continue
        if prop in _NONNEGATIVE and lower < 0:
            problems.add(pt.at("bounds"), f"{pname} must stay >= 0 over the whole box; lower bound is {lower:g}")
            continue
        if prop == "depth" and upper > wall.thickness:
            problems.add(pt.at("bounds"), f"{pname} upper bound {upper:g} m is beyond the wall ({wall.thickness:g} m)")
            continue
        params.append(Parameter(pname, prop, idx, pt.raw("probe") if has_probe else None, base, lower, upper))
    if t.has("parameters") and not params and not problems:
        problems.add("calibration.parameters", "no parameter")
    if not t.has("parameters"):
        problems.add("calibration.parameters", "required: at least one [[calibration.parameters]]")
    if problems:
        raise StudyError(problems, source=str(study.path) if study.path else None)
    return ParameterSpace(
        parameters=tuple(params),
        targets=tuple(targets),
        objective=objective or "cse",
        algorithm=algorithm or "pso-hj",
        seed=int(seed if seed is not None else 1),
        settings=dict(settings),
        reference_wall=ref,
    )
