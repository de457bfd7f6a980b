"""Walking pattern generator (issue 5): ZMP preview control (Kajita et al. 2003) to 5 ms whole-body
joint trajectories. Pure algorithm package (no bus); see README.md in this directory.

Modules: ``footsteps`` (sequences, bounds, generators), ``timing`` (phases on the grid),
``zmp_reference``, ``preview_control`` (cart-table, gains, second stage), ``swing``, ``pattern``
(``plan_pattern``), ``support_polygon``, ``multibody_zmp``, ``wholebody`` (``WholeBodyPlanner``,
``plan_walk``).
"""
