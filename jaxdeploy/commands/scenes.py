"""`jaxdeploy scenes [SCENE]`: the scenes, or one scene's parameters (default, unit, valid
range, meaning), options (default, choices, meaning), default end time and step control."""

from __future__ import annotations

import math

from ._args import parse_pairs, refuse

NAME = "scenes"
HELP = "list the scenes, or one scene's parameters, options and defaults"


def add_arguments(parser) -> None:
    parser.add_argument("scene", nargs="?", help="scene name (default: list every scene)")
    parser.add_argument(
        "--scene-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="describe the scene with these options (e.g. ideal=true: the parameters it has); "
        "default: none",
    )


def _range(spec) -> str:
    def end(x):
        return "inf" if x == math.inf else ("-inf" if x == -math.inf else f"{x:g}")

    low = ("[" if spec.low_inclusive else "(") + end(spec.low)
    high = end(spec.high) + ("]" if spec.high_inclusive else ")")
    return f"{low}, {high}"


def _table(rows, header) -> list[str]:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header) - 1)]
    lines = []
    for r in [header, *rows]:
        cells = [str(c).ljust(w) for c, w in zip(r[:-1], widths, strict=True)]
        lines.append("  ".join([*cells, str(r[-1])]).rstrip())
    return lines


def summary_line(cls) -> str:
    """The first paragraph of the scene class's docstring (else its module's), on one line."""
    import sys

    text = cls.__doc__ or sys.modules[cls.__module__].__doc__ or ""
    return " ".join(text.strip().split("\n\n")[0].split())


def _shown(value) -> str:
    """An option value as the command line spells it (JSON: true, {"J1": "panel1"})."""
    import json

    return value if isinstance(value, str) else json.dumps(value)


def describe(scene) -> str:
    """The text `jaxdeploy scenes SCENE` prints."""
    cls = type(scene)
    doc = summary_line(cls)
    lines = [f"{scene.name}: {doc}", ""]
    lines.append(f"default end time: {scene.default_t_end:g} s (--t-end)")
    control = scene.default_control.to_json()
    shown = ", ".join(f"{k} = {v}" for k, v in control.items() if v is not None and k != "adaptive")
    lines.append(f"default step control: {shown} (--solver/--rtol/--atol/--dt-max/--dt)")
    lines += ["", "parameters (--set NAME=VALUE, SI units):"]
    ignored = scene.ignored_params()
    rows = []
    for name, spec in scene.params.items():
        meaning = spec.doc + (
            f" [not used with these options; counts with {ignored[name]}]"
            if name in ignored
            else ""
        )
        rows.append((name, f"{spec.default:g}", spec.unit or "-", _range(spec), meaning))
    lines += ["  " + r for r in _table(rows, ("name", "default", "unit", "valid", "meaning"))]
    lines += ["", "options (--scene-option KEY=VALUE):"]
    if not cls.option_specs:
        lines.append("  none")
    else:
        current = scene.options
        rows = []
        for name, spec in cls.option_specs.items():
            choices = " | ".join(
                str(c).lower() if isinstance(c, bool) else str(c) for c in spec.choices
            )
            value = current.get(name, spec.default)
            shown = str(value).lower() if isinstance(value, bool) else value
            rows.append((name, shown, choices or "(JSON)", spec.doc))
        lines += ["  " + r for r in _table(rows, ("name", "value", "choices", "meaning"))]
    return "\n".join(lines)


def run(args) -> int:
    from ..scenes import SCENES, get_scene

    if args.scene is None:
        if args.scene_option:
            return refuse("--scene-option needs a SCENE")
        width = max(len(n) for n in SCENES)
        for name, cls in SCENES.items():
            print(f"{name:<{width}}  {summary_line(cls)}")
        print("\n`jaxdeploy scenes SCENE` lists a scene's parameters and options.")
        return 0
    if args.scene not in SCENES:
        return refuse(f"unknown scene {args.scene!r}; valid: {', '.join(sorted(SCENES))}")
    try:
        scene = get_scene(args.scene, **parse_pairs(args.scene_option, "--scene-option"))
    except (ValueError, TypeError) as err:
        return refuse(f"--scene-option: {err}")
    print(describe(scene))
    return 0
