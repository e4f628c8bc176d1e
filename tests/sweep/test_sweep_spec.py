"""Sweep specs: grid / zip / ranges / inline --vary, and errors that say where the problem is."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.config import ConfigError
from flexmm.sweep.spec import load_sweep, parse_vary, spec_from_scene

REPO = Path(__file__).resolve().parents[2]
LEGO = REPO / "configs" / "lego_vector_soliton.yaml"


def write(tmp_path: Path, text: str, name: str = "sweep.yaml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def issues(exc: pytest.ExceptionInfo) -> list[str]:
    return [str(i) for i in exc.value.issues]


def test_grid_is_the_cartesian_product(tmp_path):
    spec = load_sweep(write(tmp_path, f"""\
        base: {LEGO}
        vary:
          grid:
            excitation.velocity_m_s: [1.0, 2.0]
            excitation.angular_velocity_rad_s: {{start: 0, stop: 300, num: 3}}
        """))
    assert spec.mode == "grid" and spec.shape == (2, 3)
    points = spec.points()
    assert len(points) == 6
    assert points[1].index == (0, 1)
    assert points[1].params == {"excitation.velocity_m_s": 1.0, "excitation.angular_velocity_rad_s": 150}
    assert points[5].scene.excitation.angular_velocity_rad_s == 300.0
    assert len({p.hash for p in points}) == 6


def test_zip_pairs_lists_and_log_range(tmp_path):
    spec = load_sweep(write(tmp_path, f"""\
        base: {LEGO}
        vary:
          zip:
            excitation.velocity_m_s: {{start: 0.1, stop: 10, num: 3, scale: log}}
            excitation.angular_velocity_rad_s: [10, 100, 1000]
        """))
    assert spec.mode == "zip" and spec.shape == (3,)
    assert spec.axes[0].values == (0.1, 1.0, 10.0) and spec.axes[0].scale == "log"
    points = spec.points()
    assert [p.scene.excitation.angular_velocity_rad_s for p in points] == [10, 100, 1000]


def test_name_defaults_to_file_stem_and_base_is_relative_to_the_spec(tmp_path):
    (tmp_path / "cfg").mkdir()
    (tmp_path / "cfg" / "scene.yaml").write_text(LEGO.read_text())
    (tmp_path / "sw").mkdir()
    spec = load_sweep(write(tmp_path / "sw", """\
        base: ../cfg/scene.yaml
        set: {lattice.n_units: 50}
        vary: {grid: {excitation.velocity_m_s: "1,2"}}
        """, name="my_sweep.yaml"))
    assert spec.name == "my_sweep"
    assert all(p.scene.lattice.n_units == 50 for p in spec.points())


def test_inline_base_mapping(tmp_path):
    base = textwrap.indent(LEGO.read_text(), "  ")
    spec = load_sweep(write(tmp_path, f"base:\n{base}\nvary:\n  grid:\n    lattice.n_units: [40, 60]\n"))
    assert [p.scene.lattice.n_units for p in spec.points()] == [40, 60]


@pytest.mark.parametrize("text, values, scale", [
    ("0.1:1.0:10", (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0), "linear"),
    ("log:1e-3:1e-1:3", (0.001, 0.01, 0.1), "log"),
    ("0.5,1,2.5", (0.5, 1, 2.5), "linear"),
    ("3", (3,), "linear"),
    ("100:400:4", (100, 200, 300, 400), "linear"),
])
def test_inline_vary_forms(text, values, scale):
    axis = parse_vary(f"excitation.velocity_m_s={text}")
    assert axis.values == values and axis.scale == scale
    assert axis.path == "excitation.velocity_m_s"


@pytest.mark.parametrize("raw, message", [
    ("excitation.velocity_m_s", "expected PATH="),
    ("excitation.velocity_m_s=1:2", ("excitation.velocity_m_s: got '1:2' (str); expected: start:stop:num, "
                                    "log:start:stop:num or a,b,c")),
    ("excitation.velocity_m_s=log:0:1:3", "expected: a log range with start > 0 and stop > 0"),
    ("excitation.velocity_m_s=1:2:0", ("excitation.velocity_m_s.num: got 0 (int); expected: input should be greater "
                                      "than or equal to 1")),
    ("excitation.velocity_m_s=a:2:3", "excitation.velocity_m_s.start: got 'a' (str); expected: a finite number"),
    ("excitation..velocity_m_s=1,2", "empty key"),
    ("excitation.velocity_m_s=1,,2", "expected: a list without empty values"),
])
def test_inline_vary_errors(raw, message):
    with pytest.raises(ConfigError) as exc:
        parse_vary(raw)
    assert message in str(exc.value) and "--vary" in str(exc.value)


def test_inline_sweep_from_scene_grid_and_zip():
    grid = spec_from_scene(LEGO, ["excitation.velocity_m_s=1,2", "lattice.n_units=40,60,80"])
    assert grid.shape == (2, 3) and grid.name == "lego_vector_soliton_sweep"
    zipped = spec_from_scene(LEGO, ["excitation.velocity_m_s=1,2", "lattice.n_units=40,60"], zip_axes=True)
    assert zipped.shape == (2,)
    with pytest.raises(ConfigError, match="equal lengths"):
        spec_from_scene(LEGO, ["excitation.velocity_m_s=1,2", "lattice.n_units=40,60,80"], zip_axes=True)


def test_bad_value_is_reported_at_the_sweep_line(tmp_path):
    path = write(tmp_path, f"""\
        base: {LEGO}
        vary:
          grid:
            excitation.velocity_m_s: [1.0, fast]
        """)
    with pytest.raises(ConfigError) as exc:
        load_sweep(path).points()
    [msg] = issues(exc)
    assert msg.startswith(f"{path}:4: excitation.velocity_m_s:")
    assert "'fast'" in msg and "point excitation.velocity_m_s='fast'" in msg


def test_unknown_parameter_suggests_the_field(tmp_path):
    path = write(tmp_path, f"""\
        base: {LEGO}
        vary:
          grid:
            excitation.velocity_ms: [1.0, 2.0]
        """)
    with pytest.raises(ConfigError) as exc:
        load_sweep(path).points()
    [msg] = issues(exc)
    assert f"{path}:4" in msg and "did you mean 'velocity_m_s'" in msg and "at every point (2)" in msg


def test_inline_vary_value_error_names_the_argument():
    spec = spec_from_scene(LEGO, ["lattice.n_units=40,1"])
    with pytest.raises(ConfigError) as exc:
        spec.points()
    [msg] = issues(exc)
    assert msg.startswith("--vary lattice.n_units=40,1: lattice.n_units:") and "point lattice.n_units=1" in msg


def test_cross_field_rule_and_fixed_set_error(tmp_path):
    path = write(tmp_path, f"""\
        base: {LEGO}
        set:
          excitation: {{kind: soliton, amplitude_rad: 0.5, center_site: 10}}
        vary:
          grid:
            lattice.n_units: [40, 60]
        """)
    with pytest.raises(ConfigError) as exc:
        load_sweep(path).points()
    assert any("lattice.left is 'driven'" in m and "at every point" in m for m in issues(exc))


def test_spec_structure_errors(tmp_path):
    path = write(tmp_path, """\
        base: no_such_file.yaml
        colour: blue
        vary:
          grid:
            excitation.velocity_m_s: {start: 1, stop: 2}
        analysis: {feild: theta}
        """)
    with pytest.raises(ConfigError) as exc:
        load_sweep(path)
    msgs = issues(exc)
    assert [i.line for i in exc.value.issues] == [1, 2, 5, 6], msgs  # all of them, in the file's order
    assert any(m.startswith(f"{path}:1: base:") and "cannot read file" in m for m in msgs)
    assert f"{path}:2: colour: unknown key; expected one of: analysis, base, description, keep, name, set, vary" in msgs
    assert any(m.startswith(f"{path}:5: vary.grid.excitation.velocity_m_s:")
               and "expected: num, which a range also needs (or explicit values: [...])" in m for m in msgs)
    assert (f"{path}:6: analysis.feild: unknown key; did you mean 'field'? expected one of: "
            "field, jump, kind, row, threshold_fraction") in msgs


GRID = "vary: {grid: {lattice.n_units: [40]}}\n"
ENTRY = "vary:\n  grid:\n    excitation.velocity_m_s: "


@pytest.mark.parametrize("body, where, message", [
    # the vary section
    ("vary: {}", "2: vary", "expected: exactly one of grid (a Cartesian product) or zip (paired lists)"),
    ("vary: {grid: {a.b: [1]}, zip: {c.d: [1]}}", "2: vary.grid", "expected: exactly one of grid"),
    ("vary: {product: {a.b: [1]}}", "2: vary.product", "unknown key; expected one of: grid, zip"),
    ("vary: {zip: {excitation.velocity_m_s: [1, 2], lattice.n_units: [40]}}", "2: vary",
     "expected: zipped lists of equal lengths (got excitation.velocity_m_s: 2, lattice.n_units: 1)"),
    ("vary: {grid: {a..b: [1]}}", "2: vary.grid", "expected: dotted paths of non-empty keys (got 'a..b')"),
    ("vary: {grid: {}}", "2: vary.grid", "expected: dictionary should have at least 1 item"),
    # the values of one parameter
    (ENTRY + "{start: 1, stop: 2, num: three}", "4: vary.grid.excitation.velocity_m_s.num",
     "got 'three' (str); expected: input should be a valid integer"),
    (ENTRY + "{start: 1, stop: fast, num: 3}", "4: vary.grid.excitation.velocity_m_s.stop",
     "got 'fast' (str); expected: a finite number"),
    (ENTRY + "{start: 1, stop: 2, num: 3, scale: logarithmic}", "4: vary.grid.excitation.velocity_m_s.scale",
     "got 'logarithmic' (str); expected: input should be 'linear' or 'log'"),
    (ENTRY + "{start: 0, stop: 2, num: 3, scale: log}", "4: vary.grid.excitation.velocity_m_s.start",
     "expected: a log range with start > 0 and stop > 0 (got 0, 2)"),
    (ENTRY + "{values: [1, 2], num: 3}", "4: vary.grid.excitation.velocity_m_s.values",
     "expected: either values or start, stop and num"),
    (ENTRY + "{start: 1, stop: 2, num: 3, step: 1}", "4: vary.grid.excitation.velocity_m_s.step",
     "unknown key; did you mean 'stop'? expected one of: num, scale, start, stop, values"),
    (ENTRY + "{values: []}", "4: vary.grid.excitation.velocity_m_s.values",
     "expected: list should have at least 1 item"),
    (ENTRY + '"1:2"', "4: vary.grid.excitation.velocity_m_s", "expected: start:stop:num, log:start:stop:num or a,b,c"),
    # the other sections
    (GRID + "analysis: {kind: pulses}", "3: analysis.kind",
     "got 'pulses' (str); expected: input should be 'auto', 'pulse', 'front', 'driven' or 'modes'"),
    (GRID + "analysis: {threshold_fraction: 2}", "3: analysis.threshold_fraction",
     "got 2 (int); expected: input should be less than or equal to 1"),
    (GRID + "analysis: {field: 'theta; rm'}", "3: analysis.field",
     "got 'theta; rm' (str); expected: a field name: theta, u, u_dot, strain[:NAME] or velocity[:NAME]"),
    (GRID + "analysis: theta", "3: analysis", "got 'theta' (str); expected: input should be a valid dictionary"),
    (GRID + "name: my sweep", "3: name", "got 'my sweep' (str); expected: string should match pattern"),
    (GRID + "set: [lattice.n_units]", "3: set",
     "got ['lattice.n_units'] (list); expected: input should be a valid dictionary"),
    ("base: 3\n" + GRID, "1: base",
     "got 3 (int); expected: a scene file path (relative to this file) or an inline scene mapping"),
])
def test_spec_errors_name_line_field_and_expectation(tmp_path, body, where, message):
    path = write(tmp_path, body + "\n" if body.startswith("base:") else f"base: {LEGO}\n{body}\n")
    with pytest.raises(ConfigError) as exc:
        load_sweep(path)
    [msg] = issues(exc)
    assert msg.startswith(f"{path}:{where}: ") and message in msg, msg


def test_analysis_kinds_are_those_the_analysis_dispatches_on():
    from flexmm.analysis.report.analyze import KINDS
    from flexmm.config.analysis import AnalysisOptions

    assert AnalysisOptions.model_json_schema()["properties"]["kind"]["enum"] == list(KINDS)


@pytest.mark.parametrize("spec", sorted((REPO / "sweeps").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_sweep_validates(spec):
    sw = load_sweep(spec)
    points = sw.points()
    assert len(points) == sw.n_points > 1 and sw.name == spec.stem
    assert all(len(a.values) > 1 for a in sw.axes)


def test_cli_reports_errors_with_exit_code_2(tmp_path):
    path = write(tmp_path, f"base: {LEGO}\nvary: {{grid: {{excitation.velocity_m_s: [1.0, fast]}}}}\n")
    res = CliRunner().invoke(app, ["sweep", str(path), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2
    assert f"{path}:2: excitation.velocity_m_s" in res.output
    res = CliRunner().invoke(app, ["sweep", str(LEGO)])
    assert res.exit_code == 2 and "--vary" in res.output


def test_cli_validate_checks_the_spec_and_every_point(tmp_path):
    res = CliRunner().invoke(app, ["validate", str(REPO / "sweeps" / "lego_speed_vs_amplitude.yaml")])
    assert res.exit_code == 0 and "ok — sweep lego_speed_vs_amplitude: 22 points" in res.output
    bad_spec = write(tmp_path, f"base: {LEGO}\nvary: {{grid: {{lattice.n_units: [40]}}}}\nanalysis: {{kind: x}}\n")
    res = CliRunner().invoke(app, ["validate", str(bad_spec)])
    assert res.exit_code == 2 and f"{bad_spec}:3: analysis.kind: got 'x' (str)" in res.output
    bad_point = write(tmp_path, f"base: {LEGO}\nvary: {{grid: {{lattice.n_units: [40, 1]}}}}\n", "p.yaml")
    res = CliRunner().invoke(app, ["validate", str(bad_point)])
    assert res.exit_code == 2 and f"{bad_point}:2: lattice.n_units: got 1 (int)" in res.output
    assert "[at point lattice.n_units=1]" in res.output and "Traceback" not in res.output


def test_cli_dry_run_lists_points_without_running(tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sweep", str(LEGO), "--vary", "excitation.velocity_m_s=1:3:3",
                                   "--out", str(out), "--dry-run"])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.stdout.splitlines() if "pending" in ln]
    assert len(lines) == 3 and "excitation.velocity_m_s=2" in lines[1]
    assert not (out / "points").exists()
