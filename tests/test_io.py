import subprocess
import sys

import numpy as np
import pytest

from epa.artifacts import files
from epa.core.errors import EpaError
from epa.readers import text


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


TUM = "# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 2\n2.0 1 0 0 0 0 0 1\n3.0 2 0 0 0 0 0 1\n"


def test_tum_any_whitespace_comments_and_normalised(tmp_path):
    t = text.read_trajectory(write(tmp_path, "a.txt", TUM.replace(" ", "\t", 3)))
    assert len(t) == 3 and np.allclose(t.q[0], [0, 0, 0, 1]) and t.p[2, 0] == 2


OV_ROW = " 0.1" * 12  # an OpenVINS row's 12 covariance entries


@pytest.mark.parametrize(
    "fmt,content",
    [
        ("tum", "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n"),
        ("openvins", f"1 0 0 0 0 0 0 1{OV_ROW}\n2 1 0 0 0 0 0 1{OV_ROW}\n"),
        ("euroc", "1.5,0,0,0,1,0,0,0\n2.5,1,0,0,1,0,0,0\n"),
        ("csv", TUM),
        ("position", "1 0 0 0\n2 1 0 0\n"),
    ],
    ids=["tum", "openvins", "euroc", "named csv", "position"],
)
def test_a_trajectorys_arrays_are_its_own(tmp_path, fmt, content):
    """t and p are not column views of the file's rows, which would keep the whole table alive
    through every stage (2 x 61 MB at a million poses) and make every pass over them stride; nor
    are a stage artifact's t, p and q, read back."""
    notes: list = []
    tr = text.read_trajectory(write(tmp_path, "f.txt", content), fmt, notes=notes)
    back = files.read_tum_file(files.write_tum(tmp_path / "a.tum", tr) or tmp_path / "a.tum")
    for a in (tr.t, tr.p, back.t, back.p, back.q):
        assert a.flags.c_contiguous and a.base is None
    assert not np.shares_memory(tr.t, tr.p) and len(tr) == len(back) > 1


@pytest.mark.parametrize(
    "content,msg,line",
    [
        ("", "no data rows", None),
        ("# only\n", "no data rows", None),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", "expected 8 columns", 2),
        ("1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n", "not a number: 'x'", 2),
        ("1 0 0 0 0 0 0 1\n2 0 nan 0 0 0 0 1\n", "non-finite", 2),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n", "zero quaternion", 2),
        ("1 0 0 0 0 0 0 1\n# c\n0.5 0 0 0 0 0 0 1\n", "goes backwards", 3),
        ("1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", "repeats", 2),
    ],
)
def test_bad_input_is_one_line_with_file_and_line(tmp_path, content, msg, line):
    p = write(tmp_path, "bad.txt", content)
    with pytest.raises(EpaError) as exc:
        text.read_trajectory(p)
    s = exc.value.one_line()
    assert "\n" not in s and msg in s and s.startswith(str(p) + (f":{line}:" if line else ":"))


def test_sort_mode_drops_duplicates(tmp_path):
    p = write(
        tmp_path, "u.txt", "1 0 0 0 0 0 0 1\n3 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n3 5 0 0 0 0 0 1\n"
    )
    t = text.read_trajectory(p, on_unsorted="sort")
    assert list(t.t) == [1, 2, 3] and t.p[2, 0] == 0


def test_euroc_csv_ns_qw_first_extra_columns(data):
    t = text.read_trajectory(data / "MichaelGrupp_evo/test/data/V102_groundtruth.csv")
    assert len(t) == 16702 and 1.4e9 < t.t[0] < 1.5e9
    assert np.allclose(
        t.q[0],
        np.array([0.789985, -0.205376, 0.554528, 0.161996])
        / np.linalg.norm([0.789985, -0.205376, 0.554528, 0.161996]),
    )


def test_openvins_covariance_and_cnspy_header(data):
    a = text.read_trajectory(data / "qmy0519_open_vins-master/traj_estimate.txt")
    assert a.cov_pos.shape == (1922, 3, 3) and np.isclose(a.cov_pos[0, 0, 2], 0.0008880070)
    assert np.allclose(a.cov_pos, np.swapaxes(a.cov_pos, 1, 2))
    b = text.read_trajectory(
        data / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv"
    )
    assert len(b) == 3369 and b.cov_rot is not None


