"""The station's procedures, once: every table, list and switch keyed by a procedure reads it.

Kept free of numpy (and of everything but the standard library) so that the CLI's
argument parser and the TUI's Connect screen can list the procedures without loading the
numerics. A procedure's code lives under one file stem (``docs/ARCHITECTURE.md``,
"Procedure map"):

- ``station/procedures/<stem>.py``: the module of :class:`station.procedures.contract.ProcedureModule`
  (``prepare``, ``calibrate``, ``format_text``, ``diagnosis_input``);
- ``station/procedures/<stem>_guide.py`` and ``station/screens/<stem>.py`` when it is guided
  in the TUI; ``docs/<doc>.md``; ``tests/test_<stem>.py``. The guide module also holds its
  simulated live device (``live_device``) and, optionally, its scripted demo without a screen
  (``headless_demo``, ``DEMO_MIN_AVERAGE_S``).

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
    # what the calibration report says of it: what it calibrates, how; the document it follows
    description: str = ""
    source: str = "—"
    # its result maps onto flight-firmware parameters of its sensor kind (station export
    # --format px4|ardupilot|qgc); the conversion is station/firmware_export.py's
    firmware: bool = False
    # a flight log or foreign CSV can feed it (station import; calibrate/diagnose --procedure):
    # the samples of its sensor kind become the capture's rows
    from_logs: bool = False
    # the units line of its C header (station export --format c-header); {accel_unit} and
    # {mag_unit} are the capture's
    units_note: str = "SI unless the name says otherwise"
    # the simulated device's id prefix ("SIM-ACC" → SIM-ACC-0007 for seed 7): what the Connect
    # screen shows before the device is started (its guide's live_device reports the same)
    sim_device: str = ""
    counts: tuple[str, str] = ("position", "positions")  # what its result's n_positions counts
    # what the Connect screen's "Average (s)" is for it (P4: the record's length)
    average: str = "not used"
    # the shortest "Average (s)" its fit takes [s]: the Connect screen refuses less before
    # anything is recorded (P4: solvers.gyrodrift.MIN_DURATION_S; a test holds them equal)
    min_average_s: float = 0.0
    # the Connect screen's "Average (s)" on the built-in simulated device [s] (0: the real
    # device's DEFAULT_AVERAGE_S): a first run shows the whole procedure in minutes, not hours
    sim_average_s: float = 0.0
    # an interrupted guided run continues from its resume file (Connect's Resume, F6)
    resumes: bool = False
    # its simulator in solvers/simulate.py (station simulate names its --option choices from it)
    simulator: str = ""
    # that simulator takes a site (place and date: station simulate passes it --date); without
    # one (P2's table) the date given is written into the capture (a test holds this to the signature)
    takes_site: bool = False

    def load(self):
        """The procedure's module (imported on first use)."""
        return importlib.import_module(self.module)

    def guide(self):
        """Its UI-free guide module (``station.procedures.<stem>_guide``), None when not guided."""
        return importlib.import_module(f"station.procedures.{self.stem}_guide") if self.screen else None


@dataclass(frozen=True)
class GuidedRun:
    """A guided TUI run beside the procedures' own screens: another mode of one (P4 with a
    reference IMU, whose capture is a ``gyro-drift`` one) or not a calibration at all (the
    gyro noise run)."""

    name: str
    title: str
    screen: str
    procedure: str  # the procedure whose simulated device (and guide) it runs
    reference: bool = False  # that device carries a reference IMU
    demo: bool = False  # `station demo --procedure <name>` offers it
    average: str = "record length"  # what the Connect screen's "Average (s)" is for it
    min_average_s: float = 0.0  # the shortest it takes [s] (Procedure.min_average_s)
    sim_average_s: float = 0.0  # its default on the simulated device [s] (Procedure.sim_average_s)


