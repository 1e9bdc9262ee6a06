"""The Chinese report's reasons (epa.outputs.zh_reasons): every reason template the code writes,
made by the code itself, is said in Chinese with its numbers unchanged and no English word left
but units, keys and names; an unknown clause passes through. Both reports give the fail segments
in seconds after the first matched pose, the zero of the figures' time axes."""

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import smooth_path

from epa import simulate
from epa.artifacts import files
from epa.artifacts.case import CaseFolder
from epa.core.trajectory import Trajectory, position_only
from epa.metrics import consistency, efficiency, sim3_check
from epa.outputs import case_report, figures, zh_reasons
from epa.outputs import report as report_module
from epa.steps import align, calibrate, plan, sync
from epa.workflow import chain, settings
from epa.workflow.stages import calibrate as calibrate_stage
from epa.workflow.stages import drift as drift_stage
from epa.workflow.stages import sync as sync_stage

SRC = Path(__file__).resolve().parents[1] / "src/epa"

# what a Chinese reason may still hold in Latin letters: units, names of methods and quantities
ALLOWED = {"m", "s", "ms", "deg", "rad", "ln", "ATE", "RMSE", "SE3", "Sim3", "NEES", "ov_eval"}
ALLOWED |= {"rpg"}


def latin_words(text: str) -> set[str]:
    """The Latin words of a text, keys in backticks and numbers (1e-05, inf) aside."""
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(rf"(?<![A-Za-z_]){zh_reasons.NUM}(?![A-Za-z_])", "", text)
    return set(re.findall(r"[A-Za-z_][A-Za-z_0-9]*", text))


def numbers(text: str) -> list[str]:
    """The numbers of a text as printed, in order (those inside a name such as SE3 aside)."""
    return re.findall(rf"(?<![A-Za-z_\d.]){zh_reasons.NUM}(?![A-Za-z_])", text)


def _posonly(traj: Trajectory) -> Trajectory:
    return Trajectory(traj.t, traj.p, np.full((len(traj), 4), np.nan))


def _peak(k: int, value: float, ratio: float, best_beyond: float) -> sync._Peak:
    """A correlation peak within a ±10-step window, as _windowed_peak finds one."""
    lags = np.arange(-10, 11)
    return sync._Peak(
        lags=lags,
        corr=np.zeros(len(lags)),
        kmax=10,
        k=k,
        value=value,
        estimated=float(lags[k]) * 0.01,
        left=max(k - 2, 0),
        right=min(k + 2, 20),
        ratio=ratio,
        best_beyond=best_beyond,
        lag_beyond=1.234 if best_beyond > 0 else None,
        span_b=(0, 100),
    )


def _verdict(scale: bool, **info) -> calibrate.Extrinsic:
    base = {
        "rotation_residual_rms_deg": 0.1,
        "translation_residual_rms_m": 0.01,
        "rotation_unobservable_axes": [],
        "translation_unobservable_directions": [],
        "scale_unobservable": False,
        "scale_std": 0.001,
        "rotation_std_deg": [0.1, 0.1, 0.1],
        "translation_std_m": [0.001, 0.001, 0.001],
    }
    ext = calibrate.Extrinsic(scale=1.0, info={**base, **info})
    return calibrate._verdict(ext, scale, 2.0, 0.2, 1.0, 0.05, 0.02)


