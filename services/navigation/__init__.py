"""Navigation: the two-stage planner of "Manipulating While Walking" (001_771c0ce3779b0683.txt). Stage 1:
car-like collision-free paths of the body's floor boxes (OMPL Dubins / Reeds-Shepp), named-object goals,
the carried bar's 3D sweep, footsteps along the path. Stage 2: the whole-body walk holding the bar, its
3D collision check and the smooth reshaping of the bar's motion. ``service.py`` serves ``navigation/goto``.
See README.md."""
