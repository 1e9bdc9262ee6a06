"""The Chinese report's reasons: the records keep their English sentences (they are the data), and
``report_zh.md`` says them in Chinese at rendering time, through the one table of patterns below.

A reason is a clause or several joined by "; " (Step 2's problems, a plan's "Step 2 not trusted:
..." with them, a warning and its fix). Each clause is matched whole against :data:`RULES`, its
numbers, stamps and keys put back as they were; a clause no pattern knows stays as it is (English
beats nothing). Patterns are compiled once, at import; a translated clause is kept, since a grid's
cases repeat the same few.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable

# a number as the reasons print it (:.3g, :g, :+.3f, a config value's repr): 0.139, -1.2e-05, inf
NUM = r"[-+]?(?:\d+(?:\.\d*)?(?:e[-+]?\d+)?|inf|nan)"
_N = f"({NUM})"
# one or more unit directions, "[0.10, 0.99, 0.00] and [...]" (Step 2's unobservable ones)
_AXES = r"\[[^\]]*\](?: and \[[^\]]*\])*"

# Words a pattern lets through as a group named w_*, each said in Chinese where it is inserted.
WORDS = {
    "reference": "参考轨迹",
    "estimate": "估计轨迹",
    "rotation": "旋转",
    "translation": "平移",
    "relative scale": "相对尺度",
    "the reference is position-only": "参考轨迹只有位置",
    "the estimate is position-only": "估计轨迹只有位置",
    "the reference and the estimate are position-only": "参考轨迹与估计轨迹都只有位置",
    "estimated, not used": "已估计但未使用",
    "not trusted": "不可信",
    " deg": " deg",
    " m": " m",
    "": "",
    " (declare metric_scale: false if its scale is arbitrary)": (
        "（若其尺度任意，请声明 `metric_scale: false`）"
    ),
    "for an algorithm declared metric (metric_scale: true): its scale is wrong": (
        "该算法声明为公制尺度（`metric_scale: true`）：其尺度有误"
    ),
    "if its scale is arbitrary (monocular), declare"
    " sources.algorithms.<algorithm>.metric_scale: false to evaluate it with Sim3": (
        "若其尺度任意（单目），请声明 `sources.algorithms.<algorithm>.metric_scale: false`，"
        "以 Sim3 评估"
    ),
}


def _alt(*words: str) -> str:
    return "|".join(re.escape(w) for w in sorted(words, key=len, reverse=True))


_SIDE = f"(?P<w_side>{_alt('reference', 'estimate')})"
_WHICH = "(?P<w_which>" + _alt(*(w for w in WORDS if w.endswith("position-only"))) + ")"
_QUANTITY = f"(?P<w_q>{_alt('rotation', 'translation', 'relative scale')})"


def _unobservable(m: re.Match) -> str:
    """Step 2's unobservable list: rotation about axes, translation along directions, scale."""
    said = []
    for item in re.finditer(rf"(rotation about|translation along) ({_AXES})|scale", m["items"]):
        if item[1] is None:
            said.append("尺度")
        else:
            axes = item[2].replace(" and ", " 与 ")
            said.append(f"绕 {axes} 的旋转" if item[1] == "rotation about" else f"沿 {axes} 的平移")
    return "不可观：" + "、".join(said)


_ITEM = rf"(?:rotation about {_AXES}|translation along {_AXES}|scale)"