def every_reason() -> list[str]:
    """Every reason template the code writes into a record the report reads, each made by the
    code that writes it (a test oracle that follows the code's wording)."""
    cfg = settings.defaults()
    ref = smooth_path()
    out = []
    # Step 1: signals
    out.append(sync._speed_signals(ref.select(np.arange(3)), ref, 0.1, sync.angular_speed))
    twice = Trajectory(np.repeat(ref.t, 2), np.repeat(ref.p, 2, 0), np.repeat(ref.q, 2, 0))
    out.append(sync._speed_signals(twice, ref, 0.1, sync.angular_speed))
    short = Trajectory(ref.t[:5] * 0.01, ref.p[:5], ref.q[:5])
    out.append(sync._speed_signals(ref, short, 0.1, sync.angular_speed))
    t = ref.t
    for linear in (False, True):
        out.append(sync._signals_refused(t, t, {"a": 1e-4, "b": 1.0}, 2.0, 0.05, linear)[1])
    out.append(sync._signals_refused(t, t + 100.0, {"a": 1.0, "b": 1.0}, 2.0, 0.05)[1])
    # Step 1: the peak (edge, outside, weak, ambiguous) and the whole estimate
    for peak in (
        _peak(0, 0.9, 5.0, -1.0),
        _peak(10, 0.5, 5.0, 0.9),
        _peak(10, 0.9, 1.05, -1.0),
    ):
        out.append(sync._peak_refused(peak, 0.1, 0.3, 1.1)[1])
    weak = sync._peak_refused(_peak(10, 0.1, 5.0, -1.0), 0.1, 0.3, 1.1)[1]
    out.append(weak)
    # the smooth path turns slowly (0.004 rad/s): any motion is enough here
    out.append(sync.estimate_offset(ref, ref, min_motion=0.0, resample_dt=1e3).reason)
    out.append(sync.estimate_offset(ref, ref, min_motion=0.0, max_std=-1.0).reason)
    out.append(sync.estimate_offset(ref, ref, min_motion=0.0).reason)  # "estimated"
    off = {**cfg, "sync": {**cfg["sync"], "estimate_offset": False}}
    out.append(sync_stage.compute(ref, ref, off)[2]["step1"]["reason"])  # "disabled"
    # Step 2
    out.append(calibrate.solve(ref, ref, min_pairs=10**6).reason)
    out.append(calibrate.solve(ref, ref, min_rotation_deg=1e3).reason)
    out.append(calibrate.solve(ref, ref).reason)  # "solved"
    unobservable = _verdict(
        True,
        rotation_unobservable_axes=[[0.0, 0.0, 1.0]],
        translation_unobservable_directions=[[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]],
        scale_unobservable=True,
        rotation_residual_rms_deg=3.5,
        translation_residual_rms_m=0.5,
        rotation_std_deg=[2.0, 0.1, 0.1],
        translation_std_m=[0.1, 0.001, 0.001],
        scale_std=0.5,
    )
    out.append(unobservable.reason)
    nan, inf = float("nan"), float("inf")
    for value in (nan, inf):
        out.append(
            _verdict(
                True,
                rotation_std_deg=[value, 0.1, 0.1],
                translation_std_m=[value, 0.1, 0.1],
                scale_std=value,
            ).reason
        )
    for which in (_posonly(ref), ref), (ref, _posonly(ref)), (_posonly(ref), _posonly(ref)):
        out.append(calibrate_stage.position_only_reason(position_only(*which)))
    # the evaluation plan: its reason and dropped list
    untrusted = {"used": False, "reason": weak}
    for mode in ("ov_eval", "rpg"):
        out.append(plan.evaluation_plan({**cfg, "mode": mode}, untrusted)["reason"])
    out.append(plan.evaluation_plan(cfg, untrusted)["reason"])
    out.append(plan.evaluation_plan(cfg, {"used": True, "offset": 0.0}, unobservable)["reason"])
    out.append(plan.evaluation_plan(cfg, {"used": True, "offset": 0.0})["reason"])
    out.append(plan.evaluation_plan(cfg, {"used": True}, _verdict(False))["reason"])
    for used in (True, False):
        for scale in (True, False):
            c = {**cfg, "calibrate": {**cfg["calibrate"], "scale": scale}}
            out += plan.dropped(c, {"used": used})
    # consistency and efficiency
    identity = align.Similarity(np.eye(3), np.zeros(3))
    out.append(consistency.evaluate(ref, ref, identity)[0]["reason"])
    zero = np.zeros((len(ref), 3, 3))
    with_zero_cov = Trajectory(ref.t, ref.p, ref.q, cov_rot=zero, cov_pos=zero)
    out.append(consistency.evaluate(ref, with_zero_cov, identity)[0]["reason"])
    timing = (ref.t + 1e3, np.full(len(ref), 10.0))
    out.append(efficiency.evaluate(ref.t, ref.t, ref.t * 0, 1.0, timing, 20.0, 0.01)[0]["reason"])
    # drift detection's warning, each fix
    for mode in ("fixed", "scale_aware"):
        record = {"ate": {"trans_m": {"rmse": 3.472}}, "ref_length_m": 80.52}
        c = {**cfg["drift"], "mode": mode}
        out.append(drift_stage.thresholds_misfit({"success_rate_distance_pct": 100.0}, record, c))
    # the Sim3 scale check's warnings
    c = cfg["metrics"]["sim3_check"]
    for declared in (True, None):
        out += sim3_check.findings(5.151, 3.472, 0.03822, declared, c)
        out += sim3_check.unscaled_findings(5.151, 3.472, 0.03822, declared, c, 80.52)
    return out


