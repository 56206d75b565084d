"""The wall: a stack of layers with probes.

Conventions (the one place they are written down)
------------------------------------------------
- Layers are listed from the **exterior** face inwards.
- Depth ``x`` [m] is measured from the exterior face of the first layer.
- A heat flux density ``q`` [W/m2] is **positive towards the interior**, at
  either face and inside the wall.
- Temperatures are in degC in the API; the engine works in degC as well
  (only differences and the lambda(T) law enter the physics).
- A layer's conductivity may depend on temperature:
  ``lambda(T) = conductivity * exp(f * (T - reference_temperature))`` (the
  ISO 10456 form, :mod:`wallcal.standards.iso10456`), or a piecewise-linear
  table of ``(T [degC], lambda [W/(m K)])`` points, held constant beyond its ends.
- A layer may be a no-mass resistive layer (an air layer given only its
  ``thermal_resistance`` [m2K/W]); it stores no heat.
- ``contact_resistance`` [m2K/W] of a layer sits between it and the next layer
  inwards.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .standards.iso10456 import temperature_factor

#: Physical range of each layer property a wall file may give, ``(lowest, highest)`` in the property's SI
#: unit (docs/robustness.md): generous, but a value outside is a typing or unit error, and would give a grid
#: or a time constant no engine can run (a conductivity of 1e-300 W/(m K) asks for 1e150 nodes).
LIMITS = {
    "thickness": (1e-6, 10.0),  # m (massive layer); a no-mass layer may be 0 thick
    "conductivity": (1e-3, 500.0),  # W/(m K): vacuum insulation core .. beyond copper
    "density": (0.5, 25_000.0),  # kg/m3: aerogel, air .. beyond osmium
    "specific_heat": (50.0, 50_000.0),  # J/(kg K): lead .. the apparent heat of a phase-change material
    "conductivity_temperature_coefficient": (-0.05, 0.05),  # 1/K: ISO 10456 gives 0.003 .. 0.006
    "reference_temperature": (-100.0, 200.0),  # degC
    "table_temperature": (-100.0, 200.0),  # degC, a conductivity_table's temperatures
    "contact_resistance": (0.0, 10.0),  # m2K/W
    "thermal_resistance": (1e-4, 100.0),  # m2K/W (no-mass layer)
    "vapour_resistance_factor": (1e-3, 1e8),  # - (mu; a vapour barrier reaches 1e7)
    "moisture_conductivity_coefficient": (0.0, 1000.0),  # - (b in lambda_dry (1 + b w / density))
    "sorption_scale": (1e-3, 1e3),  # - (multiplies the storage function)
    "liquid_transport_scale": (0.0, 1e6),  # - (multiplies the liquid transport coefficient)
    "vapour_resistance_shape": (1e-3, 1.0),  # - (HAMSTAD's p in mu(w))
}
#: Most layers in a wall (real walls have a few dozen; each layer costs nodes and arrays).
MAX_LAYERS = 200
#: Most probes in a wall.
MAX_PROBES = 200
#: Most points of a conductivity_table.
MAX_TABLE_POINTS = 1000
#: Largest ratio of lambda(T) to the declared conductivity over the data's temperature range (both ways):
#: beyond it the law is a typing or unit error (ISO 10456's coefficients change lambda by a few per cent per
#: 10 K), and the schemes lose accuracy (fd-cn and fd-reference end in NaN at a ratio of a few hundred).
MAX_LAMBDA_RATIO = 10.0

#: Properties of a layer that calibration may change.
LAYER_PROPERTIES = (
    "conductivity",
    "density",
    "specific_heat",
    "conductivity_temperature_coefficient",
    "contact_resistance",
    "thickness",
    "thermal_resistance",
    "vapour_resistance_factor",
    "moisture_conductivity_coefficient",
    "sorption_scale",
    "liquid_transport_scale",
)
#: A layer's hygric tables kept as JSON text in :attr:`Layer.hygric` (its scalar hygric keys are fields).
HYGRIC_TABLE_KEYS = ("moisture_storage", "liquid_transport", "vapour_resistance_shape")


@dataclass(frozen=True)
class Layer:
    """One homogeneous layer.

    Parameters
    ----------
    id : str
        Identifier, unique in the wall (e.g. ``"3"``).
    thickness : float
        Thickness [m]. May be 0 for a no-mass resistive layer.
    conductivity : float or None
        Thermal conductivity at ``reference_temperature`` [W/(m K)]. None for a
        no-mass resistive layer.
    density : float or None
        Density [kg/m3].
    specific_heat : float or None
        Specific heat capacity [J/(kg K)].
    material : str
        Free text.
    conductivity_temperature_coefficient : float
        f [1/K] in ``lambda(T) = conductivity * exp(f (T - reference_temperature))``.
    reference_temperature : float
        Temperature of the declared conductivity [degC].
    conductivity_table : tuple of (float, float) or None
        Piecewise-linear lambda(T): ``((T_degC, lambda), ...)`` with increasing T,
        constant beyond its ends. When ``conductivity`` is also set, the table is
        scaled so that it passes through ``conductivity`` at ``reference_temperature``.
    contact_resistance : float
        Thermal resistance to the next layer inwards [m2K/W].
    thermal_resistance : float or None
        For a no-mass resistive layer: its resistance [m2K/W].
    vapour_resistance_factor : float or None
        Water vapour diffusion resistance factor mu [-] (ISO 10456); needed only by
        the ISO 13788 condensation check (:mod:`wallcal.retrofitting.glaser`) and the
        heat-and-moisture engine.
    hygric : str
        The layer's hygric tables (:data:`HYGRIC_TABLE_KEYS`: ``moisture_storage``, ``liquid_transport``,
        ``vapour_resistance_shape``) as JSON text ('' when it has none); :meth:`hygric_keys` gives them as a
        dict with the scalar hygric fields. ``docs/moisture.md`` describes the keys.
    moisture_conductivity_coefficient : float or None
        b [-] in ``lambda = lambda_dry (1 + b w / density)`` (heat-and-moisture engine).
    sorption_scale, liquid_transport_scale : float
        Multipliers of the storage function and the liquid transport coefficient (calibration parameters).
    """

    id: str
    thickness: float
    conductivity: float | None = None
    density: float | None = None
    specific_heat: float | None = None
    material: str = ""
    conductivity_temperature_coefficient: float = 0.0
    reference_temperature: float = 10.0
    conductivity_table: tuple[tuple[float, float], ...] | None = None
    contact_resistance: float = 0.0
    thermal_resistance: float | None = None
    vapour_resistance_factor: float | None = None
    hygric: str = ""
    moisture_conductivity_coefficient: float | None = None
    sorption_scale: float = 1.0
    liquid_transport_scale: float = 1.0

    def hygric_keys(self) -> dict:
        """Every hygric key of the layer (``wallcal.moisture.materials.HYGRIC_KEYS``) that it has."""
        import json

        out = json.loads(self.hygric) if self.hygric else {}
        if self.vapour_resistance_factor is not None:
            out["vapour_resistance_factor"] = self.vapour_resistance_factor
        if self.moisture_conductivity_coefficient is not None:
            out["moisture_conductivity_coefficient"] = self.moisture_conductivity_coefficient
        if self.sorption_scale != 1.0:
            out["sorption_scale"] = self.sorption_scale
        if self.liquid_transport_scale != 1.0:
            out["liquid_transport_scale"] = self.liquid_transport_scale
        return out

    def hygric_material(self, where: str | None = None):
        """The layer's :class:`wallcal.moisture.materials.HygricMaterial` (StudyError naming the layer and the
        missing or bad key)."""
        from .moisture.materials import hygric_material

        if self.is_massless:
            from .errors import StudyError

            raise StudyError([f"{where or f'layer {self.id!r}'}: a no-mass layer cannot carry moisture"])
        return hygric_material(
            self.material or self.id,
            self.hygric_keys(),
            conductivity=float(self.conductivity_at(self.reference_temperature)),
            density=float(self.density),
            specific_heat=float(self.specific_heat),
            where=where or f"layer {self.id!r}",
        )

    @property
    def is_massless(self) -> bool:
        """True for a no-mass resistive layer."""
        return self.thermal_resistance is not None

    @property
    def is_temperature_dependent(self) -> bool:
        """True when the conductivity depends on temperature."""
        return (not self.is_massless) and (
            self.conductivity_temperature_coefficient != 0.0 or self.conductivity_table is not None
        )

    @property
    def volumetric_heat_capacity(self) -> float:
        """rho * c [J/(m3 K)]; 0 for a no-mass layer."""
        if self.is_massless:
            return 0.0
        return float(self.density) * float(self.specific_heat)

    @property
    def diffusivity(self) -> float:
        """Thermal diffusivity at the reference temperature [m2/s]."""
        if self.is_massless:
            return float("inf")
        return float(self.conductivity_at(self.reference_temperature)) / self.volumetric_heat_capacity

    @property
    def areal_heat_capacity(self) -> float:
        """rho * c * d [J/(m2 K)]."""
        return self.volumetric_heat_capacity * self.thickness

    @property
    def resistance(self) -> float:
        """Thermal resistance d / lambda at the reference temperature [m2K/W] (no contact)."""
        if self.is_massless:
            return float(self.thermal_resistance)
        return self.thickness / float(self.conductivity_at(self.reference_temperature))

    def conductivity_at(self, temperature_C):
        """Conductivity [W/(m K)] at ``temperature_C`` [degC] (scalar or array)."""
        if self.is_massless:
            raise ValueError(f"layer {self.id!r} is a no-mass layer and has no conductivity")
        if self.conductivity_table is not None:
            table = np.asarray(self.conductivity_table, dtype=float)
            lam = np.interp(temperature_C, table[:, 0], table[:, 1])
            if self.conductivity is not None:  # a calibrated conductivity scales the table
                lam = lam * float(self.conductivity) / np.interp(self.reference_temperature, table[:, 0], table[:, 1])
            return float(lam) if np.ndim(lam) == 0 else lam
        lam = float(self.conductivity) * temperature_factor(
            self.conductivity_temperature_coefficient,
            np.asarray(temperature_C, dtype=float) - self.reference_temperature,
        )
        return float(lam) if np.ndim(lam) == 0 else lam

    def conductivity_range(self, low_C: float, high_C: float) -> tuple[float, float]:
        """Lowest and highest conductivity [W/(m K)] over the temperatures ``low_C`` .. ``high_C`` [degC]
        (the exponential law is monotone; a table is piecewise linear, so its points and the ends suffice)."""
        temps = [low_C, high_C]
        if self.conductivity_table is not None:
            temps += [t for t, _ in self.conductivity_table if low_C < t < high_C]
        lam = np.atleast_1d(self.conductivity_at(np.asarray(temps, dtype=float)))
        return float(np.min(lam)), float(np.max(lam))

    def replace(self, **changes) -> Layer:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Probe:
    """A temperature probe inside the wall (or on a face).

    Parameters
    ----------
    name : str
        Probe name (matches a sensor's ``name``).
    depth : float
        Depth from the exterior face [m].
    side : str or None
        At an interface carrying a contact resistance, which face the probe
        touches: ``"exterior"`` (the outer layer's face), ``"interior"``, or
        None for the mean of both.
    """

    name: str
    depth: float
    side: str | None = None


@dataclass(frozen=True)
class Wall:
    """A stack of layers (exterior first) with probes.

    Parameters
    ----------
    layers : tuple of Layer
    probes : tuple of Probe
    name, description : str
    """

    layers: tuple[Layer, ...]
    probes: tuple[Probe, ...] = ()
    name: str = ""
    description: str = ""
    meta: dict = field(default_factory=dict, compare=False, hash=False)

    # ------------------------------------------------------------------ geometry
    @property
    def thickness(self) -> float:
        """Total thickness [m]."""
        return float(sum(layer.thickness for layer in self.layers))

    @property
    def interfaces(self) -> np.ndarray:
        """Depths [m] of the faces of every layer: 0, d1, d1+d2, ..., total."""
        return np.concatenate([[0.0], np.cumsum([layer.thickness for layer in self.layers])])

    def layer_index(self, layer_id: str) -> int:
        """Index of the layer with this id."""
        for i, layer in enumerate(self.layers):
            if layer.id == layer_id:
                return i
        raise KeyError(layer_id)

    def probe(self, name: str) -> Probe:
        for p in self.probes:
            if p.name == name:
                return p
        raise KeyError(name)

    # ------------------------------------------------------------------ steady-state figures
    @property
    def resistance(self) -> float:
        """Surface-to-surface thermal resistance R [m2K/W], at each layer's reference temperature."""
        return float(sum(layer.resistance + layer.contact_resistance for layer in self.layers[:-1])) + (
            self.layers[-1].resistance
        )

    def u_value(self, rsi: float = 0.13, rse: float = 0.04) -> float:
        """Thermal transmittance U = 1 / (Rsi + R + Rse) [W/(m2K)].

        Parameters
        ----------
        rsi, rse : float
            Interior and exterior surface resistances [m2K/W] (ISO 6946
            horizontal heat flow defaults).
        """
        return 1.0 / (rsi + self.resistance + rse)

    @property
    def areal_heat_capacity(self) -> float:
        """Total areal heat capacity sum(rho c d) [J/(m2 K)]."""
        return float(sum(layer.areal_heat_capacity for layer in self.layers))

    @property
    def is_linear(self) -> bool:
        """True when no conductivity depends on temperature."""
        return not any(layer.is_temperature_dependent for layer in self.layers)

    def conductivity_problems(self, low_C: float, high_C: float) -> list[str]:
        """What is wrong with the layers' lambda(T) over the temperatures ``low_C`` .. ``high_C`` [degC] (the
        data's): each problem ``"wall.layers[i]...: ..."``; empty when every lambda(T) stays within
        ``LIMITS["conductivity"]`` and within a factor :data:`MAX_LAMBDA_RATIO` of the declared conductivity."""
        out = []
        lowest, highest = LIMITS["conductivity"]
        for i, layer in enumerate(self.layers):
            if not layer.is_temperature_dependent:
                continue
            lo, hi = layer.conductivity_range(low_C, high_C)
            ref = float(layer.conductivity_at(layer.reference_temperature))
            if lo >= lowest and hi <= highest and hi <= MAX_LAMBDA_RATIO * ref and lo >= ref / MAX_LAMBDA_RATIO:
                continue
            key = (
                "conductivity_table"
                if layer.conductivity_table is not None
                else ("conductivity_temperature_coefficient")
            )
            out.append(
                f"wall.layers[{i}].{key}: lambda(T) spans {lo:.3g} .. {hi:.3g} W/(m K) over the data's "
                f"{low_C:.1f} .. {high_C:.1f} degC, beyond {lowest:g} .. {highest:g} or a factor "
                f"{MAX_LAMBDA_RATIO:g} of its {ref:.3g} (ISO 10456: about 0.005 1/K)"
            )
        return out

    def nonfinite_cause(self) -> str:
        """The likely cause of a simulation that ended in NaN or inf, and what to do, in words."""
        nonlinear = [f"{i}" for i, layer in enumerate(self.layers) if layer.is_temperature_dependent]
        if nonlinear:
            return (
                f"likely cause: the lambda(T) law of wall.layers[{', '.join(nonlinear[:5])}]; lower its "
                "conductivity_temperature_coefficient or conductivity_table, or use a shorter time step or fd-implicit"
            )
        return (
            "likely cause: a very thin or very conductive layer next to a massive one; use a shorter "
            "simulation.time_step or a smaller grid_constant, or declare the thin layer massless (thermal_resistance)"
        )

    # ------------------------------------------------------------------ editing
    def replace_layer(self, layer_id: str, **changes) -> Wall:
        """A copy with one layer's fields changed."""
        i = self.layer_index(layer_id)
        layers = list(self.layers)
        layers[i] = layers[i].replace(**changes)
        return dataclasses.replace(self, layers=tuple(layers))

    def replace_probe(self, name: str, **changes) -> Wall:
        """A copy with one probe's fields changed."""
        probes = tuple(dataclasses.replace(p, **changes) if p.name == name else p for p in self.probes)
        return dataclasses.replace(self, probes=probes)

    def replace(self, **changes) -> Wall:
        return dataclasses.replace(self, **changes)

    def steady_profile(self, t_ext: float, t_int: float, depths) -> np.ndarray:
        """Series-resistance steady temperatures [degC] at ``depths`` [m] for constant
        conductivities and imposed surface temperatures (used in tests and docs)."""
        r_at = []
        r = 0.0
        xs = [0.0]
        rs = [0.0]
        for layer in self.layers:
            r += layer.resistance
            xs.append(xs[-1] + layer.thickness)
            rs.append(r)
            if layer.contact_resistance:
                r += layer.contact_resistance
                xs.append(xs[-1])
                rs.append(r)
        xs_a, rs_a = np.array(xs), np.array(rs)
        for d in np.atleast_1d(depths):
            r_at.append(np.interp(d, xs_a, rs_a))
        r_at = np.array(r_at)
        return t_ext + (t_int - t_ext) * r_at / rs_a[-1]