# (pattern of one whole clause, its Chinese): a str is formatted with the groups (numbered ones by
# position: {0}, {1}, ...; w_* through WORDS; "say" translated as a reason itself), a callable gets
# the match. Grouped by the code that writes the English.
RULES: tuple[tuple[str, str | Callable[[re.Match], str]], ...] = (
    # Step 1 (epa.steps.sync; "disabled": workflow.stages.sync)
    ("disabled", "已关闭"),
    ("estimated", "已估计"),
    ("too few poses for a correlation", "位姿太少，无法做相关"),
    (
        f"the {_SIDE}'s median interval between consecutive stamps is {_N} s \\(repeated or"
        " unsorted stamps\\): no sample interval for a correlation",
        "{w_side}相邻时间戳间隔的中位数为 {0} s（时间戳重复或未排序）：没有可用于相关的采样间隔",
    ),
    (
        f"too few poses for a correlation: the {_SIDE}'s poses span no {_N} s",
        "位姿太少，无法做相关：{w_side}的位姿跨度不足 {0} s",
    ),
    (
        f"too little rotational motion \\(std of angular speed {_N} rad/s < {_N}\\)",
        "旋转运动太少（角速度标准差 {0} rad/s < {1}）",
    ),
    (
        f"too little linear motion \\(std of speed {_N} m/s < {_N}\\)",
        "平移运动太少（速度标准差 {0} m/s < {1}）",
    ),
    (
        f"the stamps do not overlap within the ±{_N} s search window",
        "时间戳在 ±{0} s 搜索窗口内没有重叠",
    ),
    (f"too few samples on the {_N} s correlation grid", "步长 {0} s 的相关网格上样本太少"),
    (
        f"correlation peak at the edge of the ±{_N} s search window"
        " \\(the offset may lie outside it: widen sync\\.window\\)",
        "相关峰值位于 ±{0} s 搜索窗口的边缘（偏移可能在窗口之外：请增大 `sync.window`）",
    ),
    (
        f"a better match \\({_N} at {_N} s\\) lies outside the ±{_N} s search window than"
        f" inside it \\({_N}\\): widen sync\\.window",
        "±{2} s 搜索窗口之外有更好的匹配（{1} s 处为 {0}），优于窗口之内（{3}）：请增大 `sync.window`",
    ),
    (f"correlation peak {_N} below {_N}", "相关峰值 {0} 低于 {1}"),
    (f"ambiguous peak: best/second = {_N} < {_N}", "峰值不明确：最高/次高 = {0} < {1}"),
    (
        f"offset {_N} ms too uncertain: std {_N} ms > {_N} ms",
        "偏移 {0} ms 不确定性太大：标准差 {1} ms > {2} ms",
    ),
    # Step 2 (epa.steps.calibrate; the position-only one: workflow.stages.calibrate)
    ("solved", "已求解"),
    (f"only {_N} motion pairs \\({_N} needed\\)", "只有 {0} 个运动对（需要 {1} 个）"),
    (
        f"too little rotation: {_N} pairs rotate more than {_N} deg \\({_N} needed\\)",
        "旋转太少：只有 {0} 个运动对的旋转超过 {1} deg（需要 {2} 个）",
    ),
    (f"unobservable: (?P<items>{_ITEM}(?:, {_ITEM})*)", _unobservable),
    (f"rotation residual {_N} deg > {_N}", "旋转残差 {0} deg > {1}"),
    (f"translation residual {_N} m > {_N}", "平移残差 {0} m > {1}"),
    (
        f"{_QUANTITY} std undefined \\(motion pairs in one time block\\)",
        "{w_q}标准差无定义（运动对都在同一时间块内）",
    ),
    (f"{_QUANTITY} std not finite", "{w_q}标准差不是有限值"),
    (f"{_QUANTITY} std {_N}(?P<w_unit> deg| m|) > {_N}", "{w_q}标准差 {0}{w_unit} > {1}"),
    (
        f"{_WHICH}: the hand-eye equations need both sides' relative rotations",
        "{w_which}：手眼方程需要两侧的相对旋转",
    ),
    (
        "a lever arm alone would have to be fitted jointly with Step 3's alignment, which is not"
        " done \\(an offset of the tracked point from the body stays in the translation errors\\)",
        "单独的杆臂需要与步骤 3 的对齐联合拟合，目前未这样做（跟踪点相对机体的偏移留在平移误差中）",
    ),
    # the evaluation plan's reason and dropped list (epa.steps.plan)
    ("ov_eval mode", "ov_eval 模式"),
    ("rpg mode", "rpg 模式"),
    ("Steps 1 and 2 applied", "已使用步骤 1 和 2"),
    ("Step 2 disabled", "步骤 2 已关闭"),
    ("Step 1 not trusted: (?P<say>.+)", "步骤 1 不可信：{say}"),
    ("Step 2 not trusted: (?P<say>.+)", "步骤 2 不可信：{say}"),
    (
        "Step 1's time offset \\((?P<w_how>estimated, not used|not trusted); the configured"
        f" sync\\.offset {_N} s instead\\)",
        "步骤 1 的时间偏移（{w_how}；改用配置的 `sync.offset` {0} s）",
    ),
    ("Step 2's extrinsic", "步骤 2 的外参"),
    (
        "Step 2's extrinsic and scale \\(Step 3's Sim3 fits the scale\\)",
        "步骤 2 的外参与尺度（由步骤 3 的 Sim3 拟合尺度）",
    ),
    # consistency (epa.metrics.consistency, workflow.stages.consistency), efficiency
    ("the estimate has no covariance", "估计轨迹没有协方差"),
    ("no pose has a positive-definite covariance", "没有位姿具有正定协方差"),
    (f"{_WHICH}: the NEES needs the rotation errors", "{w_which}：NEES 需要旋转误差"),
    ("no timing file for this run", "本次运行没有计时文件"),
    (f"no pose has a timing entry within {_N} s", "没有位姿在 {0} s 以内有计时记录"),
    # drift detection's warning (workflow.stages.drift)
    (
        f"success rate 100 % beside an ATE RMSE of {_N} m, {_N} % of the {_N} m path"
        f" \\(> drift\\.max_ate_path_pct {_N}\\): the drift thresholds do not fit this"
        " dataset's scale",
        "成功率 100 %，而 ATE RMSE 为 {0} m，占 {2} m 路径的 {1} %（> `drift.max_ate_path_pct` {3}）："
        "漂移阈值不适合该数据集的尺度",
    ),
    (
        "set drift\\.mode: scale_aware, or the thresholds under overrides\\.datasets",
        "请设置 `drift.mode: scale_aware`，或在 `overrides.datasets` 下设置阈值",
    ),
    (
        "set tighter thresholds \\(drift\\.scale_rpe_factor, drift\\.scale_jump_factor\\)",
        "请设置更严的阈值（`drift.scale_rpe_factor`、`drift.scale_jump_factor`）",
    ),
    # the Sim3 scale check's warnings (epa.metrics.sim3_check)
    (
        f"Sim3 scale {_N} for an algorithm declared metric \\(metric_scale: true\\):"
        f" \\|ln s\\| = {_N} > {_N}",
        "声明为公制尺度（`metric_scale: true`）的算法，Sim3 尺度为 {0}：|ln s| = {1} > {2}",
    ),
    (f"the SE3 ATE is {_N} m against {_N} m under Sim3", "SE3 ATE 为 {0} m，Sim3 下为 {1} m"),
    (
        f"the SE3 ATE \\({_N} m\\) is more than {_N} times the Sim3 ATE \\({_N} m\\): the Sim3"
        f" scale \\({_N}\\) hides most of the error"
        "(?P<w_declare>| \\(declare metric_scale: false if its scale is arbitrary\\))",
        "SE3 ATE（{0} m）超过 Sim3 ATE（{2} m）的 {1} 倍：Sim3 尺度（{3}）掩盖了大部分误差{w_declare}",
    ),
    (
        f"a Sim3 fit finds scale {_N} \\(\\|ln s\\| = {_N} > {_N}\\) and removes {_N} % of the"
        f" ATE \\({_N} m -> {_N} m\\): (?P<w_what>"
        + _alt(*(w for w in WORDS if w.startswith(("for an algorithm", "if its scale"))))
        + ")",
        "Sim3 拟合得到尺度 {0}（|ln s| = {1} > {2}），消除了 ATE 的 {3} %（{4} m -> {5} m）：{w_what}",
    ),
)

