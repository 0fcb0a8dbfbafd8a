"""The driver core: lifecycle, sessions on a device, the cycle loop, safety rules."""
