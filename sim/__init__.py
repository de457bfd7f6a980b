"""sim: the pybullet world (scenes, robot, cameras, grasping) and the ``sim`` service; see sim/README.md."""
