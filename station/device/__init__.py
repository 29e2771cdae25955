"""Device I/O: the station line protocol, MAVLink input, the serial reader, the simulated
device on a pseudo-terminal, headless recording, and the live detectors the TUI shares.

See docs/protocol.md for the wire format.
"""
