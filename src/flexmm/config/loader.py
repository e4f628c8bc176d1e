"""Read configs from YAML, apply ``--set`` overrides, validate, and report errors by file:line.

One loader for every config of flexmm: scenes, sweep specs (``config.sweep``), design and fit
specs, and analysis options given on the command line (``config.analysis``) are Pydantic models
validated by ``validate``. Every error names the file and line (or the option the value came
from), the dotted field path, what was given and what was expected (an unknown key: the keys
expected there); the CLI prints them and exits with status 2 (no traceback).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError

from flexmm.config.base import COERCED_NUMBER
from flexmm.config.scene import Scene
from flexmm.errors import FlexmmError

Path_ = tuple[Any, ...]


class _Loader(yaml.SafeLoader):
    """Safe YAML loader that also reads 1e-3 and 1E+6 as floats (YAML 1.2 style)."""


_FLOAT = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+][0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)
_Loader.yaml_implicit_resolvers = {
    k: [r for r in v if r[0] != "tag:yaml.org,2002:float"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))


@dataclass
class ConfigIssue:
    """One problem: where it is and what is wrong."""

    source: str
    line: int | None
    path: str
    message: str

    def __str__(self) -> str:
        where = f"{self.source}:{self.line}" if self.line else self.source
        field = f" {self.path}:" if self.path else ""
        return f"{where}:{field} {self.message}"


class ConfigError(FlexmmError):
    """A user error in a config; ``str()`` is the full, readable report."""

    def __init__(self, issues: list[ConfigIssue]):
        self.issues = issues
        super().__init__("\n".join(str(i) for i in issues))


def _line_map(node: yaml.Node, path: Path_ = (), out: dict | None = None) -> dict[Path_, int]:
    """Map every key path in a composed YAML tree to its 1-based line."""
    out = {} if out is None else out
    out.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = k.value
            out[path + (key,)] = k.start_mark.line + 1
            _line_map(v, path + (key,), out)
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            out[path + (i,)] = v.start_mark.line + 1
            _line_map(v, path + (i,), out)
    return out


def _duplicate_keys(node: yaml.Node, path: Path_ = ()) -> list[tuple[Path_, int, int]]:
    """(path, line, first line) of keys repeated in one mapping (YAML keeps the last silently)."""
    out: list[tuple[Path_, int, int]] = []
    if isinstance(node, yaml.MappingNode):
        seen: dict[Any, int] = {}
        for k, v in node.value:
            line = k.start_mark.line + 1
            if k.value in seen:
                out.append((path + (k.value,), line, seen[k.value]))
            seen.setdefault(k.value, line)
            out += _duplicate_keys(v, path + (k.value,))
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            out += _duplicate_keys(v, path + (i,))
    return out


#: a config file larger than this, or expanding (through YAML aliases) to more values, is refused
MAX_CONFIG_BYTES = 1_000_000
MAX_CONFIG_NODES = 200_000


def _expanded_size(node: yaml.Node | None, memo: dict[int, int]) -> int:
    """Number of values ``node`` stands for once aliases are expanded (linear time: memoised per
    node, so a 'billion laughs' file is measured, not expanded)."""
    if node is None:
        return 0
    key = id(node)
    if key not in memo:
        memo[key] = 1  # a cycle counts once
        if isinstance(node, yaml.MappingNode):
            memo[key] = 1 + sum(_expanded_size(k, memo) + _expanded_size(v, memo) for k, v in node.value)
        elif isinstance(node, yaml.SequenceNode):
            memo[key] = 1 + sum(_expanded_size(v, memo) for v in node.value)
    return memo[key]


def read_yaml(path: str | Path) -> tuple[dict, dict[Path_, int]]:
    """Parse a YAML file into a dict plus a key-path -> line map; ConfigError on failure."""
    src = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError([ConfigIssue(src, None, "", f"cannot read file: {exc.strerror}")]) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError([ConfigIssue(src, None, "", f"file of {len(raw):,} bytes; a config file is at most "
                                                      f"{MAX_CONFIG_BYTES:,} (is this the right file?)")])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ConfigError([ConfigIssue(src, line, "", f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at "
                                                      f"offset {exc.start}); save the file as UTF-8")]) from None
    return parse_yaml(text, src)


def parse_yaml(text: str, src: str = "<string>") -> tuple[dict, dict[Path_, int]]:
    """Parse YAML text (a config given as a string; ``src`` names it in errors) into a dict plus
    a key-path -> line map; ConfigError on failure, with the same checks as ``read_yaml``."""
    if len(text) > MAX_CONFIG_BYTES:
        raise ConfigError([ConfigIssue(src, None, "", f"text of {len(text):,} characters; a config is at most "
                                                      f"{MAX_CONFIG_BYTES:,}")])
    try:
        node = yaml.compose(text, Loader=_Loader)
        size = _expanded_size(node, {})
        if size > MAX_CONFIG_NODES:
            raise ConfigError([ConfigIssue(src, None, "", f"the YAML expands to {size:.3g} values through its "
                                                          f"aliases (limit {MAX_CONFIG_NODES:,}): refusing it")])
        data = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark else None
        what = getattr(exc, "problem", None) or str(exc)
        raise ConfigError([ConfigIssue(src, line, "", f"invalid YAML: {what}")]) from None
    if not isinstance(data, dict):
        raise ConfigError([ConfigIssue(src, 1, "", "expected a mapping of sections (a scene: name, lattice, ...; a sweep spec: base, vary, ...)")])
    dups = _duplicate_keys(node)
    if dups:
        raise ConfigError([ConfigIssue(src, line, ".".join(map(str, keys)), f"duplicate key (first given at line {first})")
                           for keys, line, first in dups])
    return data, _line_map(node) if node is not None else {}


def parse_overrides(pairs: list[str]) -> list[tuple[tuple[str, ...], Any, str]]:
    """Parse ``a.b.c=value`` strings; values are read as YAML scalars (1e-3 is a number)."""
    parsed = []
    for raw in pairs:
        if "=" not in raw:
            raise ConfigError([ConfigIssue("--set", None, raw, "expected KEY.PATH=VALUE")])
        key, value = raw.split("=", 1)
        keys = tuple(k for k in key.strip().split(".") if k)
        if not keys:
            raise ConfigError([ConfigIssue("--set", None, raw, "empty key path")])
        try:
            val = yaml.load(value, Loader=_Loader) if value.strip() else None
        except yaml.YAMLError:
            val = value
        parsed.append((keys, val, raw))
    return parsed


def apply_overrides(data: dict, overrides, lines: dict, source: str, origin: str = "--set") -> None:
    """Set each override into ``data`` (in place); record their origin (``origin raw``, e.g.
    ``--set a.b=1``) for error messages."""
    for keys, val, raw in overrides:
        node = data
        for depth, k in enumerate(keys[:-1]):
            if not isinstance(node.get(k), dict):
                node[k] = {}  # replaces a scalar: errors there come from this override
                lines[keys[: depth + 1]] = f"{origin} {raw}"
            node = node[k]
        node[keys[-1]] = val
        lines[keys] = f"{origin} {raw}"


def _yaml_path(loc: tuple, data: Any) -> tuple:
    """Drop pydantic's union-tag entries from ``loc`` so it matches keys in the data."""
    out, node = [], data
    for part in loc:
        if isinstance(node, dict) and part in node:
            out.append(part)
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            out.append(part)
            node = node[part]
        elif isinstance(node, dict) and isinstance(part, str) and part not in node:
            if node.get("kind") == part or part.startswith("function-"):
                continue  # discriminated-union tag or validator wrapper
            out.append(part)
            node = None
        else:
            out.append(part)
            node = None
    return tuple(out)


