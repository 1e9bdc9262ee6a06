"""epica: trajectory evaluation for SLAM and VIO (import package ``epa``).

Layers, each importing only from those before it (``tests/test_layers.py`` enforces it):
``core`` -> ``steps`` -> ``metrics`` -> ``readers`` -> ``artifacts`` -> ``simulate`` -> ``outputs``
-> ``workflow`` -> ``evo`` -> ``rpg`` -> ``api`` -> ``cli``. Each subpackage's ``__init__`` says what
lives there.

The Python API (:mod:`epa.api`, docs/api.md) is reached from here lazily, so ``import epa`` stays
light (no Snakemake, matplotlib or pandas): :func:`evaluate`, :func:`read_results`,
:func:`read_cells`, :func:`read_case`, :class:`Result`, and the building blocks
:func:`read_trajectory`, :func:`associate`, :func:`align`, :func:`ape`, :func:`rpe`, :func:`stats`
(with :class:`Trajectory` and :class:`Similarity`).
"""

import logging

__version__ = "0.2.0"

# A library prints nothing unless asked: each module logs to ``logging.getLogger(__name__)``, a
# child of "epa", and only the command (epa.cli) and the workflow (epa.workflow.terminal) attach
# handlers. Without one of those, nor the application's own, Python's last-resort handler would
# print epa's warnings on stderr.
logging.getLogger("epa").addHandler(logging.NullHandler())
# epa.api's __all__, written out so that `import epa` need not import it (tests/test_api.py holds
# the two equal)
__all__ = [
    "Result",
    "Similarity",
    "Trajectory",
    "align",
    "ape",
    "associate",
    "evaluate",
    "read_case",
    "read_cells",
    "read_results",
    "read_trajectory",
    "rpe",
    "stats",
]


def __getattr__(name: str):
    if name in __all__:
        from epa import api

        return getattr(api, name)
    raise AttributeError(f"module 'epa' has no attribute {name!r}")
