"""Sweep specs: a base scene plus the parameters to vary, expanded into validated points.

A sweep YAML file::

    name: lego_speed_vs_amplitude          # optional; default the file's stem
    description: ...
    base: ../configs/lego_vector_soliton.yaml   # path relative to this file, or an inline scene
    set:                                   # optional fixed overrides, applied like --set
      lattice.left: free
      excitation: {kind: soliton, amplitude_rad: 0.5, center_site: 20}
    vary:
      grid:                                # Cartesian product (or `zip:` for paired lists)
        excitation.amplitude_rad: {start: 0.15, stop: 1.2, num: 12}       # linear range
        damping.viscous.damping_ratio: {start: 1e-4, stop: 1e-2, num: 5, scale: log}
        lattice.n_units: [100, 200]        # explicit values
        excitation.velocity_m_s: "log:0.25:6:12"   # the inline syntax also works here
        solver.dt_fraction: {values: [0.05, 0.1, 0.2], scale: log}   # explicit, plotted on log axes
    analysis: {field: theta}               # options of flexmm.sweep.observe (kind, field, ...)

Inline (``flexmm sweep CONFIG --vary PATH=VALUES``) VALUES is ``start:stop:num`` (linear, both
ends included), ``log:start:stop:num`` (geometric) or ``a,b,c`` (explicit, read as YAML scalars).
Range values are rounded to 12 significant digits so a point's config (and its hash) does not
depend on floating-point noise in the range arithmetic.

Every point is the base with ``set`` then its own values applied through
``flexmm.config.loader`` — validated exactly like ``--set``; a bad value is reported at the
sweep file's line (or the ``--vary`` argument) that produced it.
"""

from __future__ import annotations

import copy
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from flexmm.config.loader import (
    ConfigError,
    ConfigIssue,
    apply_overrides,
    parse_overrides,
    read_yaml,
    scene_from_dict,
)
from flexmm.config.scene import Scene
from flexmm.io.provenance import config_hash
from flexmm.sweep.values import parse_values, values_of

SPEC_KEYS = ("name", "description", "base", "set", "vary", "analysis")
MODES = ("grid", "zip")
ANALYSIS_KEYS = ("kind", "field", "threshold_fraction", "trim_fraction")
ANALYSIS_KINDS = ("auto", "pulse", "front", "driven", "modes")


@dataclass(frozen=True)
class Axis:
    """One varied parameter: dotted config path, its values, where they were written."""

    path: str
    values: tuple
    origin: str
    scale: str = "linear"

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(self.path.split("."))


@dataclass(frozen=True)
class Point:
    """One validated scene of a sweep: its index in the sweep, its varied values, its hash."""

    index: tuple[int, ...]
    params: dict[str, Any]
    scene: Scene
    hash: str

    @property
    def label(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.params.items())