def test_orbslam3_float_ns_and_kimera(data):
    t = text.read_trajectory(data / "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_stereo.txt")
    assert 1.4e9 < t.t[0] < 1.5e9 and abs(np.median(np.diff(t.t)) - 0.05) < 1e-3
    k = text.read_trajectory(
        data
        / "MIT-SPARK_Kimera-VIO-Evaluation/evaluation/tests/test_results/V1_01_easy/Euroc/traj_vio.csv"
    )
    # ns stamps, qw first: (w, x, y, z) = (-0.0605, 0.828, 0.0575, 0.554) on row 1
    assert len(k) == 52
    assert np.allclose(k.q[0], [0.82800183, 0.05748841, 0.55447594, -0.06053841], atol=2e-5)
    assert abs(k.t[0] - 1403715274.012143) < 1e-5


def test_kitti_with_times_file_and_rate(data, tmp_path):
    t = text.read_trajectory(data / "MichaelGrupp_evo/test/data/KITTI_00_gt.txt")
    assert len(t) == 4541 and np.isclose(t.t[-1], 470.58, atol=0.01)
    (tmp_path / "k.txt").write_text(
        (data / "MichaelGrupp_evo/test/data/KITTI_00_ORB.txt").read_text()
    )
    r = text.read_trajectory(tmp_path / "k.txt", kitti_rate=5.0)
    assert np.isclose(r.t[10], 2.0)


def test_okvis_unpadded_nsec_repair(data):
    p = data / "SidSong01_modifiedOKVIS-for-benchmarking/trajectory_01.txt"
    with pytest.raises(EpaError, match="trajectory_01.txt:38: .*goes backwards"):
        text.read_trajectory(p)
    t = text.read_trajectory(p, time_unit="sec_nsec")
    assert np.all(np.diff(t.t) > 0) and abs(t.t[-1] - t.t[0] - 184.07) < 0.01


def _turning(angle: float) -> tuple[float, ...]:
    return np.sin(angle) / 2, -np.sin(angle) / 3, np.sin(angle) / 5, np.cos(angle)


COV_HEADER = files.TUM_HEADER + " " + " ".join(files.COV_HEADER) + "\n"  # OpenVINS layout
ROWS = "\n".join(f"{1e9 + k * 0.01:.6f} {k * 0.1:.4f} 0.5 0.25 0 0 0 1" for k in range(300))
FAST_PATH_CASES = {
    "header": "# t x y z qx qy qz qw\n" + ROWS + "\n",
    "crlf": ("# t x y z qx qy qz qw\n" + ROWS + "\n").replace("\n", "\r\n"),
    "tabs": ROWS.replace(" ", "\t"),
    "trailing spaces": ROWS.replace("\n", " \n"),
    "bad token": ROWS.replace("0.25 0 0 0 1\n", "0.25 0 0 x 1\n", 1),
    "short row": ROWS.replace("0.25 0 0 0 1\n", "0.25 0 0 1\n", 9),
    "nan": ROWS.replace("0.25 0 0 0 1\n", "nan 0 0 0 1\n", 3),
    "comment mid-file": ROWS.replace("0.25 0 0 0 1\n", "0.25 0 0 0 1\n# mid\n", 5),
    "repeated stamp": ROWS.replace("1000000000.010000", "1000000000.000000", 1),
    "named csv": "t,x,y,z,qx,qy,qz,qw\n" + ROWS.replace(" ", ",") + "\n",
    "utf-8 comment": "# café t x y z qx qy qz qw\n" + ROWS + "\n",
    # a parse that takes whole-number columns as integers (faster in pandas, tried and not landed:
    # docs/performance.md, the fourth round) loses -0 and may round big stamps differently
    "-0 in a whole-number column": "\n".join(
        f"{1e9 + k * 0.01:.6f} {k % 3 - 1 if k % 7 else '-0'} 0.5 0.25 0 0 0 1" for k in range(300)
    ),
    "-0 as the last token": COV_HEADER
    + "\n".join(f"{1e9 + k * 0.01:.6f} 1 2 3 0 0 0 1 1 0 0 1 0 1 1 0 0 1 0 1" for k in range(300))
    + "\n1000000003.000000 1 2 3 0 0 0 1 1 0 0 1 0 1 1 0 0 1 0 -0",
    "-00 in a whole-number column": "\n".join(
        f"{1e9 + k * 0.01:.6f} {k % 3 if k % 7 else '-00'} 0.5 0.25 0 0 0 1" for k in range(300)
    ),
    # more rows than pandas parses in one chunk: whole numbers in the first, decimals later
    "-0 in whole numbers before the parser's next chunk of decimals": "\n".join(
        f"{1e9 + k * 0.005:.6f} {k * 0.001:g} 0.5 0.25 "
        + (
            ("-0 0 0 1" if k == 10 else "0 0 0 1")
            if k < 66_000
            else " ".join(f"{v:g}" for v in _turning((k - 66_000) * 1e-4))
        )
        for k in range(70_000)
    ),
    "nanosecond stamps beyond 2**53": "\n".join(
        f"{1403636579763555584 + k * 10_000_001} {k * 0.1:.4f} 0.5 0.25 0 0 0 1" for k in range(300)
    ),
}


