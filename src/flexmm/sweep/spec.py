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
    analysis: {field: theta}               # flexmm.config.analysis.AnalysisOptions (kind, field, ...)

The file is a ``flexmm.config.sweep.SweepFile``, validated by ``flexmm.config.loader`` like a
scene: a mistake is reported at its line with the field and what was expected. Inline
(``flexmm sweep CONFIG --vary PATH=VALUES``) VALUES is ``start:stop:num`` (linear, both ends
included), ``log:start:stop:num`` (geometric) or ``a,b,c`` (explicit, read as YAML scalars),
the values of ``flexmm.config.sweep.VaryValues``.

Every point is the base with ``set`` then its own values applied through
``flexmm.config.loader`` — validated exactly like ``--set``; a bad value is reported at the
sweep file's line (or the ``--vary`` argument) that produced it.
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from flexmm.config.analysis import AnalysisOptions
from flexmm.config.loader import (
    ConfigError,
    ConfigIssue,
    apply_overrides,
    in_line_order,
    parse_overrides,
    read_yaml,
    scene_from_dict,
    validate,
)
from flexmm.config.scene import Scene
from flexmm.config.sweep import INLINE_FORMS, KEEP_FORMS, SweepFile, Vary, VaryValues, keep_condition, keep_every
from flexmm.io.provenance import config_hash


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
    flat: int = 0

    @functools.cached_property
    def hash(self) -> str:
        """sha256 of the point's resolved scene (``flexmm.io.provenance.config_hash``)."""
        return config_hash(self.scene)

    @property
    def label(self) -> str:
        return label(self.params)


def label(params: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in params.items())


#: up-front check: at most this many values of each axis are validated before anything runs
CHECK_VALUES_PER_AXIS = 256


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
    analysis: AnalysisOptions = field(default_factory=AnalysisOptions)
    keep: str = "none"

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

    @functools.cached_property
    def _fixed_base(self) -> tuple[dict, dict]:
        """The base with the fixed overrides, computed once per spec object (per worker)."""
        return self._with_fixed()

    def index_of(self, flat: int) -> tuple[int, ...]:
        """The point's index in the sweep's shape (C order) from its number."""
        if self.mode == "zip":
            return (flat,)
        out = []
        for n in reversed(self.shape):
            flat, k = divmod(flat, n)
            out.append(k)
        return tuple(reversed(out))

    def params_at(self, flat: int) -> dict[str, Any]:
        """The varied values of point number ``flat`` (nothing validated)."""
        index = self.index_of(flat)
        return {a.path: a.values[index[0] if self.mode == "zip" else index[k]] for k, a in enumerate(self.axes)}

    def point_at(self, flat: int) -> Point:
        """Point number ``flat`` (C order over ``shape``), validated: ConfigError if its values
        make an invalid scene (reported at the sweep file's lines that produced them)."""
        base, base_lines = self._fixed_base
        params = self.params_at(flat)
        data, lines = copy.deepcopy(base), dict(base_lines)
        for axis in self.axes:
            val = params[axis.path]
            apply_overrides(data, [(axis.keys, val, f"{axis.path}={val!r}")], lines, self.base_source)
            lines[axis.keys] = axis.origin
        scene = scene_from_dict(data, lines=lines, source=self.base_source)
        return Point(self.index_of(flat), params, scene, flat)

    def keeps(self, flat: int, observables=None) -> bool:
        """Whether point number ``flat`` keeps its full run directory (``keep:``); for ``keep:
        where <condition>``, whether its ``observables`` (in ``OBSERVABLES`` order; None: not
        measured yet) meet the condition."""
        every = keep_every(self.keep)
        if every:
            return flat % every == 0
        where = self.keep_where
        if where is None or observables is None:
            return False
        from flexmm.sweep.observe import OBSERVABLES

        return where(dict(zip(OBSERVABLES, (float(v) for v in observables))))

    @functools.cached_property
    def keep_where(self):
        """The condition of ``keep: where <condition>`` (a ``flexmm.config.condition.Condition``), or None."""
        return keep_condition(self.keep)

    def check(self) -> None:
        """The up-front validation of a sweep: the base with the fixed overrides, and each of
        the first CHECK_VALUES_PER_AXIS values of every axis (the other axes at their first
        value). One ConfigError with every problem, grouped, at the lines that produced them;
        any other point is validated when it is run (an invalid one is recorded as failed)."""
        if self.mode == "zip":
            flats = range(min(self.n_points, CHECK_VALUES_PER_AXIS))
        else:
            strides = [math.prod(self.shape[k + 1:]) for k in range(len(self.shape))]
            flats = sorted({i * strides[k] for k, n in enumerate(self.shape)
                            for i in range(min(n, CHECK_VALUES_PER_AXIS))})
        self._validate(flats)

    def points(self) -> list[Point]:
        """Every point, validated; one ConfigError listing all problems (grouped) if any fail."""
        return self._validate(range(self.n_points))

    def _validate(self, flats) -> list[Point]:
        out, problems = [], {}
        for flat in flats:
            try:
                out.append(self.point_at(flat))
            except ConfigError as exc:
                where = ", ".join(f"{k}={v!r}" for k, v in self.params_at(flat).items())
                for issue in exc.issues:
                    problems.setdefault((issue.source, issue.line, issue.path, issue.message), []).append(where)
        if problems:
            raise ConfigError([_grouped_issue(key, labels, len(flats), self.n_points)
                               for key, labels in problems.items()])
        return out