_COMPILED = tuple((re.compile(pattern), said) for pattern, said in RULES)


def clauses(reason: str) -> list[str]:
    """The clauses of a reason: split at "; " outside parentheses (a dropped Step 1 says "(not
    trusted; the configured ...)" in one clause)."""
    parts = reason.split("; ")
    if "(" not in reason:
        return parts
    out: list[str] = []
    depth = 0
    for part in parts:
        if depth > 0:
            out[-1] += "; " + part
        else:
            out.append(part)
        depth += part.count("(") - part.count(")")
    return out


@functools.lru_cache(maxsize=4096)
def clause(text: str) -> str:
    """One clause in Chinese, or as it is when no pattern knows it."""
    for rx, said in _COMPILED:
        m = rx.fullmatch(text)
        if m is None:
            continue
        if callable(said):
            return said(m)
        named = {
            k: say(v) if k == "say" else WORDS[v] if k.startswith("w_") else v
            for k, v in m.groupdict(default="").items()
        }
        return said.format(*_numbered(m), **named)
    return text


def _numbered(m: re.Match) -> list[str]:
    """The unnamed groups of a match, in order (the numbers)."""
    names = set(m.re.groupindex.values())
    return [m[i] for i in range(1, (m.re.groups or 0) + 1) if i not in names]


def say(reason: str) -> str:
    """A reason (clauses joined by "; ") in Chinese, clause by clause; unknown clauses unchanged."""
    if not reason:
        return reason
    return "；".join(clause(c) for c in clauses(reason))
