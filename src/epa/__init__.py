"""epica: trajectory evaluation for SLAM and VIO (import package ``epa``).

Layers, each importing only from those before it (``tests/test_layers.py`` enforces it):
``core`` -> ``steps`` -> ``metrics`` -> ``readers`` -> ``artifacts`` -> ``simulate`` -> ``outputs``
-> ``workflow`` -> ``evo`` -> ``cli``. Each subpackage's ``__init__`` says what lives there.
"""

__version__ = "0.1.0"