def _grouped_issue(key: tuple, labels: list[str], n_checked: int, n_total: int) -> ConfigIssue:
    source, line, path, message = key
    if len(labels) == n_checked == n_total and n_total > 1:
        where = f"at every point ({n_total})"
    elif len(labels) == n_checked and n_checked > 1:
        where = f"at every point checked ({n_checked} of {n_total})"
    elif len(labels) == 1:
        where = f"at point {labels[0]}"
    else:
        where = f"at {len(labels)} of {n_checked} points, e.g. {labels[0]}"
    return ConfigIssue(source, line, path, f"{message} [{where}]")


def parse_vary(raw: str) -> Axis:
    """One ``--vary PATH=VALUES`` argument as an Axis; ConfigError if malformed."""
    if "=" not in raw:
        raise ConfigError([ConfigIssue("--vary", None, raw, f"expected PATH=VALUES, VALUES one of {INLINE_FORMS}")])
    path, text = raw.split("=", 1)
    path = path.strip()
    if not path or any(not k for k in path.split(".")):
        raise ConfigError([ConfigIssue("--vary", None, raw, "empty key in the dotted path")])
    try:
        values = validate(VaryValues, text, lines={(): f"--vary {raw}"}, source="--vary")
    except ConfigError as exc:
        raise ConfigError([replace(i, path=".".join(filter(None, (path, i.path)))) for i in exc.issues]) from None
    return Axis(path, values.expand(), f"--vary {raw}", values.scale)


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
    twice = sorted({a.path for a in axes if sum(b.path == a.path for b in axes) > 1})
    if twice:
        raise ConfigError([ConfigIssue("--vary", None, p, "varied twice") for p in twice])
    # the rules on the set of axes (zipped lists of equal lengths) are those of a sweep file's vary:
    validate(Vary, {mode: {a.path: {"values": list(a.values)} for a in axes}}, source="--vary")
    scene_name = data.get("name") if isinstance(data.get("name"), str) else Path(config).stem
    return SweepSpec(
        name=name or f"{scene_name}_sweep", source=str(config), base_data=data, base_lines=lines,
        base_source=str(config), axes=axes, mode=mode, fixed=_fixed_from_strings(overrides or []),
    )


def is_sweep_spec(data: dict) -> bool:
    """True if a YAML file's data is a sweep spec (it has ``base`` or ``vary``), not a scene."""
    return "vary" in data or "base" in data


