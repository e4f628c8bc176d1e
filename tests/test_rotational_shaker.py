"""The shaker's prescribed-rotation mode (``amplitude_rad``): config rules and the driven DOFs."""
import copy

import numpy as np
import pytest
from conftest import LEGO_LATTICE

from flexmm.assemble import build_system
from flexmm.config import scene_from_dict
from flexmm.errors import FlexmmError

SCENE = {"name": "rot", "lattice": {**LEGO_LATTICE, "n_units": 20},
         "excitation": {"kind": "shaker", "end": "left", "frequency_hz": 300.0, "amplitude_rad": 0.01},
         "solver": {"duration_s": 1e-3}}


def test_rotational_shaker_drives_the_rotation_of_the_end_unit():
    system, terms = build_system(scene_from_dict(copy.deepcopy(SCENE)))
    theta0 = system.dof(system.rotation_field, 0)
    assert list(terms.drv_dof) == [theta0]
    assert terms.drv_prm[0][0] == pytest.approx(0.01)  # radians need no scaling


@pytest.mark.parametrize("extra", [{"amplitude_m": 1e-4}, {"amplitude_n": 0.1}, {"angle_deg": 10.0}])
def test_rotational_shaker_excludes_other_amplitudes_and_tilts(extra):
    data = copy.deepcopy(SCENE)
    data["excitation"].update(extra)
    with pytest.raises((FlexmmError, ValueError)):
        scene_from_dict(data)


def test_energy_budget_infers_the_work_of_a_prescribed_rotation():
    """A prescribed rotation does work the controller does not record: the budget infers it."""
    import xarray as xr
    import yaml

    from flexmm.analysis.measure.energy import energy_budget

    t = np.linspace(0.0, 1.0, 5)
    ds = xr.Dataset({"kinetic_energy": ("time", t), "potential_energy": ("time", 0 * t),
                     "total_energy": ("time", t), "applied_work": ("time", 0 * t)},
                    coords={"time": t}, attrs={"config": yaml.safe_dump(SCENE)})
    budget = energy_budget(ds)
    assert not budget.work_recorded and budget.work_j == pytest.approx(1.0)
