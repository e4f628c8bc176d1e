"""Predictions for the rotating-triangles chain and kagome sheet (docs/physics.md §1.6) from a
run's config: longitudinal pulses (u, its rate and strain) against the linear long-wave speed of
the Bloch analysis (``flexmm.linear.triangles``), converted with c0 = a sqrt(k_l/m). Rotation
and transverse pulses (no theory of their nonlinear waves yet) and lattices with a ``variation``
get no prediction.
"""

from __future__ import annotations

import math

from flexmm.analysis.context import Comparison, ModelTheory

_LONGITUDINAL = ("u", "u_dot", "strain", "strain:u", "velocity", "velocity:u")


def _chain_speed(lat) -> tuple[float, str]:
    from flexmm.linear.triangles import chain_long_wave_speed

    return chain_long_wave_speed(lat), "chain"


def _sheet_speed(lat) -> tuple[float, str]:
    from flexmm.linear.triangles import sheet_long_wave_speeds

    return sheet_long_wave_speeds(lat, 0.0)[1], "sheet, longitudinal planar wave"


def pulse_predictor(speed):
    """The speed row of a longitudinal pulse, from ``speed(lattice) -> (c / c0, what)`` (a
    sheet's: a planar wave along x)."""
    def pulse(ctx, p_meas) -> list[Comparison]:
        lat = ctx.scene().lattice
        if p_meas.field not in _LONGITUDINAL or lat.variation:  # the Bloch speed is a uniform lattice's
            return []
        c, what = speed(lat)
        c0 = lat.a_m * math.sqrt(lat.k_long_n_per_m / lat.mass_kg)
        return [Comparison("", "speed", float(p_meas.speed_m_s), c * c0, "m/s",
                           f"linear long-wave speed, Bloch ({what}; docs/physics.md §1.6)")]
    return pulse


#: the theories of the two triangle kinds (``config.lattice.MODELS``); the Bloch long-wave speed
#: is the longitudinal wave's
CHAIN = ModelTheory(pulse=pulse_predictor(_chain_speed), pulse_field="u")
SHEET = ModelTheory(pulse=pulse_predictor(_sheet_speed), pulse_field="u")
