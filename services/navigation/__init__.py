"""Navigation: car-like collision-free paths for the lower body (OMPL Dubins / Reeds-Shepp), the carried
object's 3D sweep along them, named-object goals and footsteps along the path (stage 1 of the two-stage
planner of "Manipulating While Walking", 001_771c0ce3779b0683.txt). See README.md."""