@dataclass(frozen=True)
class SweepSpec:
    """A base scene (as loaded YAML data), fixed overrides, and the axes to vary."""

    name: str
    source: str
    base_data: dict
    base_lines: dict
    base_source: str
    axes: tuple[Axis, ...]
    mode: str = "grid"
    fixed: tuple = ()
    description: str = ""
    analysis: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid: one length per axis; zip: (number of points,)."""
        if self.mode == "zip":
            return (len(self.axes[0].values),)
        return tuple(len(a.values) for a in self.axes)

    @property
    def n_points(self) -> int:
        return math.prod(self.shape)

    def base_scene(self) -> Scene:
        """The base with the fixed overrides, before any varied value."""
        data, lines = self._with_fixed()
        return scene_from_dict(data, lines=lines, source=self.base_source)

    def _with_fixed(self) -> tuple[dict, dict]:
        data, lines = copy.deepcopy(self.base_data), dict(self.base_lines)
        for keys, val, raw, origin in self.fixed:
            apply_overrides(data, [(keys, val, raw)], lines, self.base_source)
            lines[keys] = origin
        return data, lines

    def _indices(self):
        if self.mode == "zip":
            return [(i,) for i in range(self.shape[0])]
        return list(itertools.product(*(range(n) for n in self.shape)))

    def points(self) -> list[Point]:
        """Every point, validated; one ConfigError listing all problems (grouped) if any fail."""
        base, base_lines = self._with_fixed()
        out, problems = [], {}
        indices = self._indices()
        for index in indices:
            params, data, lines = {}, copy.deepcopy(base), dict(base_lines)
            for k, axis in enumerate(self.axes):
                val = axis.values[index[0] if self.mode == "zip" else index[k]]
                params[axis.path] = val
                apply_overrides(data, [(axis.keys, val, f"{axis.path}={val!r}")], lines, self.base_source)
                lines[axis.keys] = axis.origin
            try:
                scene = scene_from_dict(data, lines=lines, source=self.base_source)
            except ConfigError as exc:
                label = ", ".join(f"{k}={v!r}" for k, v in params.items())
                for issue in exc.issues:
                    problems.setdefault((issue.source, issue.line, issue.path, issue.message), []).append(label)
                continue
            out.append(Point(index, params, scene, config_hash(scene)))
        if problems:
            raise ConfigError([_grouped_issue(key, labels, len(indices)) for key, labels in problems.items()])
        return out


def _grouped_issue(key: tuple, labels: list[str], n_total: int) -> ConfigIssue:
    source, line, path, message = key
    if len(labels) == n_total and n_total > 1:
        where = f"at every point ({n_total})"
    elif len(labels) == 1:
        where = f"at point {labels[0]}"
    else:
        where = f"at {len(labels)} of {n_total} points, e.g. {labels[0]}"
    return ConfigIssue(source, line, path, f"{message} [{where}]")


def parse_vary(raw: str) -> Axis:
    """One ``--vary PATH=VALUES`` argument as an Axis; ConfigError if malformed."""
    if "=" not in raw:
        raise ConfigError([ConfigIssue("--vary", None, raw, "expected PATH=start:stop:num, PATH=log:start:stop:num or PATH=a,b,c")])
    path, text = raw.split("=", 1)
    path = path.strip()
    if not path or any(not k for k in path.split(".")):
        raise ConfigError([ConfigIssue("--vary", None, raw, "empty key in the dotted path")])
    vals, scale, err = parse_values(text)
    if err:
        raise ConfigError([ConfigIssue("--vary", None, path, f"{err} (in {raw!r})")])
    return Axis(path, vals, f"--vary {raw}", scale)


# ---------------------------------------------------------------- building specs


def _fixed_from_strings(pairs: list[str], origin: str = "--set") -> tuple:
    return tuple((keys, val, raw, f"{origin} {raw}") for keys, val, raw in parse_overrides(pairs))


def spec_from_scene(config: str | Path, vary: list[str], *, zip_axes: bool = False,
                    overrides: list[str] | None = None, name: str | None = None) -> SweepSpec:
    """An inline sweep: a scene file plus ``--vary`` arguments (grid, or zipped with zip_axes)."""
    data, lines = read_yaml(config)
    axes = tuple(parse_vary(v) for v in vary)
    if not axes:
        raise ConfigError([ConfigIssue("--vary", None, "", "give at least one --vary PATH=VALUES")])
    mode = "zip" if zip_axes else "grid"
    _check_axes(axes, mode, "--vary")
    scene_name = data.get("name") if isinstance(data.get("name"), str) else Path(config).stem
    return SweepSpec(
        name=name or f"{scene_name}_sweep", source=str(config), base_data=data, base_lines=lines,
        base_source=str(config), axes=axes, mode=mode, fixed=_fixed_from_strings(overrides or []),
    )


def _check_axes(axes: tuple[Axis, ...], mode: str, source: str, line: int | None = None) -> None:
    issues = []
    seen = set()
    for a in axes:
        if a.path in seen:
            issues.append(ConfigIssue(source, line, a.path, "varied twice"))
        seen.add(a.path)
    if mode == "zip" and len({len(a.values) for a in axes}) > 1:
        lens = ", ".join(f"{a.path}: {len(a.values)}" for a in axes)
        issues.append(ConfigIssue(source, line, "vary.zip", f"zipped lists must have equal lengths (got {lens})"))
    if issues:
        raise ConfigError(issues)


def load_sweep(path: str | Path, *, overrides: list[str] | None = None) -> SweepSpec:
    """Read a sweep YAML file (see the module docstring); ConfigError with file:line on problems."""
    src = str(path)
    data, lines = read_yaml(path)
    issues: list[ConfigIssue] = []

    def bad(keys: tuple, message: str) -> None:
        issues.append(ConfigIssue(src, _line(lines, keys), ".".join(map(str, keys)), message))

    for k in data:
        if k not in SPEC_KEYS:
            bad((k,), f"unknown key; expected one of: {', '.join(SPEC_KEYS)}")
    base_data, base_lines, base_source = _base(data, lines, Path(path), bad)
    fixed = _fixed_from_mapping(data.get("set"), lines, src, bad)
    mode, axes = _axes(data.get("vary"), lines, src, bad)
    analysis = data.get("analysis") or {}
    if not isinstance(analysis, dict):
        bad(("analysis",), "expected a mapping, e.g. {field: theta}")
        analysis = {}
    for k in analysis:
        if k not in ANALYSIS_KEYS:
            bad(("analysis", k), f"unknown key; expected one of: {', '.join(ANALYSIS_KEYS)}")
    if analysis.get("kind", "auto") not in ANALYSIS_KINDS:
        bad(("analysis", "kind"), f"expected one of: {', '.join(ANALYSIS_KINDS)} (got {analysis['kind']!r})")
    name = data.get("name", Path(path).stem)
    if not isinstance(name, str) or not name.replace("_", "").replace("-", "").replace(".", "").isalnum():
        bad(("name",), f"expected a name of letters, digits, '_', '-' or '.' (got {name!r})")
    if issues:
        raise ConfigError(issues)
    _check_axes(axes, mode, src, _line(lines, ("vary",)))
    return SweepSpec(
        name=name, source=src, base_data=base_data, base_lines=base_lines, base_source=base_source,
        axes=axes, mode=mode, fixed=fixed + _fixed_from_strings(overrides or []),
        description=str(data.get("description", "")), analysis=dict(analysis),
    )


def _line(lines: dict, keys: tuple) -> int | None:
    for k in range(len(keys), -1, -1):
        if keys[:k] in lines and isinstance(lines[keys[:k]], int):
            return lines[keys[:k]]
    return None


def _base(data: dict, lines: dict, path: Path, bad) -> tuple[dict, dict, str]:
    base = data.get("base")
    if isinstance(base, str):
        file = (path.parent / base) if not Path(base).is_absolute() else Path(base)
        try:
            bdata, blines = read_yaml(file)
        except ConfigError as exc:
            bad(("base",), f"base config {str(file)!r}: " + "; ".join(i.message for i in exc.issues))
            return {}, {}, str(file)
        return bdata, blines, str(file)
    if isinstance(base, dict):
        blines = {k[1:]: v for k, v in lines.items() if k[:1] == ("base",)}
        return copy.deepcopy(base), blines, str(path)
    bad(("base",), "expected a scene file path (relative to this file) or an inline scene mapping"
        if base is not None else "required: a base scene file path or an inline scene mapping")
    return {}, {}, str(path)


def _fixed_from_mapping(section: Any, lines: dict, src: str, bad) -> tuple:
    if section is None:
        return ()
    if not isinstance(section, dict):
        bad(("set",), "expected a mapping of dotted.path: value")
        return ()
    out = []
    for key, val in section.items():
        keys = tuple(k for k in str(key).split(".") if k)
        if not keys:
            bad(("set", key), "empty key path")
            continue
        out.append((keys, val, f"{key}={val!r}", f"{src}:{_line(lines, ('set', key))}"))
    return tuple(out)


def _axes(vary: Any, lines: dict, src: str, bad) -> tuple[str, tuple[Axis, ...]]:
    if not isinstance(vary, dict) or not vary:
        bad(("vary",), "required: a mapping with `grid:` or `zip:` of dotted.path: values")
        return "grid", ()
    modes = [m for m in vary if m in MODES]
    for m in vary:
        if m not in MODES:
            bad(("vary", m), "unknown key; expected `grid` or `zip` (then dotted.path: values)")
    if len(modes) != 1:
        if not any(m not in MODES for m in vary):
            bad(("vary",), "give exactly one of `grid` or `zip`")
        return "grid", ()
    mode = modes[0]
    section = vary[mode]
    if not isinstance(section, dict) or not section:
        bad(("vary", mode), "expected a mapping of dotted.path: values")
        return mode, ()
    axes = []
    for key, spec in section.items():
        keys = ("vary", mode, key)
        origin = f"{src}:{_line(lines, keys)}"
        vals, scale, err = values_of(spec)
        if err:
            bad(keys, err)
        elif not vals:
            bad(keys, "no values")
        else:
            axes.append(Axis(str(key), vals, origin, scale))
    return mode, tuple(axes)


def spec_summary(spec: SweepSpec) -> dict:
    """Plain-data description of a spec (for spec.yaml in the sweep dir and dataset attrs)."""
    return {
        "name": spec.name,
        "source": spec.source,
        "base": spec.base_source,
        "mode": spec.mode,
        "set": {".".join(k): v for k, v, _, _ in spec.fixed},
        "vary": {a.path: {"values": list(a.values), "scale": a.scale} for a in spec.axes},
        "analysis": spec.analysis,
    }
