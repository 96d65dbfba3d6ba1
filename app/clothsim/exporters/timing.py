"""Which states an export writes, and at which time codes: at the simulation's own rate, or
resampled to another frame rate.

At the simulation's rate (``out_fps`` None or equal to frames_per_sec) the time codes are the
simulated frame numbers ``start, start + K, ...`` and the last one, each written exactly. At
another rate F, time code k is the moment k / F seconds; the frames written are every K-th of
those that fall within the simulated span, and the last of them. A moment that falls on a
simulated frame is that frame's state; one between two frames is their linear interpolation,
point by point. Ratios are exact (:class:`fractions.Fraction` of the two rates), so 90 -> 30 hits
every third frame exactly and never drifts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..errors import ClothsimError
from ..sweeps.runner import sample_frames
from ..validate import check, number

__all__ = ["MAX_OUT_FPS", "Sample", "check_out_fps", "exported_samples", "blend"]

#: The highest output frame rate accepted (a sample every 0.1 ms; more would only make files larger).
MAX_OUT_FPS = 10000.0


@dataclass(frozen=True)
class Sample:
    """One exported frame: its time ``code`` (frame number at the output rate), the simulated
    ``frame`` at or just before it and ``weight``, the share of ``frame + 1`` (0: exactly ``frame``)."""

    code: int
    frame: int
    weight: float

    @property
    def last_frame(self) -> int:
        """The last simulated frame this sample needs."""
        return self.frame + (1 if self.weight else 0)


def check_out_fps(value: float | None, field: str = "out_fps") -> float | None:
    """``value`` as a frame rate in (0, :data:`MAX_OUT_FPS`], or None; one line naming ``field``."""
    if value is None:
        return None
    return check(number(gt=0.0, le=MAX_OUT_FPS), value, field)


def exported_samples(start: int, frames: int, every: int, sim_fps: float, out_fps: float | None = None,
                     field: str = "out_fps") -> list[Sample]:
    """The frames an export writes, in order: see the module's text. ``start`` is the first
    simulated frame, ``frames`` how many are simulated after it, ``every`` the step between
    written frames (at the output rate). Raises one :class:`ClothsimError` line when no output
    frame falls within the simulated span."""
    if out_fps is None or float(out_fps) == float(sim_fps):
        return [Sample(start + f, start + f, 0.0) for f in sample_frames(frames, every)]
    ratio = Fraction(float(out_fps)) / Fraction(float(sim_fps))  # output frames per simulated frame
    first = math.ceil(start * ratio)
    last = math.floor((start + frames) * ratio)
    if first > last:
        raise ClothsimError(f"{field} {out_fps:g}: no frame at that rate falls between simulated frames "
                            f"{start} and {start + frames} (simulate more frames)")
    codes = [first + c for c in sample_frames(last - first, every)]
    out = []
    for code in codes:
        at = code / ratio  # in simulated frames
        frame = math.floor(at)
        out.append(Sample(code, frame, float(at - frame)))
    return out


def blend(before: np.ndarray, after: np.ndarray, weight: float) -> np.ndarray:
    """Linear interpolation ``before + weight (after - before)`` in float64, (N, 3)."""
    a = np.asarray(before, dtype=np.float64)
    return a + weight * (np.asarray(after, dtype=np.float64) - a)