# what pyarrow's reader takes or refuses differently from pandas' and numpy's: each file must read
# (or fail, on the same line with the same words) as the general path does
FAST_PATH_CASES |= {
    "nan(1), which pyarrow alone reads (as NaN)": ROWS.replace(" 0 0 0 1\n", " 0 nan(1) 0 1\n", 4),
    "overflow to inf": ROWS.replace("0.25 0 0 0 1\n", "1e500 0 0 0 1\n", 2),
    "empty field": ROWS.replace("0.25 0 0 0 1\n", "0.25  0 0 1\n", 6),
    "quoted number": ROWS.replace("0.25 0 0 0 1\n", '0.25 "0" 0 0 1\n', 3),
    "NA": ROWS.replace("0.25 0 0 0 1\n", "0.25 NA 0 0 1\n", 3),
    "blank lines": ROWS.replace("0.25 0 0 0 1\n", "0.25 0 0 0 1\n\n\n", 7),
    "a blank line of spaces": ROWS.replace("0.25 0 0 0 1\n", "0.25 0 0 0 1\n   \n", 7),
    "no final newline": ROWS,
    "lone CR line ends": ROWS.replace("\n", "\r"),
    "leading space": ROWS.replace("\n", "\n ", 5),
    "two spaces": ROWS.replace(" 0.5 ", "  0.5 "),
    "a tab inside": ROWS.replace(" 0.5 ", " \t0.5 ", 3),
    "a header and no rows": "# t x y z qx qy qz qw\n\n",
    "comma and space": ROWS.replace(" ", ", "),
    "semicolons": "t;x;y;z;qx;qy;qz;qw\n" + ROWS.replace(" ", ";"),
    "a row of spaces among commas": ROWS.replace(" ", ",").replace(
        "\n", "\n" + ROWS[:40] + "\n", 1
    ),
    "a trailing comma": ROWS.replace(" ", ",").replace("\n", ",\n", 3),
    "an empty field among commas": ROWS.replace(" ", ",").replace(",0,0,1\n", ",,0,1\n", 3),
    "a comment among commas": ROWS.replace(" ", ",").replace(",1\n", ",1\n# here\n", 5),
    "a csv with quotes": "t,x,y,z,qx,qy,qz,qw\n"
    + ROWS.replace(" ", ",").replace(",0,1\n", ',"0",1\n', 2),
}
# parsers in C, as text.parsers_for may choose them: pyarrow's, pandas', both in turn
PARSER_SETS = [("arrow",), ("pandas",), ("arrow", "pandas")]


