"""The serial-servo kit: what servo buses share, for the families built on it (Dynamixel
Protocol 2.0 and 1.0, Feetech) — the frame variants (``frames``), the conversation of a host
and its servos (``session``), control-table items with their units and encodings (``items``),
the serial port I/O of a driver (``serial_io``) and an emulated bus's pseudo-terminal with its
wire pacing (``pty_server``). It names no family; ``frames`` and ``session`` do no I/O."""
