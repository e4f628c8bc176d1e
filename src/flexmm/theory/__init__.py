"""Analytical theory for flexmm: closed forms and reduced ODEs used to seed and check simulations.

Pure numpy/scipy and nondimensional (docs/physics.md §1.1 scales for the rotating-squares chain).
`rotating` covers the rotating-squares chain (docs/physics.md §1.3, §1.4), `prestressed` the chain held
rotated by an end load, `cnoidal` periodic (cnoidal) waves and the driven wave of a chain; `chains`
covers chains of masses with nonlinear springs and on-site potentials (docs/physics.md §2).
"""
from flexmm.theory.chains import (
    BistableFront,
    SechWave,
    bistable_front,
    bistable_front_profile,
    evanescent_decay,
    front_kinetic_energy,
    Kink,
    driven_kink_speed,
    fpu_beta_solitary_wave,
    hertz_kdv_wave,
    phi4_kink,
    sine_gordon_kink,
    linear_chain_band,
    linear_chain_cutoff_frequency,
    linear_chain_dispersion,
    nesterenko_precompressed_speed,
    nesterenko_profile,
    nesterenko_speed,
    nesterenko_speed_from_force,
    nesterenko_support,
    softening_profile,
    softening_solitary_wave,
    toda_soliton,
    toda_speed,
)
from flexmm.theory.cnoidal import CnoidalWave, DrivenWave, cnoidal_through, driven_wave, linear_speed
from flexmm.theory.prestressed import prestressed_chain, soliton_window, static_rotation
from flexmm.theory.rotating import (
    BandEdges,
    RotatingChainND,
    TravellingState,
    amplitude_gap,
    band_edges,
    cnoidal_wave,
    continuum_coefficients,
    dispersion_chain,
    dispersion_rotational,
    exact_soliton,
    gradient_coefficient,
    hinge_stretch,
    lego_parameters,
    long_wave_speed,
    min_phase_speed_rotational,
    omega_max_chain,
    rotational_cutoff_speed,
    soliton_amplitude,
    soliton_exists,
    soliton_initial_state,
    soliton_profile,
    soliton_speed,
    soliton_width,
)

__all__ = [
    "BandEdges", "BistableFront", "CnoidalWave", "DrivenWave", "RotatingChainND", "SechWave",
    "TravellingState", "cnoidal_through", "driven_wave", "linear_speed", "prestressed_chain",
    "soliton_window", "static_rotation",
    "amplitude_gap", "band_edges", "bistable_front", "bistable_front_profile", "cnoidal_wave",
    "continuum_coefficients", "dispersion_chain", "dispersion_rotational", "evanescent_decay",
    "exact_soliton", "front_kinetic_energy", "gradient_coefficient", "hinge_stretch",
    "lego_parameters", "linear_chain_band", "linear_chain_cutoff_frequency",
    "linear_chain_dispersion", "long_wave_speed", "min_phase_speed_rotational",
    "nesterenko_precompressed_speed", "nesterenko_profile", "nesterenko_speed", "nesterenko_speed_from_force", "nesterenko_support",
    "omega_max_chain", "rotational_cutoff_speed", "softening_profile", "softening_solitary_wave",
    "soliton_amplitude", "soliton_exists", "soliton_initial_state", "soliton_profile",
    "Kink", "driven_kink_speed", "fpu_beta_solitary_wave", "hertz_kdv_wave", "phi4_kink", "sine_gordon_kink",
    "soliton_speed", "soliton_width", "toda_soliton", "toda_speed",
]
