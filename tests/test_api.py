"""The notebook API (``flexmm.run``, ``flexmm.analyze``, ``flexmm.render``; docs/api.md).

One short LEGO impact run (0.3 s of configs/lego_vector_soliton.yaml on a 200-unit chain with a free
far end) is shared by the tests that need a run; the config-error tests run nothing.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import numpy as np
import pytest

import flexmm
from conftest import DEMO_AS_LEGO_SCENE, LEGO_SCENE
from flexmm.config import ConfigError, Scene, scene_from_dict
from flexmm.errors import FlexmmError, UsageError

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
#: long enough for the vector soliton to form and be fitted over 10+ sites, short enough for a test
SHORT = {**DEMO_AS_LEGO_SCENE, "solver.duration_s": 0.3, "output.n_frames": 301}


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """The demo for 0.3 s through ``flexmm.run`` in memory, with the temporary directory it used."""
    tmp = tmp_path_factory.mktemp("api-tmp")
    old = tempfile.tempdir
    tempfile.tempdir = str(tmp)
    try:
        res = flexmm.run(str(DEMO), **SHORT)
    finally:
        tempfile.tempdir = old
    return res, tmp


def test_three_lines_reach_a_dataset_and_the_soliton_speed(short_run):
    """The target of docs/api.md: a Dataset and the soliton's measured speed in three lines, the
    speed within 3 % of the exact vector-soliton law at its amplitude (the theory module's
    prediction, which the measurement does not use)."""
    res, tmp = short_run
    m = flexmm.analyze(res.dataset)
    speed = m.speed_m_s
    assert res.ok and res.status == "finished" and res.message == ""
    assert res.dataset.sizes["time"] == 301 and "theta" in res.dataset
    assert res.error_estimate is not None and res.error_estimate <= res.accuracy["accuracy_requested"]
    row = next(c for c in m.comparisons if c["item"] == f"pulse {m.principal.index}" and c["quantity"] == "speed")
    assert row["measured"] == speed and row["predicted"] is not None
    assert abs(speed - row["predicted"]) < 0.03 * row["predicted"]
    assert repr(res).startswith("<flexmm.Result 'lego_vector_soliton': finished; dataset (time: 301, site: 200), "
                                "error estimate ")
    # in memory: nothing left on disk, no path
    assert res.path is None
    assert list(tmp.iterdir()) == []


def test_analysis_of_a_dataset_equals_that_of_its_file(short_run, tmp_path):
    """``flexmm.analyze(ds)`` measures what ``flexmm analyze RUN`` measures on the same data, and
    leaves the dataset as it was."""
    res, _ = short_run
    nc = tmp_path / "dataset.nc"
    res.dataset.to_netcdf(nc, engine="h5netcdf")
    before = res.dataset.copy(deep=True)
    from_memory, from_file = flexmm.analyze(res.dataset), flexmm.analyze(tmp_path)
    assert res.dataset.identical(before)
    assert from_memory.kind == from_file.kind == "pulse"
    assert repr(from_memory.comparisons) == repr(from_file.comparisons)  # nan-aware
    assert str(from_memory) == str(from_file)
    table = from_memory.dataset
    assert table.attrs["analysis"] == "pulse"
    assert float(table["pulse_speed_m_s"][from_memory.principal.index]) == from_memory.speed_m_s


def test_analyze_options_are_validated(short_run):
    res, _ = short_run
    with pytest.raises(ConfigError, match=r"flexmm.analyze: kind: got 'pulses'"):
        flexmm.analyze(res.dataset, kind="pulses")
    with pytest.raises(ConfigError, match="threshold_fraction"):
        flexmm.analyze(res.dataset, threshold_fraction=5.0)


def _pixels(fig) -> np.ndarray:
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).copy()


def test_render_draws_the_frame_asked_for(short_run, tmp_path):
    """A Figure of one frame; the in-memory dataset draws exactly what its file draws, and another
    time draws another picture."""
    from matplotlib.figure import Figure

    res, _ = short_run
    res.dataset.to_netcdf(tmp_path / "dataset.nc", engine="h5netcdf")
    fig = flexmm.render(res.dataset, t=0.1)
    assert isinstance(fig, Figure)
    same = _pixels(fig)
    assert np.array_equal(same, _pixels(flexmm.render(tmp_path, t=0.1)))
    assert not np.array_equal(same, _pixels(flexmm.render(res.dataset, t=0.25)))
    with pytest.raises(UsageError, match="outside the run"):
        flexmm.render(res.dataset, t=5.0)
    with pytest.raises(UsageError, match="unknown option colour"):
        flexmm.render(res.dataset, colour="theta")


def test_run_writes_a_run_directory_when_asked(tmp_path):
    """``out``: dataset.nc, config.yaml and run.log as ``flexmm run --out`` writes them; the
    dataset returned is the one written. A dict scene with ``overrides=`` and dotted keywords."""
    scene = copy.deepcopy(LEGO_SCENE)
    scene["lattice"]["n_units"] = 40
    res = flexmm.run(scene, tmp_path / "run", overrides={"solver.duration_s": 0.01, "output.n_frames": 5},
                     **{"output.n_frames": 11})
    assert res.ok and res.path == tmp_path / "run" / "dataset.nc"
    assert {p.name for p in (tmp_path / "run").iterdir()} >= {"dataset.nc", "config.yaml", "run.log"}
    assert (res.dataset.sizes["time"], res.dataset.sizes["site"]) == (11, 40)
    import xarray as xr

    assert res.dataset.identical(xr.load_dataset(res.path, engine="h5netcdf"))
    assert scene["lattice"]["n_units"] == 40 and "output" in scene  # the dict given is not modified
    assert scene["output"] == LEGO_SCENE["output"]


# ----------------------------------------------------------------------------- config errors

def test_a_bad_dict_raises_config_error_with_the_dotted_path():
    bad = copy.deepcopy(LEGO_SCENE)
    bad["lattice"]["n_units"] = "many"
    bad["solver"]["duraton_s"] = 1.0
    with pytest.raises(ConfigError) as err:
        flexmm.run(bad)
    text = str(err.value)
    assert "<dict>: lattice.n_units: got 'many' (str); expected: " in text
    assert "<dict>: solver.duraton_s: unknown key; did you mean 'duration_s'?" in text
    assert isinstance(err.value, FlexmmError)


def test_a_bad_yaml_string_names_its_line():
    text = DEMO.read_text().replace("n_units: 900", "n_units: -3")
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "n_units: -3" in s)
    with pytest.raises(ConfigError, match=rf"<string>:{line}: lattice.n_units: got -3 \(int\); expected: "):
        flexmm.run(text)
    with pytest.raises(ConfigError, match=r"<string>:\d+: invalid YAML"):
        flexmm.run("name: x\nlattice: [unclosed\n")


def test_a_bad_override_names_the_override():
    with pytest.raises(ConfigError, match=r"override solver.duration_s=-1: solver.duration_s: got -1 \(int\); "
                                          r"expected: input should be greater than 0"):
        flexmm.run(DEMO, **{"solver.duration_s": -1})


def test_a_missing_file_and_a_wrong_type_are_config_errors():
    with pytest.raises(ConfigError, match="no_such_scene.yaml: cannot read file"):
        flexmm.run("no_such_scene.yaml")
    with pytest.raises(ConfigError, match="expected: a Scene, a dict, YAML text or the path of a YAML file"):
        flexmm.run(42)


def test_every_form_of_a_scene_gives_the_same_scene():
    """Path, path string, YAML text, dict and Scene (with overrides applied to each)."""
    from flexmm.config import resolve_scene

    over = {"solver.duration_s": 0.2, "lattice.n_units": 50}
    want = scene_from_dict({**LEGO_SCENE, "lattice": {**LEGO_SCENE["lattice"], "n_units": 50},
                            "solver": {**LEGO_SCENE["solver"], "duration_s": 0.2}})
    from_file = resolve_scene(DEMO, over)
    forms = [str(DEMO), DEMO.read_text(), copy.deepcopy(LEGO_SCENE), resolve_scene(DEMO)]
    got = [resolve_scene(f, over) for f in forms]
    assert isinstance(from_file, Scene)
    assert from_file.lattice == want.lattice and from_file.solver.duration_s == 0.2
    for g in got:
        assert g.lattice == from_file.lattice and g.solver.duration_s == 0.2 and g.excitation == from_file.excitation


def test_import_flexmm_is_light():
    """``import flexmm`` imports none of the API's modules until one is used."""
    import subprocess
    import sys

    code = "import sys, flexmm; print(sorted(m for m in sys.modules if m.startswith(('flexmm.', 'numpy', 'xarray'))))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['flexmm._version']"


