"""Malformed configs fail with a readable report: file:line, dotted path, what was expected.

The expected line of each case is found by searching the YAML text for the offending key (an
oracle independent of the loader's line map). The same cases go through the CLI (exit code 2,
no traceback). A hypothesis test mutates a valid config at random: validation must either
succeed or raise ConfigError, and ``flexmm validate`` must never print a traceback.
"""

from __future__ import annotations

import copy
import textwrap
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.config import ConfigError, load_scene, scene_from_dict
from flexmm.models import MODELS

BASE = textwrap.dedent("""\
    # a small LEGO chain (values of configs/lego_vector_soliton.yaml)
    name: small
    lattice:
      kind: rotating_squares_chain
      n_units: 20
      a_m: 0.016
      k_long_n_per_m: 71690
      k_shear_n_per_m: 1326.98
      k_rot_n_m_per_rad: 7.038e-4
      mass_kg: 4.52e-3
      inertia_kg_m2: 8.7814e-8
      n_lateral: 1
      left: driven
    excitation:
      kind: impact
      velocity_m_s: 3.0
    solver:
      duration_s: 1e-3
    """)
IMPACT = "excitation:\n  kind: impact\n  velocity_m_s: 3.0\n"


def variant(*pairs: tuple[str, str]) -> str:
    text = BASE
    for old, new in pairs:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


# name -> (yaml text, text marking the offending line (None: no line), dotted path, expected fragments)
CASES = {
    "typo_key": (variant(("n_units: 20", "n_unit: 20")), "n_unit:", "lattice.n_unit",
                 ["unknown key", "did you mean 'n_units'"]),
    "unknown_section": (variant(("solver:", "solvr:")), "solvr:", "solvr", ["did you mean 'solver'"]),
    "wrong_type": (variant(("n_units: 20", "n_units: many")), "n_units:", "lattice.n_units",
                   ["got 'many'", "valid integer"]),
    "fractional_int": (variant(("n_units: 20", "n_units: 2.5")), "n_units:", "lattice.n_units",
                       ["got 2.5 (float)", "expected an integer"]),
    "boolean_int": (variant(("n_units: 20", "n_units: true")), "n_units:", "lattice.n_units",
                    ["got True (bool)", "expected an integer (a boolean is not a number)"]),
    "float_int": (variant(("n_units: 20", "n_units: 2e1")), "n_units:", "lattice.n_units",
                  ["got 20.0 (float)", "expected an integer", "e.g. 20"]),
    "boolean_float": (variant(("mass_kg: 4.52e-3", "mass_kg: false")), "mass_kg:", "lattice.mass_kg",
                      ["got False (bool)", "expected a number"]),
    "negative_mass": (variant(("mass_kg: 4.52e-3", "mass_kg: -4.52e-3")), "mass_kg:", "lattice.mass_kg",
                      ["-0.00452", "greater than 0"]),
    "shaker_20khz": (variant((IMPACT, "excitation:\n  kind: shaker\n  frequency_hz: 20e3\n  amplitude_n: 1.0\n")),
                     "frequency_hz:", "excitation.frequency_hz", ["20000", "less than or equal to 10000"]),
    "two_shaker_amplitudes": (
        variant((IMPACT, "excitation:\n  kind: shaker\n  frequency_hz: 200\n  amplitude_m: 1e-4\n  amplitude_n: 1.0\n")),
        "amplitude_m:", "excitation.amplitude_m", ["exactly one of amplitude_m", "amplitude_n"]),
    "broken_yaml": (variant(("  mass_kg: 4.52e-3", "  mass_kg: 4.52e-3: 1")), "mass_kg:", "",
                    ["invalid YAML", "mapping values are not allowed"]),
    "tab_indent": (variant(("  a_m: 0.016", "\ta_m: 0.016")), "a_m:", "", ["invalid YAML", "'\\t'"]),
    "duplicate_key": (variant(("  a_m: 0.016\n", "  a_m: 0.016\n  a_m: 0.017\n")), "a_m: 0.017", "lattice.a_m",
                      ["duplicate key", "first given at line"]),
    "missing_section": (variant(("solver:\n  duration_s: 1e-3\n", "")), "name:", "solver",
                        ["required field is missing"]),
    "missing_field": (variant(("  mass_kg: 4.52e-3\n", "")), "lattice:", "lattice.mass_kg",
                      ["required field is missing"]),
    "section_not_mapping": (variant(("solver:\n  duration_s: 1e-3\n", "solver: 5\n")), "solver:", "solver",
                            ["got 5", "valid dictionary"]),
    "unknown_lattice_kind": (variant(("kind: rotating_squares_chain", "kind: rotating_square_chain")),
                             "kind: rotating_square", "lattice.kind",
                             ["rotating_square_chain", *(repr(k) for k in MODELS)]),
    "unknown_excitation_kind": (variant(("kind: impact", "kind: hammer")), "kind: hammer", "excitation.kind",
                                ["'hammer'", "'impact'", "'shaker'", "'boundary_displacement'", "'soliton'"]),
    "theta0_out_of_range": (variant(("  a_m: 0.016\n", "  a_m: 0.016\n  theta0_rad: 1.0\n")), "theta0_rad:",
                            "lattice.theta0_rad", ["|θ0| < π/4", "1.0"]),
    "driven_end_without_excitation": (variant((IMPACT, "excitation:\n  kind: none\n")), "left: driven",
                                      "lattice.left", ["'driven'", "no impact, shaker, boundary_displacement or boundary_force"]),
    "soliton_center_outside": (
        variant((IMPACT, "excitation:\n  kind: soliton\n  amplitude_rad: 0.3\n  center_site: 25\n"),
                ("left: driven", "left: free")),
        "center_site:", "excitation.center_site", ["center_site=25", "outside 0..19"]),
    "seed_site_outside": (BASE + "imperfection:\n  kind: rotation_seed\n  theta_rad: 0.01\n  sites: [0, 99]\n",
                          "sites:", "imperfection.sites", ["[99]", "outside 0..19"]),
    "unknown_output_field": (BASE + "output:\n  fields: [u, phi]\n", "fields:", "output.fields",
                             ["'phi'", "'u'", "'theta'"]),
    "viscous_two_ways": (BASE + "damping:\n  viscous:\n    damping_ratio: 0.1\n    coefficient_n_s_per_m: 1.0\n",
                         "coefficient_n_s_per_m:", "damping.viscous.coefficient_n_s_per_m",
                         ["exactly one of coefficient_n_s_per_m or damping_ratio"]),
    "empty_file": ("", None, "", ["expected a mapping of sections"]),
}


