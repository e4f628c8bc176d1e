"""Run a planar wave in a sheet on the smallest lattice that carries it (docs/physics.md §1.2).

When every unit of a column starts and is driven alike and the sheet is periodic across the
wave (bottom/top periodic), the motion keeps that symmetry up to the checkerboard: u and θ are
the same in every row, while the shear of the horizontal hinges (sign σ alternating with the
row) drives a lateral displacement v = (−1)^row w(col). The motion therefore has period two in
the rows, and two reductions follow:

- ``strip`` (exact, the default): the same sheet with 2 rows, periodic across — identical to
  the full sheet to rounding, n_rows/2 times cheaper;
- ``chain``: the rotating-squares chain with n_lateral = 2, lateral_stretch = true (docs/physics.md §1.2),
  which suppresses v. It is exact only as K_s → 0: the staggered v relaxes the shear hinges, so
  with stiff shear (K_s ~ 0.2) the chain's θ pulse differs at first order; with K_s ~ 0.02 the
  rotational band shifts by ~0.5 %. ``flexmm compare --fidelity full,chain`` measures it.

The whole scene must have that symmetry, the initial state (``initial``) included: its fields
are evaluated on every unit of the sheet and must repeat every two rows (every row for the
chain, which has no v), pins must hold whole columns, and a state read from another run or a
launched wave keeps the sheet.

Reducers are the ``reducers`` hooks of a kind's ``ModelSpec`` (``flexmm.config.lattice.MODELS``);
each takes the scene as a plain dict and its lattice config and returns the reduced scene dict,
or raises ``NotPlanar``.
"""

from __future__ import annotations


class NotPlanar(Exception):
    """The scene has no exact lower-dimensional equivalent; the message says why."""


def _excitation(data: dict):
    """The scene dict's excitation as its validated config (its hooks say what it does)."""
    from pydantic import TypeAdapter

    from flexmm.config.excitation import ExcitationConfig

    return TypeAdapter(ExcitationConfig).validate_python(data.get("excitation") or {"kind": "none"})


def _columns_of(sites: list[int], n_rows: int, n_cols: int, what: str) -> list[int]:
    """Columns whose every unit is listed in ``sites``; NotPlanar if ``sites`` is not whole columns."""
    chosen = set(sites)
    cols = sorted({s % n_cols for s in chosen})
    if any(r * n_cols + c not in chosen for c in cols for r in range(n_rows)):
        raise NotPlanar(f"{what} does not cover whole columns")
    return cols


def _check_initial(data: dict, lat, period: int) -> None:
    """NotPlanar unless ``initial`` repeats every ``period`` rows: each ``fields`` entry is evaluated
    on the whole sheet (value and rate), pins hold whole columns, nothing comes from another run."""
    import numpy as np

    from flexmm.initial_state import field_values, grid_variables, spacing

    init = data.get("initial") or {}
    if init.get("from_run"):
        raise NotPlanar("initial.from_run: the state of another run is not checked to be uniform across rows")
    if init.get("launch"):
        raise NotPlanar("initial.launch: launched waves are not checked to be uniform across rows")
    for k, pin in enumerate(init.get("pinned") or []):
        _columns_of(pin["sites"], lat.n_rows, lat.n_cols, f"initial.pinned.{k}.sites")
    if not init.get("fields"):
        return
    from flexmm.config.initial import FieldInit

    row, col = np.divmod(np.arange(lat.n_rows * lat.n_cols), lat.n_cols)
    variables = grid_variables(col, row, spacing(lat))
    for k, f in enumerate(init["fields"]):
        if period == 1 and f["field"] == "v":
            raise NotPlanar(f"initial.fields.{k}: the chain has no lateral displacement v")
        try:
            values = field_values(FieldInit.model_validate(f), variables, row.size)
        except ValueError:
            raise NotPlanar(f"initial.fields.{k} cannot be evaluated on the sheet") from None
        for what, arr in zip(("value", "rate"), values):
            grid = arr.reshape(lat.n_rows, lat.n_cols)
            repeated = grid[np.arange(lat.n_rows) % period]
            if np.max(np.abs(grid - repeated), initial=0.0) > 1e-12 * np.max(np.abs(grid), initial=0.0):
                across = "alike in every row" if period == 1 else "periodic with period 2 across the rows"
                raise NotPlanar(f"initial.fields.{k} ({f['field']} {what}) is not {across}")


def _pinned_rows(data: dict, lat, rows) -> list | None:
    """``initial.pinned`` with the sites of whole columns remapped onto ``rows`` (None: no pins)."""
    pins = (data.get("initial") or {}).get("pinned") or []
    out = []
    for pin in pins:
        cols = _columns_of(pin["sites"], lat.n_rows, lat.n_cols, "initial.pinned.sites")
        out.append({**pin, "sites": [r * lat.n_cols + c for r in rows for c in cols]})
    return out


