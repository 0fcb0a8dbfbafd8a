"""A MkDocs hook: fills the manual's markers with what deltoctl itself knows, at build time,
so the manual cannot drift from the tool.

    <!-- deltoctl: topic NAME -->   the help topic deltoctl/topics/NAME.md (`deltoctl help NAME`)
    <!-- deltoctl: cli -->          every verb and sub-command: the verb table and the CLI's options
    <!-- deltoctl: schemas -->      the JSON Schemas of the --json documents (deltoctl/schemas/)
    <!-- deltoctl: exit-codes -->   the exit codes (deltoctl.errors.EXIT_CODES)
    <!-- deltoctl: examples -->     the shipped examples (`deltoctl help examples`)
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # the checkout's deltoctl, installed or not
    sys.path.insert(0, str(ROOT))

MARKER = re.compile(r"<!-- deltoctl: ([a-z-]+)(?: ([a-z0-9-]+))? -->")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    return MARKER.sub(lambda m: generate(m.group(1), m.group(2)), markdown)


def generate(kind: str, arg: str | None = None) -> str:
    if kind == "topic" and arg:
        from deltoctl.topics_lookup import topic_text

        return topic_text(arg)
    makers = {"cli": cli_reference, "schemas": schemas_reference,
              "exit-codes": exit_codes, "examples": examples}
    if kind not in makers:
        raise ValueError(f"unknown marker <!-- deltoctl: {kind} -->")
    return makers[kind]()


# -- the command line ----------------------------------------------------------------------

def cli_reference() -> str:
    from typer.main import get_command

    from deltoctl.cli.main import app

    root = get_command(app)
    ctx = root.context_class(root, info_name="deltoctl")
    lines = ["## Global options", "",
             "Given before or after the verb (`deltoctl --json profile show` = "
             "`deltoctl profile show --json`).", "", *_options(root, ctx)]
    for name in root.list_commands(ctx):
        lines += _command(f"deltoctl {name}", name, root.get_command(ctx, name), ctx, "##")
    return "\n".join(lines) + "\n"


def _command(title: str, path: str, command: Any, parent: Any, level: str) -> list[str]:
    from deltoctl import verbs

    ctx = command.context_class(command, info_name=path.split()[-1], parent=parent)
    entry = verbs.lookup(path)
    lines = ["", f"{level} {title}", "", _text(command.help or ""), "",
             f"```\n{title} {' '.join(command.collect_usage_pieces(ctx))}\n```", "",
             f"**Effect on the robot:** {verbs.describe(path)}. "
             f"**On a robot's agent (`--robot`):** "
             f"{'runs' if verbs.remote(path) else 'does not run'}.", ""]
    if entry is not None and entry.example:
        lines += ["Example:", "", f"```sh\n{entry.example}\n```", ""]
    lines += _options(command, ctx)
    for sub_name, sub in getattr(command, "commands", {}).items():
        lines += _command(f"{title} {sub_name}", f"{path} {sub_name}", sub, ctx, "###")
    return lines


def _options(command: Any, ctx: Any) -> list[str]:
    rows = []
    for param in command.params:
        if getattr(param, "hidden", False) or param.name == "help":
            continue
        if param.param_type_name == "argument":
            spelled, value = "", param.make_metavar(ctx)
        else:
            spelled = ", ".join(f"`{o}`" for o in [*param.opts, *param.secondary_opts])
            value = "" if param.is_flag or param.count else param.make_metavar(ctx)
        rows.append(f"| {spelled} | {_cell(f'`{value}`' if value else '')} | "
                    f"{_cell(_text(getattr(param, 'help', None) or ''))} |")
    if not rows:
        return []
    return ["| option | value | what |", "|---|---|---|", *rows, ""]


def _text(text: str) -> str:
    """A help text as Markdown paragraphs (typer's markup escapes removed)."""
    text = text.replace("\\[", "[")
    return "\n\n".join(" ".join(p.split()) for p in text.strip().split("\n\n") if p.strip())


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n\n", " ")


# -- JSON Schemas, exit codes, examples ----------------------------------------------------

def schemas_reference() -> str:
    from deltoctl.schemas_lookup import SCHEMAS

    lines = []
    for path in sorted(SCHEMAS.glob("*.json")):
        schema = json.loads(path.read_text(encoding="utf-8"))
        name = path.stem.replace("-", " ")
        required = set(schema.get("required", ()))
        lines += [f"## {name}", "", f"`deltoctl help schema {name}` — "
                  f"{schema.get('title', '')}.", "", schema.get("description", ""), ""]
        props = schema.get("properties", {})
        if props:
            lines += ["| key | type | required |", "|---|---|---|"]
            lines += [f"| `{key}` | {_cell(_type(value))} | {'yes' if key in required else ''} |"
                      for key, value in props.items()]
        lines += ["", '??? note "JSON Schema"', "", "    ```json",
                  *("    " + line for line in json.dumps(schema, indent=2).splitlines()),
                  "    ```", ""]
    return "\n".join(lines) + "\n"


def _type(schema: Any) -> str:
    if not isinstance(schema, dict):
        return ""
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if "anyOf" in schema or "oneOf" in schema:
        return " or ".join(_type(s) for s in schema.get("anyOf", schema.get("oneOf", [])))
    kind = schema.get("type", "any")
    kind = " or ".join(kind) if isinstance(kind, list) else kind
    if kind == "array" and isinstance(schema.get("items"), dict):
        return f"array of {_type(schema['items'])}"
    return kind


def exit_codes() -> str:
    from deltoctl.errors import EXIT_CODES

    return "\n".join(["| code | meaning |", "|---|---|",
                      *(f"| {code} | {meaning} |" for code, meaning in EXIT_CODES)]) + "\n"


def examples() -> str:
    from deltoctl.topics_lookup import examples as shipped

    return "\n".join(["| file | what |", "|---|---|",
                      *(f"| `{name}` | {_cell(what)} |" for name, what in shipped())]) + "\n"
