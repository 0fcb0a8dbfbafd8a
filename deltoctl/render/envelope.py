"""Every verb's JSON document in one shape: ``verb``, ``profile``, its data (``blocks`` and
``result``), ``warnings`` and ``exit_code``; and an error as stderr says it."""

from __future__ import annotations

import json
from typing import Any

# verbs that report each block of the robot: ``blocks`` beside the envelope's keys, their
# other data in ``result``
BLOCK_VERBS = ("connect", "identify", "detect", "home", "jog", "calibrate ft", "calibrate imu")


def envelope(verb: str, data: Any, warnings: list[str], exit_code: int,
             profile: str | None) -> dict[str, Any]:
    """These keys and no others: ``verb``, ``profile``, the data — ``blocks`` for the
    robot's blocks, ``result`` for the rest (a verb that reports each block has both when it
    says more than its blocks: home's ``settled``) —, ``warnings`` and ``exit_code``."""
    named = data.get("profile") if isinstance(data, dict) else None
    profile = named if isinstance(named, str) else profile
    if verb in BLOCK_VERBS and isinstance(data, dict) and isinstance(data.get("blocks"), list):
        rest = {k: v for k, v in data.items() if k not in ("profile", "blocks")}
        body = {"blocks": data["blocks"], **({"result": rest} if rest else {})}
    else:
        body = {"result": data}
    return {"verb": verb, "profile": profile, **body, "warnings": list(warnings),
            "exit_code": exit_code}


def error_text(message: str, hint: str | None, exit_code: int, as_json: bool,
               **more: str) -> str:
    """An error: one line (and its hint) for people; with ``as_json`` one object,
    ``{"error": {"message", "hint", "exit_code"}}`` (and ``more``: the robot a remote verb
    ran on)."""
    if as_json:
        error = {"message": message, "hint": hint, "exit_code": exit_code, **more}
        return json.dumps({"error": error})
    return f"deltoctl: error: {message}" + (f"\n  hint: {hint}" if hint else "")


def dumps(data: Any, compact: bool = False) -> str:
    """A document as JSON text: indented, or on one line (``compact``: a stream's)."""
    if compact:
        return json.dumps(data, separators=(",", ":"), default=_jsonable)
    return json.dumps(data, indent=2, default=_jsonable)


def _jsonable(value: Any) -> Any:
    if hasattr(value, "__fspath__"):
        return str(value)
    if isinstance(value, (set, tuple)):
        return list(value)
    raise TypeError(f"cannot write {type(value).__name__} as JSON")
