"""Conditions on named numbers, as a sweep's ``keep: where <condition>`` writes them.

A condition is an expression of names (a point's observables, e.g. ``speed``), numbers,
``+ - * /``, ``abs(...)``, comparisons (``< <= > >= == !=``, chained), ``and``, ``or``, ``not``
and parentheses, e.g. ``speed > 1.5 and abs(amplitude) < 0.3``. It is parsed once (Python's
own grammar, restricted to those forms: nothing else is evaluated), and evaluated on plain
floats. A value that was not measured is NaN: every comparison with it is false.
"""

from __future__ import annotations

import ast
import math
import operator
from dataclasses import dataclass
from typing import Mapping

_COMPARE = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.Eq: operator.eq, ast.NotEq: operator.ne}
_ARITH = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv}
FORMS = "names, numbers, + - * /, abs(), < <= > >= == !=, and, or, not, parentheses"


@dataclass(frozen=True)
class Condition:
    """A parsed condition: its text, the names it reads, its syntax tree."""

    text: str
    names: frozenset[str]
    tree: ast.Expression

    @classmethod
    def parse(cls, text: str) -> Condition:
        """ValueError saying what is wrong (and what is allowed) if ``text`` is not a condition."""
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except SyntaxError as exc:
            raise ValueError(f"cannot parse the condition {text!r} ({exc.msg}); it may use {FORMS}") from None
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Name):
                names.add(node.id)
            elif isinstance(node, ast.Call):
                if not (isinstance(node.func, ast.Name) and node.func.id == "abs" and len(node.args) == 1
                        and not node.keywords):
                    raise ValueError(f"{ast.unparse(node)!r}: the only function is abs(x); a condition may use {FORMS}")
                names.discard("abs")
            elif isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                                     or not isinstance(node.value, (int, float))):
                raise ValueError(f"{ast.unparse(node)}: only numbers are allowed as constants")
            elif not isinstance(node, (ast.Expression, ast.BoolOp, ast.And, ast.Or, ast.UnaryOp, ast.Not, ast.USub,
                                       ast.UAdd, ast.BinOp, ast.Compare, ast.Constant, ast.Load,
                                       *_COMPARE, *_ARITH)):
                raise ValueError(f"{ast.unparse(node) if hasattr(node, 'lineno') else type(node).__name__!r} "
                                 f"is not allowed in a condition; it may use {FORMS}")
        return cls(text.strip(), frozenset(names - {"abs"}), tree)

    def __call__(self, values: Mapping[str, float]) -> bool:
        """The condition's truth for ``values`` (every name it reads must be there)."""
        return bool(_eval(self.tree.body, values))


def _eval(node: ast.AST, values: Mapping[str, float]):
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return float(values[node.id])
    if isinstance(node, ast.Call):
        return abs(_eval(node.args[0], values))
    if isinstance(node, ast.BoolOp):
        parts = (bool(_eval(v, values)) for v in node.values)
        return all(parts) if isinstance(node.op, ast.And) else any(parts)
    if isinstance(node, ast.UnaryOp):
        x = _eval(node.operand, values)
        return (not x) if isinstance(node.op, ast.Not) else (-x if isinstance(node.op, ast.USub) else x)
    if isinstance(node, ast.BinOp):
        a, b = _eval(node.left, values), _eval(node.right, values)
        if isinstance(node.op, ast.Div) and b == 0:
            return math.nan
        return _ARITH[type(node.op)](a, b)
    if isinstance(node, ast.Compare):
        left = _eval(node.left, values)
        for op, right_node in zip(node.ops, node.comparators):
            right = _eval(right_node, values)
            if not _COMPARE[type(op)](left, right):
                return False
            left = right
        return True
    raise ValueError(f"not a condition: {ast.dump(node)}")  # pragma: no cover - parse() allows nothing else
