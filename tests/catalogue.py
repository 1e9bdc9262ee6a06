"""The catalogue of bad inputs: every row is a situation a user can create, the one-line error (or the
note on a correct result) they get, and a test (``tests/test_catalogue.py`` runs every row).

``python tests/catalogue.py > docs/bad-inputs.md`` writes the documentation from these rows; a test
checks that the page is current, so a row cannot be documented without being tested.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _rows(t, p, q=None, fmt="{:.9f}", sep=" ") -> str:
    q = np.tile([0, 0, 0, 1.0], (len(t), 1)) if q is None else q
    return "".join(sep.join(fmt.format(v) for v in (a, *b, *c)) + "\n" for a, b, c in zip(t, p, q))


def motion(n=600, dt=0.05, t0=1403636580.0):
    """Curved 3-D motion with rotation, the shape a VIO run has."""
    t = t0 + np.arange(n) * dt
    s = t - t0
    p = np.column_stack([5 * np.sin(s / 5), 3 * np.cos(s / 3), 0.1 * s])
    yaw, pitch = 0.6 * np.sin(s / 2), 0.3 * np.sin(s / 1.3)
    q = np.column_stack(
        [
            np.zeros(n),
            np.sin(pitch / 2) * np.cos(yaw / 2),
            np.sin(yaw / 2) * np.cos(pitch / 2),
            np.cos(yaw / 2) * np.cos(pitch / 2),
        ]
    )
    return t, p, q / np.linalg.norm(q, axis=1, keepdims=True)


T, P, Q = motion()
THREE = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0.5]])  # three poses, not on one line
LINE = np.column_stack([2 * (T - T[0]), 0 * T, 0 * T])  # 2 m/s along x, never turning
GOOD = _rows(T, P, Q)
POSITIONS = "".join(" ".join(f"{v:.9f}" for v in (a, *b)) + "\n" for a, b in zip(T, P))  # t x y z
GOOD_CSV = (
    "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n"
    + "".join(
        f"{int(round(a * 1e9))},{b[0]:.9f},{b[1]:.9f},{b[2]:.9f},{c[3]:.9f},{c[0]:.9f},{c[1]:.9f},{c[2]:.9f}\n"
        for a, b, c in zip(T, P, Q)
    )
)


def _replace_line(text: str, k: int, line: str) -> str:
    lines = text.splitlines(keepends=True)
    lines[k] = line + "\n"
    return "".join(lines)


def _kitti(n=300, bad_row=None) -> str:
    _, p, q = motion(n)
    from scipy.spatial.transform import Rotation

    r = Rotation.from_quat(q).as_matrix()
    m = np.concatenate([r, p[:, :, None]], axis=2).reshape(n, 12)
    if bad_row is not None:
        m[bad_row, :3] *= 2  # a rotation block that is no rotation
    return "".join(" ".join(f"{v:.9e}" for v in row) + "\n" for row in m)


@dataclass
class Bad:
    """One situation. ``where``: how it is run (eval: ``epa eval REF EST``; config: ``epa eval
    --config``; grid: a grid with one good case beside it; workflow: ``snakemake -n``)."""

    id: str
    where: str
    situation: str
    expect: str  # a fragment of the one-line error; for ``ok`` rows, of the note on the result
    est: str | bytes | None = None
    ref: str | bytes = GOOD
    est_name: str = "est.txt"
    ref_name: str = "ref.txt"
    args: tuple = ()
    config: str | None = None
    ok: bool = False  # a correct result (with a note saying what was inferred), not an error
    setup: str | None = None  # a named special setup done by the runner (links, folders, names)
    blame: str = (
        "est"  # whose path the error line names: est, ref, config or none (the command line)
    )
    timing: str | None = None  # content of est's <run>_timing.txt
    stamps: str | None = None  # content of stamps.txt in the working folder (metrics.eth3d)
    keeps_accuracy: bool = False  # the error is a later stage's: metrics.json stands
    blamed: str | None = None  # command rows: what the error line starts with ({ref}, {est}, {tmp})
    sheet: str | None = None  # workflow rows: the run sheet runs.tsv beside the config


S = GOOD.splitlines(keepends=True)
ETH3D_STAMPS = "metrics:\n  eth3d:\n    enabled: true\n    image_stamps: stamps.txt\n"
# the workflow rows of inputs where they lie: truth/seq.txt, algorithms/a/seq/run1.txt and
# other/a/seq/run1.txt (setup wf-inputs), named by patterns or a sheet
PATTERNS = "inputs:\n  reference: truth/{{dataset}}.txt\n  estimate: {estimate}\n"
SHEET = (
    "algorithm\tdataset\trun\testimate\treference\n"
    "a\tseq\trun1\talgorithms/a/seq/run1.txt\ttruth/seq.txt\n"
)
CATALOGUE: list[Bad] = [
    # ------------------------------------------------------------------ readers: what the file is
    Bad(
        "empty-file",
        "eval",
        "an empty estimate file",
        "no data rows (the file is empty or holds only comments)",
        est="",
    ),
    Bad(
        "only-comments",
        "eval",
        "only comment lines",
        "no data rows",
        est="# t x y z qx qy qz qw\n# nothing\n",
    ),
    Bad(
        "only-header",
        "eval",
        "a CSV header and no rows",
        "no data rows",
        est="t,x,y,z,qx,qy,qz,qw\n",
        est_name="est.csv",
    ),
    Bad(
        "binary",
        "eval",
        "binary garbage",
        "binary data, not a text trajectory file",
        est=bytes(range(256)) * 8,
    ),
    Bad(
        "gzip",
        "eval",
        "a gzip-compressed trajectory",
        "gzip-compressed (decompress it first)",
        est=b"\x1f\x8b\x08\x00" + bytes(60),
    ),
    Bad(
        "zip",
        "eval",
        "a zip archive",
        "a zip archive (extract it first)",
        est=b"PK\x03\x04" + bytes(60),
        est_name="est.zip",
    ),
    Bad(
        "utf16",
        "eval",
        "UTF-16 text (a Windows export)",
        "UTF-16 text (save it as UTF-8)",
        est=b"\xff\xfe" + GOOD.encode("utf-16-le"),
    ),
    Bad(
        "png",
        "eval",
        "an image given by mistake",
        "binary data",
        est=b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4,
        est_name="est.png",
    ),
    Bad(
        "bom-headerless",
        "eval",
        "a byte-order mark before headerless TUM rows",
        "format tum (8 columns)",
        est=b"\xef\xbb\xbf" + GOOD.encode(),
        ok=True,
    ),
    Bad(
        "bom-header",
        "eval",
        "a byte-order mark before a CSV header with qw first",
        "format csv",
        est=b"\xef\xbb\xbf"
        + (
            "t,x,y,z,qw,qx,qy,qz\n"
            + "".join(
                f"{a:.9f},{b[0]:.9f},{b[1]:.9f},{b[2]:.9f},{c[3]:.9f},{c[0]:.9f},{c[1]:.9f},{c[2]:.9f}\n"
                for a, b, c in zip(T, P, Q)
            )
        ).encode(),
        est_name="est.csv",
        ok=True,
    ),
    Bad(
        "crlf",
        "eval",
        "Windows line endings",
        "format tum",
        est=GOOD.replace("\n", "\r\n"),
        ok=True,
    ),
    Bad(
        "tabs", "eval", "tab-separated columns", "format tum", est=GOOD.replace(" ", "\t"), ok=True
    ),
    Bad(
        "latin1-comment",
        "eval",
        "a Latin-1 comment (é) above the rows",
        "format tum",
        est=b"# r\xe9sultat\n" + GOOD.encode(),
        ok=True,
    ),
    Bad(
        "inline-comment",
        "eval",
        "a comment at the end of a row",
        "format tum",
        est=_replace_line(GOOD, 3, S[3].rstrip() + "  # keyframe"),
        ok=True,
    ),
    # ------------------------------------------------------------------ readers: rows
    Bad(
        "empty-fields",
        "eval",
        "a row of empty fields (`,,,,,,,`) before the data",
        "est.csv:2: a row of empty fields",
        est="t,x,y,z,qx,qy,qz,qw\n,,,,,,,\n" + GOOD.replace(" ", ","),
        est_name="est.csv",
    ),
    Bad(
        "ragged",
        "eval",
        "a row with a missing column",
        "est.txt:6: expected 8 columns like the first data row, found 7",
        est=_replace_line(GOOD, 5, " ".join(S[5].split()[:7])),
    ),
    Bad(
        "truncated",
        "eval",
        "a file cut off mid-row (a crashed run)",
        "expected 8 columns like the first data row, found 3",
        est=GOOD + "1403636610.0 1.2 3.4",
    ),
    Bad(
        "word",
        "eval",
        "a word in a number column",
        "est.txt:4: not a number: 'nope'",
        est=_replace_line(GOOD, 3, S[3].replace(S[3].split()[2], "nope", 1)),
    ),
    Bad(
        "nan",
        "eval",
        "nan after a divergence",
        "est.txt:11: non-finite value (nan or inf)",
        est=_replace_line(GOOD, 10, " ".join(S[10].split()[:1] + ["nan"] * 7)),
    ),
    Bad(
        "inf",
        "eval",
        "an infinite position",
        "est.txt:3: non-finite value",
        est=_replace_line(GOOD, 2, S[2].replace(S[2].split()[1], "inf", 1)),
    ),
    Bad(
        "huge",
        "eval",
        "positions of 1e300",
        "est.txt:2: position 1e+300 m is beyond 1e+09 m",
        est=_replace_line(GOOD, 1, S[1].replace(S[1].split()[1], "1e300", 1)),
    ),
    Bad(
        "zero-quat",
        "eval",
        "an all-zero quaternion",
        "est.txt:5: zero quaternion",
        est=_replace_line(GOOD, 4, " ".join(S[4].split()[:4] + ["0", "0", "0", "0"])),
    ),
    Bad(
        "quat-norm",
        "eval",
        "quaternions far from unit norm (columns scaled or swapped)",
        "quaternions normalised (norm off by up to 1",
        est=_rows(T, P, 2 * Q),
        ok=True,
    ),
    Bad(
        "concatenated",
        "eval",
        "two files pasted together (a header line mid-file)",
        "est.txt:601: not a number: 't'",
        est=GOOD + "t x y z qx qy qz qw\n" + GOOD,
    ),
    Bad("one-pose", "eval", "a single pose", "only 1 pose(s); at least 2 are needed", est=S[0]),
    Bad(
        "two-headers",
        "eval",
        "two header rows (names, then units)",
        "est.csv:2: not a number: 's' (a second header line",
        est="t,x,y,z,qx,qy,qz,qw\ns,m,m,m,-,-,-,-\n" + GOOD.replace(" ", ","),
        est_name="est.csv",
    ),
    Bad(
        "header-width",
        "eval",
        "a header naming 8 columns above 9-column rows",
        "est.csv:1: the header names 8 columns but the rows have 9",
        est="t,x,y,z,qx,qy,qz,qw\n" + GOOD.replace(" ", ",").replace("\n", ",0\n"),
        est_name="est.csv",
    ),
    Bad(
        "decimal-comma",
        "eval",
        "a spreadsheet export with decimal commas",
        "decimal commas are not supported",
        est=GOOD.replace(".", ",").replace(" ", ";"),
        est_name="est.csv",
    ),
    Bad(
        "no-header-csv-7",
        "eval",
        "a headerless CSV of 7 columns",
        "cannot tell the format from 7 columns",
        est="".join(",".join(line.split()[:7]) + "\n" for line in S),
        est_name="est.csv",
    ),
    # ------------------------------------------------------------------ readers: format detection
    Bad(
        "unknown-width",
        "eval",
        "rows of 10 numbers",
        "cannot tell the format from 10 columns: expected 4 (t x y z, position only), 8 (TUM)",
        est=GOOD.replace("\n", " 0 0\n"),
    ),
    # ------------------------------------------------------------------ position-only estimates
    Bad(
        "position-only",
        "eval",
        "positions only: `t x y z` rows (GNSS, UWB, some LiDAR odometry)",
        "position only: no orientation, so every rotation quantity is null",
        est=POSITIONS,
        ok=True,
    ),
    Bad(
        "position-only-csv",
        "eval",
        "a CSV whose header names only time and x, y, z",
        "position only: no orientation, so every rotation quantity is null",
        est="#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]\n"
        + "".join(
            f"{int(round(a * 1e9))},{b[0]:.9f},{b[1]:.9f},{b[2]:.9f}\n" for a, b in zip(T, P)
        ),
        est_name="est.csv",
        ok=True,
    ),
    Bad(
        "position-unknown-column",
        "eval",
        "positions beside a column the header does not name as part of a pose (`speed`)",
        "cannot tell the columns from the header (t, x, y, z, speed)",
        est="t,x,y,z,speed\n" + POSITIONS.replace(" ", ",").replace("\n", ",1.0\n"),
        est_name="est.csv",
    ),
    Bad(
        "position-geodetic",
        "eval",
        "a GNSS export in latitude, longitude, altitude (a NavSatFix dump): never converted by guess",
        "cannot tell the columns from the header (time, lat, lon, alt)",
        est="time,lat,lon,alt\n" + POSITIONS.replace(" ", ","),
        est_name="est.csv",
    ),
    Bad(
        "position-rpe-angle",
        "eval",
        "a position-only estimate asked for an RPE whose pairs its rotation angle chooses",
        "its pairs are chosen by the estimate's rotation angle, and the estimate is position-only",
        est=POSITIONS,
        config="metrics:\n  rpe:\n    - {delta: 10, unit: deg}\n",
    ),
    Bad(
        "position-rpg-one-pose",
        "eval",
        "a position-only estimate aligned in mode rpg on its first pose's orientation",
        "aligns on the first pose's orientation, and the estimate is position-only",
        est=POSITIONS,
        args=("--mode", "rpg", "--first-n", "1"),
    ),
    Bad(
        "unnamed-time",
        "eval",
        "a CSV header whose time column is `t_s`",
        "cannot tell the columns from the header (t_s, x, y, z, qx, qy, qz, qw)",
        est="t_s,x,y,z,qx,qy,qz,qw\n" + GOOD.replace(" ", ","),
        est_name="est.csv",
    ),
    Bad(
        "foreign-header",
        "eval",
        "a header in another language",
        "cannot tell the columns from the header (zeit,",
        est="zeit,px,py,pz,a,b,c,d\n" + GOOD.replace(" ", ","),
        est_name="est.csv",
    ),
    Bad(
        "euroc-guess",
        "eval",
        "a headerless `.csv` of 8 columns (EuRoC order by extension and width)",
        "format euroc (8 columns)",
        est="".join(
            ",".join(line.split()[:4] + [line.split()[7]] + line.split()[4:7]) + "\n" for line in S
        ),
        est_name="est.csv",
        ok=True,
    ),
    Bad(
        "named-csv",
        "eval",
        "a CSV whose header names the columns in any order",
        "format csv (8 columns, header names them)",
        est="qw,qx,qy,qz,x,y,z,timestamp\n"
        + "".join(
            ",".join(line.split()[7:8] + line.split()[4:7] + line.split()[1:4] + line.split()[:1])
            + "\n"
            for line in S
        ),
        est_name="est.csv",
        ok=True,
    ),
    Bad(
        "euroc-gt",
        "eval",
        "EuRoC ground truth (`#timestamp [ns]` header, `qw` first)",
        "format csv (8 columns, header names them)",
        est=GOOD_CSV,
        est_name="est.csv",
        ok=True,
    ),
    Bad(
        "bad-format-setting",
        "eval",
        "`--est-format tumm`",
        "command line: load.estimate_format: 'tumm' is not one of",
        est=GOOD,
        args=("--est-format", "tumm"),
        blame="none",
    ),
    Bad(
        "wrong-format-setting",
        "eval",
        "`--est-format kitti` on a TUM file",
        "KITTI needs 12 columns (3x4 row-major pose), found 8",
        est=GOOD,
        args=("--est-format", "kitti"),
    ),
    Bad(
        "kitti-not-rotation",
        "eval",
        "a KITTI row whose rotation block is not a rotation",
        "est.txt:8: rotation block is not a rotation",
        est=_kitti(bad_row=7),
        ref=_kitti(),
        args=("--no-offset-estimate", "--no-calibrate"),
    ),
    Bad(
        "kitti-times",
        "eval",
        "a KITTI `times.txt` with fewer stamps than poses",
        "times file has 5 stamps for 300 poses",
        est=_kitti(),
        ref=_kitti(),
        setup="kitti-times",
    ),
    Bad(
        "kitti-rate",
        "eval",
        "KITTI poses without a times file",
        "KITTI stamps at 10.0 Hz (no times file; load.kitti_rate)",
        est=_kitti(),
        ref=_kitti(),
        args=("--no-offset-estimate", "--no-calibrate"),
        ok=True,
    ),
    Bad(
        "openvins-20",
        "eval",
        "OpenVINS 20 columns (pose + covariance)",
        "format openvins (20 columns)",
        est=GOOD.replace("\n", " 1 0 0 1 0 1 1 0 0 1 0 1\n"),
        ok=True,
    ),
    # ------------------------------------------------------------------ readers: time stamps
    Bad(
        "mixed-units",
        "eval",
        "seconds and nanoseconds mixed in one file",
        "is in nanoseconds but most stamps are seconds: the file mixes units",
        est=_replace_line(
            GOOD, 6, S[6].replace(S[6].split()[0], str(int(float(S[6].split()[0]) * 1e9)), 1)
        ),
    ),
    Bad(
        "ns-inferred",
        "eval",
        "nanosecond stamps in a headerless file",
        "stamps read as nanoseconds (above 1e12, so not seconds)",
        est="".join(
            f"{int(round(a * 1e9))} " + " ".join(line.split()[1:]) + "\n" for a, line in zip(T, S)
        ),
        ok=True,
    ),
    Bad(
        "ns-as-float",
        "eval",
        "nanosecond stamps printed as floats (`1.4036e+18`)",
        "stamps read as nanoseconds",
        est="".join(
            f"{a * 1e9:.15e} " + " ".join(line.split()[1:]) + "\n" for a, line in zip(T, S)
        ),
        ok=True,
    ),
    Bad(
        "sec-nsec-bad",
        "eval",
        "`--time-unit sec_nsec` on a stamp that is not sec.nsec",
        "is not of the form sec.nsec",
        est=_replace_line(GOOD, 2, S[2].replace(S[2].split()[0], "-5", 1)),
        args=("--time-unit", "sec_nsec"),
    ),
    Bad(
        "repeated",
        "eval",
        "a repeated timestamp",
        "est.txt:11: timestamp 1403636580.45 repeats (set load.unsorted: sort",
        est=_replace_line(GOOD, 10, S[9].rstrip()),
    ),
    Bad(
        "backwards",
        "eval",
        "a timestamp that goes backwards",
        "est.txt:21: timestamp 1403636580.1 goes backwards",
        est=_replace_line(GOOD, 20, S[2].rstrip()),
    ),
    Bad(
        "sorted-on-request",
        "eval",
        "repeated stamps with `--unsorted sort`",
        "0 backward and 1 repeated timestamps: sorted",
        est=_replace_line(GOOD, 10, S[9].rstrip()),
        args=("--unsorted", "sort"),
        ok=True,
    ),
    Bad(
        "different-clock",
        "eval",
        "an estimate stamped from 0 while the reference uses Unix time",
        "the stamps do not overlap: reference 1403636580.000..1403636609.950 s, estimate 0.000..29.950 s",
        est=_rows(T - T[0], P, Q),
    ),
    # ------------------------------------------------------------------ paths
    Bad(
        "missing-file",
        "eval",
        "an estimate path that does not exist",
        "est.txt: file not found",
        setup="missing",
    ),
    Bad(
        "directory",
        "eval",
        "a folder given as the estimate",
        "is a directory, expected a trajectory file",
        setup="directory",
    ),
    Bad(
        "dangling-link",
        "eval",
        "a symbolic link to a deleted file",
        "file not found",
        setup="dangling",
    ),
    Bad(
        "device",
        "eval",
        "a link to `/dev/zero` (would never end)",
        "not a regular file (a device, pipe or socket)",
        setup="device",
    ),
    Bad(
        "not-a-folder",
        "eval",
        "a path through a file (`est.txt/x.txt`)",
        "cannot read: Not a directory",
        setup="through-file",
    ),
    Bad(
        "name-too-long",
        "eval",
        "a file name longer than the file system allows",
        "cannot read: File name too long",
        setup="long-name",
    ),
    Bad(
        "missing-ref",
        "eval",
        "a reference path that does not exist",
        "ref.txt: file not found",
        setup="missing-ref",
        blame="ref",
    ),
    Bad(
        "bad-ref",
        "eval",
        "a broken reference (a row of text)",
        "ref.txt:3: not a number: 'oops'",
        ref=_replace_line(GOOD, 2, "oops"),
        est=GOOD,
        blame="ref",
    ),
    # ------ bags (est.bag: /pose, /gt, /tf, /chatter, /empty)
    Bad(
        "bag-ok",
        "eval",
        "a bag topic as the estimate",
        "bag topic /pose (PoseStamped, header stamps)",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/pose"),
        ok=True,
    ),
    Bad(
        "bag-same-bag",
        "eval",
        "reference and estimate as two topics of one bag",
        "bag topic /gt",
        est_name="est.bag",
        setup="bag-same",
        args=("--ref-topic", "/gt", "--est-topic", "/pose"),
        ok=True,
    ),
    Bad(
        "bag-ros2",
        "eval",
        "a ROS 2 bag folder (sqlite3)",
        "bag topic /pose",
        est_name="est_ros2",
        setup="bag-sqlite3",
        args=("--est-topic", "/pose"),
        ok=True,
    ),
    Bad(
        "bag-mcap",
        "eval",
        "a ROS 2 MCAP bag",
        "bag topic /pose",
        est_name="est_mcap",
        setup="bag-mcap",
        args=("--est-topic", "/pose"),
        ok=True,
    ),
    Bad(
        "bag-only-topic",
        "eval",
        "no topic given, the bag has one pose topic",
        "topic /pose (the bag's only pose topic)",
        est_name="est.bag",
        setup="bag-one",
        ok=True,
    ),
    Bad(
        "bag-missing-topic",
        "eval",
        "a topic the bag does not have",
        "no topic '/nope'; the bag has /chatter (String), /empty (PoseStamped), /gt (PoseStamped), /pose (PoseStamped), /tf (TFMessage)",  # noqa: E501
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/nope"),
    ),
    Bad(
        "bag-choose",
        "eval",
        "no topic given, the bag has several",
        "choose a topic: the bag has",
        est_name="est.bag",
        setup="bag",
    ),
    Bad(
        "bag-wrong-type",
        "eval",
        "a topic of a type that holds no pose",
        "topic /chatter is std_msgs/msg/String, not a pose type",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/chatter"),
    ),
    Bad(
        "bag-empty-topic",
        "eval",
        "a topic without messages",
        "topic /empty has no messages",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/empty"),
    ),
    Bad(
        "bag-tf-no-frames",
        "eval",
        "`/tf` without frames",
        "topic /tf is TF: give the parent and child frame",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/tf"),
    ),
    Bad(
        "bag-tf-unknown-frame",
        "eval",
        "a TF frame the bag does not have",
        "unknown frame 'base'; the TF frames are body, world",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/tf", "--est-frames", "world", "base"),
    ),
    Bad(
        "bag-tf-ok",
        "eval",
        "a TF chain as the estimate",
        "bag TF world -> body",
        est_name="est.bag",
        setup="bag",
        args=("--est-topic", "/tf", "--est-frames", "world", "body"),
        ok=True,
    ),
    Bad(
        "bag-truncated",
        "eval",
        "a ROS 1 bag cut off by a crash",
        "cannot read the bag",
        est_name="est.bag",
        setup="bag-truncated",
        args=("--est-topic", "/pose"),
    ),
    Bad(
        "bag-corrupt",
        "eval",
        "garbage named `.bag`",
        "cannot read the bag",
        est=bytes(range(256)) * 4,
        est_name="est.bag",
        args=("--est-topic", "/pose"),
    ),
    Bad(
        "bag-mcap-corrupt",
        "eval",
        "garbage named `.mcap`",
        "cannot read the bag",
        est=b"\x89MCAP0\r\n" + bytes(300),
        est_name="est.mcap",
        args=("--est-topic", "/pose"),
    ),
    Bad(
        "bag-folder-no-storage",
        "eval",
        "a ROS 2 bag folder whose database is missing",
        "cannot read the bag",
        est_name="est_ros2",
        setup="bag-no-db",
        args=("--est-topic", "/pose"),
    ),
    Bad(
        "bag-missing",
        "eval",
        "a bag path that does not exist",
        "file not found",
        est_name="est.bag",
        args=("--est-topic", "/pose"),
        setup="missing",
    ),
    Bad(
        "bag-topic-on-text",
        "eval",
        "a topic given for a text file",
        "a topic is set for this source but it is not a bag",
        est=GOOD,
        args=("--est-topic", "/pose"),
    ),
    Bad(
        "bag-repeated",
        "eval",
        "a bag topic with a repeated header stamp",
        "topic /pose: message 11: stamp 1403636580.45 repeats",
        est_name="est.bag",
        setup="bag-repeated",
        args=("--est-topic", "/pose"),
    ),
    # ------------------------------------------------------------------ covariance and timing
    Bad(
        "timing-columns",
        "eval",
        "a timing file with 3 columns",
        "est_timing.txt: a timing file has 2 columns (<timestamp> <milliseconds>) or an OpenVINS header with 'total'; found 3",  # noqa: E501
        est=GOOD,
        timing="1 2 3\n4 5 6\n",
        blame="timing",
        keeps_accuracy=True,
    ),
    Bad(
        "timing-negative",
        "eval",
        "a negative frame time",
        "est_timing.txt:2: negative frame time -3 ms",
        est=GOOD,
        timing="1403636580.0 12\n1403636580.05 -3\n",
        blame="timing",
        keeps_accuracy=True,
    ),
    Bad(
        "timing-word",
        "eval",
        "a word in a timing file",
        "est_timing.txt:2: not a number: 'slow'",
        est=GOOD,
        timing="1403636580.0 12\n1403636580.05 slow\n",
        blame="timing",
        keeps_accuracy=True,
    ),
    Bad(
        "timing-missing",
        "eval",
        "`--timing` naming a missing file",
        "timing file not found",
        est=GOOD,
        args=("--timing", "nowhere_timing.txt"),
        blame="timing-arg",
        keeps_accuracy=True,
    ),
    Bad(
        "timing-other-clock",
        "eval",
        "a timing file on another clock (no pose has an entry)",
        "no pose has a timing entry within 0.01 s",
        est=GOOD,
        timing="5.0 12\n5.05 13\n",
        ok=True,
    ),
    Bad(
        "timing-partial",
        "eval",
        "a timing file covering part of the run",
        "poses have no timing entry within 0.01 s",
        est=GOOD,
        timing="".join(f"{t:.9f} 20\n" for t in T[:300]),
        ok=True,
    ),
    Bad(
        "timing-rate-guessed",
        "eval",
        "no sensor rate configured",
        "sensor rate 20.000 Hz from the timing file's stamps",
        est=GOOD,
        timing="".join(f"{t:.9f} 20\n" for t in T),
        ok=True,
    ),
    Bad(
        "mixed-separators",
        "eval",
        "space-separated rows, then comma-separated ones",
        "est.txt:6: fields separated by ',' where the first data row (line 1) separates them by spaces",
        est=_replace_line(GOOD, 5, S[5].strip().replace(" ", ",")),
    ),
    Bad(
        "stamp-record-text",
        "eval",
        "`--stamp record` (bags only) for text files",
        "stamp: record is set for this source but it is not a bag",
        est=GOOD,
        args=("--stamp", "record"),
        blame="ref",
    ),
    Bad(
        "tf-loop",
        "eval",
        "a TF tree with a loop (world -> odom and odom -> world): the same error whatever the hash seed",
        "the TF frames form a loop (odom -> world and world -> odom close it)",
        args=("--est-topic", "/tf", "--est-frames", "world", "body"),
        est_name="est.bag",
        setup="bag-tf-loop",
    ),
    Bad(
        "timing-overflow",
        "eval",
        "a 100,000 ms frame in a timing file (EA-Drift would be inf)",
        "its EA-Drift weight overflows, so EA-Drift is left empty",
        est=GOOD,
        timing="".join(f"{t:.9f} {100000 if k == 100 else 20}\n" for k, t in enumerate(T)),
        args=("--rate", "20"),
        ok=True,
    ),
    Bad(
        "timing-ns-overflow",
        "eval",
        "a timing file in nanoseconds given as milliseconds (every frame 'takes' 3e7 ms)",
        "its EA-Drift weight overflows",
        est=GOOD,
        timing="".join(f"{t:.9f} 30000000\n" for t in T),
        args=("--rate", "20"),
        ok=True,
    ),
    Bad(
        "cov-not-pd",
        "eval",
        "a covariance that is not positive definite",
        '"n_not_positive_definite": 1',
        est=_replace_line(
            GOOD.replace("\n", " 1 0 0 1 0 1 1 0 0 1 0 1\n"),
            4,
            " ".join(S[4].split() + ["-1", "0", "0", "1", "0", "1"] * 2),
        ),
        ok=True,
    ),
    Bad(
        "cov-none",
        "eval",
        "an estimate without covariance",
        "the estimate has no covariance",
        est=GOOD,
        ok=True,
    ),
    # ------------------------------------------------------------------ stages
    Bad(
        "no-overlap",
        "stage",
        "estimate and reference that do not overlap in time",
        "sync: only 0 poses matched within 0.02 s",
        est=_rows(T + 1000, P, Q),
    ),
    Bad(
        "too-few-matched",
        "stage",
        "an estimate at 0.2 Hz (6 poses)",
        "sync: only 6 poses matched within 0.02 s (offset 0.000000 s); 10 needed",
        est=_rows(T[::100], P[::100], Q[::100]),
    ),
    Bad(
        "static-est",
        "stage",
        "an estimate that never moves",
        "align: the estimate does not move over the 600 poses used by align se3",
        est=_rows(T, 0 * P, Q),
        args=("--no-calibrate",),
    ),
    Bad(
        "static-ref",
        "stage",
        "a reference that never moves",
        "the reference does not move",
        ref=_rows(T, 0 * P, Q),
        est=_rows(T, 0 * P, Q),
        args=("--no-offset-estimate", "--no-calibrate"),
    ),
    Bad(
        "static-ref-no-align",
        "stage",
        "a static reference with `--align none`",
        "metrics: the reference does not move",
        ref=_rows(T, 0 * P, Q),
        est=_rows(T, 0 * P, Q),
        args=("--no-offset-estimate", "--no-calibrate", "--align", "none"),
    ),
    Bad(
        "eth3d-stamps-missing",
        "stage",
        "`metrics.eth3d.image_stamps` naming a file that does not exist",
        "cannot read the image stamps: FileNotFoundError",
        est=GOOD,
        config=ETH3D_STAMPS,
        blame="stamps",
    ),
    Bad(
        "eth3d-stamps-text",
        "stage",
        "an image stamps file with a word for a stamp",
        "image stamp 'rgb/1.png' is not a number",
        est=GOOD,
        config=ETH3D_STAMPS,
        stamps=f"# timestamp filename\n{T[10]:.6f} rgb/0.png\nrgb/1.png {T[11]:.6f}\n",
        blame="stamps",
    ),
    Bad(
        "eth3d-stamps-unsorted",
        "stage",
        "image stamps out of order",
        "image stamp before the one above it (the stamps must be sorted)",
        est=GOOD,
        config=ETH3D_STAMPS,
        stamps=f"{T[20]:.6f}\n{T[10]:.6f}\n",
        blame="stamps",
    ),
    Bad(
        "eth3d-stamps-outside",
        "stage",
        "image stamps outside the reference's time span",
        "eth3d: 0 of 2 image stamps lie between two reference poses",
        est=GOOD,
        config=ETH3D_STAMPS,
        stamps=f"{T[0] - 100:.6f}\n{T[0] - 99:.6f}\n",
    ),
    Bad(
        "eth3d-dataset-in-eval",
        "stage",
        "`metrics.eth3d.image_stamps` naming `{dataset}` in `epa eval` (one case, no dataset)",
        "names {dataset} and this case has no dataset (epa eval): name the file itself",
        est=GOOD,
        config="metrics:\n  eth3d:\n    enabled: true\n    image_stamps: '{dataset}.txt'\n",
    ),
    Bad(
        "eth3d-sparse-reference",
        "stage",
        "the ETH3D protocol on a 20 Hz reference (gaps over its 1/75 s limit)",
        "max_interpolation_timespan; the reference's median step is 0.05 s",
        est=GOOD,
        config="metrics:\n  eth3d:\n    enabled: true\n",
    ),
    Bad(
        "eth3d-missing-output",
        "stage",
        "the ETH3D protocol on an estimate that stops before the reference",
        "lie outside the estimate: it is held at its first or last pose there",
        est="".join(S[:400]),
        config="metrics:\n  eth3d:\n    enabled: true\n    max_interpolation_timespan: 0.1\n",
        ok=True,
    ),
    Bad(
        "collinear",
        "stage",
        "a straight-line estimate aligned with se3",
        "lie on one straight line: the rotation about it is undetermined",
        est=_rows(T, np.column_stack([T - T[0], 0 * T, 0 * T]), Q),
        args=("--no-calibrate",),
    ),
    Bad(
        "first-n-2",
        "stage",
        "`--first-n 2`",
        "command line: align.first_n: 2 is not allowed",
        est=GOOD,
        args=("--first-n", "2"),
        blame="none",
    ),
    Bad(
        "first-n-big",
        "stage",
        "`--first-n` beyond the matched poses (all are used)",
        "poses matched",
        est=GOOD,
        args=("--first-n", "100000"),
        ok=True,
    ),
    Bad(
        "long-segment",
        "stage",
        "a segment length longer than the path",
        "no 1000 m segment fits in the",
        est=GOOD,
        args=("--segments", "8", "1000"),
        ok=True,
    ),
    Bad(
        "offset-untrusted",
        "stage",
        "too little rotation for Step 1 (estimate held still in rotation)",
        "Step 1 not used",
        est=_rows(T, P),
        ref=_rows(T, P),
        ok=True,
    ),
    Bad(
        "three-matched",
        "stage",
        "exactly 3 matched poses (`sync.min_pairs: 3`): no RPE pair, statistics null with a note",
        "no two matched poses are 1 s (±10 %) apart in 0.100 s: the 1 s RPE is empty",
        ref=_rows(T[:3], THREE),
        est=_rows(T[:3], THREE + [[0.01, 0, 0], [0, 0.02, 0], [0, 0, 0.01]]),
        config="sync:\n  min_pairs: 3\n",
        ok=True,
    ),
    Bad(
        "pure-translation-drifting",
        "stage",
        "pure translation without rotation (a straight line, `--align posyaw`) whose estimate"
        " drifts everywhere (3x its length): the drift-valid ATE null with a note",
        "no drift-valid interval (distance success rate 0 %): every drift-valid metric is empty",
        ref=_rows(T, LINE),
        est=_rows(T, 3 * LINE),
        args=("--no-offset-estimate", "--no-calibrate", "--align", "posyaw"),
        ok=True,
    ),
    # ------------------------------------------------------------------ config
    Bad(
        "cfg-list",
        "config",
        "a config that is a YAML list",
        "a config must be a mapping of settings, not a list",
        est=GOOD,
        config="- sync\n- align\n",
    ),
    Bad(
        "cfg-yaml",
        "config",
        "a config that is not YAML",
        "cfg.yaml:3: not valid YAML",
        est=GOOD,
        config="sync:\n  - [\n",
    ),
    Bad(
        "cfg-duplicate",
        "config",
        "a key given twice",
        "cfg.yaml:3: 'sync' is given twice",
        est=GOOD,
        config="sync:\n  policy: evo\nsync:\n  max_diff: 0.1\n",
    ),
    Bad(
        "cfg-typo",
        "config",
        "a misspelt key (`algin`)",
        "Additional properties are not allowed ('algin' was unexpected)",
        est=GOOD,
        config="algin:\n  method: sim3\n",
    ),
    Bad(
        "cfg-enum",
        "config",
        "an unknown alignment method",
        "align.method: 'sim4' is not one of",
        est=GOOD,
        config="align:\n  method: sim4\n",
    ),
    Bad(
        "cfg-negative",
        "config",
        "a negative tolerance",
        "sync.max_diff: -0.01 is less than or equal to the minimum of 0",
        est=GOOD,
        config="sync:\n  max_diff: -0.01\n",
    ),
    Bad(
        "cfg-type",
        "config",
        "a segment length with a unit (`8m`)",
        "metrics.segments.0: '8m' is not of type 'number'",
        est=GOOD,
        config="metrics:\n  segments: [8m]\n",
    ),
    Bad(
        "cfg-empty-list",
        "config",
        "no segment lengths",
        "metrics.segments: [] should be non-empty",
        est=GOOD,
        config="metrics:\n  segments: []\n",
    ),
    Bad(
        "cfg-crop",
        "config",
        "a crop that ends before it starts",
        "crop.end (5) must be after crop.start (10)",
        est=GOOD,
        config="crop:\n  start: 10\n  end: 5\n",
    ),
    Bad(
        "cfg-missing",
        "config",
        "`--config` naming a missing file",
        "cannot read: No such file or directory",
        est=GOOD,
        setup="missing-config",
    ),
    Bad(
        "cfg-python",
        "config",
        "a YAML tag that would run code",
        "not valid YAML",
        est=GOOD,
        config="sync: !!python/object/apply:os.system ['touch HACKED']\n",
    ),
    Bad(
        "cfg-eval-per-case",
        "config",
        "`report.per_case: true` in an `epa eval` config (`--report` decides)",
        "report.per_case: true in the config is not used by epa eval",
        est=GOOD,
        config="report:\n  per_case: true\n",
        ok=True,
    ),
    Bad(
        "cfg-mode-override",
        "config",
        "`mode: ov_eval` with `sync.policy: evo`",
        "mode ov_eval overrides sync.policy: 'evo' -> 'ov_eval'",
        est=GOOD,
        config="mode: ov_eval\nsync:\n  policy: evo\n",
        ok=True,
    ),
    Bad(
        "cfg-inf",
        "config",
        "`sync.window: .inf` (would pass a minimum, then fail inside Step 1)",
        "sync.window: inf is not a finite number",
        est=GOOD,
        config="sync:\n  window: .inf\n",
    ),
    Bad(
        "cfg-nan",
        "config",
        "`drift.rpe_trans_max_m: .nan` (nan passes every bound)",
        "drift.rpe_trans_max_m: nan is not a finite number",
        est=GOOD,
        config="drift:\n  rpe_trans_max_m: .nan\n",
    ),
    Bad(
        "cfg-nan-in-list",
        "config",
        "a nan among the segment lengths",
        "metrics.segments.1: nan is not a finite number",
        est=GOOD,
        config="metrics:\n  segments: [8, .nan]\n",
    ),
    Bad(
        "cfg-negative-crop",
        "config",
        "a negative crop start",
        "crop.start: -1 is less than the minimum of 0",
        est=GOOD,
        config="crop:\n  start: -1\n",
    ),
    Bad(
        "cfg-negative-rpe-delta",
        "config",
        "a negative RPE delta (`metrics.rpe`)",
        "metrics.rpe.0.delta: -5 is less than or equal to the minimum of 0",
        est=GOOD,
        config="metrics:\n  rpe:\n    - {delta: -5, unit: m}\n",
    ),
    Bad(
        "cfg-quoted-boolean",
        "config",
        'a quoted `"no"` for a boolean in a config file (only `--config` strings are coerced)',
        "calibrate.scale: 'no' is not of type 'boolean'",
        est=GOOD,
        config='calibrate:\n  scale: "no"\n',
    ),
    # ------------------------------------------------------------------ grids
    Bad(
        "grid-bad-run",
        "grid",
        "one run with a broken row among good runs",
        "load: ",
        setup="grid-bad-run",
    ),
    Bad(
        "grid-bad-truth",
        "grid",
        "a broken reference: its dataset's cases fail, others finish",
        "not a number: 'oops'",
        setup="grid-bad-truth",
    ),
    Bad(
        "grid-dangling",
        "grid",
        "a run that is a dangling link",
        "file not found",
        setup="grid-dangling",
    ),
    Bad("grid-static", "grid", "a run that never moves", "does not move", setup="grid-static"),
    Bad(
        "grid-names",
        "grid",
        "run names with spaces, unicode, `%`, `&`, `..`, braces",
        "ok",
        setup="grid-names",
        ok=True,
    ),
    Bad(
        "grid-bag-reference",
        "grid",
        "bag references (ROS 2 folders) with text estimates",
        "ok",
        setup="grid-bag-ref",
        ok=True,
    ),
    Bad(
        "grid-bag-truncated",
        "grid",
        "a truncated bag among good runs",
        "cannot read the bag",
        setup="grid-bag-truncated",
    ),
    Bad(
        "grid-two-runs",
        "grid",
        "`run1.txt` and `run1.csv` in one folder",
        "two runs named 'run1' (run1.csv, run1.txt)",
        setup="grid-two-runs",
    ),
    Bad(
        "grid-two-refs",
        "grid",
        "two reference files for one dataset",
        "two reference files for dataset 'seq'",
        setup="grid-two-refs",
    ),
    Bad(
        "grid-no-cases",
        "grid",
        "an algorithms folder whose datasets match no reference",
        "no estimate matches a reference (expected <algorithm>/<dataset>/<run>.<ext>)",
        setup="grid-no-cases",
    ),
    Bad(
        "grid-stray",
        "grid",
        "stray files and folders at the wrong level",
        "taken as neither a run nor a reference",
        setup="grid-stray",
        ok=True,
    ),
    Bad(
        "grid-no-truth",
        "grid",
        "a dataset folder without a reference",
        "no reference",
        setup="grid-no-truth",
        ok=True,
    ),
    Bad(
        "grid-backslash-name",
        "grid",
        "a run named `run1\\..\\..\\EPABI.txt` (backslashes): it fails alone, nothing is written outside",
        "plain names",
        setup="grid-backslash",
    ),
    Bad(
        "grid-every-run-fails",
        "grid",
        "an algorithm whose every run fails (no numpy warning in the tables or figures)",
        "load: ",
        setup="grid-all-fail",
    ),
    Bad(
        "grid-timing-pattern",
        "grid",
        'a configured timing pattern (`timing: "{run}.frames"`) beside the runs: side files, not runs',
        "ok",
        setup="grid-timing-pattern",
        config='sources:\n  algorithms:\n    good: {timing: "{run}.frames"}\n',
        ok=True,
    ),
    Bad(
        "grid-unknown-algorithm-source",
        "grid",
        "`sources.algorithms.<name>` naming no algorithm of the grid",
        "sources.algorithms.nope names no algorithm of the grid (good): ignored",
        config="sources:\n  algorithms:\n    nope: {format: tum}\n",
        ok=True,
    ),
    Bad(
        "grid-unknown-dataset-source",
        "grid",
        "`sources.datasets.<name>` (or `efficiency.datasets`) naming no dataset of the grid",
        "sources.datasets.nope names no dataset of the grid (other, seq): ignored",
        config="sources:\n  datasets:\n    nope: {format: tum}\n",
        ok=True,
    ),
    Bad(
        "grid-empty-dataset",
        "grid",
        "an algorithm whose only dataset folder is empty",
        "algorithm 'empty' has no case: it is in no output",
        setup="grid-empty-dataset",
        ok=True,
    ),
    Bad(
        "grid-ea-drift-overflow",
        "grid",
        "a 100,000 ms frame in a timing file: EA-Drift empty with the reason (never inf)",
        "its EA-Drift weight overflows, so EA-Drift is left empty",
        setup="grid-ea-overflow",
        config="efficiency: {sensor_rate_hz: 20}\n",
        ok=True,
    ),
    Bad(
        "grid-killed-write",
        "grid",
        "a temporary file a killed write left in a case folder (`03_sync/.xcorr.csv.<random>`):"
        " the next run removes it",
        "removed what a killed run left: .xcorr.csv.k1ll3d_x",
        setup="grid-killed-write",
        ok=True,
    ),
    # ------------------------------------------------------------------ commands
    Bad(
        "ape-save-under-a-file",
        "command",
        "`epa ape ... --save_results X/ape.zip` where X is a file",
        "X is a file, not a folder",
        args=("ape", "tum", "{ref}", "{est}", "--save_results", "{tmp}/X/ape.zip"),
        setup="file-X",
        blamed="{tmp}/X/ape.zip",
    ),
    Bad(
        "rpe-negative-delta",
        "command",
        "`epa rpe ... -d -5 -u m` (a negative delta)",
        "--delta must be positive, not -5",
        args=("rpe", "tum", "{ref}", "{est}", "-d", "-5", "-u", "m"),
        blamed="--delta",
    ),
    Bad(
        "ape-negative-n-to-align",
        "command",
        "`epa ape ... -a --n_to_align -5` (only -1 means all)",
        "--n_to_align must be -1 (all) or a number of poses, not -5",
        args=("ape", "tum", "{ref}", "{est}", "-a", "--n_to_align", "-5"),
        blamed="--n_to_align",
    ),
    Bad(
        "rpe-nan-tolerance",
        "command",
        "`epa rpe ... --t_max_diff nan`",
        "--t_max_diff must be a finite number, not nan",
        args=("rpe", "tum", "{ref}", "{est}", "--t_max_diff", "nan"),
        blamed="--t_max_diff",
    ),
    Bad(
        "res-no-title",
        "command",
        "`epa res` on a saved result without title",
        "epica-result/1 result without a title (key 'title')",
        args=("res", "{tmp}/r.json"),
        setup="result-no-title",
        blamed="{tmp}/r.json",
    ),
    Bad(
        "res-no-stats",
        "command",
        "`epa res` on a saved result without stats",
        "key 'stats' holds no statistics: None",
        args=("res", "{tmp}/r.json"),
        setup="result-no-stats",
        blamed="{tmp}/r.json",
    ),
    Bad(
        "res-ate-null",
        "command",
        "`epa res` on a metrics.json whose ate is null",
        "key 'ate' holds no ATE: None",
        args=("res", "{tmp}/metrics.json"),
        setup="metrics-ate-null",
        blamed="{tmp}/metrics.json",
    ),
    Bad(
        "res-missing",
        "command",
        "`epa res` on a file that does not exist",
        "file not found",
        args=("res", "{tmp}/nowhere.json"),
        blamed="{tmp}/nowhere.json",
    ),
    Bad(
        "selftest-short",
        "command",
        "`epa selftest` on a 3-pose reference",
        "too short for a selftest: 0.100 s of reference (3 poses)",
        args=("selftest", "{ref}"),
        ref="".join(S[:3]),
        blamed="{ref}",
    ),
    Bad(
        "selftest-rate",
        "command",
        "`epa selftest --rate -1`",
        "--trials must be at least 1 and --rate a positive number",
        args=("selftest", "{ref}", "--rate", "-1"),
        blamed="--trials",
    ),
    Bad(
        "fig-no-data",
        "command",
        "`epa fig` on a bundle without `data`",
        "a plot bundle without its data (key 'data')",
        args=("fig", "{tmp}/b.json", "--out", "{tmp}/fig"),
        setup="bundle-no-data",
        blamed="{tmp}/b.json",
    ),
    Bad(
        "fig-partial-data",
        "command",
        "`epa fig` on a bundle whose data lacks a series",
        "the ape_time bundle's data cannot be drawn: missing key 't'",
        args=("fig", "{tmp}/b.json", "--out", "{tmp}/fig"),
        setup="bundle-partial",
        blamed="{tmp}/b.json",
    ),
    Bad(
        "fig-negative-width",
        "command",
        "`epa fig --width -3`",
        "--width must be between 0 and 100 inches, not -3",
        args=("fig", "{tmp}/b.json", "--out", "{tmp}/fig", "--width", "-3"),
        setup="bundle-partial",
        blamed="--width",
    ),
    Bad(
        "traj-damaged-tf",
        "command",
        "`epa traj` reading a TF chain from a bag with a damaged (bz2) chunk",
        "topic /tf: cannot read the messages",
        args=("traj", "{est}", "--topic", "/tf", "--frames", "world", "body"),
        est_name="est.bag",
        setup="bag-damaged",
        blamed="{est}",
    ),
    Bad(
        "traj-damaged-mcap",
        "command",
        "`epa traj` listing an MCAP bag with a damaged (zstd) chunk",
        "cannot read the bag: ZstdError",
        args=("traj", "{est}"),
        est_name="est",
        setup="mcap-damaged",
        blamed="{est}",
    ),
    Bad(
        "traj-stamp-record-text",
        "command",
        "`epa traj FILE --stamp record` on a text file",
        "stamp: record is set for this source but it is not a bag",
        args=("traj", "{est}", "--stamp", "record"),
        blamed="{est}",
    ),
    Bad(
        "traj-export-tum-covariance",
        "command",
        "`epa traj BAG --topic /amcl_pose --export poses.tum`: 8 columns, covariance left out",
        "its covariance is left out (--covariance writes it)",
        args=("traj", "{est}", "--topic", "/amcl_pose", "--export", "{tmp}/poses.tum"),
        est_name="est.bag",
        setup="bag-amcl",
        ok=True,
    ),
    Bad(
        "traj-export-covariance",
        "command",
        "`--export poses.tum --covariance`: the OpenVINS 20-column layout",
        "OpenVINS layout: TUM + covariance",
        args=(
            "traj",
            "{est}",
            "--topic",
            "/amcl_pose",
            "--export",
            "{tmp}/poses.tum",
            "--covariance",
        ),
        est_name="est.bag",
        setup="bag-amcl",
        ok=True,
    ),
    Bad(
        "traj-covariance-without",
        "command",
        "`--covariance` for a trajectory without covariance",
        "--covariance: this trajectory has no covariance to write",
        args=("traj", "{est}", "--export", "{tmp}/poses.tum", "--covariance"),
        blamed="{est}",
    ),
    Bad(
        "eval-document",
        "command",
        "`epa eval --out DIR`: DIR/metrics.json holds every stage's record",
        "poses matched",
        args=("eval", "{ref}", "{est}", "--out", "{tmp}/out"),
        setup="eval-document",
        ok=True,
    ),
    Bad(
        "tum-ate-no-overlap",
        "command",
        "`epa tum-ate REF EST` where no stamps are within --max_difference",
        "Couldn't find matching timestamp pairs between groundtruth and estimated trajectory!",
        args=("tum-ate", "{ref}", "{est}"),
        est=_rows(T + 1000.0, P, Q),
        blamed="{est}",
    ),
    Bad(
        "tum-ate-not-a-number",
        "command",
        "`epa tum-ate` on a file with a value that is not a number",
        "'x' is not a number",
        args=("tum-ate", "{ref}", "{est}"),
        est=_replace_line(GOOD, 4, "1403636580.2 0.1 x 0.3 0 0 0 1"),
        blamed="{est}:5",
    ),
    Bad(
        "tum-rpe-short-line",
        "command",
        "`epa tum-rpe` on a line without a quaternion",
        "4 values, a stamp, x y z and qx qy qz qw needs 8",
        args=("tum-rpe", "{ref}", "{est}"),
        est=_replace_line(GOOD, 2, "1403636580.1 0.1 0.2 0.3"),
        blamed="{est}:3",
    ),
    Bad(
        "tum-rpe-plot-without-fixed-delta",
        "command",
        "`epa tum-rpe ... --plot F` without `--fixed_delta` (the script refuses it too)",
        "can only be used in combination with '--fixed_delta'",
        args=("tum-rpe", "{ref}", "{est}", "--plot", "{tmp}/fig.png"),
        blamed="--plot",
    ),
    Bad(
        "tum-ate-inf-max-difference",
        "command",
        "`epa tum-ate ... --max_difference inf` (every pair of poses a candidate)",
        "--max_difference must be a finite number, not inf",
        args=("tum-ate", "{ref}", "{est}", "--max_difference", "inf"),
        blamed="--max_difference",
    ),
    Bad(
        "tum-rpe-negative-max-pairs",
        "command",
        "`epa tum-rpe ... --max_pairs -5` (the script fails in random.sample)",
        "--max_pairs must be 0 (every pair) or a number of pairs, not -5",
        args=("tum-rpe", "{ref}", "{est}", "--fixed_delta", "--max_pairs", "-5"),
        blamed="--max_pairs",
    ),
    Bad(
        "tum-rpe-no-overlap",
        "command",
        "`epa tum-rpe REF EST --offset 1000`: the shifted estimate does not overlap the reference",
        "Number of overlap in the timestamps is too small",
        args=("tum-rpe", "{ref}", "{est}", "--offset", "1000"),
        blamed="{est}",
    ),
    # ------------------------------------------------------------------ workflow (snakemake)
    Bad(
        "wf-inf",
        "workflow",
        "`sync.window: .inf` in a grid config",
        "sync.window: inf is not a finite number",
        config="truth_dir: truth\nalgorithms_dir: algorithms\nsync:\n  window: .inf\n",
    ),
    Bad(
        "wf-bool-override",
        "workflow",
        "`--config 'report={\"per_case\": false}'` (Snakemake passes the string 'false')",
        "Job stats",
        config="truth_dir: truth\nalgorithms_dir: algorithms\n",
        args=("--config", 'report={"per_case": false}'),
        setup="wf-folders",
        ok=True,
    ),
    Bad(
        "wf-no-algorithms",
        "workflow",
        "`--configfile` naming no `algorithms_dir`",
        "names no algorithms_dir (the bundled example's would be used)",
        config="truth_dir: truth\n",
    ),
    Bad(
        "wf-truth-missing",
        "workflow",
        "a `truth_dir` that does not exist",
        "truth_dir 'nowhere' is not a folder; relative paths start at",
        config="truth_dir: nowhere\nalgorithms_dir: algorithms\n",
    ),
    Bad(
        "wf-schema",
        "workflow",
        "a schema error in the grid config",
        "align.method: 'sim4' is not one of",
        config="truth_dir: truth\nalgorithms_dir: algorithms\nalign:\n  method: sim4\n",
    ),
    Bad(
        "wf-list",
        "workflow",
        "a grid config that is a YAML list (Snakemake's own message, without the file)",
        "Config file must be given as JSON or YAML with keys at top level",
        config="- truth_dir\n",
        blame="none",
    ),
    Bad(
        "wf-python-tag",
        "workflow",
        "a grid config with a YAML tag that would run code (nothing runs)",
        "Config file is not valid JSON or YAML",
        config="truth_dir: !!python/object/apply:os.system ['touch HACKED']\n",
        blame="none",
    ),
    # ------------------------------------------------------------------ scoring protocols
    Bad(
        "tartanair-unequal",
        "stage",
        "TartanAir (pairs by index) on an estimate with fewer poses than the reference",
        "metrics: metrics.tartanair: TartanAir pairs poses by index, but the reference has 600"
        " poses and the estimate 590",
        est=_rows(T[:590], P[:590], Q[:590]),
        config="metrics:\n  tartanair: {enabled: true}\n",
    ),
    Bad(
        "hilti-few-control-points",
        "stage",
        "Hilti control points (every 10 s) that the estimate reaches only one of within 2 s",
        "metrics.hilti: 1 of the 3 control points have an estimate pose within 2 s; the SE3 fit"
        " needs at least 3",
        est=_rows(T[:100], P[:100], Q[:100]),
        config="metrics:\n  hilti: {enabled: true, control_every_s: 10}\n",
    ),
    Bad(
        "hilti-dense",
        "stage",
        "Hilti on a dense reference (more than 100 poses) without `control_every_s`",
        "no score: 600 control points (more than 100: a dense trajectory, which the challenge does"
        " not score; set metrics.hilti.control_every_s)",
        est=GOOD,
        config="metrics:\n  hilti: {enabled: true}\n",
        ok=True,
    ),
    # ------------------------------------------------------------------ inputs where they lie
    Bad(
        "wf-inputs-two-ways",
        "workflow",
        "folders and `inputs.sheet` both in a grid config",
        "truth_dir/algorithms_dir and inputs.sheet both name the inputs: keep one way",
        config="truth_dir: truth\nalgorithms_dir: algorithms\ninputs: {sheet: runs.tsv}\n",
        setup="wf-inputs",
    ),
    Bad(
        "wf-patterns-said",
        "workflow",
        "path patterns naming files where they lie: what each matched is printed",
        "epa: inputs.estimate 'algorithms/{algorithm}/{dataset}/{run}.txt': 1 run(s)",
        config=PATTERNS.format(estimate="algorithms/{algorithm}/{dataset}/{run}.txt"),
        setup="wf-inputs",
        ok=True,
    ),
    Bad(
        "wf-sheet-said",
        "workflow",
        "a run sheet: what it lists is printed",
        "epa: inputs.sheet runs.tsv: 1 run(s) of 1 algorithm(s) on 1 dataset(s)",
        config="inputs: {sheet: runs.tsv}\n",
        sheet=SHEET,
        setup="wf-inputs",
        ok=True,
    ),
    Bad(
        "wf-pattern-wildcard",
        "workflow",
        "a path pattern with an unknown wildcard (`{algo}`)",
        "inputs.estimate: unknown wildcard {algo} in 'algorithms/{algo}/{dataset}/{run}.txt'"
        " (known here: {algorithm}, {dataset}, {run})",
        config=PATTERNS.format(estimate="algorithms/{algo}/{dataset}/{run}.txt"),
        setup="wf-inputs",
    ),
    Bad(
        "wf-pattern-nothing",
        "workflow",
        "a path pattern that matches no file",
        "inputs.estimate: 'results/{algorithm}/{dataset}/{run}.txt' matches no file",
        config=PATTERNS.format(estimate="results/{algorithm}/{dataset}/{run}.txt"),
        setup="wf-inputs",
    ),
    Bad(
        "wf-pattern-twice",
        "workflow",
        "two estimate patterns matching the same file",
        "matched by two patterns, inputs.estimate.0 and inputs.estimate.1: make them exclusive",
        config=PATTERNS.format(
            estimate='["algorithms/{algorithm}/{dataset}/{run}.txt",'
            ' "algorithms/{algorithm}/{dataset}/run{run}.txt"]'
        ),
        setup="wf-inputs",
        blamed="algorithms/a/seq/run1.txt: ",
    ),
    Bad(
        "wf-pattern-duplicate-case",
        "workflow",
        "two files the patterns give the same case name",
        "two files for case 'a/seq/run1' (algorithms/a/seq/run1.txt, other/a/seq/run1.txt): give"
        " the patterns a {run}, or rename one",
        config=PATTERNS.format(
            estimate='["algorithms/{algorithm}/{dataset}/{run}.txt",'
            ' "other/{algorithm}/{dataset}/{run}.txt"]'
        ),
        setup="wf-inputs",
        blamed="other/a/seq/run1.txt: ",
    ),
    Bad(
        "wf-sheet-column",
        "workflow",
        "a run sheet without the `reference` column",
        "no column 'reference' (a sheet needs algorithm dataset run estimate reference, tab-separated)",
        config="inputs: {sheet: runs.tsv}\n",
        sheet="algorithm\tdataset\trun\testimate\na\tseq\trun1\talgorithms/a/seq/run1.txt\n",
        setup="wf-inputs",
        blamed="runs.tsv:1: ",
    ),
    Bad(
        "wf-sheet-duplicate",
        "workflow",
        "a run sheet listing one run twice",
        "case 'a/seq/run1' is also on line 2: one row per run",
        config="inputs: {sheet: runs.tsv}\n",
        sheet=SHEET + SHEET.splitlines(keepends=True)[1],
        setup="wf-inputs",
        blamed="runs.tsv:3: ",
    ),
    Bad(
        "wf-sheet-folder",
        "workflow",
        "a run sheet's row whose estimate is a folder",
        "estimate 'algorithms/a/seq' is a folder, not a trajectory file",
        config="inputs: {sheet: runs.tsv}\n",
        sheet=SHEET.replace("algorithms/a/seq/run1.txt", "algorithms/a/seq"),
        setup="wf-inputs",
        blamed="runs.tsv:2: ",
    ),
    Bad(
        "wf-sheet-value",
        "workflow",
        "a run sheet's row with a format the schema does not know",
        "column format: 'tum2' is not one of",
        config="inputs: {sheet: runs.tsv}\n",
        sheet=SHEET.replace("estimate\treference", "estimate\treference\tformat").replace(
            "truth/seq.txt\n", "truth/seq.txt\ttum2\n"
        ),
        setup="wf-inputs",
        blamed="runs.tsv:2: ",
    ),
]


# Replication packages and moved inputs (`epa verify`, `epa pack`): run by tests/test_package.py
# on a 4-case grid it makes, packs and moves (an archive needs a real results folder).
PACKAGE_ROWS = (
    (
        "not-an-archive",
        "`epa verify` of a file that is not an archive",
        "cannot unpack: not a tar.gz archive",
    ),
    (
        "cut-archive",
        "`epa verify` of a package cut off halfway (an incomplete download)",
        "cannot unpack: the archive is cut off",
    ),
    (
        "newer-package",
        "`epa verify` of a package made by a newer epica",
        "made by epica 99.0.0, newer than this epica",
    ),
    (
        "escaping-member",
        "`epa verify` of an archive holding a member named `../x` (it would write outside)",
        "refused: the archive holds '../x'",
    ),
    (
        "wrong-hash-input",
        "`epa verify --data DIR` where DIR holds an input with the right name and other bytes",
        "found with the right name but the wrong hash: ",
    ),
    (
        "input-not-found",
        "`epa verify --data DIR` where an input is nowhere under DIR",
        "not found under --data: ",
    ),
    (
        "tampered-package",
        "`epa verify` of a package one of whose tables was edited after packing",
        "1 files changed since packed",
    ),
    (
        "manifest-not-a-file",
        "`epa verify` of an archive whose `package.json` is a folder (or a link), not a file",
        "not an epica package: its package.json is not a file",
    ),
    (
        "unlisted-member",
        "`epa verify` of a package to which a member `results/huge.bin` was added after packing "
        "(named, never extracted; exit status 1)",
        "NOT VERIFIED: 1 archive members not listed in package.json",
    ),
)


def markdown() -> str:
    titles = {
        "eval": "Reading a file (`epa eval`, and the load stage of a grid)",
        "stage": "Stages: numbers that cannot be computed",
        "config": "Settings (`--config`, config files)",
        "grid": "Grids (discovery, one bad case among good ones)",
        "command": "Commands (`epa ape`, `rpe`, `res`, `selftest`, `fig`, `traj`, `eval --out`)",
        "workflow": "Snakemake (parse time)",
    }
    out = [
        "# Bad inputs",
        "",
        "What the tool does with inputs it cannot or must not take at face value. Each row is run by",
        "`tests/test_catalogue.py` (this page is generated from `tests/catalogue.py`, and a test checks it",
        "is current). An error is one line, `epa: error: <file>[:<line>]: <what is wrong>`, the exit status",
        "is 2 and no partial output is left; in a grid the case is marked failed in `summary.csv` and",
        "the report, and every other case finishes. A row marked *result* is read correctly and what was",
        "inferred is a warning and a note in `load.json` (or `metrics.json`, `drift.json`, the case's",
        "log). A quantity without samples is `null` in the record, with a note saying why (never NaN).",
        "",
    ]
    n = 0
    for where, title in titles.items():
        out += [f"## {title}", "", "| # | Input | Outcome |", "|---|---|---|"]
        for b in CATALOGUE:
            if b.where != where:
                continue
            n += 1
            what = f"*result*, note: `{b.expect}`" if b.ok else f"`…{b.expect}…`"
            cell = what.replace("|", "\\|")
            out.append(f"| {n} | {b.situation} | {cell} |")
        out.append("")
    out += [
        "## Replication packages and moved inputs (`epa verify`, `epa pack`)",
        "",
        "Run by `tests/test_package.py` on a grid it makes, packs and moves. A package that cannot be",
        "read is exit status 2; inputs that are not what was recorded make `epa verify` say",
        "`NOT VERIFIED` (exit status 1) without re-running anything.",
        "",
        "| # | Input | Outcome |",
        "|---|---|---|",
    ]
    for _, situation, expect in PACKAGE_ROWS:
        n += 1
        out.append(f"| {n} | {situation} | `…{expect.strip()}…` |")
    out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(markdown(), end="")