def test_a_failed_run_returns_its_frames_and_why(tmp_path, monkeypatch):
    """A run that fails (here: the disk fills after 100 frames) does not raise: the Result says
    'failed' and why, with the frames written, and the temporary directory is gone."""
    import flexmm.io.run_dataset as run_dataset

    flush = run_dataset.DatasetWriter.flush

    def full_after_100(self) -> None:
        if self.n_written >= 100:
            raise OSError(28, "No space left on device")
        flush(self)

    monkeypatch.setattr(run_dataset.DatasetWriter, "flush", full_after_100)
    monkeypatch.setattr(run_dataset, "BUFFER_BYTES", 8 * 400 * 2 * 50)  # flush every 50 frames
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    res = flexmm.run(DEMO, **SHORT)
    assert not res.ok and res.status == "failed" and "No space left on device" in res.message
    assert res.dataset.sizes["time"] == 100 and res.dataset.attrs["status"] == "failed"
    assert res.path is None and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kind", ["pulse", "front", "driven"])
def test_nothing_to_measure_is_a_flexmm_error(short_run, kind):
    """A run in which nothing moves has no pulse, front or drive: ``flexmm.analyze`` raises a
    FlexmmError (what a caller of the API catches), not a bare Exception."""
    res, _ = short_run
    still = res.dataset.copy(deep=True)
    for name, var in still.data_vars.items():
        if var.dims == ("time", "site"):
            still[name].values[...] = still[name].values[:1]  # every frame the first (rest)
    with pytest.raises(FlexmmError) as err:
        flexmm.analyze(still, kind=kind)
    assert not isinstance(err.value, ConfigError)
