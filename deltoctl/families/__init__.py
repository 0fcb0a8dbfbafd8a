"""The built-in device families, one folder each: the sans-I/O codec, the model tables, the
driver and the emulator, and in ``__init__`` the descriptor the registry reads
(``deltoctl.registry``; registered in ``pyproject.toml`` under ``deltoctl.families``)."""
