"""The ``epa`` command: the top-level parser and ``main``. Each command's parser and handler are in
their own module: ``epa eval`` in cli.evaluate, ``epa traj|fig`` in cli.trajectory, ``epa config|
selftest|stage|simulate`` in cli.tools, ``epa verify|pack`` in cli.packages, ``epa tum-ate|tum-rpe``
in cli.tum; ``epa ape|rpe|res`` (evo's command lines) in epa.evo and ``epa rpg`` in epa.rpg."""

from __future__ import annotations

import argparse
import logging
import sys

from epa import __version__
from epa.core.errors import EpaError

# Each command group's parser builder, in the order `epa --help` lists them: (the commands it adds,
# its module, its function). A command's own parser is built alone (`epa eval` builds only eval's),
# so a run imports only its own command's modules (compiled anew at each start where no bytecode is
# cached): `epa ape` no longer imports eval's, which imports every metric module (0.05-0.07 s).
BUILDERS = (
    (("eval",), "epa.cli.evaluate", "add_parser"),
    (("traj", "fig"), "epa.cli.trajectory", "add_parsers"),
    (("config",), "epa.cli.tools", "add_config"),
    (("ape", "rpe"), __name__, "_add_evo"),
    (("res",), __name__, "_add_res"),
    (("rpg",), __name__, "_add_rpg"),
    (("verify", "pack"), "epa.cli.packages", "add_parsers"),
    (("tum-ate", "tum-rpe"), "epa.cli.tum", "add_parsers"),
    (("selftest",), "epa.cli.tools", "add_selftest"),
    (("stage",), "epa.cli.tools", "add_stage"),
    (("simulate",), "epa.cli.tools", "add_simulate"),
)
COMMANDS = tuple(name for names, _, _ in BUILDERS for name in names)
# The commands that the top-level usage line (printed with an error the command's parser leaves to
# it, such as an unrecognised argument) lists after one of these: epica's own, as it always has.
OWN_COMMANDS = ("eval", "traj", "fig", "config", "selftest", "stage", "simulate")


def _parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line; for one of COMMANDS only its own group's parsers (``epa --help``, an
    unknown command and None build every one, as the top-level usage lists them)."""
    import importlib

    p = argparse.ArgumentParser(prog="epa", description="Trajectory evaluation for SLAM/VIO.")
    p.add_argument("--version", action="version", version=f"epica {__version__}")
    listed = OWN_COMMANDS if command in OWN_COMMANDS else COMMANDS
    # a command's own parser alone: the usage line lists the commands as before
    metavar = "{" + ",".join(listed) + "}" if command in COMMANDS else None
    sub = p.add_subparsers(dest="command", required=True, metavar=metavar)
    for names, module, function in BUILDERS:
        if command not in COMMANDS or command in names:
            getattr(importlib.import_module(module), function)(sub)
    return p


def _add_evo(sub) -> None:
    """evo's ape and rpe commands, whose parsers their module builds (their options copy evo's)."""
    from epa.evo import commands as cli_evo

    cli_evo.add_parsers(sub)
    for name in ("ape", "rpe"):
        sub.choices[name].set_defaults(func=cli_evo.run)


def _add_res(sub) -> None:
    from epa.evo import commands as cli_evo

    cli_evo.add_res_parser(sub)
    sub.choices["res"].set_defaults(func=cli_evo.res)


def _add_rpg(sub) -> None:
    """rpg_trajectory_evaluation's command, whose parser its module builds (its options copy rpg's)."""
    from epa.rpg import command as rpg_command

    rpg_command.add_parser(sub)
    sub.choices["rpg"].set_defaults(func=rpg_command.run)


def main(argv=None) -> int:
    if argv is None:  # the `epa` command's own process, not a program calling main()
        _without_cloudpickle()
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv else None
    if command == "eval":  # its files are read while its parser imports the metrics
        from epa.cli import evaluate

        done = evaluate.read_ahead(argv[1:])
    else:
        done = _nothing
    try:
        args = _parser(command).parse_args(argv)
        logging.basicConfig(level=logging.WARNING, format="epa: %(levelname)s: %(message)s")
        try:
            status = args.func(args)  # an exit status (epa verify), or None when it is done
        except EpaError as exc:
            print(f"epa: error: {exc.one_line()}", file=sys.stderr)
            return 2
    finally:  # files read ahead that no stage took (a mistake, --help): their reading ends here
        done()
    return 0 if status is None else status


def _nothing() -> None:
    pass


def _without_cloudpickle() -> None:
    """pyarrow (epa's parser of large text files) imports cloudpickle where it is installed, only to
    pickle pyarrow's own objects, which no epa command does: 8-10 ms of each run that reads one (it
    falls back on pickle). Nothing else a command imports uses it (Snakemake runs in a process of
    its own); a program calling main() keeps its modules as they are."""
    if "pyarrow" not in sys.modules:
        sys.modules.setdefault("cloudpickle", None)  # type: ignore[arg-type]


if __name__ == "__main__":
    sys.exit(main())
