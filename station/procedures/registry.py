"""The station's procedures, once: every table, list and switch keyed by a procedure reads it.

Kept free of numpy (and of everything but the standard library) so that the CLI's
argument parser and the TUI's Connect screen can list the procedures without loading the
numerics. A procedure's code lives under one file stem (``docs/ARCHITECTURE.md``,
"Procedure map"):

- ``station/procedures/<stem>.py``: the module of :class:`station.procedures.contract.ProcedureModule`
  (``prepare``, ``calibrate``, ``format_text``, ``diagnosis_input``);
- ``station/procedures/<stem>_guide.py`` and ``station/screens/<stem>.py`` when it is guided
  in the TUI; ``docs/<doc>.md``; ``tests/test_<stem>.py``.

Adding a procedure: one :class:`Procedure` entry in :data:`PROCEDURES` and its module.
``solvers/simulate.py`` keeps its own list (solvers never import the station); a test holds
the two equal.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class Procedure:
    """One procedure: what the station calls it and where its parts live."""

    name: str  # the capture's ``procedure:`` value (capture-format.md)
    code: str  # P1…P5: the code of the source documents and the TUI
    stem: str  # the file stem of its module, guide, screen and tests
    title: str  # what it calibrates, how (the Connect screen's list: "<code> <title>")
    short: str  # a word or two in result titles ("P3 compass result"); empty: the code alone
    sensor_kind: str  # the database's sensor kind (devices.sensor_kinds): accel, gyro, mag, ldv
    module: str  # the dotted module that satisfies contract.ProcedureModule
    screen: str | None  # "module:Class" of its guided TUI screen, None when not guided
    result_unit: str  # the unit of its calibrate result's ``residual_rms``
    doc: str  # its page under docs/

    def load(self):
        """The procedure's module (imported on first use)."""
        return importlib.import_module(self.module)


@dataclass(frozen=True)
class GuidedRun:
    """A guided TUI run beside the procedures' own screens: another mode of one (P4 with a
    reference IMU, whose capture is a ``gyro-drift`` one) or not a calibration at all (the
    gyro noise run)."""

    name: str
    title: str
    screen: str


PROCEDURES: tuple[Procedure, ...] = (
    Procedure(
        name="accel-tabletop",
        code="P1",
        stem="tabletop",
        title="accelerometer, level table",
        short="",
        sensor_kind="accel",
        module="station.procedures.tabletop",
        screen="station.screens.tabletop:ProcedureScreen",
        result_unit="m/s²",
        doc="accel",
    ),
    Procedure(
        name="accel-centrifuge",
        code="P2",
        stem="centrifuge",
        title="accelerometer, centrifuge",
        short="centrifuge",
        sensor_kind="accel",
        module="station.procedures.centrifuge",
        screen="station.screens.centrifuge:CentrifugeScreen",
        result_unit="g",
        doc="accel",
    ),
    Procedure(
        name="compass",
        code="P3",
        stem="compass",
        title="compass sweep",
        short="compass",
        sensor_kind="mag",
        module="station.procedures.compass",
        screen="station.screens.compass:CompassScreen",
        result_unit="nT",
        doc="compass",
    ),
    Procedure(
        name="gyro-drift",
        code="P4",
        stem="gyrodrift",
        title="gyro drift, static base",
        short="gyro drift",
        sensor_kind="gyro",
        module="station.procedures.gyrodrift",
        screen="station.screens.gyrodrift:HoldScreen",
        result_unit="rad/s",
        doc="gyrodrift",
    ),
    Procedure(
        name="ldv",
        code="P5",
        stem="ldv",
        title="laser velocimeter",
        short="LDV",
        sensor_kind="ldv",
        module="station.procedures.ldv",
        screen="station.screens.ldv:LdvScreen",
        result_unit="m/s",
        doc="ldv",
    ),
)

GUIDED_RUNS: tuple[GuidedRun, ...] = (
    GuidedRun("gyro-reference", "P4 gyro drift, reference IMU", "station.screens.gyrodrift:ReferenceScreen"),
    GuidedRun("gyro-noise", "Gyro noise (Allan) run", "station.screens.noise:NoiseHoldScreen"),
)

DEFAULT = PROCEDURES[0].name

# Everything below reads PROCEDURES when called, so that an entry added to it (a test's
# toy procedure) is seen everywhere.


def names() -> tuple[str, ...]:
    """The procedures' names (capture ``procedure:`` values), in registry order."""
    return tuple(p.name for p in PROCEDURES)


def sensor_kinds() -> tuple[str, ...]:
    """The sensor kinds the procedures calibrate (the database's devices.sensor_kinds)."""
    return tuple(dict.fromkeys(p.sensor_kind for p in PROCEDURES))


def get(name: str | None) -> Procedure | None:
    """The procedure called ``name``, None when there is none."""
    return next((p for p in PROCEDURES if p.name == name), None)


def result_title(name: str | None) -> str:
    """The Results screen's title: 'P1 result', 'P3 compass result', '<name> result'."""
    p = get(name)
    if p is None:
        return f"{name} result"
    return f"{p.code} {p.short} result" if p.short else f"{p.code} result"


def guided() -> dict[str, str]:
    """Every guided TUI run, name → the Connect screen's label, procedures first."""
    out = {p.name: f"{p.code} {p.title}" for p in PROCEDURES if p.screen}
    out.update({r.name: r.title for r in GUIDED_RUNS})
    return out


def screen_for(name: str):
    """A new guided screen for procedure or run ``name`` (the default's when ``name`` has none)."""
    spec = next((r.screen for r in GUIDED_RUNS if r.name == name), None)
    if spec is None:
        p = get(name)
        spec = p.screen if p is not None and p.screen else get(DEFAULT).screen
    module, cls = spec.split(":")
    return getattr(importlib.import_module(module), cls)()
