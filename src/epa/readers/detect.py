"""What a file is: a bag (told by its name), not a text trajectory at all (told by its first bytes),
or which text format (told by its header, its name and its number of columns)."""

from __future__ import annotations

from pathlib import Path

from epa.core.errors import EpaError
from epa.readers.header import named_columns, position_columns
from epa.readers.table import Table, is_number

BAG_SUFFIXES = (".bag", ".mcap")


def is_bag(path) -> bool:
    """A ROS 1 bag, a bare MCAP file or a ROS 2 bag folder (judged by name, so a missing bag is still
    reported as a missing bag)."""
    path = Path(path)
    try:
        return path.suffix.lower() in BAG_SUFFIXES or (
            path.is_dir() and (path / "metadata.yaml").is_file()
        )
    except OSError:  # an unusable path: the text reader reports it
        return False


def bag_files(path) -> list[Path]:
    """The files a bag consists of (a folder's metadata and storage files; else the file itself)."""
    path = Path(path)
    if path.is_dir():
        return sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
    return [path]


# Files that are not text trajectories, by their first bytes: say what they are.
_MAGIC = {
    b"\x1f\x8b": "gzip-compressed (decompress it first)",
    b"PK\x03\x04": "a zip archive (extract it first)",
    b"#ROSBAG": "a ROS 1 bag (give it as a bag source with a topic)",
    b"SQLite format 3": "an SQLite database (a ROS 2 bag's .db3: give the bag folder with a topic)",
    b"\x89MCAP": "an MCAP file (give it as a bag source with a topic)",
    b"\xff\xfe": "UTF-16 text (save it as UTF-8)",
    b"\xfe\xff": "UTF-16 text (save it as UTF-8)",
}


def check_text(path: Path, head: bytes) -> None:
    """Raise, saying what the file is, when its first bytes are not those of a text file."""
    for magic, what in _MAGIC.items():
        if head.startswith(magic):
            raise EpaError(f"{what}, not a text trajectory file", path=str(path))
    if b"\x00" in head or head.decode("utf-8", errors="replace").count("\ufffd") > 8:
        raise EpaError("binary data, not a text trajectory file", path=str(path))


FORMAT_SETTINGS = "load.truth_format / load.estimate_format"


def detect_format(path: Path, tab: Table) -> str:
    """The format when the file says it unambiguously; otherwise an error naming what was found.

    A header naming time, position and quaternion columns means ``csv``. A header of the file's
    width that names them otherwise (``t_s``, a byte-order mark, another language) is not guessed
    at; nor is one naming exactly time, x, y, z (a position-only ``csv``). Without such a header:
    ``.csv`` with 8+ columns is EuRoC (``qw`` first), else 4 columns position-only ``t x y z``, 8
    TUM, 12 KITTI, 20 OpenVINS."""
    width = tab.rows.shape[1]
    if named_columns(tab.header, width) is not None or position_columns(tab.header, width):
        return "csv"
    if tab.header and len(tab.header) == width and not all(is_number(h) for h in tab.header):
        raise EpaError(
            f"cannot tell the columns from the header ({', '.join(tab.header)}): name them t (or"
            " timestamp), x, y, z, qx, qy, qz, qw, or set " + FORMAT_SETTINGS,
            path=str(path),
        )
    if path.suffix.lower() == ".csv" and width >= 8:
        return "euroc"
    by_width = {4: "position", 8: "tum", 12: "kitti", 20: "openvins"}
    if width in by_width:
        return by_width[width]
    raise EpaError(
        f"cannot tell the format from {width} columns: expected 4 (t x y z, position only), 8 (TUM),"
        f" 12 (KITTI), 20 (OpenVINS) or a CSV header naming the columns; set {FORMAT_SETTINGS}",
        path=str(path),
    )
