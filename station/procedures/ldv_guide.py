"""The guided P5 run (three-beam laser velocimeter against INS/DGPS) as a UI-free state
machine: the vehicle drives while the station records the beams and the reference
velocity, and shows the procedure's own check as it builds: the conditioning of the
body velocity set, ``κ = cond(HᵀH)`` (``solvers.ldv.velocity_condition``: the number the
P5 calibration refuses above ``KAPPA_REFUSE`` and warns about above ``KAPPA_WARN``), from
running sums of ``HᵀH``, with the per-beam least squares ``X_j = (HᵀH)⁻¹ Hᵀ V_Lj`` and its
read-out (δK, α, β, γ; ``solvers.models.ldv.angles_from_X``) once κ allows it.

The set is **enough** when κ ≤ ``KAPPA_WARN`` and has stayed so for ``good_for_s`` (a set
that just crossed the line is marginal: more turns keep it well inside), at least
``min_epochs`` moving epochs are in and ``min_s`` have been recorded; the recording then
ends by itself (``f`` ends it earlier,
the calibration still refuses an ill-conditioned set). Epochs with the vehicle parked
(|v| < ``moving_mps``) are recorded but add nothing to HᵀH worth counting.

Phases: ``record`` → ``done`` | ``aborted``. Times are the samples' own ``t_s``. The capture
is a P5 time series (``t vl1 vl2 vl3 vx vy vz wx wy wz temp_c``, the reference in the body
frame, x forward, y right, z down) for ``station.procedures.ldv``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from solvers.ldv import KAPPA_REFUSE, KAPPA_WARN
from solvers.models import ldv as ldv_model
from station.procedures.guide_base import GuideBase, recorded_columns, site_meta, started_utc

BEAMS = ("vl1", "vl2", "vl3")
REF = ("vx", "vy", "vz")
RATES = ("wx", "wy", "wz")


@dataclass
class LdvConfig:
    """min_s: shortest recording [s]; max_s: the recording ends here whatever κ [s];
    min_epochs: moving epochs needed; moving_mps: speed under which an epoch is "parked";
    good_for_s: how long κ must have stayed at or below KAPPA_WARN [s]."""

    min_s: float = 120.0
    good_for_s: float = 30.0
    max_s: float = 1800.0
    min_epochs: int = 300
    moving_mps: float = 0.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.good_for_s) and self.good_for_s >= 0):
            raise ValueError(f"good_for_s must be >= 0, got {self.good_for_s!r}")
        if not (0 <= self.min_s <= self.max_s and self.max_s > 0):
            raise ValueError("min_s and max_s must satisfy 0 <= min_s <= max_s, max_s > 0")
        if not (isinstance(self.min_epochs, int) and self.min_epochs >= 4):
            raise ValueError(f"min_epochs must be an integer >= 4, got {self.min_epochs!r}")
        if not (math.isfinite(self.moving_mps) and self.moving_mps >= 0):
            raise ValueError(f"moving_mps must be >= 0, got {self.moving_mps!r}")


@dataclass(frozen=True)
class LdvStatus:
    phase: str
    kappa: float  # cond(HᵀH) of the moving epochs so far (inf before 3 independent directions)
    verdict: str  # "none" | "refused" (> KAPPA_REFUSE) | "poor" (> KAPPA_WARN) | "good"
    enough: bool
    n_epochs: int  # moving epochs
    n_samples: int
    recorded_s: float
    speed_mps: float  # |reference velocity| now
    v_ref: tuple[float, float, float]  # reference body velocity now (m/s)
    beams: tuple[tuple[float, float, float], ...]  # now (m/s)
    estimate: tuple[tuple[float, float, float, float], ...] | None  # per beam (δK, α°, β°, γ°)
    t_s: float
    message: str


class LdvGuide(GuideBase):
    procedure = "ldv"

    def __init__(
        self, *, sample_rate_hz: float, device_id: str = "", site: dict | None = None, config: LdvConfig | None = None
    ):
        self.config = config or LdvConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.device_id = device_id
        self.site = dict(site or {})
        self.started = started_utc()
        self.phase = "record"
        self._events: list[tuple[str, str]] = []
        self._reset()

    def _reset(self) -> None:
        self._chunks: list[dict[str, np.ndarray]] = []
        self._n = 0
        self._epochs = 0
        self._HtH = np.zeros((3, 3))
        self._HtY = np.zeros((3, 3))  # column j: Hᵀ V_Lj
        self._t0 = math.nan
        self._t1 = math.nan
        self._good_since = math.nan  # device time κ last came down to KAPPA_WARN
        self._last = None
        self._message = "Drive: the station records the beams and the INS/DGPS velocity"

    @property
    def kappa(self) -> float:
        if self._epochs < 3:
            return math.inf
        ev = np.linalg.eigvalsh(self._HtH)
        return float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf

    def update(self, t_s, beams, v_ref, rates=None, temp_c=None) -> LdvStatus:
        """t_s (n,), beams (n, 3) m/s, v_ref (n, 3) body-frame reference m/s (FRD), rates
        (n, 3) rad/s or None, temp_c (n,) or None."""
        t_s = np.asarray(t_s, float)
        if len(t_s) == 0 or self.phase != "record":
            return self.status()
        beams, v_ref = (np.asarray(x, float).reshape(-1, 3) for x in (beams, v_ref))
        rates = np.full((len(t_s), 3), np.nan) if rates is None else np.asarray(rates, float).reshape(-1, 3)
        temp = np.full(len(t_s), np.nan) if temp_c is None else np.asarray(temp_c, float)
        self._chunks.append({"t": t_s, "vl": beams, "v": v_ref, "w": rates, "temp": temp})
        self._n += len(t_s)
        if not math.isfinite(self._t0):
            self._t0 = float(t_s[0])
        self._t1 = float(t_s[-1])
        ok = np.all(np.isfinite(beams), axis=1) & np.all(np.isfinite(v_ref), axis=1)
        moving = ok & (np.linalg.norm(np.where(ok[:, None], v_ref, 0.0), axis=1) >= self.config.moving_mps)
        H, Y = v_ref[moving], beams[moving]
        self._epochs += len(H)
        self._HtH += H.T @ H
        self._HtY += H.T @ Y
        self._last = (v_ref[-1], beams[-1])
        if self.kappa <= KAPPA_WARN:
            if not math.isfinite(self._good_since):
                self._good_since = self._t1
        else:
            self._good_since = math.nan
        st = self.status()
        if st.enough:
            self._finish(
                f"κ {st.kappa:.3g} ≤ {KAPPA_WARN:.0e} with {st.n_epochs} moving epochs in {st.recorded_s:.0f} s"
            )
        elif st.recorded_s >= self.config.max_s:
            self._finish(f"time limit {self.config.max_s:.0f} s reached at κ {st.kappa:.3g}")
        return self.status()

    def finish(self) -> None:
        """The operator ends the recording now (the calibration judges what it got)."""
        if self.phase == "record":
            self._finish(f"finished by the operator at κ {self.kappa:.3g}")

    def restart(self) -> None:
        self.phase = "record"
        self._reset()
        self._events.append(("restarted", "recording restarted"))

    def _estimate(self):
        try:
            X = np.linalg.solve(self._HtH, self._HtY).T  # row j: X_j
        except np.linalg.LinAlgError:
            return None
        a = ldv_model.angles_from_X(X)
        return tuple(
            (float(a["dK"][j]), float(a["alpha_deg"][j]), float(a["beta_deg"][j]), float(a["gamma_deg"][j]))
            for j in range(len(X))
        )

    def status(self) -> LdvStatus:
        c = self.config
        kappa = self.kappa
        verdict = (
            "none"
            if not math.isfinite(kappa)
            else "refused"
            if kappa > KAPPA_REFUSE
            else "poor"
            if kappa > KAPPA_WARN
            else "good"
        )
        rec = (self._t1 - self._t0) if math.isfinite(self._t0) else 0.0
        good_s = (self._t1 - self._good_since) if math.isfinite(self._good_since) else 0.0
        enough = verdict == "good" and good_s >= c.good_for_s and self._epochs >= c.min_epochs and rec >= c.min_s
        v, b = self._last if self._last is not None else (np.full(3, np.nan), np.full(3, np.nan))
        speed = float(np.linalg.norm(v))
        msg = self._message
        if self.phase == "record":
            if not (speed >= c.moving_mps):
                msg = "Parked: drive (the beams see nothing worth fitting at rest)"
            elif verdict in ("none", "refused"):
                msg = (
                    "Straight driving: the velocity hardly changes direction, the beam angles cannot be "
                    "separated; drive turns, slopes, braking"
                )
            elif verdict == "poor":
                msg = "Poorly conditioned still: keep turning and changing slope"
            elif not enough:
                left = max(c.min_s - rec, c.good_for_s - good_s, 0.0)
                more = max(c.min_epochs - self._epochs, 0)
                togo = (f"{more} epochs, " if more else "") + f"{left:.0f} s to go"  # not "0 epochs"
                msg = f"Well conditioned: keep driving and turning ({togo})"
        return LdvStatus(
            phase=self.phase,
            kappa=kappa,
            verdict=verdict,
            enough=enough,
            n_epochs=self._epochs,
            n_samples=self._n,
            recorded_s=rec,
            speed_mps=speed,
            v_ref=tuple(float(x) for x in v),
            beams=tuple(float(x) for x in b),
            estimate=self._estimate() if verdict in ("poor", "good") else None,
            t_s=self._t1,
            message=msg,
        )

    def capture(self, extra_meta: dict | None = None):
        """The recording as a P5 time-series capture (body-frame reference)."""
        from station.capture import Capture

        cols = recorded_columns(self._chunks, (("vl", BEAMS), ("v", REF), ("w", RATES)), optional=("w",))
        meta = {
            "station-capture": "1",
            "procedure": self.procedure,
            "device": self.device_id or "unknown",
            "date": self.started[:10],
            "sample_rate_hz": repr(self.sample_rate_hz),
            "frame": "body x forward, y right, z down",
        }
        meta.update(site_meta(self.site))
        meta.update({k: str(v) for k, v in (extra_meta or {}).items()})
        return Capture(meta=meta, columns=cols)


class Driver:
    """The demo's driver: sets off, drives straight for ``straight_s`` (the conditioning
    stays bad, as the source warns), then turns and climbs until the guide is done."""

    def __init__(self, place, *, straight_s: float = 30.0):
        self.place = place
        self.straight_s = straight_s
        self._t0 = None
        self._turning = False

    def step(self, guide: LdvGuide, t_s: float) -> str | None:
        if guide.phase != "record" or not math.isfinite(t_s):
            return None
        if self._t0 is None:
            self._t0 = t_s
            self.place("drive")
            return "drive"
        if not self._turning and t_s - self._t0 >= self.straight_s:
            self._turning = True
            self.place("turns")
            return "turns"
        return None


def live_device(*, seed: int, rate_hz: float, reference: bool = False):
    """The simulated vehicle with INS/DGPS and the LDV (``solvers.simulate.LiveVehicle``) at
    its own 10 Hz, whatever ``rate_hz`` asks."""
    from solvers.simulate import LiveVehicle

    return LiveVehicle(seed=seed, rate_hz=10.0)


def headless_demo(src, now: list, *, average_s: float, out, max_device_s: float = 900.0) -> LdvGuide:
    """``station demo --headless --procedure ldv``: the demo driver sets off straight, then
    turns and climbs, on the started simulated vehicle ``src`` (clock ``now[0]``, advanced
    here); the conditioning of the velocity set goes to ``out`` as it builds."""
    guide = LdvGuide(sample_rate_hz=src.rate_hz, device_id=src.device_id, site=src.site)
    driver = Driver(src.place)
    verdict = None
    while guide.phase == "record" and now[0] < max_device_s:
        now[0] += 0.5
        b = src.drain()
        if b is None:
            continue
        e = b.extra
        st = guide.update(
            b.t_s,
            np.column_stack([e["vl1"], e["vl2"], e["vl3"]]),
            np.column_stack([e["vx"], e["vy"], e["vz"]]),
            b.gyro,
            b.temp_c,
        )
        said = driver.step(guide, st.t_s)
        if said:
            print(f"{st.t_s:7.1f} s  driver: {said}", file=out)
        if st.verdict != verdict:
            verdict = st.verdict
            print(f"{st.t_s:7.1f} s  conditioning {verdict} (κ {st.kappa:.3g}, {st.n_epochs} moving epochs)", file=out)
    return guide
