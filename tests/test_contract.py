"""The numeric contract (epa.outputs.contract, docs/reproducibility.md): what passes as the same
result on another CPU and what fails, on hand-made texts whose verdict follows from the rules."""

import json

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from epa.outputs import contract
from epa.outputs.contract import Verdict

TUM_HEAD = "# t x y z qx qy qz qw pr11 pr12 pr13 pr22 pr23 pr33 pt11 pt12 pt13 pt22 pt23 pt33"


def _tum(rows) -> str:
    return TUM_HEAD + "\n" + "\n".join(" ".join(f"{v:.17g}" for v in r) for r in rows) + "\n"


def _cov_row(t=1700000000.5, y=2.0, qx=1e-14, pt12=7e-12):
    """A TUM row with covariance: a pose, its rotation block, its position block."""
    pose = [t, 1.0, y, 3.0, qx, 0.0, 0.0, 1.0]
    return pose + [3e-6, 0, 0, 3e-6, 0, 3e-6] + [2.5e-5, pt12, 0.0, 2.5e-5, 0.0, 2.5e-5]


# ----------------------------------------------------------------------------- printed outputs
def test_the_same_text_is_identical():
    assert (
        contract.compare_printed("t.txt", "ATE 0.089\n", "ATE 0.089\n").verdict == Verdict.IDENTICAL
    )


def test_a_digit_flipped_at_a_rounding_boundary_is_reported_and_passes():
    got = contract.compare_printed("t.tex", "a & 0.100 & 7 \\\\\n", "a & 0.099 & 7 \\\\\n")
    assert got.verdict == Verdict.ROUNDING and got.ok
    assert got.worst.where == "line 1" and (got.worst.a, got.worst.b) == ("0.100", "0.099")
    # %g drops trailing zeros: 100 against 99.9999999 is one unit of the finer one
    assert contract.compare_printed("s.csv", "x\n100\n", "x\n99.9999999\n").ok
    # a negative zero from a value that rounds to zero either way
    assert contract.compare_printed("t.txt", "-0.000\n", "0.000\n").verdict == Verdict.ROUNDING
    # one unit exactly, which binary floating point made 1.0000000502e-13 against a unit of 1e-13
    flip = contract.compare_printed("s.csv", "x\n-3.38073579e-05\n", "x\n-3.3807358e-05\n")
    assert flip.verdict == Verdict.ROUNDING and flip.worst.where == "line 2, column x"


def test_a_printed_change_beyond_one_unit_or_in_a_count_or_a_word_differs():
    two_units = contract.compare_printed("t.txt", "0.100\n", "0.098\n")
    assert two_units.verdict == Verdict.DIFFERS and two_units.worst.diff > two_units.worst.tol
    assert contract.compare_printed("c.tex", "1--2\n", "2--1\n").verdict == Verdict.DIFFERS
    assert contract.compare_printed("t.txt", "ok 0.1\n", "failed 0.1\n").verdict == Verdict.DIFFERS
    assert contract.compare_printed("t.txt", "a\nb\n", "a\n").verdict == Verdict.DIFFERS
    # words with digits in them are words: run1 against run2 is no rounding
    assert contract.compare_printed("t.txt", "run1 0.1\n", "run2 0.1\n").verdict == Verdict.DIFFERS


def test_a_csv_flip_is_named_by_row_and_column():
    a = "algorithm,ate_trans_rmse_m\nvio,0.0576048617\n"
    b = "algorithm,ate_trans_rmse_m\nvio,0.0576048618\n"
    got = contract.compare_printed("summary.csv", a, b)
    assert got.verdict == Verdict.ROUNDING
    assert got.worst.where == "line 2, column ate_trans_rmse_m"


# ----------------------------------------------------------------------------- JSON records
def _json(**kw) -> str:
    return json.dumps(kw)


def test_json_numbers_within_the_relative_tolerance_pass_and_beyond_it_fail():
    a = _json(ate={"rmse": 0.0576048617, "n": 2980}, offset_s=-3.380735793765787e-05)
    b = _json(ate={"rmse": 0.0576048617 * (1 + 2e-12), "n": 2980}, offset_s=-3.3807357938513915e-05)
    got = contract.compare_record("metrics.json", a, b)
    assert got.verdict == Verdict.WITHIN and got.worst.diff <= got.worst.tol
    sixth_digit = _json(ate={"rmse": 0.0576048617 * (1 + 1e-5), "n": 2980}, offset_s=-3.38e-05)
    bad = contract.compare_record("metrics.json", a, sixth_digit)
    assert bad.verdict == Verdict.DIFFERS and bad.worst.where == "$.ate.rmse"
    one_in_a_million = _json(ate={"rmse": 0.0576048617 * (1 + 1e-6), "n": 2980}, offset_s=-3.38e-05)
    assert contract.compare_record("m.json", a, one_in_a_million).verdict == Verdict.DIFFERS


