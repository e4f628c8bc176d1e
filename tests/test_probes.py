"""Probes of the command line: no input a user can give ends in a traceback.

Every reading verb (``analyze``, ``analyze --json -``, ``render``, ``run --from``, ``validate``)
meets every kind of file flexmm may be handed — a run directory and its dataset.nc, an
analysis.nc, a sweep directory and its sweep.nc (also renamed), foreign netCDF files made with
xarray (with and without time/site variables), a truncated dataset, a text file, an empty
file, a dataset with NaN values, a dataset with a field deleted, an empty directory, a missing
path — then every option is given wrong values, and a seeded fuzz (hypothesis) draws options
and environment variables. Each answer must be a result (exit 0), "nothing to measure" (exit
1, analyze), or a user error (exit 2, ``error: ...`` on stderr); never an exception. The
commands run in-process through typer's CliRunner (a few as real processes, which also check
the stderr text a user sees). ``-m slow`` runs a larger fuzz.
"""

from __future__ import annotations

import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.environment import VARIABLES

ROOT = Path(__file__).resolve().parents[1]
LEGO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
#: a run of a few seconds: 60 LEGO units (free far end) for 0.05 s (a pulse forms), velocity Verlet at the
#: stable fraction
TINY_RUN = ["--set", "lattice.n_units=60", "--set", "damping.absorbing=null", "--set", "solver.duration_s=0.05",
            "--set", "output.n_frames=51",
            "--set", "solver.accuracy=null", "--set", "solver.integrator=velocity_verlet"]

runner = CliRunner()


def invoke(*args, env: dict | None = None):
    return runner.invoke(app, [str(a) for a in args], env=env)


def answered(result, *fragments: str, codes=(0, 1, 2)):
    """The command ended by itself (no exception but its exit), with one of ``codes``; a user
    error (2) is printed as ``error: ...`` or as click's usage error; ``fragments`` are in stderr."""
    exc = result.exception
    if exc is not None and not isinstance(exc, SystemExit):
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        pytest.fail(f"traceback:\n{tb}\nstderr:\n{result.stderr}")
    assert "Traceback" not in result.output, result.output
    assert result.exit_code in codes, (result.exit_code, result.output)
    if result.exit_code == 2:
        assert result.stderr.startswith(("error:", "Usage:")), result.stderr
    for f in fragments:
        assert f in result.stderr, (f, result.stderr)
    return result