# reasons written inline by a stage's run: held to their sources, which must still say them
INLINE = {
    "workflow/stages/consistency.py": (
        "{which}: the NEES needs the rotation errors",
        [
            f"{position_only(_posonly(smooth_path(8)), smooth_path(8))}: the NEES needs the rotation errors"
        ],
    ),
    "workflow/stages/efficiency.py": (
        '"no timing file for this run"',
        ["no timing file for this run"],
    ),
}


def test_every_reason_the_code_writes_is_said_in_chinese():
    reasons = every_reason() + [r for _, made in INLINE.values() for r in made]
    assert len(reasons) == 49 and all(isinstance(r, str) and r for r in reasons)
    for reason in reasons:
        said = zh_reasons.say(reason)
        assert latin_words(said) <= ALLOWED, (reason, said)
        assert re.search("[\u4e00-\u9fff]", said), (reason, said)
        # every number comes back as printed (numbers taken by key names such as sync.offset aside)
        assert sorted(numbers(said)) == sorted(numbers(reason)), (reason, said)


def test_inline_reasons_are_still_in_their_sources():
    for path, (text, _) in INLINE.items():
        assert text in (SRC / path).read_text(encoding="utf-8"), path


def test_a_reason_said_clause_by_clause_numbers_unchanged():
    reason = (
        "Step 2 not trusted: unobservable: rotation about [0.00, 0.00, 1.00], translation along"
        " [1.00, 0.00, 0.00] and [0.00, 0.60, 0.80], scale; rotation residual 2.53 deg > 2.0;"
        " translation std 120 m > 0.05"
    )
    assert zh_reasons.say(reason) == (
        "步骤 2 不可信：不可观：绕 [0.00, 0.00, 1.00] 的旋转、沿 [1.00, 0.00, 0.00] 与"
        " [0.00, 0.60, 0.80] 的平移、尺度；旋转残差 2.53 deg > 2.0；平移标准差 120 m > 0.05"
    )
    # a "; " inside parentheses is one clause's
    dropped = "Step 1's time offset (not trusted; the configured sync.offset -0.015 s instead)"
    assert zh_reasons.clauses(dropped) == [dropped]
    assert (
        zh_reasons.say(dropped) == "步骤 1 的时间偏移（不可信；改用配置的 `sync.offset` -0.015 s）"
    )
    assert zh_reasons.say("correlation peak 1.2e-05 below 0.3") == "相关峰值 1.2e-05 低于 0.3"


def test_an_unknown_reason_passes_through_unchanged():
    assert zh_reasons.say("stage metrics: boom (exit 3)") == "stage metrics: boom (exit 3)"
    assert zh_reasons.say("") == ""
    # a known clause beside an unknown one: each kept, the known one said in Chinese
    mixed = zh_reasons.say("something new happened; correlation peak 0.139 below 0.3")
    assert mixed == "something new happened；相关峰值 0.139 低于 0.3"
    # a template that changed its words is no longer matched: it stays English, not dropped
    assert (
        zh_reasons.say("correlation peak 0.139 is below 0.3")
        == "correlation peak 0.139 is below 0.3"
    )


