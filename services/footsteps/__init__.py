"""Footstep planning as inverse kinematics (Kanoun, Laumond, Yoshida): see README.md.

Entry points: ``services.footsteps.planner.plan_footsteps(FootstepPlanRequest) -> FootstepPlanResult``
(``services.footsteps.request``), ``services.footsteps.execution.execute_plan`` (walk + reach motion).
Nothing is imported here so that ``humanoid --help`` stays light.
"""