PROCEDURES: tuple[Procedure, ...] = (
    Procedure(
        name="accel-tabletop",
        simulator="simulate_tabletop",
        takes_site=True,
        code="P1",
        resumes=True,
        stem="tabletop",
        title="accelerometer, level table",
        short="",
        sensor_kind="accel",
        module="station.procedures.tabletop",
        screen="station.screens.tabletop:ProcedureScreen",
        result_unit="m/s^2",
        doc="accel",
        description="accelerometer triad on a level table, 12+ static positions",
        source="CN102636665A",
        firmware=True,
        from_logs=True,
        units_note="V in the capture's accel_unit ({accel_unit}), A in m/s^2; B in m/s^2, M in m/s^2 per {accel_unit}",
        sim_device="SIM-ACC",
        average="per position (source: 180–300 s)",
        sim_average_s=10.0,
    ),
    Procedure(
        name="accel-centrifuge",
        simulator="simulate_centrifuge",
        code="P2",
        stem="centrifuge",
        title="accelerometer, centrifuge",
        short="centrifuge",
        sensor_kind="accel",
        module="station.procedures.centrifuge",
        screen="station.screens.centrifuge:CentrifugeScreen",
        result_unit="g",
        doc="accel",
        description="accelerometer triad on a centrifuge (quadratic coefficient)",
        source="Wang & Li 2021",
        firmware=True,
        units_note="f in g, N in the capture's accel_unit ({accel_unit}); b in {accel_unit}, D in g/g^2",
        sim_device="SIM-CFG",
        counts=("row", "rows"),
        average="per row (speed held steady)",
        sim_average_s=5.0,
    ),
    Procedure(
        name="compass",
        simulator="simulate_compass",
        takes_site=True,
        code="P3",
        stem="compass",
        title="compass sweep",
        short="compass",
        sensor_kind="mag",
        module="station.procedures.compass",
        screen="station.screens.compass:CompassScreen",
        result_unit="nT",
        doc="compass",
        description="electronic compass: hard and soft iron against the IGRF field",
        source="CN102252689A",
        firmware=True,
        from_logs=True,
        units_note="m_raw and hard_iron in the capture's mag_unit ({mag_unit}); soft_iron maps {mag_unit} to nT",
        sim_device="SIM-COM",
        counts=("distinct orientation", "distinct orientations"),
        average="not used: the sweep ends at 80 % coverage",
    ),
    Procedure(
        name="gyro-drift",
        simulator="simulate_gyro_drift",
        takes_site=True,
        code="P4",
        stem="gyrodrift",
        title="gyro drift, static base",
        short="gyro drift",
        sensor_kind="gyro",
        module="station.procedures.gyrodrift",
        screen="station.screens.gyrodrift:HoldScreen",
        result_unit="rad/s",
        doc="gyrodrift",
        description="MEMS gyro drift at power-up",
        source="source 003 (gyro drift at power-up)",
        firmware=True,
        from_logs=True,
        units_note="rates in rad/s; body axes x forward, y up, z right",
        sim_device="SIM-GYR",
        counts=("record", "records"),  # one still record (its Results said "1 position")
        average="record length (P4 asks ≥ 180 s)",
        min_average_s=30.0,
        sim_average_s=60.0,
    ),
    Procedure(
        name="ldv",
        simulator="simulate_ldv",
        takes_site=True,
        code="P5",
        stem="ldv",
        title="laser velocimeter",
        short="LDV",
        sensor_kind="ldv",
        module="station.procedures.ldv",
        screen="station.screens.ldv:LdvScreen",
        result_unit="m/s",
        doc="ldv",
        description="three-beam laser velocimeter mounting angles and scale factor",
        source="CN102706365A",
        units_note="velocities in m/s, angles in degrees",
        sim_device="SIM-LDV",
        counts=("epoch", "epochs"),
        average="not used: the drive ends when κ allows",
    ),
)

GUIDED_RUNS: tuple[GuidedRun, ...] = (
    GuidedRun(
        "gyro-reference",
        "P4 gyro drift, reference IMU",
        "station.screens.gyrodrift:ReferenceScreen",
        procedure="gyro-drift",
        reference=True,
        demo=True,
        average="record length (P4 asks ≥ 180 s)",
        min_average_s=30.0,
        sim_average_s=60.0,
    ),
    # the gyro noise (Allan) run holds the unit still like P4
    GuidedRun(
        "gyro-noise",
        "Gyro noise (Allan) run",
        "station.screens.noise:NoiseHoldScreen",
        procedure="gyro-drift",
        sim_average_s=120.0,
    ),
)

DEFAULT = PROCEDURES[0].name

# Everything below reads PROCEDURES when called, so that an entry added to it (a test's
# toy procedure) is seen everywhere.


def one_of(choices) -> str:
    """'one of a, b, c': a --procedure option's choices in its help, which argparse wraps at
    the terminal's width (its own {a,b,c} in the usage line ran past 80 columns)."""
    return "one of " + ", ".join(choices)


def names() -> tuple[str, ...]:
    """The procedures' names (capture ``procedure:`` values), in registry order."""
    return tuple(p.name for p in PROCEDURES)


def sensor_kinds() -> tuple[str, ...]:
    """The sensor kinds the procedures calibrate (the database's devices.sensor_kinds)."""
    return tuple(dict.fromkeys(p.sensor_kind for p in PROCEDURES))


