"""A reader for DELPHIN 6 material files (``.m6``, plain text): the layer keys they give.

A ``.m6`` file has sections ``[GENERAL]``, ``[PARAMETERS]``, ``[MOISTURE_STORAGE]``,
``[MOISTURE_TRANSPORT]`` (and others, ignored). ``[PARAMETERS]`` lines read ``KEY = value unit``;
a function is a line ``FUNCTION = name`` followed by two lines of numbers, the arguments and the values.
What is read:

- ``RHO`` [kg/m3] -> density, ``CE`` [J/(kg K)] -> specific_heat, ``LAMBDA`` [W/(m K)] -> conductivity,
  ``MEW`` [-] -> vapour_resistance_factor, ``THETA_EFF`` [m3/m3] -> the saturation content, ``AW``
  [kg/(m2 s^0.5)] -> a Kuenzel liquid transport when the file has no ``lgKl(Theta_l)``;
- ``Theta_l(pC)_de`` (moisture content [m3/m3] against ``pC = log10(pc [Pa])``, desorption) ->
  ``moisture_storage = {form = "suction_table", log10_pc, w}`` (w = 1000 Theta_l kg/m3);
- ``lgKl(Theta_l)`` (log10 of the liquid conductivity [s] against Theta_l) ->
  ``liquid_transport = {form = "conductivity_table", w, log10_k}``.

Bad input raises :class:`~wallcal.errors.StudyError` with one line naming the file and what is wrong.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import StudyError

#: largest .m6 file read [bytes]
MAX_BYTES = 2_000_000
_PARAMETERS = {"RHO": "density", "CE": "specific_heat", "LAMBDA": "conductivity", "MEW": "vapour_resistance_factor"}


def _numbers(line: str, path: Path, what: str) -> list[float]:
    try:
        return [float(v) for v in line.split()]
    except ValueError:
        raise StudyError([f"{path}: {what}: a line of numbers expected, got {line.strip()[:60]!r}"]) from None


def read_m6(path: str | Path) -> dict:
    """The layer keys (thermal and hygric) a DELPHIN 6 material file gives (see the module docstring)."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise StudyError([f"{path}: larger than {MAX_BYTES:,} bytes; not a DELPHIN material file"])
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise StudyError([f"{path}: cannot read the DELPHIN material file ({exc.strerror or exc})"]) from None
    sections: dict[str, list[str]] = {}
    current = None
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        s = line.strip()
        if s.startswith("[") and s.endswith("]"):
            current = s[1:-1].strip().upper()
            sections[current] = []
        elif current is not None:
            sections[current].append(s)
    if "PARAMETERS" not in sections:
        raise StudyError([f"{path}: no [PARAMETERS] section; not a DELPHIN 6 material file"])
    params: dict[str, float] = {}
    for s in sections["PARAMETERS"]:
        if "=" not in s:
            continue
        key, value = (v.strip() for v in s.split("=", 1))
        try:
            params[key.upper()] = float(value.split()[0])
        except (ValueError, IndexError):
            raise StudyError([f"{path}: [PARAMETERS] {key}: a number expected, got {value[:40]!r}"]) from None
    functions: dict[str, tuple[list[float], list[float]]] = {}
    for sec in ("MOISTURE_STORAGE", "MOISTURE_TRANSPORT"):
        lines = sections.get(sec, [])
        k = 0
        while k < len(lines):
            s = lines[k]
            if s.upper().startswith("FUNCTION") and "=" in s:
                name = s.split("=", 1)[1].strip()
                if k + 2 >= len(lines):
                    raise StudyError([f"{path}: [{sec}] {name}: needs two lines of numbers"])
                xs = _numbers(lines[k + 1], path, f"[{sec}] {name}")
                ys = _numbers(lines[k + 2], path, f"[{sec}] {name}")
                if len(xs) != len(ys) or len(xs) < 2:
                    raise StudyError(
                        [f"{path}: [{sec}] {name}: {len(xs)} arguments and {len(ys)} values (same number, >= 2)"]
                    )
                functions[name] = (xs, ys)
                k += 3
            else:
                k += 1
    out: dict = {dst: params[src] for src, dst in _PARAMETERS.items() if src in params}
    if "Theta_l(pC)_de" not in functions:
        raise StudyError([f"{path}: [MOISTURE_STORAGE] has no function Theta_l(pC)_de (the storage function)"])
    pcs, theta = functions["Theta_l(pC)_de"]
    out["moisture_storage"] = {"form": "suction_table", "log10_pc": pcs, "w": [1000.0 * v for v in theta]}
    if "lgKl(Theta_l)" in functions:
        th, lgk = functions["lgKl(Theta_l)"]
        out["liquid_transport"] = {"form": "conductivity_table", "w": [1000.0 * v for v in th], "log10_k": lgk}
    elif params.get("AW", 0.0) > 0:
        out["liquid_transport"] = {"form": "kuenzel", "absorption": params["AW"]}
    return out
