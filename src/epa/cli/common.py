"""What several commands share: the report stage's folder in a case folder, and how a command keeps
an old spelling of an option working."""

import argparse
import sys

from epa.artifacts.stage import folder

REPORT_STAGE = "report"
REPORT = folder(REPORT_STAGE)  # the report stage's folder in a case folder


def deprecated_alias(container, old: str, new: str, dest: str) -> None:
    """``old``: an earlier spelling of ``new`` (one spelling per option across the commands), still
    accepted with a warning and hidden from ``--help``."""

    class Alias(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            print(f"epa: WARNING: {old} is deprecated: use {new}", file=sys.stderr)
            setattr(namespace, self.dest, values)

    # no default of its own: the option it spells gives it
    container.add_argument(
        old, dest=dest, action=Alias, default=argparse.SUPPRESS, help=argparse.SUPPRESS
    )