def load_sweep(path: str | Path, *, overrides: list[str] | None = None) -> SweepSpec:
    """Read a sweep YAML file (a ``SweepFile``, see the module docstring); one ConfigError with
    file:line, field and what was expected for every problem of the spec and its base file."""
    src = str(path)
    data, lines = read_yaml(path)
    issues: list[ConfigIssue] = []
    try:
        spec = validate(SweepFile, data, lines=lines, source=src)
    except ConfigError as exc:
        issues += exc.issues
    base_data, base_lines, base_source = _base(data.get("base"), lines, Path(path), issues)
    if issues:
        raise ConfigError(in_line_order(issues))
    check_keep(spec.keep, src, _line(lines, ("keep",)))
    mode = spec.vary.mode
    axes = tuple(Axis(key, vals.expand(), f"{src}:{_line(lines, ('vary', mode, key))}", vals.scale)
                 for key, vals in spec.vary.axes.items())
    fixed = tuple((tuple(key.split(".")), val, f"{key}={val!r}", f"{src}:{_line(lines, ('set', key))}")
                  for key, val in spec.set.items())
    return SweepSpec(
        name=spec.name or Path(path).stem, source=src, base_data=base_data, base_lines=base_lines,
        base_source=base_source, axes=axes, mode=mode, fixed=fixed + _fixed_from_strings(overrides or []),
        description=spec.description, analysis=spec.analysis, keep=spec.keep,
    )


def check_keep(keep: str, source: str, line: int | None = None) -> None:
    """ConfigError at ``source``:``line`` unless ``keep`` is a valid ``keep:`` whose condition
    (``where ...``) reads only observables."""
    import re

    from flexmm.config.sweep import KEEP_PATTERN
    from flexmm.sweep.observe import OBSERVABLES

    try:
        if not re.match(KEEP_PATTERN, keep):
            raise ValueError(f"got {keep!r}; expected {KEEP_FORMS}")
        where = keep_condition(keep)
    except ValueError as exc:
        raise ConfigError([ConfigIssue(source, line, "keep", str(exc))]) from None
    unknown = sorted(where.names - set(OBSERVABLES)) if where else []
    if unknown:
        raise ConfigError([ConfigIssue(source, line, "keep", f"unknown observable(s) {', '.join(unknown)} in the "
                                       f"condition; expected some of: {', '.join(OBSERVABLES)}")])


def _line(lines: dict, keys: tuple) -> int | None:
    for k in range(len(keys), -1, -1):
        if keys[:k] in lines and isinstance(lines[keys[:k]], int):
            return lines[keys[:k]]
    return None


def _base(base: Any, lines: dict, path: Path, issues: list[ConfigIssue]) -> tuple[dict, dict, str]:
    """(scene data, its line map, its source) of the spec's ``base``: a file read (its problems
    added to ``issues``) or the inline mapping (the spec's lines); {} if neither."""
    if isinstance(base, str):
        file = (path.parent / base) if not Path(base).is_absolute() else Path(base)
        try:
            bdata, blines = read_yaml(file)
        except ConfigError as exc:
            issues.append(ConfigIssue(str(path), _line(lines, ("base",)), "base",
                                      f"base config {str(file)!r}: " + "; ".join(i.message for i in exc.issues)))
            return {}, {}, str(file)
        return bdata, blines, str(file)
    if isinstance(base, dict):
        blines = {k[1:]: v for k, v in lines.items() if k[:1] == ("base",)}
        return copy.deepcopy(base), blines, str(path)
    return {}, {}, str(path)


def spec_summary(spec: SweepSpec) -> dict:
    """Plain-data description of a spec (for spec.yaml in the sweep dir and dataset attrs)."""
    return {
        "name": spec.name,
        "source": spec.source,
        "base": spec.base_source,
        "mode": spec.mode,
        "set": {".".join(k): v for k, v, _, _ in spec.fixed},
        "vary": {a.path: {"values": list(a.values), "scale": a.scale} for a in spec.axes},
        "analysis": spec.analysis.model_dump(exclude_defaults=True),
        "keep": spec.keep,
    }