def user_error(result, *fragments: str):
    return answered(result, *fragments, codes=(2,))


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Every kind of file, made once: a real run, its analysis.nc, a real (pending) sweep.nc, and
    foreign, damaged and unrelated files."""
    from flexmm.sweep import load_sweep
    from flexmm.sweep.combine import write_combined
    from flexmm.sweep.execute import prepare
    from flexmm.sweep.observe import OBSERVABLES

    d = tmp_path_factory.mktemp("probes")
    run = d / "run"
    answered(invoke("run", LEGO, *TINY_RUN, "--out", run, "-q"), codes=(0,))
    answered(invoke("analyze", run, "-q"), codes=(0, 1))
    assert (run / "analysis.nc").is_file()
    spec = d / "tiny_sweep.yaml"
    spec.write_text(f"name: tiny\nbase: {LEGO}\nset:\n  lattice.n_units: 40\n  damping.absorbing: null\n"
                    "vary:\n  grid:\n    excitation.velocity_m_s: [2, 3]\n")
    sweep = d / "sweep"
    sweep.mkdir()
    plan = prepare(load_sweep(spec), sweep)
    plan.store.create_or_check(plan.fingerprint, plan.n_points, list(OBSERVABLES), plan.spec.name)  # laid out, not run
    write_combined(plan)  # a sweep.nc of pending points (nothing run)
    renamed = d / "renamed_sweep.nc"
    renamed.write_bytes((sweep / "sweep.nc").read_bytes())
    ds = xr.load_dataset(run / "dataset.nc", engine="h5netcdf")
    xr.Dataset({"temperature": (("lat", "lon"), np.ones((3, 4)))}).to_netcdf(d / "foreign.nc", engine="h5netcdf")
    xr.Dataset({"theta": (("time", "site"), np.ones((3, 4)))},
               coords={"time": [0.0, 1.0, 2.0], "site": np.arange(4)}).to_netcdf(d / "foreign_ts.nc",
                                                                              engine="h5netcdf")
    nan = ds.copy(deep=True)
    nan["theta"].values[5:, 3] = np.nan
    nan.to_netcdf(d / "nan.nc", engine="h5netcdf")
    ds.drop_vars("theta").to_netcdf(d / "no_theta.nc", engine="h5netcdf")
    raw = (run / "dataset.nc").read_bytes()
    (d / "truncated.nc").write_bytes(raw[: len(raw) // 2])
    (d / "text.nc").write_text("not a dataset\n")
    (d / "empty.nc").write_bytes(b"")
    (d / "empty_dir").mkdir()
    return {"run": run, "run_nc": run / "dataset.nc", "analysis_nc": run / "analysis.nc", "sweep": sweep,
            "sweep_nc": sweep / "sweep.nc", "renamed_sweep": renamed, "foreign": d / "foreign.nc",
            "foreign_ts": d / "foreign_ts.nc", "nan": d / "nan.nc", "no_theta": d / "no_theta.nc",
            "truncated": d / "truncated.nc", "text": d / "text.nc", "empty": d / "empty.nc",
            "empty_dir": d / "empty_dir", "missing": d / "missing", "config": LEGO}


#: what each reading verb must say about each kind of file that is not for it (stderr fragments)
NOT_A_RUN = {
    "analysis_nc": "is an analysis file", "sweep_nc": "sweep's combined dataset",
    "renamed_sweep": "sweep's combined dataset", "sweep": "is a sweep directory",
    "foreign": "did not write as a run", "foreign_ts": "did not write as a run",
    "truncated": "not a readable flexmm dataset", "text": "not a readable flexmm dataset",
    "empty": "not a readable flexmm dataset", "empty_dir": "no dataset.nc in",
    "missing": "no such run directory or file", "config": "not a readable flexmm dataset",
}
#: for analyze: a sweep (directory or sweep.nc of any name) is summarised; damaged runs refused
ANALYZE = {**NOT_A_RUN, "sweep": None, "sweep_nc": None, "renamed_sweep": None,
           "nan": "NaN or infinite", "no_theta": "has no theta, which its run saved"}
KINDS = ["run", "run_nc", *NOT_A_RUN, "nan", "no_theta"]


@pytest.mark.parametrize("kind", KINDS)
def test_analyze_answers_every_file(files, kind, tmp_path):
    res = answered(invoke("analyze", files[kind], "--no-save", "--plot-dir", tmp_path))
    expect = ANALYZE.get(kind)
    if expect is None:
        assert res.exit_code in (0, 1), res.output
    else:
        user_error(res, expect)


@pytest.mark.parametrize("kind", ["run", "analysis_nc", "foreign", "truncated", "nan"])
def test_analyze_json_answers_files(files, kind, tmp_path):
    answered(invoke("analyze", files[kind], "--no-save", "--json", "-", "--plot-dir", tmp_path))


@pytest.mark.parametrize("kind", KINDS)
def test_render_answers_every_file(files, kind, tmp_path):
    res = answered(invoke("render", files[kind], "--time", "0.01", "--out", tmp_path / "f.png", "-q"))
    if kind in NOT_A_RUN:
        user_error(res, NOT_A_RUN[kind])
    elif kind == "nan":  # drawn, with a warning
        answered(res, "warning: ", "theta holds NaN or infinite values", codes=(0,))
    else:
        assert "warning" not in res.stderr, res.stderr


@pytest.mark.parametrize("kind", KINDS)
def test_run_from_answers_every_file(files, kind, tmp_path):
    """``--from`` is checked before anything runs, and its mistakes are reported under --from."""
    if kind in ("run", "run_nc"):
        pytest.skip("a real continuation: tests/test_initial_state.py")
    res = user_error(invoke("run", LEGO, *TINY_RUN, "--from", files[kind], "--out", tmp_path / "x"))
    if kind in ("nan", "no_theta"):  # run datasets, refused when the initial state is built from them
        assert f"initial.from_run {files[kind]}" in res.stderr, res.stderr
        assert ("NaN or infinite" if kind == "nan" else "no field 'theta'") in res.stderr, res.stderr
    else:
        assert f"--from {files[kind]}" in res.stderr and "--set initial.from_run" not in res.stderr, res.stderr


@pytest.mark.parametrize("verb", ["validate", "plan", "run", "sweep", "stability", "bands", "compare", "bench", "fit",
                                  "design"])
@pytest.mark.parametrize("kind", ["run_nc", "analysis_nc", "sweep_nc", "text", "empty", "foreign", "empty_dir"])
def test_config_verbs_answer_files_that_are_not_configs(files, verb, kind, tmp_path):
    user_error(invoke(verb, files[kind], *(["--out", tmp_path / "o"] if verb in ("run", "sweep") else [])))


BAD_OPTIONS = [
    # config values through --set: booleans and floats are not integers, bounds, cross-field rules
    (("validate", LEGO, "--set", "lattice.n_units=true"), "expected an integer (a boolean is not a number)"),
    (("validate", LEGO, "--set", "output.n_frames=1e7"), "expected an integer"),
    (("validate", LEGO, "--set", "output.n_frames=5000000"), "less than or equal to 1000000"),
    (("validate", LEGO, "--set", "output.site_stride=900"), "saves only unit 0 of the 900 units"),
    (("validate", LEGO, "--set", "solver.threads=1000"), "less than or equal to 256"),
    (("validate", LEGO, "--set", "solver.duration_s=yes"), "expected a number (a boolean is not a number)"),
    (("validate", LEGO, "--set", "solver.duration_s=nan"), "solver.duration_s"),
    (("validate", LEGO, "--set", "lattice"), "expected KEY.PATH=VALUE"),
    (("validate", LEGO, "--set", "lattice.n_unitz=3"), "did you mean 'n_units'"),
    (("plan", LEGO, "--fidelity", "chains"), "--fidelity 'chains': expected one of auto, full, chain, continuum"),
    (("run", LEGO, "--fidelity", ""), "--fidelity ''"),
    (("run", LEGO, "--analysis", "pulses"), "--analysis"),
    (("run", LEGO, "--out", "/proc/flexmm-probe"), "cannot create output directory"),
    (("compare", LEGO, "--fidelity", "full"), "--fidelity takes two of"),
    (("analyze", "RUN", "--field", "nope"), "no field 'nope'"),
    (("analyze", "RUN", "--analysis", "pulsar"), "--analysis pulsar"),
    (("analyze", "RUN", "--row", "-1"), "--row -1"),
    (("analyze", "RUN", "--threshold", "5"), "--threshold 5"),
    (("analyze", "RUN", "--threshold", "nan"), "--threshold nan"),
    (("analyze", "RUN", "--threshold", "abc"), ""),
    (("render", "RUN", "--sites", "5:1"), "--sites '5:1'"),
    (("render", "RUN", "--sites", "a:b"), "--sites 'a:b'"),
    (("render", "RUN", "--time", "-1"), "--time"),
    (("render", "RUN", "--time", "soon"), "--time"),
    (("render", "RUN", "--clim", "1:inf"), "--clim"),
    (("render", "RUN", "--color", "nope"), "nope"),
    (("render", "RUN", "--shape", "circle"), "circle"),
    (("render", "RUN", "--out", "OUT/x.bmp"), "x.bmp"),
    (("render", "RUN", "--fps", "0"), "--fps"),
    (("render", "RUN", "--width", "-5"), "--width"),
    (("render", "RUN", "--exaggerate", "nan"), "--exaggerate"),
    (("sweep", LEGO, "--vary", "lattice.n_units"), "--vary"),
    (("sweep", LEGO, "--vary", "lattice.n_units=100:200:4", "--dry-run", "--out", "OUT/s"), "expected an integer"),
    (("stability", LEGO, "--set", "solver.dt_s=-1"), "solver.dt_s"),
]


@pytest.mark.parametrize("args, fragment", BAD_OPTIONS, ids=[" ".join(map(str, a[0][::-1][:3])) for a in BAD_OPTIONS])
def test_every_option_given_a_wrong_value(files, tmp_path, args, fragment):
    args = [str(files["run"]) if a == "RUN" else str(a).replace("OUT", str(tmp_path)) for a in args]
    if args[0] == "render" and "--out" not in args:
        args += ["--out", str(tmp_path / "f.png")]
    user_error(invoke(*args), fragment)


@pytest.mark.parametrize("name", sorted(VARIABLES))
@pytest.mark.parametrize("value", ["abc", "-1", "0", "nan", "inf", "1e999", "true", " "])
def test_environment_variables_are_checked(name, value):
    res = answered(invoke("validate", LEGO, env={name: value}))
    try:
        VARIABLES[name].parse(value.strip())
        ok = bool(value.strip())
    except (ValueError, OverflowError):
        ok = False
    if ok or not value.strip():  # an empty value is unset
        assert res.exit_code == 0, res.stderr
    else:
        user_error(res, f"environment variable {name}={value!r}: expected {VARIABLES[name].expected}")


def test_a_bad_limit_is_refused_not_ignored():
    """The limit FLEXMM_MAX_MEMORY_GIB=abc was once silently replaced by the default."""
    from flexmm.environment import EnvironmentVariableError
    from flexmm.plan.cost import limits

    old = os.environ.get("FLEXMM_MAX_MEMORY_GIB")
    try:
        os.environ["FLEXMM_MAX_MEMORY_GIB"] = "abc"
        with pytest.raises(EnvironmentVariableError, match="FLEXMM_MAX_MEMORY_GIB='abc'"):
            limits()
        os.environ["FLEXMM_MAX_MEMORY_GIB"] = "0.5"
        assert limits()["memory_gib"] == 0.5
    finally:
        if old is None:
            os.environ.pop("FLEXMM_MAX_MEMORY_GIB", None)
        else:
            os.environ["FLEXMM_MAX_MEMORY_GIB"] = old


def test_real_processes_print_error_lines_without_traceback(files):
    """What a user sees in a terminal (stderr of a real process), for a few of the cases above."""
    env = {**os.environ, "FLEXMM_MAX_OUTPUT_GIB": "lots"}
    cases = [(["analyze", files["analysis_nc"]], None, "is an analysis file"),
             (["validate", LEGO, "--set", "lattice.n_units=true"], env, "FLEXMM_MAX_OUTPUT_GIB='lots'")]
    for args, environ, fragment in cases:
        res = subprocess.run([FLEXMM, *map(str, args)], capture_output=True, text=True, timeout=300, env=environ)
        assert res.returncode == 2 and res.stderr.startswith("error:") and "Traceback" not in res.stderr, res.stderr
        assert fragment in res.stderr, (fragment, res.stderr)


# ------------------------------------------------------------------ fuzz
VALUES = st.one_of(  # what a command line or an environment can hold: any text but NUL
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",), exclude_characters="\x00"),
            max_size=12),
    st.integers(-10**12, 10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["true", "no", "null", "~", "[]", "{}", "1e400", "-0", "0x10", "1:2", "a:b", ":", "1e-400"]),
)
ANALYZE_OPTIONS = ["--field", "--analysis", "--row", "--threshold", "--jump"]
RENDER_OPTIONS = ["--time", "--start", "--stop", "--every", "--max-frames", "--fps", "--color", "--clim",
                  "--exaggerate", "--shape", "--sites", "--row", "--width"]
SET_PATHS = ["lattice.n_units", "lattice.theta0_rad", "lattice.left", "excitation.velocity_m_s",
             "excitation.kind", "solver.duration_s", "solver.dt_s", "solver.threads", "solver.integrator",
             "output.n_frames", "output.every_s", "output.site_stride", "output.fields", "damping", "name"]


def _fuzz(files, tmp_path, data) -> None:
    verb = data.draw(st.sampled_from(["analyze", "render", "validate"]))
    env = {name: data.draw(VALUES) for name in data.draw(st.sets(st.sampled_from(sorted(VARIABLES)), max_size=2))}
    if verb == "validate":
        args = ["validate", LEGO]
        for _ in range(data.draw(st.integers(1, 3))):
            args += ["--set", f"{data.draw(st.sampled_from(SET_PATHS))}={data.draw(VALUES)}"]
    else:
        names = ANALYZE_OPTIONS if verb == "analyze" else RENDER_OPTIONS
        args = [verb, files["run"]]
        for name in data.draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True)):
            args += [name, data.draw(VALUES)]
        args += ["--no-save"] if verb == "analyze" else ["--out", tmp_path / "f.png", "-q"]
    answered(invoke(*args, env=env))


@settings(max_examples=40, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_fuzz_options_and_environment(files, tmp_path, data):
    _fuzz(files, tmp_path, data)


@pytest.mark.slow
@settings(max_examples=600, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_fuzz_options_and_environment_at_length(files, tmp_path, data):
    _fuzz(files, tmp_path, data)


# ------------------------------------------------------------------ small things that mislead
def test_render_sites_takes_colour_limits_from_the_units_shown(files):
    """``--sites A:B`` once coloured by limits from the whole chain: a window's own wave was
    saturated (or, as here, a quiet window drawn in the faint colours of a distant pulse)."""
    from flexmm.render import RenderOptions
    from flexmm.render.api import still_figure

    ds = xr.load_dataset(files["run_nc"], engine="h5netcdf")
    theta = np.abs(ds["theta"].values[-1])
    peak = int(np.argmax(theta))
    a = 0 if peak >= 30 else 45  # ten units far from the pulse
    window = theta[a:a + 10].max()
    assert window < 0.5 * theta.max()  # the case: a quiet window, a strong pulse elsewhere
    t = float(ds["time"].values[-1])
    whole = still_figure(files["run"], RenderOptions(time_s=t, color="theta")).colouring
    shown = still_figure(files["run"], RenderOptions(time_s=t, color="theta", sites=(a, a + 10))).colouring
    assert whole.vmax > window  # the whole chain's limits reach the pulse
    assert 0 < shown.vmax <= window * (1 + 1e-12) and shown.vmin == -shown.vmax


def test_movie_message_says_render_time_and_movie_length(files, tmp_path):
    res = answered(invoke("render", files["run"], "--out", tmp_path / "m.gif", "--max-frames", "6", "--fps", "4"),
                   codes=(0,))
    n = int(res.stderr.split(": ", 1)[1].split(" frames")[0])
    assert f"(a {n / 4:.3g} s movie at 4 frames/s); render time " in res.stderr, res.stderr


def test_more_threads_than_cores_runs_on_the_cores_and_says_so(tmp_path, monkeypatch):
    """solver.threads above the cores the process may use (here made 1) is clamped with a line."""
    import flexmm.controller
    import flexmm.integrators.parallel

    for module in (flexmm.controller, flexmm.integrators.parallel):
        monkeypatch.setattr(module, "available_threads", lambda: 1)
    res = answered(invoke("run", LEGO, *TINY_RUN, "--set", "solver.threads=200", "--out", tmp_path / "r"),
                   codes=(0,))
    assert "solver.threads 200 > the 1 threads this process may use: running on 1" in res.stderr, res.stderr
    assert "200 threads" not in res.stderr and ", 2 threads" not in res.stderr, res.stderr
