"""The guard every profile file passes before it is read: a regular file of at most
MAX_PROFILE_BYTES (the catalog, the loaders, xacro's includes and recordings share it)."""

from __future__ import annotations

import stat
from pathlib import Path

from deltoctl.errors import ProfileError

MAX_PROFILE_BYTES = 16 << 20  # checked before a profile file is read


def check_profile_file(path: Path) -> None:
    """Refuse what is not a regular file of at most MAX_PROFILE_BYTES, before reading it."""
    try:
        info = path.stat()
    except OSError as exc:
        raise ProfileError(f"cannot read the file: {exc.strerror}", str(path)) from None
    if not stat.S_ISREG(info.st_mode):
        raise ProfileError("not a regular file", str(path))
    if info.st_size > MAX_PROFILE_BYTES:
        raise ProfileError(f"{info.st_size} bytes: larger than {MAX_PROFILE_BYTES >> 20} MiB, "
                           "the limit for a profile", str(path))
