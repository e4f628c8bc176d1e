"""Model no more than a scene needs: plan the domain, dimension, continuum, output and time step.

``make_plan(scene, fidelity)`` (``planner``) is what ``flexmm plan`` prints and what
``flexmm run`` executes; ``compare_fidelities`` (``compare``) runs two fidelities of a scene
and reports how their observables and costs differ.
"""

from flexmm.plan.planner import FIDELITIES, Plan, PlanError, PlanStep, make_plan

__all__ = ["FIDELITIES", "Plan", "PlanError", "PlanStep", "make_plan"]
