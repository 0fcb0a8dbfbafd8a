"""What every verb's help shows besides its own options: the global options in their panel,
the verb's effect on the robot, its example (from deltoctl.verbs) and the exit codes. The CLI
applies it to its click commands only when help is shown or a command line is completed: a
verb that just runs pays nothing for it."""

from __future__ import annotations

from typing import Any

from deltoctl import verbs

EXIT_LINE = ("Exit codes: 0 ok · 1 failed · 2 usage or invalid input · 3 warnings · "
             "4 unreachable · 5 refused for safety · 130 interrupted")
# one example per verb, shown in its help (command path without "deltoctl")
EXAMPLES = verbs.examples()
GLOBAL_PANEL = "Global options (before or after the verb)"
_NOT_GLOBAL = ("version", "help", "install_completion", "show_completion")


def _documented(param: Any) -> Any:
    """A copy of a root option that only shows in a verb's help (and completes there): the
    value itself is hoisted to the root before any parsing, so the copy never receives one."""
    import copy

    doc = copy.copy(param)
    doc.name = f"global_{param.name}"  # apart from a verb's own (torque's TARGET argument)
    doc.expose_value = False
    doc.callback = None
    doc.is_eager = False
    doc.envvar = None  # read once, by the root
    doc.show_envvar = False
    doc.rich_help_panel = GLOBAL_PANEL
    return doc


def teach_verbs(root: Any, loaded: dict[str, Any]) -> None:
    """Teach the verbs just loaded by the root group: their panel (their stage) and line in
    its help."""
    from deltoctl.render.manpages import summary

    globals_ = [_documented(p) for p in root.params if p.name not in _NOT_GLOBAL]
    for name, command in loaded.items():
        teach(command, name, globals_)
        command.rich_help_panel = verbs.TITLES.get(verbs.TABLE[name].stage)
        command.short_help = summary(command.help)


def teach(command: Any, path: str, globals_: list[Any]) -> None:
    """Give a verb (and its sub-verbs) the global options panel, its effect on the robot
    and its example (from the verb table), and the exit codes."""
    known = {o for p in command.params for o in getattr(p, "opts", ())}
    command.params.extend(p for p in globals_ if not known & set(p.opts))
    command.parse_args = _lenient(command, command.parse_args)
    example = EXAMPLES.get(path)
    command.epilog = (f"Effect: {verbs.describe(path)}.\n\n"
                      + (f"Example: {example}\n\n" if example else "") + EXIT_LINE)
    for name, sub in getattr(command, "commands", {}).items():
        teach(sub, f"{path} {name}", globals_)


def _lenient(command: Any, parse: Any) -> Any:
    """``parse_args`` that, while completing, drops a last option still waiting for its value
    (the one being completed): click would stop there, before the arguments, and
    ``sim serve mh5 --missing <TAB>`` would not know the profile."""
    def parse_args(ctx: Any, args: list[str]) -> list[str]:
        if ctx.resilient_parsing and args and _wants_value(command, args[-1]):
            args = args[:-1]
        return parse(ctx, args)

    return parse_args


def _wants_value(command: Any, arg: str) -> bool:
    return any(arg in p.opts and not (p.is_flag or p.count) for p in command.params
               if getattr(p, "param_type_name", "") == "option")