@pytest.mark.parametrize("parsers", PARSER_SETS, ids="+".join)
@pytest.mark.parametrize("name", sorted(FAST_PATH_CASES))
def test_c_parser_fast_path_reads_as_the_general_path(tmp_path, monkeypatch, name, parsers):
    """Asked for, a file goes whole to a parser in C without its body being decoded
    (text._read_in_c); the trajectory, the notes and every error (with its line) are the general
    reader's, and the line-by-line reader's, bit for bit."""
    for parser in parsers:
        pytest.importorskip({"arrow": "pyarrow", "pandas": "pandas"}[parser])
    monkeypatch.setattr(text, "parsers_for", lambda size, pandas_min_bytes: parsers)
    path = tmp_path / "f.txt"
    path.write_bytes(FAST_PATH_CASES[name].encode())

    def read():
        notes: list = []
        try:
            tr = text.read_trajectory(path, notes=notes)
        except EpaError as exc:
            return str(exc)
        covariance = [c.tobytes() for c in (tr.cov_rot, tr.cov_pos) if c is not None]
        return [a.tobytes() for a in (tr.t, tr.p, tr.q)] + covariance + notes

    in_c, real = [], text._read_in_c
    monkeypatch.setattr(text, "_read_in_c", lambda *args: in_c.append(1) or real(*args))
    fast = read()
    assert in_c  # the C parser had the file
    monkeypatch.setattr(text, "_read_in_c", lambda *args: (None, False))
    assert read() == fast
    monkeypatch.setattr(text, "_c_parser_rows", lambda *args: None)
    assert read() == fast  # and the line-by-line reader's


def _tricky_numbers(rng, n: int) -> np.ndarray:
    """Text of n rows of 8 numbers a parser may round differently: shortest round-trip reprs over
    the whole exponent range (subnormals included), 17- and 20-digit mantissas, exponents with
    signs and leading zeros, -0, integers beyond 2**53, leading zeros and a leading '+'."""
    bits = rng.integers(0, 2**63 - 2**52, size=(n, 8), dtype=np.int64)
    values = bits.view(np.float64) * rng.choice([-1.0, 1.0], size=(n, 8))
    tokens = np.array([repr(float(v)) for v in values.ravel()], dtype=object).reshape(n, 8)
    close = rng.normal(size=(n, 8)) * 10.0 ** rng.integers(-30, 30, size=(n, 8))
    forms = [
        lambda v, k: f"{v:.16e}",  # 17 significant digits
        lambda v, k: f"{v:.19e}".replace("e", "E"),  # 20, and a capital E
        lambda v, k: f"{v:.16e}".replace("e-", "e-00").replace("e+", "e+0"),
        lambda v, k: "-0" if k % 2 else "-0.0",
        lambda v, k: str(int(2**53 + k * 12345)),
        lambda v, k: "+" + f"{abs(v):.12f}",
        lambda v, k: "000" + f"{abs(v):.17g}".lstrip("-"),
        lambda v, k: f"{v:.25g}",
    ]
    pick = rng.integers(0, len(forms) + 2, size=(n, 8))
    for (i, j), f in np.ndenumerate(pick):
        if f < len(forms):
            tokens[i, j] = forms[f](close[i, j], i)
    return tokens


@pytest.mark.parametrize("sep", [" ", ","])
def test_every_parser_gives_the_same_doubles(tmp_path, monkeypatch, sep):
    """pyarrow's reader, pandas' C parser (whitespace only) and numpy's loadtxt (the parser chosen
    by a file's size and what is installed) give the same doubles, bit for bit, on numbers any of
    them might round differently; and with pyarrow missing, pandas takes its files."""
    pytest.importorskip("pyarrow")
    pytest.importorskip("pandas")
    rng = np.random.default_rng(34)
    path = tmp_path / "tricky.txt"
    tokens = _tricky_numbers(rng, 40_000)
    path.write_text("\n".join(sep.join(row) for row in tokens) + "\n")
    expected = np.array([[float(t) for t in row] for row in tokens])
    used = []
    for name in ("arrow_rows", "_pandas_rows"):
        real = getattr(text, name)
        spy = lambda *a, real=real, name=name: used.append(name) or real(*a)  # noqa: E731
        monkeypatch.setattr(text, name, spy)
    for parsers in [*PARSER_SETS, ()]:
        used.clear()
        monkeypatch.setattr(text, "parsers_for", lambda size, least, parsers=parsers: parsers)
        rows = text.read_table(path).rows
        takes = [p for p in parsers if p == "arrow" or sep == " "][:1]  # the one that parsed it
        assert used == [{"arrow": "arrow_rows", "pandas": "_pandas_rows"}[p] for p in takes]
        assert rows.flags.c_contiguous and rows.tobytes() == expected.tobytes(), parsers
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as if not installed: pandas parses
    used.clear()
    monkeypatch.setattr(text, "parsers_for", lambda size, least: ("arrow", "pandas"))
    assert text.read_table(path).rows.tobytes() == expected.tobytes()
    assert used == ["arrow_rows", "_pandas_rows"][: 2 if sep == " " else 1]


