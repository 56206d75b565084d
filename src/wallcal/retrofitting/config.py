"""The ``[retrofit]`` table of a study file: validated once, into a frozen :class:`RetrofitSpec`.

Every problem is reported at once with its key path (``retrofit.variants[1].add_exterior[0].thickness:
must be > 0, got -0.1``), in the same :class:`~wallcal.errors.StudyError` as the rest of the study file.
Variant layer tables take the keys of ``[[wall.layers]]`` (validated by the same code as the wall), plus
``material = "..."`` from the bundled catalogue (:mod:`.materials`); keys given explicitly win.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import StudyError, closest
from ..schema import Problems, Table, describe
from ..wall import Layer, Wall
from ..wallfile import LAYER_KEYS, WALL_KEYS, parse_wall, wall_to_dict
from . import materials

RETROFIT_KEYS = (
    "weather",
    "azimuth",
    "solar_absorptance",
    "sky_radiation",
    "exterior_surface_coefficient",
    "interior_temperature",
    "interior_surface_coefficient",
    "interior_relative_humidity",
    "interior_humidity_class",
    "samples",
    "variants",
    # extensions (documented in docs/retrofit.md)
    "thermal_emissivity",
    "ground_albedo",
    "time_step",
    "condensation_check",
    # the hygrothermal run (EN 15026) and the mould index (docs/retrofit.md, "Moisture risk")
    "moisture_check",
    "driving_rain_factor",
    "mould_sensitivity",
    "mould_decline_coefficient",
    "moisture_max_years",
    "moisture_interior_climate",
)
#: ``moisture_interior_climate``: the interior of the moisture runs (moisture_risk.interior_climate)
INTERIOR_CLIMATES = ("constant", "EN 15026 normal", "EN 15026 high")
VARIANT_KEYS = ("name", "add_exterior", "add_interior", "remove", "replace")


@dataclass(frozen=True)
class VariantSpec:
    """One retrofit variant.

    ``add_exterior`` / ``add_interior``: layers added on that side (listed from the exterior inwards, as in
    the wall); ``remove``: ids of layers taken out; ``replace``: layer id -> the keys to change (raw table,
    resolved against the wall by :func:`apply_variant`). ``path`` is its key path for messages.
    """

    name: str
    add_exterior: tuple[Layer, ...] = ()
    add_interior: tuple[Layer, ...] = ()
    remove: tuple[str, ...] = ()
    replace: tuple[tuple[str, dict], ...] = ()
    path: str = ""

    @property
    def is_unchanged(self) -> bool:
        return not (self.add_exterior or self.add_interior or self.remove or self.replace)


@dataclass(frozen=True)
class RetrofitSpec:
    """The validated ``[retrofit]`` table (SI units; temperatures degC; angles degrees).

    Attributes
    ----------
    weather : str
        As written in the study: a path relative to the study, or the name of a shipped weather file.
    weather_path : Path or None
        ``weather`` resolved against the study's folder when such a file exists, else None (then it names a
        shipped file; :func:`wallcal.weather.resolve_weather` decides).
    azimuth : float
        Outward normal of the wall, degrees clockwise from north (180 = facing south).
    solar_absorptance : float
        Short-wave absorptance of the exterior surface [-].
    sky_radiation : bool
        Long-wave exchange with the sky (sky view 1/2 for a vertical wall; the ground half at air temperature).
    exterior_surface_coefficient, interior_surface_coefficient : float
        Combined surface coefficients h_e, h_i [W/(m2K)].
    interior_temperature : float
        [degC], constant.
    interior_relative_humidity : float or None
        [-], constant; or ``interior_humidity_class`` 1..5 (ISO 13788 Annex A).
    samples : int
        Posterior draws used for intervals.
    thermal_emissivity : float
        Long-wave emissivity of the exterior surface [-] (default 0.9).
    ground_albedo : float
        Short-wave reflectance of the ground [-] (default 0.2).
    time_step : float
        Engine time step [s], at most 3600 and a divisor of it.
    condensation_check : bool
        Run ISO 13788 (needs mu on every layer).
    moisture_check : bool
        Run the hygrothermal year (EN 15026) and the mould index when the wall's layers have hygric data.
    driving_rain_factor : float
        R_1 of the driving rain (EN ISO 15927-3's C_R C_T O W) [-].
    mould_sensitivity : tuple of (str, str)
        Layer id or material name -> mould sensitivity class (Ojanen et al. 2010), overriding the defaults.
    mould_decline_coefficient : float
        Ojanen's relative decline coefficient C_mat [-].
    moisture_max_years : int
        Most years of the periodic hygrothermal run.
    moisture_interior_climate : str
        The interior of the moisture runs: ``"constant"`` (``interior_temperature`` and the interior RH or
        humidity class) or EN 15026 Annex C's ``"EN 15026 normal"`` / ``"EN 15026 high"`` occupancy (indoor
        temperature and RH from the daily mean outdoor temperature). The heat loss and ISO 13788 keep the
        constant interior.
    """

    weather: str
    weather_path: Path | None
    variants: tuple[VariantSpec, ...]
    azimuth: float = 180.0
    solar_absorptance: float = 0.6
    sky_radiation: bool = True
    exterior_surface_coefficient: float = 25.0
    interior_temperature: float = 20.0
    interior_surface_coefficient: float = 7.69
    interior_relative_humidity: float | None = 0.5
    interior_humidity_class: int | None = None
    samples: int = 200
    thermal_emissivity: float = 0.9
    ground_albedo: float = 0.2
    time_step: float = 3600.0
    condensation_check: bool = True
    moisture_check: bool = True
    driving_rain_factor: float = 0.4
    mould_sensitivity: tuple[tuple[str, str], ...] = ()
    mould_decline_coefficient: float = 0.25
    moisture_max_years: int = 10
    moisture_interior_climate: str = "constant"
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def replace(self, **changes) -> RetrofitSpec:
        return dataclasses.replace(self, **changes)


# ============================================================================ layer tables
def _resolve_catalogue(d: dict, path: str, problems: Problems) -> dict | None:
    """A layer table with its catalogue material's properties filled in (explicit keys win).

    A ``material`` that is not in the catalogue is kept as free text when the table gives every property
    itself; otherwise it is an unknown material (with the closest names).
    """
    name = d.get("material")
    if not isinstance(name, str):
        return dict(d)
    mat = materials.find(name)
    if mat is None:
        needed = {"conductivity", "density", "specific_heat"}
        if "thermal_resistance" not in d and not needed <= set(d):
            problems.add(f"{path}.material", materials.unknown_message(name))
            return None  # no follow-up 'required, missing' for the properties the material was to give
        return dict(d)
    out = {k: v for k, v in mat.layer_keys(d.get("thickness")).items() if "thermal_resistance" not in d}
    out.update(d)
    return out


def _parse_layers(tables: list[dict], path: str, problems: Problems) -> tuple[Layer, ...]:
    """Layer tables (already completed) through the wall's own layer validation."""
    local = Problems()
    wall = parse_wall(Table({"layers": tables}, "__v", local, WALL_KEYS), local, None)
    for p in local:
        problems.append(p.replace("__v.layers", path))
    if local or wall is None:
        return ()
    return wall.layers


