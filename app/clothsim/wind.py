"""Wind: the scene's ``wind`` object (validation) and its gust field's seeded modes.

``"wind": {"velocity": [vx, vy, vz], "turbulence": 0.0, "drag": 1.0, "lift": 0.0,
"air_density": 1.2, "seed": 0, "turbulence_scale": 1.0}`` (SI units; one object or a list).
``turbulence`` is the largest speed (m/s) the gusts add to ``velocity``; ``turbulence_scale`` the
length (m) of the largest gust. The forces themselves are computed by
:mod:`clothsim.sim.passes.wind`.

The gust field of one wind is a sum of :data:`GUST_MODES` travelling waves,

    g(x, t) = turbulence * sum_k a_k d_k w(k_k . (x - U t) - f_k t + phi_k),

with ``U`` the mean velocity (gusts are carried by the wind), unit directions ``d_k``, weights
``a_k`` summing to 1 and ``w`` a C1 periodic wave bounded by 1 (see :func:`clothsim.sim.passes.wind.wave`),
so ``|g| <= turbulence`` everywhere and at every time; the modes (directions, wave vectors in
cycles per metre, frequencies in Hz, phases in cycles) are drawn from ``seed`` alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import validate as V

#: Travelling waves in one wind's gust field.
GUST_MODES = 4
#: Floats per mode in :func:`gust_modes`' rows: k (3, cycles/m), amplitude * direction (3),
#: phase rate (cycles/s, the frequency plus the advection k . U), phase (cycles).
MODE_FLOATS = 8
#: Floats per wind in :func:`wind_rows`: velocity (3), 1/2 rho C_d, rho C_L, turbulence.
WIND_FLOATS = 6
# Added by a blowing wind (counted from its arrays, not measured): two triangles a point, each
# with its corners (3 x 8 B), force (3 x 8 B) and work space (12 x 8 B), and a point's list of
# triangles (7 x 8 B): 344 B, plus 25 %.
WIND_BYTES_PER_POINT = 432


@dataclass(frozen=True)
class WindSpec:
    """One validated ``wind`` object."""

    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    turbulence: float = 0.0
    drag: float = 1.0
    lift: float = 0.0
    air_density: float = 1.2
    seed: int = 0
    turbulence_scale: float = 1.0

    @property
    def still(self) -> bool:
        """True for zero velocity and zero turbulence: no wind at all (the scene's air is still,
        and still air is the course model's: no air drag), so it is left out of the run."""
        return self.turbulence == 0.0 and not any(self.velocity)

    def as_json(self) -> dict[str, Any]:
        """The object as a scene file writes it."""
        return {"velocity": list(self.velocity), "turbulence": self.turbulence, "drag": self.drag,
                "lift": self.lift, "air_density": self.air_density, "seed": self.seed,
                "turbulence_scale": self.turbulence_scale}


# Speeds beyond a hurricane's are refused: the explicit drag term (see sim/passes/wind.py) needs
# dt * rho * C_d * |v| / density well below 1.
MAX_SPEED = 1e3
_DEFAULTS = WindSpec()

_FIELDS = V.record({
    "velocity": V.default(V.vec3(V.number(ge=-MAX_SPEED, le=MAX_SPEED)), _DEFAULTS.velocity),
    "turbulence": V.default(V.number(ge=0.0, le=MAX_SPEED), _DEFAULTS.turbulence),
    "drag": V.default(V.number(ge=0.0, le=100.0), _DEFAULTS.drag),
    "lift": V.default(V.number(ge=-100.0, le=100.0), _DEFAULTS.lift),
    "air_density": V.default(V.number(ge=0.0, le=1e4), _DEFAULTS.air_density),
    "seed": V.default(V.integer(ge=0, le=2**63 - 1), _DEFAULTS.seed),
    "turbulence_scale": V.default(V.number(gt=0.0, le=1e6), _DEFAULTS.turbulence_scale),
})


def WIND(value: Any, at: V.At) -> WindSpec:  # noqa: N802 - a rule, named like the scene's records
    """The rule for one ``wind`` object (every key optional, SI units)."""
    if isinstance(value, WindSpec):
        return value
    return WindSpec(**_FIELDS(value, at))


#: The rule for the top-level ``wind``: null, one object or a list of them.
WINDS = V.one_or_many(WIND)


def gust_modes(wind: WindSpec) -> np.ndarray:
    """(GUST_MODES, MODE_FLOATS) rows of the wind's gust field, drawn from its seed alone."""
    rng = np.random.default_rng([wind.seed, 0x57494E44])  # the seed, and a tag that is this field's
    rows = np.zeros((GUST_MODES, MODE_FLOATS))
    weights = rng.uniform(0.5, 1.0, GUST_MODES)
    weights /= weights.sum()
    for k in range(GUST_MODES):
        # wavelengths from the scale down to a quarter of it; a quarter to one cycle per second
        wavelength = wind.turbulence_scale * 2.0 ** (-k * 2.0 / (GUST_MODES - 1) + rng.uniform(-0.25, 0.25))
        direction = _unit(rng.normal(size=3))
        wave = _unit(rng.normal(size=3)) / wavelength
        frequency = rng.uniform(0.25, 1.0)
        rows[k, 0:3] = wave
        rows[k, 3:6] = weights[k] * direction
        rows[k, 6] = frequency + float(wave @ np.asarray(wind.velocity))
        rows[k, 7] = rng.uniform(0.0, 1.0)
    return rows


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0.0 else np.array([1.0, 0.0, 0.0])


def wind_rows(winds: tuple[WindSpec, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The winds that blow (still ones left out) as kernel arrays: (W, WIND_FLOATS) and their
    gust modes (W, GUST_MODES, MODE_FLOATS)."""
    blowing = [w for w in winds if not w.still]
    rows = np.array([[*w.velocity, 0.5 * w.air_density * w.drag, w.air_density * w.lift, w.turbulence]
                     for w in blowing], dtype=np.float64).reshape(-1, WIND_FLOATS)
    modes = np.array([gust_modes(w) for w in blowing], dtype=np.float64).reshape(-1, GUST_MODES, MODE_FLOATS)
    return rows, modes


def wind_speed(winds: tuple[WindSpec, ...]) -> float:
    """Bound (m/s) on the air's speed: the fastest wind with its gusts (the blow-up guard's)."""
    return max((math.hypot(*w.velocity) + w.turbulence for w in winds), default=0.0)