def _model_at(path: tuple, data: dict, root: type[BaseModel]) -> type[BaseModel] | None:
    """The pydantic model class that describes the mapping at ``path`` of a ``root`` config
    (through fields, discriminated unions and ``dict[str, Model]`` sections)."""
    cls: Any = root
    node: Any = data
    for part in path:
        if _is_model(cls):
            if part not in cls.model_fields:
                return None
            ann = cls.model_fields[part].annotation
        elif get_origin(cls) is dict:
            ann = get_args(cls)[1]
        else:
            return None
        node = node.get(part) if isinstance(node, dict) else None
        cls = _narrow(ann, node)
    return cls if _is_model(cls) else None


def _is_model(a: Any) -> bool:
    return isinstance(a, type) and not get_args(a) and issubclass(a, BaseModel)


def _narrow(ann, node):
    """The model (or ``dict[str, Model]`` type) of an annotation that describes ``node``: the only
    one it names, else the union member whose ``kind`` Literal holds the node's kind."""
    found = []
    stack = [ann]
    while stack:
        a = stack.pop()
        if _is_model(a) or (get_origin(a) is dict and _is_model(get_args(a)[1])):
            found.append(a)
        else:
            stack.extend(get_args(a))
    if len(found) == 1:
        return found[0]
    kind = node.get("kind") if isinstance(node, dict) else None
    for m in found:
        f = m.model_fields.get("kind") if _is_model(m) else None
        if f is not None and kind in get_args(f.annotation):
            return m
    return None


