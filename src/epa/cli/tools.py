"""``epa config`` (every setting), ``epa selftest`` (Steps 1-2 on a reference's own motion),
``epa stage`` (one stage of one grid case) and ``epa simulate`` (the example grid)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from epa.cli.common import deprecated_alias
from epa.core.errors import EpaError


def add_config(sub) -> None:
    c = sub.add_parser(
        "config", help="every setting: the defaults, or the effective settings of a config file"
    )
    c.set_defaults(func=_config)
    c.add_argument("config", nargs="?", help="a config YAML (without it: the defaults)")


def add_selftest(sub) -> None:
    st = sub.add_parser(
        "selftest",
        help="how well Steps 1-2 recover known offsets and extrinsics on a reference's own motion",
    )
    st.set_defaults(func=_selftest)
    st.add_argument(
        "reference", help="the reference trajectory (a text file, or a bag with --config's sources)"
    )
    st.add_argument(
        "--config", help="a config YAML: its load, sources, sync and calibrate settings are used"
    )
    st.add_argument(
        "--rate", type=float, default=20.0, help="pose rate of the simulated estimates (Hz)"
    )
    st.add_argument("--trials", type=int, default=5, help="trials per noise level")
    st.add_argument("--scale", action="store_true", help="simulate and solve a scale (monocular)")
    st.add_argument("--seed", type=int, default=0)


def add_stage(sub) -> None:
    sg = sub.add_parser(
        "stage", help="run one stage of one grid case from the previous stage's artifacts"
    )
    sg.set_defaults(func=_stage)
    sg.add_argument("name", help="the stage: load, crop, sync, calibrate, align, metrics, ...")
    sg.add_argument("case_dir", help="the case folder, results/cases/<algorithm>/<dataset>/<run>")
    sg.add_argument(
        "--config", default="config/config.yaml", help="the grid's config (its settings apply)"
    )
    deprecated_alias(sg, "--configfile", "--config", dest="config")


def add_simulate(sub) -> None:
    s = sub.add_parser("simulate", help="write the deterministic example grid")
    s.set_defaults(func=_simulate)
    s.add_argument("out", help="folder to write truth/, algorithms/ and manifest.json into")
    s.add_argument("--seed", type=int, default=7)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def _config_listing(path) -> str:
    """One ``key: value`` line per setting, in the schema's order; with a config file, the settings it
    changes are marked with their default."""
    import json

    from epa.workflow import settings

    defaults = _flat(settings.defaults())
    if path is None:
        return "".join(f"{k}: {json.dumps(v)}\n" for k, v in defaults.items())
    effective = _flat(settings.from_configfile(path))
    lines = []
    for k, v in effective.items():
        note = (
            ""
            if k in defaults and defaults[k] == v
            else (f"  # set (default {json.dumps(defaults[k])})" if k in defaults else "  # set")
        )
        lines.append(f"{k}: {json.dumps(v)}{note}\n")
    return "".join(lines)


def _selftest(args) -> None:
    from epa.workflow import recovery as selftest
    from epa.workflow import settings
    from epa.workflow.stages import load

    cfg: dict[str, Any] = {"truth_dir": ".", "algorithms_dir": "."}
    if args.config:
        cfg.update(settings.load_yaml(args.config))
    if args.scale:
        cfg.setdefault("calibrate", {})["scale"] = True
    cfg = settings.resolve(cfg, source=args.config or "command line")
    ref, _ = load.load_reference(args.reference, cfg)
    if args.trials < 1 or not (math.isfinite(args.rate) and args.rate > 0):
        raise EpaError("--trials must be at least 1 and --rate a positive number")
    try:
        results = selftest.run(ref, cfg, trials=args.trials, rate=args.rate, seed=args.seed)
    except EpaError as exc:
        raise (exc if exc.path else EpaError(exc.message, path=args.reference)) from None
    print(selftest.report(results, Path(args.reference).name, args.rate), end="")


def _config(args) -> None:
    print(_config_listing(args.config), end="")


def _stage(args) -> None:
    from epa.workflow import one_stage

    elapsed, written = one_stage.run(args.name, args.case_dir, args.config)
    print(f"{args.name}: {elapsed:.3f} s, wrote " + ", ".join(map(str, written)))


def _simulate(args) -> None:
    from epa import simulate

    manifest = simulate.simulate(args.out, seed=args.seed)
    print(
        f"wrote {len(manifest['cases'])} estimates and {len(simulate.SEQUENCES)} references to {args.out}"
    )
