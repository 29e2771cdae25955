"""Pure numerics for the calibration station: no I/O, no UI, no database."""