def _layer_list(vt: Table, key: str, problems: Problems, prefix: str) -> tuple[Layer, ...]:
    raw = vt.raw(key)
    path = vt.at(key)
    if isinstance(raw, list) and raw and not all(isinstance(x, dict) for x in raw):
        for k, x in enumerate(raw):
            if not isinstance(x, dict):
                problems.add(
                    f"{path}[{k}]", f"must be a layer table {{ material = ..., thickness = ... }}, got {describe(x)}"
                )
        return ()
    if not isinstance(raw, list) or not raw:
        problems.add(
            path,
            f"must be a non-empty list of layer tables [{{ material = ..., thickness = ... }}], got {describe(raw)}",
        )
        return ()
    tables = []
    for k, t in enumerate(raw):
        lp = f"{path}[{k}]"
        for bad in t:
            if bad not in LAYER_KEYS:
                problems.add(f"{lp}.{bad}", f"unknown key; {closest(bad, LAYER_KEYS)}")
        t = {kk: vv for kk, vv in t.items() if kk in LAYER_KEYS}
        t.setdefault("id", f"{prefix}{k + 1}")
        tables.append(_resolve_catalogue(t, lp, problems))
    if any(t is None for t in tables):
        return ()
    return _parse_layers(tables, path, problems)


def parse_retrofit(raw: Any, problems: Problems, base_dir: Path | None, wall: Wall | None) -> RetrofitSpec | None:
    """Validate the ``[retrofit]`` table, adding every problem to ``problems`` (key paths ``retrofit....``).

    ``remove`` / ``replace`` ids are checked against the wall a run actually uses (the study's, ``--wall``
    or a calibrated wall) when the run starts (:func:`apply_variant`), so that another wall file does not make
    the study unreadable for the other commands. ``wall`` is accepted for that future use and not needed.
    """
    t = Table(raw, "retrofit", problems, RETROFIT_KEYS)
    if not t.ok:
        return None
    weather = t.str("weather")
    wpath = None
    if weather:
        cand = (base_dir / weather) if base_dir else Path(weather)
        wpath = cand if cand.exists() else None
    kw: dict[str, Any] = {
        "azimuth": t.num("azimuth", 180.0, ge=0.0, le=360.0),
        "solar_absorptance": t.num("solar_absorptance", 0.6, ge=0.0, le=1.0),
        "sky_radiation": t.bool("sky_radiation", True),
        "exterior_surface_coefficient": t.num("exterior_surface_coefficient", 25.0, gt=0.0, le=1e4),
        "interior_temperature": t.num("interior_temperature", 20.0, ge=-50.0, le=60.0),
        "interior_surface_coefficient": t.num("interior_surface_coefficient", 7.69, gt=0.0, le=1e4),
        "samples": t.num("samples", 200, integer=True, ge=1, le=100000),
        "thermal_emissivity": t.num("thermal_emissivity", 0.9, ge=0.0, le=1.0),
        "ground_albedo": t.num("ground_albedo", 0.2, ge=0.0, le=1.0),
        "time_step": t.num("time_step", 3600.0, gt=0.0, le=3600.0),
        "condensation_check": t.bool("condensation_check", True),
        "moisture_check": t.bool("moisture_check", True),
        "driving_rain_factor": t.num("driving_rain_factor", 0.4, ge=0.0, le=10.0),
        "mould_decline_coefficient": t.num("mould_decline_coefficient", 0.25, ge=0.0, le=1.0),
        "moisture_max_years": t.num("moisture_max_years", 10, integer=True, ge=2, le=100),
        "moisture_interior_climate": t.str("moisture_interior_climate", "constant", choices=INTERIOR_CLIMATES),
    }
    if kw["moisture_max_years"] is not None:
        kw["moisture_max_years"] = int(kw["moisture_max_years"])
    kw["mould_sensitivity"] = _mould_sensitivity(t, problems)
    if kw["time_step"] is not None and abs(3600.0 / kw["time_step"] - round(3600.0 / kw["time_step"])) > 1e-9:
        problems.add("retrofit.time_step", f"must divide one hour (3600, 1800, 900, ... s), got {kw['time_step']:g}")
    rh = t.num("interior_relative_humidity", None, gt=0.0, le=1.0)
    cls = t.num("interior_humidity_class", None, integer=True, ge=1, le=5)
    if t.has("interior_relative_humidity") and t.has("interior_humidity_class"):
        problems.add("retrofit", "give interior_relative_humidity or interior_humidity_class, not both")
    if cls is not None:
        kw["interior_humidity_class"], kw["interior_relative_humidity"] = int(cls), None
    elif rh is not None:
        kw["interior_relative_humidity"] = rh
    if kw["samples"] is not None:
        kw["samples"] = int(kw["samples"])

    variants: list[VariantSpec] = []
    names: set[str] = set()
    vtables = t.tables("variants", VARIANT_KEYS, required=False)
    if not t.has("variants"):
        vtables = [Table({"name": "as built"}, "retrofit.variants[0]", problems, VARIANT_KEYS)]
    elif isinstance(t.raw("variants"), list) and not t.raw("variants"):
        problems.add("retrofit.variants", "list at least one variant")
    for vt in vtables:
        name = vt.str("name")
        if name is not None:
            if not name.strip():
                problems.add(vt.at("name"), "must not be empty")
            elif name in names:
                problems.add(vt.at("name"), f"variant {name!r} is defined twice")
            names.add(name)
        add_e = _layer_list(vt, "add_exterior", problems, "ext") if vt.has("add_exterior") else ()
        add_i = _layer_list(vt, "add_interior", problems, "int") if vt.has("add_interior") else ()
        remove: tuple[str, ...] = ()
        if vt.has("remove"):
            r = vt.raw("remove")
            r = (
                [str(x) if isinstance(x, int) and not isinstance(x, bool) else x for x in r]
                if isinstance(r, list)
                else r
            )
            if not isinstance(r, list) or not r or not all(isinstance(x, str) for x in r):
                problems.add(vt.at("remove"), f'must be a non-empty list of layer ids such as ["9"], got {describe(r)}')
            else:
                remove = tuple(r)
        replace: tuple[tuple[str, dict], ...] = ()
        if vt.has("replace"):
            rp = vt.raw("replace")
            if not isinstance(rp, dict) or not rp:
                problems.add(
                    vt.at("replace"), f'must be a table {{ "id" = {{ key = value, ... }} }}, got {describe(rp)}'
                )
            else:
                pairs = []
                for lid, changes in rp.items():
                    lp = f"{vt.at('replace')}.{lid}"
                    if not isinstance(changes, dict):
                        problems.add(
                            lp, f"must be a table of layer keys {{ conductivity = ... }}, got {describe(changes)}"
                        )
                        continue
                    n_before = len(problems)
                    for bad in changes:
                        if bad not in LAYER_KEYS or bad == "id":
                            problems.add(f"{lp}.{bad}", f"unknown key; {closest(bad, LAYER_KEYS[1:])}")
                    if len(problems) == n_before:  # types and ranges now, on a stand-in layer; ids at run time
                        _replaced(Layer(str(lid), 1.0, 1.0, 1000.0, 1000.0), changes, lp, problems)
                    pairs.append((str(lid), dict(changes)))
                replace = tuple(pairs)
        if name is None:
            continue
        v = VariantSpec(name=name, add_exterior=add_e, add_interior=add_i, remove=remove, replace=replace, path=vt.path)
        variants.append(v)
    optional = ("interior_relative_humidity", "interior_humidity_class")  # one of them is None by design
    if weather is None or any(v is None for k, v in kw.items() if k not in optional and not isinstance(v, bool)):
        return None
    return RetrofitSpec(weather=weather, weather_path=wpath, variants=tuple(variants), raw=dict(raw), **kw)


