"""The accelerometer's front end for tilt: raw outputs (volts, counts) → specific force.

P3 (compass) and the live readouts need pitch and roll from an accelerometer that may only
speak volts or counts. A bench engineer expects the station to use the best it knows about
that unit, in this order:

1. the device's **last accepted P1 calibration** (``A = B + M V``, in the same raw unit):
   the unit's own zero and scale, measured;
2. the **front end the device declares** (a capture's or device's ``accel_offset`` and
   ``accel_scale_mps2_per_unit`` metadata; the simulated device's data-sheet values);
3. nothing: a raw unit with neither gets no tilt (never a guess).

An accelerometer already in physical units (``g``, ``m/s^2``) needs none of this.

Capture metadata (written by the TUI, read by ``station calibrate``):

- ``accel_offset``: the zero-g output per axis, ``x, y, z`` in ``accel_unit`` (P4 mode B
  reads the same key);
- ``accel_scale_mps2_per_unit``: m/s² per ``accel_unit``: one number (all axes), three (per
  axis) or nine (the row-major matrix ``M`` of P1);
- ``accel_frontend``: where they came from (``P1 calibration #12 (2026-11-20)`` or
  ``nominal (data sheet)``), for the record.

Then ``f = M (V − offset)``, i.e. P1's ``A = B + M V`` with ``B = −M offset``
(``solvers.models.accel.p1_apply``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solvers.models import accel as accel_model

OFFSET_KEY = "accel_offset"
SCALE_KEY = "accel_scale_mps2_per_unit"
SOURCE_KEY = "accel_frontend"


class FrontendError(ValueError):
    """Metadata that does not describe a front end (the message says which key and why)."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class Frontend:
    """``f [m/s²] = B + M V``; ``source`` says where B and M came from."""

    B: np.ndarray  # (3,) m/s²
    M: np.ndarray  # (3, 3) m/s² per raw unit
    source: str

    @classmethod
    def from_nominal(cls, zero, sensitivity_per_mps2, source: str = "nominal (data sheet)") -> Frontend:
        """A data-sheet front end: zero-g output ``zero`` and sensitivity (raw units per m/s²),
        scalars or per axis."""
        zero = np.broadcast_to(np.asarray(zero, float), (3,)).copy()
        sens = np.broadcast_to(np.asarray(sensitivity_per_mps2, float), (3,))
        M = np.diag(1.0 / sens)
        return cls(-M @ zero, M, source)

    @classmethod
    def from_p1(cls, record: dict) -> Frontend:
        """A stored P1 calibration (a ``Store.history`` row): its B and M."""
        from station.procedures import registry

        p = record["params"]
        when = str(record.get("time") or "")[:10]
        entry = registry.get(record.get("procedure"))
        code = entry.code if entry is not None else str(record.get("procedure") or "")
        return cls(
            np.asarray(p["B"], float).reshape(3),
            np.asarray(p["M"], float).reshape(3, 3),
            f"{code} calibration #{record.get('id')}" + (f" ({when})" if when else ""),
        )

    @classmethod
    def from_meta(cls, meta: dict) -> Frontend | None:
        """From a capture's metadata (module docstring); None when neither key is there.
        Raises FrontendError on a malformed value or only one of the two keys."""
        off_s, scale_s = meta.get(OFFSET_KEY), meta.get(SCALE_KEY)
        if off_s is None and scale_s is None:
            return None
        if off_s is None or scale_s is None:
            missing = OFFSET_KEY if off_s is None else SCALE_KEY
            raise FrontendError(
                SCALE_KEY if off_s is not None else OFFSET_KEY,
                f"'{SCALE_KEY if off_s is None else OFFSET_KEY}' without '{missing}': give both "
                "(the zero-g output and m/s^2 per unit) or neither",
            )
        off = _numbers(off_s, OFFSET_KEY, (3,))
        s = _numbers(scale_s, SCALE_KEY, (1, 3, 9))
        M = np.diag(np.broadcast_to(s, (3,))) if len(s) in (1, 3) else s.reshape(3, 3)
        if not np.isfinite(M).all() or abs(np.linalg.det(M)) == 0:
            raise FrontendError(SCALE_KEY, f"{SCALE_KEY} {scale_s!r}: the scale must be finite and invertible")
        return cls(-M @ off, M, str(meta.get(SOURCE_KEY) or "capture metadata"))

    @property
    def offset(self) -> np.ndarray:
        """The zero-g output per axis [raw unit]: ``−M⁻¹ B``."""
        return -np.linalg.solve(self.M, self.B)

    def meta(self) -> dict[str, str]:
        """The capture metadata that carries it (module docstring)."""
        M = self.M
        diag = np.allclose(M, np.diag(np.diag(M)), rtol=0, atol=0)
        scale = np.diag(M) if diag else M.reshape(9)
        return {
            OFFSET_KEY: ", ".join(repr(float(x)) for x in self.offset),
            SCALE_KEY: ", ".join(repr(float(x)) for x in scale),
            SOURCE_KEY: self.source,
        }

    def __call__(self, raw) -> np.ndarray:
        """Specific force [m/s²] of raw rows (n, 3) or one sample (3,)."""
        return accel_model.p1_apply(raw, self.B, self.M).reshape(np.shape(raw))


def _numbers(text: str, key: str, sizes: tuple[int, ...]) -> np.ndarray:
    try:
        x = np.array([float(v) for v in str(text).replace(",", " ").split()])
    except ValueError:
        x = np.zeros(0)
    if len(x) not in sizes or not np.isfinite(x).all():
        want = " or ".join(str(n) for n in sizes)
        raise FrontendError(key, f"{key} {text!r}: give {want} finite numbers")
    return x


def for_device(history: list[dict], accel_unit: str | None, nominal=None) -> Frontend | None:
    """The front end a bench engineer expects for a unit whose accelerometer reads
    ``accel_unit``: its last accepted P1 calibration in that unit (``history``: the
    device's calibrations, oldest first; those of the form ``A = B + M V`` count), else
    the device's ``nominal`` ``(zero, sensitivity per m/s²)``, else None."""
    for rec in reversed(history or []):
        unit = ((rec.get("extra") or {}).get("units") or {}).get("V")
        params = rec.get("params") or {}
        if rec.get("accepted") and unit == accel_unit and "B" in params and "M" in params:
            return Frontend.from_p1(rec)
    if nominal is not None:
        return Frontend.from_nominal(*nominal)
    return None
