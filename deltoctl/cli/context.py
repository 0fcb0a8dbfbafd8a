"""The global options every verb shares (parsed into deltoctl.cmdline.Options, which loads the
profile they select), and the keys of the root context's meta the verbs read."""

from __future__ import annotations

import typer

# the parsed global options, and NAME=VALUE pairs (--arg, --package-path), below the CLI
from deltoctl.cmdline import Options as Options
from deltoctl.cmdline import parse_pairs as parse_pairs

TEACH = "deltoctl.teach"  # ctx.meta key: this run shows help or completes, so verbs are taught
ARGV = "deltoctl.argv"  # ctx.meta key: the command line, global options first
DOCUMENT = "deltoctl.document"  # ctx.meta key: the verb's JSON document, written as it exits


def options(ctx: typer.Context) -> Options:
    root = ctx.find_root()
    if not isinstance(root.obj, Options):
        root.obj = Options()
    return root.obj