def _describe(value: Any) -> str:
    text = repr(value)
    text = text if len(text) <= 60 else text[:57] + "..."
    return f"{text} ({type(value).__name__})"


_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.(?:[A-Za-z_][A-Za-z0-9_]*|[0-9]+))*")


def _given(data: Any, keys: tuple) -> bool:
    for k in keys:
        if isinstance(data, list) and isinstance(k, int) and k < len(data):
            data = data[k]
        elif isinstance(data, dict) and k in data:
            data = data[k]
        else:
            return False
    return True


def _rule_path(path: tuple, message: str, data: dict) -> tuple:
    """Locate a cross-field rule (a model validator has no location of its own).

    The rule's message names the fields it checks ('lattice.left is ...', 'give exactly one of
    amplitude_m or amplitude_n', 'variation.2.last ...'; a number is a list index): the first
    dotted name, else the first plain name, that is a key given in the config (relative to the
    validated mapping, or absolute) becomes the path.
    """
    names = _NAME.findall(message)
    for name in [n for n in names if "." in n] + [n for n in names if "." not in n]:
        keys = tuple(int(k) if k.isdigit() else k for k in name.split("."))
        for cand in (path + keys, keys):
            if _given(data, cand):
                return cand
    return path


def _issue(err: dict, data: dict, lines: dict, source: str, root: type[BaseModel] | None) -> ConfigIssue:
    path = _yaml_path(err["loc"], data)
    etype, msg = err["type"], err["msg"]
    if etype == "value_error":
        msg = str(err.get("ctx", {}).get("error", msg))
        path = _rule_path(path, msg, data)
    elif etype == COERCED_NUMBER:  # a model's check of its own fields (config.base.Strict): at the field
        path = path + (err["ctx"]["field"],)
    elif etype == "union_tag_invalid":  # the wrong value sits at the discriminator key
        path = path + (str(err.get("ctx", {}).get("discriminator", "kind")).strip("'\""),)
    dotted = ".".join(str(p) for p in path)
    line = None
    for k in range(len(path), -1, -1):
        if path[:k] in lines:
            line = lines[path[:k]]
            break
    where = source
    if isinstance(line, str):  # from --set
        where, line = line, None
    if etype == "extra_forbidden":
        model = _model_at(path[:-1], data, root) if root is not None else None
        valid = sorted(model.model_fields) if model else []
        close = difflib.get_close_matches(str(path[-1]), valid, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        text = f"unknown key{hint or ';'} expected one of: {', '.join(valid)}" if valid else "unknown key"
    elif etype == "missing":
        text = "required field is missing"
    elif etype == COERCED_NUMBER:
        text = f"got {_describe(err['ctx']['given'])}; expected {err['ctx']['expected']}"
    else:
        given = f"got {_describe(err['input'])}; " if "input" in err and not isinstance(err["input"], dict) else ""
        text = f"{given}expected: {msg[0].lower() + msg[1:] if msg else msg}"
    return ConfigIssue(where, line, dotted, text)


def validation_issues(exc: ValidationError, data: dict, lines: dict, source: str,
                      root: type[BaseModel] | None = None) -> list[ConfigIssue]:
    """The file:line issues of a pydantic ValidationError of any config read with ``read_yaml``;
    ``root``: the model validated (unknown keys then list the keys expected there). In the
    order of the file's lines (then those given elsewhere, e.g. by --set)."""
    return in_line_order([_issue(e, data, lines, source, root) for e in exc.errors()])


def in_line_order(issues: list[ConfigIssue]) -> list[ConfigIssue]:
    """Issues sorted by line (stable), those without one (--set, options) last."""
    return sorted(issues, key=lambda i: (i.line is None, i.line or 0))


M = TypeVar("M", bound=BaseModel)


def validate(cls: type[M], data: Any, *, lines: dict | None = None, source: str = "<config>",
             context: dict | None = None) -> M:
    """Validate ``data`` as the config model ``cls``; a ConfigError naming file:line, the field and
    what was expected if it does not validate (every config of flexmm is read through this:
    scenes, sweep specs, design and fit specs, analysis options).

    ``lines``: the key-path -> line map of ``read_yaml`` (a value that is a string instead of a
    line names where the value came from, e.g. ``--set a.b=1`` or ``--analysis front``).
    """
    try:
        return cls.model_validate(data, context=context)
    except ValidationError as exc:
        raise ConfigError(validation_issues(exc, data, lines or {}, source, cls)) from None


def scene_from_dict(data: dict, *, lines: dict | None = None, source: str = "<config>",
                    base_dir: str | Path | None = None) -> Scene:
    """Validate a plain dict as a Scene, converting pydantic errors into a ConfigError.

    ``base_dir``: the directory relative data-file paths in the scene are relative to (the
    config file's; None: the working directory).
    """
    return validate(Scene, data, lines=lines, source=source,
                    context={"base_dir": base_dir} if base_dir is not None else None)


def load_scene(path: str | Path, overrides: list[str] | None = None,
               options: dict[str, tuple[str, Any]] | None = None) -> Scene:
    """Read, override and validate a scene file. ``options``: config values a command-line option
    sets, ``{"initial.from_run": ("--from", "runs/x")}``: set after the ``--set`` overrides (the
    value as given, not read as YAML), and a mistake is reported under the option's name."""
    data, lines = read_yaml(path)
    if overrides:
        apply_overrides(data, parse_overrides(overrides), lines, str(path))
    for dotted, (option, value) in (options or {}).items():
        keys = tuple(dotted.split("."))
        apply_overrides(data, [(keys, value, str(value))], lines, str(path), origin=option)
    return scene_from_dict(data, lines=lines, source=str(path), base_dir=Path(path).resolve().parent)


def _looks_like_path(text: str) -> bool:
    """A scene given as one string: a file path (one line that names a file, ends in .yaml/.yml or
    has no ``key: value``) rather than YAML text."""
    if "\n" in text:
        return False
    return Path(text).expanduser().is_file() or text.endswith((".yaml", ".yml")) or ":" not in text


def resolve_scene(scene: Scene | dict | str | Path, overrides: dict[str, Any] | None = None) -> Scene:
    """A validated Scene from a YAML file path, YAML text, a dict or a Scene, with ``overrides``
    (dotted keys to Python values, e.g. ``{"solver.duration_s": 0.1}``) applied.

    A mistake raises ``ConfigError`` naming the source (the file, ``<string>`` or ``<dict>``) and
    line where there is one, the dotted field path and what was expected; a mistake in an
    override names it (``override solver.duration_s=-1``). The dict given is not modified.
    """
    import copy

    from flexmm.io.provenance import resolved_config

    pairs = [(tuple(k for k in str(key).split(".") if k), val, f"{key}={val!r}")
             for key, val in (overrides or {}).items()]
    for keys, _, raw in pairs:
        if not keys:
            raise ConfigError([ConfigIssue("override", None, raw, "empty key path")])
    if isinstance(scene, Scene):
        if not pairs:
            return scene
        data, lines, source, base = resolved_config(scene), {}, "<Scene>", None
    elif isinstance(scene, dict):
        data, lines, source, base = copy.deepcopy(scene), {}, "<dict>", None
    elif isinstance(scene, Path) or (isinstance(scene, str) and _looks_like_path(scene)):
        path = Path(scene).expanduser()
        data, lines = read_yaml(path)
        source, base = str(path), path.resolve().parent
    elif isinstance(scene, str):
        data, lines = parse_yaml(scene)
        source, base = "<string>", None
    else:
        raise ConfigError([ConfigIssue("scene", None, "", f"got {_describe(scene)}; expected: a Scene, a dict, "
                                                          "YAML text or the path of a YAML file")])
    apply_overrides(data, pairs, lines, source, origin="override")
    return scene_from_dict(data, lines=lines, source=source, base_dir=base)