def line_of(text: str, marker: str | None) -> int | None:
    if marker is None:
        return None
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if marker in line]
    assert len(hits) == 1, (marker, hits)
    return hits[0]


@pytest.fixture(params=list(CASES))
def bad_config(request, tmp_path):
    text, marker, path, fragments = CASES[request.param]
    f = tmp_path / f"{request.param}.yaml"
    f.write_text(text)
    return f, line_of(text, marker), path, fragments


def test_config_error_report(bad_config):
    f, line, path, fragments = bad_config
    with pytest.raises(ConfigError) as err:
        load_scene(f)
    report = str(err.value)
    where = f"{f}:{line}:" if line else f"{f}:"
    assert where in report, report
    assert any(i.path == path and (i.line == line or not line) for i in err.value.issues), report
    for fragment in fragments:
        assert fragment in report, (fragment, report)


def test_config_error_through_cli(bad_config):
    f, line, path, fragments = bad_config
    result = CliRunner().invoke(app, ["validate", str(f)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    where = f"{f}:{line}:" if line else str(f)
    assert where in result.output
    assert path in result.output and fragments[0] in result.output


def test_missing_file(tmp_path):
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read file: No such file"):
        load_scene(missing)
    result = CliRunner().invoke(app, ["validate", str(missing)])
    assert result.exit_code == 2 and "nope.yaml" in result.output and "Traceback" not in result.output


def test_exponent_floats_are_numbers(tmp_path):
    """YAML 1.1 reads 1e-3 (no dot) as a string; flexmm's loader reads it as a number."""
    f = tmp_path / "ok.yaml"
    f.write_text(BASE.replace("duration_s: 1e-3", "duration_s: 1e-3\n  dt_s: 2E-6"))
    scene = load_scene(f)
    assert scene.solver.duration_s == 1e-3 and scene.solver.dt_s == 2e-6
    assert scene.lattice.k_rot_n_m_per_rad == 7.038e-4 and scene.lattice.inertia_kg_m2 == 8.7814e-8
    assert load_scene(f, ["solver.dt_s=1e-6"]).solver.dt_s == 1e-6


@pytest.mark.parametrize("override, source, path, fragment", [
    ("lattice.n_units", "--set", "lattice.n_units", "expected KEY.PATH=VALUE"),
    ("=3", "--set", "=3", "empty key path"),
    ("lattice.n_unitz=30", "--set lattice.n_unitz=30", "lattice.n_unitz", "did you mean 'n_units'"),
    ("solver.dt_s=abc", "--set solver.dt_s=abc", "solver.dt_s", "valid number"),
    ("lattice.mass_kg=-1e-3", "--set lattice.mass_kg=-1e-3", "lattice.mass_kg", "greater than 0"),
    ("name.first=3", "--set name.first=3", "name", "valid string"),
])
def test_bad_override(override, source, path, fragment, tmp_path):
    f = tmp_path / "ok.yaml"
    f.write_text(BASE)
    with pytest.raises(ConfigError) as err:
        load_scene(f, [override])
    issue = err.value.issues[0]
    assert (issue.source, issue.line, issue.path) == (source, None, path), str(err.value)
    assert fragment in issue.message
    result = CliRunner().invoke(app, ["validate", str(f), "--set", override])
    assert result.exit_code == 2 and source in result.output and "Traceback" not in result.output


def test_build_time_user_errors_exit_2(tmp_path):
    """Errors found only when building (no soliton of that amplitude, dt too large) are user errors."""
    f = tmp_path / "sol.yaml"
    f.write_text(variant((IMPACT, "excitation:\n  kind: soliton\n  amplitude_rad: 3.0\n  center_site: 10\n"),
                         ("left: driven", "left: free")))
    for extra in ([], ["--set", "excitation.amplitude_rad=0.3", "--set", "solver.dt_s=1e-3"]):
        result = CliRunner().invoke(app, ["validate", str(f), *extra])
        assert result.exit_code == 2, result.output
        assert "Traceback" not in result.output
        assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
        assert ("excitation.amplitude_rad" if not extra else "stable limit") in result.output


@pytest.mark.slow  # a fresh interpreter importing numba/scipy: ~5-10 s on a loaded machine
def test_cli_in_a_real_process_prints_no_traceback(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    f = tmp_path / "bad.yaml"
    f.write_text(CASES["typo_key"][0])
    exe = Path(sys.executable).with_name("flexmm")
    proc = subprocess.run([str(exe), "validate", str(f)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stdout + proc.stderr
    assert f"{f}:{line_of(CASES['typo_key'][0], 'n_unit:')}: lattice.n_unit" in proc.stderr


# ------------------------------------------------------------------ property test
VALID = yaml.safe_load(BASE.replace("n_units: 20", "n_units: 12"))
SCALARS = st.one_of(
    st.integers(-3, 64), st.sampled_from([0, -1, 10**9, 2**63, 20_000_001]),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8), st.booleans(), st.none(),
    st.lists(st.integers(0, 3), max_size=3), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def mappings(d, path=()):
    yield path
    for k, v in d.items():
        if isinstance(v, dict):
            yield from mappings(v, path + (k,))


def leaves(d, path=()):
    for k, v in d.items():
        yield path + (k,)
        if isinstance(v, dict):
            yield from leaves(v, path + (k,))


def get(d, path):
    for k in path:
        d = d[k]
    return d


CONFIGS = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
SHIPPED_DATA = {c.stem: yaml.safe_load(c.read_text()) for c in CONFIGS}


@st.composite
def mutated(draw, bases=None):
    """A config with 1–3 random mutations: ``VALID``, or one of ``bases`` (name -> dict)."""
    d = copy.deepcopy(VALID if bases is None else bases[draw(st.sampled_from(sorted(bases)))])
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["delete", "retype", "junk", "known", "known"]))
        if op == "junk":
            where = draw(st.sampled_from(list(mappings(d))))
            get(d, where)[draw(st.text(min_size=1, max_size=10))] = draw(SCALARS)
            continue
        paths = list(leaves(d))
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = get(d, path[:-1])
        if op == "delete":
            del parent[path[-1]]
        elif op == "retype":
            parent[path[-1]] = draw(SCALARS)
        else:  # a plausible value of another field: exercises cross-field rules
            parent[path[-1]] = draw(st.sampled_from(
                ["free", "fixed", "driven", "shaker", "soliton", "none", "boundary_displacement",
                 0.3, -0.3, 0.0, 1, 2, 25, 1e-9, 1e9, "1e-3", True, 5e-324, 1e-300, 1e300]))
    return d


HYP = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@HYP
@given(mutated())
def test_mutated_configs_validate_or_raise_config_error(data):
    try:
        scene_from_dict(copy.deepcopy(data))
    except ConfigError as exc:
        assert exc.issues and all(str(i) for i in exc.issues)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutated())
def test_cli_validate_never_prints_a_traceback(tmp_path_factory, data):
    f = tmp_path_factory.mktemp("cfg") / "mutated.yaml"
    f.write_text(yaml.safe_dump(data, allow_unicode=True))
    result = CliRunner().invoke(app, ["validate", str(f)])
    assert result.exit_code in (0, 2), (result.output, result.exception)
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert ("error" if result.exit_code else "ok") in result.output


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(SHIPPED_DATA))
def test_every_shipped_config_mutated_validates_or_raises_config_error(data):
    """The schema fuzz over all 31 shipped scenes, not one base config."""
    try:
        scene_from_dict(copy.deepcopy(data), base_dir=Path(__file__).resolve().parents[1] / "configs")
    except ConfigError as exc:
        assert exc.issues and all(str(i) for i in exc.issues)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(SHIPPED_DATA))
def test_mutated_shipped_configs_that_validate_build_or_raise_a_user_error(data):
    """Run-time paths: what validates is built (its cost estimated: the scene itself when small,
    a small copy when large) or refused with a FlexmmError — never another exception."""
    from flexmm.errors import FlexmmError
    from flexmm.plan.cost import check, estimate

    try:
        scene = scene_from_dict(copy.deepcopy(data), base_dir=Path(__file__).resolve().parents[1] / "configs")
    except ConfigError:
        return
    try:
        check(estimate(scene))
    except FlexmmError as exc:
        assert str(exc)
