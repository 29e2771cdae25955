"""The station database: devices, captures, calibrations, drift (SQLite via sqlite-utils)."""