def test_a_component_that_is_zero_up_to_rounding_takes_its_arrays_scale():
    a = _json(q=[0.9999999999, 2.294493107808379e-14, 0.0, 1e-5])
    b = _json(q=[0.9999999999, 2.2941063606957197e-14, 0.0, 1e-5])  # 1.7e-4 relative
    assert contract.compare_record("transform.json", a, b).verdict == Verdict.WITHIN
    # a matrix is one array: an off-diagonal entry is measured against the diagonal
    m = [[3e-6, 4.6967906348378915e-11], [4.6967906348378915e-11, 3e-6]]
    m2 = [[3e-6, 4.6967906355604235e-11], [4.6967906355604235e-11, 3e-6]]
    assert contract.compare_record("c.json", _json(cov=m), _json(cov=m2)).ok


def test_statistics_of_one_quantity_share_its_scale():
    """rpg's relative rotation comes from arccos near 1: its min of 0.006 deg moves by 1e-10 deg
    between CPU paths, which is measured against the max of the same statistics."""
    a = _json(rot={"min": 0.0059996331980796055, "max": 0.5, "mean": 0.1, "num_samples": 10})
    b = _json(rot={"min": 0.005999633319575272, "max": 0.5, "mean": 0.1, "num_samples": 10})
    assert contract.compare_record("stats.json", a, b).verdict == Verdict.WITHIN
    c = _json(rot={"min": 0.0059996331980796055, "max": 0.5, "mean": 0.1, "num_samples": 11})
    assert contract.compare_record("stats.json", a, c).verdict == Verdict.DIFFERS
    # the same change on a lone named quantity is no rounding
    lone = contract.compare_record(
        "x.json", _json(rot_min=0.0059996331980796), _json(rot_min=0.0059996333)
    )
    assert lone.verdict == Verdict.DIFFERS


def test_json_structure_strings_and_counts_must_be_equal():
    base = _json(status="trusted", n=3, notes=["a"], v=None)
    assert (
        contract.compare_record(
            "r.json", base, _json(status="uncertain", n=3, notes=["a"], v=None)
        ).worst.where
        == "$.status"
    )
    assert (
        contract.compare_record(
            "r.json", base, _json(status="trusted", n=4, notes=["a"], v=None)
        ).verdict
        == Verdict.DIFFERS
    )
    missing = contract.compare_record("r.json", base, _json(status="trusted", n=3, notes=["a"]))
    assert missing.verdict == Verdict.DIFFERS and missing.worst.where == "$.v"
    assert (
        contract.compare_record(
            "r.json", base, _json(status="trusted", n=3, notes=["a", "b"], v=None)
        ).verdict
        == Verdict.DIFFERS
    )
    assert (
        contract.compare_record(
            "r.json", base, _json(status="trusted", n=3, notes=["a"], v=0.0)
        ).verdict
        == Verdict.DIFFERS
    )


def test_stamps_are_absolute():
    t = 1700000000.5
    a = _json(est_span_s=[t, t + 149.0])
    ulp = _json(est_span_s=[np.nextafter(t, 2e9), t + 149.0])
    assert contract.compare_record("load.json", a, ulp).verdict == Verdict.WITHIN
    # 10 us (a float64 stamp near 1.7e9 s resolves 0.24 us; 1e-8 relative would be 17 s)
    later = _json(est_span_s=[t + 1e-5, t + 149.0])
    assert contract.compare_record("load.json", a, later).verdict == Verdict.DIFFERS


def test_yaml_records_are_compared_as_numbers():
    a = "rot:\n  max: 179.88753538721286\n  min: 0.01\n  num_samples: 2980\n"
    b = "rot:\n  max: 179.8875353922561\n  min: 0.01\n  num_samples: 2980\n"
    assert contract.compare_record("absolute_err_statistics.yaml", a, b).verdict == Verdict.WITHIN