def get(name: str | None) -> Procedure | None:
    """The procedure called ``name``, None when there is none."""
    return next((p for p in PROCEDURES if p.name == name), None)


def resumes(name: str | None) -> bool:
    """Whether an interrupted guided run of ``name`` continues from a resume file."""
    p = get(name)
    return p is not None and p.resumes


def firmware_kind(name: str | None) -> str | None:
    """The sensor kind whose flight-firmware parameters ``name``'s result sets; None: none."""
    p = get(name)
    return p.sensor_kind if p is not None and p.firmware else None


def importable() -> tuple[str, ...]:
    """The procedures a flight log or foreign CSV can feed (``station import --procedure``)."""
    return tuple(p.name for p in PROCEDURES if p.from_logs)


def short_code(name):
    """P1…P5 for a procedure's name (the name itself when it is none of the registry's)."""
    p = get(name)
    return p.code if p is not None else name


def guided_run(name: str | None) -> GuidedRun | None:
    """The guided run (not itself a procedure) called ``name``, None when there is none."""
    return next((r for r in GUIDED_RUNS if r.name == name), None)


def device_of(name: str) -> tuple[Procedure | None, bool]:
    """The procedure whose simulated device procedure or guided run ``name`` runs, and
    whether that device carries a reference IMU ((None, False) for an unknown name)."""
    run = guided_run(name)
    if run is not None:
        return get(run.procedure), run.reference
    return get(name), False


def demos() -> tuple[str, ...]:
    """What ``station demo --procedure`` offers: the guided procedures, then the guided runs
    marked ``demo``."""
    return tuple(p.name for p in PROCEDURES if p.screen) + tuple(r.name for r in GUIDED_RUNS if r.demo)


def result_title(name: str | None) -> str:
    """The Results screen's title: 'P1 result', 'P3 compass result', '<name> result'."""
    p = get(name)
    if p is None:
        return f"{name} result"
    return f"{p.code} {p.short} result" if p.short else f"{p.code} result"


def count_text(name: str | None, n) -> str:
    """'12 positions', '60 rows', '1 record': what a result's ``n_positions`` counts."""
    p = get(name)
    one, many = p.counts if p is not None else ("position", "positions")
    return f"{n} {one if n == 1 else many}"


def guided() -> dict[str, str]:
    """Every guided TUI run, name → the Connect screen's label, procedures first."""
    out = {p.name: f"{p.code} {p.title}" for p in PROCEDURES if p.screen}
    out.update({r.name: r.title for r in GUIDED_RUNS})
    return out


def average_means(name: str | None) -> str:
    """What the Connect screen's "Average (s)" is for procedure or guided run ``name``."""
    run = guided_run(name)
    if run is not None:
        return run.average
    p = get(name)
    return p.average if p is not None else ""


def min_average_s(name: str | None) -> float:
    """The shortest "Average (s)" procedure or guided run ``name`` takes [s] (0: any positive)."""
    run = guided_run(name)
    if run is not None:
        return run.min_average_s
    p = get(name)
    return p.min_average_s if p is not None else 0.0


# "Average (s)" on a real device when none is given: P1's source asks 3–5 minutes per position
DEFAULT_AVERAGE_S = 180.0


def default_average_s(name: str | None, simulated: bool) -> float:
    """The "Average (s)" the Connect screen offers for procedure or guided run ``name``: the
    source's 180 s on a real device, the entry's ``sim_average_s`` on the simulated one."""
    if not simulated:
        return DEFAULT_AVERAGE_S
    entry = guided_run(name) or get(name)
    sim = getattr(entry, "sim_average_s", 0.0) if entry is not None else 0.0
    return sim if sim > 0 else DEFAULT_AVERAGE_S


def average_text(name: str | None, simulated: bool) -> str:
    """What the Connect screen says beside "Average (s)": what it is for ``name`` and, on the
    simulated device when its default is shorter, that default ("…, sim 10 s")."""
    means = average_means(name)
    sim = default_average_s(name, True)
    if simulated and sim != DEFAULT_AVERAGE_S and not means.startswith("not used"):
        return f"{means}, sim {sim:g} s"
    return means


def screen_for(name: str):
    """A new guided screen for procedure or run ``name`` (the default's when ``name`` has none)."""
    spec = next((r.screen for r in GUIDED_RUNS if r.name == name), None)
    if spec is None:
        p = get(name)
        spec = p.screen if p is not None and p.screen else get(DEFAULT).screen
    module, cls = spec.split(":")
    return getattr(importlib.import_module(module), cls)()
