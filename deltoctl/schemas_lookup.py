"""The JSON Schemas of the verbs' --json documents, shipped in deltoctl/schemas/ (``deltoctl
help schema VERB`` prints one)."""

from __future__ import annotations

from pathlib import Path

from deltoctl.errors import InvalidInput

SCHEMAS = Path(__file__).resolve().parent / "schemas"  # shipped in the package


def schema_file(verb: str) -> Path:
    """The JSON Schema of a verb's --json document (``gpio get`` → gpio-get.json; a
    stream's frames: ``stream-frame``; an error: ``error``)."""
    return SCHEMAS / f"{'-'.join(verb.split())}.json"


def schema_text(verb: str) -> str:
    """The text of a verb's JSON Schema; InvalidInput naming the verbs that have one."""
    from deltoctl.suggest import did_you_mean

    path = schema_file(verb)
    if not verb or not path.is_file():
        names = sorted(p.stem.replace("-", " ") for p in SCHEMAS.glob("*.json"))
        raise InvalidInput(f"no schema for {verb!r}" + did_you_mean(verb, names)
                           if verb else "help schema VERB: which verb's schema?",
                           f"one of: {', '.join(names)}")
    return path.read_text(encoding="utf-8")