def _check_planar(data: dict, lat, period: int = 2) -> None:
    """NotPlanar unless the sheet scene keeps every column uniform (see module docstring) and its
    initial state repeats every ``period`` rows."""
    if lat.bottom != "periodic":
        raise NotPlanar(f"bottom/top edges are {lat.bottom}/{lat.top}, not periodic: the wave does not "
                        "stay planar near them")
    if lat.skew_cols:
        raise NotPlanar(f"skew-periodic sheet (skew_cols = {lat.skew_cols}): its waves are oblique, "
                        "not uniform along columns")
    if lat.n_rows <= 2:
        raise NotPlanar(f"{lat.n_rows} rows: already the smallest periodic sheet")
    if lat.magnets is not None:
        raise NotPlanar("magnets: the reduction is not verified with dipole forces")
    for v in lat.variation:
        if getattr(v, "axis", None) != "x" or v.kind not in ("gradient", "interface"):
            raise NotPlanar(f"a {v.kind} variation is not uniform across rows")
    pre = lat.predeform
    if pre is not None and (pre.strain_y is not None or any(ld.end in ("top", "bottom") for ld in pre.loads)):
        raise NotPlanar("a predeformation along y")
    issue = _excitation(data).planar_issue()
    if issue is not None:
        raise NotPlanar(issue)
    imp = data.get("imperfection")
    if imp is not None:
        if imp["kind"] != "rotation_seed":
            raise NotPlanar(f"imperfection {imp['kind']!r} is not uniform across rows")
        _columns_of(imp["sites"], lat.n_rows, lat.n_cols, "imperfection.sites")
    _check_initial(data, lat, period)


def _scaled_loads(pre, factor: float) -> dict:
    p = pre.model_dump(mode="json")
    p["loads"] = [{**ld, "force_n": ld["force_n"] * factor} for ld in p["loads"]]
    return p


def sheet_to_strip(data: dict, lat) -> dict:
    """The same planar scene on a 2-row periodic sheet (exact)."""
    _check_planar(data, lat)
    out = {**data, "lattice": {**data["lattice"], "n_rows": 2}}
    if lat.predeform is not None:  # end loads are split over the edge units: keep the load per unit
        out["lattice"]["predeform"] = _scaled_loads(lat.predeform, 2 / lat.n_rows)
    imp = data.get("imperfection")
    if imp is not None:
        cols = _columns_of(imp["sites"], lat.n_rows, lat.n_cols, "imperfection.sites")
        out["imperfection"] = {**imp, "sites": [r * lat.n_cols + c for r in (0, 1) for c in cols]}
    if data.get("initial"):
        out["initial"] = {**data["initial"], "pinned": _pinned_rows(data, lat, (0, 1))}
    return out


def sheet_to_chain(data: dict, lat) -> dict:
    """The planar scene as the n_lateral = 2, lateral_stretch chain (suppresses v; see docstring)."""
    _check_planar(data, lat, period=1)
    if "periodic" in (lat.left, lat.right):
        raise NotPlanar("left/right periodic has no chain equivalent")
    if lat.ligament_length_m != 0:
        raise NotPlanar("ligaments are not in the chain model")
    chain = {
        "kind": "rotating_squares_chain", "n_units": lat.n_cols, "a_m": lat.a_m,
        "theta0_rad": lat.theta0_rad, "k_long_n_per_m": lat.k_long_n_per_m,
        "k_shear_n_per_m": lat.k_shear_n_per_m, "k_rot_n_m_per_rad": lat.k_rot_n_m_per_rad,
        "mass_kg": lat.unit_mass_kg, "inertia_kg_m2": lat.unit_inertia_kg_m2,
        "n_lateral": 2, "lateral_stretch": True, "left": lat.left, "right": lat.right,
        "variation": data["lattice"].get("variation", []),
    }
    if lat.predeform is not None:
        chain["predeform"] = _scaled_loads(lat.predeform, 1 / lat.n_rows)
    out = {**data, "lattice": chain}
    out["excitation"] = dict(data.get("excitation") or {"kind": "none"})
    if data.get("initial"):
        out["initial"] = {**data["initial"], "pinned": _pinned_rows(data, lat, (0,))}
    imp = data.get("imperfection")
    if imp is not None:
        out["imperfection"] = {**imp, "sites": _columns_of(imp["sites"], lat.n_rows, lat.n_cols, "")}
    output = dict(data.get("output") or {})
    if output.get("fields") is not None:
        output["fields"] = [f for f in output["fields"] if f != "v"] or None
    out["output"] = output
    return out


NOTES = {
    "strip": "runs as the 2-row periodic strip ({factor:g}× fewer units, exact: the planar motion "
             "has period 2 across the rows); --fidelity full runs the sheet",
    "chain": "runs as the {n}-unit chain with n_lateral = 2, lateral_stretch = true ({factor:g}× fewer "
             "units; approximate: suppresses the staggered lateral displacement)",
}


def reduce_dimension(scene, reduction: str = "strip"):
    """(reduced Scene, note) if the scene has a planar equivalent, else (None, reason)."""
    from flexmm.config import scene_from_dict
    from flexmm.config.lattice import MODELS

    reducer = MODELS[scene.lattice.kind].reducer(reduction)
    if reducer is None:
        return None, f"{scene.lattice.kind}: no lower-dimensional ({reduction}) equivalent registered"
    data = scene.model_dump(mode="json")
    try:
        reduced = reducer(data, scene.lattice)
    except NotPlanar as why:
        return None, f"kept the {scene.lattice.kind}: {why}"
    lat = scene.lattice
    factor = lat.n_rows / 2 if reduction == "strip" else lat.n_rows
    note = f"planar excitation of a {lat.n_rows}×{lat.n_cols} sheet, periodic across: " + NOTES[reduction].format(
        factor=factor, n=lat.n_cols)
    return scene_from_dict(reduced, source=f"<plan: planar {reduction}>"), note
