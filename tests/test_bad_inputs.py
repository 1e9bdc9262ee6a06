"""Bad inputs found by trying the tool as a new user would: each a one-line error naming the file
(and line), never a traceback or a silently wrong number."""

import os
import stat

import numpy as np
import pytest

from epa.artifacts import files
from epa.artifacts.case import failure_of
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers import text
from epa.steps import align as alignment
from epa.workflow import chain, settings
from epa.workflow import discovery as cases
from epa.workflow.stages import load as load_stage

POSES = "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 2 1 0 0 0 0 1\n"


def read_error(tmp_path, name, content: str | bytes) -> str:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(EpaError) as err:
        text.read_trajectory(path)
    message = err.value.one_line()
    assert "\n" not in message and message.startswith(str(path))
    return message


def test_byte_order_mark_on_a_headerless_file_keeps_the_first_pose(tmp_path):
    (tmp_path / "a.txt").write_bytes(b"\xef\xbb\xbf" + POSES.encode())
    assert len(text.read_trajectory(tmp_path / "a.txt")) == 3


def test_byte_order_mark_before_a_csv_header_still_names_the_columns(tmp_path):
    # qw first in the file: read by name, not in EuRoC order
    body = "t,x,y,z,qw,qx,qy,qz\n1,0,0,0,0.5,0.5,0.5,0.5\n2,1,0,0,0.5,0.5,0.5,0.5\n"
    (tmp_path / "a.csv").write_bytes(b"\xef\xbb\xbf" + body.encode())
    traj = text.read_trajectory(tmp_path / "a.csv")
    np.testing.assert_allclose(traj.q[0], [0.5, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(traj.t, [1, 2])


def test_a_header_that_names_no_time_column_is_not_guessed(tmp_path):
    msg = read_error(tmp_path, "a.csv", "t_s,x,y,z,qx,qy,qz,qw\n1,0,0,0,0,0,0,1\n2,1,0,0,0,0,0,1\n")
    assert "cannot tell the columns from the header (t_s, x, y, z, qx, qy, qz, qw)" in msg
    assert "load.truth_format / load.estimate_format" in msg


def test_a_row_of_empty_fields_is_an_error_with_its_line(tmp_path):
    msg = read_error(tmp_path, "a.csv", "#t,x,y,z,qx,qy,qz,qw\n,,,,,,,\n" + POSES.replace(" ", ","))
    assert msg.endswith("a.csv:2: a row of empty fields")


def test_binary_data_is_named_as_such(tmp_path):
    msg = read_error(tmp_path, "a.bin", bytes(range(256)) * 4)
    assert msg.endswith("binary data, not a text trajectory file")


def test_absurd_positions_are_an_error_not_an_infinite_ate(tmp_path):
    msg = read_error(tmp_path, "a.txt", POSES.replace("2.0 1 0 0", "2.0 1e300 0 0"))
    assert ":2: position 1e+300 m is beyond 1e+09 m" in msg


def test_a_static_reference_fails_the_case_instead_of_nan_success(tmp_path):
    t = np.arange(0, 20, 0.05)
    still = Trajectory(t, np.zeros((len(t), 3)), np.tile([0, 0, 0, 1.0], (len(t), 1)))
    files.write_tum(tmp_path / "ref.txt", still)
    files.write_tum(tmp_path / "est.txt", still)
    cfg = settings.resolve(
        {"truth_dir": ".", "algorithms_dir": ".", "sync": {"estimate_offset": False}}
    )
    with pytest.raises(EpaError, match="the reference does not move"):
        chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "out", cfg)
    # the alignment meets it first: with no motion its rotation is undetermined
    assert failure_of(tmp_path / "out/05_align/transform.json").startswith(
        "align: the reference does not move"
    )


def test_first_n_error_says_how_many_poses_matched():
    traj = Trajectory(
        np.arange(50.0),
        np.random.default_rng(0).normal(size=(50, 3)),
        np.tile([0, 0, 0, 1.0], (50, 1)),
    )
    with pytest.raises(
        EpaError, match=r"needs at least 3 poses: align.first_n is 2 \(50 poses matched\)"
    ):
        alignment.fit(traj, traj, method="se3", first_n=2)


def test_a_dangling_link_is_a_failed_case_not_a_missing_one(tmp_path):
    (tmp_path / "truth").mkdir()
    (tmp_path / "truth/seq.txt").write_text(POSES)
    (tmp_path / "algs/a/seq").mkdir(parents=True)
    os.symlink(tmp_path / "gone.txt", tmp_path / "algs/a/seq/run1.txt")
    _, found = cases.discover(tmp_path / "truth", tmp_path / "algs")
    assert [c.key for c in found] == ["a/seq/run1"]
    with pytest.raises(EpaError, match="run1.txt: file not found"):
        text.read_trajectory(found[0].estimate)


@pytest.mark.parametrize(
    "content,message",
    [
        ("truth_dir: t\n", "names no algorithms_dir (the bundled example's would be used)"),
        ("- a\n- b\n", "a config must be a mapping of settings, not a list"),
        ("a: [\n", "not valid YAML"),
    ],
)
def test_user_config_files_are_checked(tmp_path, content, message):
    (tmp_path / "my.yaml").write_text(content)
    with pytest.raises(EpaError) as err:
        settings.check_user_configs([tmp_path / "my.yaml"], {})
    assert message in err.value.one_line() and str(tmp_path / "my.yaml") in err.value.one_line()


def test_folders_given_on_the_command_line_count():
    settings.check_user_configs([], {})  # no --configfile: the workflow's own config is the grid
    # --configfile my.yaml --config algorithms_dir=...: named, no error
    settings.check_user_configs([], {"truth_dir": "t", "algorithms_dir": "a"})


def test_results_follow_the_umask_not_mkstemps_0600(tmp_path):
    files.write_text(tmp_path / "x.txt", "x")
    assert stat.S_IMODE((tmp_path / "x.txt").stat().st_mode) == 0o666 & ~files._UMASK


@pytest.mark.parametrize(
    "rows,line,what",
    [
        (
            "1403636592.5 0 0 0 0 0 0 1\n1403636592600000000 1 0 0 0 0 0 1\n1403636592.7 2 0 0 0 0 0 1\n",
            2,
            "timestamp 1403636592600000000 is in nanoseconds but most stamps are seconds: the file mixes units",
        ),
        (
            "1403636592500000000 0 0 0 0 0 0 1\n1403636592.6 1 0 0 0 0 0 1\n1403636592700000000 2 0 0 0 0 0 1\n",
            2,
            "timestamp 1403636592.6 is in seconds but most stamps are nanoseconds: the file mixes units",
        ),
    ],
)
def test_a_file_mixing_second_and_nanosecond_stamps_is_refused(tmp_path, rows, line, what):
    assert f"m.txt:{line}: {what}" in read_error(tmp_path, "m.txt", rows)


def test_every_inference_is_a_note_in_load_json(tmp_path):
    # nanosecond stamps without a header saying so, and a repeated stamp sorted away
    rows = "".join(
        f"{1_700_000_000_000_000_000 + k * 50_000_000} {k * 0.1} 0 0 0 0 0 1\n" for k in range(400)
    )
    rows += rows.splitlines(keepends=True)[-1]
    (tmp_path / "est.txt").write_text(rows)
    cfg = settings.resolve({"truth_dir": ".", "algorithms_dir": ".", "load": {"unsorted": "sort"}})
    notes: list = []
    traj = text.read_trajectory(tmp_path / "est.txt", on_unsorted="sort", notes=notes)
    assert len(traj) == 400
    assert notes == [
        "format tum (8 columns)",
        "stamps read as nanoseconds (above 1e12, so not seconds)",
        "0 backward and 1 repeated timestamps: sorted, kept the first of each repeat",
    ]
    _, _, info, _ = load_stage.compute(tmp_path / "est.txt", tmp_path / "est.txt", cfg)
    assert info["est_notes"] == notes and info["ref_notes"] == notes