def test_the_parser_is_chosen_by_size_and_what_is_imported(monkeypatch):
    """pyarrow from 2 MB on (its import repaid), from 32 KB on once epa imported it; pandas from
    the caller's size on; below both, numpy's loadtxt."""
    monkeypatch.setitem(text._ARROW, "installed", True)
    monkeypatch.delitem(text._ARROW, "imported", raising=False)
    assert text.parsers_for(text.ARROW_MIN_BYTES - 1, text.C_PARSER_MIN_BYTES) == ()
    assert text.parsers_for(text.ARROW_MIN_BYTES, text.C_PARSER_MIN_BYTES) == ("arrow",)
    assert text.parsers_for(text.C_PARSER_MIN_BYTES, text.C_PARSER_MIN_BYTES) == ("arrow", "pandas")
    assert text.parsers_for(1000, 0) == ("pandas",)
    monkeypatch.setitem(text._ARROW, "imported", True)
    assert text.parsers_for(text.ARROW_IMPORTED_MIN_BYTES, text.C_PARSER_MIN_BYTES) == ("arrow",)
    monkeypatch.setitem(text._ARROW, "installed", False)
    assert text.parsers_for(text.C_PARSER_MIN_BYTES - 1, text.C_PARSER_MIN_BYTES) == ()


def test_artifact_text_is_np_savetxt_byte_for_byte():
    """Stage artifacts are written by files.savetxt (a block of rows formatted at a time): the bytes
    must be np.savetxt's with %.17g, including -0, nan, inf and integers at the edge of exact float
    representation."""
    import io

    rng = np.random.default_rng(7)
    edge = [0.0, -0.0, 1.0, -3.0, 2.0**53, 2.0**53 - 1, -(2.0**53 - 1), 1e16, 1e17, np.nan, np.inf]
    for _ in range(300):
        n, m = rng.integers(1, 40), rng.integers(1, 6)
        table = rng.normal(size=(n, m)) * 10.0 ** rng.integers(-5, 18)
        for k in range(m):
            kind = rng.integers(0, 5)
            if kind == 0:
                table[:, k] = np.round(table[:, k])
            elif kind == 1:
                table[:, k] = rng.integers(-1000, 1000, n)
            elif kind == 2:
                table[:, k] = rng.choice(edge, n)
        for kw in ({}, {"delimiter": ",", "header": "a,b", "comments": ""}):
            expected = io.BytesIO()
            np.savetxt(expected, table, fmt="%.17g", **kw)
            written = io.StringIO()
            files.savetxt(written, table, **kw)
            assert written.getvalue() == expected.getvalue().decode()


