"""The help topics shipped in deltoctl/topics/ (``deltoctl help TOPIC`` prints one; the manual
includes the same files), and the examples shipped beside the profiles (``deltoctl help
examples`` lists them, ``--copy DIR`` copies them out)."""

from __future__ import annotations

from pathlib import Path

from deltoctl.errors import DeviceError, InvalidInput

TOPICS = Path(__file__).resolve().parent / "topics"  # shipped in the package


def topic_names() -> list[str]:
    """The topics with a text of their own (``trust-model``, ``targets`` …)."""
    return sorted(p.stem for p in TOPICS.glob("*.md"))


def topic_text(name: str) -> str:
    """A topic's text (Markdown); InvalidInput naming the topics when there is none."""
    from deltoctl.suggest import did_you_mean

    path = TOPICS / f"{name}.md"
    if name not in topic_names():
        raise InvalidInput(f"no help topic {name!r}" + did_you_mean(name, topic_names()),
                           f"one of: {', '.join(topic_names())}")
    return path.read_text(encoding="utf-8")


def examples_dir() -> Path:
    from deltoctl.data_paths import data_dir

    return data_dir("examples")


def examples() -> list[tuple[str, str]]:
    """Each shipped example's file name and what it is (the start of its first comment)."""
    return [(path.name, _summary(path)) for path in sorted(examples_dir().iterdir())
            if path.is_file()]


def _summary(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.lstrip("/# ").strip()
        if line.startswith(("#", "//")) and not line.startswith("#!") and text:
            return text.split(": ", 1)[0].rstrip(",.")
    return ""


def copy_examples(dest: Path, force: bool = False) -> list[Path]:
    """Copy every example into ``dest`` (made when missing); an example already there is
    refused, before anything is written, unless ``force``."""
    import shutil

    if dest.exists() and not dest.is_dir():
        raise InvalidInput(f"{dest}: not a directory")
    names = [name for name, _ in examples()]
    there = [name for name in names if (dest / name).exists()]
    if there and not force:
        raise InvalidInput(f"{dest}: {', '.join(there)} already there",
                           "--force overwrites them")
    try:
        dest.mkdir(parents=True, exist_ok=True)
        return [Path(shutil.copy2(examples_dir() / name, dest / name)) for name in names]
    except OSError as exc:
        raise DeviceError(f"{dest}: {exc.strerror or exc}") from None
