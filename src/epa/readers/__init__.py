"""Readers: every way a trajectory comes in.

- :mod:`epa.readers.text`: text files (TUM, KITTI, EuRoC, OpenVINS, named CSV): the parse paths
  and ``read_trajectory``; beside it :mod:`~epa.readers.table` (a file's rows),
  :mod:`~epa.readers.header` (header lines, column names), :mod:`~epa.readers.detect` (what a file
  is), :mod:`~epa.readers.formats` (a builder per format) and :mod:`~epa.readers.checks` (the rules
  every source's poses follow, bags' too).
- :mod:`epa.readers.bags`: ROS 1 / ROS 2 bags (topics, TF chains), read with ``rosbags``.
- :mod:`epa.readers.timing`: per-frame timing files.
- :mod:`epa.readers.source`: a source read with its per-source settings (``read``, ``options``).
"""

from epa.readers.source import (
    KEYS,
    TIMING_DEFAULTS,
    describe,
    options,
    read,
    read_printed_quaternions,
    timing_file,
)

__all__ = [
    "KEYS",
    "TIMING_DEFAULTS",
    "describe",
    "options",
    "read",
    "read_printed_quaternions",
    "timing_file",
]
