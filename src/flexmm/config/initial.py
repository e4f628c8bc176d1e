"""Initial states of any shape: per-site fields, launched waves, pinned sites (``scene.initial``).

```yaml
initial:
  fields:
    - {field: u, value: "0.002 * tanh((x - 0.5) / 0.05)", rate: "0"}   # expressions of the site
    - {field: theta, table: theta0.csv}     # CSV (site or x, value[, rate]), relative to the config
  launch:
    - {kind: toda_soliton, kappa: 1.0, center_site: 60, direction: 1}
    - {kind: kink, center_site: 100, direction: 1}   # sine-Gordon / φ⁴ kink
  pinned:
    - {field: u, sites: [0, 199]}           # held at their initial value (inverse mass 0)
  from_run: runs/previous                   # start from the last frame of another run
```

Expressions are a small, safe language (``Expression``): numbers, the site variables ``x`` and
``y`` (rest position, m), ``n`` (site index), ``i``/``j`` (column/row of a 2D lattice), the
operators + − * / ** and unary −, comparisons, ``a if c else b``, the functions of
``FUNCTIONS``, constants ``pi``, ``e``, and the seeded random fields of ``RANDOM``:
``random(seed)`` (uniform on [0, 1)) and ``normal(seed)`` (standard normal), one independent
value per site, the same for the same integer seed (``"1e-3 * normal(7)"``: a frozen noise of
1 mrad standard deviation). Text is parsed with ``ast`` and only whitelisted nodes
are accepted; it is evaluated by walking that tree with numpy — no ``eval``/``exec``, no names
or attributes beyond the whitelist, no calls of anything else.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from flexmm.config.base import Finite, Positive, Strict

FUNCTIONS = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt,
    "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "arctan": np.arctan, "arcsin": np.arcsin,
    "arccos": np.arccos, "abs": np.abs, "sign": np.sign, "floor": np.floor,
    "sech": lambda z: 1.0 / np.cosh(z), "heaviside": lambda z: np.heaviside(z, 0.5),
    "minimum": np.minimum, "maximum": np.maximum, "where": np.where,
}
#: seeded random fields: ``random(seed)`` uniform on [0, 1), ``normal(seed)`` standard normal, one
#: independent value per site in site order (numpy's default generator seeded with the integer
#: ``seed``: the same seed gives the same field, and a site's value does not depend on how many
#: sites follow it)
RANDOM = {"random": lambda rng, n: rng.random(n), "normal": lambda rng, n: rng.standard_normal(n)}
CONSTANTS = {"pi": math.pi, "e": math.e}
VARIABLES = ("x", "y", "n", "i", "j")
MAX_LENGTH = 2000
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide,
           ast.Pow: np.power}
_COMPARE = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
            ast.Eq: np.equal, ast.NotEq: np.not_equal}


def parse_expression(text: str) -> ast.Expression:
    """The checked syntax tree of ``text``; ValueError naming what is not allowed."""
    if len(text) > MAX_LENGTH:
        raise ValueError(f"expression longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ValueError(f"not an expression: {exc.msg} in {text!r}") from None
    for node in ast.walk(tree):
        if isinstance(node, (ast.Expression, ast.Load, ast.UnaryOp, ast.USub, ast.UAdd, ast.IfExp)):
            continue
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            continue
        if type(node) in _BINARY:
            continue
        if isinstance(node, ast.Compare) and all(type(o) in _COMPARE for o in node.ops):
            continue
        if type(node) in _COMPARE:
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            continue
        if isinstance(node, ast.Name) and (node.id in VARIABLES or node.id in CONSTANTS or node.id in FUNCTIONS
                                           or node.id in RANDOM):
            continue
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS \
                and not node.keywords:
            continue
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in RANDOM:
            _seed(node)
            continue
        what = node.id if isinstance(node, ast.Name) else type(node).__name__
        raise ValueError(f"{what!r} is not allowed in an expression (allowed: numbers, {', '.join(VARIABLES)}, "
                         f"{', '.join(CONSTANTS)}, + - * / **, comparisons, 'a if c else b', the "
                         f"functions {', '.join(sorted(FUNCTIONS))}, and the random fields "
                         f"{', '.join(f'{r}(seed)' for r in RANDOM)})")
    for node in ast.walk(tree):  # a function name only as the callee, a variable never called
        if isinstance(node, ast.Name) and (node.id in FUNCTIONS or node.id in RANDOM):
            if not any(isinstance(p, ast.Call) and p.func is node for p in ast.walk(tree)):
                raise ValueError(f"function {node.id!r} must be called")
    return tree


def _seed(call: ast.Call) -> int:
    """The seed of ``random(seed)``/``normal(seed)``: one non-negative integer literal."""
    args = call.args
    if call.keywords or len(args) != 1 or not isinstance(args[0], ast.Constant) \
            or type(args[0].value) is not int or args[0].value < 0:
        raise ValueError(f"{call.func.id}(seed) takes one seed, a non-negative integer such as "
                         f"{call.func.id}(7)")
    return args[0].value


def _eval(node, env: dict):
    if isinstance(node, ast.Expression):
        return _eval(node.body, env)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id] if node.id in env else CONSTANTS[node.id]
    if isinstance(node, ast.UnaryOp):
        v = _eval(node.operand, env)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_eval(node.left, env), _eval(node.right, env))
    if isinstance(node, ast.Compare):
        left, out = _eval(node.left, env), True
        for op, comp in zip(node.ops, node.comparators):
            right = _eval(comp, env)
            out = np.logical_and(out, _COMPARE[type(op)](left, right))
            left = right
        return out
    if isinstance(node, ast.IfExp):
        return np.where(_eval(node.test, env), _eval(node.body, env), _eval(node.orelse, env))
    if isinstance(node, ast.Call) and node.func.id in RANDOM:
        return RANDOM[node.func.id](np.random.default_rng(_seed(node)), np.size(env["n"]))
    if isinstance(node, ast.Call):
        return FUNCTIONS[node.func.id](*(_eval(a, env) for a in node.args))
    raise ValueError(f"cannot evaluate {type(node).__name__}")  # parse_expression let nothing else in


def evaluate(text: str, n_sites: int, **variables: np.ndarray) -> np.ndarray:
    """The expression on every site: a float array of shape (n_sites,); ValueError if it is not
    finite everywhere or has the wrong shape."""
    tree = parse_expression(text)
    with np.errstate(all="ignore"):
        try:
            out = np.broadcast_to(np.asarray(_eval(tree, variables), float), (n_sites,)).copy()
        except (TypeError, ValueError) as exc:
            raise ValueError(f"expression {text!r}: {exc}") from None
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise ValueError(f"expression {text!r} is not finite at sites {bad[:5].tolist()}")
    return out


Expression = Annotated[str, Field(description="safe expression of x, y (m), n, i, j (config.initial)")]


class FieldInit(Strict):
    """Initial value (SI units of the field: m or rad) and rate (per s) of one field on every site."""

    field: str = Field(description="a field of the model: u, v, theta, ...")
    value: Expression | None = None
    rate: Expression | None = None
    table: str | None = Field(None, description="CSV with columns (site or x), value[, rate]; relative "
                                               "to the config file")

    @field_validator("value", "rate")
    @classmethod
    def _parses(cls, text: str | None) -> str | None:
        if text is not None:
            parse_expression(text)
        return text

    @field_validator("table")
    @classmethod
    def _relative_to_config(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return None
        base = (info.context or {}).get("base_dir")
        p = Path(value).expanduser()
        p = p if p.is_absolute() or base is None else (Path(base) / p).resolve()
        if not p.is_file():
            raise ValueError(f"table file {str(p)!r} not found")
        return str(p)

    @model_validator(mode="after")
    def _source(self):
        if self.table is not None and (self.value is not None or self.rate is not None):
            raise ValueError("give a table or expressions (value, rate), not both")
        if self.table is None and self.value is None and self.rate is None:
            raise ValueError("give value and/or rate expressions, or a table")
        return self


class TodaSoliton(Strict):
    """The exact Toda soliton (docs/physics.md §2) of a mass chain with a Toda bond."""

    kind: Literal["toda_soliton"]
    kappa: Positive = Field(description="inverse width (per site); speed sqrt(ab/m) sinh κ/κ sites per unit time")
    center_site: Finite
    direction: Literal[1, -1] = 1


class TodaTwoSoliton(Strict):
    """The exact Toda two-soliton (Hirota's τ function, docs/physics.md §2): two solitons centred on
    ``center_site`` (the asymptotic centres: also overlapping, mid-collision) moving ``direction``."""

    kind: Literal["toda_two_soliton"]
    kappa: tuple[Positive, Positive]
    center_site: tuple[Finite, Finite]
    direction: tuple[Literal[1, -1], Literal[1, -1]] = (1, -1)


class Sech2Pulse(Strict):
    """The long-wave sech² solitary wave of a polynomial (k1, k2) bond (docs/physics.md §2)."""

    kind: Literal["sech2_pulse"]
    strain: Finite = Field(description="peak bond strain D_m/a (sign of k2: tensile for a softening bond)")
    center_site: Finite
    direction: Literal[1, -1] = 1


class FpuBetaPulse(Strict):
    """The long-wave sech (mKdV) solitary wave of an FPU-β (k1, k3 > 0, k2 = 0) polynomial bond (§2)."""

    kind: Literal["fpu_beta_pulse"]
    strain: Finite = Field(description="peak bond strain D_m/a (either sign); width sqrt(k1/(6 k3))/|D_m| sites")
    center_site: Finite
    direction: Literal[1, -1] = 1


class TanhFront(Strict):
    """The damped bistable front (L/2)(1 − tanh((x − X)/w)) of a bistable_cubic chain (§2), moving at
    its predicted speed; ``speed: static`` places the kink (a saddle) at rest."""

    kind: Literal["tanh_front"]
    center_site: Finite
    direction: Literal[1, -1] = 1
    speed: Literal["theory", "static"] = "theory"


class HertzKdvPulse(Strict):
    """The weak (KdV) solitary wave of a precompressed Hertz chain (exponent 3/2; Nesterenko, §2)."""

    kind: Literal["hertz_kdv_pulse"]
    amplitude_ratio: Positive = Field(description="peak excess strain over the precompression strain ξ0 "
                                                  "(ε ≪ 1; width sqrt(2/ε) sites, speed c0 sqrt(1 + ε/6))")
    center_site: Finite
    direction: Literal[1, -1] = 1


class KinkLaunch(Strict):
    """The sine-Gordon or φ⁴ kink of a linear chain on a sine or phi4 substrate (§2): at rest, or
    driven by a constant_force against viscous damping at its terminal (McLaughlin–Scott) speed,
    the well the force favours behind it."""

    kind: Literal["kink"]
    center_site: Finite
    direction: Literal[1, -1] = 1
    speed: Literal["theory", "static"] = "theory"


Launch = Annotated[Union[TodaSoliton, TodaTwoSoliton, Sech2Pulse, FpuBetaPulse, HertzKdvPulse, KinkLaunch, TanhFront],
                   Field(discriminator="kind")]


class Pin(Strict):
    """Sites whose field is held at its initial value (inverse mass 0)."""

    field: str
    sites: list[Annotated[int, Field(ge=0)]] = Field(min_length=1)


class Initial(Strict):
    """The initial state, added to the excitation's (fields, then launches, then pins)."""

    fields: list[FieldInit] = Field(default_factory=list)
    launch: list[Launch] = Field(default_factory=list)
    pinned: list[Pin] = Field(default_factory=list)
    from_run: str | None = Field(None, description="run directory whose last frame is the initial state")

    @field_validator("from_run")
    @classmethod
    def _run_exists(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return None
        from flexmm.io.identify import RunNotFound, run_dataset

        p = Path(value).expanduser()
        try:  # a run's dataset: not a missing path, an analysis or sweep file, a foreign or damaged one
            run_dataset(p)
        except RunNotFound as exc:
            raise ValueError(f"{exc} (from_run names a finished run directory)") from None
        return str(p.resolve())
