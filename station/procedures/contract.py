"""The shape every procedure module has (``station/procedures/<stem>.py``).

``prepare`` reads what both the calibration and the diagnosis need from a capture (units,
signs, positions or rows, local gravity) once; ``calibrate`` returns the calibrate.md dict;
``format_text`` prints it for a person; ``diagnosis_input`` turns the capture and its
baseline calibration into the problem the diagnosis engine (``solvers.diagnose``) fits.
A module satisfies :class:`ProcedureModule` structurally (``isinstance`` works on it: the
protocol is runtime-checkable); ``tests/test_procedure_contract.py`` checks every module of
the registry.

Optional constants the station's checks read where a module has them: ``MEASURED`` (columns
read as measurements) and ``CORE_PARAMS`` (parameters it exists to deliver) for
``station.guard``; ``DEAD_IF_CONSTANT``/``DEAD_IF_CONSTANT_SAYS`` (columns that must change);
``PARAM_SHAPES`` (every parameter block the result can hold and its shape: the names a limit or
tolerance may give, ``station devices add``), ``PARAM_UNITS`` (a unit per parameter block, or per ``.<leaf>``), ``RESIDUAL_LIMIT`` (in the
result unit), ``ZERO_IS_A_RESULT`` and ``DISPLAY_UNITS`` (the unit a screen shows a block
or ``residual_rms`` in, when not the stored one) for ``station.procedures.review``. Optional functions:
``report_figures(result, meta, columns)`` (``station.report``), ``results_lines(result)`` and
``position_residuals(capture, result)`` (the TUI's Results), ``firmware_accel(params, k,
unit)`` (``station.firmware_export``).
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol, runtime_checkable


class DiagnosisInput(NamedTuple):
    """What ``station diagnose`` needs from a procedure module."""

    problem: Any  # solvers.diagnose.engine.Problem
    drivers: dict  # what the plots draw the residuals against (per row)
    explain: str  # what an outlier row of this procedure usually means
    group_kind: str = "time block"  # what one cross-validation group is ("position", "mounting")
    quality: tuple = ()  # procedure-specific quality findings, rows as capture row indices
    # the same capture with the groups the screen left out as outliers kept (a callable returning a
    # DiagnosisInput), tried when it has some: an effect may be what put them far from the rest
    kept: Any = None
    flagged_groups: tuple = ()  # in a kept input: the problem's groups the screen flagged and kept
    # the unit of each parameter the text names, where it is not the residuals' (the compass's raw
    # hard iron): name -> (unit, factor to the residuals' unit or None where none exists, the unit then)
    param_units: dict = {}  # noqa: RUF012 - read only


@runtime_checkable
class ProcedureModule(Protocol):
    """A procedure module (a Python module satisfies a Protocol by its attributes)."""

    MODEL: str
    DIAGNOSIS_BASELINE: bool  # diagnosis_input needs the calibrate result (False: it fits its own)

    def prepare(self, capture) -> Any:
        """What calibrate and diagnose both need, read from ``capture`` once; holds its own
        ``warnings`` (a list of str)."""

    def calibrate(self, capture, method: str | None = None, *, prepared=None) -> dict:
        """The calibrate.md result; ``prepared`` (from :meth:`prepare`) saves reading the
        capture again."""

    def format_text(self, result: dict) -> str:
        """The result as plain text for a person."""

    def diagnosis_input(self, capture, base: dict | None, prepared=None) -> DiagnosisInput:
        """The diagnosis problem of ``capture`` around the baseline calibration ``base``
        (None where the diagnosis fits its own baseline: P4)."""
