"""Walking pattern generator (issue 5): ZMP preview control (Kajita et al. 2003) to 5 ms whole-body joint
trajectories. Pure algorithm package (no bus) plus its bus adapter ``service.py``; see README.md.

Modules: ``footsteps`` (sequences, bounds, generators), ``timing`` (phases on the grid),
``zmp_reference``, ``preview_control`` (cart-table, gains, second stage), ``swing``, ``pattern``
(``plan_pattern``), ``support_polygon``, ``multibody_zmp``, ``upper_body`` (hand and gaze tasks while
walking), ``wholebody`` (``WholeBodyPlanner``, ``plan_walk``), ``service`` (the ``walking/plan``
endpoint; the only module that touches the bus).
"""