# ----------------------------------------------------------------------------- arrays
def test_arrays_compare_by_column_with_stamps_and_covariance_blocks():
    a = _tum([_cov_row(), _cov_row(t=1700000000.55, y=2.5, qx=0.15)])
    b = _tum(
        [
            # zero up to rounding against their column's 0.15 and their block's 2.5e-5
            _cov_row(qx=2.3e-14, pt12=7.0000057e-12),
            _cov_row(t=np.nextafter(1700000000.55, 2e9), y=2.5 * (1 + 3e-15), qx=0.15),
        ]
    )
    got = contract.compare_record("aligned.tum", a, b)
    assert got.verdict == Verdict.WITHIN, got.line()
    moved = _tum([_cov_row(), _cov_row(t=1700000000.55, y=2.5 * (1 + 1e-6))])
    bad = contract.compare_record("aligned.tum", a, moved)
    assert bad.verdict == Verdict.DIFFERS and bad.worst.where == "row 2, column y"
    late = _tum([_cov_row(), _cov_row(t=1700000000.55 + 1e-5, y=2.5)])
    assert contract.compare_record("aligned.tum", a, late).worst.where == "row 2, column t"


def test_csv_words_rows_and_headers_must_be_equal():
    a = "t,valid,note\n1.5,1,ok\n2.5,0,\n"
    assert (
        contract.compare_record("p.csv", a, a.replace("ok", "no")).worst.where
        == "row 1, column note"
    )
    assert contract.compare_record("p.csv", a, a + "3.5,1,ok\n").verdict == Verdict.DIFFERS
    assert contract.compare_record("p.csv", a, a.replace("valid", "good")).worst.where == "header"
    assert contract.compare_record("p.csv", a, a.replace("0,\n", "1,\n")).verdict == Verdict.DIFFERS
    assert contract.compare_record("p.csv", "x\nnan\n", "x\nnan\n").verdict == Verdict.IDENTICAL
    assert contract.compare_record("p.csv", "x,y\nnan,1\n", "x,y\n0,1\n").verdict == Verdict.DIFFERS


# ----------------------------------------------------------------------------- properties
finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False).filter(lambda v: abs(v) > 1e-3)


@settings(max_examples=200, deadline=None)
@given(st.lists(finite, min_size=1, max_size=30), st.integers(min_value=-64, max_value=64))
def test_last_bit_noise_passes_and_a_change_of_1e_6_fails(values, ulps):
    """Any column moved by up to 64 units in the last place passes; scaling one value that is at
    least a hundredth of its column's largest by 1 + 1e-6 fails."""
    x = np.array(values)
    noisy = x + ulps * np.spacing(x)
    text = "v\n" + "\n".join(f"{v:.17g}" for v in x) + "\n"
    moved_text = "v\n" + "\n".join(f"{v:.17g}" for v in noisy) + "\n"
    assert contract.compare_record("a.csv", text, moved_text).ok
    k = int(np.argmax(np.abs(x)))
    changed = x.copy()
    changed[k] *= 1 + 1e-6
    changed_text = "v\n" + "\n".join(f"{v:.17g}" for v in changed) + "\n"
    got = contract.compare_record("a.csv", text, changed_text)
    assert got.verdict == Verdict.DIFFERS and got.worst.where == f"row {k + 1}, column v"


def test_a_column_or_list_that_is_zero_up_to_rounding_has_the_absolute_floor():
    """Values that are all zero up to rounding (1e-17 against each other: no scale of their own)
    pass within 1e-12 in their unit; a change of 1e-11 does not."""
    tiny_a = "t,x\n1,1.3877787807814457e-17\n2,-2.7755575615628914e-17\n"
    tiny_b = "t,x\n1,-4.163336342344337e-17\n2,5.551115123125783e-17\n"
    got = contract.compare_record("a.csv", tiny_a, tiny_b)
    assert got.verdict == Verdict.WITHIN and got.worst.tol == contract.FLOOR_ATOL
    moved = "t,x\n1,1e-11\n2,-2.7755575615628914e-17\n"
    assert contract.compare_record("a.csv", tiny_a, moved).verdict == Verdict.DIFFERS
    lists = contract.compare_record("c.json", _json(v=[1e-17, -3e-17]), _json(v=[-2e-17, 4e-17]))
    assert lists.verdict == Verdict.WITHIN
    assert not contract.compare_record("c.json", _json(v=[1e-17, 0.0]), _json(v=[2e-12, 0.0])).ok
