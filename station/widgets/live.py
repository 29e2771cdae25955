"""Live indicators of a guided step: placement drawing, stability, orientation,
averaging countdown, readouts. Each is a Static that redraws from a GuideStatus."""

from __future__ import annotations

import math

from rich.text import Text
from textual.widgets import Static

from solvers.units import si_factor
from station.formatting import num
from station.procedures.tabletop_guide import position_drawing


def bar(fraction: float, width: int) -> str:
    """A text bar, ``fraction`` in 0..1 (NaN: empty)."""
    if not math.isfinite(fraction):
        fraction = 0.0
    full = int(round(max(0.0, min(1.0, fraction)) * width))
    return "█" * full + "░" * (width - full)


def mmss(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "--:--"
    s = int(math.ceil(seconds))
    return f"{s // 60:d}:{s % 60:02d}"


class PlacementView(Static):
    """How to place the unit: the instruction and a drawing of the up face."""

    def show(self, name: str, instruction: str, direction) -> None:
        t = Text()
        t.append(f"{name}", style="bold")
        t.append(f"  {instruction}\n")
        t.append("\n".join(position_drawing(direction)))
        self.update(t)


class StabilityBar(Static):
    """Still or moving: a bar of the stillness detector's level (< 1 is still), seconds held."""

    WIDTH = 14
    LABEL = "Stillness   "

    def show(self, st) -> None:
        t = Text(self.LABEL)
        if st.calibrating:
            t.append(self.calibrating_text(), style="yellow")
        else:
            # level: decision statistic / threshold; draw 1/level so a steady unit fills the bar
            lvl = st.level
            frac = 1.0 if lvl <= 0 else min(1.0, 1.0 / lvl) if math.isfinite(lvl) else 0.0
            t.append(bar(frac, self.WIDTH), style="green" if st.is_still else "red")
            word, style = self.state_text(st)
            t.append(f" {word}", style=style)
        self.update(t)

    def calibrating_text(self) -> str:
        return "measuring noise… hold still"

    def state_text(self, st) -> tuple[str, str]:
        if st.is_still:
            return f"still {st.still_for_s:4.1f} s", "green"
        return "moving", "bold red"


class SteadyBar(StabilityBar):
    """The same detector on a centrifuge (P2): a steady output at a steady table rate, not a
    unit standing still; it says whether the measured rate is the asked one."""

    LABEL = "Steadiness  "

    def calibrating_text(self) -> str:
        return "measuring noise… keep the table stopped"

    def state_text(self, st) -> tuple[str, str]:
        if not st.is_still:
            return "changing", "bold red"
        rate = getattr(st, "table_rate_rad_s", math.nan)
        if not (isinstance(rate, float) and math.isfinite(rate)):
            return f"steady {st.still_for_s:4.1f} s", "green"
        if abs(rate) < 0.05:  # rad/s: the table stands
            return f"steady, stopped {st.still_for_s:4.1f} s", "yellow"
        if getattr(st, "at_speed", True):
            return f"steady at speed {st.still_for_s:4.1f} s", "green"
        return "steady, not at speed", "yellow"


class OrientationIndicator(Static):
    """Angle between the measured and the asked direction; wrong face up when > 90°."""

    def show(self, st, tol_deg: float) -> None:
        t = Text("Orientation ")
        a = st.angle_deg
        if not math.isfinite(a):
            t.append("not known yet (learned from the first positions)", style="yellow")
        elif st.wrong_face:
            t.append(f"{a:5.1f}° WRONG FACE UP", style="bold white on red")
        elif a <= tol_deg:
            t.append(f"{a:5.1f}° in position", style="green")
        else:
            t.append(f"{a:5.1f}° from the asked position", style="yellow")
        self.update(t)


class CountdownBar(Static):
    """Averaging (or recording) progress and time left; ``label`` names what runs."""

    WIDTH = 14

    def __init__(self, *args, label: str = "Average", **kw) -> None:
        super().__init__(*args, **kw)
        self.label = label

    def show(self, st, average_s: float) -> None:
        t = Text(f"{self.label:<12}")
        if st.phase == "average":
            t.append(bar(st.progress, self.WIDTH), style="cyan")
            t.append(f" {mmss(st.countdown_s)} left")
        elif st.phase == "settle":
            t.append(bar(0.0, self.WIDTH))
            t.append(f" starts in {num(st.settle_left_s, '.1f')} s")
        elif st.phase == "done":
            t.append(bar(1.0, self.WIDTH), style="green")
            t.append(" all done")
        elif st.phase == "change":  # P2: the last row is in; remount or change speed first
            t.append(bar(0.0, self.WIDTH))
            t.append(" after the change")
        elif getattr(st, "at_speed", True) is False:  # P2: still or not, the rate is what is wrong
            t.append(bar(0.0, self.WIDTH))
            t.append(" not at the asked speed", style="bold red")
        else:
            t.append(bar(0.0, self.WIDTH))
            t.append(f" {mmss(average_s)} when still")
        self.update(t)


def rate_deg_s(gyro, unit: str | None) -> tuple[tuple[float, float, float], str, str]:
    """A gyro reading in the device's ``unit`` as an operator reads a rate: (values, unit,
    format), in °/s for a physical unit (rad/s, mrad/s, ...); a raw unit (counts, V, none)
    as it comes, with its name."""
    factor = si_factor("gyro", unit)  # unit → rad/s
    if factor is None:
        return tuple(gyro), unit or "raw", "9.4f"
    return tuple(math.degrees(x * factor) for x in gyro), "°/s", "9.3f"


class Readouts(Static):
    """Raw and calibrated-so-far values, |a|, rates (°/s), temperature, sample rate, parse errors."""

    def show(self, st, stats, units: dict) -> None:
        au = units.get("accel_unit") or "raw"
        r, f = st.raw, st.f_mps2
        g, gu, gf = rate_deg_s(st.gyro, units.get("gyro_unit"))
        lines = [
            f"raw  {num(r[0], '9.4f')} {num(r[1], '9.4f')} {num(r[2], '9.4f')} {au}",
            f"f    {num(f[0], '9.3f')} {num(f[1], '9.3f')} {num(f[2], '9.3f')} m/s^2  |a| {num(st.norm_mps2, '.3f')}",
            f"rate {num(g[0], gf)} {num(g[1], gf)} {num(g[2], gf)} {gu}",
            f"temp {num(st.temp_c, '.1f')} °C   {num(stats.rate_hz, '.0f')} Hz   "
            f"errors {stats.parse_errors}   dropped {stats.dropped}" + ("" if stats.connected else "   DISCONNECTED"),
        ]
        self.update("\n".join(lines))