def test_the_reports_say_reasons_in_their_language():
    doc = {
        "metrics": {
            "sync": {
                "step1": {
                    "used": False,
                    "status": "weak peak",
                    "reason": "correlation peak 0.139 below 0.3",
                }
            },
            "calibrate": {
                "step2_status": "not run",
                "plan": {
                    "fallback": True,
                    "reason": "Step 1 not trusted: correlation peak 0.139 below 0.3",
                    "dropped": [
                        "Step 1's time offset (not trusted; the configured sync.offset 0 s instead)",
                        "Step 2's extrinsic",
                    ],
                },
            },
        },
        "drift": {
            "warning": "set tighter thresholds (drift.scale_rpe_factor, drift.scale_jump_factor)"
        },
        "consistency": {"available": False, "reason": "the estimate has no covariance"},
        "efficiency": {"available": False, "reason": "no timing file for this run"},
    }
    zh = case_report.report_md(doc, "a/b/c", [], "zh", {}, t0=0.0)
    en = case_report.report_md(doc, "a/b/c", [], "en", {}, t0=0.0)
    assert "未使用（状态 `weak peak`：相关峰值太弱；相关峰值 0.139 低于 0.3）" in zh
    assert "步骤 1 不可信：相关峰值 0.139 低于 0.3" in zh
    assert (
        "未使用：步骤 1 的时间偏移（不可信；改用配置的 `sync.offset` 0 s）；步骤 2 的外参。" in zh
    )
    assert "**警告**: drift: 请设置更严的阈值" in zh
    assert "不可用: 估计轨迹没有协方差" in zh and "不可用: 本次运行没有计时文件" in zh
    # the English report and the records keep the English
    assert "correlation peak 0.139 below 0.3" in en and "Step 2's extrinsic." in en
    assert "**Warning**: drift: set tighter thresholds" in en


@pytest.fixture(scope="module")
def diverged(tmp_path_factory):
    """The example's diverging run (fail segments), with its report."""
    tmp = tmp_path_factory.mktemp("zh")
    simulate.simulate(tmp / "sim")
    cfg = settings.resolve({"truth_dir": str(tmp), "algorithms_dir": str(tmp)})
    cfg["report"]["figures"] = "none"
    out = tmp / "case"
    est = next((tmp / "sim/algorithms/vo_drifty/urban_drive").glob("run2.*"))
    chain.run_case(tmp / "sim/truth/urban_drive.txt", est, out, cfg, write_arrays=True)
    report_module.write_case_report(chain.CaseData(CaseFolder(out)), "diverged", cfg)
    return out


def test_fail_segments_are_seconds_after_the_first_matched_pose(diverged):
    fail = files.read_csv(diverged / "07_drift/fail_segments.csv")
    assert len(fail["t_start"]) >= 1 and fail["t_start"][0] > 1e9  # stamps of the reference clock
    bundle = figures.read_bundle(diverged / "10_report/bundles/ape_time.json")
    drift = files.read_json(diverged / "07_drift/drift.json")
    # the figure's zero: the first matched reference pose (pairs.csv of the calibrated poses)
    t0 = files.read_csv(diverged / "06_metrics/ape.csv")["t"][0]
    assert drift["first_fail_t"] == pytest.approx(fail["t_start"][0] - t0, abs=1e-9)
    rows = [
        f"| {s:.3f} | {e:.3f} |"
        for s, e in zip(bundle["data"]["fail_start"], bundle["data"]["fail_end"])
    ]
    assert rows[0] == f"| {drift['first_fail_t']:.3f} | {fail['t_end'][0] - t0:.3f} |"
    for lang, head in (
        ("en", "| start [s after the first matched pose] | end [s after the first matched pose] |"),
        ("zh", "| 开始 [s，自首个匹配位姿起] | 结束 [s，自首个匹配位姿起] |"),
    ):
        md = (diverged / f"10_report/report_{lang}.md").read_text(encoding="utf-8")
        table = md[md.index(head) :].splitlines()[2 : 2 + len(rows)]
        assert table == rows, lang
        assert f"{fail['t_start'][0]:.3f}" not in md  # no absolute stamp