def test_artifact_rows_by_pyarrow_read_back_as_the_same_doubles(tmp_path):
    """Stage artifacts (write_tum, write_csv) are written by pyarrow's CSV writer where installed:
    every number the shortest text of its double. Each parser the readers use (pyarrow's, pandas' C
    parser, np.loadtxt) must read back the very doubles, -0, nan, inf, subnormals and the extremes
    included; a float32 column is written as its double."""
    pytest.importorskip("pyarrow")
    rng = np.random.default_rng(3)
    edge = [0.0, -0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 2.0**53 + 2, 0.1]
    table = rng.normal(size=(3000, 5)) * 10.0 ** rng.integers(-300, 300, size=(3000, 5))
    table[:, 1] = np.round(rng.normal(size=3000) * 1e3, 3)  # short decimals
    table[:40, 2] = rng.choice([*edge, np.nan, np.inf, -np.inf], 40)
    table[:, 3] = rng.normal(size=3000).astype(np.float32)
    files.write_csv(tmp_path / "a.csv", {f"c{k}": table[:, k] for k in range(5)})
    text_ = (tmp_path / "a.csv").read_text()
    assert text_.startswith("c0,c1,c2,c3,c4\n") and "0.10000000000000001" not in text_
    body = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)
    got = files.read_csv(tmp_path / "a.csv")  # pyarrow declines the non-finite: another parser
    for rows in (body, np.column_stack([got[f"c{k}"] for k in range(5)])):
        assert np.array_equal(rows, table, equal_nan=True)
        assert np.array_equal(np.signbit(rows), np.signbit(table))
    finite = np.isfinite(table).all(axis=1)
    files.write_csv(tmp_path / "b.csv", {f"c{k}": table[finite, k] for k in range(5)})
    got = files.read_csv(tmp_path / "b.csv")  # pyarrow's parse
    assert np.array_equal(np.column_stack([got[f"c{k}"] for k in range(5)]), table[finite])
    files.write_csv(tmp_path / "c.csv", {"a": np.zeros(0), "b": np.zeros(0)})
    assert (tmp_path / "c.csv").read_text() == "a,b\n"
    f32 = np.float32(0.1)
    rows = files.exact_rows(np.array([[f32]], dtype=np.float32), " ")
    assert rows is not None and b"".join(rows) == repr(float(f32)).encode() + b"\n"
    big = rng.normal(size=(2 * files.ARROW_ROWS_PER_BLOCK + 5, 2))  # written in three blocks
    files.write_csv(tmp_path / "d.csv", {"a": big[:, 0], "b": big[:, 1]})
    got = files.read_csv(tmp_path / "d.csv")
    assert np.array_equal(np.column_stack([got["a"], got["b"]]), big)


def test_writing_an_artifact_does_not_import_pandas(tmp_path):
    """pyarrow's pa.table and pa.array import pandas to check for a frame (0.25-0.5 s): a process
    that writes artifacts without having pandas (the tables rule, `epa eval --artifacts`) must not
    pay it. In a new process, as those are."""
    pytest.importorskip("pyarrow")
    code = (
        "import sys, numpy as np; from epa.artifacts import files;"
        f" files.write_csv({str(tmp_path / 'a.csv')!r}, {{'a': np.arange(3.0), 'b': np.ones(3)}});"
        " print('pandas' in sys.modules, 'pyarrow' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True"]
    assert (tmp_path / "a.csv").read_text() == "a,b\n0,1\n1,1\n2,1\n"


def test_artifact_numbers_keep_negative_zero_next_to_a_missing_value(tmp_path):
    """An artifact column of whole numbers with -0 and a missing value: files._numbers (pandas' C
    parser) must give np.loadtxt's doubles, sign of zero included (a parse that infers the column
    as integers, then float because of the missing value, would give +0)."""
    pytest.importorskip("pandas")
    table = np.zeros((5000, 3))
    table[:, 0] = np.arange(5000) * 0.1 + 0.05
    table[:, 1] = np.arange(5000) % 4
    table[7, 1], table[9, 1] = -0.0, np.nan
    table[:, 2] = np.round(np.random.default_rng(0).normal(size=5000), 3)
    path = tmp_path / "a.csv"
    files.write_csv(path, {"a": table[:, 0], "b": table[:, 1], "c": table[:, 2]})
    assert path.stat().st_size >= files.PANDAS_FROM_BYTES  # the C parser's path
    read = files._numbers(path, ",", 1)
    expected = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    assert read.tobytes() == expected.tobytes() and np.signbit(read[7, 1])


