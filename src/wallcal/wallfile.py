"""Wall files: reading and writing the ``[wall]`` table.

A wall file is a TOML file with a ``[wall]`` table (layers from the exterior, probes), the same
table a study file holds; :func:`load_wall` reads one (every problem at once, with key paths),
:func:`dump_wall` writes one that :func:`load_wall` reads back (``calibrated_wall.toml``).
``docs/study-file.md`` documents every key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from . import materials as catalogue
from .errors import StudyError, clip, show
from .schema import MISSING, Problems, Table, check_number, describe, read_toml
from .wall import HYGRIC_TABLE_KEYS, LIMITS, MAX_LAYERS, MAX_PROBES, MAX_TABLE_POINTS, Layer, Probe, Wall

FACES = ("exterior", "interior")

LAYER_KEYS = (
    "id",
    "material",
    "thickness",
    "conductivity",
    "density",
    "specific_heat",
    "conductivity_temperature_coefficient",
    "reference_temperature",
    "conductivity_table",
    "contact_resistance",
    "vapour_resistance_factor",
    "thermal_resistance",
    "moisture_storage",
    "liquid_transport",
    "vapour_resistance_shape",
    "moisture_conductivity_coefficient",
    "sorption_scale",
    "liquid_transport_scale",
    "hygric_file",
)
PROBE_KEYS = ("name", "depth", "depth_from", "side")
WALL_KEYS = ("name", "description", "layers", "probes", "file")
#: Most wall files in a chain of ``[wall] file = ...`` references (a study's wall file, that one's, ...).
MAX_WALL_FILES = 4


class WallFileCycle(StudyError):
    """``[wall] file`` references that lead back to a file already being read (reported once, not nested)."""


def _limits(name: str) -> dict:
    low, high = LIMITS[name]
    return {"ge": low, "le": high}


def parse_wall(t: Table, problems: Problems, base_dir: Path | None, chain: tuple[Path, ...] = ()) -> Wall | None:
    """The wall of a ``[wall]`` table, or None after recording every problem in ``problems``.

    ``chain``: the wall files being read around this one (resolved paths), to refuse a cycle of ``file``
    references and chains longer than :data:`MAX_WALL_FILES`.
    """
    if t.has("file"):
        others = [k for k in t.data if k not in ("file",)]
        fname = t.str("file")
        if others:
            problems.add(t.path, f"with 'file', give no other wall keys (found {clip(', '.join(others), 100)})")
        if fname is None:
            return None
        path = (base_dir / fname) if base_dir else Path(fname)
        resolved = path.resolve()
        if resolved in chain:
            names = " -> ".join(p.name for p in (*chain[chain.index(resolved) :], resolved))
            raise WallFileCycle(
                [
                    f"{t.at('file')}: the wall files refer back to themselves ({clip(names, 150)}); "
                    "point wall.file to a file that gives [[wall.layers]]"
                ],
                source=str(path),
            )
        if len(chain) >= MAX_WALL_FILES:
            problems.add(t.at("file"), f"wall files refer to further wall files more than {MAX_WALL_FILES} deep")
            return None
        try:
            return load_wall(path, _chain=(*chain, resolved))
        except WallFileCycle:
            raise
        except StudyError as exc:
            for p in exc.problems:
                problems.append(f"{t.path}.file ({clip(str(path), 100)}): {p}")
            return None
    for key, most in (("layers", MAX_LAYERS), ("probes", MAX_PROBES)):
        items = t.raw(key)
        if isinstance(items, list) and len(items) > most:
            problems.add(t.at(key), f"{len(items):,} {key}, more than wallcal takes ({most})")
            return None
    layers: list[Layer] = []
    ids: set[str] = set()
    geometry_thickness = 0.0
    for lt in t.tables("layers", LAYER_KEYS):
        _complete_layer(lt, problems, base_dir)
        lid = lt.data.get("id")
        if isinstance(lid, int) and not isinstance(lid, bool):
            lid = str(lid)
        elif not isinstance(lid, str):
            problems.add(
                lt.at("id"),
                'required, a string such as "3"' if lid is None else f"must be a string, got {describe(lid)}",
            )
            lid = None
        if lid is not None:
            if lid in ids:
                problems.add(lt.at("id"), f"layer id {show(lid)} is used twice")
            ids.add(lid)
        massless = lt.has("thermal_resistance")
        low, high = LIMITS["thickness"]
        d = lt.raw("thickness")
        if not massless and isinstance(d, int | float) and not isinstance(d, bool) and 0 < d < low:
            problems.add(
                lt.at("thickness"),
                f"{d:.3g} m is thinner than {low:g} m; declare the layer massless with thermal_resistance = "
                "thickness / conductivity [m2K/W] (a film stores no heat), or remove it",
            )
            thickness = None
        else:
            thickness = lt.num(
                "thickness",
                0.0 if massless else MISSING,
                ge=0.0 if massless else low,
                le=high,
                gt=None if massless else 0.0,
            )
        if thickness is not None:
            geometry_thickness += thickness  # probes are checked against every valid thickness
        kw: dict[str, Any] = {}
        if massless:
            kw["thermal_resistance"] = lt.num("thermal_resistance", gt=0.0, **_limits("thermal_resistance"))
            for k in (
                "conductivity",
                "density",
                "specific_heat",
                "conductivity_table",
                "conductivity_temperature_coefficient",
            ):
                if lt.has(k):
                    problems.add(lt.at(k), "a no-mass layer (thermal_resistance) takes no " + k)
        else:
            table = None
            if lt.has("conductivity_table"):
                table = _parse_table(lt.raw("conductivity_table"), lt.at("conductivity_table"), problems)
            kw["conductivity"] = lt.num(
                "conductivity", None if table is not None else MISSING, gt=0.0, **_limits("conductivity")
            )
            kw["density"] = lt.num("density", gt=0.0, **_limits("density"))
            kw["specific_heat"] = lt.num("specific_heat", gt=0.0, **_limits("specific_heat"))
            kw["conductivity_temperature_coefficient"] = lt.num(
                "conductivity_temperature_coefficient", 0.0, **_limits("conductivity_temperature_coefficient")
            )
            kw["conductivity_table"] = table
            if table is not None and kw["conductivity_temperature_coefficient"]:
                problems.add(
                    lt.at("conductivity_table"),
                    "give either conductivity_table or conductivity_temperature_coefficient, not both",
                )
        kw["reference_temperature"] = lt.num("reference_temperature", 10.0, **_limits("reference_temperature"))
        kw["contact_resistance"] = lt.num("contact_resistance", 0.0, **_limits("contact_resistance"))
        kw["vapour_resistance_factor"] = lt.num(
            "vapour_resistance_factor", None, gt=0.0, **_limits("vapour_resistance_factor")
        )
        material = lt.str("material", "")
        kw.update(_hygric(lt, problems))
        if (
            None in (lid, thickness)
            or any(kw.get(k) is None for k in ("density", "specific_heat", "thermal_resistance") if k in kw)
            or ("conductivity" in kw and kw["conductivity"] is None and kw.get("conductivity_table") is None)
        ):
            continue
        if kw.get("conductivity_table") is not None and kw.get("conductivity") is None:
            kw["conductivity"] = None
        layers.append(
            Layer(
                id=lid,
                thickness=thickness,
                material=material or "",
                **{k: v for k, v in kw.items() if v is not None or k == "conductivity_table"},
            )
        )
    if t.has("layers") and isinstance(t.raw("layers"), list) and not t.raw("layers"):
        problems.add(t.at("layers"), "the wall needs at least one layer")
    total = geometry_thickness  # also counts layers dropped for another bad value: no follow-up problems
    probes: list[Probe] = []
    names: set[str] = set()
    for pt in t.tables("probes", PROBE_KEYS, required=False):
        name = pt.str("name")
        depth = pt.num("depth", ge=0.0)
        depth_from = pt.str("depth_from", "exterior", choices=FACES)
        side = pt.str("side", None, choices=FACES)
        if name is not None:
            if name in names:
                problems.add(pt.at("name"), f"probe {show(name)} is defined twice")
            names.add(name)
        if name is None or depth is None:
            continue
        if layers and depth > total * (1 + 1e-12):
            problems.add(pt.at("depth"), f"{depth:g} m is beyond the wall's thickness {total:g} m")
            continue
        if depth_from == "interior":
            depth = max(total - depth, 0.0)
        probes.append(Probe(name=name, depth=depth, side=side))
    name = t.str("name", "")
    desc = t.str("description", "")
    if not layers:
        return None
    return Wall(layers=tuple(layers), probes=tuple(probes), name=name or "", description=desc or "")


def _complete_layer(lt: Table, problems: Problems, base_dir: Path | None) -> None:
    """Fill a layer table's missing keys from its ``hygric_file`` (a DELPHIN ``.m6`` file) and from its
    catalogue ``material`` (:mod:`wallcal.materials`), in that order: keys given in the table win."""
    if not lt.ok:
        return
    given = lt.data
    fill: dict[str, Any] = {}
    name = given.get("material")
    mat = catalogue.find(name) if isinstance(name, str) else None
    if mat is not None:
        d = given.get("thickness")
        thickness = (
            d if isinstance(d, float) and 0 < d < 1e3 else (float(d) if type(d) is int and 0 < d < 1000 else None)
        )
        fill.update(mat.layer_keys(thickness, hygric=True))
    fname = given.get("hygric_file")
    if fname is not None:
        if not isinstance(fname, str):
            problems.add(lt.at("hygric_file"), f"must be a file name (a string), got {describe(fname)}")
        else:
            from .moisture.delphin import read_m6

            path = (base_dir / fname) if base_dir else Path(fname)
            try:
                fill.update(read_m6(path))
            except StudyError as exc:
                for p in exc.problems:
                    problems.add(lt.at("hygric_file"), p)
    if "thermal_resistance" in given:
        for k in ("conductivity", "density", "specific_heat"):
            fill.pop(k, None)
    if fill:
        lt.data = {**fill, **given}


def _hygric(lt: Table, problems: Problems) -> dict:
    """The hygric fields of a layer table (checked for shape here; the physics when a moisture engine needs
    them, :meth:`wallcal.wall.Layer.hygric_material`)."""
    import json

    out: dict[str, Any] = {}
    tables = {}
    for k in ("moisture_storage", "liquid_transport"):
        v = lt.raw(k)
        if v is None:
            continue
        if not isinstance(v, dict):
            problems.add(lt.at(k), 'must be a table such as {form = "kuenzel", ...}, got ' + describe(v))
            continue
        tables[k] = v
    from .moisture.materials import liquid_transport_functions, saturation_content, storage_function

    w_sat = 1.0
    if "moisture_storage" in tables:
        try:  # a storage table or closed form that cannot be a storage function is refused at once
            storage_function(tables["moisture_storage"], lt.path)
            w_sat = saturation_content(dict(tables["moisture_storage"]))
        except StudyError as exc:
            problems.extend(exc.problems)
            del tables["moisture_storage"]  # reported: not kept
        except (KeyError, TypeError, ValueError, OverflowError):
            pass  # said by storage_function
    if "liquid_transport" in tables:
        try:  # likewise a liquid transport table of an unknown form or with missing keys
            liquid_transport_functions(tables["liquid_transport"], lt.path, w_sat)
        except StudyError as exc:
            problems.extend(exc.problems)
            del tables["liquid_transport"]
    shape = lt.num("vapour_resistance_shape", None, **_limits("vapour_resistance_shape"))
    if shape is not None:
        tables["vapour_resistance_shape"] = shape
    if tables:
        out["hygric"] = json.dumps({k: tables[k] for k in HYGRIC_TABLE_KEYS if k in tables}, sort_keys=True)
    out["moisture_conductivity_coefficient"] = lt.num(
        "moisture_conductivity_coefficient", None, **_limits("moisture_conductivity_coefficient")
    )
    for k in ("sorption_scale", "liquid_transport_scale"):
        v = lt.num(k, 1.0, **_limits(k))
        out[k] = 1.0 if v is None else v
    return out


def _parse_table(v, path, problems):
    if not isinstance(v, list) or len(v) < 2:
        problems.add(path, "must be a list of at least two [temperature_degC, conductivity] pairs")
        return None
    if len(v) > MAX_TABLE_POINTS:
        problems.add(path, f"{len(v):,} points, more than wallcal takes ({MAX_TABLE_POINTS})")
        return None
    out = []
    for i, pair in enumerate(v):
        if not isinstance(pair, list) or len(pair) != 2:
            problems.add(f"{path}[{i}]", "must be a pair [temperature_degC, conductivity]")
            return None
        tc = check_number(pair[0], f"{path}[{i}][0]", problems, **_limits("table_temperature"))
        lam = check_number(pair[1], f"{path}[{i}][1]", problems, gt=0.0, **_limits("conductivity"))
        if tc is None or lam is None:
            return None
        out.append((tc, lam))
    if any(b[0] <= a[0] for a, b in zip(out, out[1:], strict=False)):
        problems.add(path, "temperatures must increase")
        return None
    return tuple(out)


def load_wall(path: str | Path, _chain: tuple[Path, ...] = ()) -> Wall:
    """Read a wall file (a TOML file with a ``[wall]`` table, or a study file).

    Raises
    ------
    StudyError
        With every problem found (:class:`WallFileCycle` when ``[wall] file`` references lead back to a
        file being read).
    """
    path = Path(path)
    raw = read_toml(path)
    problems = Problems()
    if "wall" not in raw:
        raise StudyError(["wall: required table, missing"], source=str(path))
    wt = Table(raw["wall"], "wall", problems, WALL_KEYS)
    wall = parse_wall(wt, problems, path.parent, _chain or (path.resolve(),))
    if problems:
        raise StudyError(problems, source=str(path))
    if wall is None:
        raise StudyError(["wall: no valid layer"], source=str(path))
    return wall


# ============================================================================ writing walls
def wall_to_dict(wall: Wall) -> dict:
    """The ``[wall]`` table of a wall file (inverse of :func:`load_wall`)."""
    layers = []
    for layer in wall.layers:
        d: dict[str, Any] = {"id": layer.id}
        if layer.material:
            d["material"] = layer.material
        d["thickness"] = layer.thickness
        if layer.is_massless:
            d["thermal_resistance"] = layer.thermal_resistance
        else:
            if layer.conductivity is not None:
                d["conductivity"] = layer.conductivity
            d["density"] = layer.density
            d["specific_heat"] = layer.specific_heat
            if layer.conductivity_temperature_coefficient:
                d["conductivity_temperature_coefficient"] = layer.conductivity_temperature_coefficient
            if layer.conductivity_table is not None:
                d["conductivity_table"] = [list(p) for p in layer.conductivity_table]
        if layer.reference_temperature != 10.0 or layer.is_temperature_dependent:
            d["reference_temperature"] = layer.reference_temperature
        if layer.contact_resistance:
            d["contact_resistance"] = layer.contact_resistance
        d.update({k: v for k, v in layer.hygric_keys().items() if k not in d})
        layers.append(d)
    out: dict[str, Any] = {}
    if wall.name:
        out["name"] = wall.name
    if wall.description:
        out["description"] = wall.description
    out["layers"] = layers
    if wall.probes:
        probes = []
        for p in wall.probes:
            d = {"name": p.name, "depth": p.depth}
            if p.side:
                d["side"] = p.side
            probes.append(d)
        out["probes"] = probes
    return out


def dump_wall(wall: Wall, header: str = "") -> str:
    """A wall file (TOML text) that :func:`load_wall` reads back, and that a study can use with
    ``[wall] file = "..."``."""
    import tomli_w

    text = tomli_w.dumps({"wall": wall_to_dict(wall)})
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    return text
