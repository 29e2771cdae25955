"""The calibration station application: CLI, capture files, device I/O, procedures, TUI."""

__version__ = "0.1.0"
