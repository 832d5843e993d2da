"""Physical units of the mapped signals: checked against the DBC, converted at decode time.

A temperature is binned in °C and a drift in the session's drift unit
(``session.drift_unit``, default deg/h). A DBC signal in another unit the project knows is
converted by an exact linear map ``v' = v·scale + offset``:

    K -> °C:    T_C = T_K - 273.15            mK -> °C:  T_C = 0.001·T_mK - 273.15
    °F -> °C:   T_C = (T_F - 32)·5/9          rad/s -> deg/h:  ω·(180/π)·3600

A signal already in the target unit gets no conversion at all (``None``: its samples are
the decoded values, to the bit). A unit the project cannot convert (``V``, ``km/h``, a
temperature as a drift) is a :class:`UnitError` naming the unit; the session parser
prefixes it with the key path. A signal without a unit is taken as the target unit (the
parser logs it: the DBC does not say).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["Conversion", "UnitError", "TEMPERATURE_UNIT", "DEFAULT_DRIFT_UNIT", "norm_unit",
           "temperature_conversion", "rate_conversion", "rate_units", "temperature_units"]

TEMPERATURE_UNIT = "degC"
DEFAULT_DRIFT_UNIT = "deg/h"


class UnitError(ValueError):
    """A unit the project cannot convert to the channel's unit."""


def norm_unit(unit: str | None) -> str:
    """A DBC unit string in one spelling: lower case, no blanks, ``°``/``degree`` as
    ``deg``, ``/sec`` ``/hour`` ``/hr`` as ``/s`` ``/h``.

    >>> norm_unit("°/h"), norm_unit("Deg/Sec"), norm_unit("°F"), norm_unit(" Kelvin ")
    ('deg/h', 'deg/s', 'degf', 'kelvin')
    """
    u = (unit or "").strip().lower().replace(" ", "")
    u = u.replace("°", "deg").replace("º", "deg").replace("degree", "deg").replace("degs", "deg")
    u = u.replace("/sec", "/s").replace("/hour", "/h").replace("/hr", "/h")
    return u.replace("per", "/")


#: temperature units as (scale, offset) to °C
_TEMPERATURE = {
    "degc": (1.0, 0.0), "c": (1.0, 0.0), "celsius": (1.0, 0.0), "degcelsius": (1.0, 0.0),
    "k": (1.0, -273.15), "degk": (1.0, -273.15), "kelvin": (1.0, -273.15),
    "mk": (0.001, -273.15), "millikelvin": (0.001, -273.15),
    "degf": (5.0 / 9.0, -160.0 / 9.0), "f": (5.0 / 9.0, -160.0 / 9.0),
    "fahrenheit": (5.0 / 9.0, -160.0 / 9.0), "degfahrenheit": (5.0 / 9.0, -160.0 / 9.0),
    "mdegc": (0.001, 0.0), "cdegc": (0.01, 0.0),
}
_RAD = 180.0 / math.pi
#: angular-rate units as deg/h per unit
_RATE = {
    "deg/h": 1.0, "dph": 1.0, "deg/min": 60.0, "deg/s": 3600.0, "dps": 3600.0,
    "mdeg/s": 3.6, "rad/s": _RAD * 3600.0, "mrad/s": _RAD * 3.6, "urad/s": _RAD * 3.6e-3,
    "µrad/s": _RAD * 3.6e-3, "rad/h": _RAD, "arcsec/s": 1.0, "arcsec/h": 1.0 / 3600.0,
    "rpm": 360.0 * 60.0, "rev/min": 360.0 * 60.0,
}


def rate_units() -> tuple[str, ...]:
    """The angular-rate units the project converts (normalised spellings)."""
    return tuple(_RATE)


def temperature_units() -> tuple[str, ...]:
    """The temperature units the project converts (normalised spellings)."""
    return tuple(_TEMPERATURE)


@dataclass(frozen=True)
class Conversion:
    """``value·scale + offset``: a signal's decoded value (in ``source``) in ``target``."""

    source: str
    target: str
    scale: float
    offset: float

    def __call__(self, value: float) -> float:
        return value * self.scale + self.offset

    def inverse(self, value: float) -> float:
        """The source-unit value of a target-unit ``value`` (the stand simulator encodes
        its truth, given in the session's units, into the DBC's)."""
        return (value - self.offset) / self.scale

    def describe(self) -> str:
        """``K -> degC (v - 273.15)``, as ``init`` and ``run --check`` print it."""
        if self.scale == 1.0:
            how = f"v {'+' if self.offset >= 0 else '-'} {abs(self.offset):.6g}"
        elif self.offset == 0.0:
            how = f"v × {self.scale:.10g}"
        else:
            how = f"v × {self.scale:.6g} {'+' if self.offset >= 0 else '-'} " \
                  f"{abs(self.offset):.6g}"
        return f"{self.source} -> {self.target} ({how})"


def _known(unit: str | None, table: Mapping[str, object], what: str) -> str | None:
    """``unit`` normalised, None when blank; :class:`UnitError` ("is not ``what``") when
    ``table`` does not know it."""
    u = norm_unit(unit)
    if not u:
        return None
    if u not in table:
        raise UnitError(f"unit {unit!r} is not {what}")
    return u


def temperature_conversion(unit: str | None) -> Conversion | None:
    """The conversion of a temperature in ``unit`` to °C; None when it already is (or the
    DBC gives no unit). Raises :class:`UnitError` for a unit that is no temperature."""
    u = _known(unit, _TEMPERATURE, f"a temperature the project converts to "
                                   f"{TEMPERATURE_UNIT} (it knows degC, K, mK, degF)")
    if u is None:
        return None
    scale, offset = _TEMPERATURE[u]
    if scale == 1.0 and offset == 0.0:
        return None
    return Conversion(str(unit), TEMPERATURE_UNIT, scale, offset)


def rate_conversion(unit: str | None, target: str = DEFAULT_DRIFT_UNIT) -> Conversion | None:
    """The conversion of an angular rate in ``unit`` to ``target``; None when it already
    is (or the DBC gives no unit). Raises :class:`UnitError` for a unit that is no
    angular rate (or a ``target`` that is none)."""
    t = norm_unit(target)
    if t not in _RATE:
        raise UnitError(f"drift unit {target!r} is not an angular rate the project knows "
                        f"({', '.join(_RATE)})")
    u = _known(unit, _RATE, f"an angular rate the project converts to {target} (it knows "
                            f"{', '.join(_RATE)})")
    if u is None:
        return None
    scale = _RATE[u] / _RATE[t]
    if scale == 1.0:
        return None
    return Conversion(str(unit), str(target), scale, 0.0)