@pytest.mark.parametrize("parsers", [*PARSER_SETS, ()], ids=lambda p: "+".join(p) or "loadtxt")
def test_artifacts_read_back_alike_by_every_parser(tmp_path, monkeypatch, parsers):
    """A stage's TUM and CSV artifacts read back (files._numbers) by pyarrow's reader, pandas' C
    parser or loadtxt: the same doubles, bit for bit (-0, 17 digits, a NaN, a header and no rows)."""
    from epa.core import runtime
    from epa.core.trajectory import Trajectory

    for parser in parsers:
        pytest.importorskip({"arrow": "pyarrow", "pandas": "pandas"}[parser])
    rng = np.random.default_rng(5)
    n = 3000
    q = rng.normal(size=(n, 4))
    traj = Trajectory(1e9 + np.arange(n) * 0.005, rng.normal(size=(n, 3)) * 1e3, q)
    traj.p[5] = -0.0
    files.write_tum(tmp_path / "a.tum", traj)
    columns = {
        "i": np.arange(n) % 4 * 1.0,
        "x": rng.normal(size=n) * 10.0 ** rng.integers(-9, 9, n),
    }
    columns["i"][7] = -0.0
    files.write_csv(tmp_path / "a.csv", columns)
    files.write_csv(tmp_path / "nan.csv", {**columns, "y": np.where(np.arange(n) == 9, np.nan, 1)})
    files.write_csv(tmp_path / "empty.csv", {"a": np.zeros(0), "b": np.zeros(0)})
    expected = {
        name: np.loadtxt(tmp_path / name, delimiter=delimiter, ndmin=2, skiprows=skip)
        for name, delimiter, skip in (("a.tum", None, 0), ("a.csv", ",", 1), ("nan.csv", ",", 1))
    }
    monkeypatch.setattr(text, "parsers_for", lambda size, least: parsers)
    runtime.use_pandas_parser("pandas" in parsers)
    try:
        for name, rows in expected.items():
            delimiter, skip = (" ", 0) if name.endswith(".tum") else (",", 1)
            assert files._numbers(tmp_path / name, delimiter, skip).tobytes() == rows.tobytes()
        assert files.read_tum_file(tmp_path / "a.tum").p.tobytes() == traj.p.tobytes()
        assert np.signbit(files.read_csv(tmp_path / "a.csv")["i"][7])
        assert files.read_csv(tmp_path / "empty.csv")["a"].shape == (0,)
    finally:
        runtime.use_pandas_parser(False)


@pytest.mark.parametrize("content", [TUM, "1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n", ""])
def test_a_table_read_ahead_reads_and_fails_as_the_reader(tmp_path, content):
    """`epa eval` parses the estimate in a second thread (text.TableAhead): the same trajectory,
    or the same error, raised where the reader would have raised it."""
    p = write(tmp_path, "a.txt", content)
    try:
        here = text.read_trajectory(p)
    except EpaError as exc:
        with pytest.raises(EpaError) as ahead:
            text.read_trajectory(p, table=text.TableAhead(p))
        assert ahead.value.one_line() == exc.one_line()
        return
    there = text.read_trajectory(p, table=text.TableAhead(p))
    assert all(np.array_equal(getattr(here, k), getattr(there, k)) for k in ("t", "p", "q"))


def test_upper_to_full_is_the_gather_layout_and_all():
    """The covariance columns' gather: the values and the strides of numpy's fancy index (sums over
    the poses depend on the layout)."""
    rows = np.random.default_rng(2).normal(size=(50, 20))
    idx = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
    for u, columns in (
        (rows[:, 8:14], None),
        (rows, [14, 15, 16, 17, 18, 19]),
        (rows[:0], [3] * 6),
    ):
        full = text.upper_to_full(u, columns)
        gathered = u[:, idx if columns is None else np.asarray(columns)[idx]]
        assert np.array_equal(full, gathered) and full.strides == gathered.strides
        assert np.array_equal(full.sum(axis=0), gathered.sum(axis=0))


def test_the_parser_follows_the_size_and_epas_own_import_not_sys_modules(monkeypatch):
    """pyarrow imported by someone else (a notebook's pandas) changes nothing; once epa has
    imported it for a large file, it is worth its cost from ARROW_IMPORTED_MIN_BYTES on."""
    import types

    size, never = 100_000, 10**12  # between the two thresholds; pandas out of the way
    monkeypatch.setattr(text, "_ARROW", {"installed": True})
    monkeypatch.setitem(sys.modules, "pyarrow", types.ModuleType("pyarrow"))
    assert text.ARROW_IMPORTED_MIN_BYTES < size < text.ARROW_MIN_BYTES
    assert text.parsers_for(size, never) == ()
    assert text.parsers_for(text.ARROW_MIN_BYTES, never) == ("arrow",)
    monkeypatch.setattr(text, "_ARROW", {"installed": True, "imported": True})
    assert text.parsers_for(size, never) == ("arrow",)
    assert text.parsers_for(text.ARROW_IMPORTED_MIN_BYTES - 1, never) == ()
    monkeypatch.setattr(text, "_ARROW", {"installed": False, "imported": True})
    assert text.parsers_for(text.ARROW_MIN_BYTES, never) == ()
