"""rpg_trajectory_evaluation's per-folder settings files (``eval_cfg.yaml``), read once for
``epa rpg`` and for a grid in ``mode: rpg`` (where a folder's file gives its cases' alignment)."""

from __future__ import annotations

from pathlib import Path

import yaml

from epa.core.errors import EpaError
from epa.steps.rpg import ALIGN_TYPES

DEFAULT_ALIGN = ("sim3", -1)  # rpg's, where a folder has no eval_cfg.yaml


def read_yaml(path: Path):
    try:
        with open(path) as f:
            return yaml.safe_load(f)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise EpaError(
            f"not valid YAML ({getattr(exc, 'problem', None) or exc})",
            path=path,
            line=None if mark is None else mark.line + 1,
        ) from None
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror or exc}", path=path) from None


def read_eval_cfg(case_dir: Path) -> tuple[str, int]:
    """``eval_cfg.yaml``'s ``align_type`` and ``align_num_frames``; rpg's defaults when the file is absent."""
    path = Path(case_dir) / "eval_cfg.yaml"
    if not path.exists():
        return DEFAULT_ALIGN
    cfg = read_yaml(path)
    if not isinstance(cfg, dict) or "align_type" not in cfg or "align_num_frames" not in cfg:
        raise EpaError("needs the keys align_type and align_num_frames", path=path)
    kind, n = cfg["align_type"], cfg["align_num_frames"]
    if kind not in ALIGN_TYPES:
        raise EpaError(f"align_type {kind!r} is not one of {', '.join(ALIGN_TYPES)}", path=path)
    if isinstance(n, bool) or not isinstance(n, int) or not (n == -1 or n >= 1 or kind == "none"):
        raise EpaError(f"align_num_frames {n!r} must be -1 (all) or a positive integer", path=path)
    if kind == "sim3" and n == 1:
        raise EpaError("align_type sim3 needs align_num_frames >= 2 or -1", path=path)
    return kind, n
