"""The ``epa`` command: the top-level parser and ``main``. Each command's parser and handler are in
their own module: ``epa eval`` in cli.evaluate, ``epa traj|fig`` in cli.trajectory, ``epa config|
selftest|stage|simulate`` in cli.tools, ``epa verify|pack`` in cli.packages, ``epa tum-ate|tum-rpe``
in cli.tum; ``epa ape|rpe|res`` (evo's command lines) in epa.evo and ``epa rpg`` in epa.rpg."""

from __future__ import annotations

import argparse
import logging
import sys

from epa import __version__
from epa.cli import evaluate, packages, tools, trajectory, tum
from epa.core.errors import EpaError

# The commands whose parsers need no import beyond the cli package's; the others' (evo, rpg) are
# built by their modules, whose imports (numpy, yaml, the contract) a run of these commands does not
# need.
OWN_COMMANDS = ("eval", "traj", "fig", "config", "selftest", "stage", "simulate")


def _parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line; for one of OWN_COMMANDS only its own parsers (``epa --help`` and the
    other commands build every one)."""
    p = argparse.ArgumentParser(prog="epa", description="Trajectory evaluation for SLAM/VIO.")
    p.add_argument("--version", action="version", version=f"epica {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    # in the order `epa --help` lists them
    evaluate.add_parser(sub)
    trajectory.add_parsers(sub)
    tools.add_config(sub)
    if command not in OWN_COMMANDS:
        _add_evo_rpg(sub)
        packages.add_parsers(sub)
        tum.add_parsers(sub)
    tools.add_selftest(sub)
    tools.add_stage(sub)
    tools.add_simulate(sub)
    return p


def _add_evo_rpg(sub) -> None:
    """The evo- and rpg-compatible commands, whose parsers their own modules build (their options
    copy their tools'); their handlers are attached by name."""
    from epa.evo import commands as cli_evo

    cli_evo.add_parsers(sub)
    cli_evo.add_res_parser(sub)

    from epa.rpg import command as rpg_command

    rpg_command.add_parser(sub)
    handlers = {"ape": cli_evo.run, "rpe": cli_evo.run, "res": cli_evo.res, "rpg": rpg_command.run}
    for name, func in handlers.items():
        sub.choices[name].set_defaults(func=func)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser(argv[0] if argv else None).parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="epa: %(levelname)s: %(message)s")
    try:
        status = args.func(args)  # an exit status (epa verify), or None when the command is done
    except EpaError as exc:
        print(f"epa: error: {exc.one_line()}", file=sys.stderr)
        return 2
    return 0 if status is None else status


if __name__ == "__main__":
    sys.exit(main())