def _mould_sensitivity(t: Table, problems: Problems) -> tuple[tuple[str, str], ...]:
    """``mould_sensitivity = { "<layer id or material>" = "<class>" }``: each class checked by name."""
    from ..moisture.mould import mould_class

    if not t.has("mould_sensitivity"):
        return ()
    raw = t.raw("mould_sensitivity")
    if not isinstance(raw, dict):
        problems.add(
            t.at("mould_sensitivity"),
            f'must be a table {{ "layer id or material" = "sensitive", ... }}, got {describe(raw)}',
        )
        return ()
    out = []
    for key, cls in raw.items():
        try:
            out.append((str(key), mould_class(cls, f"{t.at('mould_sensitivity')}.{key}").name))
        except StudyError as exc:
            problems.append(exc.problems[0])
    return tuple(out)


# ============================================================================ applying a variant
def apply_variant(wall: Wall, v: VariantSpec) -> Wall:
    """The wall of variant ``v`` (probes dropped: a variant's outputs are its faces).

    Raises
    ------
    StudyError
        An id that is not a layer of ``wall``, a clash of layer ids, a replacement that is not a valid layer,
        or a variant that removes every layer.
    """
    problems = Problems()
    ids = [layer.id for layer in wall.layers]
    for k, lid in enumerate(v.remove):
        if lid not in ids:
            problems.add(f"{v.path}.remove[{k}]", f"{lid!r} is not a layer id of the wall; {closest(lid, ids)}")
    layers = {layer.id: layer for layer in wall.layers}
    for lid, changes in v.replace:
        path = f"{v.path}.replace.{lid}"
        if lid not in layers:
            problems.add(path, f"{lid!r} is not a layer id of the wall; {closest(lid, ids)}")
            continue
        if lid in v.remove:
            problems.add(path, f"layer {lid!r} is also removed")
            continue
        layers[lid] = _replaced(layers[lid], changes, path, problems)
    kept = [layers[i] for i in ids if i not in v.remove]
    if not kept and not problems:
        problems.add(f"{v.path}.remove", "removes every layer of the wall; keep at least one")
    new = list(v.add_exterior) + kept + list(v.add_interior)
    seen: set[str] = set()
    for layer in new:
        if layer.id in seen:
            problems.add(
                v.path, f"layer id {layer.id!r} is used twice in the variant's wall; give the added layer another id"
            )
        seen.add(layer.id)
    if problems:
        raise StudyError(problems)
    if not new:
        raise StudyError([f"{v.path}: the variant has no layer"])
    return wall.replace(layers=tuple(new), probes=())


def _replaced(layer: Layer, changes: dict, path: str, problems: Problems) -> Layer | None:
    """A layer with some keys changed; a catalogue ``material`` resets its properties first."""
    base = wall_to_dict(Wall(layers=(layer,)))["layers"][0]
    name = changes.get("material")
    if isinstance(name, str):
        if materials.find(name) is not None:
            base = {"id": layer.id, "thickness": layer.thickness}
        elif not {"conductivity", "density", "specific_heat", "thermal_resistance"} & set(changes):
            problems.add(f"{path}.material", materials.unknown_message(name))
            return layer
    if "thermal_resistance" in changes:
        for k in (
            "conductivity",
            "density",
            "specific_heat",
            "conductivity_table",
            "conductivity_temperature_coefficient",
        ):
            base.pop(k, None)
    elif {"conductivity", "density", "specific_heat"} & set(changes):
        base.pop("thermal_resistance", None)
    table = dict(base)
    table.update({k: v for k, v in changes.items() if k in LAYER_KEYS and k != "id"})
    table = _resolve_catalogue(table, path, problems)
    if table is None:
        return layer
    local = Problems()
    out = _parse_layers([table], "__r", local)
    for p in local:
        problems.append(p.replace("__r[0]", path))
    return out[0] if out else layer
